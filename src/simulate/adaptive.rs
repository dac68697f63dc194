//! The adaptive robot, the paper's "cleverRobot" (sect. 7.2.2): after taking its scans at a
//! pose it levels them with what a robot knows (the scans themselves, never `true_pose` or
//! `hit`), and when the estimate is possibly poor (sect. 7.2.2) it takes more scans at other
//! elevations, up to a limit: tilted the other way when too few wall polygons were found because
//! the scanner faces the floor or the ceiling (sect. 5.5); away from the floor (or the ceiling,
//! whichever it saw more of) when the walls seen could not pin the attitude down. Scans added
//! above or below the first set widen the vertical span the wall polygons cover, and so
//! sharpen their normals even on the same walls.

use super::raycast::World;
use super::scanner::{ScannerParams, simulate_pose};
use crate::geometry::Pose;
use crate::level::{FailReason, LevelEstimate, LevelParams, SurfaceKind, level_pose};
use crate::scan::Scan;
use rand::Rng;
use serde_json::json;

/// Parameters of the adaptive robot.
#[derive(Clone, Debug, PartialEq)]
pub struct AdaptiveParams {
    /// Retakes allowed per pose after the first set of scans. Default 2.
    pub max_retakes: usize,
    /// How far each retake shifts the elevations \[rad\]; the direction comes from the failure
    /// (facing the floor: tilt up, i.e. negative; facing the ceiling: positive). Default 0:
    /// the span of the elevation set plus one step, so a retake adds new elevations next to
    /// the old ones.
    pub shift: f64,
    /// Leveling used to judge the scans.
    pub level: LevelParams,
}

impl Default for AdaptiveParams {
    fn default() -> Self {
        Self {
            max_retakes: 2,
            shift: 0.0,
            level: LevelParams::default(),
        }
    }
}

/// The shift that moves a set of elevations just past itself: its span plus one step (for a
/// single elevation, 5 degrees).
fn default_shift(elevations: &[f64]) -> f64 {
    let lo = elevations.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = elevations.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let step = if elevations.len() > 1 {
        (hi - lo) / (elevations.len() - 1) as f64
    } else {
        5f64.to_radians()
    };
    (hi - lo) + step
}

/// Scans at one pose the way cleverRobot takes them. Every scan keeps the pose's `sequence`
/// and gets `"adaptive": {"attempt": k, "shift": rad}` (attempt 0 is the first set, shift its
/// offset from the requested elevations). Retakes stop as soon as the pose levels, or fails for
/// a reason a retake cannot cure (too few or inconsistent scans). A pose that levels (from the
/// floor) while facing the floor is retaken too: its pseudo-level scan needs walls.
pub fn simulate_pose_adaptive<R: Rng + ?Sized>(
    world: &World,
    sequence: u64,
    world_from_robot: &Pose,
    elevations: &[f64],
    scanner: &ScannerParams,
    params: &AdaptiveParams,
    rng: &mut R,
) -> Vec<Scan> {
    let step = if params.shift > 0.0 {
        params.shift
    } else {
        default_shift(elevations)
    };
    let mut all: Vec<Scan> = Vec::new();
    let mut offset = 0.0;
    for attempt in 0..=params.max_retakes {
        let shifted: Vec<f64> = elevations.iter().map(|e| e + offset).collect();
        let mut scans = simulate_pose(world, sequence, world_from_robot, &shifted, scanner, rng);
        for s in &mut scans {
            s.extra.insert(
                "adaptive".to_string(),
                json!({"attempt": attempt, "shift": offset}),
            );
        }
        all.extend(scans);
        if attempt == params.max_retakes {
            break;
        }
        // Judge with what the robot has: its scans, stripped of the simulator's truth.
        let seen: Vec<Scan> = all.iter().map(robot_view).collect();
        offset = match retake_direction(&level_pose(&seen, &params.level)) {
            // Positive elevation tilts the beams down: facing the floor, look up.
            Some(FailReason::FacingFloor) => offset.min(0.0) - step,
            Some(FailReason::FacingCeiling) => offset.max(0.0) + step,
            _ => break,
        };
    }
    all
}

