//! The matcher on synthetic scans with known answers.

mod matching_support;

use levelscan::eval::metrics::{ate, rpe};
use levelscan::geometry::{Pose2, wrap_angle};
use levelscan::matching::{
    Coarse, FallbackReason, IcpParams, MatchStatus, Matcher, MatcherParams, Metric, Mode,
    NormalParams, ScanReference, icp, match_run,
};
use matching_support::*;
use nalgebra::Point2;

fn close(a: &Pose2, b: &Pose2, tol_xy: f64, tol_theta: f64) -> bool {
    (a.translation() - b.translation()).norm() <= tol_xy
        && wrap_angle(a.theta - b.theta).abs() <= tol_theta
}

#[test]
fn point_to_line_recovers_a_known_motion_exactly_without_noise() {
    let walls = office();
    let a = Pose2::new(2.0, 1.5, 0.3);
    let b = Pose2::new(2.15, 1.58, 0.36);
    let reference = ScanReference::new(
        scan_at(&a, &walls, 181, 0.0, 1),
        &Point2::origin(),
        &NormalParams::default(),
    );
    let source = scan_at(&b, &walls, 181, 0.0, 2);
    let truth = a.between(&b);
    let params = IcpParams {
        epsilon_xy: 1e-10,
        epsilon_theta: 1e-10,
        ..IcpParams::default()
    };
    let r = icp(&source, &reference, Pose2::identity(), &params).unwrap();
    assert!(r.converged);
    assert!(
        close(&r.pose, &truth, 1e-6, 1e-7),
        "{:?} vs {truth:?}",
        r.pose
    );
}

#[test]
fn point_to_point_recovers_a_known_motion_exactly_with_exact_partners() {
    // Point-to-point is exact only when every source point has its true partner in the
    // reference, and finds it when the motion is small against the spacing: scattered posts
    // 40 cm apart, moved by 7 cm and 2 degrees.
    let source: Vec<Point2<f64>> = (0..60)
        .map(|i| {
            let (gx, gy) = ((i % 10) as f64, (i / 10) as f64);
            Point2::new(0.4 * gx + 0.03 * (i as f64 * 1.7).sin(), 0.4 * gy - 1.0)
        })
        .collect();
    let truth = Pose2::new(0.05, -0.05, 2f64.to_radians());
    let moved: Vec<Point2<f64>> = source.iter().map(|p| truth.transform_point(p)).collect();
    let reference = ScanReference::new(moved, &Point2::origin(), &NormalParams::default());
    let params = IcpParams {
        metric: Metric::PointToPoint,
        epsilon_xy: 1e-12,
        epsilon_theta: 1e-12,
        ..IcpParams::default()
    };
    let r = icp(&source, &reference, Pose2::identity(), &params).unwrap();
    assert!(r.converged);
    assert!(
        close(&r.pose, &truth, 1e-9, 1e-9),
        "{:?} vs {truth:?}",
        r.pose
    );
}

#[test]
fn a_corridor_is_flagged_degenerate() {
    let walls = corridor();
    let truth = [Pose2::new(0.0, 0.0, 0.0), Pose2::new(0.5, 0.1, 0.02)];
    let scans: Vec<_> = truth
        .iter()
        .enumerate()
        .map(|(i, p)| (scan_at(p, &walls, 181, 0.005, i as u64), Some(*p)))
        .collect();
    for metric in [Metric::PointToLine, Metric::PointToPoint] {
        let mut params = MatcherParams::default();
        params.icp.metric = metric;
        let reports = match_run(&scans, &params);
        assert_eq!(
            reports[1].status,
            MatchStatus::Fallback(FallbackReason::Degenerate),
            "{metric:?}"
        );
        // The fallback is the odometry.
        assert!(close(&reports[1].estimate, &truth[1], 1e-12, 1e-12));
    }
}

#[test]
fn a_wrong_odometry_guess_within_the_basin_converges() {
    let walls = office();
    let a = Pose2::new(2.0, 1.5, 0.3);
    let b = Pose2::new(2.2, 1.55, 0.4);
    let scans = vec![
        (scan_at(&a, &walls, 181, 0.0, 1), Some(a)),
        // Odometry says b is 10 cm and 5 degrees elsewhere.
        (
            scan_at(&b, &walls, 181, 0.0, 2),
            Some(b.compose(&Pose2::new(0.08, -0.06, 0.087))),
        ),
    ];
    for metric in [Metric::PointToLine, Metric::PointToPoint] {
        for coarse in [Coarse::Never, Coarse::Auto] {
            let mut params = MatcherParams::default();
            params.icp.metric = metric;
            params.coarse = coarse;
            let reports = match_run(&scans, &params);
            assert_eq!(reports[1].status, MatchStatus::Ok, "{metric:?} {coarse:?}");
            let tol = if metric == Metric::PointToLine {
                1e-5
            } else {
                0.02
            };
            assert!(
                close(&reports[1].estimate, &b, tol, tol),
                "{metric:?} {coarse:?}: {:?}",
                reports[1].estimate
            );
        }
    }
}

