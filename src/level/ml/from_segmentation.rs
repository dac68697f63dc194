//! The leveler's last stage: the maximum-likelihood core fed the segmentation the leveler chose
//! (docs/ESTIMATOR.md, "Design note: feeding it the leveler's segmentation").
//!
//! The surfaces are the estimate's patches: the re-segmented models when the kept solution is
//! re-segmentation's ([`crate::level::adopt`]), else the patches of region growing; wall
//! patches whose lines coincide in the level frame are merged as one wall (`refine_merge_deg`, as re-segmentation merges its lines), every floor
//! patch one `Floor` and every ceiling patch one `Ceiling` (the world has one floor height).
//! Each grid point becomes a [`LabelledPoint`] with the leveler's range sigma (the ray's own
//! `readings_sigma` when given). The core starts from the leveler's up; its answer replaces the
//! leveler's up and sigmas when it passes the same gate. Its covariance is the information
//! matrix's (inflated by its own chi-square test, covering the cluster-robust one), widened by
//! the distance to rival segmentations of the same ranges: the fit on the points relabelling
//! left where they were and, above `level_edges_above`, the fit without the floor's and
//! ceiling's edges. Where the core
//! refuses, the leveler's answer stands, or the pose fails as before.

use super::discover::with_missing_walls;
use super::relabel::{Neighbours, relabel, without_level_edges};
use super::solve::{one_step, refine_labelled_from};
use super::{LabelledPoint, MlParams, MlSolution, Surface};
use crate::geometry::Attitude;
use crate::level::attitude::attitude_sigmas;
use crate::level::checks::Check;
use crate::level::failure::within_wall_angle;
use crate::level::grid::PoseGrid;
use crate::level::patches::Patch;
use crate::level::up::{UpSolution, mahalanobis2};
use crate::level::{FailCause, LevelEstimate, LevelParams, NoiseSource, SurfaceKind, failure};
use crate::scan::Scan;
use nalgebra::Vector2;

/// Grid indices of one surface's points.
type Group<'a> = (Surface, &'a [usize]);

/// Sets the estimate's attitude, sigmas and up (or its failure) from the leveler's
/// `result`, refined by the core when `params.ml.enabled`. `est`'s patches are the
/// segmentation behind `result` (the refined models when re-segmentation's solution was kept,
/// [`crate::level::adopt`]).
pub(crate) fn finish(
    est: &mut LevelEstimate,
    scans: &[Scan],
    result: Result<UpSolution, FailCause>,
    params: &LevelParams,
) {
    let leveler = match result {
        Ok(sol) => sol,
        Err(cause) => return est.fail(failure::reported(est, cause)),
    };
    let ml = params
        .ml
        .enabled
        .then(|| final_estimate(est, scans, &leveler, params))
        .flatten();
    match ml {
        Some(sol) if gate(&sol, &leveler, params) => {
            est.attitude = Some(Attitude::new(sol.attitude[0], sol.attitude[1]));
            est.sigmas = Some(sol.sigmas());
            est.up = Some(sol.up);
            est.failure = None;
            est.cause = None;
        }
        refused => {
            let attitude = leveler.attitude();
            let mut sigmas = attitude_sigmas(&leveler, params);
            if let Some(rival) = refused {
                widen_sigmas_by(&mut sigmas, &attitude, rival.attitude);
                let max_sigma = params.max_sigma_deg.to_radians();
                if sigmas.iter().any(|&s| s > max_sigma) {
                    return est.fail(failure::reported(est, FailCause::LastStageDisagrees));
                }
            }
            est.attitude = Some(attitude);
            est.sigmas = Some(sigmas);
            est.up = Some(leveler.up);
        }
    }
}

