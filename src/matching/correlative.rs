//! Coarse correlative scan matching (Olson 2009, "Real-time correlative scan matching"):
//! an exhaustive search over a bounded window of poses, scored on a rasterised likelihood
//! table of the reference points. It finds the right basin when the odometry is far off;
//! ICP then refines.
//!
//! Two resolutions (Olson's sect. IV-B): a low-resolution table whose cells hold the maximum
//! of the fine table over the block of translations they stand for, so a low-resolution score
//! bounds every fine score it covers; candidates are refined best-first and the search stops
//! as soon as no remaining bound can beat the best fine score (branch and bound, exact on the
//! fine grid).

use crate::geometry::Pose2;
use nalgebra::Point2;

/// Settings of the coarse search. Units in brackets.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CorrelativeParams {
    /// Half-width of the translation window around the guess \[m\]. Default 0.4.
    pub window_xy: f64,
    /// Half-width of the heading window around the guess \[rad\]. Default 20 deg.
    pub window_theta: f64,
    /// Heading step \[rad\]. Default 1 deg.
    pub step_theta: f64,
    /// Fine table cell size \[m\]. Default 0.05.
    pub resolution: f64,
    /// Fine cells per low-resolution cell, per axis [-]. Default 4.
    pub coarse_factor: usize,
    /// Source points used (spread evenly over the scan) [-]. Default 90.
    pub max_points: usize,
    /// Reference points farther than this from the reference scanner are left out of the
    /// table, which keeps it small on long-range scans \[m\]. Default 15.
    pub max_range: f64,
}

impl Default for CorrelativeParams {
    fn default() -> Self {
        Self {
            window_xy: 0.4,
            window_theta: 20f64.to_radians(),
            step_theta: 1f64.to_radians(),
            resolution: 0.05,
            coarse_factor: 4,
            max_points: 90,
            max_range: 15.0,
        }
    }
}

/// The fine likelihood table and its low-resolution bound.
struct Table {
    origin: Point2<f64>,
    width: i64,
    height: i64,
    fine: Vec<f32>,
    coarse: Vec<f32>,
}

impl Table {
    fn build(reference: &[Point2<f64>], res: f64, factor: usize, margin: f64) -> Option<Table> {
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
        let mut fine = vec![0f32; (width * height) as usize];
        // Each point spreads a Gaussian of one cell's sigma over its neighbourhood (Olson eq. 5's
        // rasterised cost), keeping the maximum where neighbourhoods overlap.
        let reach = 2i64;
        for p in reference {
            let cx = ((p.x - origin.x) / res).round() as i64;
            let cy = ((p.y - origin.y) / res).round() as i64;
            for dy in -reach..=reach {
                for dx in -reach..=reach {
                    let (x, y) = (cx + dx, cy + dy);
                    if x < 0 || y < 0 || x >= width || y >= height {
                        continue;
                    }
                    let cell = Point2::new(origin.x + x as f64 * res, origin.y + y as f64 * res);
                    let d2 = (cell - p).norm_squared() / (res * res);
                    let v = (-0.5 * d2).exp() as f32;
                    let slot = &mut fine[(y * width + x) as usize];
                    if v > *slot {
                        *slot = v;
                    }
                }
            }
        }
        // coarse[x, y] = max over fine[x + i, y + j], 0 <= i, j < factor (separable).
        let f = factor as i64;
        let mut rows = vec![0f32; fine.len()];
        for y in 0..height {
            for x in 0..width {
                let mut m = 0f32;
                for i in 0..f.min(width - x) {
                    m = m.max(fine[(y * width + x + i) as usize]);
                }
                rows[(y * width + x) as usize] = m;
            }
        }
        let mut coarse = vec![0f32; fine.len()];
        for y in 0..height {
            for x in 0..width {
                let mut m = 0f32;
                for j in 0..f.min(height - y) {
                    m = m.max(rows[((y + j) * width + x) as usize]);
                }
                coarse[(y * width + x) as usize] = m;
            }
        }
        Some(Table {
            origin,
            width,
            height,
            fine,
            coarse,
        })
    }

    #[inline]
    fn score(&self, table: &[f32], cells: &[(i64, i64)], ox: i64, oy: i64) -> f32 {
        let mut s = 0f32;
        for &(cx, cy) in cells {
            let (x, y) = (cx + ox, cy + oy);
            if x >= 0 && y >= 0 && x < self.width && y < self.height {
                s += table[(y * self.width + x) as usize];
            }
        }
        s
    }
}

