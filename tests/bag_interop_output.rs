//! The MCAP files levelscan writes (`level -o`, `match -o`, `simulate -o`), read by the
//! reference decoder (foxglove's `mcap` + `mcap-ros2-support`, tests/interop/check_output.py):
//! the ROS 2 profile, ros2msg schemas, cdr, a summary with chunk indexes, every input message
//! copied through, and the contract's topics ("ROS bags"): one /attitude, /scan_level and
//! /level_status per pose (REP 145 for failed poses), one /odom_matched and /match_status per
//! scan. The inputs are bags written by `rosbags` (tests/interop/write_bag.py).
//!
//! Needs the Python of tests/bag_interop.rs (`LEVELSCAN_PYTHON`; skipped with a message
//! without it, failing instead when `LEVELSCAN_REQUIRE_INTEROP=1`).

mod bag_support;
use bag_support::interop::*;
use bag_support::*;

use serde_json::Value;

/// Roll and pitch of a quaternion (x, y, z, w), REP-103 fixed axes.
fn roll_pitch(q: &Value) -> (f64, f64) {
    let (x, y, z, w) = (f(&q["x"]), f(&q["y"]), f(&q["z"]), f(&q["w"]));
    let roll = (2.0 * (w * x + y * z)).atan2(1.0 - 2.0 * (x * x + y * y));
    let pitch = (2.0 * (w * y - z * x)).clamp(-1.0, 1.0).asin();
    (roll, pitch)
}

fn stamp_ns(header: &Value) -> u64 {
    let s = &header["stamp"];
    s["sec"].as_u64().unwrap() * 1_000_000_000 + s["nanosec"].as_u64().unwrap()
}

/// Checks one /attitude message against its pose's level object (the contract and REP 145).
fn assert_attitude(imu: &Value, level: &Value, case: &str) {
    let cov = imu["orientation_covariance"].as_array().unwrap();
    assert_eq!(
        f(&imu["angular_velocity_covariance"][0]),
        -1.0,
        "{case}: angular velocity unknown"
    );
    assert_eq!(
        f(&imu["linear_acceleration_covariance"][0]),
        -1.0,
        "{case}: acceleration unknown"
    );
    let q = &imu["orientation"];
    if level["status"] == "ok" {
        let (roll, pitch) = roll_pitch(q);
        assert!(
            (roll - f(&level["theta_x"])).abs() < 1e-9,
            "{case}: roll {roll} vs {}",
            level["theta_x"]
        );
        assert!((pitch - f(&level["theta_y"])).abs() < 1e-9, "{case}: pitch");
        let yaw = (2.0 * (f(&q["w"]) * f(&q["z"]) + f(&q["x"]) * f(&q["y"])))
            .atan2(1.0 - 2.0 * (f(&q["y"]).powi(2) + f(&q["z"]).powi(2)));
        assert!(yaw.abs() < 1e-12, "{case}: yaw {yaw} should be 0");
        let want = [
            f(&level["sigma_x"]).powi(2),
            f(&level["sigma_y"]).powi(2),
            1e6,
        ];
        for i in 0..3 {
            for j in 0..3 {
                let c = f(&cov[3 * i + j]);
                let w = if i == j { want[i] } else { 0.0 };
                assert!(
                    (c - w).abs() <= 1e-9 * w.abs().max(1e-12),
                    "{case}: covariance[{i}][{j}] {c} vs {w}"
                );
            }
        }
    } else {
        assert_eq!(
            f(&cov[0]),
            -1.0,
            "{case}: failed pose needs orientation_covariance[0] = -1"
        );
        for (k, want) in [("x", 0.0), ("y", 0.0), ("z", 0.0), ("w", 1.0)] {
            assert_eq!(f(&q[k]), want, "{case}: failed pose: identity orientation");
        }
    }
}

