//! One run, pose by pose: what level and match said, against the truth where the records carry
//! it. The numbers behind the plots people look for first: roll and pitch over time with their
//! 3-sigma band (sect. 5.4's sigmas), and the position error along the trajectory (Sturm et al.
//! 2012's ATE, pose by pose).
//!
//! Read from the records themselves, in any mix: `level` output (an attitude and its sigmas),
//! `match` output (an `estimate`; its `level` object when it matched leveled scans), and raw
//! scans, whose 6-DOF `true_pose` gives the true attitude of their `sequence` (level output
//! keeps only `[x, y, rz]` of it).

use super::metrics::{Ate, ate};
use crate::geometry::Pose2;
use crate::scan::Scan;
use serde::Serialize;
use std::collections::HashMap;

/// One pose of a run.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RunPose {
    pub sequence: Option<u64>,
    /// Seconds since the run's first timestamp, when the records have timestamps.
    pub time_s: Option<f64>,
    /// Level's estimate `[theta_x, theta_y]` (roll, pitch) \[rad\], when leveled.
    pub attitude: Option<[f64; 2]>,
    /// Its sigmas \[rad\].
    pub sigma: Option<[f64; 2]>,
    /// Why level failed, when it did.
    pub reason: Option<String>,
    /// The true attitude `[theta_x, theta_y]` \[rad\], from a raw scan of the same sequence.
    pub true_attitude: Option<[f64; 2]>,
    /// The planar estimate (match's) and the reference (`true_pose`).
    #[serde(skip)]
    pub estimate: Option<Pose2>,
    #[serde(skip)]
    pub reference: Option<Pose2>,
}

/// The run's summary and its per-pose errors.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RunEvaluation {
    pub poses: usize,
    pub leveled: usize,
    /// RMS error of roll and pitch over leveled poses with a known truth \[deg\].
    pub attitude_rmse_deg: Option<[f64; 2]>,
    /// Largest max(|d roll|, |d pitch|) \[deg\].
    pub attitude_max_deg: Option<f64>,
    /// Share of those poses whose roll and pitch errors both lie within 3 sigmas.
    pub within_3_sigma: Option<f64>,
    /// ATE of the estimates against the reference, over poses that have both.
    pub ate: Option<Ate>,
    /// Per pose: the estimate after the ATE alignment \[m, m, rad\].
    #[serde(skip)]
    pub aligned: Vec<Option<Pose2>>,
    /// Per pose: its position error after the alignment \[m\].
    pub position_error_m: Vec<Option<f64>>,
    /// Per pose: distance travelled along the reference up to it \[m\].
    pub distance_m: Vec<Option<f64>>,
}

fn level_field(scan: &Scan, key: &str) -> Option<f64> {
    scan.extra.get("level")?.get(key)?.as_f64()
}

/// The poses of a run: one per `level` or `match` record, in order, with the true attitude of
/// raw scans of the same sequence. Empty when the records hold neither.
pub fn run_poses(records: &[Scan]) -> Vec<RunPose> {
    let is_output = |s: &Scan| s.extra.contains_key("level") || s.extra.contains_key("match");
    let mut truth: HashMap<u64, [f64; 2]> = HashMap::new();
    for s in records.iter().filter(|s| !is_output(s)) {
        if let (Some(seq), Some(p)) = (s.sequence, s.true_pose) {
            truth.entry(seq).or_insert([p.rx, p.ry]);
        }
    }
    let outputs: Vec<&Scan> = records.iter().filter(|s| is_output(s)).collect();
    let t0 = outputs
        .iter()
        .find_map(|s| s.timestamp)
        .map(|t| t.seconds());
    outputs
        .iter()
        .map(|s| {
            let pair = |a: &str, b: &str| Some([level_field(s, a)?, level_field(s, b)?]);
            let reason = s
                .extra
                .get("level")
                .and_then(|l| l.get("reason"))
                .and_then(|r| r.as_str())
                .map(str::to_string);
            RunPose {
                sequence: s.sequence,
                time_s: s.timestamp.zip(t0).map(|(t, t0)| t.seconds() - t0),
                attitude: pair("theta_x", "theta_y"),
                sigma: pair("sigma_x", "sigma_y"),
                reason,
                true_attitude: s.sequence.and_then(|q| truth.get(&q).copied()),
                estimate: s.estimate.map(|p| p.to_pose2()),
                reference: s.true_pose.map(|p| p.to_pose2()),
            }
        })
        .collect()
}

