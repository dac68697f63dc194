//! Re-segmentation's driver (after sect. 9): which solutions it starts from, which refined
//! solution is kept and gated, and how the kept solution's covariance is widened when two
//! readings of the same ranges disagree. The engine is [`refine`](super::refine).

use super::attitude::attitude_sigmas;
use super::checks::Check;
use super::failure::{FailCause, acceptable, acceptable_within};
use super::first_pass::robust_obs;
use super::grid::{PlaneFit, PoseGrid};
use super::patches::Patch;
use super::up::{self, UpSolution, mahalanobis2};
use super::{Estimator, LevelEstimate, LevelParams, SurfaceKind, refine};
use crate::level::params::resegment::*;

/// The solution of a pose after re-segmentation (robust estimator, `refine_passes` > 0): a
/// first solution pinned down to `refine_above_sigma_deg` stands; otherwise the refined one
/// replaces it when it passes the gate, and the kept one is widened by its distance from the
/// other ([`widened_against_first`], [`widened_unconfirmed`], [`widened_from_start`]) and gated
/// again. With it, the refined segmentation's models when the solution kept is the refined one.
pub(crate) fn resegmented(
    est: &LevelEstimate,
    levels: &[PlaneFit],
    first: Result<UpSolution, FailCause>,
    params: &LevelParams,
) -> (Result<UpSolution, FailCause>, Option<Vec<refine::Model>>) {
    if params.estimator != Estimator::Robust
        || params.refine_passes == 0
        || !needs_refine(&first, params)
    {
        return (first, None);
    }
    let Some(re) = refine_estimate(est, levels, &first, params) else {
        return (first, None);
    };
    // The solution kept and the distance that widens it: the refined one's from the first,
    // or from where it started when it stands alone; else the first's from the refined one.
    let accepted = refined_solution(est, &re.refined, &re.rivals, params);
    let (kept, widened) = match (accepted, &first) {
        (Some(kept), Ok(first)) => (kept, widened_against_first(&kept, first)),
        (Some(kept), Err(_)) => (kept, widened_from_start(&kept, &re.start)),
        (None, Ok(first)) => (*first, widened_unconfirmed(first, &re.refined.solution)),
        (None, Err(_)) => return (first, None),
    };
    let result = match widened {
        // Only its sigma changed: the walls' spread was judged already.
        Some(widened) => acceptable(&widened, params, true)
            .map(|()| widened)
            .map_err(|_| FailCause::ResegmentationDisagrees),
        None => Ok(kept),
    };
    (result, accepted.map(|_| re.refined.models))
}

/// [`Check::RefineAboveSigma`]: whether the first solution is re-segmented: when it failed,
/// or when either reported sigma exceeds `refine_above_sigma_deg`.
pub(crate) fn needs_refine(first: &Result<UpSolution, FailCause>, params: &LevelParams) -> bool {
    first.as_ref().map_or(true, |sol| {
        attitude_sigmas(sol, params)
            .iter()
            .any(|s| s.to_degrees() > Check::RefineAboveSigma.threshold(params))
    })
}

/// [`Check::StartMaxSigma`]: whether re-segmentation may start from `start`. From a start
/// looser than that, it can settle on a wrong but self-consistent set of planes (a pose 16
/// degrees off at the start, 23 degrees of sigma, ended 7 degrees off with sigmas near one
/// degree); it rescues almost nothing from there.
pub(crate) fn start_tight_enough(start: &UpSolution, params: &LevelParams) -> bool {
    start.max_attitude_sigma() <= Check::StartMaxSigma.threshold(params)
}

/// [`Check::LineMaxSigma`]: whether a refined solution that uses floor or ceiling lines
/// passes the stricter gate of `level_line_max_sigma_deg` (and `max_sigma_deg`).
pub(crate) fn passes_line_gate(sol: &UpSolution, params: &LevelParams) -> bool {
    let strict = Check::MaxSigma
        .threshold(params)
        .min(Check::LineMaxSigma.threshold(params));
    acceptable_within(sol, params, true, strict).is_ok()
}

/// Re-segmentation in the provisional level frame ([`refine`]): its start, its refined model
/// (not yet gated), and the other starts' refined solutions that pass the gate.
pub struct Resegmented {
    pub start: UpSolution,
    pub refined: refine::Refined,
    pub rivals: Vec<UpSolution>,
}

