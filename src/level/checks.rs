//! Every accept/reject rule of level estimation in one table ([`CHECKS`]): its name, the stage
//! that applies it, what it tests, its threshold (read from [`LevelParams`] or the stage's fixed
//! constants in [`params`](super::params)), and what failing it does: fail the pose with one of
//! the contract's reasons (sect. 5.5), or drop, widen or keep back a candidate (a quad, a patch,
//! a level plane or line, a solution). The gates of sect. 5.5 and of re-segmentation read their
//! thresholds through [`Check::threshold`], so the table is what the code applies.

use super::grid::PlaneFit;
use super::params::{first_pass, patches, quads, refine, resegment, up};
use super::{FailCause, LevelParams};
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
    /// Maximum likelihood on the chosen segmentation (`ml::from_segmentation`).
    LastStage,
}

/// What failing a check does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outcome {
    /// The pose fails with this cause (reported as its contract reason).
    Fails(FailCause),
    /// The named candidate is dropped (or, for a gate on a candidate solution, not used).
    Drops(&'static str),
    /// The kept solution's covariance takes in its distance from another.
    Widens,
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

/// Declares [`Check`] and [`CHECKS`] from one list, so that each check's name and row are
/// written once, in the same order.
macro_rules! checks {
    ($($name:ident: $stage:ident, $unit:literal, $threshold:expr, $outcome:expr,
        $tests:literal;)*) => {
        /// The named checks, in pipeline order; [`CHECKS`] holds one row for each.
        #[derive(Clone, Copy, Debug, PartialEq, Eq)]
        pub enum Check {
            $($name,)*
        }

        /// Every accept/reject rule, one row per [`Check`] in its order.
        pub const CHECKS: &[Spec] = &[$(Spec {
            check: Check::$name,
            stage: Stage::$stage,
            unit: $unit,
            threshold: $threshold,
            outcome: $outcome,
            tests: $tests,
        },)*];
    };
}

use FailCause as F;
use Outcome::{Drops, Fails, Widens};

checks! {
    TooFewScans: Grid, "scans", |_| 3.0, Fails(F::TooFewScans),
        "at least three distinct scan elevations (grid::PoseGrid::from_scans_with)";
    InconsistentScans: Grid, "rays", |_| 0.0, Fails(F::InconsistentScans),
        "every scan has as many rays (grid::PoseGrid::from_scans_with)";
    QuadCoplanar: Quads, "sigma", |p| p.coplanar_k, Drops("quad"),
        "every point of a quad within coplanar_k sigmas of its plane (polygons::any_beyond)";
    QuadNearTriangle: Quads, "1", |p| p.min_edge_ratio, Drops("quad"),
        "the shorter of opposite sides over the longer (polygons::near_triangle)";
    QuadDiagonal: Quads, "tolerances", |_| quads::DIAGONAL_PLANE_TOLERANCES, Drops("quad"),
        "a point this many coplanarity tolerances off the plane through the centroid normal to the diagonals: a corner or an edge (polygons::any_beyond)";
    PatchMinPoints: Patches, "points", |p| p.min_patch_points as f64, Drops("patch"),
        "a patch's points, over at least two rows (patches::patch_rows)";
    PatchStacked: Patches, "1", |p| p.min_stacked_share, Drops("patch"),
        "share of members with a member in an adjacent row of their column (patches::split::stacked)";
    PatchTooBent: Patches, "1", |p| p.max_misfit_sigmas, Drops("patch"),
        "a small patch's misfit beyond 1 + k sqrt(2 / dof) (patches::split::too_bent_to_split)";
    PatchBentAcrossRows: Patches, "1", |p| p.max_row_bend_sigmas, Drops("patch"),
        "rows' mean residuals, chi2 / dof beyond 1 + k sqrt(2 / dof) (patches::split::bent_across_rows)";
    PatchEdgeRow: Patches, "sigma", |p| p.trim_sigmas, Drops("edge row, or a three-row patch"),
        "an edge row's mean residual from the other rows' plane (patches::trim::edge_row_off)";
    PatchTrimmedRows: Patches, "1", |_| patches::MIN_TRIMMED_ROW_SHARE, Drops("trim"),
        "each of three adjacent rows left after a trim holds this share of the points (patches::trim::trimmed_rows_hold)";
    PatchFrontRun: Patches, "sigma", |p| p.front_end_sigmas, Drops("run at a row's end"),
        "a run of at least MIN_FRONT_RUN points in front of the plane (patches::trim::front_run)";
    PatchSplitMisfit: Patches, "1", |p| p.split_misfit, Drops("unsplit patch"),
        "a patch's misfit ratio above which it is tested for two planes (patches::plane_explained)";
    PatchSplitF: Patches, "1", |p| p.split_f, Drops("unsplit patch"),
        "F statistic of two planes against one (patches::split::two_planes)";
    LevelMinPoints: LevelSurfaces, "points", |p| p.min_level_points as f64, Drops("level plane"),
        "a floor or ceiling plane's points (first_pass::enough_for_level, refine::level_support)";
    LevelMisfit: LevelSurfaces, "1", |p| p.max_level_misfit, Drops("level plane"),
        "a cleaned floor or ceiling patch's misfit ratio (first_pass::level_plane_stands)";
    LevelMinRowsNoisy: LevelSurfaces, "scans", |_| first_pass::LEVEL_MIN_ROWS_NOISY as f64, Drops("level plane"),
        "scan lines of a level plane from level_steep_min_sigma of noise (first_pass::enough_for_level)";
    LevelSteepVeto: LevelSurfaces, "m", |p| p.level_steep_min_sigma, Drops("level plane"),
        "noise from which a plane only points on a steep surface make is vetoed (first_pass::steep_veto)";
    LevelOpaque: LevelSurfaces, "points", |_| refine::MAX_BEYOND as f64, Drops("level plane"),
        "points seen beyond a floor or ceiling (refine::opaque)";
    MinPolygons: Gate, "quads", |p| p.min_polygons as f64, Fails(F::TooFewPolygons),
        "wall quads when no level plane is seen; facing_* when Facing holds (first_pass::solve)";
    Facing: Gate, "quads", |_| 0.0, Fails(F::FacingFloor),
        "floor (ceiling: facing_ceiling) quads outnumber wall quads, for a pose any gate refuses (failure::reported)";
    ParallelRatio: Gate, "1", |p| p.parallel_ratio, Fails(F::WallsParallel),
        "smaller over larger eigenvalue of up's information, walls only (failure::acceptable_within)";
    WallAngle: Gate, "deg", |p| p.wall_min_angle_deg, Fails(F::BeyondWallAngle),
        "up within this angle of the robot's z axis (failure::within_wall_angle)";
    MaxSigma: Gate, "deg", |p| p.max_sigma_deg, Fails(F::SigmaAboveGate),
        "both reported attitude sigmas (failure::acceptable_within)";
    RefineAboveSigma: Resegment, "deg", |p| p.refine_above_sigma_deg, Drops("re-segmentation"),
        "a first solution this tight stands without re-segmentation (resegment::needs_refine)";
    StartMaxSigma: Resegment, "rad", |_| resegment::START_MAX_SIGMA, Drops("start"),
        "largest attitude sigma of a start of re-segmentation (resegment::start_tight_enough)";
    LineMaxSigma: Resegment, "deg", |p| p.level_line_max_sigma_deg, Drops("refined solution's lines"),
        "the stricter sigma gate of a refined solution that uses floor lines (resegment::passes_line_gate)";
    Disagreement: Resegment, "sigma", |_| resegment::DISAGREEMENT_SIGMAS, Widens,
        "two solutions apart beyond this of their joint uncertainty (resegment::widened_by_disagreement)";
    TighterThanFirst: Resegment, "1", |_| resegment::TIGHTER_THAN_FIRST, Widens,
        "a refined solution this many times tighter stands unwidened (resegment::widened_against_first)";
    Unconfirmed: Resegment, "sigma", |_| resegment::UNCONFIRMED_SIGMAS, Widens,
        "a refused refinement beyond this of the first's own sigmas (resegment::widened_unconfirmed)";
    FromStart: Resegment, "sigma", |_| resegment::FROM_START_SIGMAS, Widens,
        "a refined solution beyond this of its start's sigmas (resegment::widened_from_start)";
    RefinedWallRows: Refine, "scans", |p| p.refine_min_rows as f64, Drops("re-segmented wall"),
        "scans holding WALL_ROW_SHARE of a re-segmented wall's points each (refine::spans_wall_rows)";
    RefinedLevelAngle: Refine, "deg", |p| p.refine_level_max_deg, Drops("re-segmented floor or ceiling"),
        "its normal within this of up (checks::refined_level)";
    RefinedLevelMisfit: Refine, "1", |p| p.refine_level_misfit, Drops("re-segmented floor or ceiling"),
        "its misfit ratio (checks::refined_level)";
    RefinedClearOfScanner: Refine, "m", |_| refine::MIN_LEVEL_DISTANCE, Drops("floor or ceiling"),
        "its plane's distance from the scanner (refine::clear_of_scanner)";
    LineMinPoints: Refine, "points", |p| p.level_line_min_points as f64, Drops("floor or ceiling line"),
        "a scan's floor line alone; PLANE_LINE_MIN_POINTS beside a full one (refine::lines::fit_line)";
    LineMisfit: Refine, "1", |p| p.level_line_misfit, Drops("floor or ceiling line"),
        "a line's points' chi2 / dof about it (refine::lines::line_misfits)";
    LinesAtOneHeight: Refine, "sigma", |p| p.refine_k, Drops("floor or ceiling lines"),
        "floor lines below the scanner, ceiling lines above, each surface's at one height under the up they give (refine::lines::lines_at_one_height)";
    LinesPlaneMisfit: Refine, "1", |_| refine::LINES_PLANE_MISFIT, Drops("floor or ceiling lines"),
        "several scans' lines, skew when their plane misfits beyond this (refine::lines::skew_lines)";
    CeilingBandSteps: Refine, "points", |_| refine::CEILING_BAND_MIN_STEPS as f64, Drops("ceiling"),
        "points stepping as a ceiling does among the highest (refine::steps_as_ceiling)";
    MaxTilt: Refine, "deg", |_| up::MAX_TILT_DEG, Drops("up candidate"),
        "largest robot tilt the up search and the frameless level start consider (up::within_max_tilt, refine::ransac)";
    LastStageShift: LastStage, "sigma", |p| p.ml.max_shift_sigmas, Drops("the stage's answer"),
        "the stage's answer within this of its start's sigmas (ml::from_segmentation::gate)";
}

impl Check {
    /// The check's threshold under `params` (from its row in [`CHECKS`]).
    pub fn threshold(self, params: &LevelParams) -> f64 {
        (CHECKS[self as usize].threshold)(params)
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
        assert_eq!(CHECKS.len(), Check::LastStageShift as usize + 1);
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