/// Which way a retake should look, as the surface to look away from (`FacingFloor`: look up,
/// `FacingCeiling`: look down); `None` when no retake is needed or none can help.
fn retake_direction(est: &LevelEstimate) -> Option<FailReason> {
    let away = || {
        let count = |k: SurfaceKind| est.quads.iter().filter(|q| q.kind == k).count();
        est.facing()
            .unwrap_or(if count(SurfaceKind::Ceiling) > count(SurfaceKind::Floor) {
                FailReason::FacingCeiling
            } else {
                FailReason::FacingFloor
            })
    };
    match est.failure {
        None if few_wall_points(est) => Some(away()),
        None => est.facing(),
        Some(FailReason::TooFewScans | FailReason::InconsistentScans) => None,
        Some(f @ (FailReason::FacingFloor | FailReason::FacingCeiling)) => Some(f),
        Some(FailReason::TooFewPolygons | FailReason::ParallelWalls) => Some(away()),
    }
}

/// Whether fewer than half of the base scan's returns lie on the wall polygons and patches
/// the pose was leveled from: it levels, but from a small part of what it saw (a robot
/// pitched at the floor in a doorway), and its pseudo-level scan is thin. Measured on the
/// example plans' tilted runs (eval matching, seeds 1-3): leveled pairwise ATE at most 2.1 cm,
/// against up to 11.7 cm without these retakes.
pub fn few_wall_points(est: &LevelEstimate) -> bool {
    let (Some(grid), Some(base)) = (&est.grid, est.base_scan) else {
        return false;
    };
    let Some(row) = grid.scan_index.iter().position(|&s| s == base) else {
        return false;
    };
    let cells = row * grid.cols..(row + 1) * grid.cols;
    let returns = grid.points[cells.clone()].iter().flatten().count();
    let on_walls = est.wall_mask[cells].iter().filter(|&&w| w).count();
    2 * on_walls < returns
}

