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
const BAD_SCAN_LINES: [(&str, &str, &str); 13] = [
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
        "nrays must be a positive integer, not 0",
    ),
    (
        "negative_nrays",
        r#"{"sequence": 1, "nrays": -181, "theta": [], "readings": []}"#,
        "nrays: must be a positive integer, not -181",
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
        "absurd_max_theta",
        r#"{"sequence": 1, "nrays": 3, "min_theta": 0, "max_theta": 1e308, "readings": [1, 2, 3]}"#,
        "max_theta is 1e308, not an angle within one turn (+-2 pi rad); angles are in radians",
    ),
    (
        "bearing_in_degrees",
        r#"{"sequence": 1, "nrays": 3, "theta": [-90, 0, 90], "readings": [1, 2, 3]}"#,
        "theta[0] is -90, not an angle within one turn",
    ),
    (
        "negative_sigma",
        r#"{"sequence": 1, "nrays": 3, "theta": [-1, 0, 1], "readings": [1, 2, 3], "readings_sigma": [0.01, -0.01, 0.01]}"#,
        "readings_sigma[1] is -0.01: a noise sigma must be >= 0 metres (or null)",
    ),
    (
        "absurd_nrays",
        r#"{"sequence": 1, "nrays": 1000000, "min_theta": -1, "max_theta": 1, "readings": [1, 2, 3]}"#,
        "nrays is 1000000, more than the limit of 100000 rays per scan",
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
    assert_eq!(
        err,
        format!("{}:5: nrays must be a positive integer, not 0", f.path())
    );
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
fn a_carmen_log_of_unread_laser_kinds_says_so() {
    let raw = "RAWLASER1 0 -1.5708 3.1416 0.0175 81.9 0.01 0 3 2 2 2 0 5.0 host 5.0\n";
    let log = TempFile::new("raw.log", format!("# log\n{raw}{raw}{raw}").as_bytes());
    for command in ["info", "match"] {
        let out = bin().args([command, log.path()]).output().unwrap();
        assert_eq!(
            one_line_failure(&out, command),
            format!(
                "{}:2: no scans: 3 RAWLASER1 lines skipped (the first here); levelscan reads \
                 FLASER and ROBOTLASER1 laser lines",
                log.path()
            )
        );
    }
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

// ---------------------------------------------------------------------------------------------
// Outputs: `-o` never destroys an input, a failed run leaves no half file, and every write
// error names the output.

/// A temporary directory that is removed, with everything in it, when dropped.
struct TempDir(PathBuf);

impl TempDir {
    fn new(name: &str) -> TempDir {
        // Tests run in parallel threads of one process: a counter keeps their names apart.
        static COUNT: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
        let k = COUNT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let path =
            std::env::temp_dir().join(format!("levelscan-out-{}-{k}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&path);
        std::fs::create_dir_all(&path).unwrap();
        TempDir(path)
    }

    fn file(&self, name: &str, bytes: &[u8]) -> String {
        let p = self.0.join(name);
        std::fs::write(&p, bytes).unwrap();
        self.path(name)
    }

    fn path(&self, name: &str) -> String {
        self.0.join(name).to_str().unwrap().to_string()
    }

    /// The names in the directory: no temporary file may be left behind.
    fn names(&self) -> Vec<String> {
        let mut names: Vec<String> = std::fs::read_dir(&self.0)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        names
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

const ROOM: &str = r#"{"wallheight": 3, "walls": [[[0,0],[6,0],[6,5],[0,5],[0,0]]], "poses": [[2,2,0.45,30,4,-3], [3,2.5,0.45,-60,-5,2]]}"#;

/// Simulated scans of ROOM, the input of the output tests.
fn simulated_scans() -> Vec<u8> {
    let d = TempDir::new("sim");
    let plan = d.file("room.wall", ROOM.as_bytes());
    let out = bin()
        .args(["simulate", &plan, "--rays", "61"])
        .output()
        .unwrap();
    assert!(out.status.success());
    out.stdout
}

/// 2D scans of ROOM at hinge elevation 0 (one per random pose), the input of `match` in the
/// output tests: `match` refuses raw scans at other elevations.
fn flat_scans() -> Vec<u8> {
    let d = TempDir::new("flat");
    let plan = d.file("room.wall", ROOM.as_bytes());
    let out = bin()
        .args([
            "simulate",
            &plan,
            "--rays",
            "61",
            "--elevations",
            "0",
            "--random",
            "6",
        ])
        .output()
        .unwrap();
    assert!(out.status.success());
    out.stdout
}

#[test]
fn an_output_that_is_an_input_is_refused_and_the_input_kept() {
    let d = TempDir::new("same");
    let scans = simulated_scans();
    let input = d.file("scans.jsonl", &scans);
    std::os::unix::fs::symlink(d.path("scans.jsonl"), d.path("link.jsonl")).unwrap();
    std::fs::hard_link(d.path("scans.jsonl"), d.path("hard.jsonl")).unwrap();
    let plan = d.file("room.wall", ROOM.as_bytes());
    let cases: [(&str, Vec<String>); 6] = [
        (
            "same path",
            vec!["level".into(), input.clone(), "-o".into(), input.clone()],
        ),
        (
            "symlink",
            vec![
                "level".into(),
                input.clone(),
                "-o".into(),
                d.path("link.jsonl"),
            ],
        ),
        (
            "hard link",
            vec![
                "match".into(),
                input.clone(),
                "-o".into(),
                d.path("hard.jsonl"),
            ],
        ),
        (
            "simulate",
            vec!["simulate".into(), plan.clone(), "-o".into(), plan.clone()],
        ),
        (
            "view",
            vec!["view".into(), input.clone(), "-o".into(), input.clone()],
        ),
        (
            "trajectory",
            vec![
                "match".into(),
                input.clone(),
                "-o".into(),
                d.path("m.jsonl"),
                "--trajectory".into(),
                d.path("m.jsonl"),
            ],
        ),
    ];
    for (case, args) in cases {
        let out = bin().args(&args).output().unwrap();
        let err = one_line_failure(&out, case);
        assert!(
            err.contains("the output is also an input of this run"),
            "{case}: {err}"
        );
    }
    assert_eq!(std::fs::read(&input).unwrap(), scans, "the input is intact");
    assert_eq!(std::fs::read_to_string(&plan).unwrap(), ROOM);
    assert_eq!(
        d.names(),
        ["hard.jsonl", "link.jsonl", "room.wall", "scans.jsonl"]
    );
}

#[test]
fn an_output_that_is_standard_input_or_output_redirected_to_an_input_is_refused() {
    let d = TempDir::new("redirect");
    let scans = simulated_scans();
    let input = d.file("scans.jsonl", &scans);
    // levelscan level -o scans.jsonl < scans.jsonl
    let out = bin()
        .args(["level", "-o", &input])
        .stdin(std::fs::File::open(&input).unwrap())
        .output()
        .unwrap();
    let err = one_line_failure(&out, "stdin");
    assert!(err.contains("(<stdin>)"), "{err}");
    // levelscan level scans.jsonl >> scans.jsonl
    let append = std::fs::OpenOptions::new()
        .append(true)
        .open(&input)
        .unwrap();
    let out = bin()
        .args(["level", &input])
        .stdout(append)
        .stderr(std::process::Stdio::piped())
        .output()
        .unwrap();
    let err = one_line_failure(&out, "stdout");
    assert_eq!(
        err,
        format!(
            "<stdout>: is the input file {input} (redirected with > or >>); write to another file"
        )
    );
    assert_eq!(std::fs::read(&input).unwrap(), scans);
    // Devices are no input's file: /dev/null as input and output is fine.
    let out = bin()
        .args(["info", "/dev/null"])
        .stdout(std::fs::File::create("/dev/null").unwrap())
        .output()
        .unwrap();
    assert!(out.status.success());
}

#[test]
fn a_failed_run_leaves_the_output_as_it_was() {
    let d = TempDir::new("failed");
    let scans = simulated_scans();
    let text = String::from_utf8(scans.clone()).unwrap();
    let mut lines: Vec<&str> = text.lines().collect();
    lines.insert(3, r#"{"garbage"#);
    let bad = d.file("bad.jsonl", (lines.join("\n") + "\n").as_bytes());
    let out_path = d.file("out.jsonl", b"old\n");
    let out = bin()
        .args(["level", &bad, "-o", &out_path])
        .output()
        .unwrap();
    let err = one_line_failure(&out, "bad line");
    assert!(err.starts_with(&format!("{bad}:4: ")), "{err}");
    assert_eq!(std::fs::read_to_string(&out_path).unwrap(), "old\n");
    // A new output is not created at all; no temporary file is left.
    let text = String::from_utf8(flat_scans()).unwrap();
    let mut lines: Vec<&str> = text.lines().collect();
    lines.insert(3, r#"{"garbage"#);
    let bad = d.file("bad2d.jsonl", (lines.join("\n") + "\n").as_bytes());
    let out = bin()
        .args(["match", &bad, "-o", &d.path("new.jsonl")])
        .output()
        .unwrap();
    let err = one_line_failure(&out, "match");
    assert!(err.starts_with(&format!("{bad}:4: ")), "{err}");
    assert_eq!(d.names(), ["bad.jsonl", "bad2d.jsonl", "out.jsonl"]);
    // To standard output, the records before the bad line are written (the contract).
    let out = bin().args(["match", &bad]).output().unwrap();
    assert!(!out.status.success());
    assert_eq!(
        out.stdout.iter().filter(|&&b| b == b'\n').count(),
        3,
        "the scans before line 4"
    );
}

#[test]
fn a_run_that_succeeds_replaces_the_output_whole() {
    let d = TempDir::new("ok");
    let input = d.file("scans.jsonl", &simulated_scans());
    let target = d.file("level.jsonl", b"old\n");
    let out = bin()
        .args(["level", &input, "-o", &target])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let to_stdout = bin().args(["level", &input]).output().unwrap();
    assert_eq!(std::fs::read(&target).unwrap(), to_stdout.stdout);
    // Written through a symbolic link, the link stays and its target gets the output.
    let other = d.file("other.jsonl", b"old\n");
    std::os::unix::fs::symlink(&other, d.path("link.jsonl")).unwrap();
    let out = bin()
        .args(["match", &target, "-o", &d.path("link.jsonl")])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        std::fs::symlink_metadata(d.path("link.jsonl"))
            .unwrap()
            .file_type()
            .is_symlink()
    );
    let matched = bin().args(["match", &target]).output().unwrap();
    assert_eq!(std::fs::read(&other).unwrap(), matched.stdout);
    assert_eq!(
        d.names(),
        ["level.jsonl", "link.jsonl", "other.jsonl", "scans.jsonl"]
    );
}

#[test]
fn a_full_disk_is_an_error_naming_the_output_never_a_panic() {
    if !std::path::Path::new("/dev/full").exists() {
        eprintln!("no /dev/full here: skipped");
        return;
    }
    let d = TempDir::new("full");
    let input = d.file("scans.jsonl", &simulated_scans());
    let flat = d.file("flat.jsonl", &flat_scans());
    let plan = d.file("room.wall", ROOM.as_bytes());
    let log = d.file(
        "real.log",
        b"FLASER 3 1 2 3 0 0 0 0 0 0 1.0 h 1\nFLASER 3 1 2 3 0.1 0 0 0.1 0 0 2.0 h 2\n",
    );
    let full = || {
        std::fs::OpenOptions::new()
            .write(true)
            .open("/dev/full")
            .unwrap()
    };
    let demo_dir = d.path("demo");
    let stdout_cases: [(&str, Vec<&str>); 8] = [
        ("simulate", vec!["simulate", &plan]),
        (
            "demo",
            vec!["demo", "--out", &demo_dir, "--accuracy-poses", "2"],
        ),
        ("level", vec!["level", &input]),
        ("match", vec!["match", &flat]),
        ("info", vec!["info", &input]),
        (
            "eval accuracy",
            vec![
                "eval",
                "accuracy",
                &plan,
                "--poses",
                "2",
                "--scans",
                "3",
                "--sigma",
                "0.01",
                "--estimator",
                "robust",
            ],
        ),
        ("eval real", vec!["eval", "real", &log]),
        ("view", vec!["view", &input, "-o", "-"]),
    ];
    for (case, args) in stdout_cases {
        let out = bin()
            .args(&args)
            .stdout(full())
            .stderr(std::process::Stdio::piped())
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr).to_string();
        assert!(
            !out.status.success() && !err.contains("panicked"),
            "{case}: {err}"
        );
        let last = err.lines().last().unwrap_or_default();
        assert_eq!(
            last, "<stdout>: cannot write: No space left on device (os error 28)",
            "{case}"
        );
    }
    for (case, args) in [
        ("simulate -o", vec!["simulate", &plan, "-o", "/dev/full"]),
        ("level -o", vec!["level", &input, "-o", "/dev/full"]),
        (
            "match --trajectory",
            vec![
                "match",
                &flat,
                "--trajectory",
                "/dev/full",
                "-o",
                "/dev/null",
            ],
        ),
    ] {
        let out = bin().args(&args).output().unwrap();
        let err = one_line_failure(&out, case);
        assert_eq!(
            err, "/dev/full: cannot write: No space left on device (os error 28)",
            "{case}"
        );
    }
}

// ---------------------------------------------------------------------------------------------
// Plans, CARMEN logs and sizes that used to get through.

#[test]
fn a_wall_of_coincident_points_is_refused_naming_it() {
    let d = TempDir::new("coincident");
    let plan = d.file(
        "room.wall",
        br#"{"wallheight": 3, "walls": [[[0,0],[10,0],[10,8],[0,8],[0,0]], [[5,5],[5,5],[5,5]]]}"#,
    );
    let want = format!(
        "{plan}:walls[1]: all 3 points are the same point [5, 5]; a wall needs two distinct points"
    );
    let out = bin()
        .args(["simulate", "--random", "3", &plan])
        .output()
        .unwrap();
    assert_eq!(one_line_failure(&out, "simulate"), want);
    let out = bin()
        .args(["eval", "accuracy", &plan, "--poses", "2"])
        .output()
        .unwrap();
    assert_eq!(one_line_failure(&out, "eval accuracy"), want);
}

#[test]
fn a_long_run_of_collinear_wall_pieces_is_simulated() {
    // One closed outline whose bottom side is 64,000 collinear pieces (it took 7-15 s).
    let d = TempDir::new("collinear");
    let n = 64_000;
    let mut points: Vec<String> = (0..=n)
        .map(|i| format!("[{}, 0]", 10.0 * i as f64 / n as f64))
        .collect();
    points.extend(["[10, 8]", "[0, 8]", "[0, 0]"].map(String::from));
    let text = format!(r#"{{"wallheight": 3, "walls": [[{}]]}}"#, points.join(", "));
    let plan = d.file("long.wall", text.as_bytes());
    let out = bin()
        .args(["simulate", "--random", "3", "--rays", "31", &plan])
        .output()
        .unwrap();
    assert_eq!(records(&out).len(), 9);
}

#[test]
fn carmen_counts_and_trailing_tokens_are_checked() {
    let d = TempDir::new("carmen");
    let good = "FLASER 3 1 2 3 0 0 0 0 0 0 1.5 host 1.5";
    let cases = [
        (
            "FLASER 2 1 2 3 0 0 0 0 0 0 1.5 host 1.5",
            "FLASER: the count says 2 readings but the line has 3 (before x y theta odom_x \
             odom_y odom_theta timestamp [host logger_timestamp])",
        ),
        (
            "FLASER 3 1 2 3 0 0 0 0 0 0 1.5 host 1.5 4",
            "FLASER: 3 more field(s) after the timestamp (field 11), from `host`; the line must \
             end with the timestamp, or with `host logger_timestamp`",
        ),
        (
            "FLASER 1000000 1 2 3",
            "FLASER: the number of readings is 1000000, more than the limit of 100000 rays per \
             scan",
        ),
    ];
    for (bad, want) in cases {
        let log = d.file("bad.log", format!("# log\n{good}\n{bad}\n").as_bytes());
        for command in ["info", "match"] {
            let out = bin().args([command, &log]).output().unwrap();
            assert_eq!(
                one_line_failure(&out, command),
                format!("{log}:3: {want}"),
                "{command}"
            );
        }
    }
}

#[test]
fn absurd_sizes_are_capped_and_real_scanners_pass() {
    let d = TempDir::new("sizes");
    let plan = d.file("room.wall", ROOM.as_bytes());
    // Hokuyo UTM-30LX, SICK TiM/LMS4000, RPLidar S2: 1081, 2000 and 3200 rays.
    for rays in ["1081", "2000", "3200"] {
        let scans = bin()
            .args(["simulate", &plan, "--rays", rays, "--fov", "270"])
            .output()
            .unwrap();
        assert!(scans.status.success());
        let out = run_with_stdin(&["level"], &scans.stdout);
        let poses = records(&out);
        assert_eq!(poses.len(), 2, "{rays} rays");
        assert!(poses.iter().all(|p| p["level"]["status"] == "ok"), "{rays}");
    }
    let out = bin()
        .args(["simulate", &plan, "--rays", "1000000"])
        .output()
        .unwrap();
    assert_eq!(
        one_line_failure(&out, "--rays"),
        "--rays 1000000 is more than 100000, the limit of rays per scan"
    );
    // A line of 33 MiB is refused before it is read whole.
    let mut long = b"{\"theta\": [0], \"readings\": [1], \"note\": \"".to_vec();
    long.resize(33 << 20, b'x');
    long.extend_from_slice(b"\"}\n");
    let f = d.file("long.jsonl", &long);
    let out = bin().args(["info", &f]).output().unwrap();
    assert_eq!(
        one_line_failure(&out, "long line"),
        format!(
            "{f}:1: the line is longer than 32 MiB, the limit for one scan (a scan of 100000 \
             rays with every field takes about 10 MB); is this a scan file?"
        )
    );
}