/// One /scan_level message against the pose's JSON Lines record (`level BAG` output): the
/// base scan's grid, each kept point in the bin of its leveled bearing, the nearer range
/// winning a shared bin, the other bins NaN.
fn assert_scan_level(msg: &Value, rec: &Value, grid: (f64, f64), case: &str) {
    assert_eq!(msg["header"]["frame_id"], "laser_level", "{case}");
    let (amin, inc) = (f(&msg["angle_min"]), f(&msg["angle_increment"]));
    assert_eq!(
        (amin as f32, inc as f32),
        (grid.0 as f32, grid.1 as f32),
        "{case}: the base scan's grid"
    );
    let ranges = msg["ranges"].as_array().unwrap();
    let n = rec["nrays"].as_u64().unwrap() as usize;
    assert_eq!(ranges.len(), n, "{case}: ray count");
    let mut want = vec![f64::INFINITY; n];
    for i in 0..n {
        if rec["valid"][i] == 1 {
            let bin = ((f(&rec["theta"][i]) - amin) / inc).round();
            if bin >= 0.0 && (bin as usize) < n {
                let b = bin as usize;
                want[b] = want[b].min(f(&rec["readings"][i]));
            }
        }
    }
    for (b, (r, w)) in ranges.iter().zip(&want).enumerate() {
        match r.as_f64() {
            Some(r) => assert!((r - w).abs() < 1e-5, "{case}: bin {b}: {r} vs {w}"),
            None => assert!(
                w.is_infinite(),
                "{case}: bin {b} NaN ({r}) but a point {w} falls in it"
            ),
        }
    }
}

#[test]
fn level_writes_a_bag_the_reference_decoder_reads() {
    let Some(fx) = Fixture::new("bag-level-out") else {
        return;
    };
    let scans: Vec<Value> = std::fs::read_to_string(&fx.scans)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let r2 = fx.bag("r2", "mcap", &[]);
    let r1 = fx.bag("r1.bag", "ros1", &[]);
    // A tight --max-sigma (0.25 degree) fails some poses (parallel_walls): REP 145's -1.
    let tight: &[&str] = &["--max-sigma", "0.25"];
    for (i, (case, bag, flags)) in [
        ("rosbag2", &r2, &[][..]),
        ("rosbag2, some poses failed", &r2, tight),
        ("ROS 1", &r1, &[][..]),
    ]
    .into_iter()
    .enumerate()
    {
        let out = fx.dir.join(&format!("level-{i}.mcap"));
        let mut args = vec!["level", bag.as_str()];
        args.extend_from_slice(flags);
        let recs = ok_records(&args);
        args.extend_from_slice(&["-o", &out]);
        ok_stdout(&args);
        let failed = recs
            .iter()
            .filter(|r| r["level"]["status"] == "failed")
            .count();
        if !flags.is_empty() {
            assert!(
                failed >= 1 && failed < recs.len(),
                "{case}: want a mix, {failed} failed"
            );
        }
        let found = fx.check(&out, &["--input", bag]);
        assert_eq!(found["profile"], "ros2", "{case}");
        assert!(
            found["chunk_indexes"].as_u64().unwrap() >= 1,
            "{case}: chunk indexes: {found}"
        );
        assert!(
            found["chunk_compression"]
                .as_array()
                .unwrap()
                .iter()
                .any(|c| c == "zstd"),
            "{case}: {}",
            found["chunk_compression"]
        );
        let topics = &found["topics"];
        for (t, ty) in [
            ("/scan_level", "sensor_msgs/msg/LaserScan"),
            ("/attitude", "sensor_msgs/msg/Imu"),
            ("/level_status", "std_msgs/msg/String"),
        ] {
            assert_eq!(topics[t]["type"], ty, "{case}: {t}");
            assert_eq!(topics[t]["count"], recs.len(), "{case}: one {t} per pose");
        }
        assert_eq!(
            topics["/scan"]["count"], 18,
            "{case}: the input scans copied through"
        );
        assert_eq!(
            topics["/joint_states"]["count"], 36,
            "{case}: joint states copied through"
        );
        for (k, rec) in recs.iter().enumerate() {
            assert_pose_messages(&found["messages"], k, rec, &scans, case);
        }
    }
}