/// Best pose (`reference_from_source`) in the window around `guess`, with its score as the
/// mean likelihood per used point (0 to 1). `None` when either point set is empty.
pub fn correlative_search(
    source: &[Point2<f64>],
    reference: &[Point2<f64>],
    reference_sensor: &Point2<f64>,
    guess: Pose2,
    params: &CorrelativeParams,
) -> Option<(Pose2, f64)> {
    let near: Vec<Point2<f64>> = reference
        .iter()
        .filter(|p| (*p - reference_sensor).norm() <= params.max_range)
        .copied()
        .collect();
    let stride = source.len().div_ceil(params.max_points.max(1)).max(1);
    let used: Vec<Point2<f64>> = source.iter().step_by(stride).copied().collect();
    if used.is_empty() {
        return None;
    }
    let res = params.resolution;
    let factor = params.coarse_factor.max(1) as i64;
    let table = Table::build(&near, res, factor as usize, 2.0 * res)?;
    let w = (params.window_xy / res).ceil() as i64;
    let kt = (params.window_theta / params.step_theta).round() as i64;

    // Per heading, each used point's cell under the guess translation.
    let mut cells_per_heading: Vec<(f64, Vec<(i64, i64)>)> = Vec::new();
    let mut candidates: Vec<(f32, usize, i64, i64)> = Vec::new();
    for k in -kt..=kt {
        let theta = guess.theta + k as f64 * params.step_theta;
        let pose = Pose2::new(guess.x, guess.y, theta);
        let cells: Vec<(i64, i64)> = used
            .iter()
            .map(|p| {
                let m = pose.transform_point(p);
                (
                    ((m.x - table.origin.x) / res).round() as i64,
                    ((m.y - table.origin.y) / res).round() as i64,
                )
            })
            .collect();
        let h = cells_per_heading.len();
        let mut oy = -w;
        while oy <= w {
            let mut ox = -w;
            while ox <= w {
                candidates.push((table.score(&table.coarse, &cells, ox, oy), h, ox, oy));
                ox += factor;
            }
            oy += factor;
        }
        cells_per_heading.push((theta, cells));
    }
    // Best bound first; ties go to the candidate nearer the guess (smaller offsets).
    candidates.sort_by(|a, b| {
        b.0.total_cmp(&a.0).then_with(|| {
            let da = a.2.abs() + a.3.abs() + (a.1 as i64 - kt).abs();
            let db = b.2.abs() + b.3.abs() + (b.1 as i64 - kt).abs();
            da.cmp(&db)
        })
    });
    let mut best: (f32, Pose2) = (f32::NEG_INFINITY, guess);
    for &(bound, h, ox0, oy0) in &candidates {
        if bound <= best.0 {
            break;
        }
        let (theta, cells) = &cells_per_heading[h];
        for oy in oy0..(oy0 + factor).min(w + 1) {
            for ox in ox0..(ox0 + factor).min(w + 1) {
                let s = table.score(&table.fine, cells, ox, oy);
                if s > best.0 {
                    best = (
                        s,
                        Pose2::new(guess.x + ox as f64 * res, guess.y + oy as f64 * res, *theta),
                    );
                }
            }
        }
    }
    Some((best.1, best.0 as f64 / used.len() as f64))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_a_far_offset_that_icp_would_miss() {
        // An irregular outline, displaced by 30 cm and 12 degrees.
        let reference: Vec<Point2<f64>> = (0..360)
            .map(|i| {
                let a = (i as f64).to_radians();
                let r = 3.0 + 0.8 * (3.0 * a).sin() + 0.3 * (7.0 * a).cos();
                Point2::new(r * a.cos(), r * a.sin())
            })
            .collect();
        let truth = Pose2::new(0.3, -0.25, 12f64.to_radians());
        let source: Vec<Point2<f64>> = reference
            .iter()
            .map(|p| truth.inverse().transform_point(p))
            .collect();
        let (found, score) = correlative_search(
            &source,
            &reference,
            &Point2::origin(),
            Pose2::identity(),
            &CorrelativeParams::default(),
        )
        .unwrap();
        assert!((found.x - truth.x).abs() <= 0.05, "{found:?}");
        assert!((found.y - truth.y).abs() <= 0.05, "{found:?}");
        assert!((found.theta - truth.theta).abs() <= 1.01f64.to_radians());
        assert!(score > 0.5);
    }
}