/// The leveler's `sigmas` (at `attitude`) widened as [`widen_by`] widens a covariance (by
/// [`rival_spread`]'s diagonal, the leveler's sigmas being per axis), by
/// their distance from `rival`, the last stage's answer on the same segmentation that the
/// gate refused: the refinement left the leveler's answer by more than its basin allows, so
/// the two readings of the same ranges disagree and either may be the right one. Keeping the
/// leveler's answer with its own sigmas, as before, kept a class whose errors lay beyond three
/// sigmas four times as often as the rest's and held half of the poses reported ok and more
/// than 5 degrees off (docs/ESTIMATOR.md, section 13).
fn widen_sigmas_by(sigmas: &mut [f64; 2], attitude: &Attitude, rival: [f64; 2]) {
    let spread = rival_spread([attitude.theta_x, attitude.theta_y], rival);
    for (i, s) in sigmas.iter_mut().enumerate() {
        *s = (*s * *s + spread[i][i]).sqrt();
    }
}

/// The core's answer on the segmentation behind the leveler's result, before the gate; `None`
/// when the core refuses.
fn final_estimate(
    est: &LevelEstimate,
    scans: &[Scan],
    start: &UpSolution,
    params: &LevelParams,
) -> Option<MlSolution> {
    let grid = est.grid.as_ref()?;
    let groups = patch_groups(&est.patches, start, params, est.range_sigma);
    let stated = match est.noise_source {
        NoiseSource::Stated => scans,
        _ => &[],
    };
    let (index, points) = grid_points(grid, stated, est.range_sigma, params.min_sigma);
    let labels = initial_labels(grid, &index, &groups);
    let neighbours = Neighbours::new(
        index,
        grid.points.len(),
        grid.cols,
        params.ml.relabel_window,
    );
    last_stage(
        &points,
        &neighbours,
        &labels,
        &start.up,
        est.range_sigma,
        params,
    )
}

/// The last stage on one segmentation (`labels`, per point of `points`), before the gate: the
/// core's fit from `up`, relabelled by the fitted model and refitted until the labels settle
/// (an EM over the segmentation, [`relabel`], at most `relabel_passes` times, and no more once
/// a refit moves the attitude by less than `relabel_settle_sigmas`; the first relabelling also
/// takes in the walls the segmentation lacks, [`with_missing_walls`]), its covariance
/// widened by its distance from the rival segmentations of the same ranges: the fit on only
/// the points relabelling left where they were ([`agreed`]) and, when the range sigma exceeds
/// `level_edges_above`, the fit without the floor's and ceiling's edges. `None` when the core
/// refuses the first fit. Fed the true segmentation by `eval accuracy`, it measures what the
/// stage's own rules cost when the segmentation is right.
pub(crate) fn last_stage(
    points: &[LabelledPoint],
    neighbours: &Neighbours,
    labels: &[Option<Surface>],
    up: &nalgebra::Vector3<f64>,
    range_sigma: f64,
    params: &LevelParams,
) -> Option<MlSolution> {
    let mut sol = fit(points, labels, up, None, params)?;
    let first = sol.attitude;
    let mut current = labels.to_vec();
    for pass in 0..params.ml.relabel_passes {
        let mut next = relabel(
            points,
            neighbours,
            &current,
            &sol,
            params.ml.huber_k,
            params.ml.relabel_margin,
            params.ml.min_incidence,
        );
        // Once the first fit has leveled the points, the walls the segmentation lacks show
        // as straight runs of points nothing explains (docs/ESTIMATOR.md, section 18).
        if pass == 0 && params.ml.missing_walls {
            next = with_missing_walls(points, neighbours, &next, &sol, &params.ml);
        }
        if next == current {
            break;
        }
        let Some(refitted) = fit(points, &next, &sol.up, Some(&sol), params) else {
            break;
        };
        let settled = moved_sigmas(&refitted, &sol) < params.ml.relabel_settle_sigmas;
        (sol, current) = (refitted, next);
        if settled {
            break;
        }
    }
    let agreed = agreed(labels, &current);
    if agreed != current {
        // Where the agreed points no longer fix the attitude, the fit before relabelling
        // stands in as the rival (the rule before section 12).
        let rival = one_step(points, &agreed, &sol, &params.ml);
        widen_by(&mut sol, rival.unwrap_or(first));
    }
    if range_sigma > params.ml.level_edges_above {
        let rival = without_level_edges(&current, neighbours, params.ml.level_edge_window);
        if rival != current {
            // One Gauss-Newton step from the fit, as for the rival above: the edges are a
            // few points, and the whole fit gave the same sigmas to 0.004 of the bound (cell
            // medians at 10 cm, docs/ESTIMATOR.md section 18) for 2.4% more of `level`.
            if let Some(without) = one_step(points, &rival, &sol, &params.ml) {
                widen_by(&mut sol, without);
            }
        }
    }
    Some(sol)
}

