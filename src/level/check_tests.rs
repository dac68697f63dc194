//! One test per check of [`CHECKS`](super::checks::CHECKS): the smallest input where the check
//! decides, just inside its threshold (passes) and just outside (fails), and a test that the
//! table's checks are the ones tested here.

use super::checks::{CHECKS, Check, refined_level};
use super::failure::tests::solution;
use super::failure::{acceptable, reported, within_wall_angle};
use super::grid::{GridPoint, PlaneFit, PoseGrid};
use super::params::{refine as refine_consts, resegment as reseg};
use super::polygons::Polygon;
use super::resegment::{
    widened_against_first, widened_by_disagreement, widened_from_start, widened_unconfirmed,
};
use super::up::UpSolution;
use super::{FailCause, LevelEstimate, LevelParams, SurfaceKind, first_pass, refine};
use crate::scan::Scan;
use nalgebra::{Point3, Vector3};

/// The checks that have a test below, each named once.
const TESTED: &[Check] = &[
    Check::TooFewScans,
    Check::InconsistentScans,
    Check::LevelOpaque,
    Check::MinPolygons,
    Check::Facing,
    Check::ParallelRatio,
    Check::WallAngle,
    Check::MaxSigma,
    Check::Disagreement,
    Check::TighterThanFirst,
    Check::Unconfirmed,
    Check::FromStart,
    Check::RefinedLevelAngle,
    Check::RefinedLevelMisfit,
    Check::RefinedClearOfScanner,
    // In patches/tests.rs, beside the private functions they test.
    Check::PatchStacked,
    Check::PatchTooBent,
];

/// The checks still without a test of their own here: they decide deep inside a stage, with
/// no entry point of their own yet. Covered only by the stage tests and the golden corpus.
const NOT_YET_TESTED: &[Check] = &[
    Check::QuadCoplanar,
    Check::QuadNearTriangle,
    Check::QuadDiagonal,
    Check::PatchMinPoints,
    Check::PatchBentAcrossRows,
    Check::PatchEdgeRow,
    Check::PatchTrimmedRows,
    Check::PatchFrontRun,
    Check::PatchSplitMisfit,
    Check::PatchSplitF,
    Check::LevelMinPoints,
    Check::LevelMisfit,
    Check::LevelMinRowsNoisy,
    Check::LevelSteepVeto,
    Check::RefineAboveSigma,
    Check::StartMaxSigma,
    Check::LineMaxSigma,
    Check::RefinedWallRows,
    Check::LineMinPoints,
    Check::LineMisfit,
    Check::LinesPlaneMisfit,
    Check::CeilingBandSteps,
    Check::MaxTilt,
];

/// Every row of the table is either tested here or listed as not yet tested, never both, and
/// no check is named twice.
#[test]
fn every_check_is_accounted_for() {
    for spec in CHECKS {
        let tested = TESTED.contains(&spec.check);
        let pending = NOT_YET_TESTED.contains(&spec.check);
        assert!(tested != pending, "{:?}", spec.check);
    }
    assert_eq!(TESTED.len() + NOT_YET_TESTED.len(), CHECKS.len());
}

/// Just below and just above `t`, by a relative `1e-6`.
fn around(t: f64) -> (f64, f64) {
    (t * (1.0 - 1e-6), t * (1.0 + 1e-6))
}

/// A level scan of `nrays` rays, all returning 2 m, at `elevation`.
fn scan(nrays: usize, elevation: f64) -> Scan {
    let mut s = Scan::with_even_bearings(nrays, -1.0, 1.0);
    s.elevation = Some(elevation);
    s.readings = vec![Some(2.0); nrays];
    s.valid = vec![true; nrays];
    s
}

#[test]
fn too_few_scans() {
    let t = Check::TooFewScans.threshold(&LevelParams::default()) as usize;
    let scans: Vec<Scan> = (0..t).map(|i| scan(5, 0.1 * i as f64)).collect();
    assert!(PoseGrid::from_scans(&scans).is_ok());
    assert!(matches!(
        PoseGrid::from_scans(&scans[..t - 1]),
        Err(FailCause::TooFewScans)
    ));
}

#[test]
fn inconsistent_scans() {
    let mut scans: Vec<Scan> = (0..3).map(|i| scan(5, 0.1 * i as f64)).collect();
    assert!(PoseGrid::from_scans(&scans).is_ok());
    scans[2] = scan(4, 0.2);
    assert!(matches!(
        PoseGrid::from_scans(&scans),
        Err(FailCause::InconsistentScans)
    ));
}