/// Attitude statistics and the trajectory error of a run's poses.
pub fn evaluate_run(poses: &[RunPose]) -> RunEvaluation {
    // (estimate, truth, sigma) of every leveled pose with a known truth.
    type Judged = ([f64; 2], [f64; 2], Option<[f64; 2]>);
    let judged: Vec<Judged> = poses
        .iter()
        .filter_map(|p| Some((p.attitude?, p.true_attitude?, p.sigma)))
        .collect();
    let n = judged.len() as f64;
    let rms = |k: usize| {
        (judged
            .iter()
            .map(|j| (j.0[k] - j.1[k]).powi(2))
            .sum::<f64>()
            / n)
            .sqrt()
    };
    let attitude_rmse_deg =
        (!judged.is_empty()).then(|| [rms(0).to_degrees(), rms(1).to_degrees()]);
    let attitude_max_deg = judged
        .iter()
        .map(|j| {
            (j.0[0] - j.1[0])
                .abs()
                .max((j.0[1] - j.1[1]).abs())
                .to_degrees()
        })
        .reduce(f64::max);
    let within = judged
        .iter()
        .filter(|j| {
            j.2.is_some_and(|s| (0..2).all(|k| (j.0[k] - j.1[k]).abs() <= 3.0 * s[k]))
        })
        .count();
    let (ate, aligned, position_error_m) = trajectory_error(poses);
    RunEvaluation {
        poses: poses.len(),
        leveled: poses.iter().filter(|p| p.attitude.is_some()).count(),
        attitude_rmse_deg,
        attitude_max_deg,
        within_3_sigma: (!judged.is_empty()).then(|| within as f64 / n),
        ate,
        aligned,
        position_error_m,
        distance_m: distance_along(poses),
    }
}

type TrajectoryError = (Option<Ate>, Vec<Option<Pose2>>, Vec<Option<f64>>);

/// The ATE alignment over the poses with an estimate and a reference, and each pose's aligned
/// estimate and position error.
fn trajectory_error(poses: &[RunPose]) -> TrajectoryError {
    let (est, refs): (Vec<Pose2>, Vec<Pose2>) = poses
        .iter()
        .filter_map(|p| Some((p.estimate?, p.reference?)))
        .unzip();
    let Some(a) = ate(&est, &refs) else {
        return (None, vec![None; poses.len()], vec![None; poses.len()]);
    };
    let aligned: Vec<Option<Pose2>> = poses
        .iter()
        .map(|p| p.estimate.map(|e| a.alignment.compose(&e)))
        .collect();
    let errors = aligned
        .iter()
        .zip(poses)
        .map(|(e, p)| Some((e.as_ref()?.translation() - p.reference?.translation()).norm()))
        .collect();
    (Some(a), aligned, errors)
}

