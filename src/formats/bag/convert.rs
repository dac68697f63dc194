//! The messages `level` and `match` add to an output bag (CONTRACT.md, "ROS bags"), built from
//! their output records: pure functions, no I/O.
//!
//! - `level`: `/scan_level` ([`scan_level`]), `/attitude` ([`attitude`]), `/level_status`
//!   ([`status_string`] of `"level"`);
//! - `match`: `/odom_matched` ([`odom_matched`]), `/match_status` ([`status_string`] of
//!   `"match"`).
//!
//! Each is stamped with its pose's base scan, whose ROS metadata ([`ScanMeta`]) the bag
//! reader leaves in `extra["ros"]`; scans from JSON Lines or CARMEN get defaults.

use super::msgs::{Header, Imu, LaserScan, Odometry, Pose, Time, quaternion_from_rpy};
use crate::scan::{Scan, Timestamp};
use serde_json::Value;
use std::f64::consts::TAU;

/// Topics of the messages `level` and `match` add (contract).
pub const SCAN_LEVEL_TOPIC: &str = "/scan_level";
pub const ATTITUDE_TOPIC: &str = "/attitude";
pub const LEVEL_STATUS_TOPIC: &str = "/level_status";
pub const ODOM_MATCHED_TOPIC: &str = "/odom_matched";
pub const MATCH_STATUS_TOPIC: &str = "/match_status";
/// The frame of `/odom_matched` (contract).
pub const ODOM_MATCHED_FRAME: &str = "odom_matched";
/// The frame of scans that did not come from a bag.
pub const DEFAULT_FRAME: &str = "laser";

/// Variance of what is not known \[m^2 or rad^2\]: the yaw of `/attitude` (levelscan
/// measures roll and pitch only), and the pose and twist of `/odom_matched` that the match
/// does not give. Large rather than -1: robot_localization and the EKFs of ROS read the
/// diagonal as a variance and take 1e6 as "do not trust", where -1 is defined only for an
/// Imu's covariances (REP 145) and would be a negative variance elsewhere.
pub const UNKNOWN_VARIANCE: f64 = 1e6;

/// A scan's ROS metadata: what the bag reader puts in `extra["ros"]` (see the module
/// documentation of the reader), or defaults for scans from other formats.
#[derive(Clone, Debug, PartialEq)]
pub struct ScanMeta {
    pub frame_id: String,
    pub stamp: Time,
    /// The scan message's log time in its bag \[ns\]; the output's messages of this pose are
    /// logged at this time, so that they play right after the scan.
    pub log_time: u64,
    /// Bearing of ray 0 \[rad\].
    pub angle_min: f64,
    /// Bearing step between rays \[rad\] (negative for a scanner turning clockwise).
    pub angle_increment: f64,
    pub range_min: f32,
    pub range_max: f32,
    pub time_increment: f32,
    pub scan_time: f32,
}

impl ScanMeta {
    /// The metadata of `scan`: its `extra["ros"]` when present (fields missing there fall back
    /// as below), else defaults: frame `laser`, the stamp of `timestamp` (`[sec, usec]`),
    /// or `index` seconds when it has none (as `match` numbers records for TUM output);
    /// `angle_min` the first bearing and `angle_increment` the mean bearing step; range
    /// limits 0 and the farthest reading; no timing.
    ///
    /// For `level` output, pass the pose's base scan (its bearings are the scanner's); its
    /// record's bearings are the leveled ones and only approximate them.
    pub fn of(scan: &Scan, index: usize) -> ScanMeta {
        let ros = scan.extra.get("ros");
        let num = |key: &str| ros_number(scan, key);
        let stamp = ros
            .and_then(|r| r.get("stamp"))
            .and_then(stamp_from_json)
            .unwrap_or_else(|| match scan.timestamp {
                Some(t) => time_from_timestamp(t),
                None => Time::from_seconds(index as f64),
            });
        let n = scan.nrays();
        let first = scan.theta.first().copied().unwrap_or(0.0);
        let mean_step = match n {
            0 | 1 => 0.0,
            _ => (scan.theta[n - 1] - first) / (n - 1) as f64,
        };
        let farthest = scan.ranges().flatten().fold(0.0f64, f64::max);
        ScanMeta {
            frame_id: ros
                .and_then(|r| r.get("frame_id"))
                .and_then(Value::as_str)
                .unwrap_or(DEFAULT_FRAME)
                .to_string(),
            stamp,
            log_time: ros
                .and_then(|r| r.get("log_time"))
                .and_then(Value::as_u64)
                .unwrap_or_else(|| stamp.nanos()),
            angle_min: num("angle_min").unwrap_or(first),
            angle_increment: num("angle_increment").unwrap_or(mean_step),
            range_min: num("range_min").unwrap_or(0.0) as f32,
            range_max: num("range_max").unwrap_or(farthest) as f32,
            time_increment: num("time_increment").unwrap_or(0.0) as f32,
            scan_time: num("scan_time").unwrap_or(0.0) as f32,
        }
    }

