//! A uniform 2D grid over wall segments, walked cell by cell along a ray (Amanatides & Woo
//! 1987, "A fast voxel traversal algorithm for ray tracing").
//!
//! Walls are vertical, so the xy-projection of a 3D ray decides which walls it can meet; the
//! walk stops at the first cell whose exit lies beyond the best hit found so far. The cell
//! count follows the segment count, so the cost per ray depends on how crowded the plan is
//! near the ray, not on how many segments it has in all.

use super::raycast::{END_SLACK, ray_segment};
use crate::plan::Segment;
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
}

impl SegmentGrid {
    pub(crate) fn build(segments: &[Segment]) -> SegmentGrid {
        let Some((lo, hi)) = bounds(segments) else {
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
        let max = Point2::new(
            self.min.x + self.nx as f64 * self.cell,
            self.min.y + self.ny as f64 * self.cell,
        );
        // Clip [0, limit] to the grid's box (slab test).
        let (mut t0, mut t1) = (0.0f64, limit);
        for (o, dd, lo, hi) in [
            (p.x, d2.x, self.min.x, max.x),
            (p.y, d2.y, self.min.y, max.y),
        ] {
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
        if t0 > t1 {
            return None;
        }
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

fn bounds(segments: &[Segment]) -> Option<(Point2<f64>, Point2<f64>)> {
    let mut pts = segments.iter().flat_map(|s| [s.a, s.b]);
    let first = pts.next()?;
    Some(pts.fold((first, first), |(lo, hi), p| {
        (
            Point2::new(lo.x.min(p.x), lo.y.min(p.y)),
            Point2::new(hi.x.max(p.x), hi.y.max(p.y)),
        )
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn seg(ax: f64, ay: f64, bx: f64, by: f64) -> Segment {
        Segment {
            a: Point2::new(ax, ay),
            b: Point2::new(bx, by),
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
