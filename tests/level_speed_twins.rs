//! Brute-force twins of the leveling shortcuts taken for speed: each shortcut must give exactly
//! what the plain computation gives, bit for bit, since `level`'s output must not change.

use levelscan::level::LevelParams;
use levelscan::level::grid::{GridPoint, PlaneAccumulator, PoseGrid};
use levelscan::level::patches::{seed_cols, split_members};
use nalgebra::{Point3, Vector3};
use proptest::prelude::*;
use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, Normal};

/// A 5 x `cols` grid of rays from the origin (1 degree apart, elevations 5 degrees apart)
/// meeting two walls at a corner (x = 3 and y = `far`), with Gaussian range noise `sigma`
/// and a few rays without a return.
fn corner_grid(cols: usize, far: f64, sigma: f64, seed: u64) -> PoseGrid {
    let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(seed);
    let noise = Normal::new(0.0, sigma.max(1e-300)).unwrap();
    let elevation: Vec<f64> = (0..5)
        .map(|r| (r as f64 - 2.0) * 5f64.to_radians())
        .collect();
    let mut points = Vec::new();
    for &e in &elevation {
        for c in 0..cols {
            let bearing = (c as f64 * 1.0 - 10.0).to_radians();
            let dir = Vector3::new(bearing.cos() * e.cos(), bearing.sin(), -e.sin());
            let to_x = if dir.x > 1e-9 {
                3.0 / dir.x
            } else {
                f64::INFINITY
            };
            let to_y = if dir.y > 1e-9 {
                far / dir.y
            } else {
                f64::INFINITY
            };
            let range = to_x.min(to_y) + noise.sample(&mut rng);
            let missing = rng.random::<f64>() < 0.03;
            points.push((!missing).then(|| GridPoint {
                p: Point3::from(dir * range),
                dir,
                range,
            }));
        }
    }
    PoseGrid {
        scan_index: (0..5).collect(),
        elevation,
        cols,
        points,
    }
}

/// The split as first written: every candidate cut fitted, orders by a stable sort.
fn split_reference(
    grid: &PoseGrid,
    members: &[usize],
    params: &LevelParams,
    sigma: f64,
    depth: usize,
) -> Vec<Vec<usize>> {
    let whole = vec![members.to_vec()];
    if depth == 0 || members.len() < 2 * params.min_patch_points {
        return whole;
    }
    let cols = grid.cols;
    let acc_of = |m: &[usize]| {
        let mut acc = PlaneAccumulator::default();
        for g in m.iter().filter_map(|&i| grid.points[i].as_ref()) {
            acc.add(g);
        }
        acc
    };
    let span = |m: &[usize]| {
        m.iter().fold((usize::MAX, 0), |(lo, hi), &i| {
            (lo.min(i / cols), hi.max(i / cols))
        })
    };
    let Some(fit_all) = acc_of(members).fit(sigma) else {
        return whole;
    };
    let mut best: Option<(f64, usize, usize)> = None;
    let mut orders = [members.to_vec(), members.to_vec()];
    for (which, sorted) in orders.iter_mut().enumerate() {
        let key = |i: usize| if which == 1 { i / cols } else { i % cols };
        sorted.sort_by_key(|&i| (key(i), i));
        let n = sorted.len();
        let total = acc_of(sorted);
        let half = params.min_patch_points / 2;
        for b in half.max(1)..n.saturating_sub(half).max(1) {
            if key(sorted[b]) == key(sorted[b - 1]) {
                continue;
            }
            let ((llo, lhi), (rlo, rhi)) = (span(&sorted[..b]), span(&sorted[b..]));
            if lhi <= llo || rhi <= rlo {
                continue;
            }
            let l = acc_of(&sorted[..b]);
            let r = total.minus(&l);
            let (Some(fl), Some(fr)) = (l.fit(sigma), r.fit(sigma)) else {
                continue;
            };
            let rss2 = fl.residual_ss + fr.residual_ss;
            if best.is_none_or(|(br, _, _)| rss2 < br) {
                best = Some((rss2, which, b));
            }
        }
    }
    let Some((_, which, cut)) = best else {
        return whole;
    };
    let (a, b) = (orders[which][..cut].to_vec(), orders[which][cut..].to_vec());
    let ok = |m: &[usize]| {
        let (lo, hi) = span(m);
        m.len() >= params.min_patch_points / 2 && hi > lo
    };
    if !ok(&a) || !ok(&b) {
        return whole;
    }
    let (Some(fa), Some(fb)) = (acc_of(&a).fit(sigma), acc_of(&b).fit(sigma)) else {
        return whole;
    };
    let rss2 = fa.residual_ss + fb.residual_ss;
    let n = members.len() as f64;
    let f = ((fit_all.residual_ss - rss2) / 3.0) / (rss2 / (n - 6.0)).max(1e-300);
    if f.is_nan() || f <= params.split_f {
        return whole;
    }
    let mut out = split_reference(grid, &a, params, sigma, depth - 1);
    out.extend(split_reference(grid, &b, params, sigma, depth - 1));
    out
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// Pruning candidate cuts by their lower bounds, and ordering members by counting, give
    /// the very parts that fitting every cut gives, members in any input order.
    #[test]
    fn split_members_matches_fitting_every_cut(
        seed in 0u64..1_000_000,
        cols in 30usize..90,
        far in 1.5f64..6.0,
        sigma in prop_oneof![Just(0.0), 0.001f64..0.15],
        shuffle in any::<bool>(),
    ) {
        let grid = corner_grid(cols, far, sigma, seed);
        let params = LevelParams::default();
        let mut members: Vec<usize> =
            (0..grid.points.len()).filter(|&i| grid.points[i].is_some()).collect();
        if shuffle {
            let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(seed + 1);
            for k in (1..members.len()).rev() {
                members.swap(k, rng.random_range(0..=k));
            }
        }
        let fast = split_members(&grid, &members, &params, sigma, params.split_depth);
        let slow = split_reference(&grid, &members, &params, sigma, params.split_depth);
        prop_assert_eq!(fast, slow);
    }
}

