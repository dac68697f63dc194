//! Every accept/reject rule of level estimation in one table ([`CHECKS`]): its name, the stage
//! that applies it, what it tests, its threshold (read from [`LevelParams`] or the stage's fixed
//! constants in [`params`](super::params)), and what failing it does: fail the pose with one of
//! the contract's reasons (sect. 5.5), or drop, widen or keep back a candidate (a quad, a patch,
//! a level plane or line, a solution). The gates of sect. 5.5 and of re-segmentation read their
//! thresholds through [`Check::threshold`], so the table is what the code applies.

use super::grid::PlaneFit;
use super::params::{first_pass, patches, quads, refine, resegment, up};
use super::{FailReason, LevelParams};
use nalgebra::{Point3, Vector3};

/// The stage that applies a check, in pipeline order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    /// The grid of robot-frame points (sect. 5.1, `grid`).
    Grid,
    /// The paper's quads (sect. 5.2, `polygons`).
    Quads,
    /// Region growing, splits and trims (after sect. 9, `patches`).
    Patches,
    /// The floor and ceiling planes of the first solution (sect. 5.3, `first_pass`).
    LevelSurfaces,
    /// The gate every solution passes (sect. 5.5, `failure`, `first_pass`).
    Gate,
    /// Re-segmentation's driver: starts, choice and widening (`resegment`).
    Resegment,
    /// Re-segmentation's engine: walls, floors, ceilings and their lines (`refine`).
    Refine,
}

/// What failing a check does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outcome {
    /// The pose fails with this reason (the contract's).
    Fails(FailReason),
    /// The named candidate is dropped (or, for a gate on a candidate solution, not used).
    Drops(&'static str),
    /// The kept solution's covariance takes in its distance from another.
    Widens,
}

/// The named checks; [`CHECKS`] holds one row for each, in this order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Check {
    TooFewScans,
    InconsistentScans,
    QuadCoplanar,
    QuadNearTriangle,
    QuadDiagonal,
    PatchMinPoints,
    PatchStacked,
    PatchTooBent,
    PatchBentAcrossRows,
    PatchEdgeRow,
    PatchTrimmedRows,
    PatchFrontRun,
    PatchSplitMisfit,
    PatchSplitF,
    LevelMinPoints,
    LevelMisfit,
    LevelMinRowsNoisy,
    LevelSteepVeto,
    LevelOpaque,
    MinPolygons,
    Facing,
    ParallelRatio,
    WallAngle,
    MaxSigma,
    RefineAboveSigma,
    StartMaxSigma,
    LineMaxSigma,
    Disagreement,
    TighterThanFirst,
    Unconfirmed,
    FromStart,
    RefinedWallRows,
    RefinedLevelAngle,
    RefinedLevelMisfit,
    RefinedClearOfScanner,
    LineMinPoints,
    LineMisfit,
    LinesPlaneMisfit,
    CeilingBandSteps,
    MaxTilt,
}

/// One row of the table.
pub struct Spec {
    pub check: Check,
    pub stage: Stage,
    /// The threshold's unit (`1` for a ratio or a count of sigmas).
    pub unit: &'static str,
    pub threshold: fn(&LevelParams) -> f64,
    pub outcome: Outcome,
    /// What it tests, and where.
    pub tests: &'static str,
}

use Check as C;
use FailReason as F;
use Outcome::{Drops, Fails, Widens};
use Stage as S;

