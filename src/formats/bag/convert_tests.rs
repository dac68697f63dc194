use super::*;
use crate::geometry::{Attitude, Pose as Pose6};
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use serde_json::json;

/// A record whose ray i has bearing `theta[i]` and reading `readings[i]`.
fn record(theta: &[f64], readings: &[Option<f64>]) -> Scan {
    Scan {
        theta: theta.to_vec(),
        readings: readings.to_vec(),
        valid: readings.iter().map(Option::is_some).collect(),
        ..Scan::default()
    }
}

fn meta(angle_min: f64, angle_increment: f64) -> ScanMeta {
    ScanMeta {
        frame_id: "base_laser".into(),
        stamp: Time {
            sec: 1002,
            nanosec: 100_000_000,
        },
        log_time: 1_002_100_000_123,
        angle_min,
        angle_increment,
        range_min: 0.05,
        range_max: 30.0,
        time_increment: 1e-4,
        scan_time: 0.025,
    }
}

/// Bearings exactly on the bins: every kept point in its own bin, the others NaN, and the
/// base scan's geometry and frame `<frame>_level`.
#[test]
fn points_on_exact_bearings_fill_their_own_bins() {
    let (min, inc) = (-0.5, 0.25);
    let theta: Vec<f64> = (0..5).map(|i| min + inc * i as f64).collect();
    let readings = [Some(1.0), None, Some(2.5), Some(3.0), None];
    let m = meta(min, inc);
    let s = scan_level(&record(&theta, &readings), &m);
    assert_eq!(s.ranges.len(), 5);
    assert_eq!(s.ranges[0], 1.0);
    assert!(s.ranges[1].is_nan() && s.ranges[4].is_nan());
    assert_eq!((s.ranges[2], s.ranges[3]), (2.5, 3.0));
    assert_eq!(s.header.frame_id, "base_laser_level");
    assert_eq!(s.header.stamp, m.stamp);
    assert_eq!(
        (s.angle_min, s.angle_increment, s.angle_max),
        (-0.5, 0.25, 0.5)
    );
    assert_eq!((s.range_min, s.range_max, s.scan_time), (0.05, 30.0, 0.025));
    assert_eq!(s.time_increment, 0.0);
    assert!(s.intensities.is_empty());
}

/// Leveled bearings move points into other bins; two in one bin: the nearer wins, whichever
/// comes first; a bin left empty is NaN even though its own ray had a return elsewhere.
#[test]
fn nearer_point_wins_a_shared_bin() {
    let (min, inc) = (0.0, 0.1);
    // Rays 0 and 1 both land in bin 1 (0.09 and 0.12 are within half a bin of 0.1).
    for (a, b) in [(4.0, 2.0), (2.0, 4.0)] {
        let r = record(&[0.09, 0.12, 0.2], &[Some(a), Some(b), Some(7.0)]);
        let s = scan_level(&r, &meta(min, inc));
        assert!(s.ranges[0].is_nan());
        assert_eq!(s.ranges[1], 2.0);
        assert_eq!(s.ranges[2], 7.0);
    }
}

/// Bin edges: within half a bin of `angle_min` is bin 0, farther outside the field of view is
/// dropped; a 360-degree scan wraps its last bin onto its first; a clockwise scanner
/// (negative increment) bins the same way.
#[test]
fn bins_wrap_the_full_turn_and_respect_the_field_of_view() {
    let inc: f64 = 0.01;
    let r = record(
        &[-0.5 - 0.4 * inc, -0.5 - 0.6 * inc, 0.5 + 0.6 * inc],
        &[Some(1.0), Some(2.0), Some(3.0)],
    );
    let mut r = r;
    // A 101-ray scan from -0.5 to 0.5: pad the record to 101 rays (invalid).
    r.theta.resize(101, 0.0);
    r.readings.resize(101, None);
    r.valid.resize(101, false);
    let s = scan_level(&r, &meta(-0.5, inc));
    assert_eq!(s.ranges[0], 1.0);
    assert_eq!(s.ranges.iter().filter(|v| !v.is_nan()).count(), 1);

    let n = 360;
    let step = TAU / n as f64;
    let mut full = record(&vec![0.0; n], &vec![None; n]);
    full.theta[0] = std::f64::consts::PI - 0.3 * step; // just before -pi: bin 0
    full.readings[0] = Some(5.0);
    full.valid[0] = true;
    full.theta[1] = std::f64::consts::PI - 0.7 * step; // the last bin
    full.readings[1] = Some(6.0);
    full.valid[1] = true;
    let s = scan_level(&full, &meta(-std::f64::consts::PI, step));
    assert_eq!((s.ranges[0], s.ranges[n - 1]), (5.0, 6.0));

    let cw = record(&[0.5, 0.3, -0.51], &[Some(1.0), Some(2.0), Some(3.0)]);
    let s = scan_level(&cw, &meta(0.5, -0.5));
    assert_eq!((s.ranges[0], s.ranges[2]), (1.0, 3.0));
    assert!(s.ranges[1].is_nan());
}

