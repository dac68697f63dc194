//! A plan's closed polylines and the inside tests on them, behind free space
//! (`simulate::is_free`).
//!
//! Plans are sets of polylines, not always closed. A closed polyline (first point == last,
//! at least 3 points) bounds a region, and a point is inside it when the ray from the point
//! towards +x crosses it an odd number of times. A closed polyline bounds either a room (free
//! space inside) or a solid (a pillar, a box: none inside): it is solid when one of its corners
//! lies strictly inside a larger closed polyline, as a pillar stands in its room, also when it
//! is half built into the room's wall. The plan's outline is closed when it has rooms and every
//! open wall lies within (or on) them: the plan is a closed building.
//!
//! Every test goes through the grid index ([`super::grid`]), so that a plan of many segments
//! (long runs of collinear pieces, thousands of pillars) costs about linear time, not the
//! square of its size; the brute-force twins in the tests must agree exactly.

use super::grid::SegmentGrid;
use super::segment::Segment;
use super::{Plan, wall_pieces};
use nalgebra::Point2;

/// Distance within which a point lies on a polyline \[m\].
const ON_POLYLINE: f64 = 1e-9;

/// Polylines' segments, indexed, each segment knowing which polyline it belongs to.
#[derive(Clone, Debug, Default)]
pub(crate) struct Polylines {
    segments: Vec<Segment>,
    /// The polyline of each segment.
    owner: Vec<u32>,
    /// The first segment of each polyline.
    starts: Vec<usize>,
    grid: SegmentGrid,
}

impl Polylines {
    /// Indexes the polylines, given as their (non-empty) lists of segments.
    pub(crate) fn new(polylines: impl IntoIterator<Item = Vec<Segment>>) -> Polylines {
        let mut p = Polylines::default();
        for (k, segments) in polylines.into_iter().enumerate() {
            p.starts.push(p.segments.len());
            p.owner
                .extend(std::iter::repeat_n(k as u32, segments.len()));
            p.segments.extend(segments);
        }
        p.grid = SegmentGrid::build(&p.segments);
        p
    }

    pub(crate) fn segments(&self) -> &[Segment] {
        &self.segments
    }

    fn len(&self) -> usize {
        self.starts.len()
    }

    fn polyline(&self, k: usize) -> &[Segment] {
        let end = self
            .starts
            .get(k + 1)
            .copied()
            .unwrap_or(self.segments.len());
        &self.segments[self.starts[k]..end]
    }

    /// Whether the ray from `p` towards +x crosses the polylines an odd number of times in
    /// all: `p` is inside an odd number of them (the index's crossings, tested).
    #[cfg(test)]
    fn odd_crossings(&self, p: &Point2<f64>) -> bool {
        let mut odd = false;
        self.grid
            .for_each_crossing(&self.segments, p, |_| odd = !odd);
        odd
    }

    /// The polylines that the ray from `p` towards +x crosses an odd number of times (those
    /// that hold `p`, unless it lies on them), in order.
    fn odd_polylines(&self, p: &Point2<f64>) -> Vec<u32> {
        let mut crossed = Vec::new();
        self.grid
            .for_each_crossing(&self.segments, p, |s| crossed.push(self.owner[s as usize]));
        crossed.sort_unstable();
        let mut odd = Vec::new();
        for run in crossed.chunk_by(|a, b| a == b) {
            if run.len() % 2 == 1 {
                odd.push(run[0]);
            }
        }
        odd
    }

    /// Whether `p` lies on polyline `k` (within [`ON_POLYLINE`]), or on any when `None`.
    fn on(&self, k: Option<u32>, p: &Point2<f64>) -> bool {
        self.grid.any_near(p, ON_POLYLINE, |s| {
            k.is_none_or(|k| self.owner[s as usize] == k)
                && self.segments[s as usize].distance_to(p) <= ON_POLYLINE
        })
    }
}

/// Whether a wall is a closed polyline: at least 3 points, the first the last.
fn is_closed(wall: &[Point2<f64>]) -> bool {
    wall.len() >= 3 && wall.first() == wall.last()
}

