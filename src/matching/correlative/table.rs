//! The coarse search's rasterised likelihood tables: where they lie, how a reference point's
//! Gaussian is stamped into them (and cleared again), and how a set of source cells is scored
//! over many translation offsets at once, exactly on the fine table or as an upper bound on the
//! low-resolution one (Olson 2009, sect. IV-B).

use super::CorrelativeScratch;
use nalgebra::Point2;

/// `v.round() as i64` without the libm call (`round` is not inlined without SSE4.1, and the
/// search rounds every used point under every heading): below 2^52 the fraction `v - trunc v`
/// is exact, so comparing it with one half rounds half away from zero exactly as `round`;
/// beyond, and for NaN, `v` is already integral and the cast is the same.
#[inline]
pub(super) fn round_i64(v: f64) -> i64 {
    if v.is_nan() || v.abs() >= 4_503_599_627_370_496.0 {
        return v as i64;
    }
    let t = v as i64;
    let frac = v - t as f64;
    if frac >= 0.5 {
        t + 1
    } else if frac <= -0.5 {
        t - 1
    } else {
        t
    }
}

/// How far (in cells, per axis) a reference point's Gaussian reaches in the fine table.
pub(super) const REACH: i64 = 2;

/// A point's stamp is this many cells across.
const MAX_SIDE: usize = (2 * REACH + 1) as usize;

/// `out[a]` = the maximum of `v[a + 1 - factor ..= a]` (the indices inside `v`), for `a` in
/// `0..v.len() + factor - 1`: each block of `factor` offsets that overlaps `v`. Windows that
/// start at 0 are prefix maxima, windows that end at the last index suffix maxima; the values
/// are the same as a loop over each window (the maximum of the same numbers).
#[inline]
pub(super) fn window_maxima(v: &[f32], factor: usize, out: &mut [f32]) {
    let n = v.len();
    let mut prefix = [0f32; MAX_SIDE];
    let mut suffix = [0f32; MAX_SIDE];
    let mut m = 0f32;
    for (p, &x) in prefix.iter_mut().zip(v) {
        m = m.max(x);
        *p = m;
    }
    m = 0.0;
    for i in (0..n).rev() {
        m = m.max(v[i]);
        suffix[i] = m;
    }
    for (a, o) in out.iter_mut().enumerate() {
        let lo = (a + 1).saturating_sub(factor);
        let hi = a.min(n - 1);
        *o = if lo == 0 {
            prefix[hi]
        } else if hi == n - 1 {
            suffix[lo]
        } else {
            v[lo..=hi].iter().fold(0f32, |m, &x| m.max(x))
        };
    }
}

/// Where the fine likelihood table and its low-resolution bound lie (the cells themselves
/// are in `CorrelativeScratch`).
#[derive(Clone, Copy)]
pub(super) struct Table {
    pub(super) origin: Point2<f64>,
    pub(super) width: i64,
    pub(super) height: i64,
}

/// Translation offsets (in cells) scored together: a grid of rows of y, x ascending in each.
#[derive(Clone, Debug, Default)]
pub(super) struct Offsets {
    pub(super) xy: Vec<(i64, i64)>,
    /// Offsets per row, and the step between them along x.
    pub(super) per_row: usize,
    pub(super) step: usize,
    /// `oy * width + ox` of each row's first offset: its step in the table's cell array.
    pub(super) row_starts: Vec<i64>,
    /// Smallest and largest x, then y.
    pub(super) extent: (i64, i64, i64, i64),
}

impl Offsets {
    /// The offsets `xs × ys` (ranges with a step), rows (y) outer.
    pub(super) fn set(
        &mut self,
        xs: impl Iterator<Item = i64> + Clone,
        ys: impl Iterator<Item = i64>,
        width: i64,
    ) {
        self.xy.clear();
        self.row_starts.clear();
        for oy in ys {
            self.row_starts
                .push(oy * width + xs.clone().next().unwrap_or(0));
            self.xy.extend(xs.clone().map(|ox| (ox, oy)));
        }
        let mut x = xs;
        let first = x.next();
        self.per_row = usize::from(first.is_some()) + x.clone().count();
        self.step = match (first, x.next()) {
            (Some(a), Some(b)) => (b - a) as usize,
            _ => 1,
        };
        if self.row_starts.is_empty() {
            self.per_row = 0;
        }
        let (first, last) = (self.xy.first(), self.xy.last());
        self.extent = match (first, last) {
            (Some(f), Some(l)) => (f.0.min(l.0), f.0.max(l.0), f.1, l.1),
            _ => (0, -1, 0, -1),
        };
    }
}

impl Table {
    pub(super) fn around(reference: &[Point2<f64>], res: f64, margin: f64) -> Option<Table> {
        let (mut lo, mut hi) = (
            Point2::new(f64::INFINITY, f64::INFINITY),
            Point2::new(f64::NEG_INFINITY, f64::NEG_INFINITY),
        );
        for p in reference {
            lo = lo.inf(p);
            hi = hi.sup(p);
        }
        if !lo.x.is_finite() {
            return None;
        }
        let origin = Point2::new(lo.x - margin, lo.y - margin);
        let width = ((hi.x - lo.x + 2.0 * margin) / res).ceil() as i64 + 1;
        let height = ((hi.y - lo.y + 2.0 * margin) / res).ceil() as i64 + 1;
        Some(Table {
            origin,
            width,
            height,
        })
    }

