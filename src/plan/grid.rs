//! A uniform 2D grid over wall segments, the spatial index of a plan: walked cell by cell
//! along a ray (Amanatides & Woo 1987, "A fast voxel traversal algorithm for ray tracing"),
//! searched around a point, and along a row for the inside tests' crossings.
//!
//! Walls are vertical, so the xy-projection of a 3D ray decides which walls it can meet; the
//! walk stops at the first cell whose exit lies beyond the best hit found so far. The cell
//! count follows the segment count, so the cost of a query depends on how crowded the plan is
//! near it, not on how many segments it has in all.

use super::segment::{END_SLACK, Segment, bounds, crossing_x, end_points, ray_segment};
use nalgebra::{Point2, Point3, Vector2, Vector3};

/// Cells per segment: a few segments per cell keeps both the walk and the tests short.
const CELLS_PER_SEGMENT: f64 = 2.0;
/// Most cells a grid may have, to bound memory on huge plans.
const MAX_CELLS: f64 = 4.0e6;

#[derive(Clone, Debug, Default)]
pub(crate) struct SegmentGrid {
    min: Point2<f64>,
    cell: f64,
    nx: usize,
    ny: usize,
    /// Cell `c`'s segments are `items[starts[c]..starts[c + 1]]` (row-major, x fastest).
    starts: Vec<u32>,
    items: Vec<u32>,
    /// Segments indexed.
    count: usize,
}

impl SegmentGrid {
    pub(crate) fn build(segments: &[Segment]) -> SegmentGrid {
        let Some((lo, hi)) = bounds(end_points(segments)) else {
            return SegmentGrid::default();
        };
        let extent = (hi.x - lo.x).max(hi.y - lo.y);
        // Registration is padded by more than the ends' slack, so a hit found by
        // `ray_segment` always lies in a cell that lists its segment.
        let pad = 1e-7 * (1.0 + extent.abs()) + END_SLACK * extent;
        let min = Point2::new(lo.x - pad, lo.y - pad);
        let (w, h) = (hi.x - lo.x + 2.0 * pad, hi.y - lo.y + 2.0 * pad);
        let target = (CELLS_PER_SEGMENT * segments.len() as f64).clamp(1.0, MAX_CELLS);
        let cell = (w * h / target).sqrt().max(w.max(h) / target);
        let nx = ((w / cell).ceil() as usize).max(1);
        let ny = ((h / cell).ceil() as usize).max(1);

        // Two passes (count, then fill) into one flat array.
        let mut counts = vec![0u32; nx * ny + 1];
        let grid = SegmentGrid {
            min,
            cell,
            nx,
            ny,
            starts: Vec::new(),
            items: Vec::new(),
            count: segments.len(),
        };
        for s in segments {
            grid.for_each_cell(s, pad, |c| counts[c] += 1);
        }
        let mut starts = Vec::with_capacity(nx * ny + 1);
        let mut sum = 0u32;
        for c in &counts {
            starts.push(sum);
            sum += c;
        }
        let mut fill = starts.clone();
        let mut items = vec![0u32; sum as usize];
        for (i, s) in segments.iter().enumerate() {
            grid.for_each_cell(s, pad, |c| {
                items[fill[c] as usize] = i as u32;
                fill[c] += 1;
            });
        }
        SegmentGrid {
            starts,
            items,
            ..grid
        }
    }

    /// Calls `f` with every cell that the segment, thickened by `pad`, overlaps.
    fn for_each_cell(&self, s: &Segment, pad: f64, mut f: impl FnMut(usize)) {
        let (x0, x1) = (s.a.x.min(s.b.x) - pad, s.a.x.max(s.b.x) + pad);
        let (y0, y1) = (s.a.y.min(s.b.y) - pad, s.a.y.max(s.b.y) + pad);
        let (ix0, ix1) = (self.index_x(x0), self.index_x(x1));
        let (iy0, iy1) = (self.index_y(y0), self.index_y(y1));
        let e = s.b - s.a;
        let normal = Vector2::new(-e.y, e.x);
        let half = self.cell / 2.0 + pad;
        for iy in iy0..=iy1 {
            for ix in ix0..=ix1 {
                // Separating axis along the segment's normal (the bounding boxes already
                // overlap): the line must pass within the padded cell.
                let centre = Point2::new(
                    self.min.x + (ix as f64 + 0.5) * self.cell,
                    self.min.y + (iy as f64 + 0.5) * self.cell,
                );
                let reach = half * (normal.x.abs() + normal.y.abs());
                if normal.dot(&(centre - s.a)).abs() <= reach {
                    f(iy * self.nx + ix);
                }
            }
        }
    }

