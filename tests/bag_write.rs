//! Writing ROS 2 bags: `BagWriter` output read back with the mcap crate's own reader (every
//! message type, copy-through, the unseekable path, the summary), and `levelscan simulate -o
//! run.mcap` read back in Rust and by the reference Python decoder (foxglove's `mcap` and
//! `mcap-ros2-support`, tests/interop/read_simulated.py).
//!
//! The Python test needs `LEVELSCAN_PYTHON` (else `python3`) with those packages; without
//! them it says it is skipped, unless `LEVELSCAN_REQUIRE_INTEROP=1`, when it fails.

mod cli_support;
use cli_support::*;

use levelscan::formats::bag::convert::{self, ScanMeta};
use levelscan::formats::bag::msgs::{Header, Pose, Time};
use levelscan::formats::bag::{
    BagWriter, CdrMessage, Imu, JointState, LaserScan, Odometry, PoseStamped, RawMessage, StringMsg,
};
use levelscan::scan::Scan;
use serde_json::{Value, json};
use std::collections::BTreeMap;
use std::io::Cursor;
use std::path::{Path, PathBuf};

fn header(frame: &str, sec: i32) -> Header {
    Header {
        stamp: Time { sec, nanosec: 7 },
        frame_id: frame.into(),
    }
}

fn laser_scan() -> LaserScan {
    LaserScan {
        header: header("laser", 1000),
        angle_min: -1.0,
        angle_max: 1.0,
        angle_increment: 0.5,
        time_increment: 1e-4,
        scan_time: 0.025,
        range_min: 0.1,
        range_max: 30.0,
        ranges: vec![1.0, f32::NAN, 2.5, 3.0, f32::INFINITY],
        intensities: vec![],
    }
}

fn odometry() -> Odometry {
    let mut o = Odometry {
        header: header("odom", 1001),
        child_frame_id: "base_link".into(),
        pose: Pose {
            position: [1.0, 2.0, 0.0],
            orientation: [0.0, 0.0, 0.6, 0.8],
        },
        ..Odometry::default()
    };
    o.pose_covariance[35] = 0.01;
    o.twist = [0.1, 0.0, 0.0, 0.0, 0.0, 0.2];
    o
}

/// A bag's messages as (topic, schema name, schema encoding, message encoding, sequence, log
/// time, publish time, bytes), in file order.
type Read = (String, String, String, String, u32, u64, u64, Vec<u8>);

fn read_all(bytes: &[u8]) -> Vec<Read> {
    mcap::MessageStream::new(bytes)
        .unwrap()
        .map(|m| {
            let m = m.unwrap();
            let schema = m.channel.schema.as_ref();
            (
                m.channel.topic.clone(),
                schema.map_or(String::new(), |s| s.name.clone()),
                schema.map_or(String::new(), |s| s.encoding.clone()),
                m.channel.message_encoding.clone(),
                m.sequence,
                m.log_time,
                m.publish_time,
                m.data.into_owned(),
            )
        })
        .collect()
}

fn decode<M: CdrMessage>(r: &Read) -> M {
    M::from_cdr(&r.7).unwrap()
}

/// The header record's profile and library.
fn profile_and_library(bytes: &[u8]) -> (String, String) {
    let first = mcap::read::LinearReader::new(bytes)
        .unwrap()
        .next()
        .unwrap()
        .unwrap();
    match first {
        mcap::records::Record::Header(h) => (h.profile, h.library),
        other => panic!("first record {other:?}"),
    }
}

