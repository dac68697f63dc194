//! The first pass (sect. 5.3-5.5): up from the wall quads (paper) or the wall patches and the
//! level surfaces cleaned of wall points (robust), and the failure reasons of a pose that
//! cannot be leveled.

use super::failure::{FailCause, acceptable};
use super::grid::{PlaneAccumulator, PlaneFit, PoseGrid};
use super::patches::Patch;
use super::up::{self, PlaneObs, UpSolution};
use super::{Estimator, LevelEstimate, LevelParams, SurfaceKind, refine};
use crate::level::params::first_pass::*;
use nalgebra::Vector3;

/// Failure detection (sect. 5.5) and the up vector: too few wall quads and no level plane, or
/// a solution the gate refuses. The facing test names the reason of the pipeline's result
/// ([`reported`](super::failure::reported)), this one's or re-segmentation's.
pub(crate) fn solve(
    est: &LevelEstimate,
    levels: &[PlaneFit],
    params: &LevelParams,
    sigma: f64,
) -> Result<UpSolution, FailCause> {
    if est.wall_polygons() < params.min_polygons && levels.is_empty() {
        return Err(FailCause::TooFewPolygons);
    }
    let sigma_eff = sigma.max(params.min_sigma);
    let sol = match params.estimator {
        Estimator::Paper => {
            let walls = est.quads.iter().filter(|q| q.kind == SurfaceKind::Wall);
            let normals: Vec<(Vector3<f64>, f64)> =
                walls.clone().map(|q| (q.fit.normal, q.area)).collect();
            let up = up::up_paper(&normals).ok_or(FailCause::NoUp)?;
            let misfit = |f: &PlaneFit| f.misfit_ratio(sigma_eff).max(1.0);
            let obs: Vec<PlaneObs> = walls
                .map(|q| PlaneObs::wall(&q.fit, misfit(&q.fit)))
                .collect();
            up::solution_at(up, &obs, sigma_eff, false)
        }
        Estimator::Robust => {
            // Wall patches over three or more scans, and the level planes.
            let obs = robust_obs(est, levels, params, sigma);
            if obs.is_empty() {
                return Err(FailCause::NoWallPatches);
            }
            up::up_robust(&obs, sigma_eff, params.iterations).ok_or(FailCause::NoUp)?
        }
    };
    acceptable(&sol, params, !levels.is_empty()).map(|()| sol)
}

/// The robust estimator's observations: wall patches over three or more scans (a plane
/// through two scan lines can be a wall line and a floor line that happen to be coplanar;
/// fewer when the grid has fewer) and the level planes.
pub(crate) fn robust_obs<'a>(
    est: &'a LevelEstimate,
    levels: &'a [PlaneFit],
    params: &LevelParams,
    sigma: f64,
) -> Vec<PlaneObs<'a>> {
    let rows = est.grid.as_ref().map_or(0, PoseGrid::rows);
    let full_rows = params.quad_rows.min(rows).saturating_sub(1);
    est.patches
        .iter()
        .filter(|p| p.kind == SurfaceKind::Wall)
        .filter(|p| p.row_range.1 - p.row_range.0 >= full_rows)
        .map(|p| wall_obs(&p.fit, params, sigma))
        .chain(levels.iter().map(|f| level_obs(f, params, sigma)))
        .collect()
}

/// A wall's plane as evidence of up at range noise `sigma`, its normal's variance widened by
/// how much worse than the noise the plane fits its points.
pub(crate) fn wall_obs<'a>(fit: &'a PlaneFit, params: &LevelParams, sigma: f64) -> PlaneObs<'a> {
    PlaneObs::wall(fit, misfit(fit, params, sigma))
}

/// A floor's or ceiling's plane as evidence of up, widened as a wall's and by
/// `level_inflation` (what cleaning leaves of a wall's foot in it).
pub(crate) fn level_obs<'a>(fit: &'a PlaneFit, params: &LevelParams, sigma: f64) -> PlaneObs<'a> {
    PlaneObs::level(fit, misfit(fit, params, sigma) * params.level_inflation)
}

/// How much worse than the noise `fit` explains its points, at least 1.
fn misfit(fit: &PlaneFit, params: &LevelParams, sigma: f64) -> f64 {
    fit.misfit_ratio(sigma.max(params.min_sigma)).max(1.0)
}

