//! Deskewing (`matching::deskew`): a robot that turns while it scans warps each scan, and
//! pairwise matching adds the warp's heading error at every step; moved to the scanner's
//! frame at each stamp with the odometry's velocity, the scans match without it.

mod matching_support;

use levelscan::geometry::Pose2;
use levelscan::matching::{DeskewParams, MatcherParams, Mode, SweepTracker, match_run};
use matching_support::*;
use nalgebra::Point2;

/// Time between scans \[s\] and the sweep of one scan from its first ray to its last \[s\]
/// (a 40 Hz scanner's).
const PERIOD: f64 = 0.1;
const SWEEP: f64 = 0.025;
const RAYS: usize = 181;
/// Scans in one lap: 12 s round the pillar, 30 degrees a second at 0.7 m/s.
const LAP: usize = 120;

/// A scan's points and each one's time after the scan's stamp \[s\].
type TimedScan = (Vec<Point2<f64>>, Vec<f64>);

/// The steady turn of [`steady_turn`]: the true poses and each scan's points with their times
/// after its stamp.
fn swept_loop() -> (Vec<Pose2>, Vec<TimedScan>) {
    let (truth, ranges) = steady_turn(LAP, PERIOD, SWEEP, RAYS);
    let scans = ranges
        .iter()
        .map(|ranges| {
            ranges
                .iter()
                .enumerate()
                .filter_map(|(i, r)| {
                    let (s, c) = bearing(i, RAYS).sin_cos();
                    let t = SWEEP * i as f64 / (RAYS - 1) as f64;
                    r.map(|r| (Point2::new(r * c, r * s), t))
                })
                .unzip()
        })
        .collect();
    (truth, scans)
}

/// The run's heading error summed over its steps from the second scan on \[rad\]: what
/// pairwise matching adds up. (The first scan has no velocity before it and is matched as
/// recorded: right for a robot that starts from rest, as this one does not.)
fn heading_drift(estimate: &[Pose2], truth: &[Pose2]) -> f64 {
    estimate
        .windows(2)
        .zip(truth.windows(2))
        .skip(1)
        .map(|(e, t)| {
            let d = e[0].between(&e[1]).theta - t[0].between(&t[1]).theta;
            d.sin().atan2(d.cos())
        })
        .sum()
}

/// The heading drift of pairwise matching with `odometry`, the scans as recorded and
/// deskewed with the odometry's velocity (a scan's from the previous scan's odometry).
fn drift_recorded_and_deskewed(
    truth: &[Pose2],
    scans: &[TimedScan],
    odometry: &[Pose2],
) -> (f64, f64) {
    let params = MatcherParams {
        mode: Mode::Pairwise,
        ..MatcherParams::default()
    };
    let recorded: Vec<_> = scans
        .iter()
        .zip(odometry)
        .map(|((points, _), o)| (points.clone(), Some(*o)))
        .collect();
    let mut tracker = SweepTracker::new();
    let deskewing = DeskewParams::default();
    let deskewed: Vec<_> = scans
        .iter()
        .zip(odometry)
        .enumerate()
        .map(|(k, ((points, times), o))| {
            let mut points = points.clone();
            let time = Some(k as f64 * PERIOD);
            tracker.deskew_next(&mut points, times, Some(*o), time, &deskewing);
            (points, Some(*o))
        })
        .collect();
    let run = |inputs: &[(Vec<Point2<f64>>, Option<Pose2>)]| {
        let estimate: Vec<Pose2> = match_run(inputs, &params)
            .iter()
            .map(|r| r.estimate)
            .collect();
        heading_drift(&estimate, truth)
    };
    (run(&recorded), run(&deskewed))
}

#[test]
fn deskewed_pairwise_matching_keeps_the_heading_a_turning_sweep_loses() {
    let (truth, scans) = swept_loop();
    // A steady turn of omega over a sweep of T through pi of bearing stretches the scan's
    // bearings by 1 + omega T / pi, so each step's turn dtheta is found short by
    // dtheta omega T / pi, with omega = dtheta / PERIOD: -1.5 degrees over the lap, to first
    // order (the drive during the sweep adds a little).
    let predicted: f64 = truth
        .windows(2)
        .skip(1)
        .map(|w| {
            let turn = w[0].between(&w[1]).theta;
            -turn * turn * SWEEP / (std::f64::consts::PI * PERIOD)
        })
        .sum();
    // With the odometry exact, deskewing leaves nothing of it (the turn is steady, so the
    // previous step's velocity is this sweep's); with a wheel odometry's noise (2 mm and 0.1
    // degree a step) in the velocity too, little.
    let noisy = noisy_odometry(&truth, 0.002, 0.1f64.to_radians(), 11);
    for (odometry, left) in [(&truth, 1e-9), (&noisy, 0.15 * predicted.abs())] {
        let (as_recorded, fixed) = drift_recorded_and_deskewed(&truth, &scans, odometry);
        assert!(
            (as_recorded - predicted).abs() < 0.15 * predicted.abs(),
            "as recorded {:.3} deg, predicted {:.3}",
            as_recorded.to_degrees(),
            predicted.to_degrees()
        );
        assert!(
            fixed.abs() < left,
            "deskewed {:.4} deg against {:.4} as recorded",
            fixed.to_degrees(),
            as_recorded.to_degrees()
        );
    }
}
