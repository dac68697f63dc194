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

mod table;

use crate::geometry::{Pose2, wrap_angle};
use nalgebra::Point2;
use std::cmp::Reverse;
use table::{Offsets, Table};

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

/// Buffers of the coarse search, kept between calls so a search allocates nothing once they
/// have grown to the largest table seen. Between calls both tables are all zeros: a search
/// writes only the cells near its reference points and clears those same cells before it
/// returns, so no pass over the whole table is ever made.
#[derive(Clone, Debug, Default)]
pub struct CorrelativeScratch {
    fine: Vec<f32>,
    coarse: Vec<f32>,
    near: Vec<Point2<f64>>,
    used: Vec<Point2<f64>>,
    /// Each used point's cell under the guess translation, heading after heading.
    cells: Vec<(i64, i64)>,
    headings: Vec<f64>,
    candidates: Vec<(f32, usize, i64, i64)>,
    /// The low-resolution blocks' first offsets; one block's fine offsets; the sums of the
    /// offsets being scored.
    offsets: Offsets,
    block: Offsets,
    sums: Vec<f32>,
    /// The candidates' ranks (bound, nearness to the guess, index), as the heap's buffer.
    ranked: Vec<(i32, Reverse<i64>, Reverse<usize>)>,
    /// While a candidate is refined: the most its points from each one on can still add.
    rest: Vec<f32>,
    /// One point's Gaussian over its (2 REACH + 1)² neighbourhood, and its maxima along rows
    /// over the low-resolution blocks.
    stamp: Vec<f32>,
    rows: Vec<f32>,
    /// One column of `rows`' block maxima over the low-resolution blocks.
    maxima: Vec<f32>,
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
    let mut scratch = CorrelativeScratch::default();
    correlative_search_with(
        &mut scratch,
        source,
        reference,
        reference_sensor,
        guess,
        params,
    )
}

/// [`correlative_search`] in buffers kept by the caller (a matcher keeps one set for its run).
pub fn correlative_search_with(
    s: &mut CorrelativeScratch,
    source: &[Point2<f64>],
    reference: &[Point2<f64>],
    reference_sensor: &Point2<f64>,
    guess: Pose2,
    params: &CorrelativeParams,
) -> Option<(Pose2, f64)> {
    s.near.clear();
    s.near.extend(
        reference
            .iter()
            .filter(|p| (*p - reference_sensor).norm() <= params.max_range),
    );
    let stride = source.len().div_ceil(params.max_points.max(1)).max(1);
    s.used.clear();
    s.used.extend(source.iter().step_by(stride));
    if s.used.is_empty() {
        return None;
    }
    let res = params.resolution;
    let factor = params.coarse_factor.max(1) as i64;
    let table = Table::around(&s.near, res, 2.0 * res)?;
    let cells = (table.width * table.height) as usize;
    if s.fine.len() < cells {
        s.fine.resize(cells, 0.0);
        s.coarse.resize(cells, 0.0);
    }
    let near = std::mem::take(&mut s.near);
    table.fill(&near, res, factor, s);
    let found = search(&table, s, guess, params, factor);
    table.clear(&near, res, factor, s);
    s.near = near;
    Some((found.1, found.0 as f64 / s.used.len() as f64))
}

/// The branch and bound over the filled tables: best fine score and its pose.
fn search(
    table: &Table,
    s: &mut CorrelativeScratch,
    guess: Pose2,
    params: &CorrelativeParams,
    factor: i64,
) -> (f32, Pose2) {
    let res = params.resolution;
    let (w, kt) = window_steps(params);
    let n = s.used.len();
    s.cells.clear();
    s.headings.clear();
    s.candidates.clear();
    // The low-resolution blocks' first offsets, rows (y) outer.
    let starts = || (-w..=w).step_by(factor as usize);
    s.offsets.set(starts(), starts(), table.width);
    for k in -kt..=kt {
        let theta = guess.theta + k as f64 * params.step_theta;
        let pose = Pose2::new(guess.x, guess.y, theta);
        let rotation = pose.theta.sin_cos();
        let h = s.headings.len();
        s.cells.extend(
            s.used
                .iter()
                .map(|p| table.cell_of(&transformed(&pose, rotation, p), res)),
        );
        let cells = &s.cells[h * n..];
        table.score_offsets(&s.coarse, cells, &s.offsets, &mut s.sums);
        s.candidates.extend(
            s.sums
                .iter()
                .zip(&s.offsets.xy)
                .map(|(&bound, &(ox, oy))| (bound, h, ox, oy)),
        );
        s.headings.push(theta);
    }
    // Best bound first; ties go to the candidate nearer the guess (smaller offsets), then to
    // the earlier one. Popped from a heap: the search usually stops after a few candidates,
    // so sorting all of them would be wasted.
    let mut heap = std::collections::BinaryHeap::from(std::mem::take(&mut s.ranked));
    heap.clear();
    heap.extend(s.candidates.iter().enumerate().map(|(i, c)| {
        let near = c.2.abs() + c.3.abs() + (c.1 as i64 - kt).abs();
        (total_order_key(c.0), Reverse(near), Reverse(i))
    }));
    let mut best: (f32, Pose2) = (f32::NEG_INFINITY, guess);
    while let Some((_, _, Reverse(i))) = heap.pop() {
        let (bound, h, ox0, oy0) = s.candidates[i];
        if bound <= best.0 {
            break;
        }
        let (theta, cells) = (s.headings[h], &s.cells[h * n..(h + 1) * n]);
        // rest[i]: what points i.. can add at most over the block's offsets.
        s.rest.clear();
        s.rest.resize(n + 1, 0.0);
        for i in (0..n).rev() {
            s.rest[i] = s.rest[i + 1] + table.block_bound(&s.coarse, cells[i], ox0, oy0, factor);
        }
        let xs = ox0..(ox0 + factor).min(w + 1);
        s.block.set(xs, oy0..(oy0 + factor).min(w + 1), table.width);
        let bound = (&s.rest[..], best.0);
        if !table.score_block(&s.fine, cells, &s.block, bound, &mut s.sums) {
            continue;
        }
        // In the block's order, as offset after offset: the first of equal scores wins.
        for (&score, &(ox, oy)) in s.sums.iter().zip(&s.block.xy) {
            if score > best.0 {
                best = (
                    score,
                    Pose2::new(guess.x + ox as f64 * res, guess.y + oy as f64 * res, theta),
                );
            }
        }
    }
    s.ranked = heap.into_vec();
    best
}