/// How far `from`'s attitude lies from `to`'s, in `to`'s sigmas (the Mahalanobis distance
/// under `to`'s covariance); infinite when that covariance is singular.
fn moved_sigmas(to: &MlSolution, from: &MlSolution) -> f64 {
    let d = Vector2::from(apart(to.attitude, from.attitude));
    mahalanobis2(&d, &to.covariance_matrix()).map_or(f64::INFINITY, f64::sqrt)
}

/// `a - b`, two attitudes `(theta_x, theta_y)` \[rad\].
fn apart(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

/// `d d^T / 2` for `d` the distance between `sol`'s attitude and `rival`'s: with either of
/// two segmentations as likely to be the right one, the truth lies at one or the other, and
/// this is the expected squared error of reporting `sol` (docs/ESTIMATOR.md, section 6: at
/// 5 cm, sigma / bound 1.26-1.34 -> 1.21-1.27 with 99.1-99.5% within three sigmas, where the
/// whole `d d^T`, as if the first were surely right, padded).
fn rival_spread(sol: [f64; 2], rival: [f64; 2]) -> [[f64; 2]; 2] {
    let d = apart(sol, rival);
    [0, 1].map(|i| [0, 1].map(|j| 0.5 * d[i] * d[j]))
}

/// The labels `before` and `after` relabelling agree on; a point they give different
/// surfaces (or only one of them a surface) is left out. Its fit is the rival segmentation
/// that trusts neither side of a contested point: where relabelling only moved points the
/// first labels had wrong, it lands where the relabelled fit does; where the contested points
/// carry the answer, the two fits part (docs/ESTIMATOR.md, section 12).
fn agreed(before: &[Option<Surface>], after: &[Option<Surface>]) -> Vec<Option<Surface>> {
    before
        .iter()
        .zip(after)
        .map(|(b, a)| if b == a { *a } else { None })
        .collect()
}

/// `sol`'s covariance widened by its distance from `rival` (the attitude the same data gave
/// under another segmentation) \[rad\], by [`rival_spread`].
fn widen_by(sol: &mut MlSolution, rival: [f64; 2]) {
    let spread = rival_spread(sol.attitude, rival);
    for (row, add) in sol.covariance.iter_mut().zip(spread) {
        for (c, a) in row.iter_mut().zip(add) {
            *c += a;
        }
    }
}

/// The core's fit of the points labelled, from `up` (and from `warm`'s placements, a fit of
/// nearly the same labels, when given); `None` when it refuses.
fn fit(
    points: &[LabelledPoint],
    labels: &[Option<Surface>],
    up: &nalgebra::Vector3<f64>,
    warm: Option<&MlSolution>,
    params: &LevelParams,
) -> Option<MlSolution> {
    let ml = MlParams {
        approach: false,
        ..params.ml.clone()
    };
    refine_labelled_from(points, labels, up, warm, &ml).ok()
}

/// Per valid point (`index`: their grid indices, ascending), the surface of the group
/// holding it.
fn initial_labels(grid: &PoseGrid, index: &[usize], groups: &[Group<'_>]) -> Vec<Option<Surface>> {
    let mut by_grid = vec![None; grid.points.len()];
    for &(surface, members) in groups {
        for &i in members {
            if let Some(l) = by_grid.get_mut(i) {
                *l = Some(surface);
            }
        }
    }
    index.iter().map(|&i| by_grid[i]).collect()
}

/// Whether the core's answer `sol`, started from `start`, passes the leveler's gate: both
/// sigmas within `max_sigma_deg`, up within `wall_min_angle_deg` of the robot's z axis, and
/// no farther from the start than `ml.max_shift_sigmas` of the start's own uncertainty (a
/// refinement that runs that far left the basin of the segmentation it was given).
pub(crate) fn gate(sol: &MlSolution, start: &UpSolution, params: &LevelParams) -> bool {
    let max_sigma = params.max_sigma_deg.to_radians();
    let tight = sol.sigmas().iter().all(|&s| s <= max_sigma);
    let shift = Check::LastStageShift.threshold(params);
    let near =
        mahalanobis2(&start.offset_to(&sol.up), &start.cov).is_some_and(|z2| z2 <= shift * shift);
    tight && near && within_wall_angle(&sol.up, params)
}

fn surface_of(kind: SurfaceKind, k: usize) -> Surface {
    match kind {
        SurfaceKind::Wall => Surface::Wall(k),
        SurfaceKind::Floor => Surface::Floor,
        SurfaceKind::Ceiling => Surface::Ceiling,
    }
}

/// The patches as surfaces, leveled with `sol`: wall patches whose level-frame normals lie
/// within `refine_merge_deg` and whose lines lie within `refine_k` sigmas (of range noise
/// `sigma`) plus `flat_margin` of each other share one wall index (the first such patch's),
/// as re-segmentation merges its lines.
fn patch_groups<'a>(
    patches: &'a [Patch],
    sol: &UpSolution,
    params: &LevelParams,
    sigma: f64,
) -> Vec<Group<'a>> {
    let level_from_robot = Attitude::from_up(&sol.up).level_from_robot();
    let cos_max = params.refine_merge_deg.to_radians().cos();
    let tol = params.refine_k * sigma.max(params.min_sigma) + params.flat_margin;
    // Per wall patch seen so far: its index and its level-frame line.
    let mut lines: Vec<(usize, Vector2<f64>, f64)> = Vec::new();
    let mut groups = Vec::with_capacity(patches.len());
    for (k, p) in patches.iter().enumerate() {
        if p.kind != SurfaceKind::Wall {
            groups.push((surface_of(p.kind, k), p.members.as_slice()));
            continue;
        }
        let n = level_from_robot * p.fit.normal;
        let c = level_from_robot * p.fit.centroid;
        let Some(normal) = Vector2::new(n.x, n.y).try_normalize(1e-9) else {
            continue;
        };
        let offset = normal.dot(&Vector2::new(c.x, c.y));
        let same = lines.iter().find(|(_, m, o)| {
            let cos = normal.dot(m);
            cos.abs() >= cos_max && (offset - o * cos.signum()).abs() <= tol
        });
        let wall = match same {
            Some(&(j, _, _)) => j,
            None => {
                lines.push((k, normal, offset));
                k
            }
        };
        groups.push((Surface::Wall(wall), p.members.as_slice()));
    }
    groups
}

