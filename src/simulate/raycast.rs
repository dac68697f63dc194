//! Ray casting against a floor plan: vertical walls, the floor plane z = 0 and an optional
//! ceiling at the wall height (the paper's "simple ray tracer", sect. 7.2.1).
//!
//! Conventions, chosen so that the `hit` labels are consistent ground truth:
//! - A wall is the closed rectangle over its segment from z = 0 to `wall_height`: a ray that
//!   meets it exactly at its top or bottom edge hits the wall. Segments are two-sided.
//! - The floor and the ceiling are unbounded planes, hit from either side.
//! - When a wall and the floor or ceiling are met at the same range (the ray meets the corner
//!   line), the wall wins.
//! - A hit exactly at a segment's end counts; the ends are extended by a relative `END_SLACK` (`plan::segment`)
//!   so a ray through the joint of two segments of a polyline cannot slip between them by
//!   rounding.
//! - A ray that runs exactly along a wall (seen edge-on) hits the wall's nearer end; a ray that
//!   starts on a surface ignores that surface (ranges below `MIN_RANGE` do not count).
//! - A hit farther than the maximum range is no hit.

use crate::plan::Plan;
use crate::plan::Segment;
use crate::plan::grid::SegmentGrid;
use crate::plan::outline::Regions;
use crate::plan::segment::{MIN_RANGE, ray_segment};
use crate::scan::Hit;
use nalgebra::{Point2, Point3, Vector2, Vector3};

/// What a ray met first, and how far along it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RayHit {
    /// Distance from the ray's origin to the hit point \[m\].
    pub range: f64,
    /// The surface hit; never `Hit::Nothing`.
    pub hit: Hit,
}

/// The scene a scanner sees: a plan's walls with a spatial index, the floor and the ceiling.
#[derive(Clone, Debug)]
pub struct World {
    segments: Vec<Segment>,
    /// The closed polylines (first point == last point) as rooms and solids, for the inside
    /// tests of free space.
    regions: Regions,
    wall_height: f64,
    ceiling: bool,
    grid: SegmentGrid,
}

impl World {
    /// Builds the scene of a plan (zero-length wall pieces are skipped).
    pub fn from_plan(plan: &Plan) -> World {
        let mut world = World::from_segments(plan.segments(), plan.wall_height, plan.ceiling);
        world.regions = Regions::of_plan(plan);
        world
    }

    /// Builds a scene from loose wall segments (none of them closed), e.g. for benchmarks.
    pub fn from_segments(segments: Vec<Segment>, wall_height: f64, ceiling: bool) -> World {
        let grid = SegmentGrid::build(&segments);
        World {
            segments,
            regions: Regions::default(),
            wall_height,
            ceiling,
            grid,
        }
    }

    pub fn segments(&self) -> &[Segment] {
        &self.segments
    }

    /// The segments of the closed polylines.
    pub fn closed_segments(&self) -> &[Segment] {
        self.regions.segments()
    }

    /// Each closed polyline's segments, and whether it bounds a solid (a pillar, a box)
    /// rather than a room.
    #[cfg(test)]
    pub(crate) fn closed_polylines(&self) -> impl Iterator<Item = (&[Segment], bool)> {
        self.regions.polylines()
    }

    /// Whether `p` may be free space, clearance and enclosure aside (see [`super::is_free`]).
    pub(crate) fn open_at(&self, p: &Point2<f64>) -> bool {
        self.regions.open_at(p)
    }

    /// Whether some wall comes closer to `p` than `clearance`, through the spatial index.
    pub(crate) fn wall_within(&self, p: &Point2<f64>, clearance: f64) -> bool {
        self.grid.any_near(p, clearance, |s| {
            self.segments[s as usize].distance_to(p) < clearance
        })
    }

    /// Whether the plan's closed polylines outline all of it (see [`super::is_free`]).
    pub fn outline_closed(&self) -> bool {
        self.regions.outline_closed()
    }

    pub fn wall_height(&self) -> f64 {
        self.wall_height
    }

    pub fn has_ceiling(&self) -> bool {
        self.ceiling
    }