fn level_record(level: serde_json::Value) -> Scan {
    let mut r = record(&[0.0], &[Some(1.0)]);
    r.extra.insert("level".into(), level);
    r
}

/// The orientation is `level_from_robot`: a known pitch of +0.1 rad (nose down, REP 103)
/// is (0, sin 0.05, 0, cos 0.05), and with a roll too the quaternion's rotation equals
/// `Attitude::level_from_robot` to rounding; the covariance is diag(sx^2, sy^2, 1e6).
#[test]
fn attitude_quaternion_is_level_from_robot() {
    let m = meta(0.0, 0.0);
    let pitch = level_record(json!({"status": "ok", "reason": null, "theta_x": 0.0,
        "theta_y": 0.1, "sigma_x": 0.002, "sigma_y": 0.003}));
    let imu = attitude(&pitch, &m);
    let q = imu.orientation;
    assert!(q[0].abs() < 1e-15 && q[2].abs() < 1e-15);
    assert!((q[1] - 0.05f64.sin()).abs() < 1e-15 && (q[3] - 0.05f64.cos()).abs() < 1e-15);
    let rot = UnitQuaternion::from_quaternion(Quaternion::new(q[3], q[0], q[1], q[2]));
    // Pitched nose down, the robot's forward axis points below the level horizon.
    let fwd = rot * Vector3::x();
    assert!((fwd.z + 0.1f64.sin()).abs() < 1e-15, "{fwd}");
    assert_eq!(
        imu.orientation_covariance,
        [
            0.002 * 0.002,
            0.0,
            0.0,
            0.0,
            0.003 * 0.003,
            0.0,
            0.0,
            0.0,
            1e6
        ]
    );
    assert_eq!(imu.angular_velocity_covariance[0], -1.0);
    assert_eq!(imu.linear_acceleration_covariance[0], -1.0);
    assert_eq!(imu.header.frame_id, "base_laser");

    let both = level_record(json!({"status": "ok", "theta_x": -0.2, "theta_y": 0.3,
        "sigma_x": 0.01, "sigma_y": 0.01}));
    let q = attitude(&both, &m).orientation;
    let rot = UnitQuaternion::from_quaternion(Quaternion::new(q[3], q[0], q[1], q[2]));
    let want = Attitude::new(-0.2, 0.3).level_from_robot();
    assert!(
        (rot.to_rotation_matrix().matrix() - want.matrix())
            .abs()
            .max()
            < 1e-15
    );
}

/// REP 145: a failed pose has the identity orientation and `orientation_covariance[0]` -1.
#[test]
fn failed_pose_reports_unknown_orientation() {
    let failed = level_record(json!({"status": "failed", "reason": "too_few_polygons",
        "theta_x": null, "theta_y": null, "sigma_x": null, "sigma_y": null}));
    let imu = attitude(&failed, &meta(0.0, 0.0));
    assert_eq!(imu.orientation, [0.0, 0.0, 0.0, 1.0]);
    assert_eq!(imu.orientation_covariance[0], -1.0);
    assert!(imu.orientation_covariance[1..].iter().all(|&v| v == 0.0));
    assert_eq!(
        status_string(&failed, "level").unwrap(),
        r#"{"status":"failed","reason":"too_few_polygons","theta_x":null,"theta_y":null,"sigma_x":null,"sigma_y":null}"#
    );
    assert!(status_string(&failed, "match").is_none());
}