/// Every valid grid point as a labelled point (its surface a placeholder), with its grid
/// index: the ray's origin and direction, its range, and its sigma (the ray's
/// `readings_sigma` when its scan in `stated` gives one, else `sigma`; at least `min_sigma`).
/// `stated` is empty where the pose's noise is not the scans' own (given, or contradicted by
/// the ranges).
fn grid_points(
    grid: &PoseGrid,
    scans: &[Scan],
    sigma: f64,
    min_sigma: f64,
) -> (Vec<usize>, Vec<LabelledPoint>) {
    let mut index = Vec::with_capacity(grid.points.len());
    let mut points = Vec::with_capacity(grid.points.len());
    for (i, g) in grid.points.iter().enumerate() {
        let Some(g) = g else {
            continue;
        };
        let (row, col) = (i / grid.cols, i % grid.cols);
        let given = scans
            .get(grid.scan_index[row])
            .and_then(|s| s.readings_sigma.as_ref())
            .and_then(|v| v.get(col).copied().flatten())
            .filter(|s| s.is_finite() && *s > 0.0);
        index.push(i);
        points.push(LabelledPoint {
            origin: g.p - g.dir * g.range,
            dir: g.dir,
            range: g.range,
            sigma: given.unwrap_or(sigma).max(min_sigma),
            surface: Surface::Floor,
        });
    }
    (index, points)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The distance between two fits' attitudes in the second's sigmas: along an axis, the
    /// difference over that axis' sigma; across correlated axes, the Mahalanobis distance.
    #[test]
    fn a_refit_moves_by_its_own_sigmas() {
        let at = |a: [f64; 2], covariance: [[f64; 2]; 2]| MlSolution {
            attitude: a,
            covariance,
            ..MlSolution::default()
        };
        let to = at([0.03, 0.0], [[1e-4, 0.0], [0.0, 4e-4]]);
        assert!((moved_sigmas(&to, &at([0.0, 0.0], to.covariance)) - 3.0).abs() < 1e-12);
        assert!((moved_sigmas(&to, &at([0.03, 0.04], to.covariance)) - 2.0).abs() < 1e-12);
        let correlated = at([0.01, 0.01], [[1e-4, 0.9e-4], [0.9e-4, 1e-4]]);
        // Along the correlation: sqrt(2 d^2 / (1.9e-4)) for d = 0.01.
        let along = (2.0 * 1e-4 / 1.9e-4f64).sqrt();
        assert!((moved_sigmas(&correlated, &at([0.0, 0.0], to.covariance)) - along).abs() < 1e-9);
        assert!(moved_sigmas(&at([0.1, 0.0], [[0.0; 2]; 2]), &to).is_infinite());
    }

    /// A point keeps its label where relabelling left it, and none where it moved (to another
    /// surface, onto one or off one).
    #[test]
    fn agreed_labels_are_those_relabelling_left() {
        let (w0, w1) = (Some(Surface::Wall(0)), Some(Surface::Wall(1)));
        let floor = Some(Surface::Floor);
        let before = [w0, floor, None, w1, w1];
        let after = [w0, w1, floor, None, w1];
        assert_eq!(agreed(&before, &after), vec![w0, None, None, None, w1]);
    }

    /// The leveler's sigmas widened by their distance from a refused rival: each axis gains
    /// half its squared difference (3-4-5 triangles exactly), an equal rival changes nothing,
    /// and the sign of the difference does not matter.
    #[test]
    fn a_refused_rival_widens_the_sigmas_by_half_its_squared_distance() {
        let attitude = Attitude::new(0.10, -0.20);
        let mut sigmas = [0.03, 0.004];
        // d = (0.04 * sqrt 2, -0.003 * sqrt 2): d^2 / 2 = (0.0016, 9e-6).
        let rival = [0.10 - 0.04 * 2f64.sqrt(), -0.20 + 0.003 * 2f64.sqrt()];
        widen_sigmas_by(&mut sigmas, &attitude, rival);
        assert!((sigmas[0] - 0.05).abs() < 1e-12, "{sigmas:?}");
        assert!((sigmas[1] - 0.005).abs() < 1e-12, "{sigmas:?}");
        let mut same = [0.03, 0.004];
        widen_sigmas_by(&mut same, &attitude, [0.10, -0.20]);
        assert_eq!(same, [0.03, 0.004]);
        let mut mirrored = [0.03, 0.004];
        let other_side = [0.10 + 0.04 * 2f64.sqrt(), -0.20 - 0.003 * 2f64.sqrt()];
        widen_sigmas_by(&mut mirrored, &attitude, other_side);
        assert!((mirrored[0] - 0.05).abs() < 1e-12 && (mirrored[1] - 0.005).abs() < 1e-12);
    }
}
