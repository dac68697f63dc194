//! What the ROS bag tests share (tests/bag_interop.rs, tests/bag_bad.rs, tests/fuzz_mcap.rs):
//! temporary directories, running the binary, the one-line failure check, the Python
//! environment of the interop scripts (tests/interop/), and an MCAP writer of the test's own:
//! its own ROS 2 CDR encoder for the five message types (not levelscan's, so that a bug there
//! is not hidden by the same bug here), on foxglove's `mcap` crate for the container.
#![allow(dead_code)]

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

// ---- ROS 2 CDR, little endian (the test's own encoder) ------------------------------------

/// A CDR buffer: the 4-byte encapsulation header (CDR_LE), then fields aligned to their size
/// counted from the end of that header (the OMG CDR rule ROS 2 uses).
pub struct Cdr(pub Vec<u8>);

impl Cdr {
    pub fn new() -> Cdr {
        Cdr(vec![0, 1, 0, 0])
    }
    fn align(&mut self, n: usize) {
        while (self.0.len() - 4) % n != 0 {
            self.0.push(0);
        }
    }
    pub fn u32(&mut self, v: u32) -> &mut Self {
        self.align(4);
        self.0.extend_from_slice(&v.to_le_bytes());
        self
    }
    pub fn i32(&mut self, v: i32) -> &mut Self {
        self.u32(v as u32)
    }
    pub fn f32(&mut self, v: f32) -> &mut Self {
        self.u32(v.to_bits())
    }
    pub fn f64(&mut self, v: f64) -> &mut Self {
        self.align(8);
        self.0.extend_from_slice(&v.to_le_bytes());
        self
    }
    pub fn string(&mut self, s: &str) -> &mut Self {
        self.u32(s.len() as u32 + 1);
        self.0.extend_from_slice(s.as_bytes());
        self.0.push(0);
        self
    }
    pub fn header(&mut self, ns: u64, frame: &str) -> &mut Self {
        self.i32((ns / 1_000_000_000) as i32)
            .u32((ns % 1_000_000_000) as u32)
            .string(frame)
    }
    pub fn f64s(&mut self, v: &[f64]) -> &mut Self {
        self.u32(v.len() as u32);
        for x in v {
            self.f64(*x);
        }
        self
    }
    /// A pose: position, then the quaternion (x, y, z, w) of yaw about z, roll/pitch given.
    pub fn pose(&mut self, p: [f64; 3], q: [f64; 4]) -> &mut Self {
        for x in p.iter().chain(q.iter()) {
            self.f64(*x);
        }
        self
    }
    pub fn done(&mut self) -> Vec<u8> {
        std::mem::take(&mut self.0)
    }
}

/// Quaternion (x, y, z, w) of Rz(yaw) Ry(pitch) Rx(roll).
pub fn quat(roll: f64, pitch: f64, yaw: f64) -> [f64; 4] {
    let (sr, cr) = (roll / 2.0).sin_cos();
    let (sp, cp) = (pitch / 2.0).sin_cos();
    let (sy, cy) = (yaw / 2.0).sin_cos();
    [
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
        cr * cp * cy + sr * sp * sy,
    ]
}

pub struct LaserScanMsg<'a> {
    pub stamp_ns: u64,
    pub frame: &'a str,
    pub angle_min: f32,
    pub angle_increment: f32,
    pub range_min: f32,
    pub range_max: f32,
    pub ranges: &'a [f32],
}

pub fn laser_scan_cdr(m: &LaserScanMsg) -> Vec<u8> {
    let n = m.ranges.len().max(1) as f32;
    let mut c = Cdr::new();
    c.header(m.stamp_ns, m.frame)
        .f32(m.angle_min)
        .f32(m.angle_min + m.angle_increment * (n - 1.0))
        .f32(m.angle_increment)
        .f32(0.0)
        .f32(0.1)
        .f32(m.range_min)
        .f32(m.range_max)
        .u32(m.ranges.len() as u32);
    for r in m.ranges {
        c.f32(*r);
    }
    c.u32(0).done()
}

pub fn joint_state_cdr(stamp_ns: u64, names: &[&str], positions: &[f64]) -> Vec<u8> {
    let mut c = Cdr::new();
    c.header(stamp_ns, "").u32(names.len() as u32);
    for n in names {
        c.string(n);
    }
    c.f64s(positions).f64s(&[]).f64s(&[]).done()
}

