//! Bad input end to end (the contract's "Bad input" list): for every case, the command stops
//! with a non-zero exit and ONE line on standard error, `FILE:LINE: what is wrong` (the JSON
//! path instead of the line for `.wall` files), and never panics.

mod cli_support;
use cli_support::*;

use std::io::Write;
use std::path::PathBuf;
use std::process::Output;

/// A temporary file that is removed when dropped.
struct TempFile(PathBuf);

impl TempFile {
    fn new(name: &str, bytes: &[u8]) -> TempFile {
        let path =
            std::env::temp_dir().join(format!("levelscan-bad-{}-{name}", std::process::id()));
        std::fs::write(&path, bytes).unwrap();
        TempFile(path)
    }

    fn path(&self) -> &str {
        self.0.to_str().unwrap()
    }
}

impl Drop for TempFile {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

/// Checks the contract's failure shape and returns the one stderr line.
fn one_line_failure(out: &Output, case: &str) -> String {
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(!out.status.success(), "{case}: should fail, stderr: {err}");
    assert_eq!(out.status.code(), Some(1), "{case}: exit code ({err})");
    assert!(!err.contains("panicked"), "{case}: {err}");
    assert_eq!(
        err.lines().count(),
        1,
        "{case}: one line expected, got {err:?}"
    );
    err.trim_end().to_string()
}

const GOOD: &str =
    r#"{"sequence": 0, "nrays": 3, "elevation": 0, "theta": [-1, 0, 1], "readings": [1, 2, 3]}"#;

/// Scan files whose third line is bad, and what the message must say after `FILE:3: `.
const BAD_SCAN_LINES: [(&str, &str, &str); 9] = [
    (
        "malformed",
        r#"{"sequence": 1, "nrays": 3, "theta": [-1, 0, 1], "readings": [1, 2, 3]"#,
        "EOF while parsing an object",
    ),
    (
        "wrong_type",
        r#"{"sequence": 1, "nrays": 3, "theta": [-1, 0, 1], "readings": [1, "two", 3]}"#,
        "readings[1]: invalid type: string \"two\", expected a number",
    ),
    (
        "different_lengths",
        r#"{"sequence": 1, "nrays": 3, "theta": [-1, 0, 1], "readings": [1, 2]}"#,
        "readings has 2 entries but nrays is 3",
    ),
    (
        "zero_nrays",
        r#"{"sequence": 1, "nrays": 0, "theta": [], "readings": []}"#,
        "nrays must be > 0",
    ),
    (
        "negative_nrays",
        r#"{"sequence": 1, "nrays": -181, "theta": [], "readings": []}"#,
        "nrays: must be an integer >= 0, not -181",
    ),
    (
        "valid_not_01",
        r#"{"sequence": 1, "nrays": 3, "theta": [-1, 0, 1], "readings": [1, 2, 3], "valid": [1, 1, 7]}"#,
        "valid[2]: must be 0 or 1, not 7",
    ),
    (
        "hit_length",
        r#"{"sequence": 1, "nrays": 3, "theta": [-1, 0, 1], "readings": [1, 2, 3], "hit": [1, 1]}"#,
        "hit has 2 entries but nrays is 3",
    ),
    (
        "hit_code",
        r#"{"sequence": 1, "nrays": 3, "theta": [-1, 0, 1], "readings": [1, 2, 3], "hit": [1, 9, 1]}"#,
        "hit[1]: must be 0, 1, 2 or 3, not 9",
    ),
    (
        "not_json",
        "FLASER? no: this is not a scan",
        "expected value",
    ),
];

#[test]
fn every_bad_scan_line_fails_with_file_and_line() {
    for (case, bad, want) in BAD_SCAN_LINES {
        let text = format!("{GOOD}\n\n{bad}\n{GOOD}\n");
        let f = TempFile::new(&format!("{case}.jsonl"), text.as_bytes());
        let out = bin().args(["info", f.path()]).output().unwrap();
        let err = one_line_failure(&out, case);
        let prefix = format!("{}:3: {want}", f.path());
        assert!(err.starts_with(&prefix), "{case}: {err}\n  want {prefix}");
        assert!(
            out.stdout.is_empty(),
            "{case}: info prints nothing on failure"
        );
    }
}

#[test]
fn bad_line_on_stdin_is_named_stdin() {
    let input = format!("{GOOD}\n{}\n", BAD_SCAN_LINES[2].1);
    let out = run_with_stdin(&["info"], input.as_bytes());
    let err = one_line_failure(&out, "stdin");
    assert_eq!(err, "<stdin>:2: readings has 2 entries but nrays is 3");
}

#[test]
fn bad_line_in_a_gzipped_file_keeps_its_line_number() {
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    for _ in 0..4 {
        writeln!(gz, "{GOOD}").unwrap();
    }
    writeln!(gz, "{}", BAD_SCAN_LINES[3].1).unwrap();
    let f = TempFile::new("bad.jsonl.gz", &gz.finish().unwrap());
    let out = bin().args(["info", f.path()]).output().unwrap();
    let err = one_line_failure(&out, "gzip");
    assert_eq!(err, format!("{}:5: nrays must be > 0", f.path()));
}

#[test]
fn invalid_utf8_is_reported_with_its_line() {
    let mut bytes = format!("{GOOD}\n").into_bytes();
    bytes.extend_from_slice(b"{\"nrays\": \"\xff\"}\n");
    let f = TempFile::new("latin1.jsonl", &bytes);
    let out = bin().args(["info", f.path()]).output().unwrap();
    let err = one_line_failure(&out, "utf8");
    assert_eq!(err, format!("{}:2: is not valid UTF-8 text", f.path()));
}

#[test]
fn bad_carmen_line_fails_with_file_and_line() {
    let log = "# CARMEN log\nFLASER 3 1 2 3 0 0 0 0 0 0 1.5 host 1.5\nFLASER 3 1 2 0 0 0 0 0 0\n";
    let f = TempFile::new("short.log", log.as_bytes());
    let out = bin().args(["info", f.path()]).output().unwrap();
    let err = one_line_failure(&out, "carmen");
    assert_eq!(
        err,
        format!(
            "{}:3: FLASER: the line ends before odom_theta (field 10)",
            f.path()
        )
    );
}

#[test]
fn missing_scan_file_fails_naming_it() {
    let out = bin()
        .args(["info", "/nonexistent/levelscan/scans.jsonl"])
        .output()
        .unwrap();
    let err = one_line_failure(&out, "missing file");
    assert!(
        err.starts_with("/nonexistent/levelscan/scans.jsonl: cannot open"),
        "{err}"
    );
}

/// Floor plans: the location is the JSON path, or the line for syntax errors.
#[test]
fn every_bad_plan_fails_with_file_and_json_path() {
    let cases = [
        (
            "one_point",
            r#"{"version": "w0.1", "wallheight": 3, "walls": [[[0,0],[4,0]], [[0,0],[0,4]], [[1,1]]], "poses": [[1,1,0.4,0,0,0]]}"#,
            "walls[2]: a wall needs at least 2 points, this has 1",
        ),
        (
            "zero_height",
            r#"{"version": "w0.1", "wallheight": 0, "walls": [[[0,0],[4,0]]], "poses": [[1,1,0.4,0,0,0]]}"#,
            "wallheight: must be a positive number of metres, not 0",
        ),
        (
            "negative_height",
            r#"{"version": "w0.1", "wallheight": -3, "walls": [[[0,0],[4,0]]], "poses": [[1,1,0.4,0,0,0]]}"#,
            "wallheight: must be a positive number of metres, not -3",
        ),
        (
            "bad_pose_entry",
            r#"{"wallheight": 3, "walls": [[[0,0],[4,0]]], "poses": [[1,1,0.4,0,0,0], [1,1,0.4,"ninety",0,0]]}"#,
            "poses[1][3]: expected a finite number, found a string",
        ),
        (
            "syntax",
            "{\n  \"wallheight\": 3,\n  \"walls\": [[[0,0],[4,0]]]\n  \"poses\": []\n}",
            "4: expected `,` or `}`",
        ),
    ];
    for (case, text, want) in cases {
        let f = TempFile::new(&format!("{case}.wall"), text.as_bytes());
        let out = bin().args(["simulate", f.path()]).output().unwrap();
        let err = one_line_failure(&out, case);
        let prefix = format!("{}:{want}", f.path());
        assert!(err.starts_with(&prefix), "{case}: {err}\n  want {prefix}");
    }
}

#[test]
fn missing_plan_file_fails_naming_it() {
    let out = bin()
        .args(["simulate", "/nonexistent/levelscan/room.wall"])
        .output()
        .unwrap();
    let err = one_line_failure(&out, "missing plan");
    assert!(
        err.starts_with("/nonexistent/levelscan/room.wall: cannot open"),
        "{err}"
    );
}

/// `level` needs every scan's hinge elevation; the check is the level command's own.
#[test]
fn missing_elevation_in_level_input_fails_with_file_and_line() {
    let text = format!(
        "{GOOD}\n{}\n",
        r#"{"sequence": 0, "nrays": 3, "theta": [-1, 0, 1], "readings": [1, 2, 3]}"#
    );
    let f = TempFile::new("no_elevation.jsonl", text.as_bytes());
    let out = bin().args(["level", f.path()]).output().unwrap();
    let err = one_line_failure(&out, "missing elevation");
    assert!(
        err.starts_with(&format!("{}:2: elevation", f.path())),
        "{err}"
    );
}

/// The scan-file errors are the reader's, so `level` reports them the same way as `info`.
#[test]
fn level_reports_bad_scan_lines_like_info() {
    for (case, bad, want) in BAD_SCAN_LINES {
        let text = format!("{GOOD}\n{bad}\n");
        let f = TempFile::new(&format!("level-{case}.jsonl"), text.as_bytes());
        let out = bin().args(["level", f.path()]).output().unwrap();
        let err = one_line_failure(&out, case);
        let prefix = format!("{}:2: {want}", f.path());
        assert!(err.starts_with(&prefix), "{case}: {err}\n  want {prefix}");
    }
}
