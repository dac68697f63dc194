//! One test per check of [`CHECKS`](super::checks::CHECKS): the smallest input where the check
//! decides, just inside its threshold (passes) and just outside (fails), and a test that the
//! table's checks are the ones tested here.

use super::checks::{CHECKS, Check, refined_level};
use super::failure::tests::solution;
use super::failure::{acceptable, reported, within_wall_angle};
use super::grid::{GridPoint, PlaneFit, PoseGrid};
use super::params::{refine as refine_consts, resegment as reseg};
use super::polygons::{Polygon, any_beyond, extract_quads, near_triangle};
use super::resegment::{
    needs_refine, passes_line_gate, start_tight_enough, widened_against_first,
    widened_by_disagreement, widened_from_start, widened_unconfirmed,
};
use super::up::{UpSolution, within_max_tilt};
use super::{FailCause, LevelEstimate, LevelParams, SurfaceKind, first_pass, refine};
use crate::scan::Scan;
use nalgebra::{Point3, Vector3};

/// The checks that have a test below, each named once.
const TESTED: &[Check] = &[
    Check::TooFewScans,
    Check::InconsistentScans,
    Check::QuadCoplanar,
    Check::QuadNearTriangle,
    Check::QuadDiagonal,
    Check::LevelMinPoints,
    Check::LevelMisfit,
    Check::LevelMinRowsNoisy,
    Check::LevelSteepVeto,
    Check::LevelOpaque,
    Check::MinPolygons,
    Check::Facing,
    Check::ParallelRatio,
    Check::WallAngle,
    Check::MaxSigma,
    Check::RefineAboveSigma,
    Check::StartMaxSigma,
    Check::LineMaxSigma,
    Check::Disagreement,
    Check::TighterThanFirst,
    Check::Unconfirmed,
    Check::FromStart,
    Check::RefinedWallRows,
    Check::RefinedLevelAngle,
    Check::RefinedLevelMisfit,
    Check::RefinedClearOfScanner,
    Check::LineMinPoints,
    Check::LineMisfit,
    Check::LinesAtOneHeight,
    Check::LinesPlaneMisfit,
    Check::CeilingBandSteps,
    Check::MaxTilt,
    Check::LastStageShift,
    // In patches/tests.rs, beside the private functions they test.
    Check::PatchMinPoints,
    Check::PatchStacked,
    Check::PatchTooBent,
    Check::PatchBentAcrossRows,
    Check::PatchEdgeRow,
    Check::PatchTrimmedRows,
    Check::PatchFrontRun,
    Check::PatchSplitMisfit,
    Check::PatchSplitF,
];

/// The checks still without a test of their own here. Covered only by the stage tests and
/// the golden corpus.
const NOT_YET_TESTED: &[Check] = &[];

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

/// A grid of `rows` scans of `cols` rays with points `at(row, col)` seen along their own
/// direction from the scanner.
fn grid_of(rows: usize, cols: usize, at: impl Fn(usize, usize) -> Option<Point3<f64>>) -> PoseGrid {
    PoseGrid {
        scan_index: (0..rows).collect(),
        elevation: (0..rows).map(|r| 0.05 * r as f64).collect(),
        cols,
        points: (0..rows * cols)
            .map(|i| {
                at(i / cols, i % cols).map(|p| GridPoint {
                    p,
                    dir: p.coords.normalize(),
                    range: p.coords.norm(),
                })
            })
            .collect(),
    }
}

/// A quad of a wall 3 m ahead whose middle point stands `d` off it: by symmetry the fitted
/// plane keeps the wall's normal and moves by `d / 15`, so that point lies `14 d / 15` off
/// the fit, the others `d / 15`.
#[test]
fn quad_coplanar() {
    let p = LevelParams::default();
    let sigma = 0.01;
    let (lo, hi) = around(Check::QuadCoplanar.threshold(&p) * sigma * 15.0 / 14.0);
    let quads = |d: f64| {
        let grid = grid_of(3, 5, |r, c| {
            let off = if (r, c) == (1, 2) { d } else { 0.0 };
            Some(Point3::new(
                3.0 + off,
                0.1 * (c as f64 - 2.0),
                0.1 * (r as f64 - 1.0),
            ))
        });
        extract_quads(&grid, &p, sigma, p.quad_cols).len()
    };
    assert_eq!(quads(lo), 1);
    assert_eq!(quads(hi), 0);
}

/// Opposite sides 1 and `t` long: near a triangle once `t` is below `min_edge_ratio`.
#[test]
fn quad_near_triangle() {
    let p = LevelParams::default();
    let (lo, hi) = around(Check::QuadNearTriangle.threshold(&p));
    let corners = |t: f64| {
        [
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(t, 1.0, 0.0),
            Point3::new(0.0, 1.0, 0.0),
        ]
    };
    assert!(near_triangle(&corners(lo), p.min_edge_ratio));
    assert!(!near_triangle(&corners(hi), p.min_edge_ratio));
}