/// Re-segmentation in the provisional level frame ([`refine`]), started from the solution
/// found (`first`), or, when the gate refused it, from every start found without a level frame
/// (`blind_starts`): of their refined models, the one that pins up down best is kept, and
/// the others that pass the gate are its rivals. `None` when there is nothing to start from or
/// no refined model fixes up.
///
/// One start can settle on a wrong but self-consistent set of planes that another start does
/// not: traced, 12 scans of a cleverRobot pose, where the ungated solution (25 degrees off)
/// refined to one 15 degrees off with sigmas under one degree, and the walls with the floor's
/// lines (1 degree off) refined to one 1.2 degrees off, as tight.
pub fn refine_estimate(
    est: &LevelEstimate,
    levels: &[PlaneFit],
    first: &Result<UpSolution, FailCause>,
    params: &LevelParams,
) -> Option<Resegmented> {
    let grid = est.grid.as_ref()?;
    let sigma = est.range_sigma;
    let steps = refine::level_steps(grid, params, sigma);
    let starts = match first {
        Ok(sol) => vec![*sol],
        Err(_) => blind_starts(est, grid, levels, &steps, params),
    };
    let wall = |p: &Patch| (p.kind == SurfaceKind::Wall).then_some(p.fit);
    let walls: Vec<PlaneFit> = est.patches.iter().filter_map(wall).collect();
    let mut refined: Vec<(UpSolution, refine::Refined)> = starts
        .into_iter()
        .filter(|start| start_tight_enough(start, params))
        .filter_map(|start| {
            refine::refine(grid, &start, &walls, &steps, params, sigma).map(|r| (start, r))
        })
        .collect();
    let sigma_of = |k: usize| refined[k].1.solution.max_attitude_sigma();
    let best = (0..refined.len()).min_by(|&a, &b| sigma_of(a).total_cmp(&sigma_of(b)))?;
    let (start, kept) = refined.swap_remove(best);
    let rivals = refined
        .into_iter()
        .map(|(_, r)| r.solution)
        .filter(|r| acceptable(r, params, true).is_ok())
        .collect();
    Some(Resegmented {
        start,
        refined: kept,
        rivals,
    })
}

/// Starts of re-segmentation found without a level frame, for a pose whose first solution
/// failed the gate: the ungated robust solution; the walls with the floor's or ceiling's
/// lines (walls that cannot fix up alone, as one wall split into patches, leave up free to
/// turn about their normal); a floor or ceiling found by its range steps alone; and walls of
/// one family with the height their free angle puts most other points at
/// ([`refine::swept_start`]).
pub(crate) fn blind_starts(
    est: &LevelEstimate,
    grid: &PoseGrid,
    levels: &[PlaneFit],
    steps: &refine::LevelSteps,
    params: &LevelParams,
) -> Vec<UpSolution> {
    let sigma = est.range_sigma;
    let sigma_eff = sigma.max(params.min_sigma);
    let obs = robust_obs(est, levels, params, sigma);
    let walls = up::up_robust(&obs, sigma_eff, params.iterations);
    let with_lines = (params.level_lines && params.level_surfaces)
        .then(|| refine::start_lines(grid, steps, params, sigma))
        .filter(|lines| !lines.is_empty())
        .and_then(|lines| {
            let (mut obs, inflate) = (obs.clone(), params.level_line_inflation);
            obs.extend(lines.iter().map(|l| up::PlaneObs::level_line(l, inflate)));
            up::up_robust(&obs, sigma_eff, params.iterations)
        });
    let level = refine::level_start(grid, steps, params, sigma);
    // Walls of one family leave one angle of up free: swept for a floor or ceiling.
    let swept = refine::swept_start(grid, &est.patches, &est.labels, params, sigma);
    [walls, with_lines, level, swept]
        .into_iter()
        .flatten()
        .collect()
}

/// The solution of the `refined` model when it passes the gate, widened by its distance from
/// `rivals` that pass as well ([`refine_estimate`]). When it does not, the first stands: the
/// refined model sometimes keeps fewer points (ambiguous ones are left out), and letting its
/// verdict overrule a first solution that passed failed 4-8% more poses at 10 cm for a
/// small gain in the mean error (0.43 to 0.36 degrees at 5 scans).
pub(crate) fn refined_solution(
    est: &LevelEstimate,
    refined: &refine::Refined,
    rivals: &[UpSolution],
    params: &LevelParams,
) -> Option<UpSolution> {
    let level_models = refined.models.iter().any(|m| m.kind != SurfaceKind::Wall);
    // Lines alone leave each direction of up to single lines, with nothing to check them
    // against: traced on a zigzag wall at 10 cm, three floor lines (no wall kept) leveled a
    // pose 9.5 degrees off with a sigma of 0.3, one of them 5 degrees off level, running onto
    // a wall's foot. Over 405,000 protocol poses at 1-10 cm (seeds 101-150, nine plans), no
    // other pose was leveled that way.
    let accepted = if refined.models.is_empty() {
        None
    } else if refined.lines.is_empty() {
        acceptable(&refined.solution, params, level_models)
            .is_ok()
            .then_some(refined.solution)
    } else if passes_line_gate(&refined.solution, params) {
        // A line pins up down across it only: the other direction rests on the walls that
        // alone could not pass the gate, so it is held to a stricter one; failing that, the
        // models without the lines are gated as usual.
        Some(refined.solution)
    } else {
        refined
            .without_lines(params, est.range_sigma)
            .filter(|w| acceptable(w, params, level_models).is_ok())
    };
    // Another start's re-segmentation that passes the gate as well but lies far from this
    // one: two self-consistent readings of the pose, and which one is right is not known.
    accepted.and_then(|a| {
        let widened = rivals.iter().fold(a, |kept, rival| {
            widened_by_disagreement(&kept, rival).unwrap_or(kept)
        });
        acceptable(&widened, params, true)
            .is_ok()
            .then_some(widened)
    })
}

