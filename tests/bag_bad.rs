//! Bad ROS bags end to end (CONTRACT.md "ROS bags": "A corrupt or truncated bag, a missing
//! topic or joint, or a message that does not decode is an input error naming the topic and
//! the message's log time"). No Python: the bags are made here, with foxglove's `mcap` crate
//! and this test's own CDR encoder (tests/bag_support), from `levelscan simulate` output, then
//! cut, corrupted or given the wrong content. Every case must exit 1 with exactly one line on
//! standard error naming the file (and the topic, joint or log time where there is one), and
//! never panic; `info` and `level` are both tried.

mod bag_support;
use bag_support::*;

use serde_json::Value;

/// A small run: 3 poses, 3 scans each, 61 rays.
fn scans() -> Vec<Value> {
    simulated_scans(3, 61, 5)
}

fn write(dir: &TempDir, name: &str, bytes: &[u8]) -> String {
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

/// Runs `info` and `level` (with `extra` flags) on `path`; both must fail the contract's way,
/// naming everything in `names`. Returns level's line. (`info` too: a summary of no scans
/// with exit 0 read as an empty bag.)
fn both_fail(path: &str, extra: &[&str], names: &[&str], case: &str) -> String {
    let mut line = String::new();
    for cmd in ["info", "level"] {
        let mut args = vec![cmd, path];
        args.extend_from_slice(extra);
        let out = levelscan(&args);
        line = one_line_failure(&out, &format!("{case} ({cmd})"));
        assert_names(&line, names, &format!("{case} ({cmd})"));
        assert!(
            out.stdout.is_empty() || cmd == "level",
            "{case}: info prints nothing on failure"
        );
    }
    line
}

fn good_bag() -> Vec<u8> {
    mcap_bytes(
        &bag_messages(&scans(), &BagSpec::default()),
        Layout::default(),
    )
}

#[test]
fn the_crafted_bag_itself_reads() {
    let dir = TempDir::new("bad-good");
    let path = write(&dir, "good.mcap", &good_bag());
    let info = ok_stdout(&["info", &path]);
    assert!(
        info.contains("/scan") && info.contains("/joint_states"),
        "{info}"
    );
    let poses = ok_records(&["level", &path]);
    assert_eq!(poses.len(), 3, "one record per pose");
    // Uncompressed chunks and no chunks at all read as well.
    for (name, layout) in [
        (
            "plain.mcap",
            Layout {
                compression: None,
                ..Layout::default()
            },
        ),
        (
            "lz4.mcap",
            Layout {
                compression: Some(mcap::Compression::Lz4),
                ..Layout::default()
            },
        ),
        (
            "unchunked.mcap",
            Layout {
                use_chunks: false,
                ..Layout::default()
            },
        ),
    ] {
        let p = write(
            &dir,
            name,
            &mcap_bytes(&bag_messages(&scans(), &BagSpec::default()), layout),
        );
        assert_eq!(ok_records(&["level", &p]), poses, "{name}");
    }
}

#[test]
fn truncated_mcap() {
    let dir = TempDir::new("bad-trunc");
    let good = good_bag();
    let n = good.len();
    for cut in [4, 8, 20, n / 3, n / 2, n - 30, n - 8, n - 1] {
        let path = write(&dir, &format!("cut{cut}.mcap"), &good[..cut]);
        both_fail(&path, &[], &[&path], &format!("cut at {cut} of {n} bytes"));
    }
}

/// The records area of the first chunk: (start, length) in the file.
fn first_chunk_records(bytes: &[u8]) -> (usize, usize) {
    let (_, _, body, _) = *top_level_records(bytes)
        .iter()
        .find(|r| r.1 == OP_CHUNK)
        .expect("a chunk");
    // Chunk: start time u64, end time u64, uncompressed size u64, crc u32, compression
    // (u32 length + bytes), records (u64 length + bytes): the MCAP spec's Chunk record.
    let clen = u32::from_le_bytes(bytes[body + 28..body + 32].try_into().unwrap()) as usize;
    let at = body + 32 + clen;
    let len = u64::from_le_bytes(bytes[at..at + 8].try_into().unwrap()) as usize;
    (at + 8, len)
}

#[test]
fn corrupt_zstd_chunk() {
    let dir = TempDir::new("bad-zstd");
    let good = good_bag();
    let (start, len) = first_chunk_records(&good);
    assert!(len > 64, "a compressed chunk of some size");
    for (case, at) in [
        ("middle", start + len / 2),
        ("start", start + 4),
        ("end", start + len - 3),
    ] {
        let mut bad = good.clone();
        for b in &mut bad[at..at + 3] {
            *b ^= 0x5a;
        }
        let path = write(&dir, &format!("zstd-{case}.mcap"), &bad);
        both_fail(
            &path,
            &[],
            &[&path],
            &format!("zstd chunk corrupt at its {case}"),
        );
    }
    // An uncompressed chunk whose CRC no longer matches: corrupt, not silently read.
    let plain = mcap_bytes(
        &bag_messages(&scans(), &BagSpec::default()),
        Layout {
            compression: None,
            ..Layout::default()
        },
    );
    let (start, len) = first_chunk_records(&plain);
    let mut bad = plain.clone();
    bad[start + len / 2] ^= 0x01;
    let path = write(&dir, "crc.mcap", &bad);
    both_fail(&path, &[], &[&path], "chunk CRC mismatch");
}

#[test]
fn wrong_schema_on_the_named_topic() {
    let dir = TempDir::new("bad-schema");
    let spec = BagSpec {
        scan_type: "std_msgs/msg/String",
        ..BagSpec::default()
    };
    let path = write(
        &dir,
        "string.mcap",
        &mcap_bytes(&bag_messages(&scans(), &spec), Layout::default()),
    );
    let line = both_fail(
        &path,
        &["--scan-topic", "/scan"],
        &[&path, "/scan"],
        "String on /scan",
    );
    assert!(line.contains("String"), "says what the topic holds: {line}");
    // Not named: there is no LaserScan topic at all.
    both_fail(&path, &[], &[&path, "LaserScan"], "no LaserScan topic");
}

#[test]
fn a_laser_scan_that_does_not_decode_names_its_log_time() {
    let dir = TempDir::new("bad-decode");
    let mut msgs = bag_messages(&scans(), &BagSpec::default());
    // The second scan (pose 0, 1000.1 s): cut inside its ranges.
    let i = msgs
        .iter()
        .enumerate()
        .filter(|(_, m)| m.topic == "/scan")
        .nth(1)
        .unwrap()
        .0;
    assert_eq!(msgs[i].log_time, scan_time_ns(0, 1));
    msgs[i].data.truncate(60);
    let path = write(&dir, "short.mcap", &mcap_bytes(&msgs, Layout::default()));
    let line = both_fail(&path, &[], &[&path, "/scan"], "LaserScan cut short");
    assert!(
        line.contains("1000.1") || line.contains("1000100000000"),
        "the message's log time (1000.1 s): {line}"
    );
}

#[test]
fn missing_hinge_joint() {
    let dir = TempDir::new("bad-joint");
    let s = scans();
    let two = BagSpec {
        joint_names: vec!["wheel_left", "wheel_right"],
        ..BagSpec::default()
    };
    let path = write(
        &dir,
        "wheels.mcap",
        &mcap_bytes(&bag_messages(&s, &two), Layout::default()),
    );
    let out = levelscan(&["level", &path]);
    let line = one_line_failure(&out, "two joints, none named");
    assert_names(
        &line,
        &[&path, "/joint_states", "wheel_left", "wheel_right"],
        "two joints, none named",
    );
    let out = levelscan(&["level", &path, "--hinge-joint", "hinge"]);
    let line = one_line_failure(&out, "named joint absent");
    assert_names(
        &line,
        &[&path, "/joint_states", "hinge"],
        "named joint absent",
    );
    let none = BagSpec {
        joints: false,
        ..BagSpec::default()
    };
    let path = write(
        &dir,
        "nojoints.mcap",
        &mcap_bytes(&bag_messages(&s, &none), Layout::default()),
    );
    let line = one_line_failure(&levelscan(&["level", &path]), "no joint topic");
    assert_names(&line, &[&path, "/joint_states"], "no joint topic");
    let out = levelscan(&["level", &path, "--joint-topic", "/tilt"]);
    let line = one_line_failure(&out, "named joint topic absent");
    assert_names(&line, &[&path, "/tilt"], "named joint topic absent");
}

#[test]
fn two_laser_scan_topics_and_none_named() {
    let dir = TempDir::new("bad-two");
    let spec = BagSpec {
        scan_topics: vec!["/scan_front", "/scan_tilt"],
        ..BagSpec::default()
    };
    let path = write(
        &dir,
        "two.mcap",
        &mcap_bytes(&bag_messages(&scans(), &spec), Layout::default()),
    );
    both_fail(
        &path,
        &[],
        &[&path, "/scan_front", "/scan_tilt", "--scan-topic"],
        "two LaserScan topics",
    );
    // Naming one resolves it.
    assert_eq!(
        ok_records(&["level", &path, "--scan-topic", "/scan_tilt"]).len(),
        3
    );
}

#[test]
fn unknown_scan_topic() {
    let dir = TempDir::new("bad-topic");
    let path = write(&dir, "good.mcap", &good_bag());
    let line = both_fail(
        &path,
        &["--scan-topic", "/nope"],
        &[&path, "/nope"],
        "unknown --scan-topic",
    );
    assert!(
        line.contains("/scan"),
        "lists the LaserScan topics there are: {line}"
    );
}

#[test]
fn empty_bag() {
    let dir = TempDir::new("bad-empty");
    let path = write(&dir, "empty.mcap", &mcap_bytes(&[], Layout::default()));
    let line = one_line_failure(&levelscan(&["level", &path]), "empty bag");
    assert_names(&line, &[&path], "empty bag");
}

#[test]
fn rosbag2_with_sqlite3_storage_is_refused_clearly() {
    let dir = TempDir::new("bad-sqlite");
    let bag = dir.0.join("bag");
    std::fs::create_dir(&bag).unwrap();
    std::fs::write(
        bag.join("metadata.yaml"),
        "rosbag2_bagfile_information:\n  version: 5\n  storage_identifier: sqlite3\n  \
         relative_file_paths:\n    - bag_0.db3\n  message_count: 0\n",
    )
    .unwrap();
    let mut db = b"SQLite format 3\0".to_vec();
    db.resize(4096, 0);
    std::fs::write(bag.join("bag_0.db3"), &db).unwrap();
    let path = bag.to_str().unwrap();
    both_fail(path, &[], &[path, "sqlite3"], "sqlite3 storage");
    // The .db3 file given on its own is refused the same way.
    let db3 = bag.join("bag_0.db3");
    let db3 = db3.to_str().unwrap();
    both_fail(db3, &[], &[db3, "sqlite3"], "a .db3 file");
}

#[test]
fn truncated_ros1_bag() {
    let dir = TempDir::new("bad-ros1");
    // The version line, then a bag header record cut short: its header length says 100
    // bytes follow, and 6 do.
    let mut bytes = b"#ROSBAG V2.0\n".to_vec();
    bytes.extend_from_slice(&100u32.to_le_bytes());
    bytes.extend_from_slice(b"\x05\x00\x00\x00op");
    for (name, b) in [
        ("version-only.bag", &bytes[..13]),
        ("header-cut.bag", &bytes[..]),
    ] {
        let path = write(&dir, name, b);
        both_fail(&path, &[], &[&path], name);
    }
}

/// What the JSON Lines reader refuses (`formats::limits`: `odometry: x is 1e12 m, beyond the
/// limit of +-1e7 m`) a bag must not slip past it: the scan would go on to `match`, which then
/// refuses `level`'s output instead.
#[test]
fn odometry_beyond_the_limits_is_refused() {
    let dir = TempDir::new("bad-limits");
    let mut msgs = bag_messages(&scans(), &BagSpec::default());
    for m in msgs.iter_mut().filter(|m| m.topic == "/odom") {
        m.data = odometry_cdr(m.log_time, 1e12, 0.0, 0.0);
    }
    let path = write(&dir, "far.mcap", &mcap_bytes(&msgs, Layout::default()));
    let line = one_line_failure(&levelscan(&["level", &path]), "odometry at 1e12 m");
    assert_names(&line, &[&path, "/odom"], "odometry at 1e12 m");
}

/// A bad scan late in a bag: the scans handed out before its error are numbered 1, 2, ...
/// without a gap, the error comes once and last, and names the topic. Scans still held for
/// stamp ordering (a window of 64) when the error is met are not handed out; at scan 140 the
/// good ones span several of the reading thread's batches.
#[test]
fn scans_before_a_bad_one_come_in_order_then_its_error_once() {
    use levelscan::formats::bag::{Bag, BagOptions, BagScans};
    let dir = TempDir::new("bad-late");
    let mut msgs = bag_messages(&simulated_scans(50, 61, 5), &BagSpec::default());
    let bad = 140;
    let i = msgs
        .iter()
        .enumerate()
        .filter(|(_, m)| m.topic == "/scan")
        .nth(bad - 1)
        .unwrap()
        .0;
    msgs[i].data.truncate(60);
    let path = write(&dir, "late.mcap", &mcap_bytes(&msgs, Layout::default()));
    let bag = Bag::detect(std::path::Path::new(&path)).unwrap().unwrap();
    let (scans, _) = BagScans::open(bag, &BagOptions::default()).unwrap();
    let items: Vec<_> = scans.collect();
    let numbers: Vec<usize> = items
        .iter()
        .map_while(|r| r.as_ref().ok().map(|(n, _)| *n))
        .collect();
    let good = numbers.len();
    assert!(good > 64 && good < bad, "{good} scans before the error");
    assert_eq!(numbers, (1..=good).collect::<Vec<_>>(), "in order, no gap");
    assert_eq!(
        items.len(),
        good + 1,
        "then one error, and nothing after it"
    );
    let e = items[good].as_ref().unwrap_err().to_string();
    assert!(e.contains("/scan"), "names the topic: {e}");
}