/// A point off the diagonals' plane refuses the quad beyond `DIAGONAL_PLANE_TOLERANCES`
/// coplanarity tolerances.
#[test]
fn quad_diagonal() {
    let p = LevelParams::default();
    let tol = Check::QuadCoplanar.threshold(&p) * 0.01;
    let (lo, hi) = around(Check::QuadDiagonal.threshold(&p) * tol);
    let limit = super::params::quads::DIAGONAL_PLANE_TOLERANCES * tol;
    let points = |d: f64| [Point3::new(1.0, 2.0, 0.0), Point3::new(-1.0, 0.5, d)].into_iter();
    assert!(!any_beyond(
        &Vector3::z(),
        &Point3::origin(),
        points(lo),
        limit
    ));
    assert!(any_beyond(
        &Vector3::z(),
        &Point3::origin(),
        points(-hi),
        limit
    ));
}

#[test]
fn level_min_points() {
    let p = LevelParams::default();
    let t = Check::LevelMinPoints.threshold(&p) as usize;
    let rows = |n: usize| [n / 3, n / 3, n - 2 * (n / 3)];
    assert!(first_pass::enough_for_level(t, &rows(t), 0.01, &p));
    assert!(!first_pass::enough_for_level(t - 1, &rows(t - 1), 0.01, &p));
}

/// From `level_steep_min_sigma` of noise a level plane needs three scan lines, below it two.
#[test]
fn level_min_rows_noisy() {
    let p = LevelParams::default();
    let t = Check::LevelMinRowsNoisy.threshold(&p) as usize;
    let rows = |n: usize| -> Vec<usize> { (0..4).map(|r| if r < n { 20 } else { 0 }).collect() };
    let noisy = p.level_steep_min_sigma;
    assert!(first_pass::enough_for_level(60, &rows(t), noisy, &p));
    assert!(!first_pass::enough_for_level(60, &rows(t - 1), noisy, &p));
    assert!(first_pass::enough_for_level(60, &rows(2), noisy * 0.9, &p));
}

/// On three scan lines the veto applies from `level_steep_min_sigma` up; on two, always.
#[test]
fn level_steep_veto() {
    let p = LevelParams::default();
    let (lo, hi) = around(Check::LevelSteepVeto.threshold(&p));
    assert!(!first_pass::steep_veto(&[20, 20, 20], lo, &p));
    assert!(first_pass::steep_veto(&[20, 20, 20], hi, &p));
    assert!(first_pass::steep_veto(&[30, 30, 0], lo, &p));
}

#[test]
fn level_misfit() {
    let p = LevelParams::default();
    let (lo, hi) = around(Check::LevelMisfit.threshold(&p));
    let empty = grid_of(1, 0, |_, _| None);
    let stands =
        |m: f64| first_pass::level_plane_stands(&empty, &level_fit(-1.0, 0.0, m), 0.01, &p);
    assert!(stands(lo));
    assert!(!stands(hi));
}

/// The reported sigma, the propagated one times `sigma_inflation`, decides; a failed first
/// solution is always re-segmented.
#[test]
fn refine_above_sigma() {
    let p = LevelParams::default();
    let t = Check::RefineAboveSigma.threshold(&p).to_radians() / p.sigma_inflation;
    let (lo, hi) = around(t);
    assert!(!needs_refine(&Ok(solution(5.0, lo, (1.0, 1.0))), &p));
    assert!(needs_refine(&Ok(solution(5.0, hi, (1.0, 1.0))), &p));
    assert!(needs_refine(&Err(FailCause::NoUp), &p));
}

#[test]
fn start_max_sigma() {
    let p = LevelParams::default();
    let (lo, hi) = around(Check::StartMaxSigma.threshold(&p));
    assert!(start_tight_enough(&solution(5.0, lo, (1.0, 1.0)), &p));
    assert!(!start_tight_enough(&solution(5.0, hi, (1.0, 1.0)), &p));
}

#[test]
fn line_max_sigma() {
    let p = LevelParams::default();
    let t = Check::LineMaxSigma.threshold(&p);
    assert!(t < Check::MaxSigma.threshold(&p));
    let (lo, hi) = around(t.to_radians() / p.sigma_inflation);
    assert!(passes_line_gate(&solution(5.0, lo, (1.0, 1.0)), &p));
    assert!(!passes_line_gate(&solution(5.0, hi, (1.0, 1.0)), &p));
}

/// Members in the first `rows` of three scans, `WALL_ROW_SHARE` or more of them each.
#[test]
fn refined_wall_rows() {
    let p = LevelParams::default();
    let t = Check::RefinedWallRows.threshold(&p) as usize;
    let grid = grid_of(3, 40, |_, _| None);
    let members = |rows: usize| -> Vec<usize> {
        (0..rows)
            .flat_map(|r| (0..30).map(move |c| r * 40 + c))
            .collect()
    };
    assert!(refine::spans_wall_rows(&grid, &members(t), &p));
    assert!(!refine::spans_wall_rows(&grid, &members(t - 1), &p));
}

