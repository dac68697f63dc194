//! A plan's closed polylines and the inside tests on them, behind free space
//! (`simulate::is_free`).
//!
//! Plans are sets of polylines, not always closed. A closed polyline (first point == last,
//! at least 3 points) bounds a region, and a point is inside it when the ray from the point
//! towards +x crosses it an odd number of times. The plan's outline is closed when every wall
//! piece lies within (or on) the outermost closed polylines: the plan is a closed building.
//!
//! Every test goes through the grid index ([`super::grid`]), so that a plan of many segments
//! (long runs of collinear pieces, thousands of pillars) costs about linear time, not the
//! square of its size; the brute-force twins in the tests must agree exactly.

use super::Plan;
use super::grid::SegmentGrid;
use super::segment::Segment;
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
    /// all: `p` is inside an odd number of them.
    pub(crate) fn odd_crossings(&self, p: &Point2<f64>) -> bool {
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

/// The closed polylines of a plan (first point == last point, at least 3 points), as
/// segments (zero-length pieces skipped); a closed polyline of one point repeated has no
/// segment and is left out.
pub(crate) fn closed_polylines(plan: &Plan) -> Vec<Vec<Segment>> {
    plan.walls
        .iter()
        .filter(|w| w.len() >= 3 && w.first() == w.last())
        .map(|w| {
            w.windows(2)
                .map(|p| Segment { a: p[0], b: p[1] })
                .filter(|s| s.length() > 0.0)
                .collect::<Vec<_>>()
        })
        .filter(|segments| !segments.is_empty())
        .collect()
}

/// True when the plan has closed polylines and every wall piece lies within (or on) the
/// outermost of them: the plan is a closed building. A closed polyline is outermost when its
/// first point is not strictly inside another one.
pub(crate) fn outline_is_closed(plan: &Plan) -> bool {
    let closed = Polylines::new(closed_polylines(plan));
    let outer: Vec<Vec<Segment>> = (0..closed.len())
        .filter(|&i| {
            let first = closed.polyline(i)[0].a;
            !closed
                .odd_polylines(&first)
                .into_iter()
                .any(|j| j as usize != i && !closed.on(Some(j), &first))
        })
        .map(|i| closed.polyline(i).to_vec())
        .collect();
    if outer.is_empty() {
        return false;
    }
    let outer = Polylines::new(outer);
    plan.segments().iter().all(|s| {
        let mid = nalgebra::center(&s.a, &s.b);
        outer.on(None, &mid) || !outer.odd_polylines(&mid).is_empty()
    })
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

    /// [`outline_is_closed`] by testing every segment against every polyline.
    fn outline_is_closed_brute(plan: &Plan) -> bool {
        let closed = closed_polylines(plan);
        let outer: Vec<&Vec<Segment>> = closed
            .iter()
            .enumerate()
            .filter(|(i, c)| {
                let first = c[0].a;
                !closed
                    .iter()
                    .enumerate()
                    .any(|(j, o)| j != *i && odd_crossings_brute(o, &first) && !on_brute(o, &first))
            })
            .map(|(_, c)| c)
            .collect();
        !outer.is_empty()
            && plan.segments().iter().all(|s| {
                let mid = nalgebra::center(&s.a, &s.b);
                outer
                    .iter()
                    .any(|o| on_brute(o, &mid) || odd_crossings_brute(o, &mid))
            })
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
            prop_assert_eq!(outline_is_closed(&plan), outline_is_closed_brute(&plan));
            let closed = closed_polylines(&plan);
            let flat: Vec<Segment> = closed.iter().flatten().copied().collect();
            let index = Polylines::new(closed);
            for (x, y) in probes {
                // Quarter steps: on lattice points and lines, and between them.
                let p = Point2::new(x as f64 / 4.0, y as f64 / 4.0);
                prop_assert_eq!(index.odd_crossings(&p), odd_crossings_brute(&flat, &p));
                prop_assert_eq!(index.on(None, &p), on_brute(&flat, &p));
            }
        }
    }
}
