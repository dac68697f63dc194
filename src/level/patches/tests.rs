//! Unit tests of wall patches.

use super::*;
use nalgebra::{Point3, Vector3};
use proptest::prelude::*;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

/// Membership alone decides stacking: points with a member in the adjacent row of their
/// column stack; two rows that are not adjacent do not, even where both hold the column.
#[test]
fn only_adjacent_rows_stack() {
    let (rows, cols) = (3, 20);
    let grid = PoseGrid {
        scan_index: (0..rows).collect(),
        elevation: (0..rows).map(|r| r as f64 * 0.087).collect(),
        cols,
        points: vec![None; rows * cols],
    };
    let at = |r: usize, c: usize| r * cols + c;
    let params = LevelParams::default();
    let wall: Vec<usize> = (0..rows)
        .flat_map(|r| (0..cols).map(move |c| at(r, c)))
        .collect();
    assert!(stacked(&wall, &grid, &params));
    // Row 0 on the left, row 1 on the right, row 2 under both: every column holds two
    // rows, but only the right half's rows 1 and 2 are neighbours.
    let split: Vec<usize> = (0..10)
        .map(|c| at(0, c))
        .chain((10..20).map(|c| at(1, c)))
        .chain((0..20).map(|c| at(2, c)))
        .collect();
    assert!(!stacked(&split, &grid, &params));
}

proptest! {
    /// The bitmap ordering gives what a sort gives, dense or sparse, sorted or not.
    #[test]
    fn ascending_is_a_sort_of_distinct_indices(
        set in proptest::collection::btree_set(0usize..5000, 0..300),
        seed in any::<u64>(),
    ) {
        let mut members: Vec<usize> = set.iter().copied().collect();
        let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(seed);
        rand::seq::SliceRandom::shuffle(&mut members[..], &mut rng);
        let sorted: Vec<usize> = set.into_iter().collect();
        prop_assert_eq!(ascending(&members), sorted);
    }
}

/// A wall met obliquely: the plane through (3, 0, 0) with normal `n`, seen by 3 scans of
/// 61 rays from the origin, with Gaussian range noise `sigma`.
fn oblique_wall_grid(n: &Vector3<f64>, sigma: f64, seed: u64) -> PoseGrid {
    let elevation: Vec<f64> = (0..3).map(|r| (r as f64 - 1.0) * 0.087).collect();
    noisy_grid(elevation, 61, sigma, seed, Point3::origin(), |_, c, e| {
        let bearing = (c as f64 - 30.0).to_radians() * 1.2;
        let dir = Vector3::new(bearing.cos() * e.cos(), bearing.sin(), -e.sin());
        // Range to the plane n . (p - (3, 0, 0)) = 0 along dir.
        (dir, 3.0 * n.x / n.dot(&dir))
    })
}

/// A grid of scans at `elevation`, `cols` rays each, seen from `origin`: ray (row, column)
/// at its row's elevation goes along the direction `ray` gives and meets its surface at the
/// range it gives, plus Gaussian range noise `sigma` (drawn in grid order).
fn noisy_grid(
    elevation: Vec<f64>,
    cols: usize,
    sigma: f64,
    seed: u64,
    origin: Point3<f64>,
    ray: impl Fn(usize, usize, f64) -> (Vector3<f64>, f64),
) -> PoseGrid {
    let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(seed);
    let noise = Normal::new(0.0, sigma).unwrap();
    let rows = elevation.len();
    let mut points = Vec::with_capacity(rows * cols);
    for (r, &e) in elevation.iter().enumerate() {
        for c in 0..cols {
            let (dir, exact) = ray(r, c, e);
            let range = exact + noise.sample(&mut rng);
            points.push(Some(GridPoint {
                p: origin + dir * range,
                dir,
                range,
            }));
        }
    }
    PoseGrid {
        scan_index: (0..rows).collect(),
        elevation,
        cols,
        points,
    }
}