    fn header(&self, frame_id: &str) -> Header {
        Header {
            stamp: self.stamp,
            frame_id: frame_id.to_string(),
        }
    }
}

/// A number the bag reader kept in the scan's `extra["ros"]` (`time_increment`, `angle_min`,
/// ...), if it has one.
pub fn ros_number(scan: &Scan, key: &str) -> Option<f64> {
    scan.extra.get("ros")?.get(key)?.as_f64()
}

/// `[sec, nanosec]` as the reader writes `extra["ros"]["stamp"]`.
fn stamp_from_json(v: &Value) -> Option<Time> {
    let a = v.as_array()?;
    let sec = i32::try_from(a.first()?.as_i64()?).ok()?;
    let nanosec = u32::try_from(a.get(1)?.as_u64()?).ok()?;
    Some(Time { sec, nanosec })
}

/// A CSM timestamp `[sec, usec]` as a ROS time; microseconds outside `0..1e6` carry into the
/// seconds, times before the epoch clamp to 0 and beyond 2038 to `i32::MAX` seconds.
pub fn time_from_timestamp(t: Timestamp) -> Time {
    let ns = i128::from(t.sec) * 1_000_000_000 + i128::from(t.usec) * 1_000;
    let max = i128::from(i32::MAX) * 1_000_000_000 + 999_999_999;
    Time::from_nanos(ns.clamp(0, max) as u64)
}

/// `/scan_level` (contract): the pseudo-level scan of a `level` record as a LaserScan with the
/// base scan's `angle_min`, `angle_increment`, ray count and range limits, in frame
/// `<frame>_level`. Each kept point goes into the bin of its leveled bearing (bearings wrap
/// around the full turn, so a 360-degree scanner's last bin meets its first); when two points
/// share a bin the nearer wins, as a real scanner sees the nearer surface; bins no point falls
/// into are NaN ("no return", REP 117), as are points whose bearing falls outside the
/// scanner's field of view.
///
/// No per-ray timing: the bins are not in the order the rays were cast, so `time_increment`
/// is 0; `scan_time` is the base scan's.
pub fn scan_level(record: &Scan, meta: &ScanMeta) -> LaserScan {
    let n = record.nrays();
    let mut ranges = vec![f32::NAN; n];
    for (i, range) in record.ranges().enumerate() {
        let Some(r) = range else { continue };
        if let Some(k) = bin_of(record.theta[i], meta.angle_min, meta.angle_increment, n) {
            let r = r as f32;
            // An empty bin (NaN) always takes the point.
            if ranges[k].is_nan() || r < ranges[k] {
                ranges[k] = r;
            }
        }
    }
    LaserScan {
        header: meta.header(&format!("{}_level", meta.frame_id)),
        angle_min: meta.angle_min as f32,
        angle_max: (meta.angle_min + n.saturating_sub(1) as f64 * meta.angle_increment) as f32,
        angle_increment: meta.angle_increment as f32,
        time_increment: 0.0,
        scan_time: meta.scan_time,
        range_min: meta.range_min,
        range_max: meta.range_max,
        ranges,
        intensities: Vec::new(),
    }
}

/// The bin of bearing `theta` among `n` bins from `angle_min`, `increment` apart, each bin
/// centred on its bearing; `None` outside the field of view. The offset is taken modulo a
/// full turn (in bins), shifted half a bin so that a bearing just before `angle_min` still
/// lands in bin 0.
fn bin_of(theta: f64, angle_min: f64, increment: f64, n: usize) -> Option<usize> {
    if !theta.is_finite() || n == 0 {
        return None;
    }
    if n == 1 || increment == 0.0 || !increment.is_finite() {
        return Some(0);
    }
    let turn = TAU / increment.abs();
    let t = ((theta - angle_min) / increment + 0.5).rem_euclid(turn);
    let k = t.floor();
    (k >= 0.0 && k < n as f64).then_some(k as usize)
}