/// The closed polylines of a plan (first point == last point, at least 3 points), as
/// segments (zero-length pieces skipped); a closed polyline of one point repeated has no
/// segment and is left out.
pub(crate) fn closed_polylines(plan: &Plan) -> Vec<Vec<Segment>> {
    plan.walls
        .iter()
        .filter(|w| is_closed(w))
        .map(|w| wall_pieces(w).collect::<Vec<_>>())
        .filter(|segments| !segments.is_empty())
        .collect()
}

/// The area a closed polyline encloses \[m²\] (the shoelace formula, unsigned).
fn area(polyline: &[Segment]) -> f64 {
    polyline
        .iter()
        .map(|s| s.a.x * s.b.y - s.b.x * s.a.y)
        .sum::<f64>()
        .abs()
        / 2.0
}

/// What a plan's closed polylines bound: rooms, with free space inside, or solids (pillars,
/// boxes), with none; and whether the rooms outline the whole plan.
#[derive(Clone, Debug, Default)]
pub(crate) struct Regions {
    closed: Polylines,
    /// Per closed polyline, in [`closed_polylines`]' order: whether it bounds a solid.
    solid: Vec<bool>,
    outline_closed: bool,
}

impl Regions {
    pub(crate) fn of_plan(plan: &Plan) -> Regions {
        let closed = Polylines::new(closed_polylines(plan));
        let solid = solids(&closed);
        let rooms = Polylines::new(
            (0..closed.len())
                .filter(|&k| !solid[k])
                .map(|k| closed.polyline(k).to_vec()),
        );
        // Every open wall within (or on) a room; the closed ones are rooms themselves or
        // solids, which may stand half outside the room that holds them.
        let outline_closed = rooms.len() > 0
            && plan
                .walls
                .iter()
                .filter(|w| !is_closed(w))
                .flat_map(|w| wall_pieces(w))
                .all(|s| {
                    let mid = nalgebra::center(&s.a, &s.b);
                    rooms.on(None, &mid) || !rooms.odd_polylines(&mid).is_empty()
                });
        Regions {
            closed,
            solid,
            outline_closed,
        }
    }

    /// The closed polylines' segments.
    pub(crate) fn segments(&self) -> &[Segment] {
        self.closed.segments()
    }

    /// Each closed polyline's segments, and whether it bounds a solid.
    #[cfg(test)]
    pub(crate) fn polylines(&self) -> impl Iterator<Item = (&[Segment], bool)> {
        (0..self.closed.len()).map(|k| (self.closed.polyline(k), self.solid[k]))
    }

    /// True when the plan has rooms and every open wall lies within (or on) them: the plan is
    /// a closed building.
    pub(crate) fn outline_closed(&self) -> bool {
        self.outline_closed
    }

    /// Whether `p` may be free space, clearance and enclosure aside: inside no solid and, in a
    /// closed building, inside a room; where the rooms do not outline the plan (open outer
    /// walls), inside no closed polyline at all.
    pub(crate) fn open_at(&self, p: &Point2<f64>) -> bool {
        let holders = self.closed.odd_polylines(p);
        if self.outline_closed {
            !holders.is_empty() && holders.iter().all(|&k| !self.solid[k as usize])
        } else {
            holders.is_empty()
        }
    }
}