    /// The nearest surface along the ray from `origin` in `direction` (any length) within
    /// `max_range` metres, through the spatial index.
    pub fn cast(
        &self,
        origin: &Point3<f64>,
        direction: &Vector3<f64>,
        max_range: f64,
    ) -> Option<RayHit> {
        let d = unit(direction)?;
        let plane = self.cast_planes(origin, &d, max_range);
        let limit = plane.map_or(max_range, |h| h.range);
        let z_ok = |t: f64| self.wall_contains_z(origin.z + t * d.z);
        match self.grid.nearest(&self.segments, origin, &d, limit, z_ok) {
            Some(range) => Some(RayHit {
                range,
                hit: Hit::Wall,
            }),
            None => plane,
        }
    }

    /// The same answer as [`World::cast`] by testing every segment: the reference the spatial
    /// index must agree with (tests and benchmarks).
    pub fn cast_brute_force(
        &self,
        origin: &Point3<f64>,
        direction: &Vector3<f64>,
        max_range: f64,
    ) -> Option<RayHit> {
        let d = unit(direction)?;
        let plane = self.cast_planes(origin, &d, max_range);
        let mut best = plane.map_or(max_range, |h| h.range);
        let mut wall = false;
        let p = Point2::new(origin.x, origin.y);
        let d2 = Vector2::new(d.x, d.y);
        for s in &self.segments {
            if let Some(t) = ray_segment(&p, &d2, s)
                && t <= best
                && self.wall_contains_z(origin.z + t * d.z)
            {
                best = t;
                wall = true;
            }
        }
        if wall {
            Some(RayHit {
                range: best,
                hit: Hit::Wall,
            })
        } else {
            plane
        }
    }

    fn wall_contains_z(&self, z: f64) -> bool {
        (0.0..=self.wall_height).contains(&z)
    }

    /// The floor (z = 0) or, when present, the ceiling (z = wall height), whichever the unit
    /// ray `d` meets first within `max_range`.
    fn cast_planes(
        &self,
        origin: &Point3<f64>,
        d: &Vector3<f64>,
        max_range: f64,
    ) -> Option<RayHit> {
        if d.z == 0.0 {
            return None;
        }
        let mut best: Option<RayHit> = None;
        let mut consider = |plane_z: f64, hit: Hit| {
            let t = (plane_z - origin.z) / d.z;
            if t >= MIN_RANGE && t <= max_range && best.is_none_or(|b| t < b.range) {
                best = Some(RayHit { range: t, hit });
            }
        };
        consider(0.0, Hit::Floor);
        if self.ceiling {
            consider(self.wall_height, Hit::Ceiling);
        }
        best
    }
}