/// The weighted wall fit is better than the plain one on an oblique wall, and the normal
/// variance it reports is not smaller than the scatter over repeated noise (its sigmas are
/// not overconfident).
#[test]
fn ray_weighted_wall_fit_is_tighter_and_not_overconfident() {
    let n = Vector3::new(1.0, -1.2, 0.0).normalize();
    let params = LevelParams::default();
    let sigma = 0.1;
    let up = Vector3::z();
    let (mut sq_w, mut sq_plain, mut predicted) = (0.0, 0.0, 0.0);
    let trials = 300;
    for seed in 0..trials {
        let grid = oblique_wall_grid(&n, sigma, seed);
        let members: Vec<usize> = (0..grid.points.len()).collect();
        let plain = grid.accumulate(&members).fit(sigma).unwrap();
        let weighted =
            ray_weighted_fit(grid.points.iter().flatten(), &params, sigma, plain).unwrap();
        sq_plain += plain.normal.dot(&up).powi(2);
        sq_w += weighted.normal.dot(&up).powi(2);
        predicted += weighted.normal_variance_along(&up, sigma);
    }
    let t = trials as f64;
    let (var_w, var_plain, predicted) = (sq_w / t, sq_plain / t, predicted / t);
    assert!(
        var_w < 0.5 * var_plain,
        "weighted {var_w:.3e} vs plain {var_plain:.3e}"
    );
    assert!(
        var_w < 1.1 * predicted,
        "observed {var_w:.3e} over predicted {predicted:.3e}"
    );
}

/// Three scans of 21 rays at elevations -5, 0, 5 degrees from 0.45 m above the floor,
/// ahead of a wall 2.3 m away: rows 0 and 1 meet the wall, row 2 (pitched down) the floor
/// at `foot` metres.
fn wall_over_floor_line(foot: f64, sigma: f64, seed: u64) -> (PoseGrid, Vec<usize>) {
    let elevation: Vec<f64> = (0..3).map(|r| (r as f64 - 1.0) * 0.087).collect();
    let origin = Point3::new(0.0, 0.0, 0.45);
    let grid = noisy_grid(elevation, 21, sigma, seed, origin, |r, c, e| {
        // Pitched 7 degrees towards the floor: depressions 2, 7, 12 degrees.
        let (dep, bearing) = (e + 0.122, (c as f64 - 10.0).to_radians());
        let dir = Vector3::new(bearing.cos() * dep.cos(), bearing.sin(), -dep.sin());
        let exact = if r < 2 {
            2.3 / dir.x
        } else {
            foot / (dir.x * dir.x + dir.y * dir.y).sqrt()
        };
        (dir, exact)
    });
    let members = (0..grid.points.len()).collect();
    (grid, members)
}

/// A wall at x = 2.5 m seen by four scans (61 rays over 60 degrees), with 10 cm range noise;
/// with `floor_run`, the last 12 rays of the lowest scan meet the floor just in front of
/// the wall's foot instead, 2 to 25 cm short of it along the ray (within the growing
/// tolerance). Returns the grid, every point as members, and the floor run's indices.
fn wall_with_floor_run(floor_run: bool, seed: u64) -> (PoseGrid, Vec<usize>, Vec<usize>) {
    let (rows, cols, run) = (4, 61, 12);
    let elevation: Vec<f64> = (0..rows).map(|r| (r as f64 - 1.5) * 0.087).collect();
    let in_run = |r: usize, c: usize| floor_run && r == rows - 1 && c + run >= cols;
    let grid = noisy_grid(elevation, cols, 0.1, seed, Point3::origin(), |r, c, e| {
        let bearing = (c as f64 - 30.0).to_radians();
        let dir = Vector3::new(bearing.cos() * e.cos(), bearing.sin(), -e.sin());
        let short = if in_run(r, c) {
            0.02 + 0.02 * (c + run - cols) as f64
        } else {
            0.0
        };
        (dir, 2.5 / dir.x - short)
    });
    let members = (0..grid.points.len()).collect();
    let floor = (0..grid.points.len())
        .filter(|&i| in_run(i / cols, i % cols))
        .collect();
    (grid, members, floor)
}