/// A scan's exact floor line of `n` points (2 m ahead, 1 m down).
fn floor_line_grid(n: usize) -> PoseGrid {
    grid_of(1, n, |_, c| {
        Some(Point3::new(2.0, 0.1 * c as f64 - 1.0, -1.0))
    })
}

#[test]
fn line_min_points() {
    let p = LevelParams::default();
    let t = Check::LineMinPoints.threshold(&p) as usize;
    let fit = |n: usize| {
        let grid = floor_line_grid(n);
        refine::lines::fit_line(&grid, (0..n).collect(), &Vector3::z(), None, 0.01, &p, t)
    };
    assert!(fit(t).is_some());
    assert!(fit(t - 1).is_none());
}

/// Ten points: sixteen degrees of freedom.
#[test]
fn line_misfit() {
    let p = LevelParams::default();
    let (lo, hi) = around(Check::LineMisfit.threshold(&p) * 16.0);
    assert!(!refine::lines::line_misfits(lo, 10, &p));
    assert!(refine::lines::line_misfits(hi, 10, &p));
}

/// Two floor lines straight above each other (no tilt lever between them): one floor while
/// their heights differ by less than `refine_k` of their joint noise.
#[test]
fn lines_at_one_height() {
    let p = LevelParams::default();
    let (s, n) = (0.01, 30);
    let line = |z: f64| {
        let pts: Vec<_> = (0..n)
            .map(|k| Point3::new(2.0, -1.0 + 2.0 * k as f64 / (n - 1) as f64, z))
            .map(|q| (q, q.coords.normalize()))
            .collect();
        refine::FlatLine {
            line: super::up::LevelLine::fit(&pts, s, p.min_sigma).unwrap(),
            kind: SurfaceKind::Floor,
        }
    };
    let sd = (2.0 * (s * s / n as f64 + p.min_sigma * p.min_sigma)).sqrt();
    let (lo, hi) = around(Check::LinesAtOneHeight.threshold(&p) * sd);
    let level = solution(0.0, 0.001, (1.0, 1.0));
    let one =
        |dz: f64| refine::lines::lines_at_one_height(&[line(-0.4), line(-0.4 + dz)], &level, s, &p);
    assert!(one(lo));
    assert!(!one(hi));
}

#[test]
fn lines_plane_misfit() {
    let p = LevelParams::default();
    let (lo, hi) = around(Check::LinesPlaneMisfit.threshold(&p));
    assert!(!refine::lines::skew_lines(&level_fit(-1.0, 0.0, lo), 0.01));
    assert!(refine::lines::skew_lines(&level_fit(-1.0, 0.0, hi), 0.01));
}

#[test]
fn ceiling_band_steps() {
    let p = LevelParams::default();
    let t = Check::CeilingBandSteps.threshold(&p) as usize;
    let ceiling: Vec<bool> = (0..20).map(|i| i % 2 == 0).collect();
    let band = |steps: usize| 0..2 * steps;
    assert!(refine::steps_as_ceiling(band(t), &ceiling));
    assert!(!refine::steps_as_ceiling(band(t - 1), &ceiling));
}

#[test]
fn max_tilt() {
    let p = LevelParams::default();
    let (lo, hi) = around(Check::MaxTilt.threshold(&p));
    let up = |deg: f64| Vector3::new(deg.to_radians().sin(), 0.0, deg.to_radians().cos());
    assert!(within_max_tilt(&up(lo)));
    assert!(!within_max_tilt(&up(hi)));
}

/// The stage's answer `deg` about the x axis with sigmas `sigma` \[rad\] both ways.
fn stage_answer(deg: f64, sigma: f64) -> crate::level::ml::MlSolution {
    let up = solution(deg, sigma, (1.0, 1.0)).up;
    let a = crate::geometry::Attitude::from_up(&up);
    crate::level::ml::MlSolution {
        attitude: [a.theta_x, a.theta_y],
        up,
        covariance: [[sigma * sigma, 0.0], [0.0, sigma * sigma]],
        ..Default::default()
    }
}

#[test]
fn last_stage_shift() {
    use crate::level::ml::from_segmentation::gate;
    let p = LevelParams::default();
    // A start of 0.01 rad sigma: the answer that many sigmas away about x (the offset in
    // the start's tangent plane is the angle's sine).
    let start = solution(0.0, 0.01, (1.0, 1.0));
    let (lo, hi) = around(Check::LastStageShift.threshold(&p) * 0.01);
    let at = |offset: f64| stage_answer(offset.asin().to_degrees(), 0.001);
    assert!(gate(&at(lo), &start, &p));
    assert!(!gate(&at(hi), &start, &p));
}
