//! Pairwise matching on real logs (issue 4): the logs' corrected poses are the reference; the
//! odometry is made from them by perturbing each step with Gaussian noise (2% of the step's
//! distance + 5 mm in x and y, 2% of its rotation + 0.5 degree in heading, seeded per step,
//! `simulate::odometry`'s model), so the matcher must do better than dead reckoning. Scored by
//! RPE over consecutive pairs (Kümmerle et al. 2009), for the matcher and for the perturbed
//! odometry itself.
//!
//! A reference made by SLAM is not ground truth: where it is noisier than the matcher, RPE
//! measures the reference. The closure check needs no reference: every second scan is matched
//! again directly (scan i against scan i-2), and those two-scan steps are compared with the
//! composition of the two one-scan steps they span. A matcher that is right agrees with itself;
//! an RPE far above its closure error says the reference, not the matcher, sets the RPE.

use super::drift::{DRIFT_LENGTHS, Drift, segment_drift};
use super::metrics::{Rpe, rpe};
use super::pair_bound::RunBound;
use crate::geometry::{Pose, Pose2};
use crate::matching::{
    DeskewParams, MatchReport, MatchStatus, Matcher, MatcherParams, SweepTracker,
};
use crate::simulate::{OdometryParams, odometry};
use nalgebra::Point2;
use serde::Serialize;

/// One log's scans, reduced to what the experiment needs.
pub struct RealLog {
    pub name: String,
    /// Each scan's points in its scanner frame, in ray order.
    pub points: Vec<Vec<Point2<f64>>>,
    /// Each scan's reference (corrected) pose.
    pub reference: Vec<Pose2>,
    /// Each scan's time \[s\] (the log's timestamp, else its index), for the trajectories.
    pub times: Vec<f64>,
    /// What deskewing needs, when the run is deskewed.
    pub sweep: Option<RealSweep>,
}

/// Deskewing a log (`match --deskew`) with the odometry the experiment makes: each scan's
/// velocity from its perturbed odometry and the previous scan's.
pub struct RealSweep {
    pub params: DeskewParams,
    /// Each point's time after the mean time of its scan's rays \[s\], as `points`.
    pub ray_times: Vec<Vec<f64>>,
    /// Each scan's timestamp \[s\], if it has one.
    pub stamps: Vec<Option<f64>>,
}

impl RealSweep {
    /// The log's points deskewed with `odometry`'s velocities, and how many scans had one.
    fn deskewed(
        &self,
        points: &[Vec<Point2<f64>>],
        odometry: &[Pose2],
    ) -> (Vec<Vec<Point2<f64>>>, usize) {
        let mut tracker = SweepTracker::new();
        let mut count = 0;
        let points = points
            .iter()
            .zip(&self.ray_times)
            .zip(odometry.iter().zip(&self.stamps))
            .map(|((points, times), (odometry, stamp))| {
                let mut points = points.clone();
                if tracker.deskew_next(&mut points, times, Some(*odometry), *stamp, &self.params) {
                    count += 1;
                }
                points
            })
            .collect();
        (points, count)
    }
}

/// What the experiment found on one log.
#[derive(Clone, Debug, Serialize)]
pub struct RealResult {
    pub name: String,
    pub scans: usize,
    /// RPE of the matched trajectory against the reference.
    pub matched: Rpe,
    /// RPE of the perturbed odometry against the reference.
    pub odometry: Rpe,
    /// Drift of the matched trajectory over 1, 2, 5 and 10 m of reference path (the lengths
    /// the path is long enough for): the figure to trust where the reference jitters per step.
    pub drift: Vec<Drift>,
    /// The same for the perturbed odometry.
    pub odometry_drift: Vec<Drift>,
    /// Self-consistency: RPE of the direct matches of every second scan against the
    /// composition of the consecutive matches they span (no reference needed). `None` below
    /// three scans.
    pub closure: Option<Rpe>,
    /// Scans whose step fell back to odometry.
    pub fallbacks: usize,
    /// Scans where the coarse search ran.
    pub coarse: usize,
    /// Scans deskewed (`match --deskew`), when the run was; the others had no velocity.
    pub deskewed: Option<usize>,
    /// The Cramér-Rao bound over the consecutive pairs, for a run simulated in a known plan
    /// ([`super::pair_bound::run_bound`]; set by the caller, who has the plan).
    pub bound: Option<RunBound>,
    /// The matched trajectory, one pose per scan (written as a TUM file beside the tables, for
    /// `evo`; not in the JSON).
    #[serde(skip)]
    pub matched_poses: Vec<Pose2>,
    /// The perturbed odometry, likewise.
    #[serde(skip)]
    pub odometry_poses: Vec<Pose2>,
}