/// A scan as the robot knows it: without the simulator's `true_pose` and `hit`.
fn robot_view(s: &Scan) -> Scan {
    Scan {
        true_pose: None,
        hit: None,
        ..s.clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::Plan;
    use crate::simulate::elevations_centred;
    use nalgebra::Point2;
    use rand::SeedableRng;

    /// Closed polygons of walls 3 m high, no ceiling.
    fn walled(polygons: &[&[[f64; 2]]]) -> World {
        let closed = |poly: &[[f64; 2]]| -> Vec<Point2<f64>> {
            poly.iter()
                .chain(poly.first())
                .map(|&[x, y]| Point2::new(x, y))
                .collect()
        };
        World::from_plan(&Plan {
            wall_height: 3.0,
            walls: polygons.iter().map(|poly| closed(poly)).collect(),
            ceiling: false,
            poses: vec![],
        })
    }

    fn big_room() -> World {
        walled(&[&[[0.0, 0.0], [12.0, 0.0], [12.0, 12.0], [0.0, 12.0]]])
    }

    /// Three scans 5 degrees apart centred on level, as the robot takes them first.
    fn elevations() -> Vec<f64> {
        elevations_centred(3, 5f64.to_radians())
    }

    /// One set of scans at `pose`, and the scans cleverRobot takes there with `level`, both
    /// from the same seed (so its first set is the plain one).
    fn plain_and_adaptive(
        world: &World,
        sequence: u64,
        pose: &Pose,
        seed: u64,
        level: LevelParams,
    ) -> (Vec<Scan>, Vec<Scan>) {
        let scanner = ScannerParams::default();
        let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(seed);
        let plain = simulate_pose(world, sequence, pose, &elevations(), &scanner, &mut rng);
        let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(seed);
        let params = AdaptiveParams {
            level,
            ..AdaptiveParams::default()
        };
        let adaptive = simulate_pose_adaptive(
            world,
            sequence,
            pose,
            &elevations(),
            &scanner,
            &params,
            &mut rng,
        );
        (plain, adaptive)
    }

    /// The attitude error of leveling `scans` \[deg\]; the pose must level.
    fn leveled_error_deg(scans: &[Scan], pose: &Pose) -> f64 {
        let est = level_pose(scans, &LevelParams::default());
        assert!(est.is_ok(), "{:?}", est.failure);
        est.attitude
            .unwrap()
            .max_abs_error(&pose.attitude())
            .to_degrees()
    }

    #[test]
    fn a_robot_pitched_at_the_floor_retakes_looking_up_and_levels() {
        let pose = Pose::new(6.0, 6.0, 0.45, 0.3, 25f64.to_radians(), 3f64.to_radians());
        let (plain, scans) = plain_and_adaptive(&big_room(), 4, &pose, 3, LevelParams::default());
        let first = level_pose(&plain, &LevelParams::default());
        assert_eq!(first.facing(), Some(FailReason::FacingFloor));
        assert!(scans.len() > 3, "no retake");
        assert!(scans.iter().all(|s| s.sequence == Some(4)));
        let last = &scans[scans.len() - 1];
        assert!(
            last.elevation.unwrap() < elevations()[0],
            "the retake looks up"
        );
        assert!(last.extra["adaptive"]["attempt"].as_u64().unwrap() >= 1);
        assert!(last.extra["adaptive"]["shift"].as_f64().unwrap() < 0.0);
        let err = leveled_error_deg(&scans, &pose);
        assert!(err < 1.0, "{err}");
    }

    #[test]
    fn a_robot_between_parallel_walls_retakes_until_it_sees_the_end_wall() {
        // A corridor 20 m long, pitched 8 degrees down: its first scans see the two side walls
        // (parallel) and meet the floor before the end wall 10 m ahead.
        let world = walled(&[&[[0.0, 0.0], [20.0, 0.0], [20.0, 3.0], [0.0, 3.0]]]);
        let pose = Pose::new(10.0, 1.5, 0.45, 0.0, 8f64.to_radians(), 0.0);
        // Walls only, as the paper's cleverRobot: with the floor taken as level the floor
        // alone levels this pose and no retake is needed.
        let walls_only = LevelParams {
            level_surfaces: false,
            ..LevelParams::default()
        };
        let (plain, scans) = plain_and_adaptive(&world, 0, &pose, 5, walls_only.clone());
        let first = level_pose(&plain, &walls_only);
        assert_eq!(first.failure, Some(FailReason::ParallelWalls));
        assert!(level_pose(&plain, &LevelParams::default()).is_ok());
        assert!(scans.len() > 3, "no retake");
        assert!(
            scans[3].elevation.unwrap() < elevations()[0],
            "the retake looks up"
        );
        let err = leveled_error_deg(&scans, &pose);
        assert!(err < 0.5, "{err}");
    }

    #[test]
    fn a_pose_leveled_from_few_of_its_points_is_retaken() {
        // 8 degrees towards the floor in a 12 m room: a pillar 1.5 m ahead levels the pose,
        // while most of every scan meets the floor or walls only one scan reaches.
        let world = walled(&[
            &[[0.0, 0.0], [12.0, 0.0], [12.0, 12.0], [0.0, 12.0]],
            &[[7.3, 5.7], [7.9, 6.0], [7.6, 6.6], [7.0, 6.3]],
        ]);
        let pose = Pose::new(6.0, 6.0, 0.45, 0.0, 8f64.to_radians(), 2f64.to_radians());
        let (plain, scans) = plain_and_adaptive(&world, 0, &pose, 2, LevelParams::default());
        let first = level_pose(&plain, &LevelParams::default());
        assert!(first.is_ok(), "{:?}", first.failure);
        assert!(few_wall_points(&first));
        assert!(scans.len() > 3, "no retake");
        assert!(
            scans[3].elevation.unwrap() < elevations()[0],
            "the retake looks up"
        );
        let est = level_pose(&scans, &LevelParams::default());
        assert!(est.is_ok(), "{:?}", est.failure);
    }

    #[test]
    fn a_pose_that_levels_first_time_is_not_retaken() {
        let pose = Pose::new(3.0, 3.0, 0.45, 0.8, 0.05, -0.05);
        let (_, scans) = plain_and_adaptive(&big_room(), 0, &pose, 1, LevelParams::default());
        assert_eq!(scans.len(), 3);
        assert!(scans.iter().all(|s| s.extra["adaptive"]["attempt"] == 0));
    }
}
