//! ROS bags against independent implementations (issue 22, CONTRACT.md "ROS bags"): bags
//! written by the pure-Python `rosbags` library (tests/interop/write_bag.py: a rosbag2
//! directory with MCAP storage, a ROS 1 `.bag`) must read as the same scans as the JSON Lines
//! they were made from, and the MCAP files levelscan writes must read in the reference decoder
//! (foxglove's `mcap` + `mcap-ros2-support`, tests/interop/check_output.py) with the contract's
//! topics and messages. Everything runs the release binary as a user types it.
//!
//! Needs a Python with rosbags, mcap, mcap-ros2-support and numpy: `LEVELSCAN_PYTHON`, else
//! `python3`. Without one the tests say they are skipped, unless `LEVELSCAN_REQUIRE_INTEROP=1`
//! (`.ci/run` sets it up and requires it), when they fail.

mod bag_support;
use bag_support::interop::*;
use bag_support::*;

use serde_json::Value;

#[test]
fn level_on_bags_gives_the_attitudes_of_the_json_lines() {
    let Some(fx) = Fixture::new("bag-level") else {
        return;
    };
    let jsonl = ok_records(&["level", &fx.scans]);
    assert_eq!(jsonl.len(), 6);
    let ok = jsonl
        .iter()
        .filter(|r| r["level"]["status"] == "ok")
        .count();
    assert!(ok >= 4, "the fixture should level most poses ({ok} of 6)");
    let r2 = fx.bag("r2", "mcap", &[]);
    let r2z = fx.bag("r2z", "mcap", &["--compress"]);
    let r1 = fx.bag("r1.bag", "ros1", &[]);
    let r1z = fx.bag("r1z.bag", "ros1", &["--compress"]);
    let r2_file = format!("{r2}/r2.mcap");
    for (case, bag) in [
        ("rosbag2 directory", &r2),
        ("its MCAP file", &r2_file),
        ("zstd storage", &r2z),
        ("ROS 1 bag", &r1),
        ("ROS 1 bag, lz4 chunks", &r1z),
    ] {
        let got = ok_records(&["level", bag]);
        assert_same_levels(&got, &jsonl, case);
    }
    // Named topics, as a user with other names would give them.
    let renamed = fx.bag(
        "renamed",
        "mcap",
        &[
            "--scan-topic",
            "/tilt_scan",
            "--joint-topic",
            "/tilt/joints",
            "--joint-name",
            "tilt_joint",
        ],
    );
    let got = ok_records(&[
        "level",
        &renamed,
        "--scan-topic",
        "/tilt_scan",
        "--joint-topic",
        "/tilt/joints",
        "--hinge-joint",
        "tilt_joint",
    ]);
    assert_same_levels(&got, &jsonl, "named topics");
    // Two joints on the joint topic, the hinge named.
    let two = fx.bag("two_joints", "mcap", &["--extra-joint", "wheel"]);
    let got = ok_records(&["level", &two, "--hinge-joint", "hinge"]);
    assert_same_levels(&got, &jsonl, "two joints, hinge named");
}

/// `match` passes each input record through: on a bag, that is the scan as read. It must be
/// the scan as stored (float32 bearings and ranges), with the elevation, odometry, truth and
/// stamp of the bag, and `extra["ros"]` as the seam between tasks fixes it.
#[test]
fn scans_read_from_bags_are_the_stored_scans() {
    let Some(fx) = Fixture::new("bag-scans") else {
        return;
    };
    let expect_path = fx.dir.join("expect.jsonl");
    let r2 = fx.bag("r2", "mcap", &["--expect", &expect_path]);
    let r1 = fx.bag("r1.bag", "ros1", &[]);
    let expect: Vec<Value> = std::fs::read_to_string(&expect_path)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    for (case, bag) in [("rosbag2", &r2), ("ROS 1", &r1)] {
        let got = ok_records(&["match", "--mode", "pairwise", bag]);
        assert_eq!(got.len(), expect.len(), "{case}: scans");
        let mut pose = 0;
        for (i, (g, e)) in got.iter().zip(&expect).enumerate() {
            if i > 0 && expect[i - 1]["sequence"] != e["sequence"] {
                pose += 1;
            }
            assert_scan_as_stored(g, e, pose, &format!("{case} scan {i}"));
        }
    }
}