/// Perturbs the reference into odometry (seeded), matches the log, scores both.
/// `None` for a log of fewer than two scans.
pub fn evaluate_real(
    log: &RealLog,
    params: &MatcherParams,
    noise: &OdometryParams,
    seed: u64,
) -> Option<RealResult> {
    let poses: Vec<Pose> = log
        .reference
        .iter()
        .map(|p| Pose::planar(p.x, p.y, p.theta))
        .collect();
    let odo: Vec<Pose2> = odometry(&poses, noise, seed)
        .iter()
        .map(|p| p.to_pose2())
        .collect();
    let deskewed = log.sweep.as_ref().map(|s| s.deskewed(&log.points, &odo));
    let points = deskewed.as_ref().map_or(&log.points, |d| &d.0);
    let reports = match_all(points.iter().zip(&odo), params);
    let estimate: Vec<Pose2> = reports.iter().map(|r| r.estimate).collect();
    let every_second = points.iter().zip(&odo).step_by(2);
    let direct: Vec<Pose2> = match_all(every_second, params)
        .iter()
        .map(|r| r.estimate)
        .collect();
    let composed: Vec<Pose2> = estimate.iter().step_by(2).copied().collect();
    Some(RealResult {
        name: log.name.clone(),
        scans: log.points.len(),
        matched: rpe(&estimate, &log.reference)?,
        odometry: rpe(&odo, &log.reference)?,
        drift: drifts(&estimate, &log.reference),
        odometry_drift: drifts(&odo, &log.reference),
        closure: rpe(&direct, &composed),
        fallbacks: reports
            .iter()
            .filter(|r| matches!(r.status, MatchStatus::Fallback(_)))
            .count(),
        coarse: reports.iter().filter(|r| r.coarse).count(),
        deskewed: deskewed.as_ref().map(|d| d.1),
        bound: None,
        matched_poses: estimate,
        odometry_poses: odo,
    })
}

fn drifts(estimate: &[Pose2], reference: &[Pose2]) -> Vec<Drift> {
    DRIFT_LENGTHS
        .iter()
        .filter_map(|l| segment_drift(estimate, reference, *l))
        .collect()
}

fn match_all<'a>(
    scans: impl Iterator<Item = (&'a Vec<Point2<f64>>, &'a Pose2)>,
    params: &MatcherParams,
) -> Vec<MatchReport> {
    let mut matcher = Matcher::new(*params);
    scans.map(|(pts, o)| matcher.push(pts, Some(*o))).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn perturbed_odometry_is_worse_than_matching_identical_scans() {
        // A box seen from poses along a line; matching recovers steps the noise spoils.
        let reference: Vec<Pose2> = (0..30)
            .map(|i| Pose2::new(0.05 * i as f64, 0.0, 0.0))
            .collect();
        let points: Vec<Vec<Point2<f64>>> = reference
            .iter()
            .map(|p| {
                (0..181)
                    .filter_map(|k| {
                        let a =
                            -std::f64::consts::FRAC_PI_2 + std::f64::consts::PI * k as f64 / 180.0;
                        let (s, c) = a.sin_cos();
                        // Walls x = 4 and y = +-2.5, seen from (p.x, 0).
                        let rx = if c > 1e-9 {
                            (4.0 - p.x) / c
                        } else {
                            f64::INFINITY
                        };
                        let ry = if s.abs() > 1e-9 {
                            2.5 / s.abs()
                        } else {
                            f64::INFINITY
                        };
                        let r = rx.min(ry);
                        r.is_finite().then(|| Point2::new(r * c, r * s))
                    })
                    .collect()
            })
            .collect();
        let times = (0..reference.len()).map(|i| i as f64).collect();
        let log = RealLog {
            name: "box".into(),
            points,
            reference,
            sweep: None,
            times,
        };
        let r = evaluate_real(
            &log,
            &MatcherParams::default(),
            &OdometryParams::default(),
            1,
        )
        .unwrap();
        assert_eq!(r.scans, 30);
        assert_eq!(r.fallbacks, 0);
        assert!(r.matched.median_translation < 1e-4, "{r:?}");
        assert!(r.odometry.median_translation > 1e-3, "{r:?}");
        // 1.45 m of path: only the 1 m segments fit; matching drifts far less than odometry.
        assert_eq!(r.drift.len(), 1);
        assert_eq!(r.drift[0].segments, 10);
        assert!(r.drift[0].translation_percent < 0.01, "{r:?}");
        assert!(r.odometry_drift[0].translation_percent > 0.1, "{r:?}");
        let closure = r.closure.unwrap();
        assert_eq!(closure.pairs, 14);
        assert!(closure.median_translation < 1e-4, "{r:?}");
    }
}
