//! Random robot poses in a plan's free space (the paper's experiments use 100 random poses
//! per round, sect. 8.1).
//!
//! Plans are sets of polylines, not always closed, so "inside the building" takes two tests:
//! the CLOSED polylines, and enclosure: level rays in 16 directions all meet a wall within
//! range. A closed polyline bounds a room, or a solid (a pillar, a box) when one of its
//! corners lies inside a larger one (`plan::outline`). When the rooms outline the whole plan
//! (every open wall lies within them), free space is inside a room and outside every solid,
//! whether the solids stand free, overlap or are built half into a wall. When they do not
//! (open outer walls around closed pillars, or no closed polyline at all), free space is
//! outside every closed polyline, and enclosure decides the rest.

use super::raycast::World;
use super::{SimulateError, Stream, stream_rng};
use crate::geometry::Pose;
use crate::plan::segment::{bounds, end_points};
use nalgebra::{Point2, Point3, Vector3};
use rand::RngExt;
use rayon::prelude::*;
use std::f64::consts::PI;

/// Directions of the enclosure test.
const ENCLOSURE_RAYS: usize = 16;

/// How random poses are drawn.
#[derive(Clone, Debug, PartialEq)]
pub struct RandomPoseParams {
    /// Largest roll and pitch; both are uniform in [-tilt, +tilt] \[rad\]. Default 20 deg.
    pub tilt: f64,
    /// Smallest distance from the robot's position to every wall segment \[m\]. Default 0.5.
    pub clearance: f64,
    /// Scanner height above the floor, the pose's z \[m\]. Default 0.45.
    pub height: f64,
    /// Range within which all 16 enclosure rays must meet a wall \[m\]. Default 30 (the
    /// scanner's default maximum range).
    pub enclosure_range: f64,
    /// Positions tried per pose before giving up. Default 10,000.
    pub max_tries: usize,
}

impl Default for RandomPoseParams {
    fn default() -> Self {
        Self {
            tilt: 20.0_f64.to_radians(),
            clearance: 0.5,
            height: 0.45,
            enclosure_range: 30.0,
            max_tries: 10_000,
        }
    }
}

/// True when `p` is inside the building (in a room and no solid, and enclosed) and at least
/// `clearance` metres from every wall.
/// Both tests go through the spatial index, so a try costs about the same on a plan of
/// 100,000 segments as on one of 10.
pub fn is_free(world: &World, p: &Point2<f64>, clearance: f64, enclosure_range: f64) -> bool {
    if world.wall_within(p, clearance) {
        return false;
    }
    if !world.open_at(p) {
        return false;
    }
    // Level rays at mid-wall height, so they meet walls rather than the floor or ceiling.
    let origin = Point3::new(p.x, p.y, world.wall_height() / 2.0);
    (0..ENCLOSURE_RAYS).all(|k| {
        let a = 2.0 * PI * k as f64 / ENCLOSURE_RAYS as f64;
        world
            .cast(
                &origin,
                &Vector3::new(a.cos(), a.sin(), 0.0),
                enclosure_range,
            )
            .is_some()
    })
}