/// Every accept/reject rule, one row per [`Check`] in its order.
#[rustfmt::skip]
pub const CHECKS: &[Spec] = &[
    Spec { check: C::TooFewScans, stage: S::Grid, unit: "scans", threshold: |_| 3.0, outcome: Fails(F::TooFewScans),
        tests: "at least three distinct scan elevations (grid::PoseGrid::from_scans_with)" },
    Spec { check: C::InconsistentScans, stage: S::Grid, unit: "rays", threshold: |_| 0.0, outcome: Fails(F::InconsistentScans),
        tests: "every scan has the same bearings (grid::PoseGrid::from_scans_with)" },
    Spec { check: C::QuadCoplanar, stage: S::Quads, unit: "sigma", threshold: |p| p.coplanar_k, outcome: Drops("quad"),
        tests: "every point of a quad within coplanar_k sigmas of its plane (polygons::quad_at)" },
    Spec { check: C::QuadNearTriangle, stage: S::Quads, unit: "1", threshold: |p| p.min_edge_ratio, outcome: Drops("quad"),
        tests: "the shorter of opposite sides over the longer (polygons::quad_at)" },
    Spec { check: C::QuadDiagonal, stage: S::Quads, unit: "tolerances", threshold: |_| quads::DIAGONAL_PLANE_TOLERANCES, outcome: Drops("quad"),
        tests: "each diagonal half's corner off the other half's plane: a corner or an edge (polygons::quad_at)" },
    Spec { check: C::PatchMinPoints, stage: S::Patches, unit: "points", threshold: |p| p.min_patch_points as f64, outcome: Drops("patch"),
        tests: "a patch's points, over at least two rows (patches::make_patch)" },
    Spec { check: C::PatchStacked, stage: S::Patches, unit: "1", threshold: |p| p.min_stacked_share, outcome: Drops("patch"),
        tests: "share of members with a member in an adjacent row of their column (patches::split::stacked)" },
    Spec { check: C::PatchTooBent, stage: S::Patches, unit: "1", threshold: |p| p.max_misfit_sigmas, outcome: Drops("patch"),
        tests: "a small patch's misfit beyond 1 + k sqrt(2 / dof) (patches::split::too_bent_to_split)" },
    Spec { check: C::PatchBentAcrossRows, stage: S::Patches, unit: "1", threshold: |p| p.max_row_bend_sigmas, outcome: Drops("patch"),
        tests: "rows' mean residuals, chi2 / dof beyond 1 + k sqrt(2 / dof) (patches::split::bent_across_rows)" },
    Spec { check: C::PatchEdgeRow, stage: S::Patches, unit: "sigma", threshold: |p| p.trim_sigmas, outcome: Drops("edge row, or a three-row patch"),
        tests: "an edge row's mean residual from the other rows' plane (patches::trim::trim_edge_rows)" },
    Spec { check: C::PatchTrimmedRows, stage: S::Patches, unit: "1", threshold: |_| patches::MIN_TRIMMED_ROW_SHARE, outcome: Drops("trim"),
        tests: "each of three adjacent rows left after a trim holds this share of the points (patches::trim)" },
    Spec { check: C::PatchFrontRun, stage: S::Patches, unit: "sigma", threshold: |p| p.front_end_sigmas, outcome: Drops("run at a row's end"),
        tests: "a run of at least MIN_FRONT_RUN points in front of the plane (patches::trim::without_front_row_ends)" },
    Spec { check: C::PatchSplitMisfit, stage: S::Patches, unit: "1", threshold: |p| p.split_misfit, outcome: Drops("unsplit patch"),
        tests: "a patch's misfit ratio above which it is tested for two planes (patches::grow_patches)" },
    Spec { check: C::PatchSplitF, stage: S::Patches, unit: "1", threshold: |p| p.split_f, outcome: Drops("unsplit patch"),
        tests: "F statistic of two planes against one (patches::split::split_members)" },
    Spec { check: C::LevelMinPoints, stage: S::LevelSurfaces, unit: "points", threshold: |p| p.min_level_points as f64, outcome: Drops("level plane"),
        tests: "a floor or ceiling plane's points (first_pass::level_fits, refine)" },
    Spec { check: C::LevelMisfit, stage: S::LevelSurfaces, unit: "1", threshold: |p| p.max_level_misfit, outcome: Drops("level plane"),
        tests: "a cleaned floor or ceiling patch's misfit ratio (first_pass::clean_level_fit)" },
    Spec { check: C::LevelMinRowsNoisy, stage: S::LevelSurfaces, unit: "scans", threshold: |_| first_pass::LEVEL_MIN_ROWS_NOISY as f64, outcome: Drops("level plane"),
        tests: "scan lines of a level plane from level_steep_min_sigma of noise (first_pass::fit_without_steep)" },
    Spec { check: C::LevelSteepVeto, stage: S::LevelSurfaces, unit: "m", threshold: |p| p.level_steep_min_sigma, outcome: Drops("level plane"),
        tests: "noise from which a plane only points on a steep surface make is vetoed (first_pass::fit_without_steep)" },
    Spec { check: C::LevelOpaque, stage: S::LevelSurfaces, unit: "points", threshold: |_| refine::MAX_BEYOND as f64, outcome: Drops("level plane"),
        tests: "points seen beyond a floor or ceiling (refine::opaque)" },
    Spec { check: C::MinPolygons, stage: S::Gate, unit: "quads", threshold: |p| p.min_polygons as f64, outcome: Fails(F::TooFewPolygons),
        tests: "wall quads when no level plane is seen; facing_* when Facing holds (first_pass::solve)" },
    Spec { check: C::Facing, stage: S::Gate, unit: "quads", threshold: |_| 0.0, outcome: Fails(F::FacingFloor),
        tests: "floor (ceiling: facing_ceiling) quads outnumber wall quads, for a pose that fails (LevelEstimate::facing)" },
    Spec { check: C::ParallelRatio, stage: S::Gate, unit: "1", threshold: |p| p.parallel_ratio, outcome: Fails(F::ParallelWalls),
        tests: "smaller over larger eigenvalue of up's information, walls only (failure::acceptable_within)" },
    Spec { check: C::WallAngle, stage: S::Gate, unit: "deg", threshold: |p| p.wall_min_angle_deg, outcome: Fails(F::ParallelWalls),
        tests: "up within this angle of the robot's z axis (failure::within_wall_angle)" },
    Spec { check: C::MaxSigma, stage: S::Gate, unit: "deg", threshold: |p| p.max_sigma_deg, outcome: Fails(F::ParallelWalls),
        tests: "both reported attitude sigmas (failure::acceptable_within)" },
    Spec { check: C::RefineAboveSigma, stage: S::Resegment, unit: "deg", threshold: |p| p.refine_above_sigma_deg, outcome: Drops("re-segmentation"),
        tests: "a first solution this tight stands without re-segmentation (resegment::resegmented)" },
    Spec { check: C::StartMaxSigma, stage: S::Resegment, unit: "rad", threshold: |_| resegment::START_MAX_SIGMA, outcome: Drops("start"),
        tests: "largest attitude sigma of a start of re-segmentation (resegment::refine_estimate)" },
    Spec { check: C::LineMaxSigma, stage: S::Resegment, unit: "deg", threshold: |p| p.level_line_max_sigma_deg, outcome: Drops("refined solution's lines"),
        tests: "the stricter sigma gate of a refined solution that uses floor lines (resegment::refined_solution)" },
    Spec { check: C::Disagreement, stage: S::Resegment, unit: "sigma", threshold: |_| resegment::DISAGREEMENT_SIGMAS, outcome: Widens,
        tests: "two solutions apart beyond this of their joint uncertainty (resegment::widened_by_disagreement)" },
    Spec { check: C::TighterThanFirst, stage: S::Resegment, unit: "1", threshold: |_| resegment::TIGHTER_THAN_FIRST, outcome: Widens,
        tests: "a refined solution this many times tighter stands unwidened (resegment::widened_against_first)" },
    Spec { check: C::Unconfirmed, stage: S::Resegment, unit: "sigma", threshold: |_| resegment::UNCONFIRMED_SIGMAS, outcome: Widens,
        tests: "a refused refinement beyond this of the first's own sigmas (resegment::widened_unconfirmed)" },
    Spec { check: C::FromStart, stage: S::Resegment, unit: "sigma", threshold: |_| resegment::FROM_START_SIGMAS, outcome: Widens,
        tests: "a refined solution beyond this of its start's sigmas (resegment::widened_from_start)" },
    Spec { check: C::RefinedWallRows, stage: S::Refine, unit: "scans", threshold: |p| p.refine_min_rows as f64, outcome: Drops("re-segmented wall"),
        tests: "scans holding WALL_ROW_SHARE of a re-segmented wall's points each (refine::models_of)" },
    Spec { check: C::RefinedLevelAngle, stage: S::Refine, unit: "deg", threshold: |p| p.refine_level_max_deg, outcome: Drops("re-segmented floor or ceiling"),
        tests: "its normal within this of up (checks::refined_level)" },
    Spec { check: C::RefinedLevelMisfit, stage: S::Refine, unit: "1", threshold: |p| p.refine_level_misfit, outcome: Drops("re-segmented floor or ceiling"),
        tests: "its misfit ratio (checks::refined_level)" },
    Spec { check: C::RefinedClearOfScanner, stage: S::Refine, unit: "m", threshold: |_| refine::MIN_LEVEL_DISTANCE, outcome: Drops("floor or ceiling"),
        tests: "its plane's distance from the scanner (refine::clear_of_scanner)" },
    Spec { check: C::LineMinPoints, stage: S::Refine, unit: "points", threshold: |p| p.level_line_min_points as f64, outcome: Drops("floor or ceiling line"),
        tests: "a scan's floor line alone; PLANE_LINE_MIN_POINTS beside a full one (refine::lines)" },
    Spec { check: C::LineMisfit, stage: S::Refine, unit: "1", threshold: |p| p.level_line_misfit, outcome: Drops("floor or ceiling line"),
        tests: "a line's points' chi2 / dof about it (refine::lines::fit_line)" },
    Spec { check: C::LinesPlaneMisfit, stage: S::Refine, unit: "1", threshold: |_| refine::LINES_PLANE_MISFIT, outcome: Drops("floor or ceiling lines"),
        tests: "several scans' lines, skew when their plane misfits beyond this (refine::lines::lines_evidence)" },
    Spec { check: C::CeilingBandSteps, stage: S::Refine, unit: "points", threshold: |_| refine::CEILING_BAND_MIN_STEPS as f64, outcome: Drops("ceiling"),
        tests: "points stepping as a ceiling does among the highest (refine::refine)" },
    Spec { check: C::MaxTilt, stage: S::Refine, unit: "deg", threshold: |_| up::MAX_TILT_DEG, outcome: Drops("up candidate"),
        tests: "largest robot tilt the up search and the frameless level start consider (up, refine::ransac)" },
];

