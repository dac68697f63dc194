//! Reading ROS 2 MCAP bags (CONTRACT.md, "ROS bags"): a bag written here with the `mcap`
//! crate from simulated scans reads back as the same scans, grouped into the same poses, and
//! `level` gives the same attitudes on it as on the JSON Lines. The independent-writer twin
//! (bags from Python's `rosbags`) is tests/bag_interop.rs.

mod cli_support;

use cli_support::{bin, records};
use levelscan::formats::bag::{
    Bag, BagOptions, BagScans, CdrMessage, Header, JointState, LaserScan, Odometry, Pose,
    PoseStamped, Time, msgs::quaternion_from_rpy,
};
use levelscan::scan::Scan;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

fn temp_dir(name: &str) -> PathBuf {
    let dir =
        std::env::temp_dir().join(format!("levelscan-bag-read-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn simulate(dir: &Path, extra: &[&str]) -> (PathBuf, Vec<Scan>) {
    let path = dir.join("scans.jsonl");
    let plan = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/plans/office.wall");
    let mut args = vec!["simulate", plan, "--random", "12", "--seed", "5", "-o"];
    let p = path.to_str().unwrap().to_string();
    args.push(&p);
    args.extend_from_slice(extra);
    let out = bin().args(&args).output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(&path).unwrap();
    let scans = text
        .lines()
        .map(|l| levelscan::formats::parse_scan_line(l).unwrap())
        .collect();
    (path, scans)
}

/// Writes `scans` as a bag the contract's way: pose k at 1000 + 2k s, scans 0.1 s apart,
/// the hinge joint just before and after each scan. `sweep` (rad/s) moves the hinge during
/// each scan (time_increment set) for the nodding case.
struct BagSpec {
    with_odometry: bool,
    sweep: f64,
    scan_time: f64,
}

/// A robot that stops to scan, with odometry.
const STOP_AND_SCAN: BagSpec = BagSpec {
    with_odometry: true,
    sweep: 0.0,
    scan_time: 0.025,
};

/// Two `level` outputs pose by pose: the same status, and roll and pitch within 0.01 degree.
fn assert_same_attitudes(a: &[serde_json::Value], b: &[serde_json::Value]) {
    assert_eq!(a.len(), b.len());
    for (x, y) in a.iter().zip(b) {
        let (lx, ly) = (&x["level"], &y["level"]);
        assert_eq!(lx["status"], ly["status"]);
        for k in ["theta_x", "theta_y"] {
            if let (Some(p), Some(q)) = (lx[k].as_f64(), ly[k].as_f64()) {
                assert!((p - q).abs().to_degrees() < 0.01, "{k}: {p} against {q}");
            }
        }
    }
}

fn write_bag(path: &Path, scans: &[Scan], spec: &BagSpec) {
    let file = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    let mut w = mcap::WriteOptions::new()
        .profile("ros2")
        .compression(Some(mcap::Compression::Zstd))
        .create(file)
        .unwrap();
    let channel = |w: &mut mcap::Writer<_>, topic: &str, ty: &str| {
        let schema = w.add_schema(ty, "ros2msg", b"").unwrap();
        w.add_channel(schema, topic, "cdr", &BTreeMap::new())
            .unwrap()
    };
    let scan_ch = channel(&mut w, "/scan", LaserScan::TYPE);
    let joint_ch = channel(&mut w, "/joint_states", JointState::TYPE);
    let odom_ch = channel(&mut w, "/odom", Odometry::TYPE);
    let truth_ch = channel(&mut w, "/ground_truth", PoseStamped::TYPE);
    let mut messages: Vec<(u64, u16, Vec<u8>)> = Vec::new();
    let (mut pose, mut in_pose, mut last) = (0u64, 0u64, None);
    for s in scans {
        if last.is_some() && last != s.sequence {
            pose += 1;
            in_pose = 0;
        }
        last = s.sequence;
        let t = 1000.0 + 2.0 * pose as f64 + 0.1 * in_pose as f64;
        in_pose += 1;
        let header = |t: f64, frame: &str| Header {
            stamp: Time::from_seconds(t),
            frame_id: frame.to_string(),
        };
        let n = s.nrays();
        let inc = (s.theta[n - 1] - s.theta[0]) / (n - 1) as f64;
        let dt = spec.scan_time / n as f64;
        let e = s.elevation.unwrap();
        let laser = LaserScan {
            header: header(t, "laser"),
            angle_min: s.theta[0] as f32,
            angle_max: s.theta[n - 1] as f32,
            angle_increment: inc as f32,
            time_increment: if spec.sweep != 0.0 { dt as f32 } else { 0.0 },
            scan_time: spec.scan_time as f32,
            range_min: 0.0,
            range_max: 30.0,
            ranges: s
                .readings
                .iter()
                .map(|r| r.map_or(f32::NAN, |r| r as f32))
                .collect(),
            intensities: vec![],
        };
        let ns = |t: f64| (t * 1e9).round() as u64;
        messages.push((ns(t), scan_ch, laser.to_cdr()));
        for (tj, ej) in [
            (t - 0.001, e - spec.sweep * 0.001),
            (
                t + spec.scan_time + 0.001,
                e + spec.sweep * (spec.scan_time + 0.001),
            ),
        ] {
            let js = JointState {
                header: header(tj, ""),
                name: vec!["hinge".to_string()],
                position: vec![ej],
                velocity: vec![],
                effort: vec![],
            };
            messages.push((ns(tj), joint_ch, js.to_cdr()));
        }
        if spec.with_odometry {
            let o = s.odometry.unwrap();
            let odom = Odometry {
                header: header(t, "odom"),
                child_frame_id: "base_link".to_string(),
                pose: Pose {
                    position: [o.x, o.y, 0.0],
                    orientation: quaternion_from_rpy(0.0, 0.0, o.rz),
                },
                ..Default::default()
            };
            messages.push((ns(t), odom_ch, odom.to_cdr()));
        }
        let tp = s.true_pose.unwrap();
        let truth = PoseStamped {
            header: header(t, "world"),
            pose: Pose {
                position: [tp.x, tp.y, tp.z],
                orientation: quaternion_from_rpy(tp.rx, tp.ry, tp.rz),
            },
        };
        messages.push((ns(t), truth_ch, truth.to_cdr()));
    }
    messages.sort_by_key(|m| m.0);
    for (i, (t, ch, data)) in messages.iter().enumerate() {
        let header = mcap::records::MessageHeader {
            channel_id: *ch,
            sequence: i as u32,
            log_time: *t,
            publish_time: *t,
        };
        w.write_to_known_channel(&header, data).unwrap();
    }
    w.finish().unwrap();
}

fn read_bag(path: &Path) -> Vec<Scan> {
    let bag = Bag::detect(path).unwrap().expect("an MCAP bag");
    let (scans, _) = BagScans::open(bag, &BagOptions::default()).unwrap();
    scans.map(|s| s.unwrap().1).collect()
}

#[test]
fn a_bag_reads_as_the_scans_it_was_written_from() {
    let dir = temp_dir("same");
    let (_, scans) = simulate(&dir, &[]);
    for with_odometry in [true, false] {
        let bag = dir.join(format!("run-{with_odometry}.mcap"));
        let spec = BagSpec {
            with_odometry,
            sweep: 0.0,
            scan_time: 0.025,
        };
        write_bag(&bag, &scans, &spec);
        let read = read_bag(&bag);
        assert_eq!(read.len(), scans.len());
        for (a, b) in scans.iter().zip(&read) {
            // Poses from odometry, or (without) from the hinge's monotone sweeps.
            assert_eq!(a.sequence, b.sequence, "with_odometry {with_odometry}");
            assert_eq!(a.elevation, b.elevation);
            assert!(
                b.ray_elevation.is_none(),
                "a still hinge gives no per-ray elevation"
            );
            assert_eq!(a.nrays(), b.nrays());
            for i in 0..a.nrays() {
                assert!((a.theta[i] - b.theta[i]).abs() < 1e-6);
                match (a.range(i), b.range(i)) {
                    (Some(x), Some(y)) => assert!((x - y).abs() < 1e-5 * x.max(1.0)),
                    (x, y) => assert_eq!(x.is_some(), y.is_some()),
                }
            }
            let (ta, tb) = (a.true_pose.unwrap(), b.true_pose.unwrap());
            assert!((ta.ry - tb.ry).abs() < 1e-9 && (ta.rx - tb.rx).abs() < 1e-9);
            if with_odometry {
                let (oa, ob) = (a.odometry.unwrap(), b.odometry.unwrap());
                assert!((oa.x - ob.x).abs() < 1e-9 && (oa.rz - ob.rz).abs() < 1e-9);
            } else {
                assert!(b.odometry.is_none());
            }
            let ros = &b.extra["ros"];
            assert_eq!(ros["topic"], "/scan");
            assert_eq!(ros["frame_id"], "laser");
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_nodding_hinge_gives_each_ray_its_own_elevation() {
    let dir = temp_dir("nodding");
    let (_, scans) = simulate(&dir, &[]);
    let rate = 30f64.to_radians();
    let spec = BagSpec {
        with_odometry: true,
        sweep: rate,
        scan_time: 0.025,
    };
    let bag = dir.join("nod.mcap");
    write_bag(&bag, &scans, &spec);
    let read = read_bag(&bag);
    assert_eq!(read.len(), scans.len());
    for (a, b) in scans.iter().zip(&read) {
        let e0 = a.elevation.unwrap();
        let per_ray = b
            .ray_elevation
            .as_ref()
            .expect("the hinge moved during the scan");
        let dt = 0.025 / a.nrays() as f64;
        let mid = e0 + rate * dt * (a.nrays() - 1) as f64 / 2.0;
        let e = b.elevation.unwrap();
        assert!(
            (e - mid).abs() < 1e-7,
            "the scan's elevation is mid-scan: {e} against {mid}"
        );
        for (i, e) in per_ray.iter().enumerate() {
            // float32 time_increment: about 1e-7 relative on dt.
            let want = e0 + rate * i as f64 * dt;
            assert!((e - want).abs() < 1e-7, "ray {i}: {e} against {want}");
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn level_on_a_bag_gives_the_attitudes_of_level_on_its_json_lines() {
    let dir = temp_dir("level");
    let (jsonl, scans) = simulate(&dir, &[]);
    let bag = dir.join("run.mcap");
    write_bag(&bag, &scans, &STOP_AND_SCAN);
    let from_text = records(
        &bin()
            .args(["level", jsonl.to_str().unwrap()])
            .output()
            .unwrap(),
    );
    let from_bag = records(
        &bin()
            .args(["level", bag.to_str().unwrap()])
            .output()
            .unwrap(),
    );
    assert!(from_text.len() >= 10);
    assert_same_attitudes(&from_text, &from_bag);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn bag_topics_show_in_info_and_a_wrong_topic_is_named() {
    let dir = temp_dir("info");
    let (_, scans) = simulate(&dir, &[]);
    let bag = dir.join("run.mcap");
    write_bag(&bag, &scans, &STOP_AND_SCAN);
    let bag_arg = bag.to_str().unwrap();
    let info = records(&bin().args(["info", bag_arg]).output().unwrap());
    let info = &info[0];
    assert_eq!(info["format"], "mcap");
    assert_eq!(info["scan_topic"], "/scan");
    assert_eq!(info["hinge_joint"], "hinge");
    assert_eq!(info["odometry_topic"], "/odom");
    assert_eq!(info["scans"].as_u64(), Some(scans.len() as u64));
    let topics = info["topics"].as_array().unwrap();
    let joint = topics
        .iter()
        .find(|t| t["topic"] == "/joint_states")
        .unwrap();
    assert_eq!(joint["count"].as_u64(), Some(2 * scans.len() as u64));

    let out = bin()
        .args(["level", bag_arg, "--scan-topic", "/odom"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("/odom") && err.contains("nav_msgs/msg/Odometry"),
        "{err}"
    );
    assert!(!err.contains("panicked"));

    let out = bin()
        .args(["level", bag_arg, "--hinge-joint", "tilt"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("tilt") && err.contains("hinge"), "{err}");
    std::fs::remove_dir_all(&dir).ok();
}

/// Topic -> message count of an MCAP file, read with the mcap crate.
fn topic_counts(path: &Path) -> BTreeMap<String, usize> {
    let bytes = std::fs::read(path).unwrap();
    let mut counts = BTreeMap::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        *counts.entry(m.unwrap().channel.topic.clone()).or_insert(0) += 1;
    }
    counts
}

#[test]
fn level_and_match_write_bags_that_carry_the_input_through() {
    let dir = temp_dir("out");
    let (_, scans) = simulate(&dir, &[]);
    let bag = dir.join("run.mcap");
    write_bag(&bag, &scans, &STOP_AND_SCAN);
    let leveled = dir.join("leveled.mcap");
    let out = bin()
        .args([
            "level",
            bag.to_str().unwrap(),
            "-o",
            leveled.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let input = topic_counts(&bag);
    let output = topic_counts(&leveled);
    for (topic, n) in &input {
        assert_eq!(output.get(topic), Some(n), "{topic} copied through");
    }
    let poses = scans.last().unwrap().sequence.unwrap() as usize + 1;
    for topic in ["/scan_level", "/attitude", "/level_status"] {
        assert_eq!(output.get(topic), Some(&poses), "one {topic} per pose");
    }
    // The leveled bag reads back: match takes /scan_level by default, one record per pose.
    let matched = dir.join("matched.mcap");
    let out = bin()
        .args([
            "match",
            leveled.to_str().unwrap(),
            "-o",
            matched.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let output = topic_counts(&matched);
    assert_eq!(output.get("/odom_matched"), Some(&poses));
    assert_eq!(output.get("/match_status"), Some(&poses));
    assert_eq!(output.get("/scan"), Some(&scans.len()));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_simulated_nodding_bag_levels_like_its_json_lines() {
    let dir = temp_dir("simnod");
    let plan = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/plans/office.wall");
    let common = ["--random", "15", "--seed", "4", "--sweep-rate", "30"];
    let (jsonl, bag) = (dir.join("nod.jsonl"), dir.join("nod.mcap"));
    for out in [&jsonl, &bag] {
        let mut args = vec!["simulate", plan, "-o", out.to_str().unwrap()];
        args.extend_from_slice(&common);
        let run = bin().args(&args).output().unwrap();
        assert!(
            run.status.success(),
            "{}",
            String::from_utf8_lossy(&run.stderr)
        );
    }
    // The bag carries the sweep as joint motion and time_increment; the reader turns it back
    // into per-ray elevations, so both level alike.
    let read = read_bag(&bag);
    assert!(read.iter().all(|s| s.ray_elevation.is_some()));
    let a = records(
        &bin()
            .args(["level", jsonl.to_str().unwrap()])
            .output()
            .unwrap(),
    );
    let b = records(
        &bin()
            .args(["level", bag.to_str().unwrap()])
            .output()
            .unwrap(),
    );
    assert_eq!(a.len(), 15);
    assert_same_attitudes(&a, &b);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn leveling_a_leveled_bag_replaces_its_level_topics() {
    let dir = temp_dir("twice");
    let (_, scans) = simulate(&dir, &[]);
    let bag = dir.join("run.mcap");
    write_bag(&bag, &scans, &STOP_AND_SCAN);
    let once = dir.join("once.mcap");
    let twice = dir.join("twice.mcap");
    for (from, to) in [(&bag, &once), (&once, &twice)] {
        let args = [
            "level",
            from.to_str().unwrap(),
            "--scan-topic",
            "/scan",
            "-o",
            to.to_str().unwrap(),
        ];
        let out = bin().args(args).output().unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    assert_eq!(topic_counts(&once), topic_counts(&twice));
    std::fs::remove_dir_all(&dir).ok();
}