fn assert_scan_as_stored(g: &Value, e: &Value, pose: u64, case: &str) {
    assert_eq!(g["nrays"], e["nrays"], "{case}");
    assert_eq!(g["sequence"], pose, "{case}: sequence = pose index");
    assert_eq!(f(&g["elevation"]), f(&e["elevation"]), "{case}: elevation");
    let n = e["nrays"].as_u64().unwrap() as usize;
    for i in 0..n {
        let (gt, et) = (f(&g["theta"][i]), f(&e["theta"][i]));
        assert!((gt - et).abs() < 1e-6, "{case}: theta[{i}] {gt} vs {et}");
        let (gr, er) = (&g["readings"][i], &e["readings"][i]);
        if er.is_null() {
            assert!(
                gr.is_null() || g["valid"][i] == 0,
                "{case}: ray {i} should be no return"
            );
        } else {
            assert_eq!(f(gr) as f32, f(er) as f32, "{case}: readings[{i}]");
            assert_ne!(g["valid"][i], 0, "{case}: ray {i} valid");
        }
    }
    for key in ["odometry", "true_pose"] {
        let (ga, ea) = (g[key].as_array().unwrap(), e[key].as_array().unwrap());
        assert!(ga.len() >= 3, "{case}: {key} {ga:?}");
        let idx: &[usize] = if ga.len() == ea.len() {
            &[0, 1, 2, 3, 4, 5]
        } else {
            &[0, 1]
        };
        for &j in idx.iter().filter(|&&j| j < ga.len()) {
            let d = (f(&ga[j]) - f(&ea[j])).abs();
            assert!(d < 1e-9, "{case}: {key}[{j}] {} vs {}", ga[j], ea[j]);
        }
    }
    let ros = &g["ros"];
    assert_eq!(ros["topic"], "/scan", "{case}: {ros}");
    assert_eq!(ros["frame_id"], "laser", "{case}: {ros}");
    let (sec, usec) = (
        e["timestamp"][0].as_u64().unwrap(),
        e["timestamp"][1].as_u64().unwrap(),
    );
    assert_eq!(
        ros["stamp"],
        serde_json::json!([sec, usec * 1000]),
        "{case}: stamp"
    );
    assert_eq!(
        ros["log_time"],
        sec * 1_000_000_000 + usec * 1000,
        "{case}: log_time"
    );
    assert_eq!(
        g["timestamp"], e["timestamp"],
        "{case}: timestamp [sec, usec]"
    );
}

#[test]
fn info_on_bags_lists_topics_types_and_counts() {
    let Some(fx) = Fixture::new("bag-info") else {
        return;
    };
    let jsonl: Value = serde_json::from_str(&ok_stdout(&["info", &fx.scans])).unwrap();
    for (case, bag, scan_type) in [
        (
            "rosbag2",
            fx.bag("r2", "mcap", &[]),
            "sensor_msgs/msg/LaserScan",
        ),
        ("ROS 1", fx.bag("r1.bag", "ros1", &[]), "LaserScan"),
    ] {
        let text = ok_stdout(&["info", &bag]);
        for topic in ["/scan", "/joint_states", "/odom", "/ground_truth"] {
            assert!(
                text.contains(topic),
                "{case}: info does not list {topic}: {text}"
            );
        }
        for ty in [scan_type, "JointState", "Odometry", "PoseStamped"] {
            assert!(
                text.contains(ty),
                "{case}: info does not give the type {ty}: {text}"
            );
        }
        // The usual summary follows: the same poses and scans as the JSON Lines.
        let first: Value = serde_json::Deserializer::from_str(&text)
            .into_iter::<Value>()
            .next()
            .unwrap()
            .unwrap_or_else(|e| panic!("{case}: info output is not JSON ({e}): {text}"));
        let summary =
            find_key(&first, "poses").unwrap_or_else(|| panic!("{case}: no poses in {text}"));
        assert_eq!(summary["poses"], jsonl["poses"], "{case}: {summary}");
        assert_eq!(summary["scans"], jsonl["scans"], "{case}: {summary}");
        for n in ["18", "36"] {
            assert!(
                text.contains(n),
                "{case}: counts (18 scans, 36 joint states) missing: {text}"
            );
        }
    }
}

