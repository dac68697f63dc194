use super::record::KNOWN_FIELDS;
use super::*;
use crate::formats::{InputError, limits};
use crate::geometry::Pose;
use crate::scan::{Hit, Timestamp};
use proptest::prelude::*;
use std::io::Cursor;

/// A line as CSM's own tools write it: spaces, `null` readings and pose entries,
/// `readings_sigma` with nulls, `true_alpha`, `cov_alpha`, `timestamp`, no `sequence`,
/// no `elevation`.
const CSM_LINE: &str = r#"{ "nrays": 5, "min_theta": -1.5, "max_theta": 1.5, "theta": [ -1.5, -0.75, 0, 0.75, 1.5 ], "readings": [ 2.5, null, 3.25, 4, 1e-1 ], "valid": [ 1, 0, 1, 1, 1 ], "readings_sigma": [ 0.01, null, 0.01, 0.01, 0.01 ], "true_alpha": [ null, null, null, null, null ], "cov_alpha": [ null, null, null, null, null ], "odometry": [ 1.5, -2, 0.25 ], "estimate": [ null, null, null ], "true_pose": [ 1.5, -2.0, 0.3 ], "timestamp": [ 1190823410, 123456 ] }"#;

fn parse(text: &str) -> Scan {
    parse_scan_line(text).unwrap_or_else(|e| panic!("{e}"))
}

fn err(text: &str) -> String {
    parse_scan_line(text).unwrap_err()
}

#[test]
fn csm_log_line_is_read_as_it_is() {
    let s = parse(CSM_LINE);
    assert_eq!(s.nrays(), 5);
    assert_eq!(s.sequence, None);
    assert_eq!(s.elevation, None);
    assert_eq!(s.theta[3], 0.75);
    assert_eq!(
        s.readings,
        vec![Some(2.5), None, Some(3.25), Some(4.0), Some(0.1)]
    );
    assert_eq!(s.valid, vec![true, false, true, true, true]);
    assert_eq!(s.odometry, Some(Pose::planar(1.5, -2.0, 0.25)));
    assert_eq!(s.estimate, None, "a pose with null entries is absent");
    assert_eq!(s.true_pose, Some(Pose::planar(1.5, -2.0, 0.3)));
    assert_eq!(
        s.timestamp,
        Some(Timestamp {
            sec: 1190823410,
            usec: 123456
        })
    );
    assert_eq!(
        s.readings_sigma,
        Some(vec![Some(0.01), None, Some(0.01), Some(0.01), Some(0.01)])
    );
    let extra: Vec<&str> = s.extra.keys().map(String::as_str).collect();
    assert_eq!(
        extra,
        ["true_alpha", "cov_alpha"],
        "unknown fields kept in order"
    );
    assert_eq!(s.extra["true_alpha"][0], serde_json::Value::Null);
}

