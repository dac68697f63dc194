//! Walls as 2D lines in the level frame: new ones discovered scan by scan (classic line
//! extraction of a planar scan) and lines that are one wall merged.

use super::*;
use crate::geometry::minor_axis_2x2;

/// New walls in the level frame, found scan by scan: a run of consecutive rays whose points
/// lie on one 2D line within their noise (along-beam noise projected on the line's normal)
/// seeds a line, which grows ray by ray while the next point stays within `refine_k` sigmas.
/// This is the classic line extraction of a planar scan (e.g. Nguyen et al. 2005, "A
/// comparison of line extraction algorithms using 2D laser rangefinder"), applied to each
/// leveled scan; lines of different scans on one wall are merged afterwards.
pub(crate) fn discover_lines(f: &Frame, candidate: &[bool], width: usize) -> Vec<Line> {
    let (grid, lv, params, s) = (f.grid, &f.lv, f.params, f.s);
    let cols = grid.cols;
    let min_points = params.min_patch_points.max(width);
    let k = params.refine_k;
    let point = |i: usize| -> Option<(Vector2<f64>, Vector2<f64>, f64)> {
        let (q, d) = lv[i].as_ref().filter(|_| candidate[i])?;
        Some((q.xy(), d.xy(), q.z))
    };
    let mut out = Vec::new();
    for r in 0..grid.rows() {
        let row = r * cols;
        let mut c = 0;
        while c + width <= cols {
            let seed = c..c + width;
            // Every seed over an unusable ray fails: the next one starts past the last one.
            if let Some(j) = seed.clone().rev().find(|&j| point(row + j).is_none()) {
                c = j + 1;
                continue;
            }
            let mut acc = Line2::default();
            let seed_points = seed.filter_map(|j| point(row + j));
            seed_points.for_each(|(p, d, z)| acc.add(&p, &d, z));
            let Some(mut line) = acc
                .line()
                .filter(|l| acc.misfit(l, s, params.min_sigma) <= SEED_MISFIT)
            else {
                c += 1;
                continue;
            };
            let mut end = c + width;
            let mut gap = 0;
            let mut refit_at = acc.n * 5 / 4 + 1;
            while end < cols && gap <= MAX_GAP {
                let Some((p, d, z)) = point(row + end) else {
                    gap += 1;
                    end += 1;
                    continue;
                };
                let along = line.normal.dot(&d);
                let sd = (s * s * along * along + params.min_sigma.powi(2)).sqrt();
                if (line.normal.dot(&p) - line.offset).abs() > k * sd {
                    break;
                }
                gap = 0;
                acc.add(&p, &d, z);
                end += 1;
                if acc.n >= refit_at {
                    line = acc.line().unwrap_or(line);
                    refit_at = acc.n * 5 / 4 + 1;
                }
            }
            if acc.n >= min_points {
                out.extend(acc.line());
            }
            c = end;
        }
    }
    out
}

/// Sums for a 2D total-least-squares line.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Line2 {
    n: usize,
    sum: Vector2<f64>,
    /// Sum of `p p^T` over the points.
    pp: Matrix2<f64>,
    z: f64,
    /// Sum of `d d^T` over the ray directions (for the noise along the normal).
    dd: Matrix2<f64>,
}

impl Line2 {
    pub(crate) fn add(&mut self, p: &Vector2<f64>, d: &Vector2<f64>, z: f64) {
        self.n += 1;
        self.sum += p;
        self.pp += p * p.transpose();
        self.z += z;
        self.dd += d * d.transpose();
    }

    pub(crate) fn line(&self) -> Option<Line> {
        if self.n < 3 {
            return None;
        }
        let n = self.n as f64;
        let (c, m) = self.scatter();
        let normal = minor_axis_2x2(&m);
        Some(Line {
            normal,
            offset: normal.dot(&c),
            z: self.z / n,
            weight: n,
        })
    }

    /// The centroid, and the scatter about it per point.
    fn scatter(&self) -> (Vector2<f64>, Matrix2<f64>) {
        let c = self.sum / self.n as f64;
        (c, self.pp / self.n as f64 - c * c.transpose())
    }

    /// Residual variance about `l` over what the noise explains.
    pub(crate) fn misfit(&self, l: &Line, s: f64, min_sigma: f64) -> f64 {
        let n = self.n as f64;
        let (_, m) = self.scatter();
        let scatter = l.normal.dot(&(m * l.normal));
        let dn2 = l.normal.dot(&(self.dd * l.normal)) / n;
        let expected = s * s * dn2 + min_sigma * min_sigma;
        scatter * n / (n - 2.0).max(1.0) / expected
    }
}

/// Merges lines that are one wall: normals within `refine_merge_deg` and each one's pivot
/// within the tolerance of the other (region growing splits one noisy wall into several
/// patches; left apart they would claim the same points, which would then be dropped as
/// ambiguous).
pub(crate) fn merge_lines(lines: &mut Vec<Line>, params: &LevelParams, s: f64) {
    let cos_max = params.refine_merge_deg.to_radians().cos();
    let tol = params.refine_k * s + params.flat_margin;
    let mut i = 0;
    while i < lines.len() {
        let mut j = i + 1;
        while j < lines.len() {
            let (a, b) = (lines[i], lines[j]);
            let c = a.normal.dot(&b.normal);
            let (bn, bo) = if c < 0.0 {
                (-b.normal, -b.offset)
            } else {
                (b.normal, b.offset)
            };
            if c.abs() >= cos_max && (a.offset - bo).abs() <= tol {
                let w = a.weight + b.weight;
                let normal = (a.normal * a.weight + bn * b.weight).normalize();
                lines[i] = Line {
                    normal,
                    offset: (a.offset * a.weight + bo * b.weight) / w,
                    z: (a.z * a.weight + b.z * b.weight) / w,
                    weight: w,
                };
                lines.swap_remove(j);
            } else {
                j += 1;
            }
        }
        i += 1;
    }
}