    fn index_x(&self, x: f64) -> usize {
        (((x - self.min.x) / self.cell).floor().max(0.0) as usize).min(self.nx - 1)
    }

    fn index_y(&self, y: f64) -> usize {
        (((y - self.min.y) / self.cell).floor().max(0.0) as usize).min(self.ny - 1)
    }

    fn cell_segments(&self, c: usize) -> &[u32] {
        &self.items[self.starts[c] as usize..self.starts[c + 1] as usize]
    }

    /// Whether `pred` holds for some segment listed near `p`. Every segment that comes within
    /// `r` of `p` is offered (farther ones too, and some more than once), so `pred` checks
    /// the distance itself. Searches the cells of the box `p ± r`: a segment within `r` has a
    /// point in that box, and is listed in the cell of that point. When the box spans more
    /// cells than there are segments, every segment is offered instead.
    pub(crate) fn any_near(
        &self,
        p: &Point2<f64>,
        r: f64,
        mut pred: impl FnMut(u32) -> bool,
    ) -> bool {
        if self.items.is_empty() {
            return false;
        }
        let (ix0, ix1) = (self.index_x(p.x - r), self.index_x(p.x + r));
        let (iy0, iy1) = (self.index_y(p.y - r), self.index_y(p.y + r));
        if (ix1 - ix0 + 1).saturating_mul(iy1 - iy0 + 1) > self.count {
            return (0..self.count as u32).any(pred);
        }
        (iy0..=iy1).any(|iy| {
            (ix0..=ix1).any(|ix| {
                self.cell_segments(iy * self.nx + ix)
                    .iter()
                    .any(|&s| pred(s))
            })
        })
    }

    /// Calls `f` once with every segment that the ray from `p` towards +x crosses, by
    /// [`crossing_x`]'s half-open rule (the inside tests' crossing parity). Walks `p`'s row of
    /// cells from `p` on; a segment is listed in the cell of its crossing point, and is taken
    /// there only, so none is counted twice.
    pub(crate) fn for_each_crossing(
        &self,
        segments: &[Segment],
        p: &Point2<f64>,
        mut f: impl FnMut(u32),
    ) {
        if self.items.is_empty() {
            return;
        }
        let iy = self.index_y(p.y);
        for ix in self.index_x(p.x)..self.nx {
            for &si in self.cell_segments(iy * self.nx + ix) {
                if let Some(x) = crossing_x(&segments[si as usize], p)
                    && self.index_x(x) == ix
                {
                    f(si);
                }
            }
        }
    }

    /// The part `[t0, t1]` of the ray `p + t·d`, `t` in `[0, limit]`, inside the grid's box
    /// (slab test); `None` when the ray misses the box.
    fn clip(&self, p: &Point2<f64>, d: &Vector2<f64>, limit: f64) -> Option<(f64, f64)> {
        let max = Point2::new(
            self.min.x + self.nx as f64 * self.cell,
            self.min.y + self.ny as f64 * self.cell,
        );
        let (mut t0, mut t1) = (0.0f64, limit);
        for (o, dd, lo, hi) in [(p.x, d.x, self.min.x, max.x), (p.y, d.y, self.min.y, max.y)] {
            if dd == 0.0 {
                if o < lo || o > hi {
                    return None;
                }
            } else {
                let (ta, tb) = ((lo - o) / dd, (hi - o) / dd);
                t0 = t0.max(ta.min(tb));
                t1 = t1.min(ta.max(tb));
            }
        }
        (t0 <= t1).then_some((t0, t1))
    }