/// The match covariance of (x, y, yaw) lands at rows and columns 0, 1, 5 of the 6x6; without
/// it, 1e6 on the diagonal.
#[test]
fn odom_matched_places_the_match_covariance() {
    let mut r = record(&[0.0], &[Some(1.0)]);
    r.estimate = Some(Pose6::planar(1.5, -2.0, 0.4));
    let cov: Vec<f64> = (1..=9).map(f64::from).collect();
    r.extra
        .insert("match".into(), json!({"status": "ok", "covariance": cov}));
    let o = odom_matched(&r, &meta(0.0, 0.0)).unwrap();
    assert_eq!(o.header.frame_id, "odom_matched");
    assert_eq!(o.child_frame_id, "base_laser");
    assert_eq!(o.pose.position, [1.5, -2.0, 0.0]);
    assert!((o.pose.orientation[2] - 0.2f64.sin()).abs() < 1e-15);
    let p = &o.pose_covariance;
    assert_eq!([p[0], p[1], p[5]], [1.0, 2.0, 3.0]);
    assert_eq!([p[6], p[7], p[11]], [4.0, 5.0, 6.0]);
    assert_eq!([p[30], p[31], p[35]], [7.0, 8.0, 9.0]);
    assert_eq!([p[14], p[21], p[28]], [1e6; 3]);
    assert_eq!(p.iter().filter(|&&v| v != 0.0).count(), 12);
    assert_eq!(o.twist_covariance[0], 1e6);

    r.extra
        .insert("match".into(), json!({"status": "fallback"}));
    let o = odom_matched(&r, &meta(0.0, 0.0)).unwrap();
    assert_eq!(o.pose_covariance, diagonal(1e6));
    r.estimate = None;
    assert!(odom_matched(&r, &meta(0.0, 0.0)).is_none());
}

/// `extra["ros"]` gives the metadata; without it, the defaults of JSON Lines scans.
#[test]
fn scan_meta_from_the_reader_or_defaults() {
    let mut s = record(&[-0.3, -0.1, 0.1, 0.3], &[Some(2.0), None, Some(4.5), None]);
    s.timestamp = Some(Timestamp {
        sec: 1234,
        usec: 500_000,
    });
    let d = ScanMeta::of(&s, 7);
    assert_eq!(d.frame_id, "laser");
    assert_eq!(
        d.stamp,
        Time {
            sec: 1234,
            nanosec: 500_000_000
        }
    );
    assert_eq!(d.log_time, 1_234_500_000_000);
    assert_eq!(d.angle_min, -0.3);
    assert!((d.angle_increment - 0.2).abs() < 1e-15);
    assert_eq!((d.range_min, d.range_max), (0.0, 4.5));
    s.timestamp = None;
    assert_eq!(ScanMeta::of(&s, 7).stamp, Time { sec: 7, nanosec: 0 });

    s.extra.insert(
        "ros".into(),
        json!({"topic": "/scan", "frame_id": "hokuyo", "stamp": [1000, 5],
            "angle_min": -2.0, "angle_increment": 0.5, "range_min": 0.1, "range_max": 20.0,
            "time_increment": 0.001, "scan_time": 0.025, "log_time": 1_000_000_000_777u64}),
    );
    let r = ScanMeta::of(&s, 7);
    assert_eq!(r.frame_id, "hokuyo");
    assert_eq!(
        r.stamp,
        Time {
            sec: 1000,
            nanosec: 5
        }
    );
    assert_eq!(r.log_time, 1_000_000_000_777);
    assert_eq!((r.angle_min, r.angle_increment), (-2.0, 0.5));
    assert_eq!((r.range_min, r.range_max), (0.1, 20.0));
    assert_eq!((r.time_increment, r.scan_time), (0.001, 0.025));
}

#[test]
fn csm_timestamps_become_ros_times() {
    let t = |sec, usec| time_from_timestamp(Timestamp { sec, usec });
    assert_eq!(
        t(5, 1_500_000),
        Time {
            sec: 6,
            nanosec: 500_000_000
        }
    );
    assert_eq!(t(-3, 0), Time::default());
    assert_eq!(t(i64::MAX, 0).sec, i32::MAX);
}