/// The search window's half-widths in steps: translation offsets `-w..=w` cells of
/// `resolution` per axis, headings `-k..=k` steps of `step_theta`.
fn window_steps(params: &CorrelativeParams) -> (i64, i64) {
    (
        (params.window_xy / params.resolution).ceil() as i64,
        (params.window_theta / params.step_theta).round() as i64,
    )
}

/// Whether `found`, a search's answer around `guess`, lies on its window's edge: at the
/// outermost translation offset on either axis or the outermost heading. Such a best is not
/// bracketed (the score may still rise outside the window), so it is no maximum the search
/// found; an answer inside the window is one. On the CSAIL log a best on the heading edge,
/// 20 degrees from an odometry that was right, turned the run by 20 degrees for good
/// (docs/RESULTS.md, 2026-12-06). An axis the window does not search (half-width 0) has no edge.
pub(crate) fn on_window_edge(found: &Pose2, guess: &Pose2, params: &CorrelativeParams) -> bool {
    let (w, kt) = window_steps(params);
    let steps = |d: f64, step: f64| (d / step).round().abs() as i64;
    let res = params.resolution;
    let translation =
        w > 0 && (steps(found.x - guess.x, res) >= w || steps(found.y - guess.y, res) >= w);
    let heading = kt > 0 && steps(wrap_angle(found.theta - guess.theta), params.step_theta) >= kt;
    translation || heading
}

/// `pose.transform_point(p)` with the heading's `sin_cos` taken once for all the points (the
/// same arithmetic, so the same result to the bit).
#[inline]
fn transformed(pose: &Pose2, (s, c): (f64, f64), p: &Point2<f64>) -> Point2<f64> {
    Point2::new(pose.x + c * p.x - s * p.y, pose.y + s * p.x + c * p.y)
}

/// An integer that orders as `f32::total_cmp` orders its floats.
fn total_order_key(v: f32) -> i32 {
    let bits = v.to_bits() as i32;
    bits ^ (((bits >> 31) as u32) >> 1) as i32
}

#[cfg(test)]
mod tests {
    use super::table::{REACH, round_i64, window_maxima};
    use super::*;

    #[test]
    fn total_order_key_orders_as_total_cmp() {
        let v = [
            f32::NEG_INFINITY,
            -2.5,
            -0.0,
            0.0,
            1e-30,
            0.5,
            1.0,
            90.0,
            f32::INFINITY,
        ];
        for a in v {
            for b in v {
                assert_eq!(total_order_key(a).cmp(&total_order_key(b)), a.total_cmp(&b));
            }
        }
    }

    #[test]
    fn window_maxima_equal_a_loop_over_each_window() {
        let v = [0.3f32, 0.9, 0.1, 0.7, 0.2];
        for factor in 1..=8usize {
            let mut out = vec![-1f32; v.len() + factor - 1];
            window_maxima(&v, factor, &mut out);
            for (a, &o) in out.iter().enumerate() {
                let lo = (a + 1).saturating_sub(factor);
                let hi = a.min(v.len() - 1);
                let m = v[lo..=hi].iter().fold(0f32, |m, &x| m.max(x));
                assert_eq!(o, m, "factor {factor}, block {a}");
            }
        }
    }

