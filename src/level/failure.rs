//! Failure detection (sect. 5.5): the gate every solution passes, first or refined. A pose
//! fails when up is not pinned down in both directions, when its sigmas exceed
//! `max_sigma_deg`, or when up lies beyond `wall_min_angle_deg` of the robot's z axis; the
//! facing test ([`reported`]) names the reason of every refusal, first or refined. Each cause
//! is told apart inside ([`FailCause`]) and mapped, here only, to the contract's reasons.

use super::checks::Check;
use super::up::UpSolution;
use super::{FailReason, LevelEstimate, LevelParams, attitude::attitude_sigmas};
use nalgebra::Vector3;

/// Why a pose could not be leveled, each cause on its own. The output speaks only the
/// contract's reasons ([`FailCause::reason`], the one place they are mapped); the cause is kept
/// beside it in [`LevelEstimate::cause`] for tracing and statistics.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FailCause {
    /// Fewer than three distinct scan elevations.
    TooFewScans,
    /// Scans of different bearings.
    InconsistentScans,
    /// Fewer than `min_polygons` wall quads and no level plane.
    TooFewPolygons,
    /// Robust estimator: no wall patch over enough scan lines and no level plane.
    NoWallPatches,
    /// Refused, and floor quads outnumber wall quads (and ceiling quads).
    FacingFloor,
    /// Refused, and ceiling quads outnumber wall quads.
    FacingCeiling,
    /// The estimator found no up at all from the walls (their cross products or normals
    /// span no direction).
    NoUp,
    /// Walls only, and all parallel: up's information has a direction below
    /// `parallel_ratio` of the other.
    WallsParallel,
    /// Up beyond `wall_min_angle_deg` of the robot's z axis.
    BeyondWallAngle,
    /// An attitude sigma above `max_sigma_deg`.
    SigmaAboveGate,
    /// The re-segmented and the first solution (or the refined one and its start) disagree:
    /// the kept one, widened by their distance, has a sigma above `max_sigma_deg`.
    ResegmentationDisagrees,
    /// The last stage's fit of the same segmentation left the leveler's answer (it failed the
    /// gate), and the leveler's answer, widened by their distance, has a sigma above
    /// `max_sigma_deg`.
    LastStageDisagrees,
}

impl FailCause {
    /// The contract's reason for this cause.
    pub fn reason(self) -> FailReason {
        match self {
            FailCause::TooFewScans => FailReason::TooFewScans,
            FailCause::InconsistentScans => FailReason::InconsistentScans,
            FailCause::TooFewPolygons | FailCause::NoWallPatches => FailReason::TooFewPolygons,
            FailCause::FacingFloor => FailReason::FacingFloor,
            FailCause::FacingCeiling => FailReason::FacingCeiling,
            FailCause::NoUp
            | FailCause::WallsParallel
            | FailCause::BeyondWallAngle
            | FailCause::SigmaAboveGate
            | FailCause::ResegmentationDisagrees
            | FailCause::LastStageDisagrees => FailReason::ParallelWalls,
        }
    }

    /// The cause's name (snake case), for traces; not an output reason.
    pub fn as_str(self) -> &'static str {
        match self {
            FailCause::TooFewScans => "too_few_scans",
            FailCause::InconsistentScans => "inconsistent_scans",
            FailCause::TooFewPolygons => "too_few_polygons",
            FailCause::NoWallPatches => "no_wall_patches",
            FailCause::FacingFloor => "facing_floor",
            FailCause::FacingCeiling => "facing_ceiling",
            FailCause::NoUp => "no_up",
            FailCause::WallsParallel => "walls_parallel",
            FailCause::BeyondWallAngle => "beyond_wall_angle",
            FailCause::SigmaAboveGate => "sigma_above_gate",
            FailCause::ResegmentationDisagrees => "resegmentation_disagrees",
            FailCause::LastStageDisagrees => "last_stage_disagrees",
        }
    }
}

/// The parallel-walls test: up must be pinned down in both tangent directions.
///
/// The eigenvalue-ratio test speaks of walls: with a level plane in the fit, up is pinned in
/// both directions however unequal they are, and only the sigma test applies.
pub(crate) fn acceptable(
    sol: &UpSolution,
    params: &LevelParams,
    with_level: bool,
) -> Result<(), FailCause> {
    acceptable_within(sol, params, with_level, Check::MaxSigma.threshold(params))
}

/// [`acceptable`] with the sigma gate at `max_sigma_deg` instead of the parameters' own.
pub(crate) fn acceptable_within(
    sol: &UpSolution,
    params: &LevelParams,
    with_level: bool,
    max_sigma_deg: f64,
) -> Result<(), FailCause> {
    let (lo, hi) = sol.info_eigenvalues;
    if hi.is_nan() || hi <= 0.0 || (!with_level && lo < Check::ParallelRatio.threshold(params) * hi)
    {
        return Err(FailCause::WallsParallel);
    }
    if !within_wall_angle(&sol.up, params) {
        return Err(FailCause::BeyondWallAngle);
    }
    let s = attitude_sigmas(sol, params);
    let max_sigma = max_sigma_deg.to_radians();
    let within = s[0] <= max_sigma && s[1] <= max_sigma;
    within.then_some(()).ok_or(FailCause::SigmaAboveGate)
}