impl Check {
    /// The check's threshold under `params`.
    pub fn threshold(self, params: &LevelParams) -> f64 {
        (self.spec().threshold)(params)
    }

    /// The check's row in [`CHECKS`].
    pub fn spec(self) -> &'static Spec {
        &CHECKS[self as usize]
    }
}

/// [`Check::RefinedLevelAngle`], [`Check::RefinedLevelMisfit`] and
/// [`Check::RefinedClearOfScanner`]: whether a re-segmented floor or ceiling plane (found by
/// height, through floor lines or by sampling) may stand as level evidence: level within
/// `refine_level_max_deg` of `up`, explaining its points within `refine_level_misfit` at noise
/// `s`, and clear of the scanner (the one place these three are applied together).
pub(crate) fn refined_level(
    fit: &PlaneFit,
    up: &Vector3<f64>,
    s: f64,
    params: &LevelParams,
) -> bool {
    fit.normal.dot(up).abs() >= params.refine_level_cos()
        && fit.misfit_ratio(s) <= params.refine_level_misfit
        && clear_of_scanner(&fit.normal, &fit.centroid)
}

/// Whether the plane through `point` with unit `normal` passes clear of the scanner, as a
/// floor's or ceiling's must, not only its points: each scan's points lie in that scan's own
/// plane through the scanner whatever they hit, so a band of wall points from one or two scans
/// (near the hinge axis the scans nearly coincide) fits a plane through the scanner that can
/// pass for level. One such "ceiling", 7 cm above the scanner over wall points alone, leveled
/// a pose 6 degrees off with a sigma of 0.7.
pub(crate) fn clear_of_scanner(normal: &Vector3<f64>, point: &Point3<f64>) -> bool {
    normal.dot(&point.coords).abs() >= refine::MIN_LEVEL_DISTANCE
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The table has one row per check, in the enum's order, each named once.
    #[test]
    fn every_check_has_its_row() {
        for (i, spec) in CHECKS.iter().enumerate() {
            assert_eq!(spec.check as usize, i, "{:?}", spec.check);
        }
        assert_eq!(CHECKS.len(), Check::MaxTilt as usize + 1);
    }

    /// The thresholds read the parameters: the defaults of the gate's, and a changed value.
    #[test]
    fn thresholds_read_the_parameters() {
        let p = LevelParams::default();
        assert_eq!(Check::MaxSigma.threshold(&p), 1.5);
        assert_eq!(Check::ParallelRatio.threshold(&p), 0.01);
        assert_eq!(Check::MinPolygons.threshold(&p), 3.0);
        assert_eq!(Check::StartMaxSigma.threshold(&p), 0.2);
        let q = LevelParams {
            max_sigma_deg: 2.0,
            ..p
        };
        assert_eq!(Check::MaxSigma.threshold(&q), 2.0);
    }

    /// Only the pose-level gates fail a pose, each with a contract reason; the rest act on
    /// candidates.
    #[test]
    fn only_grid_and_gate_checks_fail_the_pose() {
        for spec in CHECKS {
            let fails = matches!(spec.outcome, Outcome::Fails(_));
            assert_eq!(
                fails,
                matches!(spec.stage, Stage::Grid | Stage::Gate),
                "{:?}",
                spec.check
            );
        }
    }
}