    #[test]
    fn round_i64_equals_round() {
        let mut v = -3.0f64;
        while v <= 3.0 {
            for x in [v, v + 1e-12, v - 1e-12, v * 1e9, v * 1e17] {
                assert_eq!(round_i64(x), x.round() as i64, "{x}");
            }
            v += 0.125;
        }
        for x in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 1e300, -1e300] {
            assert_eq!(round_i64(x), x.round() as i64);
        }
    }

    #[test]
    fn stamped_tables_equal_whole_table_passes_and_clear_to_zero() {
        // Points near the table's edges and overlapping each other.
        let reference: Vec<Point2<f64>> = (0..200)
            .map(|i| {
                let a = i as f64 * 0.7;
                Point2::new(2.0 * a.cos() + 0.013 * i as f64, 1.5 * (1.3 * a).sin())
            })
            .collect();
        let (res, factor) = (0.05, 4);
        let table = Table::around(&reference, res, 2.0 * res).unwrap();
        let (w, h) = (table.width, table.height);
        let mut s = CorrelativeScratch {
            fine: vec![0.0; (w * h) as usize],
            coarse: vec![0.0; (w * h) as usize],
            ..CorrelativeScratch::default()
        };
        table.fill(&reference, res, factor, &mut s);
        // The fine table point by point, then its block maxima over the whole table.
        let mut fine = vec![0f32; (w * h) as usize];
        for p in &reference {
            let (cx, cy) = table.cell_of(p, res);
            for y in (cy - REACH).max(0)..=(cy + REACH).min(h - 1) {
                for x in (cx - REACH).max(0)..=(cx + REACH).min(w - 1) {
                    let cell = Point2::new(
                        table.origin.x + x as f64 * res,
                        table.origin.y + y as f64 * res,
                    );
                    let v = (-0.5 * (cell - p).norm_squared() / (res * res)).exp() as f32;
                    let slot = &mut fine[(y * w + x) as usize];
                    *slot = slot.max(v);
                }
            }
        }
        assert_eq!(s.fine, fine);
        for y in 0..h {
            for x in 0..w {
                let mut m = 0f32;
                for j in y..(y + factor).min(h) {
                    for i in x..(x + factor).min(w) {
                        m = m.max(fine[(j * w + i) as usize]);
                    }
                }
                assert_eq!(s.coarse[(y * w + x) as usize], m, "cell {x}, {y}");
            }
        }
        table.clear(&reference, res, factor, &mut s);
        assert!(s.fine.iter().chain(&s.coarse).all(|&v| v == 0.0));
    }

    /// An irregular closed outline around the origin, a point per degree.
    fn outline() -> Vec<Point2<f64>> {
        (0..360)
            .map(|i| {
                let a = (i as f64).to_radians();
                let r = 3.0 + 0.8 * (3.0 * a).sin() + 0.3 * (7.0 * a).cos();
                Point2::new(r * a.cos(), r * a.sin())
            })
            .collect()
    }

    #[test]
    fn finds_a_far_offset_that_icp_would_miss() {
        // An irregular outline, displaced by 30 cm and 12 degrees.
        let reference = outline();
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
        assert!(!on_window_edge(
            &found,
            &Pose2::identity(),
            &CorrelativeParams::default()
        ));
    }

    /// Inside the window the search's best is bracketed; where the truth lies beyond it, the
    /// best is found on the edge (the score still rising outward) and said to be there, on
    /// each axis, at any guess heading (the heading's edge across +-180 degrees too).
    #[test]
    fn a_best_beyond_the_window_lies_on_its_edge() {
        let reference = outline();
        let params = CorrelativeParams::default();
        let search = |truth: Pose2, guess: Pose2| {
            let source: Vec<Point2<f64>> = reference
                .iter()
                .map(|p| truth.inverse().transform_point(p))
                .collect();
            let (found, _) =
                correlative_search(&source, &reference, &Point2::origin(), guess, &params).unwrap();
            on_window_edge(&found, &guess, &params)
        };
        for guess_theta in [0.0, 179.5f64.to_radians(), -179.5f64.to_radians()] {
            let guess = Pose2::new(0.0, 0.0, guess_theta);
            let at = |dx: f64, dy: f64, dtheta_deg: f64| {
                Pose2::new(dx, dy, guess_theta + dtheta_deg.to_radians())
            };
            assert!(!search(at(0.1, -0.2, 8.0), guess));
            assert!(search(at(0.0, 0.0, 26.0), guess));
            assert!(search(at(0.0, 0.0, -26.0), guess));
            assert!(search(at(0.6, 0.0, 0.0), guess));
            assert!(search(at(0.0, -0.6, 3.0), guess));
        }
        // Exact edges: offsets of whole steps.
        let g = Pose2::new(1.0, 2.0, 0.5);
        let edge = |dx: f64, dy: f64, dt: f64| {
            on_window_edge(&Pose2::new(1.0 + dx, 2.0 + dy, 0.5 + dt), &g, &params)
        };
        assert!(edge(0.4, 0.0, 0.0) && edge(0.0, -0.4, 0.0) && edge(0.0, 0.0, params.window_theta));
        assert!(!edge(0.35, -0.35, params.window_theta - params.step_theta));
        // A window of no width on an axis has no edge there.
        let fixed = CorrelativeParams {
            window_theta: 0.0,
            ..params
        };
        assert!(!on_window_edge(&g, &g, &fixed));
    }
}
