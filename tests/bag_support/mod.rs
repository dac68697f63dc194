//! What the ROS bag tests share (tests/bag_interop.rs, tests/bag_bad.rs, tests/fuzz_mcap.rs):
//! temporary directories, running the binary, the one-line failure check, the Python
//! environment of the interop scripts (tests/interop/), and an MCAP writer of the test's own:
//! its own ROS 2 CDR encoder for the five message types (not levelscan's, so that a bug there
//! is not hidden by the same bug here), on foxglove's `mcap` crate for the container.
#![allow(dead_code)]

pub mod cdr;
pub mod interop;
pub use cdr::*;

use serde_json::Value;
use std::collections::BTreeMap;
use std::io::Cursor;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

pub const BIN: &str = env!("CARGO_BIN_EXE_levelscan");

/// A fresh directory under the system temp dir, removed on drop.
pub struct TempDir(pub PathBuf);

impl TempDir {
    pub fn new(tag: &str) -> TempDir {
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_nanos())
            .unwrap_or(0);
        let dir =
            std::env::temp_dir().join(format!("levelscan-{tag}-{}-{nanos}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        TempDir(dir)
    }

    /// A path inside, as a string for command lines.
    pub fn join(&self, name: &str) -> String {
        self.0.join(name).to_str().unwrap().to_string()
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// `levelscan ARGS`, waited for.
pub fn levelscan(args: &[&str]) -> Output {
    Command::new(BIN).args(args).output().unwrap()
}

/// Standard output of a run that must succeed (fails the test with its stderr otherwise).
pub fn ok_stdout(args: &[&str]) -> String {
    let out = levelscan(args);
    assert!(
        out.status.success(),
        "levelscan {}: {}",
        args.join(" "),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

/// The JSON Lines records of a run that must succeed.
pub fn ok_records(args: &[&str]) -> Vec<Value> {
    ok_stdout(args)
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

/// The contract's failure shape: non-zero exit, no panic, exactly one line on standard
/// error. Returns that line.
pub fn one_line_failure(out: &Output, case: &str) -> String {
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(!out.status.success(), "{case}: should fail, stderr: {err}");
    assert!(!err.contains("panicked"), "{case}: {err}");
    assert_eq!(out.status.code(), Some(1), "{case}: exit code ({err})");
    assert_eq!(
        err.lines().count(),
        1,
        "{case}: one line expected, got {err:?}"
    );
    err.trim_end().to_string()
}

/// Asserts that `line` contains every one of `parts` (file, topic, log time...).
pub fn assert_names(line: &str, parts: &[&str], case: &str) {
    for p in parts {
        assert!(line.contains(p), "{case}: {line:?} does not name {p:?}");
    }
}

// ---- Python (tests/interop/) -------------------------------------------------------------

/// The Python interpreter with `rosbags`, `mcap` and `mcap_ros2`: `LEVELSCAN_PYTHON`, else
/// `python3`. `None` after saying the test is skipped, unless `LEVELSCAN_REQUIRE_INTEROP=1`
/// (CI), when a missing interpreter or package fails the test.
pub fn python_or_skip(test: &str) -> Option<String> {
    let python = std::env::var("LEVELSCAN_PYTHON").unwrap_or_else(|_| "python3".into());
    let probe = Command::new(&python)
        .args(["-c", "import rosbags, mcap, mcap_ros2.decoder, numpy"])
        .output();
    let why = match probe {
        Ok(o) if o.status.success() => return Some(python),
        Ok(o) => String::from_utf8_lossy(&o.stderr).trim().to_string(),
        Err(e) => e.to_string(),
    };
    if std::env::var("LEVELSCAN_REQUIRE_INTEROP").as_deref() == Ok("1") {
        panic!(
            "{test}: {python} cannot run the interop scripts ({why}) and LEVELSCAN_REQUIRE_INTEROP=1"
        );
    }
    eprintln!(
        "{test}: SKIPPED: {python} lacks rosbags, mcap or mcap-ros2-support ({why}); \
         set LEVELSCAN_PYTHON to a Python that has them (see .ci/run)"
    );
    None
}

/// Runs `tests/interop/SCRIPT ARGS` with `python`; its stdout, or the test fails.
pub fn run_script(python: &str, script: &str, args: &[&str]) -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/interop")
        .join(script);
    let out = Command::new(python).arg(&path).args(args).output().unwrap();
    assert!(
        out.status.success(),
        "{script} {}: {}",
        args.join(" "),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

// ---- MCAP files ----------------------------------------------------------------------------

/// One message to write: topic, type (ROS 2 name), log time [ns], CDR bytes.
#[derive(Clone, Debug)]
pub struct Msg {
    pub topic: String,
    pub msgtype: String,
    pub log_time: u64,
    pub data: Vec<u8>,
}

/// How to lay the file out.
#[derive(Clone, Copy, Debug)]
pub struct Layout {
    pub compression: Option<mcap::Compression>,
    /// Target chunk size [bytes]; small values make many chunks (the fuzz seeds).
    pub chunk_size: u64,
    pub use_chunks: bool,
}

impl Default for Layout {
    fn default() -> Self {
        Layout {
            compression: Some(mcap::Compression::Zstd),
            chunk_size: 64 * 1024,
            use_chunks: true,
        }
    }
}

/// An MCAP file (ROS 2 profile, ros2msg schemas, cdr channels) holding `msgs` in order.
pub fn mcap_bytes(msgs: &[Msg], layout: Layout) -> Vec<u8> {
    let opts = mcap::WriteOptions::new()
        .profile("ros2")
        .compression(layout.compression)
        .chunk_size(Some(layout.chunk_size))
        .use_chunks(layout.use_chunks);
    let mut w = opts.create(Cursor::new(Vec::new())).unwrap();
    let mut channels: BTreeMap<String, u16> = BTreeMap::new();
    for (seq, m) in msgs.iter().enumerate() {
        let id = match channels.get(&m.topic) {
            Some(id) => *id,
            None => {
                let text = schema_text(&m.msgtype);
                let schema = w
                    .add_schema(&m.msgtype, "ros2msg", text.as_bytes())
                    .unwrap();
                let id = w
                    .add_channel(schema, &m.topic, "cdr", &BTreeMap::new())
                    .unwrap();
                channels.insert(m.topic.clone(), id);
                id
            }
        };
        let header = mcap::records::MessageHeader {
            channel_id: id,
            sequence: seq as u32,
            log_time: m.log_time,
            publish_time: m.log_time,
        };
        w.write_to_known_channel(&header, &m.data).unwrap();
    }
    w.finish().unwrap();
    w.into_inner().into_inner()
}

/// What [`bag_messages`] puts in a bag, and the bad cases it can make.
#[derive(Clone, Debug)]
pub struct BagSpec {
    pub scan_topics: Vec<&'static str>,
    /// The type written on the first scan topic (a String for the wrong-schema case).
    pub scan_type: &'static str,
    pub joint_names: Vec<&'static str>,
    pub joints: bool,
    pub odom: bool,
    pub truth: bool,
}

impl Default for BagSpec {
    fn default() -> Self {
        BagSpec {
            scan_topics: vec!["/scan"],
            scan_type: "sensor_msgs/msg/LaserScan",
            joint_names: vec!["hinge"],
            joints: true,
            odom: true,
            truth: true,
        }
    }
}

/// Log time of scan `j` of pose `k` [ns]: 1000 + 2k s, scans 0.1 s apart (the contract).
pub fn scan_time_ns(pose: usize, within: usize) -> u64 {
    1_000_000_000_000 + 2_000_000_000 * pose as u64 + 100_000_000 * within as u64
}

/// The messages of a bag holding `scans` (scan JSON Lines records, simulate output) laid out
/// as the contract's `simulate -o run.mcap` (see tests/interop/write_bag.py), in log-time order.
pub fn bag_messages(scans: &[Value], spec: &BagSpec) -> Vec<Msg> {
    let mut out = Vec::new();
    let (mut pose, mut within, mut last) = (0usize, 0usize, None);
    for s in scans {
        let seq = s["sequence"].as_u64();
        if last.is_some() && seq != last {
            pose += 1;
            within = 0;
        }
        last = seq;
        scan_messages(s, scan_time_ns(pose, within), spec, &mut out);
        within += 1;
    }
    out
}

fn msg(topic: &str, ty: &str, log_time: u64, data: Vec<u8>) -> Msg {
    Msg {
        topic: topic.into(),
        msgtype: ty.into(),
        log_time,
        data,
    }
}

fn numbers(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

/// The messages of one scan stamped `t` [ns]: joints 10 ms before, the scan, odometry and
/// truth at `t`, joints 10 ms after.
fn scan_messages(s: &Value, t: u64, spec: &BagSpec, out: &mut Vec<Msg>) {
    let e = s["elevation"].as_f64().unwrap();
    let positions: Vec<f64> = (0..spec.joint_names.len())
        .map(|i| if i == 0 { e } else { 0.0 })
        .collect();
    let joints = |lt: u64| {
        let data = joint_state_cdr(lt, &spec.joint_names, &positions);
        msg("/joint_states", "sensor_msgs/msg/JointState", lt, data)
    };
    if spec.joints {
        out.push(joints(t - 10_000_000));
    }
    for (i, topic) in spec.scan_topics.iter().enumerate() {
        let ty = if i == 0 { spec.scan_type } else { LASER_SCAN };
        let data = if ty == LASER_SCAN {
            scan_cdr(s, t)
        } else {
            string_cdr("not a scan")
        };
        out.push(msg(topic, ty, t, data));
    }
    if spec.odom {
        let o = numbers(&s["odometry"]);
        let data = odometry_cdr(t, o[0], o[1], o[2]);
        out.push(msg("/odom", "nav_msgs/msg/Odometry", t, data));
    }
    if spec.truth {
        let data = pose_stamped_cdr(t, &numbers(&s["true_pose"]));
        out.push(msg(
            "/ground_truth",
            "geometry_msgs/msg/PoseStamped",
            t,
            data,
        ));
    }
    if spec.joints {
        out.push(joints(t + 10_000_000));
    }
}

const LASER_SCAN: &str = "sensor_msgs/msg/LaserScan";

/// One LaserScan of a scan record: angle_min = theta[0], the even spacing, NaN for no return.
fn scan_cdr(s: &Value, stamp_ns: u64) -> Vec<u8> {
    let theta: Vec<f64> = s["theta"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let n = theta.len();
    let ranges: Vec<f32> = s["readings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r.as_f64().map_or(f32::NAN, |r| r as f32))
        .collect();
    laser_scan_cdr(&LaserScanMsg {
        stamp_ns,
        frame: "laser",
        angle_min: theta[0] as f32,
        angle_increment: ((theta[n - 1] - theta[0]) / (n - 1) as f64) as f32,
        range_min: 0.02,
        range_max: 40.0,
        ranges: &ranges,
    })
}

/// `levelscan simulate` output (scan records) for a few random poses of the office plan.
pub fn simulated_scans(poses: usize, rays: usize, seed: u64) -> Vec<Value> {
    let plan = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/plans/office.wall");
    let args = [
        "simulate",
        plan.to_str().unwrap(),
        "--random",
        &poses.to_string(),
        "--rays",
        &rays.to_string(),
        "--seed",
        &seed.to_string(),
    ];
    ok_records(&args.iter().map(|s| s.as_ref()).collect::<Vec<&str>>())
}

/// MCAP records at the top level of `bytes` (after the 8-byte magic): (offset, opcode, body
/// start, body length), up to the first one that does not fit.
pub fn top_level_records(bytes: &[u8]) -> Vec<(usize, u8, usize, usize)> {
    let mut out = Vec::new();
    let mut at = 8;
    while at + 9 <= bytes.len() {
        let op = bytes[at];
        let len = u64::from_le_bytes(bytes[at + 1..at + 9].try_into().unwrap());
        if len > (bytes.len() - at - 9) as u64 {
            break;
        }
        let len = len as usize;
        out.push((at, op, at + 9, len));
        at += 9 + len;
    }
    out
}

/// MCAP opcodes used by the tests (the MCAP specification, "Records").
pub const OP_HEADER: u8 = 0x01;
pub const OP_FOOTER: u8 = 0x02;
pub const OP_SCHEMA: u8 = 0x03;
pub const OP_CHANNEL: u8 = 0x04;
pub const OP_MESSAGE: u8 = 0x05;
pub const OP_CHUNK: u8 = 0x06;
pub const OP_DATA_END: u8 = 0x0F;