/// `n` random poses in free space: positions uniform over the free part of the plan's bounds,
/// yaw uniform, roll and pitch uniform in +-tilt, z the scanner height. Pose `i` is drawn from
/// its own random stream (seed, i), so the poses do not depend on the thread count.
pub fn random_poses(
    world: &World,
    n: usize,
    params: &RandomPoseParams,
    seed: u64,
) -> Result<Vec<Pose>, SimulateError> {
    let Some((lo, hi)) = bounds(end_points(world.segments())) else {
        return Err(SimulateError::NoWalls);
    };
    (0..n)
        .into_par_iter()
        .map(|i| {
            let mut rng = stream_rng(seed, Stream::RandomPoses, i as u64);
            for _ in 0..params.max_tries {
                let p = Point2::new(
                    lo.x + (hi.x - lo.x) * rng.random::<f64>(),
                    lo.y + (hi.y - lo.y) * rng.random::<f64>(),
                );
                if is_free(world, &p, params.clearance, params.enclosure_range) {
                    let rz = rng.random_range(-PI..PI);
                    let mut tilt = || params.tilt * (2.0 * rng.random::<f64>() - 1.0);
                    let (ry, rx) = (tilt(), tilt());
                    return Ok(Pose::new(p.x, p.y, params.height, rz, ry, rx));
                }
            }
            Err(SimulateError::NoFreeSpace {
                tries: params.max_tries,
                clearance: params.clearance,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::{Plan, Segment};
    use proptest::prelude::*;

    /// The scene of a plan of `walls`, 3 m high, without a ceiling.
    fn world(walls: Vec<Vec<Point2<f64>>>) -> World {
        World::from_plan(&Plan {
            wall_height: 3.0,
            walls,
            ceiling: false,
            poses: vec![],
        })
    }

    /// [`is_free`] by testing every segment, as it was before the index: its twin.
    fn is_free_brute(world: &World, p: &Point2<f64>, clearance: f64, range: f64) -> bool {
        let holders: Vec<bool> = world
            .closed_polylines()
            .filter(|(segments, _)| {
                let crossings = segments
                    .iter()
                    .filter(|s| crate::plan::segment::crossing_x(s, p).is_some())
                    .count();
                crossings % 2 == 1
            })
            .map(|(_, solid)| solid)
            .collect();
        let open = if world.outline_closed() {
            !holders.is_empty() && holders.iter().all(|solid| !solid)
        } else {
            holders.is_empty()
        };
        open && world
            .segments()
            .iter()
            .all(|s| s.distance_to(p) >= clearance)
            && (0..ENCLOSURE_RAYS).all(|k| {
                let a = 2.0 * PI * k as f64 / ENCLOSURE_RAYS as f64;
                let o = Point3::new(p.x, p.y, world.wall_height() / 2.0);
                let d = Vector3::new(a.cos(), a.sin(), 0.0);
                world.cast_brute_force(&o, &d, range).is_some()
            })
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        /// Rooms with pillars, open fences and collinear pieces, on a lattice so that points
        /// on walls and exact ties are common.
        #[test]
        fn indexed_is_free_matches_brute_force(
            boxes in prop::collection::vec((0i32..12, 0i32..12, 1i32..6, 1i32..6), 1..6),
            fences in prop::collection::vec(((0i32..16, 0i32..16), (0i32..16, 0i32..16)), 0..4),
            probes in prop::collection::vec((0i32..64, 0i32..64), 24),
            clearance in prop_oneof![Just(0.0), Just(0.25), Just(0.5), Just(3.0)],
        ) {
            let c = |x: i32, y: i32| Point2::new(x as f64, y as f64);
            let mut walls: Vec<Vec<Point2<f64>>> = boxes
                .iter()
                .map(|&(x, y, w, h)| {
                    // The bottom side in unit pieces: a collinear run.
                    let mut wall: Vec<_> = (x..=x + w).map(|i| c(i, y)).collect();
                    wall.extend([c(x + w, y + h), c(x, y + h), c(x, y)]);
                    wall
                })
                .collect();
            walls.extend(fences.iter().map(|&((ax, ay), (bx, by))| vec![c(ax, ay), c(bx, by)]));
            let scene = world(walls);
            for (x, y) in probes {
                let p = Point2::new(x as f64 / 4.0, y as f64 / 4.0);
                prop_assert_eq!(
                    is_free(&scene, &p, clearance, 30.0),
                    is_free_brute(&scene, &p, clearance, 30.0),
                    "at {:?}", p
                );
            }
        }
    }

    #[test]
    fn walls_of_coincident_points_do_not_break_the_inside_tests() {
        let p = Point2::new(5.0, 5.0);
        let w = world(vec![square(0.0, 0.0, 10.0, 8.0), vec![p, p, p], vec![p, p]]);
        assert!(w.outline_closed());
        assert!(is_free(&w, &Point2::new(2.0, 2.0), 0.5, 30.0));
        let poses = random_poses(&w, 20, &RandomPoseParams::default(), 1).unwrap();
        assert_eq!(poses.len(), 20);
        let _: &[Segment] = w.closed_segments();
    }

    fn square(x0: f64, y0: f64, x1: f64, y1: f64) -> Vec<Point2<f64>> {
        vec![
            Point2::new(x0, y0),
            Point2::new(x1, y0),
            Point2::new(x1, y1),
            Point2::new(x0, y1),
            Point2::new(x0, y0),
        ]
    }

    fn room_with_pillar() -> World {
        world(vec![
            square(0.0, 0.0, 10.0, 8.0),
            square(4.0, 3.0, 6.0, 5.0),
        ])
    }

    #[test]
    fn inside_room_is_free_but_not_inside_pillar_or_outside() {
        let w = room_with_pillar();
        assert!(is_free(&w, &Point2::new(2.0, 2.0), 0.5, 30.0));
        assert!(!is_free(&w, &Point2::new(5.0, 4.0), 0.5, 30.0), "in pillar");
        assert!(!is_free(&w, &Point2::new(-3.0, 4.0), 0.5, 30.0), "outside");
        assert!(!is_free(&w, &Point2::new(0.3, 4.0), 0.5, 30.0), "near wall");
        assert!(
            !is_free(&w, &Point2::new(3.7, 4.0), 0.5, 30.0),
            "near pillar"
        );
    }

    #[test]
    fn open_polyline_plans_use_enclosure() {
        // Two open "U" shapes that together close a room: no closed polyline.
        let w = world(vec![
            vec![
                Point2::new(5.0, 0.0),
                Point2::new(0.0, 0.0),
                Point2::new(0.0, 4.0),
                Point2::new(5.0, 4.0),
            ],
            vec![
                Point2::new(5.0, 0.0),
                Point2::new(8.0, 0.0),
                Point2::new(8.0, 4.0),
                Point2::new(5.0, 4.0),
            ],
        ]);
        assert!(w.closed_segments().is_empty());
        assert!(is_free(&w, &Point2::new(4.0, 2.0), 0.5, 30.0));
        assert!(!is_free(&w, &Point2::new(4.0, 6.0), 0.5, 30.0));
    }

    #[test]
    fn closed_pillar_inside_open_outer_walls_is_not_free_space() {
        // Outer walls as four open pieces, a closed box inside: the box is solid.
        let c = |x: f64, y: f64| Point2::new(x, y);
        let w = world(vec![
            vec![c(0.0, 0.0), c(10.0, 0.0)],
            vec![c(10.0, 0.0), c(10.0, 8.0)],
            vec![c(10.0, 8.0), c(0.0, 8.0)],
            vec![c(0.0, 8.0), c(0.0, 0.0)],
            square(4.0, 3.0, 6.0, 5.0),
        ]);
        assert!(!w.outline_closed());
        assert!(is_free(&w, &c(2.0, 2.0), 0.5, 30.0));
        assert!(!is_free(&w, &c(5.0, 4.0), 0.5, 30.0), "in the box");
        assert!(!is_free(&w, &c(-3.0, 4.0), 0.5, 30.0), "outside");
        let poses = random_poses(&w, 50, &RandomPoseParams::default(), 1).unwrap();
        assert!(
            poses
                .iter()
                .all(|p| !(4.0..=6.0).contains(&p.x) || !(3.0..=5.0).contains(&p.y))
        );
    }

    #[test]
    fn a_column_built_half_into_a_wall_leaves_the_room_free() {
        // A column across the north wall, drawn from a corner inside the room: the room stays
        // free space (before, the plan counted as open and no pose was found).
        let c = |x: f64, y: f64| Point2::new(x, y);
        let w = world(vec![
            square(0.0, 0.0, 10.0, 8.0),
            vec![
                c(4.0, 7.6),
                c(4.6, 7.6),
                c(4.6, 8.4),
                c(4.0, 8.4),
                c(4.0, 7.6),
            ],
        ]);
        assert!(w.outline_closed());
        assert!(is_free(&w, &c(2.0, 2.0), 0.5, 30.0));
        assert!(
            !is_free(&w, &c(4.3, 8.2), 0.0, 30.0),
            "in the column, outside the room"
        );
        let poses = random_poses(&w, 50, &RandomPoseParams::default(), 1).unwrap();
        assert!(
            poses
                .iter()
                .all(|p| (0.5..=9.5).contains(&p.x) && (0.5..=7.5).contains(&p.y))
        );
    }

    #[test]
    fn nested_and_partitioned_closed_outlines_are_recognised() {
        // A closed building with partitions touching its walls and a pillar: closed.
        assert!(room_with_pillar().outline_closed());
        let c = |x: f64, y: f64| Point2::new(x, y);
        let w = world(vec![
            square(0.0, 0.0, 10.0, 8.0),
            vec![c(3.0, 0.0), c(3.0, 3.0)],
            vec![c(0.0, 5.0), c(10.0, 5.0)],
        ]);
        assert!(w.outline_closed());
        // A closed box with a fence outside it: not an outline of everything.
        let w = world(vec![
            square(0.0, 0.0, 4.0, 4.0),
            vec![c(6.0, 0.0), c(6.0, 4.0)],
        ]);
        assert!(!w.outline_closed());
    }

    #[test]
    fn random_poses_respect_clearance_tilt_and_height() {
        let w = room_with_pillar();
        let params = RandomPoseParams::default();
        let poses = random_poses(&w, 200, &params, 3).unwrap();
        assert_eq!(poses.len(), 200);
        for p in &poses {
            let q = Point2::new(p.x, p.y);
            assert!(is_free(&w, &q, 0.5, 30.0));
            assert!(p.rx.abs() <= params.tilt && p.ry.abs() <= params.tilt);
            assert!(p.rz.abs() <= PI);
            assert_eq!(p.z, 0.45);
        }
        // Uniform: poses on both sides of the pillar.
        assert!(poses.iter().any(|p| p.x < 4.0) && poses.iter().any(|p| p.x > 6.0));
        assert_eq!(poses, random_poses(&w, 200, &params, 3).unwrap());
    }

    #[test]
    fn impossible_clearance_is_a_clear_error() {
        let w = room_with_pillar();
        let params = RandomPoseParams {
            clearance: 5.0,
            max_tries: 500,
            ..RandomPoseParams::default()
        };
        let err = random_poses(&w, 3, &params, 0).unwrap_err();
        assert!(err.to_string().contains("500"), "{err}");
    }
}