/// Writes one message of every type, on both a seekable and an unseekable output.
fn every_type(bag: &mut BagWriter<impl std::io::Write + std::io::Seek>) {
    bag.write("/scan", 1_000_000_000_007, &laser_scan())
        .unwrap();
    let joint = JointState {
        header: header("", 999),
        name: vec!["hinge".into()],
        position: vec![-0.1],
        velocity: vec![],
        effort: vec![],
    };
    bag.write("/joint_states", 999_000_000_007, &joint).unwrap();
    bag.write("/odom", 1_001_000_000_007, &odometry()).unwrap();
    let truth = PoseStamped {
        header: header("world", 1001),
        pose: odometry().pose,
    };
    bag.write("/ground_truth", 1_001_000_000_007, &truth)
        .unwrap();
    let imu = Imu {
        header: header("laser", 1000),
        orientation: [0.0, 0.05, 0.0, 0.99875],
        orientation_covariance: [1e-6, 0.0, 0.0, 0.0, 1e-6, 0.0, 0.0, 0.0, 1e6],
        angular_velocity_covariance: [-1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        linear_acceleration_covariance: [-1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        ..Imu::default()
    };
    bag.write("/attitude", 1_000_000_000_007, &imu).unwrap();
    let status = StringMsg {
        data: r#"{"status":"ok"}"#.into(),
    };
    bag.write("/level_status", 1_000_000_000_007, &status)
        .unwrap();
    bag.write("/scan", 1_000_100_000_007, &laser_scan())
        .unwrap();
    assert_eq!(bag.message_count(), 7);
}

fn check_every_type(bytes: &[u8]) {
    let (profile, library) = profile_and_library(bytes);
    assert_eq!(profile, "ros2");
    assert_eq!(library, format!("levelscan {}", env!("CARGO_PKG_VERSION")));
    let msgs = read_all(bytes);
    assert_eq!(msgs.len(), 7);
    for m in &msgs {
        assert_eq!((m.2.as_str(), m.3.as_str()), ("ros2msg", "cdr"), "{}", m.0);
        assert_eq!(m.5, m.6, "publish time = log time");
    }
    let scan: LaserScan = decode(&msgs[0]);
    let want = laser_scan();
    // NaN != NaN: compare the bits of the ranges.
    let bits = |s: &LaserScan| s.ranges.iter().map(|r| r.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&scan), bits(&want));
    assert_eq!(
        LaserScan {
            ranges: vec![],
            ..scan
        },
        LaserScan {
            ranges: vec![],
            ..want
        }
    );
    assert_eq!(
        (msgs[0].1.as_str(), msgs[0].4),
        ("sensor_msgs/msg/LaserScan", 0)
    );
    assert_eq!(
        (msgs[6].0.as_str(), msgs[6].4),
        ("/scan", 1),
        "sequence per channel"
    );
    let joint: JointState = decode(&msgs[1]);
    assert_eq!(joint.position, [-0.1]);
    assert_eq!(msgs[1].5, 999_000_000_007);
    assert_eq!(decode::<Odometry>(&msgs[2]), odometry());
    assert_eq!(decode::<PoseStamped>(&msgs[3]).pose, odometry().pose);
    assert_eq!(decode::<Imu>(&msgs[4]).orientation_covariance[8], 1e6);
    assert_eq!(
        decode::<StringMsg>(&msgs[5]).data,
        r#"{"status":"ok"}"#.to_string()
    );

    let summary = mcap::Summary::read(bytes).unwrap().expect("a summary");
    let stats = summary.stats.as_ref().unwrap();
    assert_eq!(stats.message_count, 7);
    assert_eq!(stats.channel_count, 6);
    assert_eq!(stats.schema_count, 6);
    assert!(!summary.chunk_indexes.is_empty());
    for ci in &summary.chunk_indexes {
        assert_eq!(ci.compression, "zstd");
        assert!(!ci.message_index_offsets.is_empty());
        let indexed = summary.read_message_indexes(bytes, ci).unwrap();
        assert_eq!(indexed.values().map(Vec::len).sum::<usize>(), 7);
    }
    for ch in summary.channels.values() {
        assert!(ch.metadata["offered_qos_profiles"].contains("reliability: 1"));
    }
    let schema = summary
        .schemas
        .values()
        .find(|s| s.name == "sensor_msgs/msg/Imu")
        .unwrap();
    let text = std::str::from_utf8(&schema.data).unwrap();
    assert!(text.starts_with("std_msgs/Header header\ngeometry_msgs/Quaternion orientation\n"));
    assert!(text.contains(&format!(
        "{}\nMSG: geometry_msgs/msg/Vector3\n",
        "=".repeat(80)
    )));
}

#[test]
fn every_message_type_round_trips_through_a_file() {
    let mut bag = BagWriter::new(Cursor::new(Vec::new()), "out.mcap").unwrap();
    every_type(&mut bag);
    check_every_type(&bag.finish().unwrap().into_inner());
}

/// Standard output and staged files are written front to back: the same records.
#[test]
fn an_unseekable_output_gets_the_same_bag() {
    let mut bag = BagWriter::unseekable(Vec::new(), "<stdout>").unwrap();
    every_type(&mut bag);
    let unseekable = bag.finish().unwrap().into_inner();
    check_every_type(&unseekable);
    let mut bag = BagWriter::new(Cursor::new(Vec::new()), "out.mcap").unwrap();
    every_type(&mut bag);
    assert_eq!(
        read_all(&unseekable),
        read_all(&bag.finish().unwrap().into_inner())
    );
}

/// Input messages are copied byte for byte with their schema, encoding and both times; a
/// channel's own metadata is kept when given.
#[test]
fn copied_messages_keep_bytes_schema_and_times() {
    let ros1 = RawMessage {
        topic: "/tf",
        schema_name: "tf2_msgs/TFMessage",
        schema_encoding: "ros1msg",
        schema_data: b"geometry_msgs/TransformStamped[] transforms\n",
        message_encoding: "ros1",
        log_time: 5_000,
        publish_time: 4_000,
        data: &[1, 2, 3, 4],
    };
    let cdr = RawMessage {
        topic: "/tf_static",
        schema_name: "tf2_msgs/msg/TFMessage",
        schema_encoding: "ros2msg",
        schema_data: b"geometry_msgs/TransformStamped[] transforms\n",
        message_encoding: "cdr",
        log_time: 6_000,
        publish_time: 6_000,
        data: &[0, 1, 0, 0, 0, 0, 0, 0],
    };
    let latched = BTreeMap::from([(
        "offered_qos_profiles".to_string(),
        "- history: 1\n  depth: 1\n  reliability: 1\n  durability: 1".to_string(),
    )]);
    let mut bag = BagWriter::new(Cursor::new(Vec::new()), "out.mcap").unwrap();
    bag.copy_raw(&ros1).unwrap();
    bag.copy_raw_with_metadata(&cdr, &latched).unwrap();
    bag.copy_raw(&RawMessage {
        log_time: 7_000,
        ..ros1
    })
    .unwrap();
    let bytes = bag.finish().unwrap().into_inner();
    let msgs = read_all(&bytes);
    let want = |r: &RawMessage, seq: u32| -> Read {
        (
            r.topic.into(),
            r.schema_name.into(),
            r.schema_encoding.into(),
            r.message_encoding.into(),
            seq,
            r.log_time,
            r.publish_time,
            r.data.to_vec(),
        )
    };
    assert_eq!(msgs[0], want(&ros1, 0));
    assert_eq!(msgs[1], want(&cdr, 0));
    assert_eq!(
        msgs[2],
        want(
            &RawMessage {
                log_time: 7_000,
                ..ros1
            },
            1
        )
    );
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    let tf_static = summary
        .channels
        .values()
        .find(|c| c.topic == "/tf_static")
        .unwrap();
    assert_eq!(tf_static.metadata, latched);
    let schema = tf_static.schema.as_ref().unwrap();
    assert_eq!(&schema.data[..], cdr.schema_data);
}

#[test]
fn a_topic_keeps_one_type() {
    let mut bag = BagWriter::new(Cursor::new(Vec::new()), "out.mcap").unwrap();
    bag.write("/x", 1, &laser_scan()).unwrap();
    let err = bag.write("/x", 2, &StringMsg::default()).unwrap_err();
    assert_eq!(
        err.to_string(),
        "out.mcap: topic /x already holds sensor_msgs/msg/LaserScan messages, cannot also \
         write std_msgs/msg/String on it"
    );
}

/// `level`'s messages built from a record and written: what comes back decodes to them.
#[test]
fn level_messages_written_and_read_back() {
    let mut record = Scan {
        theta: vec![-0.1, 0.0, 0.1],
        readings: vec![Some(2.0), None, Some(3.0)],
        valid: vec![true, false, true],
        ..Scan::default()
    };
    record.extra.insert(
        "level".into(),
        json!({"status": "ok", "theta_x": 0.01, "theta_y": -0.02, "sigma_x": 0.001,
            "sigma_y": 0.002}),
    );
    record.extra.insert(
        "ros".into(),
        json!({"frame_id": "laser", "stamp": [1000, 0], "angle_min": -0.1,
            "angle_increment": 0.1, "range_min": 0.1, "range_max": 30.0, "log_time": 1_000_000_000_500u64}),
    );
    let meta = ScanMeta::of(&record, 0);
    let scan = convert::scan_level(&record, &meta);
    let imu = convert::attitude(&record, &meta);
    let status = StringMsg {
        data: convert::status_string(&record, "level").unwrap(),
    };
    let mut bag = BagWriter::new(Cursor::new(Vec::new()), "out.mcap").unwrap();
    bag.write(convert::SCAN_LEVEL_TOPIC, meta.log_time, &scan)
        .unwrap();
    bag.write(convert::ATTITUDE_TOPIC, meta.log_time, &imu)
        .unwrap();
    bag.write(convert::LEVEL_STATUS_TOPIC, meta.log_time, &status)
        .unwrap();
    let msgs = read_all(&bag.finish().unwrap().into_inner());
    let back: LaserScan = decode(&msgs[0]);
    assert_eq!(back.header.frame_id, "laser_level");
    assert_eq!(back.ranges[0], 2.0);
    assert!(back.ranges[1].is_nan());
    assert_eq!(back.ranges[2], 3.0);
    assert_eq!(decode::<Imu>(&msgs[1]), imu);
    let v: Value = serde_json::from_str(&decode::<StringMsg>(&msgs[2]).data).unwrap();
    assert_eq!(v["theta_y"], -0.02);
    assert!(msgs.iter().all(|m| m.5 == 1_000_000_000_500));
}

fn office() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/plans/office.wall")
}