/// Per closed polyline: whether one of its corners lies strictly inside a larger one (a
/// pillar in its room, or half built into the room's wall). The largest polylines have no
/// larger one to stand in and are not tested, so a building's long outline costs nothing.
fn solids(closed: &Polylines) -> Vec<bool> {
    let areas: Vec<f64> = (0..closed.len())
        .map(|k| area(closed.polyline(k)))
        .collect();
    let largest = areas.iter().copied().fold(0.0, f64::max);
    (0..closed.len())
        .map(|i| {
            areas[i] < largest
                && closed.polyline(i).iter().any(|s| {
                    closed.odd_polylines(&s.a).into_iter().any(|j| {
                        let j = j as usize;
                        j != i && areas[j] > areas[i] && !closed.on(Some(j as u32), &s.a)
                    })
                })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::segment::crossing_x;
    use proptest::prelude::*;

    /// Crossing parity by testing every segment: the twin of [`Polylines::odd_crossings`].
    fn odd_crossings_brute(segments: &[Segment], p: &Point2<f64>) -> bool {
        segments
            .iter()
            .filter(|s| crossing_x(s, p).is_some())
            .count()
            % 2
            == 1
    }

    fn on_brute(segments: &[Segment], p: &Point2<f64>) -> bool {
        segments.iter().any(|s| s.distance_to(p) <= ON_POLYLINE)
    }

    /// [`Regions::of_plan`] by testing every segment against every polyline: which closed
    /// polylines are solid, and whether the outline is closed.
    fn regions_brute(plan: &Plan) -> (Vec<bool>, bool) {
        let closed = closed_polylines(plan);
        let areas: Vec<f64> = closed.iter().map(|c| area(c)).collect();
        let solid: Vec<bool> = (0..closed.len())
            .map(|i| {
                closed[i].iter().any(|s| {
                    (0..closed.len()).any(|j| {
                        j != i
                            && areas[j] > areas[i]
                            && odd_crossings_brute(&closed[j], &s.a)
                            && !on_brute(&closed[j], &s.a)
                    })
                })
            })
            .collect();
        let rooms: Vec<&Vec<Segment>> = (0..closed.len())
            .filter(|&k| !solid[k])
            .map(|k| &closed[k])
            .collect();
        let open: Vec<Segment> = plan
            .walls
            .iter()
            .filter(|w| !is_closed(w))
            .flat_map(|w| wall_pieces(w))
            .collect();
        let outline_closed = !rooms.is_empty()
            && open.iter().all(|s| {
                let mid = nalgebra::center(&s.a, &s.b);
                rooms
                    .iter()
                    .any(|o| on_brute(o, &mid) || odd_crossings_brute(o, &mid))
            });
        (solid, outline_closed)
    }

    /// [`Regions::open_at`] by testing every segment.
    fn open_at_brute(plan: &Plan, p: &Point2<f64>) -> bool {
        let closed = closed_polylines(plan);
        let (solid, outline_closed) = regions_brute(plan);
        let holders: Vec<usize> = (0..closed.len())
            .filter(|&k| odd_crossings_brute(&closed[k], p))
            .collect();
        if outline_closed {
            !holders.is_empty() && holders.iter().all(|&k| !solid[k])
        } else {
            holders.is_empty()
        }
    }

    fn outline_is_closed(plan: &Plan) -> bool {
        Regions::of_plan(plan).outline_closed()
    }

    fn square(x0: f64, y0: f64, x1: f64, y1: f64) -> Vec<Point2<f64>> {
        [(x0, y0), (x1, y0), (x1, y1), (x0, y1), (x0, y0)]
            .map(|(x, y)| Point2::new(x, y))
            .to_vec()
    }

    fn plan(walls: Vec<Vec<Point2<f64>>>) -> Plan {
        Plan {
            wall_height: 3.0,
            walls,
            ceiling: false,
            poses: vec![],
        }
    }

    #[test]
    fn a_closed_wall_of_one_repeated_point_is_no_polyline() {
        let p = Point2::new(5.0, 5.0);
        let mut walls = vec![square(0.0, 0.0, 10.0, 8.0), vec![p, p, p]];
        assert_eq!(closed_polylines(&plan(walls.clone())).len(), 1);
        assert!(outline_is_closed(&plan(walls.clone())));
        walls.remove(0);
        assert!(!outline_is_closed(&plan(walls)));
    }

    #[test]
    fn a_pillar_built_half_into_a_wall_is_solid_and_the_room_stays_free() {
        // A 10 x 8 m room; two columns across its north wall, one drawn from a corner inside
        // the room, one from a corner outside it; two boxes that overlap inside the room.
        let c = |x: f64, y: f64| Point2::new(x, y);
        let walls = vec![
            square(0.0, 0.0, 10.0, 8.0),
            vec![
                c(4.0, 7.6),
                c(4.6, 7.6),
                c(4.6, 8.4),
                c(4.0, 8.4),
                c(4.0, 7.6),
            ],
            vec![
                c(1.0, 8.4),
                c(1.0, 7.6),
                c(1.6, 7.6),
                c(1.6, 8.4),
                c(1.0, 8.4),
            ],
            square(6.0, 2.0, 8.0, 4.0),
            square(7.0, 3.0, 9.0, 5.0),
        ];
        let regions = Regions::of_plan(&plan(walls));
        assert_eq!(regions.solid, vec![false, true, true, true, true]);
        assert!(regions.outline_closed());
        assert!(regions.open_at(&c(2.0, 2.0)), "in the room");
        assert!(
            !regions.open_at(&c(4.3, 7.8)),
            "in the column, inside the room"
        );
        assert!(
            !regions.open_at(&c(4.3, 8.2)),
            "in the column, outside the room"
        );
        assert!(!regions.open_at(&c(7.5, 3.5)), "where the boxes overlap");
        assert!(!regions.open_at(&c(6.5, 2.5)), "in one box");
        assert!(!regions.open_at(&c(12.0, 4.0)), "outside");
        // Two rooms side by side, sharing a wall: both rooms.
        let two = plan(vec![
            square(0.0, 0.0, 5.0, 4.0),
            square(5.0, 0.0, 12.0, 4.0),
        ]);
        let regions = Regions::of_plan(&two);
        assert_eq!(regions.solid, vec![false, false]);
        assert!(regions.open_at(&c(2.0, 2.0)) && regions.open_at(&c(8.0, 2.0)));
    }

    #[test]
    fn long_collinear_runs_and_many_pillars() {
        // 64,000 collinear pieces in one closed outline, and 10,000 pillars: the brute force
        // would take minutes here (the square of the segment count), the index milliseconds.
        let n = 64_000;
        let mut outline: Vec<Point2<f64>> = (0..=n)
            .map(|i| Point2::new(100.0 * i as f64 / n as f64, 0.0))
            .collect();
        outline.extend([(100.0, 100.0), (0.0, 100.0), (0.0, 0.0)].map(|(x, y)| Point2::new(x, y)));
        let mut walls = vec![outline];
        for k in 0..10_000 {
            let (x, y) = (1.0 + (k % 100) as f64 * 0.98, 1.0 + (k / 100) as f64 * 0.98);
            walls.push(square(x, y, x + 0.5, y + 0.5));
        }
        assert!(outline_is_closed(&plan(walls.clone())));
        // A fence outside the building: no longer an outline of everything.
        walls.push(vec![Point2::new(-5.0, 0.0), Point2::new(-5.0, 50.0)]);
        assert!(!outline_is_closed(&plan(walls)));
    }

    fn arb_walls() -> impl Strategy<Value = Vec<Vec<Point2<f64>>>> {
        // Coordinates on a coarse lattice, so that joints, collinear runs, repeated points
        // and exact ties are common.
        let point = (0i32..9, 0i32..9).prop_map(|(x, y)| Point2::new(x as f64, y as f64));
        let open = prop::collection::vec(point.clone(), 2..7);
        let closed = prop::collection::vec(point, 2..7).prop_map(|mut w| {
            w.push(w[0]);
            w
        });
        let boxed = (0i32..8, 0i32..8, 1i32..9, 1i32..9)
            .prop_map(|(x, y, w, h)| square(x as f64, y as f64, (x + w) as f64, (y + h) as f64));
        prop::collection::vec(prop_oneof![open, closed, boxed], 0..8)
    }

    proptest! {
        #[test]
        fn indexed_inside_tests_match_brute_force(
            walls in arb_walls(),
            probes in prop::collection::vec((0i32..37, 0i32..37), 8),
        ) {
            let plan = plan(walls);
            let regions = Regions::of_plan(&plan);
            let (solid, outline_closed) = regions_brute(&plan);
            prop_assert_eq!(regions.outline_closed(), outline_closed);
            prop_assert_eq!(&regions.solid, &solid);
            let closed = closed_polylines(&plan);
            let flat: Vec<Segment> = closed.iter().flatten().copied().collect();
            let index = Polylines::new(closed);
            for (x, y) in probes {
                // Quarter steps: on lattice points and lines, and between them.
                let p = Point2::new(x as f64 / 4.0, y as f64 / 4.0);
                prop_assert_eq!(index.odd_crossings(&p), odd_crossings_brute(&flat, &p));
                prop_assert_eq!(index.on(None, &p), on_brute(&flat, &p));
                prop_assert_eq!(regions.open_at(&p), open_at_brute(&plan, &p));
            }
        }
    }
}