pub fn odometry_cdr(stamp_ns: u64, x: f64, y: f64, yaw: f64) -> Vec<u8> {
    let mut c = Cdr::new();
    c.header(stamp_ns, "odom")
        .string("base_link")
        .pose([x, y, 0.0], quat(0.0, 0.0, yaw));
    for _ in 0..36 + 6 + 36 {
        c.f64(0.0);
    }
    c.done()
}

pub fn pose_stamped_cdr(stamp_ns: u64, pose6: &[f64]) -> Vec<u8> {
    let mut c = Cdr::new();
    let q = quat(pose6[5], pose6[4], pose6[3]);
    c.header(stamp_ns, "world")
        .pose([pose6[0], pose6[1], pose6[2]], q)
        .done()
}

pub fn string_cdr(s: &str) -> Vec<u8> {
    Cdr::new().string(s).done()
}

// ---- ros2msg schema texts ----------------------------------------------------------------

const TIME: &str = "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n";
const HEADER: &str = "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n";
const SEP: &str =
    "================================================================================\n";

pub fn schema_text(name: &str) -> String {
    let header = format!("{SEP}{HEADER}{SEP}{TIME}");
    let geometry = format!(
        "{SEP}MSG: geometry_msgs/Pose\nPoint position\nQuaternion orientation\n{SEP}\
         MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n{SEP}\
         MSG: geometry_msgs/Quaternion\nfloat64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n"
    );
    match name {
        "sensor_msgs/msg/LaserScan" => format!(
            "std_msgs/Header header\nfloat32 angle_min\nfloat32 angle_max\n\
             float32 angle_increment\nfloat32 time_increment\nfloat32 scan_time\n\
             float32 range_min\nfloat32 range_max\nfloat32[] ranges\nfloat32[] intensities\n{header}"
        ),
        "sensor_msgs/msg/JointState" => format!(
            "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\n\
             float64[] effort\n{header}"
        ),
        "nav_msgs/msg/Odometry" => format!(
            "std_msgs/Header header\nstring child_frame_id\n\
             geometry_msgs/PoseWithCovariance pose\ngeometry_msgs/TwistWithCovariance twist\n\
             {header}{SEP}MSG: geometry_msgs/PoseWithCovariance\nPose pose\n\
             float64[36] covariance\n{SEP}MSG: geometry_msgs/TwistWithCovariance\nTwist twist\n\
             float64[36] covariance\n{SEP}MSG: geometry_msgs/Twist\nVector3 linear\n\
             Vector3 angular\n{SEP}MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\n\
             float64 z\n{geometry}"
        ),
        "geometry_msgs/msg/PoseStamped" => {
            format!("std_msgs/Header header\nPose pose\n{header}{geometry}")
        }
        _ => "string data\n".to_string(),
    }
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
        let t = scan_time_ns(pose, within);
        within += 1;
        let e = s["elevation"].as_f64().unwrap();
        let msg = |topic: &str, ty: &str, lt: u64, data: Vec<u8>| Msg {
            topic: topic.into(),
            msgtype: ty.into(),
            log_time: lt,
            data,
        };
        let positions: Vec<f64> = (0..spec.joint_names.len())
            .map(|i| if i == 0 { e } else { 0.0 })
            .collect();
        if spec.joints {
            let data = joint_state_cdr(t - 10_000_000, &spec.joint_names, &positions);
            out.push(msg(
                "/joint_states",
                "sensor_msgs/msg/JointState",
                t - 10_000_000,
                data,
            ));
        }
        for (i, topic) in spec.scan_topics.iter().enumerate() {
            let ty = if i == 0 {
                spec.scan_type
            } else {
                "sensor_msgs/msg/LaserScan"
            };
            let data = if ty == "sensor_msgs/msg/LaserScan" {
                scan_cdr(s, t)
            } else {
                string_cdr("not a scan")
            };
            out.push(msg(topic, ty, t, data));
        }
        if spec.odom {
            let o: Vec<f64> = s["odometry"]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_f64().unwrap())
                .collect();
            out.push(msg(
                "/odom",
                "nav_msgs/msg/Odometry",
                t,
                odometry_cdr(t, o[0], o[1], o[2]),
            ));
        }
        if spec.truth {
            let p: Vec<f64> = s["true_pose"]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_f64().unwrap())
                .collect();
            out.push(msg(
                "/ground_truth",
                "geometry_msgs/msg/PoseStamped",
                t,
                pose_stamped_cdr(t, &p),
            ));
        }
        if spec.joints {
            let data = joint_state_cdr(t + 10_000_000, &spec.joint_names, &positions);
            out.push(msg(
                "/joint_states",
                "sensor_msgs/msg/JointState",
                t + 10_000_000,
                data,
            ));
        }
    }
    out
}

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