/// Floor and ceiling planes usable as level (when `level_surfaces` is on): each floor or
/// ceiling patch cleaned of the points that do not behave like a level surface, and refitted.
///
/// At high noise a patch grown on the floor can run up the foot of a wall (the two meet within
/// the growing tolerance), and the mixture's plane is tilted by degrees. A level surface is
/// told from a wall by how its range changes from scan to scan in one column: by more than
/// `r de` per elevation step `de` (`r cot(a) de` for a surface seen `a` < 45 degrees off the
/// beams' plane, against `r tan(b) de` on a wall). Only points with such a step to a
/// neighbouring scan, in the patch's prevailing direction, are kept. A patch mostly in one scan
/// line is dropped: it fits that scan's own plane, whose normal is near the robot's z axis
/// whatever the surface. From `level_steep_min_sigma` of noise up, so is a patch on two scan
/// lines only (`LEVEL_MIN_ROWS_NOISY`).
///
/// So each patch's members that step like a level surface ([`level_stepping_members`]) are
/// fitted without those on a steep surface ([`fit_without_steep`]), and the plane is kept when
/// it is near level, explains its points and is opaque ([`level_plane_stands`]: sect. 5.3's
/// floor and ceiling constraints must be real surfaces).
pub fn level_fits(est: &LevelEstimate, params: &LevelParams) -> Vec<PlaneFit> {
    let used = params.level_surfaces && params.estimator == Estimator::Robust;
    let level = |p: &&Patch| p.kind != SurfaceKind::Wall && p.fit.n >= params.min_level_points;
    // Nothing to do (and no steps to take below) without a floor or ceiling patch.
    let used = used && est.patches.iter().any(|p| level(&p));
    let Some(grid) = est.grid.as_ref().filter(|_| used) else {
        return Vec::new();
    };
    let sigma = est.range_sigma.max(params.min_sigma);
    // Signed scan-to-scan range steps in units of `r de` (elevation step `de`), pair `i`
    // joining point `i` to the one above it (`refine::row_pairs`).
    let steps = refine::row_pairs(grid, |i, j| {
        let (a, b) = (grid.points[i].as_ref()?, grid.points[j].as_ref()?);
        let r = grid.row(i);
        let scale = 0.5 * (a.range + b.range) * (grid.elevation[r + 1] - grid.elevation[r]);
        (scale.abs() > 1e-9).then(|| (b.range - a.range) / scale)
    });
    est.patches
        .iter()
        .filter(level)
        .filter_map(|p| {
            let kept = level_stepping_members(grid, p, &steps)?;
            let fit = fit_without_steep(grid, &kept, &steps, sigma, params)?;
            level_plane_stands(grid, &fit, sigma, params).then_some(fit)
        })
        .collect()
}

/// [`Check::LevelMisfit`](super::checks::Check::LevelMisfit): whether a cleaned floor or
/// ceiling plane stands as level evidence of the first solution: near level (within
/// `wall_min_angle_deg` of the robot's z axis), explaining its points within
/// `max_level_misfit` at noise `sigma`, and opaque.
pub(crate) fn level_plane_stands(
    grid: &PoseGrid,
    fit: &PlaneFit,
    sigma: f64,
    params: &LevelParams,
) -> bool {
    fit.normal.z.abs() > params.wall_cos()
        && fit.misfit_ratio(sigma) <= params.max_level_misfit
        && refine::opaque(grid, fit, sigma, params)
}

/// The members of `p` (in its order) whose range steps to the next scan in their column like a
/// level surface's, in the patch's prevailing direction: by more than `r de` per elevation
/// step `de` (`steps`, signed, in units of `r de`), or whose member below does. `None` with
/// fewer than `MIN_LEVEL_STEPS` steps to judge from.
fn level_stepping_members(grid: &PoseGrid, p: &Patch, steps: &[Option<f64>]) -> Option<Vec<usize>> {
    let cols = grid.cols;
    // A mask rather than a binary search: `step` asks several times per member.
    let mut in_patch = vec![false; grid.points.len()];
    for &i in &p.members {
        in_patch[i] = true;
    }
    // A member's step to the member above it.
    let step = |i: usize| {
        steps
            .get(i)
            .copied()
            .flatten()
            .filter(|_| in_patch[i + cols])
    };
    let mut values: Vec<f64> = p.members.iter().filter_map(|&i| step(i)).collect();
    if values.len() < MIN_LEVEL_STEPS {
        return None;
    }
    let sign = super::median_of(&mut values).signum();
    let levelish = |i: usize| step(i).is_some_and(|x| x * sign > 1.0);
    let kept = |i: usize| {
        let from_below = i >= cols && in_patch[i - cols] && levelish(i - cols);
        levelish(i) || from_below
    };
    Some(p.members.iter().copied().filter(|&i| kept(i)).collect())
}