/// The object (at any depth) that has `key`.
fn find_key<'a>(v: &'a Value, key: &str) -> Option<&'a Value> {
    match v {
        Value::Object(m) if m.contains_key(key) => Some(v),
        Value::Object(m) => m.values().find_map(|x| find_key(x, key)),
        Value::Array(a) => a.iter().find_map(|x| find_key(x, key)),
        _ => None,
    }
}

#[test]
fn rosbags_sqlite3_storage_is_refused_clearly() {
    let Some(fx) = Fixture::new("bag-bad-sqlite") else {
        return;
    };
    let sqlite = fx.bag("sq", "sqlite3", &[]);
    let err = one_line_failure(&levelscan(&["level", &sqlite]), "sqlite3 storage");
    assert_names(&err, &[&sqlite, "sqlite3"], "sqlite3 storage");
}

#[test]
fn truncated_rosbags_ros1_bag_fails_cleanly() {
    let Some(fx) = Fixture::new("bag-bad-ros1cut") else {
        return;
    };
    let r1 = fx.bag("whole.bag", "ros1", &[]);
    let bytes = std::fs::read(&r1).unwrap();
    // Cut before the end of the chunk section (a cut in the index tail alone still holds every
    // message, and reads).
    for frac in [0.3, 0.5, 0.9] {
        let cut = fx.dir.join(&format!("cut{frac}.bag"));
        std::fs::write(&cut, &bytes[..(bytes.len() as f64 * frac) as usize]).unwrap();
        for cmd in ["info", "level"] {
            let case = format!("ROS 1 bag cut at {frac} ({cmd})");
            let err = one_line_failure(&levelscan(&[cmd, &cut]), &case);
            assert_names(&err, &[&cut], &case);
        }
    }
}

#[test]
fn rosbags_joint_problems_fail_cleanly() {
    let Some(fx) = Fixture::new("bag-bad-joint") else {
        return;
    };
    let wrong = fx.bag("wrong_joint", "mcap", &["--joint-name", "wheel"]);
    let err = one_line_failure(
        &levelscan(&["level", &wrong, "--hinge-joint", "hinge"]),
        "missing joint",
    );
    assert_names(
        &err,
        &[&wrong, "/joint_states", "hinge", "wheel"],
        "missing joint",
    );
    // Joint messages 0.5 s after each scan: none within 0.1 s of the first, at 1000 s.
    let far = fx.bag("far_joint", "ros1", &["--joint-offset", "0.5"]);
    let err = one_line_failure(&levelscan(&["level", &far]), "joint far from scan");
    assert_names(&err, &[&far, "hinge", "1000"], "joint far from scan");
}

#[test]
fn rosbags_two_scan_topics_fail_cleanly() {
    let Some(fx) = Fixture::new("bag-bad-two") else {
        return;
    };
    let two = fx.bag("two_scans", "mcap", &["--second-scan-topic", "/scan_front"]);
    let err = one_line_failure(&levelscan(&["level", &two]), "two LaserScan topics");
    assert_names(
        &err,
        &[&two, "/scan", "/scan_front"],
        "two LaserScan topics",
    );
}

/// The last table row of `eval real` output, as cells.
fn table_row(text: &str) -> Vec<String> {
    // The first table's first data row (the drift table follows it).
    let mut lines = text.lines().skip_while(|l| !l.starts_with("|---"));
    let row = lines.nth(1).filter(|l| l.starts_with('|')).unwrap();
    row.trim_matches('|')
        .split('|')
        .map(|c| c.trim().to_string())
        .collect()
}

/// `eval real` wants one 2D scan per pose: it refuses a bag of tilting scans as it refuses
/// their JSON Lines, in one line naming the bag.
#[test]
fn eval_real_refuses_raw_bags_as_json_lines() {
    let Some(fx) = Fixture::new("bag-eval-raw") else {
        return;
    };
    let jsonl = one_line_failure(
        &levelscan(&["eval", "real", &fx.scans]),
        "eval real JSON Lines",
    );
    assert!(jsonl.contains("level them first"), "{jsonl}");
    for bag in [fx.bag("r2", "mcap", &[]), fx.bag("r1.bag", "ros1", &[])] {
        let err = one_line_failure(&levelscan(&["eval", "real", &bag]), "eval real bag");
        assert_names(&err, &[&bag, "level them first"], "eval real bag");
    }
}