/// Pose k's /level_status, /attitude and /scan_level against its `level` record.
fn assert_pose_messages(msgs: &Value, k: usize, rec: &Value, scans: &[Value], case: &str) {
    let c = format!("{case} pose {k}");
    let status: Value =
        serde_json::from_str(msgs["/level_status"][k]["data"].as_str().unwrap()).unwrap();
    assert_eq!(
        status, rec["level"],
        "{c}: /level_status is the level object"
    );
    let imu = &msgs["/attitude"][k];
    assert_attitude(imu, &rec["level"], &c);
    // Stamped with the pose's base scan: the scan of this pose at base_elevation.
    let base = scans
        .iter()
        .filter(|s| s["sequence"] == scans_sequence(scans, k))
        .position(|s| s["elevation"] == rec["level"]["base_elevation"])
        .unwrap_or_else(|| panic!("{c}: no scan at the base elevation"));
    let t = scan_time_ns(k, base);
    assert_eq!(stamp_ns(&imu["header"]), t, "{c}: /attitude stamp");
    let sl = &msgs["/scan_level"][k];
    assert_eq!(stamp_ns(&sl["header"]), t, "{c}: /scan_level stamp");
    assert_eq!(
        msgs["/level_status"][k]["log_time"], t,
        "{c}: /level_status log time"
    );
    let theta = &scans
        .iter()
        .find(|s| s["sequence"] == scans_sequence(scans, k))
        .unwrap()["theta"];
    let n = theta.as_array().unwrap().len();
    let grid = (
        f(&theta[0]),
        (f(&theta[n - 1]) - f(&theta[0])) / (n - 1) as f64,
    );
    assert_scan_level(sl, rec, grid, &c);
}

/// The `sequence` of the k-th pose of `scans`.
fn scans_sequence(scans: &[Value], k: usize) -> Value {
    let mut seqs: Vec<&Value> = Vec::new();
    for s in scans {
        if seqs.last() != Some(&&s["sequence"]) {
            seqs.push(&s["sequence"]);
        }
    }
    seqs[k].clone()
}

#[test]
fn match_writes_one_odometry_per_scan() {
    let Some(fx) = Fixture::new("bag-match-out") else {
        return;
    };
    let r2 = fx.bag("r2", "mcap", &[]);
    // Raw bag: one /odom_matched and /match_status per /scan message.
    let raw = fx.dir.join("match-raw.mcap");
    ok_stdout(&["match", "--mode", "pairwise", &r2, "-o", &raw]);
    let recs = ok_records(&["match", "--mode", "pairwise", &r2]);
    assert_eq!(recs.len(), 18);
    let found = fx.check(&raw, &["--input", &r2]);
    assert_match_topics(&found, &recs, "/scan", "laser", "raw bag");
    // Leveled bag: match reads /scan_level by default, one per pose.
    let leveled = fx.dir.join("level.mcap");
    ok_stdout(&["level", &r2, "-o", &leveled]);
    let out = fx.dir.join("match-level.mcap");
    ok_stdout(&["match", "--mode", "metascan", &leveled, "-o", &out]);
    let recs = ok_records(&["match", "--mode", "metascan", &leveled]);
    assert_eq!(recs.len(), 6, "match on a leveled bag reads /scan_level");
    let found = fx.check(&out, &["--input", &leveled]);
    assert_match_topics(&found, &recs, "/scan_level", "laser_level", "leveled bag");
}