/// The plane of the `kept` members, over at least `min_level_points` points and enough scan
/// lines (`LEVEL_MIN_ROWS_NOISY` from `level_steep_min_sigma` of noise, else 2). From that
/// noise up (or below it on two scan lines only, where a wall's
/// line and a floor line still pass for one plane when parallel), a plane that only the
/// points on a steep surface make, over a fifth of them, is no floor: a floor
/// line and a wall's line at its foot, coplanar within the noise.
fn fit_without_steep(
    grid: &PoseGrid,
    kept: &[usize],
    steps: &[Option<f64>],
    sigma: f64,
    params: &LevelParams,
) -> Option<PlaneFit> {
    let kept_points = || {
        kept.iter()
            .filter_map(|&i| Some((i, grid.points[i].as_ref()?)))
    };
    let mut rows_all = vec![0usize; grid.rows()];
    for (i, _) in kept_points() {
        rows_all[grid.row(i)] += 1;
    }
    let veto = steep_veto(&rows_all, sigma, params);
    // The fit with every kept point, and (for the veto) without those on a steep surface.
    let mut all = PlaneAccumulator::default();
    let mut flat = PlaneAccumulator::default();
    let mut rows_flat = vec![0usize; grid.rows()];
    for (i, g) in kept_points() {
        all.add(g);
        // On a steep surface: its range hardly changes to a neighbouring scan's (member or
        // not; `steps` in units of `r de`). A wall line at the foot of a wall joins a floor
        // patch through the floor line below it (their step is a floor's), but the wall above
        // it gives it away.
        let on_steep = || {
            let (below, above) = refine::row_steps(grid, steps, i);
            [below, above].into_iter().flatten().any(|x| x.abs() <= 1.0)
        };
        if veto && !on_steep() {
            flat.add(g);
            rows_flat[grid.row(i)] += 1;
        }
    }
    let usable = |acc: &PlaneAccumulator, per_row: &[usize]| {
        enough_for_level(acc.n, per_row, sigma, params)
            .then(|| acc.fit(sigma))
            .flatten()
    };
    let fit = usable(&all, &rows_all)?;
    let steep = if veto { all.n - flat.n } else { 0 };
    let vetoed =
        steep > 0 && usable(&flat, &rows_flat).is_none() && STEEP_SHARE_INV * steep > all.n;
    (!vetoed).then_some(fit)
}

/// [`Check::LevelMinPoints`](super::checks::Check::LevelMinPoints) and
/// [`Check::LevelMinRowsNoisy`](super::checks::Check::LevelMinRowsNoisy): whether `points`
/// points, `per_row` of them in each scan line, are enough for a level plane at noise `sigma`:
/// `min_level_points`, over `LEVEL_MIN_ROWS_NOISY` scan lines from `level_steep_min_sigma` of
/// noise up, else two.
pub(crate) fn enough_for_level(
    points: usize,
    per_row: &[usize],
    sigma: f64,
    params: &LevelParams,
) -> bool {
    let noisy = sigma >= params.level_steep_min_sigma;
    let min_rows = if noisy { LEVEL_MIN_ROWS_NOISY } else { 2 };
    points >= params.min_level_points
        && refine::supported_rows(per_row, LEVEL_ROW_SHARE) >= min_rows
}

/// [`Check::LevelSteepVeto`](super::checks::Check::LevelSteepVeto): whether a level plane with
/// `per_row` points in each scan line at noise `sigma` must survive without its points on a
/// steep surface ([`fit_without_steep`]): from `level_steep_min_sigma` up, and below it on
/// fewer than `LEVEL_MIN_ROWS_NOISY` scan lines.
pub(crate) fn steep_veto(per_row: &[usize], sigma: f64, params: &LevelParams) -> bool {
    sigma >= params.level_steep_min_sigma
        || refine::supported_rows(per_row, LEVEL_ROW_SHARE) < LEVEL_MIN_ROWS_NOISY
}