/// `/attitude` (contract, REP 145): a `level` record's attitude as an Imu message in the base
/// scan's frame. Orientation `level_from_robot` = `Ry(theta_y) · Rx(theta_x)` as the
/// quaternion of roll `theta_x`, pitch `theta_y`, yaw 0 (REP 103 fixed axes, the contract's
/// angles); `orientation_covariance` diag(sigma_x^2, sigma_y^2, [`UNKNOWN_VARIANCE`]): yaw is not
/// measured. Angular velocity and linear acceleration are not measured: element 0 of their
/// covariances is -1. A failed pose (or one without angles) gives the identity and
/// `orientation_covariance[0] = -1`: orientation unknown.
pub fn attitude(record: &Scan, meta: &ScanMeta) -> Imu {
    let level = record.extra.get("level");
    let field = |k: &str| level.and_then(|l| l.get(k)).and_then(Value::as_f64);
    let ok = level.and_then(|l| l.get("status")).and_then(Value::as_str) == Some("ok");
    let mut unknown = [0.0; 9];
    unknown[0] = -1.0;
    let (orientation, orientation_covariance) = match (field("theta_x"), field("theta_y")) {
        (Some(tx), Some(ty)) if ok => {
            let var = |s: Option<f64>| s.map_or(UNKNOWN_VARIANCE, |s| s * s);
            let mut cov = [0.0; 9];
            cov[0] = var(field("sigma_x"));
            cov[4] = var(field("sigma_y"));
            cov[8] = UNKNOWN_VARIANCE;
            (quaternion_from_rpy(tx, ty, 0.0), cov)
        }
        _ => ([0.0, 0.0, 0.0, 1.0], unknown),
    };
    Imu {
        header: meta.header(&meta.frame_id),
        orientation,
        orientation_covariance,
        angular_velocity: [0.0; 3],
        angular_velocity_covariance: unknown,
        linear_acceleration: [0.0; 3],
        linear_acceleration_covariance: unknown,
    }
}

/// `/level_status` or `/match_status` (contract): the record's `extra[key]` object (`"level"`
/// or `"match"`) as compact JSON; `None` when the record has none.
pub fn status_string(record: &Scan, key: &str) -> Option<String> {
    record.extra.get(key).map(Value::to_string)
}

/// `/odom_matched` (contract): a `match` record's estimate as Odometry in frame
/// `odom_matched`, child the scan's frame; `None` when the record has no estimate.
///
/// `pose.covariance` (row-major 6x6 over x, y, z, roll, pitch, yaw) takes the match's 3x3
/// covariance of (x, y, yaw) (`match.covariance`, row-major) at rows and columns 0, 1, 5.
/// Without one (a fallback step, an older record) x, y and yaw get [`UNKNOWN_VARIANCE`];
/// z, roll and pitch are not estimated by a planar match and get it too. The twist is not
/// estimated: zero with [`UNKNOWN_VARIANCE`] on its diagonal.
pub fn odom_matched(record: &Scan, meta: &ScanMeta) -> Option<Odometry> {
    let est = record.estimate?;
    let mut pose_covariance = diagonal(UNKNOWN_VARIANCE);
    if let Some(c) = match_covariance(record) {
        const AT: [usize; 3] = [0, 1, 5];
        for (r, &row) in AT.iter().enumerate() {
            for (c_, &col) in AT.iter().enumerate() {
                pose_covariance[row * 6 + col] = c[r * 3 + c_];
            }
        }
    }
    Some(Odometry {
        header: meta.header(ODOM_MATCHED_FRAME),
        child_frame_id: meta.frame_id.clone(),
        pose: Pose {
            position: [est.x, est.y, 0.0],
            orientation: quaternion_from_rpy(0.0, 0.0, est.rz),
        },
        pose_covariance,
        twist: [0.0; 6],
        twist_covariance: diagonal(UNKNOWN_VARIANCE),
    })
}

/// `match.covariance`: 9 finite numbers, else `None`.
fn match_covariance(record: &Scan) -> Option<[f64; 9]> {
    let a = record.extra.get("match")?.get("covariance")?.as_array()?;
    if a.len() != 9 {
        return None;
    }
    let mut c = [0.0; 9];
    for (out, v) in c.iter_mut().zip(a) {
        *out = v.as_f64().filter(|x| x.is_finite())?;
    }
    Some(c)
}

fn diagonal(v: f64) -> [f64; 36] {
    let mut m = [0.0; 36];
    for i in 0..6 {
        m[i * 7] = v;
    }
    m
}

#[cfg(test)]
#[path = "convert_tests.rs"]
mod tests;