    pub(super) fn cell_of(&self, p: &Point2<f64>, res: f64) -> (i64, i64) {
        (
            round_i64((p.x - self.origin.x) / res),
            round_i64((p.y - self.origin.y) / res),
        )
    }

    /// Fills the fine table, where each point spreads a Gaussian of one cell's sigma over its
    /// neighbourhood (Olson eq. 5's rasterised cost), keeping the maximum where neighbourhoods
    /// overlap; and the low-resolution one, `coarse[x, y] = max fine[x + i, y + j]` over
    /// `0 <= i, j < factor` (cells inside the table). A maximum of maxima is the maximum over
    /// the union, so each point's block maxima are taken over its own neighbourhood and
    /// merged: the same values as from the whole fine table, from only the cells it reaches.
    pub(super) fn fill(
        &self,
        reference: &[Point2<f64>],
        res: f64,
        factor: i64,
        s: &mut CorrelativeScratch,
    ) {
        let side = 2 * REACH + 1;
        let span = side + factor - 1;
        s.stamp.clear();
        s.stamp.resize((side * side) as usize, 0.0);
        s.rows.clear();
        s.rows.resize((side * span) as usize, 0.0);
        s.maxima.clear();
        s.maxima.resize(span as usize, 0.0);
        for p in reference {
            let (cx, cy) = self.cell_of(p, res);
            for dy in -REACH..=REACH {
                for dx in -REACH..=REACH {
                    let (x, y) = (cx + dx, cy + dy);
                    let slot = ((dy + REACH) * side + dx + REACH) as usize;
                    if x < 0 || y < 0 || x >= self.width || y >= self.height {
                        s.stamp[slot] = 0.0;
                        continue;
                    }
                    let cell = Point2::new(
                        self.origin.x + x as f64 * res,
                        self.origin.y + y as f64 * res,
                    );
                    let d2 = (cell - p).norm_squared() / (res * res);
                    let v = (-0.5 * d2).exp() as f32;
                    s.stamp[slot] = v;
                    let fine = &mut s.fine[(y * self.width + x) as usize];
                    if v > *fine {
                        *fine = v;
                    }
                }
            }
            // Block maxima along rows: rows[r, a] is the maximum of stamp row r over the
            // columns a - factor + 1 ..= a (of the stamp), the block of coarse column
            // cx - REACH - factor + 1 + a.
            for r in 0..side as usize {
                let row = &s.stamp[r * side as usize..(r + 1) * side as usize];
                window_maxima(
                    row,
                    factor as usize,
                    &mut s.rows[r * span as usize..][..span as usize],
                );
            }
            // Then along columns, over the blocks inside the table only.
            let (x0, y0) = (cx - REACH - factor + 1, cy - REACH - factor + 1);
            let (a_lo, a_hi) = ((-x0).max(0), (self.width - 1 - x0).min(span - 1));
            let (b_lo, b_hi) = ((-y0).max(0), (self.height - 1 - y0).min(span - 1));
            if a_lo > a_hi || b_lo > b_hi {
                continue;
            }
            let mut column = [0f32; MAX_SIDE];
            for a in a_lo..=a_hi {
                for (r, v) in column.iter_mut().enumerate() {
                    *v = s.rows[r * span as usize + a as usize];
                }
                window_maxima(&column, factor as usize, &mut s.maxima);
                let x = x0 + a;
                for b in b_lo..=b_hi {
                    let m = s.maxima[b as usize];
                    let coarse = &mut s.coarse[((y0 + b) * self.width + x) as usize];
                    if m > *coarse {
                        *coarse = m;
                    }
                }
            }
        }
    }

    /// Zeroes the cells `fill` wrote, which leaves both tables all zeros again.
    pub(super) fn clear(
        &self,
        reference: &[Point2<f64>],
        res: f64,
        factor: i64,
        s: &mut CorrelativeScratch,
    ) {
        for p in reference {
            let (cx, cy) = self.cell_of(p, res);
            let (y0, y1) = (
                (cy - REACH - factor + 1).max(0),
                (cy + REACH).min(self.height - 1),
            );
            let (x0, x1) = (
                (cx - REACH - factor + 1).max(0),
                (cx + REACH).min(self.width - 1),
            );
            for y in y0..=y1 {
                let row = (y * self.width) as usize;
                s.coarse[row + x0 as usize..=row + x1 as usize].fill(0.0);
                if (y - cy).abs() <= REACH {
                    let (f0, f1) = ((cx - REACH).max(0), x1);
                    s.fine[row + f0 as usize..=row + f1 as usize].fill(0.0);
                }
            }
        }
    }