/// The floor run at the end of a wall's lowest row tilts the wall's plane towards it by 1.6
/// degrees on average over 40 noise draws; without the runs that go (more than half of its
/// points, and at most 0.5% of the wall's) the average tilt is within 0.3 degrees of zero.
#[test]
fn a_floor_run_in_front_of_a_walls_foot_goes() {
    let params = LevelParams::default();
    let (mut floor_dropped, mut floor_total, mut wall_dropped, mut wall_total) = (0, 0, 0, 0);
    let (mut tilt_all, mut tilt_kept) = (0.0, 0.0);
    // Signed: positive when the plane leans away at its top.
    let tilt = |n: &Vector3<f64>| (n.z * n.x.signum()).asin().to_degrees() / 40.0;
    for seed in 0..40 {
        let (grid, members, floor) = wall_with_floor_run(true, seed);
        let fit = grid.accumulate(&members).fit(0.1).unwrap();
        let kept = without_front_row_ends(&grid, &members, &fit, &params, 0.1)
            .unwrap_or_else(|| members.clone());
        let dropped = |i: &usize| kept.binary_search(i).is_err();
        floor_dropped += floor.iter().filter(|i| dropped(i)).count();
        floor_total += floor.len();
        wall_dropped += members
            .iter()
            .filter(|i| !floor.contains(i) && dropped(i))
            .count();
        wall_total += members.len() - floor.len();
        tilt_all += tilt(&fit.normal);
        tilt_kept += tilt(&grid.accumulate(&kept).fit(0.1).unwrap().normal);
    }
    assert!(tilt_all < -1.0, "{tilt_all}");
    assert!(tilt_kept.abs() < 0.3, "{tilt_kept}");
    assert!(
        2 * floor_dropped > floor_total,
        "{floor_dropped} of {floor_total} floor points dropped"
    );
    assert!(
        wall_dropped as f64 <= 0.005 * wall_total as f64,
        "{wall_dropped} of {wall_total} wall points dropped"
    );
}

/// A true plane keeps every point in at least 95 of 100 noise draws: its residuals take no
/// side.
#[test]
fn a_true_plane_rarely_loses_a_row_end() {
    let params = LevelParams::default();
    let trimmed = (0..100)
        .filter(|&seed| {
            let (grid, members, _) = wall_with_floor_run(false, seed);
            let fit = grid.accumulate(&members).fit(0.1).unwrap();
            without_front_row_ends(&grid, &members, &fit, &params, 0.1).is_some()
        })
        .count();
    assert!(trimmed <= 5, "{trimmed} of 100 draws trimmed");
}

#[test]
fn wall_lines_with_the_floor_line_at_their_foot_are_bent_across_rows() {
    let params = LevelParams::default();
    for seed in 0..20 {
        // The floor line 10 cm in front of the wall's foot, at 1 cm noise.
        let (grid, members) = wall_over_floor_line(2.2, 0.01, seed);
        let fit = grid.accumulate(&members).fit(0.01).unwrap();
        assert!(
            bent_across_rows(&grid, &members, &fit, &params, 0.01),
            "seed {seed}"
        );
    }
}

/// Two wall lines and the floor line 10 cm in front of their foot, the floor line taking
/// more of the patch (the wall's third scan sees it only near the hinge axis): the patch
/// goes whole; a true three-row wall at 10 cm noise rarely does.
#[test]
fn a_three_row_patch_with_a_row_off_its_plane_goes() {
    let params = LevelParams::default();
    let dropped = |grid: &PoseGrid, members: &[usize], sigma: f64| {
        let acc = grid.accumulate(members);
        let fit = acc.fit(sigma).unwrap();
        trim_edge_rows(grid, members, &acc, &fit, sigma, &params).is_some_and(|m| m.is_empty())
    };
    for seed in 0..20 {
        let (grid, members) = wall_over_floor_line(2.2, 0.01, seed);
        // Only a few points of the top wall row, near one edge.
        let members: Vec<usize> = members
            .into_iter()
            .filter(|&i| i >= grid.cols || i % grid.cols < 5)
            .collect();
        assert!(dropped(&grid, &members, 0.01), "seed {seed}");
    }
    let n = Vector3::new(1.0, -1.2, 0.2).normalize();
    let gone = (0..200)
        .filter(|&seed| {
            let grid = oblique_wall_grid(&n, 0.1, seed);
            let members: Vec<usize> = (0..grid.points.len()).collect();
            dropped(&grid, &members, 0.1)
        })
        .count();
    assert!(gone <= 4, "{gone} of 200 true walls dropped");
}

#[test]
fn a_true_plane_over_three_rows_is_rarely_bent() {
    let params = LevelParams::default();
    let n = Vector3::new(1.0, -1.2, 0.2).normalize();
    let mut bent = 0;
    for seed in 0..200 {
        let grid = oblique_wall_grid(&n, 0.1, seed);
        let members: Vec<usize> = (0..grid.points.len()).collect();
        let fit = grid.accumulate(&members).fit(0.1).unwrap();
        bent += usize::from(bent_across_rows(&grid, &members, &fit, &params, 0.1));
    }
    // A 4-sigma threshold on one degree of freedom rejects about 1% of true planes.
    assert!(bent <= 6, "{bent} of 200 true planes called bent");
}