/// A floor 1 m below the scanner and `beyond` points a metre below it.
#[test]
fn level_opaque() {
    let p = LevelParams::default();
    let fit = PlaneFit {
        centroid: Point3::new(1.0, 0.0, -1.0),
        normal: Vector3::z(),
        in_plane: [(1.0, Vector3::x()), (1.0, Vector3::y())],
        n: 100,
        weight: 100.0,
        dn2: 1.0,
        residual_ss: 0.0,
    };
    let grid = |beyond: usize| PoseGrid {
        scan_index: vec![0],
        elevation: vec![0.0],
        cols: beyond,
        points: (0..beyond)
            .map(|i| {
                let p = Point3::new(1.0 + 0.1 * i as f64, 0.0, -2.0);
                Some(GridPoint {
                    p,
                    dir: p.coords.normalize(),
                    range: p.coords.norm(),
                })
            })
            .collect(),
    };
    let t = Check::LevelOpaque.threshold(&p) as usize;
    assert!(refine::opaque(&grid(t), &fit, 0.01, &p));
    assert!(!refine::opaque(&grid(t + 1), &fit, 0.01, &p));
}

/// Without a level plane, fewer than `min_polygons` wall quads fail the pose before any up is
/// sought; with as many, whatever else refuses it, it is not that.
#[test]
fn min_polygons() {
    let p = LevelParams::default();
    let t = Check::MinPolygons.threshold(&p) as usize;
    let mut est = LevelEstimate::empty(0.01);
    est.quads = (0..t - 1).map(|_| quad(SurfaceKind::Wall)).collect();
    let solve = |est: &LevelEstimate| first_pass::solve(est, &[], &p, 0.01);
    assert_eq!(solve(&est).err(), Some(FailCause::TooFewPolygons));
    est.quads.push(quad(SurfaceKind::Wall));
    assert_ne!(solve(&est).err(), Some(FailCause::TooFewPolygons));
}

/// A quad of `kind` (its geometry does not matter to the counts).
fn quad(kind: SurfaceKind) -> Polygon {
    Polygon {
        row: 0,
        col: 0,
        rows: 1,
        cols: 1,
        corners: [Point3::origin(); 4],
        area: 1.0,
        fit: PlaneFit {
            centroid: Point3::origin(),
            normal: Vector3::x(),
            in_plane: [(1.0, Vector3::y()), (1.0, Vector3::z())],
            n: 4,
            weight: 4.0,
            dn2: 1.0,
            residual_ss: 0.0,
        },
        kind,
    }
}

/// A refused pose is reported facing the floor once floor quads outnumber wall quads.
#[test]
fn facing() {
    let mut est = LevelEstimate::empty(0.01);
    est.quads = vec![quad(SurfaceKind::Wall), quad(SurfaceKind::Floor)];
    let cause = FailCause::SigmaAboveGate;
    assert_eq!(reported(&est, cause), cause);
    est.quads.push(quad(SurfaceKind::Floor));
    assert_eq!(reported(&est, cause), FailCause::FacingFloor);
}

#[test]
fn parallel_ratio() {
    let p = LevelParams::default();
    let (lo, hi) = around(Check::ParallelRatio.threshold(&p));
    assert_eq!(
        acceptable(&solution(5.0, 1e-3, (hi, 1.0)), &p, false),
        Ok(())
    );
    assert_eq!(
        acceptable(&solution(5.0, 1e-3, (lo, 1.0)), &p, false),
        Err(FailCause::WallsParallel)
    );
}

#[test]
fn wall_angle() {
    let p = LevelParams::default();
    let (lo, hi) = around(Check::WallAngle.threshold(&p));
    assert!(within_wall_angle(&solution(lo, 1e-3, (1.0, 1.0)).up, &p));
    assert!(!within_wall_angle(&solution(hi, 1e-3, (1.0, 1.0)).up, &p));
    assert_eq!(
        acceptable(&solution(hi, 1e-3, (1.0, 1.0)), &p, false),
        Err(FailCause::BeyondWallAngle)
    );
}

/// The gate is on the reported sigma, the propagated one times `sigma_inflation`.
#[test]
fn max_sigma() {
    let p = LevelParams::default();
    let (lo, hi) = around(Check::MaxSigma.threshold(&p).to_radians() / p.sigma_inflation);
    assert_eq!(
        acceptable(&solution(5.0, lo, (1.0, 1.0)), &p, false),
        Ok(())
    );
    assert_eq!(
        acceptable(&solution(5.0, hi, (1.0, 1.0)), &p, false),
        Err(FailCause::SigmaAboveGate)
    );
}

