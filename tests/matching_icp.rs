//! The matcher on synthetic scans with known answers.

mod common;
mod matching_support;

use common::example_plan;
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
fn a_view_of_two_walls_keeps_the_rotation_it_started_near() {
    // From where the office loop passes its north-west side, the scan sees the west and
    // south walls and little else: their lines meet at the corner, so a scan scaled about the
    // corner fits them too, and the rotation's mirror image fits as well as the rotation.
    // ICP from the exact step must stay there, not jump to the mirror image (it did, and the
    // match fell back to odometry as a large correction).
    let walls = office();
    let truth = office_loop(120);
    for k in [52, 54] {
        let reference = ScanReference::new(
            scan_at(&truth[k - 1], &walls, 181, 0.0, 1),
            &Point2::origin(),
            &NormalParams::default(),
        );
        let source = scan_at(&truth[k], &walls, 181, 0.0, 2);
        let step = truth[k - 1].between(&truth[k]);
        let r = icp(&source, &reference, step, &IcpParams::default()).unwrap();
        assert!(
            close(&r.pose, &step, 1e-9, 1e-9),
            "{k}: {:?} vs {step:?}",
            r.pose
        );
    }
    let inputs: Vec<_> = truth
        .iter()
        .map(|p| (scan_at(p, &walls, 181, 0.0, 1), Some(*p)))
        .collect();
    for mode in [Mode::Pairwise, Mode::Metascan] {
        let params = MatcherParams {
            mode,
            ..MatcherParams::default()
        };
        let reports = match_run(&inputs, &params);
        let fallbacks = reports
            .iter()
            .filter(|r| matches!(r.status, MatchStatus::Fallback(_)))
            .count();
        assert_eq!(fallbacks, 0, "{mode:?}");
    }
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
fn a_corridor_is_flagged_degenerate_when_matching_all_or_nothing() {
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
        params.checks.min_information_ratio = None;
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

/// Two scans in a corridor turned by `heading` (noise-free), the second with odometry off
/// by `odometry_error` (in the first scan's frame), matched with `params`.
fn corridor_step(
    heading: f64,
    odometry_error: Pose2,
    params: &MatcherParams,
) -> (levelscan::matching::MatchReport, Pose2, Pose2) {
    let turn = Pose2::new(0.0, 0.0, heading);
    let walls: Vec<Segment> = corridor()
        .iter()
        .map(|(u, v)| (turn.transform_point(u), turn.transform_point(v)))
        .collect();
    let a = turn;
    let step = Pose2::new(0.6, 0.08, 0.03);
    let b = a.compose(&step);
    let odometry_step = Pose2::new(
        step.x + odometry_error.x,
        step.y + odometry_error.y,
        step.theta + odometry_error.theta,
    );
    let scans = vec![
        (scan_at(&a, &walls, 181, 0.0, 1), Some(a)),
        (
            scan_at(&b, &walls, 181, 0.0, 2),
            Some(a.compose(&odometry_step)),
        ),
    ];
    let reports = match_run(&scans, params);
    (reports[1], step, odometry_step)
}

#[test]
fn a_corridor_takes_its_length_from_the_odometry_and_the_rest_from_the_scan() {
    // Odometry 7 cm long, 4 cm to the side and 1.1 degrees off: the corridor's walls fix the
    // side and the heading exactly, its length is the odometry's, whatever way it points.
    let error = Pose2::new(0.07, -0.04, 0.02);
    for heading in [0.0, 30f64.to_radians(), -2.0] {
        let (report, truth, odometry) = corridor_step(heading, error, &MatcherParams::default());
        assert_eq!(report.status, MatchStatus::Ok, "{heading}");
        let start = Pose2::new(0.0, 0.0, heading);
        let step = start.between(&report.estimate);
        // In the first scan's frame the corridor runs along x.
        assert!((step.x - odometry.x).abs() < 1e-9, "{heading}: {step:?}");
        assert!((step.y - truth.y).abs() < 1e-9, "{heading}: {step:?}");
        assert!(
            wrap_angle(step.theta - truth.theta).abs() < 1e-9,
            "{heading}: {step:?}"
        );
        let free = report.degenerate_directions();
        assert_eq!(free.len(), 1, "{heading}: {free:?}");
        let f = free[0];
        assert!(
            f[0].abs() > 1.0 - 1e-9 && f[1].abs() < 1e-6 && f[2].abs() < 1e-6,
            "{f:?}"
        );
    }
    // Point-to-point pairs slide too; its free direction is the same, its fit only close.
    let mut params = MatcherParams::default();
    params.icp.metric = Metric::PointToPoint;
    let (report, truth, odometry) = corridor_step(0.3, error, &params);
    assert_eq!(report.status, MatchStatus::Ok);
    let step = Pose2::new(0.0, 0.0, 0.3).between(&report.estimate);
    assert!((step.x - odometry.x).abs() < 1e-9, "{step:?}");
    assert!((step.y - truth.y).abs() < 0.01 && (step.theta - truth.theta).abs() < 0.01);
    assert_eq!(report.degenerate_directions().len(), 1);
}

#[test]
fn metascan_takes_a_halls_length_from_its_map_when_the_odometry_errs_along_it() {
    // A hall 4 m wide whose end wall, 12 m ahead of the start, is the only thing that pins its
    // length. Five scans with exact odometry build the map; the sixth's odometry is 6 cm long.
    // The end wall's pairs are then misfit by more than the kernel scale and trimming drops
    // them, so the solve would take the length from the odometry (6 cm off on every seed
    // without the map stage's untrimmed retry); with every pair kept the map pins it.
    let p = Point2::new;
    let walls = vec![
        (p(-30.0, -2.0), p(12.0, -2.0)),
        (p(12.0, -2.0), p(12.0, 2.0)),
        (p(12.0, 2.0), p(-30.0, 2.0)),
    ];
    let truth: Vec<Pose2> = (0..6)
        .map(|i| Pose2::new(i as f64, 0.3 * (i % 2) as f64, 0.05 * (i % 3) as f64))
        .collect();
    let mut odometry = truth.clone();
    odometry[5].x += 0.06;
    let params = MatcherParams {
        mode: Mode::Metascan,
        ..MatcherParams::default()
    };
    for seed in 1..=10u64 {
        let scans: Vec<_> = (0..6)
            .map(|i| {
                let points = scan_at(&truth[i], &walls, 181, 0.01, 10 * seed + i as u64);
                (points, Some(odometry[i]))
            })
            .collect();
        let report = match_run(&scans, &params)[5];
        assert_eq!(report.status, MatchStatus::Ok, "seed {seed}");
        assert!(
            close(&report.estimate, &truth[5], 0.01, 0.002),
            "seed {seed}: {:?}",
            report.estimate
        );
    }
}

#[test]
fn in_a_room_nothing_is_free_and_the_match_is_the_all_or_nothing_one() {
    let walls = office();
    let truth = [Pose2::new(2.0, 1.5, 0.3), Pose2::new(2.15, 1.58, 0.36)];
    let odometry = [truth[0], Pose2::new(2.2, 1.55, 0.34)];
    let scans: Vec<_> = (0..2)
        .map(|i| {
            (
                scan_at(&truth[i], &walls, 181, 0.01, i as u64),
                Some(odometry[i]),
            )
        })
        .collect();
    for mode in [Mode::Pairwise, Mode::Metascan] {
        let params = MatcherParams {
            mode,
            ..MatcherParams::default()
        };
        let mut whole = params;
        whole.checks.min_information_ratio = None;
        let (aware, all_or_nothing) = (match_run(&scans, &params), match_run(&scans, &whole));
        assert_eq!(aware[1].status, MatchStatus::Ok, "{mode:?}");
        assert!(aware[1].degenerate_directions().is_empty(), "{mode:?}");
        assert_eq!(aware[1].remapped.map(|m| m.free), Some(0), "{mode:?}");
        assert_eq!(aware[1].estimate, all_or_nothing[1].estimate, "{mode:?}");
        assert_eq!(
            aware[1].covariance, all_or_nothing[1].covariance,
            "{mode:?}"
        );
        assert!(close(&aware[1].estimate, &truth[1], 0.01, 0.01), "{mode:?}");
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

/// Asserts that no step of `run` fell back whole for one of `reasons`.
fn assert_none_thrown_away(
    run: &levelscan::eval::matching::RunResult,
    reasons: &[FallbackReason],
    what: &str,
) {
    for (i, r) in run.reports.iter().enumerate() {
        assert!(
            !matches!(r.status, MatchStatus::Fallback(f) if reasons.contains(&f)),
            "{what} {:?} {:?} step {i}: {:?}",
            run.kind,
            run.mode,
            r.status
        );
    }
}

/// The halls of examples/plans (tilted 30-pose runs, 1.5 m steps, long parallel walls and a
/// few pillars), leveled and matched as `eval matching` does: where a pose leveled, its scan
/// pins some direction (the hall's width and the heading at least), so no step may be thrown
/// away whole for degeneracy; the rest comes from odometry.
#[test]
fn tilted_runs_through_large_halls_keep_what_the_scans_pin() {
    use levelscan::eval::matching::{ExperimentParams, RunKind, matching_experiment};
    // All-or-nothing matching throws many of these steps away whole.
    let mut whole = ExperimentParams::default();
    whole.matcher.checks.min_information_ratio = None;
    let (_, runs) = matching_experiment(&example_plan("long_hall"), &whole);
    let thrown = runs
        .iter()
        .filter(|r| r.kind == RunKind::Leveled && r.mode == Mode::Pairwise)
        .flat_map(|r| &r.reports)
        .filter(|r| r.status == MatchStatus::Fallback(FallbackReason::Degenerate))
        .count();
    assert!(thrown >= 5, "{thrown} degenerate steps");
    // Seeds 1-3 (the odometry draws). A run's ATE here is mostly where its odometry errs
    // along a stretch nothing in view pins (seed 2: the level-floor metascan run itself
    // reaches 7.1 cm; fixing one step may undo a lucky cancellation), so the limits hold for
    // the mean over the three draws, or the leveled runs stay within 10% of the control:
    // the same path on a level floor, matched the same way.
    for name in ["long_hall", "wide_hall"] {
        let plan = example_plan(name);
        // Per mode: the leveled runs' and the controls' ATE summed over the seeds.
        let mut sums = [(0.0, 0.0); 2];
        for seed in 1..=3 {
            let params = ExperimentParams {
                seed,
                ..ExperimentParams::default()
            };
            let (_, runs) = matching_experiment(&plan, &params);
            for run in runs.iter().filter(|r| r.kind == RunKind::Leveled) {
                let control = runs
                    .iter()
                    .find(|r| r.kind == RunKind::LevelFloor && r.mode == run.mode)
                    .and_then(|r| r.ate.as_ref())
                    .unwrap()
                    .rmse;
                let sum = &mut sums[(run.mode == Mode::Metascan) as usize];
                sum.0 += run.ate.as_ref().unwrap().rmse;
                sum.1 += control;
                assert_none_thrown_away(
                    run,
                    &[
                        FallbackReason::Degenerate,
                        FallbackReason::TooFewCorrespondences,
                    ],
                    &format!("{name} seed {seed}"),
                );
            }
        }
        for (mode, limit, (ate, control)) in [
            (Mode::Pairwise, 0.10, sums[0]),
            (Mode::Metascan, 0.05, sums[1]),
        ] {
            let (ate, control) = (ate / 3.0, control / 3.0);
            assert!(
                ate <= limit || ate <= 1.1 * control,
                "{name} {mode:?}: mean ATE {ate} (level floor {control})"
            );
        }
    }
}

#[test]
fn halls_nobody_tuned_for_throw_no_step_away_whole() {
    use levelscan::eval::matching::{ExperimentParams, RunKind, matching_experiment};
    // The halls written after the matcher was tuned (examples/plans/halls/): in every run,
    // leveled or on a level floor, no step falls back whole for want of pinned directions.
    // (Their ATE is in docs/RESULTS.md: the pilaster hall's metascan misses 5 cm.)
    for name in ["pilaster_hall", "one_pillar_hall", "one_side_hall"] {
        let plan = example_plan(&format!("halls/{name}"));
        for seed in 1..=3 {
            let params = ExperimentParams {
                seed,
                ..ExperimentParams::default()
            };
            let (_, runs) = matching_experiment(&plan, &params);
            for run in runs.iter().filter(|r| r.kind != RunKind::Raw) {
                assert_none_thrown_away(
                    run,
                    &[
                        FallbackReason::Degenerate,
                        FallbackReason::TooFewCorrespondences,
                        FallbackReason::HighResidual,
                    ],
                    &format!("{name} seed {seed}"),
                );
            }
        }
    }
}

/// In furnished rooms metascan on a level floor stays near what the scans hold: its ATE, the
/// mean over seeds 1-3, within twice the Cramér-Rao bound on the whole path (the expected ATE
/// of an efficient estimator that saw the whole run; 1.4-1.6 times it when this was written),
/// and not far below it, which only an error in the bound or the scoring could give.
#[test]
fn metascan_in_rooms_stays_near_the_bound_on_the_path() {
    use levelscan::eval::bound::WallPlanes;
    use levelscan::eval::matching::{ExperimentParams, RunKind, matching_experiment};
    use levelscan::eval::pair_bound::scan_rays;
    use levelscan::eval::path_bound::path_bound;
    use levelscan::simulate::World;
    for name in ["office", "two_rooms"] {
        let plan = example_plan(name);
        let (world, planes) = (World::from_plan(&plan), WallPlanes::new(&plan.segments()));
        let truth: Vec<Pose2> = plan.poses.iter().map(|p| p.to_pose2()).collect();
        let defaults = ExperimentParams::default();
        let scanner = &defaults.scanner;
        let rays: Vec<_> = truth
            .iter()
            .map(|p| scan_rays(&world, &planes, p, scanner.bearings(), scanner.max_range))
            .collect();
        let sigma = scanner.range_sigma();
        let bound = path_bound(&planes, &truth, &rays, sigma, &defaults.odometry, 1)
            .unwrap()
            .ate;
        let mean = (1..=3)
            .map(|seed| {
                let params = ExperimentParams {
                    seed,
                    ..ExperimentParams::default()
                };
                let (_, runs) = matching_experiment(&plan, &params);
                runs.iter()
                    .find(|r| r.kind == RunKind::LevelFloor && r.mode == Mode::Metascan)
                    .and_then(|r| r.ate.as_ref())
                    .unwrap()
                    .rmse
            })
            .sum::<f64>()
            / 3.0;
        assert!(
            mean <= 2.0 * bound && mean >= 0.8 * bound,
            "{name}: metascan {mean:.4} m against the bound {bound:.4} m"
        );
    }
}