fn assert_match_topics(found: &Value, recs: &[Value], scan_topic: &str, frame: &str, case: &str) {
    let topics = &found["topics"];
    assert_eq!(
        topics["/odom_matched"]["type"], "nav_msgs/msg/Odometry",
        "{case}"
    );
    assert_eq!(
        topics["/match_status"]["type"], "std_msgs/msg/String",
        "{case}"
    );
    for t in ["/odom_matched", "/match_status"] {
        assert_eq!(
            topics[t]["count"], topics[scan_topic]["count"],
            "{case}: one {t} per {scan_topic}"
        );
        assert_eq!(topics[t]["count"], recs.len(), "{case}: one {t} per record");
    }
    let msgs = &found["messages"];
    for (i, rec) in recs.iter().enumerate() {
        let c = format!("{case} scan {i}");
        let odo = &msgs["/odom_matched"][i];
        assert_eq!(odo["header"]["frame_id"], "odom_matched", "{c}");
        assert_eq!(odo["child_frame_id"], frame, "{c}");
        assert_eq!(
            stamp_ns(&odo["header"]),
            rec["ros"]["log_time"].as_u64().unwrap(),
            "{c}: stamped as its scan"
        );
        let est = rec["estimate"].as_array().unwrap();
        let p = &odo["pose"]["pose"];
        assert!((f(&p["position"]["x"]) - f(&est[0])).abs() < 1e-9, "{c}: x");
        assert!((f(&p["position"]["y"]) - f(&est[1])).abs() < 1e-9, "{c}: y");
        let q = &p["orientation"];
        let yaw = 2.0 * f(&q["z"]).atan2(f(&q["w"]));
        let dyaw = (yaw - f(&est[2]) + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI)
            - std::f64::consts::PI;
        assert!(dyaw.abs() < 1e-9, "{c}: yaw {yaw} vs {}", est[2]);
        if let Some(cov) = rec["match"]["covariance"].as_array() {
            let pc = odo["pose"]["covariance"].as_array().unwrap();
            for (k, idx) in [0, 1, 5, 6, 7, 11, 30, 31, 35].iter().enumerate() {
                assert!(
                    (f(&pc[*idx]) - f(&cov[k])).abs() <= 1e-12 + 1e-9 * f(&cov[k]).abs(),
                    "{c}: covariance {k}"
                );
            }
        }
        let status: Value =
            serde_json::from_str(msgs["/match_status"][i]["data"].as_str().unwrap()).unwrap();
        assert_eq!(
            status, rec["match"],
            "{c}: /match_status is the match object"
        );
    }
}

#[test]
fn simulate_writes_a_bag_that_levels_as_its_json_lines() {
    let Some(fx) = Fixture::new("bag-simulate") else {
        return;
    };
    let run = fx.dir.join("run.mcap");
    let plan = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/plans/office.wall");
    ok_stdout(&["simulate", plan, "--random", "6", "--seed", "7", "-o", &run]);
    let found = fx.check(&run, &[]);
    let topics = &found["topics"];
    for (t, ty, n) in [
        ("/scan", "sensor_msgs/msg/LaserScan", 18),
        ("/joint_states", "sensor_msgs/msg/JointState", 36),
        ("/odom", "nav_msgs/msg/Odometry", 18),
        ("/ground_truth", "geometry_msgs/msg/PoseStamped", 18),
    ] {
        assert_eq!(topics[t]["type"], ty, "{t}: {topics}");
        assert_eq!(topics[t]["count"], n, "{t}");
    }
    let from_bag = ok_records(&["level", &run]);
    let from_jsonl = ok_records(&["level", &fx.scans]);
    assert_same_levels(&from_bag, &from_jsonl, "simulate -o run.mcap");
    // The contract's stamps, through the scans as read.
    let read = ok_records(&["match", "--mode", "pairwise", &run]);
    for (i, r) in read.iter().enumerate() {
        assert_eq!(r["ros"]["log_time"], scan_time_ns(i / 3, i % 3), "scan {i}");
        assert_eq!(r["ros"]["frame_id"], "laser", "scan {i}");
    }
}