    /// The smallest range `t <= limit` at which the unit ray meets a segment at a height the
    /// wall covers (`z_ok(t)`), walking the cells along the ray in order.
    pub(crate) fn nearest(
        &self,
        segments: &[Segment],
        origin: &Point3<f64>,
        d: &Vector3<f64>,
        limit: f64,
        z_ok: impl Fn(f64) -> bool,
    ) -> Option<f64> {
        if self.items.is_empty() {
            return None;
        }
        let p = Point2::new(origin.x, origin.y);
        let d2 = Vector2::new(d.x, d.y);
        let (t0, t1) = self.clip(&p, &d2, limit)?;
        let start = p + d2 * t0;
        let (mut ix, mut iy) = (self.index_x(start.x), self.index_y(start.y));
        // Exit ranges are computed from the cell index each step, not accumulated, so
        // rounding does not drift along long rays.
        let exit = |i: usize, o: f64, dd: f64, lo: f64| -> f64 {
            if dd > 0.0 {
                (lo + (i + 1) as f64 * self.cell - o) / dd
            } else if dd < 0.0 {
                (lo + i as f64 * self.cell - o) / dd
            } else {
                f64::INFINITY
            }
        };
        let mut best = limit;
        let mut found = false;
        loop {
            for &si in self.cell_segments(iy * self.nx + ix) {
                if let Some(t) = ray_segment(&p, &d2, &segments[si as usize])
                    && t <= best
                    && z_ok(t)
                {
                    best = t;
                    found = true;
                }
            }
            let (tx, ty) = (
                exit(ix, p.x, d2.x, self.min.x),
                exit(iy, p.y, d2.y, self.min.y),
            );
            let t_exit = tx.min(ty);
            if (found && best <= t_exit) || t_exit > t1 {
                break;
            }
            if tx < ty {
                match step(ix, d2.x, self.nx) {
                    Some(i) => ix = i,
                    None => break,
                }
            } else {
                match step(iy, d2.y, self.ny) {
                    Some(i) => iy = i,
                    None => break,
                }
            }
        }
        found.then_some(best)
    }
}

fn step(i: usize, d: f64, n: usize) -> Option<usize> {
    if d > 0.0 {
        (i + 1 < n).then_some(i + 1)
    } else {
        i.checked_sub(1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::segment::seg;
    use proptest::prelude::*;

    proptest! {
        /// Searches near a point and crossings along a row, against testing every segment.
        #[test]
        fn queries_match_brute_force(
            ends in prop::collection::vec(((0i32..40, 0i32..40), (-6i32..7, -6i32..7)), 1..200),
            probes in prop::collection::vec(((-8i32..168, -8i32..168), 0u32..5), 16),
        ) {
            let segments: Vec<Segment> = ends
                .iter()
                .map(|&((x, y), (dx, dy))| {
                    let a = Point2::new(x as f64 / 2.0, y as f64 / 2.0);
                    seg(a.x, a.y, a.x + dx as f64 / 2.0, a.y + dy as f64 / 2.0)
                })
                .collect();
            let grid = SegmentGrid::build(&segments);
            for ((x, y), k) in probes {
                let p = Point2::new(x as f64 / 8.0, y as f64 / 8.0);
                let r = [0.0, 1e-9, 0.3, 1.0, 4.0][k as usize];
                let near = |s: u32| segments[s as usize].distance_to(&p) <= r;
                let want = (0..segments.len() as u32).any(near);
                prop_assert_eq!(grid.any_near(&p, r, near), want, "near {:?} r {}", p, r);
                let mut fast = Vec::new();
                grid.for_each_crossing(&segments, &p, |s| fast.push(s));
                fast.sort_unstable();
                let slow: Vec<u32> = (0..segments.len() as u32)
                    .filter(|&s| crossing_x(&segments[s as usize], &p).is_some())
                    .collect();
                prop_assert_eq!(fast, slow, "crossings from {:?}", p);
            }
        }
    }

    #[test]
    fn long_diagonal_is_listed_only_near_its_line() {
        // 1000 short segments make fine cells; the diagonal must not fill its whole box.
        let mut segments: Vec<Segment> = (0..1000)
            .map(|i| {
                let x = (i % 40) as f64;
                let y = (i / 40) as f64;
                seg(x, y, x + 0.1, y)
            })
            .collect();
        segments.push(seg(0.0, 0.0, 40.0, 25.0));
        let grid = SegmentGrid::build(&segments);
        let listed = (0..grid.nx * grid.ny)
            .filter(|&c| grid.cell_segments(c).contains(&1000))
            .count();
        let along = (grid.nx + grid.ny) * 2;
        assert!(
            listed > 0 && listed <= along,
            "{listed} cells of {}",
            grid.nx * grid.ny
        );
    }

    #[test]
    fn every_segment_is_listed_in_the_cells_of_its_points() {
        let segments = vec![
            seg(0.0, 0.0, 10.0, 0.0),
            seg(10.0, 0.0, 3.0, 7.0),
            seg(-2.0, 5.0, -2.0, 5.5),
        ];
        let grid = SegmentGrid::build(&segments);
        for (i, s) in segments.iter().enumerate() {
            for k in 0..=20 {
                let q = s.a + (s.b - s.a) * (k as f64 / 20.0);
                let c = grid.index_y(q.y) * grid.nx + grid.index_x(q.x);
                assert!(grid.cell_segments(c).contains(&(i as u32)));
            }
        }
    }
}