#[test]
fn ray_weighted_fit_is_exact_without_noise() {
    let n = Vector3::new(1.0, -1.2, 0.3).normalize();
    let grid = oblique_wall_grid(&n, 1e-300, 1);
    let members: Vec<usize> = (0..grid.points.len()).collect();
    let plain = grid.accumulate(&members).fit(0.0).unwrap();
    let params = LevelParams::default();
    let fit = ray_weighted_fit(grid.points.iter().flatten(), &params, 0.0, plain).unwrap();
    assert!(1.0 - fit.normal.dot(&n).abs() < 1e-12, "{:?}", fit.normal);
}

/// [`Check::PatchStacked`](crate::level::checks::Check::PatchStacked): three columns held by
/// two adjacent rows and single points beside them stack while the stacked points hold
/// `min_stacked_share` of the members (6 of 8 at 0.75), and not once they fall below it (6 of 9).
#[test]
fn check_patch_stacked() {
    let params = LevelParams::default();
    assert_eq!(params.min_stacked_share, 0.75);
    let cols = 20;
    let grid = PoseGrid {
        scan_index: vec![0, 1],
        elevation: vec![0.0, 0.087],
        cols,
        points: vec![None; 2 * cols],
    };
    let members = |singles: usize| {
        let mut m: Vec<usize> = (0..3).chain(3..3 + singles).collect();
        m.extend((0..3).map(|c| cols + c));
        m
    };
    assert!(stacked(&members(2), &grid, &params));
    assert!(!stacked(&members(3), &grid, &params));
}

/// [`Check::PatchTooBent`](crate::level::checks::Check::PatchTooBent): a small patch whose
/// misfit ratio is just below `1 + k sqrt(2 / dof)` stands, just above it is too bent; from
/// twice `min_patch_points` members on, it is left to the split test.
#[test]
fn check_patch_too_bent() {
    let params = LevelParams::default();
    let (sigma, weight) = (0.01, 23.0_f64);
    let dof = weight - 3.0;
    let limit = 1.0 + params.max_misfit_sigmas * (2.0 / dof).sqrt();
    let fit = |ratio: f64| PlaneFit {
        centroid: Point3::new(2.0, 0.0, 0.0),
        normal: Vector3::x(),
        in_plane: [(1.0, Vector3::y()), (1.0, Vector3::z())],
        n: weight as usize,
        weight,
        dn2: 1.0,
        residual_ss: ratio * sigma * sigma * dof,
    };
    let small = weight as usize;
    assert!(!too_bent_to_split(
        &fit(limit * (1.0 - 1e-6)),
        small,
        &params,
        sigma
    ));
    assert!(too_bent_to_split(
        &fit(limit * (1.0 + 1e-6)),
        small,
        &params,
        sigma
    ));
    let large = 2 * params.min_patch_points;
    assert!(!too_bent_to_split(&fit(limit * 2.0), large, &params, sigma));
}

/// A wall's plane 2 m ahead whose points fit it with misfit ratio `ratio` at noise 0.01.
fn wall_fit(ratio: f64) -> PlaneFit {
    PlaneFit {
        centroid: Point3::new(2.0, 0.0, 0.0),
        normal: Vector3::x(),
        in_plane: [(1.0, Vector3::y()), (1.0, Vector3::z())],
        n: 103,
        weight: 103.0,
        dn2: 1.0,
        residual_ss: ratio * 1e-4 * 100.0,
    }
}

/// Just below and just above `t`, by a relative `1e-6`.
fn around(t: f64) -> (f64, f64) {
    (t * (1.0 - 1e-6), t * (1.0 + 1e-6))
}

/// [`Check::PatchMinPoints`](crate::level::checks::Check::PatchMinPoints): `min_patch_points`
/// members over two rows make a patch, one fewer do not.
#[test]
fn check_patch_min_points() {
    let params = LevelParams::default();
    let t = params.min_patch_points;
    let members = |n: usize| -> Vec<usize> { (0..n).map(|k| (k % 2) * 100 + k / 2).collect() };
    let sorted = |n: usize| ascending(&members(n));
    assert_eq!(patch_rows(&sorted(t), 100, &params), Some((0, 1)));
    assert_eq!(patch_rows(&sorted(t - 1), 100, &params), None);
    // One row is no patch, however many points.
    assert_eq!(
        patch_rows(&(0..2 * t).collect::<Vec<_>>(), 100, &params),
        None
    );
}