/// Whether up lies within `wall_min_angle_deg` of the robot's z axis. Walls, floors and
/// ceilings were told apart by that angle (sect. 5.2: floors slope less than 45 degrees), so an
/// up tilted beyond it contradicts the segmentation it came from: the floor would have been
/// taken for a wall. Re-segmentation from a blind start once settled on a floor and a wall's
/// top as one "wall" and leveled a pose 55 degrees off (361 rays, 10 cm noise).
pub(crate) fn within_wall_angle(up: &Vector3<f64>, params: &LevelParams) -> bool {
    up.z >= params.wall_cos()
}

/// The cause a pose refused by any gate is reported with: facing the floor / ceiling when
/// floor or ceiling quads outnumber wall quads ([`LevelEstimate::facing`], sect. 5.5), else
/// `cause`. The scanner looks at the wrong surface and a robot can retake its scans tilted the
/// other way (sect. 7.2.2), whichever solution was refused: applied once to the pipeline's
/// result, so a solution refused after re-segmentation is named as a first one is.
pub(crate) fn reported(est: &LevelEstimate, cause: FailCause) -> FailCause {
    match est.facing() {
        Some(FailReason::FacingFloor) => FailCause::FacingFloor,
        Some(FailReason::FacingCeiling) => FailCause::FacingCeiling,
        _ => cause,
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use nalgebra::Matrix2;

    /// Up tilted by `deg` about the robot's x axis, with a 1-sigma of `sigma` \[rad\] both ways
    /// and information eigenvalues `info` (also the check tests' fixture).
    pub(crate) fn solution(deg: f64, sigma: f64, info: (f64, f64)) -> UpSolution {
        let a = deg.to_radians();
        let up = Vector3::new(0.0, -a.sin(), a.cos());
        UpSolution {
            up,
            basis: [Vector3::x(), up.cross(&Vector3::x())],
            cov: Matrix2::identity() * sigma * sigma,
            info_eigenvalues: info,
        }
    }

    /// Each way the gate refuses a solution is its own cause, all reported as parallel_walls.
    #[test]
    fn the_gate_names_each_cause() {
        let p = LevelParams::default();
        let walls = |sol: &UpSolution| acceptable(sol, &p, false);
        assert_eq!(
            walls(&solution(5.0, 0.1f64.to_radians(), (1.0, 1.0))),
            Ok(())
        );
        assert_eq!(
            walls(&solution(5.0, 0.1f64.to_radians(), (1e-4, 1.0))),
            Err(FailCause::WallsParallel)
        );
        // With a level plane, unequal directions are no refusal.
        assert_eq!(
            acceptable(&solution(5.0, 0.1f64.to_radians(), (1e-4, 1.0)), &p, true),
            Ok(())
        );
        assert_eq!(
            walls(&solution(5.0, 0.1f64.to_radians(), (f64::NAN, f64::NAN))),
            Err(FailCause::WallsParallel)
        );
        assert_eq!(
            walls(&solution(50.0, 0.1f64.to_radians(), (1.0, 1.0))),
            Err(FailCause::BeyondWallAngle)
        );
        assert_eq!(
            walls(&solution(5.0, 2.0f64.to_radians(), (1.0, 1.0))),
            Err(FailCause::SigmaAboveGate)
        );
        for c in [
            FailCause::NoUp,
            FailCause::WallsParallel,
            FailCause::BeyondWallAngle,
            FailCause::SigmaAboveGate,
            FailCause::ResegmentationDisagrees,
        ] {
            assert_eq!(c.reason(), FailReason::ParallelWalls, "{c:?}");
        }
    }

    /// Every cause maps to one of the contract's reasons (CONTRACT.md, `level.reason`), the
    /// output's whole vocabulary, and every reason has a cause.
    #[test]
    fn causes_map_onto_the_contracts_reasons() {
        let contract = [
            "too_few_scans",
            "inconsistent_scans",
            "too_few_polygons",
            "facing_floor",
            "facing_ceiling",
            "parallel_walls",
        ];
        let causes = [
            FailCause::TooFewScans,
            FailCause::InconsistentScans,
            FailCause::TooFewPolygons,
            FailCause::NoWallPatches,
            FailCause::FacingFloor,
            FailCause::FacingCeiling,
            FailCause::NoUp,
            FailCause::WallsParallel,
            FailCause::BeyondWallAngle,
            FailCause::SigmaAboveGate,
            FailCause::ResegmentationDisagrees,
        ];
        let reasons: Vec<&str> = causes.iter().map(|c| c.reason().as_str()).collect();
        for r in &reasons {
            assert!(contract.contains(r), "{r}");
        }
        for r in contract {
            assert!(reasons.contains(&r), "{r}");
        }
        assert_eq!(
            FailCause::NoWallPatches.reason(),
            FailReason::TooFewPolygons
        );
    }
}