fn unit(v: &Vector3<f64>) -> Option<Vector3<f64>> {
    let n = v.norm();
    (n > 0.0 && n.is_finite()).then(|| v / n)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::segment::seg;
    use proptest::prelude::*;

    fn box_room(w: f64, h: f64, height: f64, ceiling: bool) -> World {
        World::from_plan(&crate::plan::box_plan(w, h, height, ceiling))
    }

    #[test]
    fn level_rays_from_box_centre_hit_walls_at_half_widths() {
        let world = box_room(8.0, 6.0, 3.0, false);
        let o = Point3::new(4.0, 3.0, 0.5);
        for (d, want) in [
            (Vector3::new(1.0, 0.0, 0.0), 4.0),
            (Vector3::new(-1.0, 0.0, 0.0), 4.0),
            (Vector3::new(0.0, 1.0, 0.0), 3.0),
            (Vector3::new(0.0, -1.0, 0.0), 3.0),
        ] {
            let h = world.cast(&o, &d, 30.0).unwrap();
            assert_eq!(h.hit, Hit::Wall);
            assert!((h.range - want).abs() < 1e-12, "{d:?}: {}", h.range);
        }
    }

    #[test]
    fn ray_through_room_corner_does_not_leak() {
        // A 45 degree ray from the centre of a square room meets the corner joint exactly.
        let world = box_room(4.0, 4.0, 3.0, false);
        let o = Point3::new(2.0, 2.0, 1.0);
        for d in [
            Vector3::new(1.0, 1.0, 0.0),
            Vector3::new(-1.0, 1.0, 0.0),
            Vector3::new(-1.0, -1.0, 0.0),
            Vector3::new(1.0, -1.0, 0.0),
        ] {
            let h = world.cast(&o, &d, 30.0).unwrap();
            assert_eq!(h.hit, Hit::Wall);
            assert!((h.range - 8f64.sqrt()).abs() < 1e-12);
        }
    }

    #[test]
    fn hit_exactly_at_free_segment_end_counts() {
        let world = World::from_segments(vec![seg(2.0, -1.0, 2.0, 1.0)], 3.0, false);
        let o = Point3::new(0.0, 0.0, 1.0);
        let h = world.cast(&o, &Vector3::new(2.0, 1.0, 0.0), 30.0).unwrap();
        assert!((h.range - 5f64.sqrt()).abs() < 1e-12);
        // Just past the end: no wall, and a level ray meets no plane either.
        assert!(
            world
                .cast(&o, &Vector3::new(2.0, 1.001, 0.0), 30.0)
                .is_none()
        );
    }

    #[test]
    fn ray_along_a_wall_hits_its_nearer_end() {
        let world = World::from_segments(vec![seg(3.0, 0.0, 5.0, 0.0)], 3.0, false);
        let h = world
            .cast(&Point3::new(0.0, 0.0, 1.0), &Vector3::x(), 30.0)
            .unwrap();
        assert_eq!(h.hit, Hit::Wall);
        assert_eq!(h.range, 3.0);
        // Starting on the wall, a ray along it is not blocked by it.
        assert!(
            world
                .cast(&Point3::new(4.0, 0.0, 1.0), &Vector3::x(), 30.0)
                .is_none()
        );
    }

    #[test]
    fn wall_top_edge_is_part_of_the_wall_and_above_it_is_not() {
        // Ray from z = 1 rising to meet the wall 4 m away exactly at its top (z = 3).
        let world = World::from_segments(vec![seg(4.0, -5.0, 4.0, 5.0)], 3.0, false);
        let o = Point3::new(0.0, 0.0, 1.0);
        let h = world.cast(&o, &Vector3::new(4.0, 0.0, 2.0), 30.0).unwrap();
        assert_eq!(h.hit, Hit::Wall);
        assert!((h.range - 20f64.sqrt()).abs() < 1e-12);
        assert!(
            world
                .cast(&o, &Vector3::new(4.0, 0.0, 2.01), 30.0)
                .is_none()
        );
    }

    #[test]
    fn wall_base_beats_floor_on_a_tie_and_floor_wins_before_the_wall() {
        // Descending from z = 1 to meet the floor exactly at the wall's foot, 4 m away.
        let world = World::from_segments(vec![seg(4.0, -5.0, 4.0, 5.0)], 3.0, false);
        let o = Point3::new(0.0, 0.0, 1.0);
        let h = world.cast(&o, &Vector3::new(4.0, 0.0, -1.0), 30.0).unwrap();
        assert_eq!(h.hit, Hit::Wall);
        let h = world
            .cast(&o, &Vector3::new(4.0, 0.0, -1.01), 30.0)
            .unwrap();
        assert_eq!(h.hit, Hit::Floor);
    }

    #[test]
    fn vertical_rays_meet_floor_and_ceiling() {
        let world = box_room(4.0, 4.0, 2.4, true);
        let o = Point3::new(2.0, 2.0, 0.5);
        let down = world.cast(&o, &-Vector3::z(), 30.0).unwrap();
        assert_eq!((down.hit, down.range), (Hit::Floor, 0.5));
        let up = world.cast(&o, &Vector3::z(), 30.0).unwrap();
        assert_eq!(up.hit, Hit::Ceiling);
        assert!((up.range - 1.9).abs() < 1e-12);
        let open = box_room(4.0, 4.0, 2.4, false);
        assert!(open.cast(&o, &Vector3::z(), 30.0).is_none());
    }

    #[test]
    fn hits_beyond_max_range_are_no_hits() {
        let world = box_room(8.0, 6.0, 3.0, false);
        let o = Point3::new(4.0, 3.0, 0.5);
        assert!(world.cast(&o, &Vector3::x(), 3.9).is_none());
        assert!(world.cast(&o, &Vector3::x(), 4.0).is_some());
    }

    #[test]
    fn rays_from_outside_the_grid_enter_it() {
        let world = box_room(8.0, 6.0, 3.0, false);
        let h = world
            .cast(&Point3::new(-10.0, 3.0, 1.0), &Vector3::x(), 30.0)
            .unwrap();
        assert!((h.range - 10.0).abs() < 1e-12);
        assert!(
            world
                .cast(&Point3::new(-10.0, 3.0, 1.0), &-Vector3::x(), 30.0)
                .is_none()
        );
    }

    #[test]
    fn empty_world_sees_only_the_floor() {
        let world = World::from_segments(vec![], 3.0, false);
        let o = Point3::new(0.0, 0.0, 1.0);
        assert!(world.cast(&o, &Vector3::x(), 30.0).is_none());
        let h = world.cast(&o, &Vector3::new(1.0, 0.0, -1.0), 30.0).unwrap();
        assert_eq!(h.hit, Hit::Floor);
        assert!((h.range - 2f64.sqrt()).abs() < 1e-12);
    }

    fn arb_segment(span: f64, max_len: f64) -> impl Strategy<Value = Segment> {
        (
            -span..span,
            -span..span,
            0.0..std::f64::consts::TAU,
            0.01..max_len,
        )
            .prop_map(|(x, y, a, l)| seg(x, y, x + l * a.cos(), y + l * a.sin()))
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        #[test]
        fn grid_cast_matches_brute_force(
            segments in prop::collection::vec(arb_segment(20.0, 8.0), 1..300),
            rays in prop::collection::vec(
                ((-25.0f64..25.0, -25.0f64..25.0, 0.0f64..3.5),
                 (0.0..std::f64::consts::TAU, -1.2f64..1.2)),
                16),
            ceiling in any::<bool>(),
        ) {
            let world = World::from_segments(segments, 3.0, ceiling);
            for ((x, y, z), (az, el)) in rays {
                let o = Point3::new(x, y, z);
                let d = Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
                let fast = world.cast(&o, &d, 30.0);
                let slow = world.cast_brute_force(&o, &d, 30.0);
                match (fast, slow) {
                    (None, None) => {}
                    (Some(f), Some(s)) => {
                        prop_assert_eq!(f.hit, s.hit);
                        prop_assert!((f.range - s.range).abs() < 1e-9, "{f:?} vs {s:?}");
                    }
                    _ => prop_assert!(false, "grid {fast:?} vs brute force {slow:?}"),
                }
            }
        }

        #[test]
        fn grid_cast_matches_brute_force_on_axis_aligned_grids(
            n in 1usize..12,
            ox in -1.0f64..1.0, oy in -1.0f64..1.0,
            az_steps in 0u32..16,
        ) {
            // Walls on a lattice and rays along lattice directions: exact ties and joints.
            let mut segments = Vec::new();
            for i in 0..=n {
                let c = i as f64;
                segments.push(seg(c, 0.0, c, n as f64));
                segments.push(seg(0.0, c, n as f64, c));
            }
            let world = World::from_segments(segments, 3.0, false);
            let o = Point3::new(n as f64 / 2.0 + ox * 0.5, n as f64 / 2.0 + oy * 0.5, 1.0);
            let az = az_steps as f64 * std::f64::consts::FRAC_PI_8;
            let d = Vector3::new(az.cos(), az.sin(), 0.0);
            let fast = world.cast(&o, &d, 30.0).map(|h| h.range);
            let slow = world.cast_brute_force(&o, &d, 30.0).map(|h| h.range);
            prop_assert_eq!(fast.is_some(), slow.is_some());
            if let (Some(f), Some(s)) = (fast, slow) {
                prop_assert!((f - s).abs() < 1e-9);
            }
        }
    }
}