/// `eval real` on `level`'s output bag, its /scan_level named (the bag has /scan too), the
/// truth from /ground_truth: as many scans as poses, and RPE figures.
#[test]
fn eval_real_takes_a_leveled_bag() {
    let Some(fx) = Fixture::new("bag-eval-level") else {
        return;
    };
    let r2 = fx.bag("r2", "mcap", &[]);
    let leveled = fx.dir.join("level.mcap");
    ok_stdout(&["level", &r2, "-o", &leveled]);
    let level_jsonl = fx.dir.join("level.jsonl");
    ok_stdout(&["level", &fx.scans, "-o", &level_jsonl]);
    let want = table_row(&ok_stdout(&["eval", "real", &level_jsonl]));
    let got = table_row(&ok_stdout(&[
        "eval",
        "real",
        &leveled,
        "--scan-topic",
        "/scan_level",
    ]));
    assert_eq!(got[1], want[1], "scans: {got:?} vs {want:?}");
    assert!(
        got[2].parse::<f64>().is_ok_and(f64::is_finite),
        "RPE median: {got:?}"
    );
}

/// `view` takes bags as it takes JSON Lines.
#[test]
fn view_takes_bags() {
    let Some(fx) = Fixture::new("bag-view") else {
        return;
    };
    for bag in [fx.bag("r2", "mcap", &[]), fx.bag("r1.bag", "ros1", &[])] {
        let html = fx.dir.join("view.html");
        ok_stdout(&["view", &bag, "-o", &html]);
        let page = std::fs::read_to_string(&html).unwrap();
        assert!(
            page.len() > 10_000 && page.contains("<html"),
            "{bag}: a page"
        );
    }
}

/// A nodding laser (simulate --sweep-rate 30: the hinge turns while each scan is taken) as
/// rosbags writes it: the LaserScan's time_increment and joint messages on the sweep just
/// before and after each scan. The reader must give every ray its own elevation (the joint
/// interpolated at the ray's time), so the bag levels as its JSON Lines, which carry
/// ray_elevation; the same bag read as stop-and-scan would not.
#[test]
fn nodding_bag_levels_as_its_json_lines() {
    let Some(fx) = Fixture::new("bag-nodding") else {
        return;
    };
    let scans = fx.dir.join("nod.jsonl");
    let plan = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/plans/office.wall");
    let sim = [
        "simulate",
        plan,
        "--random",
        "6",
        "--seed",
        "7",
        "--sweep-rate",
        "30",
    ];
    ok_stdout(&[&sim[..], &["-o", &scans]].concat());
    let jsonl = ok_records(&["level", &scans]);
    let fx = Fixture { scans, ..fx };
    let nod = fx.bag("nod", "mcap", &["--sweep-rate", "30"]);
    assert_same_levels(&ok_records(&["level", &nod]), &jsonl, "nodding bag");
    // The per-ray elevations as read, through match's pass-through.
    let want: Vec<Value> = std::fs::read_to_string(&fx.scans)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let read = ok_records(&["match", "--mode", "pairwise", &nod]);
    for (i, (g, w)) in read.iter().zip(&want).enumerate() {
        let (g, w) = (
            g["ray_elevation"].as_array(),
            w["ray_elevation"].as_array().unwrap(),
        );
        let g = g.unwrap_or_else(|| panic!("scan {i}: no ray_elevation read"));
        for (j, (a, b)) in g.iter().zip(w).enumerate() {
            assert!((f(a) - f(b)).abs() < 1e-8, "scan {i} ray {j}: {a} vs {b}");
        }
    }
    // Without the sweep (time_increment 0, the joint still): off by more than the tolerance.
    let still = fx.bag("still", "mcap", &[]);
    let worst = ok_records(&["level", &still])
        .iter()
        .zip(&jsonl)
        .filter(|(b, j)| b["level"]["status"] == "ok" && j["level"]["status"] == "ok")
        .map(|(b, j)| (f(&b["level"]["theta_y"]) - f(&j["level"]["theta_y"])).abs())
        .fold(0.0, f64::max);
    assert!(
        worst > ATTITUDE_TOL,
        "the test needs the sweep to matter ({worst} rad)"
    );
}