/// The twin test above means something only if cuts happen: a clean corner is split.
#[test]
fn split_members_cuts_a_corner() {
    let grid = corner_grid(60, 2.5, 0.01, 5);
    let params = LevelParams::default();
    let members: Vec<usize> = (0..grid.points.len())
        .filter(|&i| grid.points[i].is_some())
        .collect();
    let parts = split_members(&grid, &members, &params, 0.01, params.split_depth);
    assert!(parts.len() >= 2, "{} parts", parts.len());
    assert_eq!(parts.iter().map(Vec::len).sum::<usize>(), members.len());
}

/// The seed width as first written: from the median range, always found.
fn seed_cols_reference(grid: &PoseGrid, params: &LevelParams, sigma: f64) -> usize {
    let mut ranges: Vec<f64> = grid.points.iter().flatten().map(|g| g.range).collect();
    if ranges.is_empty() || grid.cols < 2 {
        return params.quad_cols;
    }
    let mid = ranges.len() / 2;
    let (_, r, _) = ranges.select_nth_unstable_by(mid, f64::total_cmp);
    let step = (0..grid.cols - 1)
        .find_map(|c| {
            let (a, b) = (grid.at(0, c)?, grid.at(0, c + 1)?);
            Some(a.dir.angle(&b.dir))
        })
        .unwrap_or(1f64.to_radians());
    let want = (params.seed_span_sigmas * sigma / (*r * step).max(1e-9)).ceil() as usize + 1;
    want.clamp(params.quad_cols, params.max_seed_cols.max(params.quad_cols))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    /// Skipping the median when enough ranges are long gives the median's width.
    #[test]
    fn seed_cols_matches_the_median_rule(
        seed in 0u64..1_000_000,
        cols in 5usize..90,
        far in 0.3f64..8.0,
        sigma in prop_oneof![Just(0.0), 0.0001f64..0.2],
    ) {
        let grid = corner_grid(cols, far, sigma, seed);
        let params = LevelParams::default();
        prop_assert_eq!(seed_cols(&grid, &params, sigma), seed_cols_reference(&grid, &params, sigma));
    }
}