/// [`Check::PatchBentAcrossRows`](crate::level::checks::Check::PatchBentAcrossRows): one point
/// per row on three rows, the first `a` off the plane: `chi2 = a^2 / sigma^2` over one degree
/// of freedom against `1 + k sqrt(2)`.
#[test]
fn check_patch_bent_across_rows() {
    let params = LevelParams::default();
    let sigma = 0.01;
    let (lo, hi) = around(1.0 + params.max_row_bend_sigmas * 2f64.sqrt());
    let bent = |chi2: f64| {
        let a = sigma * chi2.sqrt();
        let points = (0..3)
            .map(|r| {
                let p = Point3::new(2.0 + if r == 0 { a } else { 0.0 }, 0.0, 0.1 * r as f64);
                Some(GridPoint {
                    p,
                    dir: Vector3::x(),
                    range: p.coords.norm(),
                })
            })
            .collect();
        let grid = PoseGrid {
            scan_index: vec![0, 1, 2],
            elevation: vec![0.0, 0.05, 0.1],
            cols: 1,
            points,
        };
        bent_across_rows(&grid, &[0, 1, 2], &wall_fit(1.0), &params, sigma)
    };
    assert!(!bent(lo));
    assert!(bent(hi));
}

/// [`Check::PatchEdgeRow`](crate::level::checks::Check::PatchEdgeRow): an edge row's mean
/// residual against `trim_sigmas` of its spread.
#[test]
fn check_patch_edge_row() {
    let params = LevelParams::default();
    let spread: f64 = 4e-4;
    let (lo, hi) = around(params.trim_sigmas * spread.sqrt());
    assert!(!edge_row_off(-lo, spread, &params));
    assert!(edge_row_off(-hi, spread, &params));
    assert!(edge_row_off(hi, spread, &params));
}

/// [`Check::PatchTrimmedRows`](crate::level::checks::Check::PatchTrimmedRows): three adjacent
/// rows of `MIN_TRIMMED_ROW_SHARE` of the points each hold; one row a point short does not,
/// nor three rows that are not adjacent.
#[test]
fn check_patch_trimmed_rows() {
    let total = 200;
    let t = (MIN_TRIMMED_ROW_SHARE * total as f64).ceil() as usize;
    assert!(trimmed_rows_hold(&[t, t, t], total));
    assert!(!trimmed_rows_hold(&[t, t - 1, t], total));
    assert!(!trimmed_rows_hold(&[t, t, 0, t], total));
    assert!(trimmed_rows_hold(&[0, t, t, t], total));
}

/// [`Check::PatchFrontRun`](crate::level::checks::Check::PatchFrontRun): `MIN_FRONT_RUN`
/// residuals of `r` (variance one each) stand out by `sqrt(MIN_FRONT_RUN) r` sigmas.
#[test]
fn check_patch_front_run() {
    let params = LevelParams::default();
    let k = params.front_end_sigmas;
    let (lo, hi) = around(k / (MIN_FRONT_RUN as f64).sqrt());
    let run = |r: f64, len: usize| front_run(std::iter::repeat_n((r, 1.0), len), k);
    assert_eq!(run(lo, MIN_FRONT_RUN), 0);
    assert_eq!(run(hi, MIN_FRONT_RUN), MIN_FRONT_RUN);
    // Shorter runs are single noisy points, however far out.
    assert_eq!(run(10.0 * k, MIN_FRONT_RUN - 1), 0);
}

/// [`Check::PatchSplitMisfit`](crate::level::checks::Check::PatchSplitMisfit).
#[test]
fn check_patch_split_misfit() {
    let params = LevelParams::default();
    let (lo, hi) = around(params.split_misfit);
    assert!(plane_explained(&wall_fit(lo), 0.01, &params));
    assert!(!plane_explained(&wall_fit(hi), 0.01, &params));
}

/// [`Check::PatchSplitF`](crate::level::checks::Check::PatchSplitF): 106 points, two planes of
/// RSS 1 against one of `1 + 3 F / 100`.
#[test]
fn check_patch_split_f() {
    let params = LevelParams::default();
    let (lo, hi) = around(params.split_f);
    let rss1 = |f: f64| 1.0 + 3.0 * f / 100.0;
    assert!(!two_planes(rss1(lo), 1.0, 106, &params));
    assert!(two_planes(rss1(hi), 1.0, 106, &params));
}