#[test]
fn the_coarse_search_rescues_a_guess_outside_the_icp_basin() {
    let walls = office();
    let a = Pose2::new(1.5, 2.0, 0.0);
    let b = Pose2::new(1.8, 2.1, 0.25);
    let scans = vec![
        (scan_at(&a, &walls, 181, 0.01, 1), Some(a)),
        (
            scan_at(&b, &walls, 181, 0.01, 2),
            Some(b.compose(&Pose2::new(-0.25, 0.2, -0.22))),
        ),
    ];
    let params = MatcherParams {
        coarse: Coarse::Always,
        ..MatcherParams::default()
    };
    let reports = match_run(&scans, &params);
    assert_eq!(reports[1].status, MatchStatus::Ok);
    assert!(
        close(&reports[1].estimate, &b, 0.01, 0.005),
        "{:?}",
        reports[1].estimate
    );
}

#[test]
fn every_record_gets_a_report_and_empty_scans_fall_back_to_odometry() {
    let walls = office();
    let truth = office_loop(6);
    let mut scans: Vec<_> = truth
        .iter()
        .enumerate()
        .map(|(i, p)| (scan_at(p, &walls, 181, 0.0, i as u64), Some(*p)))
        .collect();
    scans[2].0.clear();
    for mode in [Mode::Pairwise, Mode::Metascan] {
        let params = MatcherParams {
            mode,
            ..MatcherParams::default()
        };
        let reports = match_run(&scans, &params);
        assert_eq!(reports.len(), 6);
        assert_eq!(reports[0].status, MatchStatus::First);
        assert_eq!(
            reports[2].status,
            MatchStatus::Fallback(FallbackReason::NoValidRays)
        );
        for (r, t) in reports.iter().zip(&truth) {
            assert!(
                close(&r.estimate, t, 1e-4, 1e-4),
                "{mode:?}: {:?} vs {t:?}",
                r.estimate
            );
        }
    }
}

#[test]
fn metascan_around_a_loop_with_poor_odometry_stays_accurate() {
    let walls = office();
    let truth = office_loop(120);
    let odo = noisy_odometry(&truth, 0.02, 1f64.to_radians(), 7);
    let scans: Vec<_> = truth
        .iter()
        .zip(&odo)
        .enumerate()
        .map(|(i, (t, o))| (scan_at(t, &walls, 181, 0.01, 100 + i as u64), Some(*o)))
        .collect();
    for mode in [Mode::Pairwise, Mode::Metascan] {
        let mut m = Matcher::new(MatcherParams {
            mode,
            ..MatcherParams::default()
        });
        let est: Vec<Pose2> = scans.iter().map(|(p, o)| m.push(p, *o).estimate).collect();
        let r = rpe(&est, &truth).unwrap();
        let a = ate(&est, &truth).unwrap();
        eprintln!("{mode:?}: {r:?} ATE {a:?}");
        assert_eq!(r.bad_pairs, 0, "{mode:?}");
        assert!(r.median_translation < 0.003, "{mode:?}: {r:?}");
        if mode == Mode::Metascan {
            assert!(a.rmse < 0.015, "{a:?}");
        }
    }
}

#[test]
fn the_correction_gate_applies_only_to_a_guess_from_odometry() {
    // With no odometry the guess is the identity, which says nothing about the step: a match
    // farther than the gate from it is still the answer. With odometry that claims no motion,
    // the same match is rejected as a large correction.
    let walls = office();
    let a = Pose2::new(1.5, 2.0, 0.0);
    let b = Pose2::new(1.75, 2.05, 0.05);
    let mut params = MatcherParams::default();
    params.checks.max_correction_xy = 0.1;
    for mode in [Mode::Pairwise, Mode::Metascan] {
        let params = MatcherParams { mode, ..params };
        let blind = vec![
            (scan_at(&a, &walls, 181, 0.0, 1), None),
            (scan_at(&b, &walls, 181, 0.0, 2), None),
        ];
        let reports = match_run(&blind, &params);
        assert_eq!(reports[1].status, MatchStatus::Ok, "{mode:?}");
        let step = reports[0].estimate.between(&reports[1].estimate);
        assert!(
            close(&step, &a.between(&b), 1e-4, 1e-4),
            "{mode:?}: {step:?}"
        );
        let still = vec![
            (scan_at(&a, &walls, 181, 0.0, 1), Some(a)),
            (scan_at(&b, &walls, 181, 0.0, 2), Some(a)),
        ];
        let reports = match_run(&still, &params);
        // Metascan's map stage may name another reason once the local stage was refused.
        match mode {
            Mode::Pairwise => assert_eq!(
                reports[1].status,
                MatchStatus::Fallback(FallbackReason::LargeCorrection)
            ),
            Mode::Metascan => assert!(
                matches!(reports[1].status, MatchStatus::Fallback(_)),
                "{:?}",
                reports[1].status
            ),
        }
    }
}