fn temp(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("levelscan-bagwrite-{}-{name}", std::process::id()))
}

/// `simulate -o run.mcap`: per pose, its scans 0.1 s apart from 1000 + 2k s, two joint
/// messages per scan at its elevation, odometry and truth at its stamp; the ranges are the
/// JSON Lines output's, as f32, NaN where it has null.
#[test]
fn simulate_writes_a_bag_with_the_json_lines_scans() {
    let path = temp("run.mcap");
    let plan = office();
    let args = [
        "simulate",
        plan.to_str().unwrap(),
        "--seed",
        "3",
        "--scans",
        "3",
    ];
    let out = bin().args(args).arg("-o").arg(&path).output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let bytes = std::fs::read(&path).unwrap();
    let _ = std::fs::remove_file(&path);
    let jsonl = records(&bin().args(args).output().unwrap());
    let msgs = read_all(&bytes);
    let on = |topic: &str| msgs.iter().filter(|m| m.0 == topic).collect::<Vec<_>>();
    let scans = on("/scan");
    assert_eq!(scans.len(), jsonl.len());
    assert_eq!(on("/joint_states").len(), 2 * jsonl.len());
    assert_eq!(on("/odom").len(), jsonl.len());
    assert_eq!(on("/ground_truth").len(), jsonl.len());
    for (i, (m, rec)) in scans.iter().zip(&jsonl).enumerate() {
        let (k, j) = (i / 3, i % 3);
        let stamp = (1000 + 2 * k as u64) * 1_000_000_000 + j as u64 * 100_000_000;
        assert_eq!(m.5, stamp, "scan {i}");
        let s: LaserScan = decode(m);
        assert_eq!(s.header.stamp.nanos(), stamp);
        let want: Vec<f32> = rec["readings"]
            .as_array()
            .unwrap()
            .iter()
            .map(|r| r.as_f64().map_or(f32::NAN, |r| r as f32))
            .collect();
        let bits = |v: &[f32]| v.iter().map(|r| r.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&s.ranges), bits(&want), "scan {i}");
        let theta0 = rec["theta"][0].as_f64().unwrap();
        assert!((f64::from(s.angle_min) - theta0).abs() < 1e-7);
    }
    let elevation = |i: usize| jsonl[i]["elevation"].as_f64().unwrap();
    for (n, m) in on("/joint_states").iter().enumerate() {
        let j: JointState = decode(m);
        assert_eq!(
            (j.name.as_slice(), j.position.as_slice()),
            (&["hinge".to_string()][..], &[elevation(n / 2)][..])
        );
    }
    let truth: PoseStamped = decode(on("/ground_truth")[0]);
    let tp = jsonl[0]["true_pose"].as_array().unwrap();
    assert_eq!(truth.pose.position[0], tp[0].as_f64().unwrap());
    assert_eq!(truth.pose.position[2], tp[2].as_f64().unwrap());

    // --format mcap to standard output: the same bytes.
    let piped = bin()
        .args(args)
        .args(["--format", "mcap"])
        .output()
        .unwrap();
    assert!(piped.status.success());
    assert_eq!(piped.stdout, bytes);
}