    /// The most a point at `cell` can add at any offset of the block from `(ox, oy)`: the
    /// low-resolution value there, or 1 (every cell's largest value) where the block starts
    /// before the table's first row or column but reaches into it.
    #[inline]
    pub(super) fn block_bound(
        &self,
        coarse: &[f32],
        (cx, cy): (i64, i64),
        ox: i64,
        oy: i64,
        factor: i64,
    ) -> f32 {
        let (x, y) = (cx + ox, cy + oy);
        if x >= 0 && y >= 0 && x < self.width && y < self.height {
            coarse[(y * self.width + x) as usize]
        } else if x + factor > 0 && y + factor > 0 && x < self.width && y < self.height {
            1.0
        } else {
            0.0
        }
    }

    /// Adds one point's values at every offset of `offsets` to `sums`; a point outside the
    /// table adds nothing. Row by row: one slice of the table per row. Offsets whose cell lies
    /// outside the table add nothing there, and are skipped: a sum starts at +0 and only adds
    /// values >= 0, so adding 0 would leave it the same float.
    #[inline]
    pub(super) fn add_point(
        &self,
        table: &[f32],
        (cx, cy): (i64, i64),
        offsets: &Offsets,
        sums: &mut [f32],
    ) {
        let (lo, hi, bottom, top) = offsets.extent;
        if cx + hi < 0 || cy + top < 0 || cx + lo >= self.width || cy + bottom >= self.height {
            return;
        }
        let (n, step) = (offsets.per_row, offsets.step);
        if n == 0 {
            return;
        }
        if cx + lo >= 0 && cy + bottom >= 0 && cx + hi < self.width && cy + top < self.height {
            // Every offset inside: no test per row.
            let base = cy * self.width + cx;
            for (row, &start) in sums.chunks_exact_mut(n).zip(&offsets.row_starts) {
                let cells = &table[(base + start) as usize..][..(n - 1) * step + 1];
                if step == 1 {
                    for (sum, &v) in row.iter_mut().zip(cells) {
                        *sum += v;
                    }
                } else {
                    for (k, sum) in row.iter_mut().enumerate() {
                        *sum += cells[k * step];
                    }
                }
            }
            return;
        }
        // The offsets k (x = cx + lo + k step) whose cells lie inside the table's columns.
        let x0 = cx + lo;
        let step_i = step as i64;
        let k_lo = if x0 >= 0 {
            0
        } else {
            ((-x0 + step_i - 1) / step_i) as usize
        };
        let k_hi = if cx + hi < self.width {
            n
        } else {
            ((self.width - 1 - x0) / step_i + 1) as usize
        };
        if k_lo >= k_hi {
            return;
        }
        let inside_y = cy + bottom >= 0 && cy + top < self.height;
        for ((row, &start), xy) in sums
            .chunks_exact_mut(n)
            .zip(&offsets.row_starts)
            .zip(offsets.xy.iter().step_by(n))
        {
            if !inside_y {
                let y = cy + xy.1;
                if y < 0 || y >= self.height {
                    continue;
                }
            }
            // `start` is the row's first offset in the cell array (`oy * width + lo`).
            let first = cy * self.width + cx + start + k_lo as i64 * step_i;
            let cells = &table[first as usize..][..(k_hi - k_lo - 1) * step + 1];
            let row = &mut row[k_lo..k_hi];
            if step == 1 {
                for (sum, &v) in row.iter_mut().zip(cells) {
                    *sum += v;
                }
            } else {
                for (k, sum) in row.iter_mut().enumerate() {
                    *sum += cells[k * step];
                }
            }
        }
    }

    /// The score of every offset of `offsets`, point by point: each offset's sum adds the
    /// points in the same order as a sum per offset would, so the sums are the same floats.
    pub(super) fn score_offsets(
        &self,
        table: &[f32],
        cells: &[(i64, i64)],
        offsets: &Offsets,
        sums: &mut Vec<f32>,
    ) {
        sums.clear();
        sums.resize(offsets.xy.len(), 0.0);
        for &cell in cells {
            self.add_point(table, cell, offsets, sums);
        }
    }

    /// `score_offsets` over one block's offsets, or `false` once the partial sums plus what
    /// the remaining points can add at most (`rest`) show that none can exceed `best`. The
    /// bound is widened by far more than the rounding of either sum, so a score that would
    /// beat `best` is never cut short.
    pub(super) fn score_block(
        &self,
        table: &[f32],
        cells: &[(i64, i64)],
        block: &Offsets,
        (rest, best): (&[f32], f32),
        sums: &mut Vec<f32>,
    ) -> bool {
        const CHECK_EVERY: usize = 16;
        sums.clear();
        sums.resize(block.xy.len(), 0.0);
        for (i, &cell) in cells.iter().enumerate() {
            self.add_point(table, cell, block, sums);
            if (i + 1) % CHECK_EVERY == 0 {
                let mut most = f32::NEG_INFINITY;
                for &v in sums.iter() {
                    if v > most {
                        most = v;
                    }
                }
                if (most + rest[i + 1]) * (1.0 + 1e-4) + 1e-6 < best {
                    return false;
                }
            }
        }
        true
    }
}