#[test]
fn csm_line_passes_through_with_unknown_fields() {
    let s = parse(CSM_LINE);
    let mut out = Vec::new();
    write_scan(&mut out, &s).unwrap();
    let text = String::from_utf8(out).unwrap();
    assert!(text.ends_with("}\n") && text.matches('\n').count() == 1);
    assert!(text.contains(r#""true_alpha":[null,null,null,null,null]"#));
    assert!(!text.contains("estimate"), "an unknown pose stays absent");
    assert_eq!(parse(&text), s);
}

#[test]
fn six_number_poses_and_multi_elevation_fields() {
    let s = parse(
        r#"{"sequence": 7, "nrays": 2, "elevation": -0.0872, "theta": [0, 0.1], "readings": [1, 2],
                "true_pose": [1, 2, 0.45, 0.5, 0.1, -0.2], "hinge_offset": [0.05, 0, 0.1], "hit": [1, 2]}"#,
    );
    assert_eq!(s.sequence, Some(7));
    assert_eq!(s.elevation, Some(-0.0872));
    assert_eq!(s.true_pose, Some(Pose::new(1.0, 2.0, 0.45, 0.5, 0.1, -0.2)));
    assert_eq!(s.hinge_offset, Some([0.05, 0.0, 0.1]));
    assert_eq!(s.hit, Some(vec![Hit::Wall, Hit::Floor]));
    assert_eq!(
        s.valid,
        vec![true, true],
        "valid defaults to: reading is a number"
    );
}

/// `ray_elevation` (a nodding hinge's per-ray elevation) is read, written back in the
/// same place and checked like the other per-ray fields.
#[test]
fn ray_elevation_round_trips_and_is_checked() {
    let line = r#"{"nrays": 3, "elevation": 0.1, "theta": [-1, 0, 1], "readings": [1, 2, 3], "ray_elevation": [0.05, 0.1, 0.15]}"#;
    let s = parse(line);
    assert_eq!(s.ray_elevation, Some(vec![0.05, 0.1, 0.15]));
    assert!(s.extra.is_empty(), "ray_elevation is a known field");
    let mut out = Vec::new();
    write_scan(&mut out, &s).unwrap();
    let text = String::from_utf8(out).unwrap();
    assert!(
        text.starts_with(r#"{"nrays":3,"elevation":0.1,"ray_elevation":[0.05,0.1,0.15],"theta""#),
        "{text}"
    );
    assert_eq!(parse(&text), s);
    let without = parse(r#"{"nrays": 1, "theta": [0], "readings": [1]}"#);
    assert_eq!(without.ray_elevation, None);
    let mut out = Vec::new();
    write_scan(&mut out, &without).unwrap();
    assert!(!String::from_utf8(out).unwrap().contains("ray_elevation"));

    let base = r#""nrays": 2, "theta": [0, 1], "readings": [1, 2]"#;
    let bad = |field: &str| err(&format!("{{{base}, \"ray_elevation\": {field}}}"));
    assert_eq!(bad("[0.1]"), "ray_elevation has 1 entries but nrays is 2");
    assert_eq!(
        bad("[0.1, 0.2, 0.3]"),
        "ray_elevation has 3 entries but nrays is 2"
    );
    let e = bad("[0.1, 7]");
    assert!(e.starts_with("ray_elevation[1] is 7, not an angle"), "{e}");
    let e = bad("[0.1, -1e300]");
    assert!(
        e.starts_with("ray_elevation[1] is -1e300, not an angle"),
        "{e}"
    );
    let e = bad("[null, 0.2]");
    assert!(e.starts_with("ray_elevation[0]"), "{e}");
    let e = bad(r#"[0.1, "x"]"#);
    assert!(e.starts_with("ray_elevation[1]"), "{e}");
    assert_eq!(
        parse(&format!("{{{base}, \"ray_elevation\": null}}")).ray_elevation,
        None
    );
}

#[test]
fn theta_absent_is_spread_from_min_to_max() {
    let s = parse(r#"{"nrays": 3, "min_theta": -1, "max_theta": 1, "readings": [1, null, 2]}"#);
    assert_eq!(s.theta, vec![-1.0, 0.0, 1.0]);
    assert_eq!(s.valid, vec![true, false, true]);
    assert_eq!(
        err(r#"{"nrays": 3, "readings": [1, null, 2]}"#),
        "theta is missing, and so are min_theta and max_theta"
    );
    assert_eq!(
        err(r#"{"nrays": 3, "min_theta": -1, "readings": [1, null, 2]}"#),
        "theta is missing, and so are min_theta and max_theta"
    );
}

#[test]
fn arrays_of_the_wrong_length_name_the_field() {
    let theta: Vec<String> = (0..181).map(|i| format!("{}", i as f64 * 0.01)).collect();
    let readings: Vec<&str> = vec!["1.0"; 180];
    let line = format!(
        r#"{{"nrays": 181, "theta": [{}], "readings": [{}]}}"#,
        theta.join(","),
        readings.join(",")
    );
    assert_eq!(err(&line), "readings has 180 entries but nrays is 181");
    assert_eq!(
        err(r#"{"nrays": 2, "theta": [0, 1], "readings": [1, 2], "valid": [1]}"#),
        "valid has 1 entries but nrays is 2"
    );
    assert_eq!(
        err(r#"{"nrays": 2, "theta": [0], "readings": [1, 2]}"#),
        "theta has 1 entries but nrays is 2"
    );
    assert_eq!(
        err(r#"{"nrays": 2, "theta": [0, 1], "readings": [1, 2], "hit": [1, 1, 1]}"#),
        "hit has 3 entries but nrays is 2"
    );
    assert_eq!(
        err(r#"{"nrays": 2, "theta": [0, 1], "readings": [1, 2], "readings_sigma": []}"#),
        "readings_sigma has 0 entries but nrays is 2"
    );
}

#[test]
fn non_positive_or_fractional_nrays_is_rejected() {
    assert_eq!(
        err(r#"{"nrays": 0, "theta": [], "readings": []}"#),
        "nrays must be a positive integer, not 0"
    );
    assert!(
        err(r#"{"nrays": -3, "theta": [], "readings": []}"#)
            .starts_with("nrays: must be a positive integer, not -3")
    );
    assert!(
        err(r#"{"nrays": 2.5, "theta": [0, 1], "readings": [1, 2]}"#)
            .starts_with("nrays: must be a positive integer, not 2.5")
    );
    assert!(
        err(r#"{"nrays": "2", "theta": [0, 1], "readings": [1, 2]}"#)
            .starts_with("nrays: invalid type: string \"2\", expected a positive integer")
    );
}

#[test]
fn nan_and_infinity_literals_get_a_hint() {
    for bad in ["NaN", "Infinity", "-Infinity", "nan"] {
        let e = err(&format!(
            r#"{{"nrays": 3, "theta": [0, 1, 2], "readings": [1, {bad}, 2]}}"#
        ));
        assert!(
            e.ends_with("; JSON has no NaN or Infinity: write null for no return"),
            "{bad}: {e}"
        );
    }
    // Other syntax errors get no such hint.
    let e = err(r#"{"nrays": 3, "theta": [0, 1, 2], "readings": [1, ?, 2]}"#);
    assert!(!e.contains("NaN"), "{e}");
}

#[test]
fn wrong_types_name_the_field_and_index() {
    let e = err(r#"{"nrays": 3, "theta": [0, 1, 2], "readings": [1, "far", 2]}"#);
    assert!(
        e.starts_with("readings[1]: invalid type: string \"far\", expected a number"),
        "{e}"
    );
    assert!(e.contains("(column "), "{e}");
    let e = err(r#"{"nrays": 3, "theta": [0, null, 2], "readings": [1, 1, 2]}"#);
    assert!(
        e.starts_with("theta[1]: invalid type: null, expected a number"),
        "{e}"
    );
    let e = err(r#"{"nrays": 2, "theta": [0, 1], "readings": [1, 2], "valid": [1, 2]}"#);
    assert!(e.starts_with("valid[1]: must be 0 or 1, not 2"), "{e}");
    let e = err(r#"{"nrays": 2, "theta": [0, 1], "readings": [1, 2], "hit": [0, 4]}"#);
    assert!(e.starts_with("hit[1]: must be 0, 1, 2 or 3, not 4"), "{e}");
    let e = err(r#"{"sequence": -1, "nrays": 1, "theta": [0], "readings": [1]}"#);
    assert!(
        e.starts_with("sequence: must be an integer >= 0, not -1"),
        "{e}"
    );
    let e = err(r#"{"nrays": 1, "theta": [0], "readings": [1], "odometry": [1, 2]}"#);
    assert!(e.starts_with("odometry: a pose has 6 numbers"), "{e}");
    let e = err(r#"{"nrays": 1, "theta": [0], "readings": [1], "elevation": "0.1"}"#);
    assert!(e.starts_with("elevation: invalid type: string"), "{e}");
    let e = err(r#"{"nrays": 1, "theta": [0], "readings": 5}"#);
    assert!(
        e.starts_with("readings: invalid type: integer `5`, expected an array"),
        "{e}"
    );
    let e = err(r#"{"nrays": 1, "theta": [0], "readings": [1], "hinge_offset": [1, 2]}"#);
    assert!(e.starts_with("hinge_offset: must be 3 numbers"), "{e}");
    let e = err(r#"{"nrays": 1, "theta": [0], "readings": [1], "timestamp": [1, 2, 3]}"#);
    assert!(e.starts_with("timestamp: must be [sec, usec]"), "{e}");
}

#[test]
fn malformed_json_and_duplicates_are_errors() {
    assert!(err(r#"{"nrays": 1, "theta": [0], "readings": [1]"#).starts_with("EOF while parsing"));
    assert!(err(r#"{"nrays": 1 "theta": [0]}"#).starts_with("expected `,` or `}`"));
    assert!(err("[1, 2]").starts_with("invalid type: sequence, expected a scan object"));
    assert!(
        err(r#"{"nrays": 1, "theta": [0], "readings": [1]} {}"#).starts_with("trailing characters")
    );
    assert!(
        err(r#"{"nrays": 1, "nrays": 1, "theta": [0], "readings": [1]}"#)
            .starts_with("duplicate field `nrays`")
    );
    assert!(err(r#"{"nrays": 1, "theta": [0]}"#).starts_with("missing field `readings`"));
}

#[test]
fn null_optional_fields_count_as_absent() {
    let s = parse(
        r#"{"sequence": null, "nrays": 1, "elevation": null, "theta": [0], "readings": [1],
                "odometry": null, "readings_sigma": null, "timestamp": null}"#,
    );
    assert_eq!(s.sequence, None);
    assert_eq!(s.elevation, None);
    assert_eq!(s.odometry, None);
    assert_eq!(s.readings_sigma, None);
}

fn reader_lines(input: &str) -> Vec<Result<(usize, Scan), InputError>> {
    ScanReader::new(Cursor::new(input.as_bytes()), "scans.jsonl").collect()
}

#[test]
fn reader_skips_blank_lines_and_reports_file_and_line() {
    let good = r#"{"sequence": 0, "nrays": 1, "theta": [0], "readings": [1]}"#;
    let input = format!(
        "{good}\n\n   \n{good}\r\n{{\"nrays\": 0, \"theta\": [], \"readings\": []}}\n{good}\n"
    );
    let items = reader_lines(&input);
    assert_eq!(items.len(), 3, "stops after the first error");
    assert_eq!(items[0].as_ref().unwrap().0, 1);
    assert_eq!(items[1].as_ref().unwrap().0, 4);
    assert_eq!(
        items[2].as_ref().unwrap_err().to_string(),
        "scans.jsonl:5: nrays must be a positive integer, not 0"
    );
}

#[test]
fn reader_reports_invalid_utf8_with_its_line() {
    let good = r#"{"nrays": 1, "theta": [0], "readings": [1]}"#;
    let mut bytes = format!("{good}\n").into_bytes();
    bytes.extend_from_slice(b"{\"nrays\": \xff}\n");
    let items: Vec<_> = ScanReader::new(Cursor::new(bytes), "x.jsonl").collect();
    assert_eq!(items.len(), 2);
    assert_eq!(
        items[1].as_ref().unwrap_err().to_string(),
        "x.jsonl:2: is not valid UTF-8 text"
    );
}

fn scan_text(n: usize) -> String {
    let mut text = String::new();
    for k in 0..n {
        let mut s = Scan::with_even_bearings(3, -1.0, 1.0);
        s.sequence = Some(k as u64 / 3);
        s.readings = vec![Some(k as f64), None, Some(0.5)];
        s.valid = vec![true, false, true];
        let mut line = Vec::new();
        write_scan(&mut line, &s).unwrap();
        text.push_str(std::str::from_utf8(&line).unwrap());
        if k % 7 == 0 {
            text.push('\n'); // blank lines shift the numbering
        }
    }
    text
}

#[test]
fn parallel_reader_matches_the_streaming_reader() {
    let text = scan_text(2500); // more than two batches
    let serial: Vec<_> = ScanReader::new(Cursor::new(text.as_bytes()), "a").collect();
    let parallel: Vec<_> = ParallelScanReader::new(Cursor::new(text.as_bytes()), "a").collect();
    assert_eq!(serial.len(), 2500);
    assert_eq!(serial, parallel);
}

#[test]
fn parallel_reader_stops_at_the_first_error_in_order() {
    let mut text = scan_text(1500);
    // Corrupt the line of scan 1200 and a later one: only the first is reported.
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let serial: Vec<_> = ScanReader::new(Cursor::new(text.as_bytes()), "a").collect();
    let (bad_line, _) = *serial[1200].as_ref().unwrap();
    lines[bad_line - 1] = r#"{"nrays": 1, "theta": [0], "readings": [1, 2]}"#.into();
    let (later, _) = *serial[1400].as_ref().unwrap();
    lines[later - 1] = "garbage".into();
    text = lines.join("\n");
    let items: Vec<_> = ParallelScanReader::new(Cursor::new(text.as_bytes()), "f").collect();
    assert_eq!(items.len(), 1201);
    assert!(items[..1200].iter().all(Result::is_ok));
    assert_eq!(
        items[1200].as_ref().unwrap_err().to_string(),
        format!("f:{bad_line}: readings has 2 entries but nrays is 1")
    );
}

#[test]
fn written_fields_come_in_the_stable_order() {
    let mut s = Scan::with_even_bearings(2, -0.5, 0.5);
    s.readings = vec![Some(1.0), None];
    s.valid = vec![true, false];
    s.sequence = Some(3);
    s.elevation = Some(0.1);
    s.odometry = Some(Pose::planar(1.0, 2.0, 0.5));
    s.true_pose = Some(Pose::new(1.0, 2.0, 0.45, 0.5, 0.1, 0.0));
    s.hit = Some(vec![Hit::Wall, Hit::Nothing]);
    s.extra.insert("zeta".into(), serde_json::json!(1));
    s.extra.insert("alpha".into(), serde_json::json!("a"));
    let mut out = Vec::new();
    write_scan(&mut out, &s).unwrap();
    assert_eq!(
        String::from_utf8(out).unwrap(),
        "{\"sequence\":3,\"nrays\":2,\"elevation\":0.1,\"theta\":[-0.5,0.5],\
         \"readings\":[1.0,null],\"valid\":[1,0],\"min_theta\":-0.5,\"max_theta\":0.5,\
         \"odometry\":[1.0,2.0,0.5],\"true_pose\":[1.0,2.0,0.45,0.5,0.1,0.0],\
         \"hit\":[1,0],\"zeta\":1,\"alpha\":\"a\"}\n"
    );
}

fn arb_f64() -> impl Strategy<Value = f64> {
    prop_oneof![
        -1e6f64..1e6,
        any::<f64>().prop_filter("finite", |v| v.is_finite()),
        Just(0.0),
        Just(-0.0),
    ]
}

/// Bearings and elevations: within one turn (`limits::MAX_ANGLE`).
fn arb_angle() -> impl Strategy<Value = f64> {
    let max = limits::MAX_ANGLE;
    prop_oneof![-max..=max, Just(0.0), Just(-0.0), Just(max), Just(-max)]
}

/// Positions: within `limits::MAX_POSITION`.
fn arb_position() -> impl Strategy<Value = f64> {
    let max = limits::MAX_POSITION;
    prop_oneof![-1e3f64..1e3, -max..=max, Just(0.0), Just(-0.0), Just(max)]
}

/// Noise sigmas: any finite number >= 0.
fn arb_sigma() -> impl Strategy<Value = f64> {
    arb_f64().prop_map(f64::abs)
}

fn arb_pose() -> impl Strategy<Value = Option<Pose>> {
    let xyz = || (arb_position(), arb_position(), arb_position());
    prop_oneof![
        Just(None),
        (arb_position(), arb_position(), arb_f64())
            .prop_map(|(x, y, t)| Some(Pose::planar(x, y, t))),
        (xyz(), (arb_f64(), arb_f64(), arb_f64()))
            .prop_map(|((x, y, z), (rz, ry, rx))| Some(Pose::new(x, y, z, rz, ry, rx))),
    ]
}

fn arb_scan() -> impl Strategy<Value = Scan> {
    (1usize..40).prop_flat_map(|n| {
        (
            (
                prop::option::of(any::<u64>()),
                prop::option::of(arb_angle()),
                prop::collection::vec(arb_angle(), n),
                prop::collection::vec(prop::option::of(arb_f64()), n),
                prop::collection::vec(any::<bool>(), n),
            ),
            (arb_pose(), arb_pose(), arb_pose()),
            (
                prop::option::of((any::<i32>(), 0i64..1_000_000)),
                prop::option::of(prop::collection::vec(prop::option::of(arb_sigma()), n)),
                prop::option::of(prop::array::uniform3(arb_position())),
                prop::option::of(prop::collection::vec(0u64..4, n)),
                prop::collection::vec(("[a-z_]{1,8}", any::<i32>()), 0..3),
            ),
            prop::option::of(prop::collection::vec(arb_angle(), n)),
        )
            .prop_map(
                |(
                    (sequence, elevation, theta, readings, valid),
                    (odometry, estimate, true_pose),
                    (stamp, sigma, hinge_offset, hit, extra),
                    ray_elevation,
                )| Scan {
                    sequence,
                    elevation,
                    ray_elevation,
                    theta,
                    readings,
                    valid,
                    odometry,
                    estimate,
                    true_pose,
                    timestamp: stamp.map(|(s, u)| Timestamp {
                        sec: s as i64,
                        usec: u,
                    }),
                    readings_sigma: sigma,
                    hinge_offset,
                    hit: hit.map(|h| h.into_iter().filter_map(Hit::from_code).collect()),
                    extra: extra
                        .into_iter()
                        .filter(|(k, _)| !KNOWN_FIELDS.contains(&k.as_str()))
                        .map(|(k, v)| (k, serde_json::json!(v)))
                        .collect(),
                },
            )
    })
}

proptest! {
    #[test]
    fn write_then_read_returns_the_same_scans(scans in prop::collection::vec(arb_scan(), 1..5)) {
        let mut out = Vec::new();
        for s in &scans {
            write_scan(&mut out, s).unwrap();
        }
        let back: Vec<Scan> = ScanReader::new(Cursor::new(&out), "rt")
            .map(|r| r.map(|(_, s)| s))
            .collect::<Result<_, _>>()
            .unwrap();
        prop_assert_eq!(back, scans);
    }

    /// CSM's tools write spaces everywhere and their own field order: the same scan laid
    /// out that way (pretty-printed onto one line, fields in reverse order) reads the same.
    #[test]
    fn spacing_and_field_order_do_not_matter(scan in arb_scan()) {
        let mut out = Vec::new();
        write_scan(&mut out, &scan).unwrap();
        let value: serde_json::Value = serde_json::from_slice(&out).unwrap();
        let serde_json::Value::Object(map) = value else { unreachable!() };
        let reversed: serde_json::Map<String, serde_json::Value> =
            map.into_iter().rev().collect();
        let text = serde_json::to_string_pretty(&reversed).unwrap().replace('\n', " ");
        let mut back = parse_scan_line(&text).unwrap();
        // Unknown fields keep the order they had in the line, now reversed.
        let extra: Vec<_> = back.extra.clone().into_iter().rev().collect();
        back.extra = extra.into_iter().collect();
        prop_assert_eq!(back, scan);
    }
}

/// `level`'s reader checks and counts `hit` but does not keep it (never read by `level`),
/// and reads everything else as the plain parser does; bad labels are still errors.
#[test]
fn skipping_hit_leaves_the_rest_alone() {
    let line = r#"{"sequence": 4, "elevation": 0.1, "theta": [0, 1], "readings": [2, null], "hit": [1, 0], "extra": [1]}"#;
    let skipped = parse_scan_line_with(line, true).unwrap();
    let mut plain = parse(&line.replace(r#""hit": [1, 0], "#, ""));
    assert_eq!(skipped, plain);
    plain.hit = Some(vec![Hit::Wall, Hit::Nothing]);
    assert_ne!(skipped, plain);
    let bad_code = line.replace("[1, 0]", "[1, 9]");
    assert!(
        parse_scan_line_with(&bad_code, true)
            .unwrap_err()
            .contains("hit[1]")
    );
    let short = line.replace("[1, 0]", "[1]");
    assert!(
        parse_scan_line_with(&short, true)
            .unwrap_err()
            .contains("hit has 1 entries but nrays is 2")
    );
    let twice = r#"{"theta": [0], "readings": [2], "hit": [1], "hit": [1]}"#;
    assert!(
        parse_scan_line_with(twice, true)
            .unwrap_err()
            .contains("duplicate field `hit`")
    );
}

#[test]
fn parallel_reader_skipping_hit_reads_the_same_scans_without_hits() {
    let lines = "{\"sequence\": 1, \"elevation\": 0, \"theta\": [0], \"readings\": [2], \"hit\": [1]}\n\n{\"sequence\": 2, \"elevation\": 0.1, \"theta\": [0], \"readings\": [3], \"hit\": [0]}\n";
    let plain: Vec<(usize, Scan)> = ParallelScanReader::new(Cursor::new(lines), "p")
        .collect::<Result<_, _>>()
        .unwrap();
    let skipped: Vec<(usize, Scan)> = ParallelScanReader::new(Cursor::new(lines), "p")
        .skipping_hit()
        .collect::<Result<_, _>>()
        .unwrap();
    assert_eq!(plain.len(), 2);
    assert_eq!(plain[1].0, 3);
    for ((la, a), (lb, b)) in plain.iter().zip(&skipped) {
        assert_eq!(la, lb);
        assert!(a.hit.is_some() && b.hit.is_none());
        assert_eq!(
            Scan {
                hit: None,
                ..a.clone()
            },
            *b
        );
    }
}