/// The re-segmented solution `kept`, widened by its disagreement with the first solution
/// ([`widened_by_disagreement`]) unless it is [`TIGHTER_THAN_FIRST`] times tighter: then the
/// re-segmentation found evidence that the first did not use (traced: a floor plane), and their
/// distance is the first's error, not doubt about which reading is right.
pub(crate) fn widened_against_first(kept: &UpSolution, first: &UpSolution) -> Option<UpSolution> {
    if kept.max_attitude_sigma() * TIGHTER_THAN_FIRST <= first.max_attitude_sigma() {
        return None;
    }
    widened_by_disagreement(kept, first)
}

/// `kept` with its covariance widened by its distance from `other` when the two disagree
/// beyond [`DISAGREEMENT_SIGMAS`] of their joint uncertainty; `None` when they agree. The
/// first solution and the re-segmented one rest on nearly the same ranges, so they can only
/// disagree that much when one of them rests on a wrong segmentation, and which one is not
/// known: traced poses ended 5-7 degrees off either way, with sigmas near one degree.
pub(crate) fn widened_by_disagreement(kept: &UpSolution, other: &UpSolution) -> Option<UpSolution> {
    let joint = kept.cov + other.cov_in(&kept.basis);
    widened_beyond(kept, other, joint, DISAGREEMENT_SIGMAS)
}

/// `kept`, the first solution, with its covariance widened by its distance from `other`, a
/// re-segmentation that could not pass the gate, when that distance exceeds
/// [`UNCONFIRMED_SIGMAS`] of the first solution's own uncertainty; `None` otherwise. Such a
/// re-segmentation is too loose to test the first solution against their joint uncertainty,
/// yet landing that far off means the first solution's planes were not the ones seen in its
/// own level frame. Traced, 13 of 17 poses reported ok and 5-7 degrees off (75,600 protocol
/// poses at 5-10 cm) were first solutions whose re-segmentation failed the gate; 11 of those
/// lay 2-18 degrees away, most of them nearer the truth, with sigmas of 1-1.5 degrees.
pub(crate) fn widened_unconfirmed(kept: &UpSolution, other: &UpSolution) -> Option<UpSolution> {
    widened_beyond(kept, other, kept.cov, UNCONFIRMED_SIGMAS)
}

/// `kept`, a refined solution that passed the gate where the first solution had failed, with
/// its covariance widened by its distance from the solution re-segmentation started from when
/// that exceeds [`FROM_START_SIGMAS`] of the start's own uncertainty. The start (one of
/// [`blind_starts`]) seeded the re-segmentation; landing that far
/// from it means its planes were wrong, and a segmentation grown from them is in doubt too.
/// Traced: a start 11 degrees off with sigmas of 1.6-1.8 degrees led to a refined solution 6
/// degrees off with sigmas under one degree.
pub(crate) fn widened_from_start(kept: &UpSolution, start: &UpSolution) -> Option<UpSolution> {
    widened_beyond(kept, start, start.cov_in(&kept.basis), FROM_START_SIGMAS)
}

/// `kept` with `d d^T` added to its covariance, for `d` its distance from `other` in its tangent
/// plane, when `d` lies beyond `sigmas` of `spread` (a covariance in `kept`'s basis).
pub(crate) fn widened_beyond(
    kept: &UpSolution,
    other: &UpSolution,
    spread: nalgebra::Matrix2<f64>,
    sigmas: f64,
) -> Option<UpSolution> {
    let d = kept.offset_to(&other.up);
    let z2 = mahalanobis2(&d, &spread)?;
    (z2 > sigmas * sigmas).then(|| UpSolution {
        cov: kept.cov + d * d.transpose(),
        ..*kept
    })
}
