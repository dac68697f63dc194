//! Failure detection (sect. 5.5): the gate every solution passes, first or refined. A pose
//! fails as `parallel_walls` when up is not pinned down in both directions, when its sigmas
//! exceed `max_sigma_deg`, or when up lies beyond `wall_min_angle_deg` of the robot's z axis;
//! the facing test ([`reported`]) names the reason of every refusal, first or refined.

use super::checks::Check;
use super::up::UpSolution;
use super::{FailReason, LevelEstimate, LevelParams};
use nalgebra::Vector3;

/// The reported 1-sigma of theta_x and theta_y \[rad\]: the propagated covariance, scaled by
/// `sigma_inflation`.
pub(crate) fn attitude_sigmas(sol: &UpSolution, params: &LevelParams) -> [f64; 2] {
    sol.attitude_sigmas().map(|s| s * params.sigma_inflation)
}

/// The parallel-walls test: up must be pinned down in both tangent directions.
///
/// The eigenvalue-ratio test speaks of walls: with a level plane in the fit, up is pinned in
/// both directions however unequal they are, and only the sigma test applies.
pub(crate) fn acceptable(
    sol: &UpSolution,
    params: &LevelParams,
    with_level: bool,
) -> Result<(), FailReason> {
    acceptable_within(sol, params, with_level, Check::MaxSigma.threshold(params))
}

/// [`acceptable`] with the sigma gate at `max_sigma_deg` instead of the parameters' own.
pub(crate) fn acceptable_within(
    sol: &UpSolution,
    params: &LevelParams,
    with_level: bool,
    max_sigma_deg: f64,
) -> Result<(), FailReason> {
    let (lo, hi) = sol.info_eigenvalues;
    if hi.is_nan() || hi <= 0.0 || (!with_level && lo < Check::ParallelRatio.threshold(params) * hi)
    {
        return Err(FailReason::ParallelWalls);
    }
    if !within_wall_angle(&sol.up, params) {
        return Err(FailReason::ParallelWalls);
    }
    let s = attitude_sigmas(sol, params);
    let max_sigma = max_sigma_deg.to_radians();
    if !(s[0] <= max_sigma && s[1] <= max_sigma) {
        return Err(FailReason::ParallelWalls);
    }
    Ok(())
}

/// Whether up lies within `wall_min_angle_deg` of the robot's z axis. Walls, floors and
/// ceilings were told apart by that angle (sect. 5.2: floors slope less than 45 degrees), so an
/// up tilted beyond it contradicts the segmentation it came from: the floor would have been
/// taken for a wall. Re-segmentation from a blind start once settled on a floor and a wall's
/// top as one "wall" and leveled a pose 55 degrees off (361 rays, 10 cm noise).
pub(crate) fn within_wall_angle(up: &Vector3<f64>, params: &LevelParams) -> bool {
    up.z >= params.wall_cos()
}

/// The reason a pose refused by any gate is reported with: facing_floor / facing_ceiling when
/// floor or ceiling quads outnumber wall quads ([`LevelEstimate::facing`], sect. 5.5), else
/// `reason`. The scanner looks at the wrong surface and a robot can retake its scans tilted the
/// other way (sect. 7.2.2), whichever solution was refused: applied once to the pipeline's
/// result, so a solution refused after re-segmentation is named as a first one is (it was
/// reported as parallel_walls).
pub(crate) fn reported(est: &LevelEstimate, reason: FailReason) -> FailReason {
    est.facing().unwrap_or(reason)
}