/// Two solutions `z` sigmas of `spread` apart about the x axis (sigma 0.01 rad each), for a
/// test of `widen` with the threshold `sigmas`: agreeing just inside, widened just outside.
fn widens_beyond(
    widen: fn(&UpSolution, &UpSolution) -> Option<UpSolution>,
    spread: f64,
    sigmas: f64,
) {
    let s = 0.01;
    let kept = solution(0.0, s, (1.0, 1.0));
    let (lo, hi) = around(sigmas * spread * s);
    // In `kept`'s basis, so that its covariance reads the same there.
    let other = |d: f64| UpSolution {
        basis: kept.basis,
        ..solution(-d.asin().to_degrees(), s, (1.0, 1.0))
    };
    assert!(widen(&kept, &other(lo)).is_none());
    let w = widen(&kept, &other(hi)).expect("widened");
    assert!(w.max_attitude_sigma() > kept.max_attitude_sigma());
}

#[test]
fn disagreement() {
    // Their joint uncertainty: both covariances.
    widens_beyond(
        widened_by_disagreement,
        2f64.sqrt(),
        reseg::DISAGREEMENT_SIGMAS,
    );
}

#[test]
fn unconfirmed() {
    widens_beyond(widened_unconfirmed, 1.0, reseg::UNCONFIRMED_SIGMAS);
}

#[test]
fn from_start() {
    widens_beyond(widened_from_start, 1.0, reseg::FROM_START_SIGMAS);
}

/// A refined solution far from the first one is widened unless it is this many times tighter.
#[test]
fn tighter_than_first() {
    let t = Check::TighterThanFirst.threshold(&LevelParams::default());
    let (lo, hi) = around(t);
    let first = |k: f64| solution(10.0, 0.01 * k, (1.0, 1.0));
    let kept = solution(0.0, 0.01, (1.0, 1.0));
    assert!(widened_against_first(&kept, &first(hi)).is_none());
    assert!(widened_against_first(&kept, &first(lo)).is_some());
}

/// A clean level plane at `height` \[m\] tilted `deg` from up, with misfit ratio `misfit` at
/// noise 0.01.
fn level_fit(height: f64, deg: f64, misfit: f64) -> PlaneFit {
    let a = deg.to_radians();
    let normal = Vector3::new(a.sin(), 0.0, a.cos());
    PlaneFit {
        centroid: Point3::from(normal * height),
        normal,
        in_plane: [(1.0, Vector3::y()), (1.0, normal.cross(&Vector3::y()))],
        n: 103,
        weight: 103.0,
        dn2: 1.0,
        residual_ss: misfit * 1e-4 * 100.0,
    }
}

#[test]
fn refined_level_angle() {
    let p = LevelParams::default();
    let (lo, hi) = around(Check::RefinedLevelAngle.threshold(&p));
    assert!(refined_level(
        &level_fit(-1.0, lo, 1.0),
        &Vector3::z(),
        0.01,
        &p
    ));
    assert!(!refined_level(
        &level_fit(-1.0, hi, 1.0),
        &Vector3::z(),
        0.01,
        &p
    ));
}

#[test]
fn refined_level_misfit() {
    let p = LevelParams::default();
    let (lo, hi) = around(Check::RefinedLevelMisfit.threshold(&p));
    assert!(refined_level(
        &level_fit(-1.0, 0.0, lo),
        &Vector3::z(),
        0.01,
        &p
    ));
    assert!(!refined_level(
        &level_fit(-1.0, 0.0, hi),
        &Vector3::z(),
        0.01,
        &p
    ));
}

#[test]
fn refined_clear_of_scanner() {
    let p = LevelParams::default();
    let t = Check::RefinedClearOfScanner.threshold(&p);
    assert_eq!(t, refine_consts::MIN_LEVEL_DISTANCE);
    let (lo, hi) = around(t);
    assert!(refined_level(
        &level_fit(hi, 0.0, 1.0),
        &Vector3::z(),
        0.01,
        &p
    ));
    assert!(!refined_level(
        &level_fit(lo, 0.0, 1.0),
        &Vector3::z(),
        0.01,
        &p
    ));
    assert!(!refined_level(
        &level_fit(-lo, 0.0, 1.0),
        &Vector3::z(),
        0.01,
        &p
    ));
}