/// Distance travelled along the reference up to each pose (`None` before the first reference
/// and where a pose has none).
fn distance_along(poses: &[RunPose]) -> Vec<Option<f64>> {
    let mut total = 0.0;
    let mut last: Option<Pose2> = None;
    poses
        .iter()
        .map(|p| {
            let r = p.reference?;
            if let Some(l) = last {
                total += (r.translation() - l.translation()).norm();
            }
            last = Some(r);
            Some(total)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Pose;
    use crate::scan::Timestamp;
    use serde_json::json;

    fn level_record(seq: u64, att: Option<[f64; 2]>, estimate: Pose, truth: Pose) -> Scan {
        let mut s = Scan {
            sequence: Some(seq),
            estimate: Some(estimate),
            true_pose: Some(truth),
            timestamp: Some(Timestamp {
                sec: 100 + seq as i64,
                usec: 500_000,
            }),
            ..Scan::default()
        };
        let level = match att {
            Some([x, y]) => json!({"status": "ok", "theta_x": x, "theta_y": y,
                                   "sigma_x": 0.005, "sigma_y": 0.005}),
            None => json!({"status": "failed", "reason": "facing_floor"}),
        };
        s.extra.insert("level".into(), level);
        s.extra.insert("match".into(), json!({"status": "ok"}));
        s
    }

    fn raw(seq: u64, rx: f64, ry: f64) -> Scan {
        Scan {
            sequence: Some(seq),
            true_pose: Some(Pose::new(0.0, 0.0, 0.45, 0.0, ry, rx)),
            ..Scan::default()
        }
    }

    #[test]
    fn attitude_errors_join_raw_truth_by_sequence() {
        let records = vec![
            raw(0, 0.10, -0.05),
            raw(0, 0.10, -0.05),
            raw(1, 0.0, 0.2),
            level_record(
                0,
                Some([0.12, -0.05]),
                Pose::planar(0.0, 0.0, 0.0),
                Pose::planar(0.0, 0.0, 0.0),
            ),
            level_record(
                1,
                None,
                Pose::planar(1.0, 0.0, 0.0),
                Pose::planar(1.0, 0.0, 0.0),
            ),
        ];
        let poses = run_poses(&records);
        assert_eq!(poses.len(), 2);
        assert_eq!(poses[0].true_attitude, Some([0.10, -0.05]));
        assert_eq!((poses[0].time_s, poses[1].time_s), (Some(0.0), Some(1.0)));
        assert_eq!(poses[1].reason.as_deref(), Some("facing_floor"));
        let ev = evaluate_run(&poses);
        assert_eq!((ev.poses, ev.leveled), (2, 1));
        let [rx, ry] = ev.attitude_rmse_deg.unwrap();
        assert!((rx - 0.02f64.to_degrees()).abs() < 1e-9 && ry.abs() < 1e-9);
        // 0.02 rad off with a sigma of 0.005: outside 3 sigma.
        assert_eq!(ev.within_3_sigma, Some(0.0));
    }

    #[test]
    fn position_error_is_measured_after_the_alignment() {
        // The estimate is the reference turned by 90 degrees about the origin, and pose 2 is
        // 0.3 m off: the alignment takes the turn out, leaving errors at pose 2 only (spread).
        let refs = [(0.0, 0.0), (2.0, 0.0), (2.0, 2.0), (0.0, 2.0)];
        let records: Vec<Scan> = refs
            .iter()
            .enumerate()
            .map(|(k, &(x, y))| {
                let off = if k == 2 { 0.3 } else { 0.0 };
                let (ex, ey) = (-(y + off), x);
                level_record(
                    k as u64,
                    Some([0.0, 0.0]),
                    Pose::planar(ex, ey, 0.0),
                    Pose::planar(x, y, 0.0),
                )
            })
            .collect();
        let ev = evaluate_run(&run_poses(&records));
        let errors: Vec<f64> = ev.position_error_m.iter().map(|e| e.unwrap()).collect();
        let rmse = (errors.iter().map(|e| e * e).sum::<f64>() / 4.0).sqrt();
        assert!((rmse - ev.ate.unwrap().rmse).abs() < 1e-12);
        assert!(errors[2] > errors[0] && errors[2] < 0.3);
        assert_eq!(
            ev.distance_m,
            vec![Some(0.0), Some(2.0), Some(4.0), Some(6.0)]
        );
    }
}