/// The Python interpreter with `mcap` and `mcap_ros2`, or `None` after saying the test is
/// skipped (a failure with `LEVELSCAN_REQUIRE_INTEROP=1`).
fn python(test: &str) -> Option<String> {
    let python = std::env::var("LEVELSCAN_PYTHON").unwrap_or_else(|_| "python3".into());
    let probe = std::process::Command::new(&python)
        .args(["-c", "import mcap, mcap_ros2.decoder"])
        .output();
    let why = match probe {
        Ok(o) if o.status.success() => return Some(python),
        Ok(o) => String::from_utf8_lossy(&o.stderr)
            .lines()
            .last()
            .unwrap_or("")
            .to_string(),
        Err(e) => e.to_string(),
    };
    if std::env::var("LEVELSCAN_REQUIRE_INTEROP").as_deref() == Ok("1") {
        panic!("{test}: {python} cannot import mcap and mcap_ros2 ({why})");
    }
    eprintln!(
        "{test}: SKIPPED: {python} has no mcap and mcap-ros2-support ({why}); set \
         LEVELSCAN_PYTHON to a Python that has them"
    );
    None
}

/// The reference readers open simulate's bag: profile ros2, ros2msg schemas, cdr messages,
/// a summary with statistics and chunk indexes (zstd, with message indexes), and every
/// message decodes.
#[test]
fn reference_decoder_reads_a_simulated_bag() {
    let Some(python) = python("reference_decoder_reads_a_simulated_bag") else {
        return;
    };
    let path = temp("interop.mcap");
    let plan = office();
    let out = bin()
        .args(["simulate", plan.to_str().unwrap(), "--scans", "4", "-o"])
        .arg(&path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/interop/read_simulated.py");
    let run = std::process::Command::new(&python)
        .arg(&script)
        .arg(&path)
        .output()
        .unwrap();
    let _ = std::fs::remove_file(&path);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let got: Value = serde_json::from_slice(&run.stdout).unwrap();
    let poses = levelscan::formats::read_plan(&office())
        .unwrap()
        .poses
        .len() as u64;
    assert_eq!(got["profile"], "ros2");
    assert_eq!(
        got["library"],
        format!("levelscan {}", env!("CARGO_PKG_VERSION"))
    );
    for (topic, ty, n) in [
        ("/scan", "sensor_msgs/msg/LaserScan", 4 * poses),
        ("/joint_states", "sensor_msgs/msg/JointState", 8 * poses),
        ("/odom", "nav_msgs/msg/Odometry", 4 * poses),
        ("/ground_truth", "geometry_msgs/msg/PoseStamped", 4 * poses),
    ] {
        assert_eq!(got["schemas"][ty], "ros2msg", "{topic}");
        assert_eq!(got["channels"][topic]["type"], ty);
        assert_eq!(got["channels"][topic]["message_encoding"], "cdr");
        assert!(got["channels"][topic]["qos"].is_string());
        assert_eq!(got["statistics"][topic], n, "{topic}");
        assert_eq!(got["counts"][topic], n, "{topic}");
    }
    let chunks = got["chunk_indexes"].as_u64().unwrap();
    assert!(chunks >= 1);
    assert_eq!(got["chunks_with_message_indexes"], chunks);
    assert_eq!(got["compression"], json!(["zstd"]));
    let scan = &got["first"]["/scan"];
    assert_eq!(scan["header"]["stamp"], json!({"sec": 1000, "nanosec": 0}));
    assert_eq!(scan["header"]["frame_id"], "laser");
    assert_eq!(scan["log_time"], 1_000_000_000_000u64);
    let joint = &got["first"]["/joint_states"];
    assert_eq!(joint["name"], json!(["hinge"]));
    assert_eq!(
        joint["header"]["stamp"],
        json!({"sec": 999, "nanosec": 999_000_000})
    );
    assert_eq!(got["first"]["/ground_truth"]["header"]["frame_id"], "world");
    assert_eq!(got["first"]["/odom"]["child_frame_id"], "base_link");
}

/// More scans per pose than fit in its 2 s: refused before anything is written.
#[test]
fn too_many_scans_per_pose_for_a_bag_is_refused() {
    let path = temp("toomany.mcap");
    let plan = office();
    let out = bin()
        .args(["simulate", plan.to_str().unwrap(), "--scans", "21", "-o"])
        .arg(&path)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(err.contains("at most 20 scans per pose"), "{err}");
    assert!(!err.contains("panicked"));
    assert!(!path.exists());
}
