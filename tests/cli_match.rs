//! End-to-end runs of `levelscan match` (the binary).

mod cli_support;
mod matching_support;
use cli_support::*;
use levelscan::geometry::Pose2;

use serde_json::Value;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Output;

fn plan(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("examples/plans/{name}.wall"))
}

/// A temporary file that is removed when dropped.
struct TempFile(PathBuf);

impl TempFile {
    fn new(name: &str, text: &[u8]) -> TempFile {
        let path =
            std::env::temp_dir().join(format!("levelscan-match-{}-{name}", std::process::id()));
        std::fs::File::create(&path)
            .unwrap()
            .write_all(text)
            .unwrap();
        TempFile(path)
    }
}

impl Drop for TempFile {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

fn pose3(v: &Value) -> [f64; 3] {
    let a = v.as_array().unwrap();
    let f = |i: usize| a[i].as_f64().unwrap();
    if a.len() == 6 {
        [f(0), f(1), f(3)]
    } else {
        [f(0), f(1), f(2)]
    }
}

/// Level 2D scans of the two-room plan's first poses, with odometry off by 2 cm / 1 degree.
fn simulated_level_scans(poses: usize) -> Vec<u8> {
    let out = bin()
        .args(["simulate", plan("two_rooms").to_str().unwrap()])
        .args(["--flat", "--elevations", "0", "--seed", "3"])
        .args(["--odo-trans", "0", "--odo-trans-min", "0.02"])
        .args(["--odo-rot", "0", "--odo-rot-min", "1"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    let mut kept = String::new();
    for line in text.lines().take(poses) {
        kept.push_str(line);
        kept.push('\n');
    }
    kept.into_bytes()
}

fn run_match(args: &[&str], stdin: &[u8]) -> Output {
    let args: Vec<&str> = std::iter::once("match")
        .chain(args.iter().copied())
        .collect();
    run_with_stdin(&args, stdin)
}

#[test]
fn simulated_run_is_matched_close_to_the_truth_in_both_modes() {
    let input = simulated_level_scans(40);
    for mode in ["pairwise", "metascan"] {
        for algo in ["plicp", "icp"] {
            let out = run_match(&["--mode", mode, "--algo", algo], &input);
            let recs = records(&out);
            assert_eq!(recs.len(), 40, "{mode} {algo}: one record per input record");
            // The first estimate is the first odometry.
            assert_eq!(pose3(&recs[0]["estimate"]), pose3(&recs[0]["odometry"]));
            // Each step's error: point-to-line within 1.5 cm (metascan steps also take up the
            // map's correction of earlier drift); point-to-point (the paper's baseline, biased
            // by sampling) within three.
            let tol = if algo == "plicp" { 0.015 } else { 0.03 };
            for w in recs.windows(2) {
                assert_eq!(
                    w[1]["match"]["status"], "ok",
                    "{mode} {algo}: {}",
                    w[1]["match"]
                );
                let step = |key: &str| {
                    let (a, b) = (pose3(&w[0][key]), pose3(&w[1][key]));
                    let (s, c) = a[2].sin_cos();
                    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
                    (c * dx + s * dy, -s * dx + c * dy)
                };
                let (e, t) = (step("estimate"), step("true_pose"));
                let err = (e.0 - t.0).hypot(e.1 - t.1);
                assert!(
                    err < tol,
                    "{mode} {algo}: step off by {err} m: {}",
                    w[1]["match"]
                );
                // match.covariance: 9 numbers, symmetric, positive on the diagonal; its x, y sigmas
                // are millimetres, below the step tolerance.
                let c = floats(&w[1]["match"]["covariance"]);
                assert_eq!(c.len(), 9);
                assert!(c[1] == c[3] && c[2] == c[6] && c[5] == c[7], "{c:?}");
                assert!(c[0] > 0.0 && c[4] > 0.0 && c[8] > 0.0, "{c:?}");
                assert!(
                    c[0].sqrt() < tol && c[4].sqrt() < tol,
                    "{mode} {algo}: {c:?}"
                );
            }
            assert_eq!(
                recs[0]["match"]["covariance"],
                serde_json::json!([0.0f64; 9].to_vec())
            );
        }
    }
}

#[test]
fn a_csm_log_line_is_read_as_it_is() {
    // CSM's own layout: spaces, null estimate entries, readings_sigma, true_alpha; two copies of
    // one scan, so the match is the identity. Unknown fields pass through.
    let n = 91;
    let theta: Vec<String> = (0..n)
        .map(|i| format!("{}", -1.5 + 3.0 * i as f64 / (n - 1) as f64))
        .collect();
    let readings: Vec<String> = (0..n)
        .map(|i| {
            let a = -1.5 + 3.0 * i as f64 / (n - 1) as f64;
            // A 2 m x 3 m box around the scanner: distance to the nearest wall along the ray.
            let (c, s) = (a.cos(), a.sin());
            let rx = if c > 1e-9 { 2.0 / c } else { f64::INFINITY };
            let ry = if s.abs() > 1e-9 {
                3.0 / s.abs()
            } else {
                f64::INFINITY
            };
            format!("{}", rx.min(ry))
        })
        .collect();
    let sigma = vec!["0.01"; n].join(", ");
    let line = format!(
        "{{ \"nrays\": {n}, \"min_theta\": -1.5, \"max_theta\": 1.5, \"theta\": [ {} ], \
         \"readings\": [ {} ], \"readings_sigma\": [ {sigma} ], \"valid\": [ {} ], \
         \"odometry\": [ 1.0, 2.0, 0.5 ], \"estimate\": [ null, null, null ], \
         \"true_alpha\": [ {} ], \"timestamp\": [ 1234, 500000 ] }}\n",
        theta.join(", "),
        readings.join(", "),
        vec!["1"; n].join(", "),
        vec!["0"; n].join(", "),
    );
    let input = format!("{line}{line}");
    let traj = TempFile::new("traj.tum", b"");
    let out = run_match(
        &["--trajectory", traj.0.to_str().unwrap()],
        input.as_bytes(),
    );
    let recs = records(&out);
    assert_eq!(recs.len(), 2);
    for r in &recs {
        let e = pose3(&r["estimate"]);
        assert!(
            (e[0] - 1.0).abs() < 1e-6 && (e[1] - 2.0).abs() < 1e-6 && (e[2] - 0.5).abs() < 1e-6
        );
        assert!(r["true_alpha"].is_array(), "unknown fields are kept");
    }
    assert_eq!(recs[1]["match"]["status"], "ok", "{}", recs[1]["match"]);
    // TUM: timestamp x y z qx qy qz qw, the time from `timestamp`.
    let tum = std::fs::read_to_string(&traj.0).unwrap();
    let rows: Vec<Vec<f64>> = tum
        .lines()
        .map(|l| l.split(' ').map(|v| v.parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len(), 2);
    assert_eq!(rows[0].len(), 8);
    assert!((rows[0][0] - 1234.5).abs() < 1e-9);
    assert!((rows[0][6] - 0.25f64.sin()).abs() < 1e-9 && (rows[0][7] - 0.25f64.cos()).abs() < 1e-9);
}

#[test]
fn carmen_flaser_and_robotlaser_lines_are_read() {
    // The same 180-beam scan of a 4 m x 6 m box, twice as FLASER (pose x y theta, odometry,
    // timestamp, host, logger time) and once as ROBOTLASER1, with comments and other messages
    // between.
    let ranges: Vec<String> = (0..180)
        .map(|i| {
            let a = -std::f64::consts::FRAC_PI_2 + std::f64::consts::PI * i as f64 / 180.0;
            let (c, s) = (a.cos(), a.sin());
            let rx = if c > 1e-9 { 2.0 / c } else { f64::INFINITY };
            let ry = if s.abs() > 1e-9 {
                3.0 / s.abs()
            } else {
                f64::INFINITY
            };
            format!("{:.3}", rx.min(ry).min(81.9))
        })
        .collect();
    let r = ranges.join(" ");
    let log = format!(
        "# CARMEN log\nPARAM robot_front_laser_max 50.0 nohost 0\n\
         FLASER 180 {r} 1.0 2.0 0.5 1.0 2.0 0.5 100.25 nohost 100.25\n\
         ODOM 1.0 2.0 0.5 0 0 0 100.3 nohost 100.3\n\
         FLASER 180 {r} 1.0 2.0 0.5 1.01 2.0 0.5 100.5 nohost 100.5\n\
         ROBOTLASER1 0 -1.5707963 3.1241393 0.0174533 50.0 0.01 0 180 {r} 0 \
         1.0 2.0 0.5 1.0 2.0 0.5 0 0 0.3 0.3 0 100.75 nohost 100.75\n"
    );
    let recs = records(&run_match(&[], log.as_bytes()));
    assert_eq!(recs.len(), 3);
    for r in &recs[1..] {
        assert_eq!(r["match"]["status"], "ok", "{}", r["match"]);
        let e = pose3(&r["estimate"]);
        // Identical scans: the match says no motion, whatever the odometry claims.
        assert!(
            (e[0] - 1.0).abs() < 1e-3 && (e[1] - 2.0).abs() < 1e-3,
            "{e:?}"
        );
    }

    // --max-range is the scanner's maximum range, as in `info`: given, a FLASER reading at or
    // beyond it is no return in the records written, not only left out of the match; absent,
    // the log's PARAM (50 m) decides.
    let valid = |r: &Value| {
        r["valid"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|v| **v == 1)
            .count()
    };
    let below = |m: f64| {
        ranges
            .iter()
            .filter(|r| r.parse::<f64>().unwrap() < m)
            .count()
    };
    assert_eq!(valid(&recs[0]), below(50.0));
    let short = records(&run_match(&["--max-range", "3.2"], log.as_bytes()));
    assert!(below(3.2) < below(50.0));
    assert_eq!(valid(&short[0]), below(3.2));
    assert_eq!(valid(&short[1]), below(3.2));
}

#[test]
fn a_record_without_valid_rays_falls_back_and_is_still_written() {
    let input = simulated_level_scans(3);
    let text = String::from_utf8(input).unwrap();
    let mut lines: Vec<Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let n = lines[1]["nrays"].as_u64().unwrap() as usize;
    lines[1]["valid"] = Value::Array(vec![Value::from(0); n]);
    let input: String = lines.iter().map(|v| format!("{v}\n")).collect();
    let recs = records(&run_match(&["--mode", "metascan"], input.as_bytes()));
    assert_eq!(recs.len(), 3);
    assert_eq!(recs[1]["match"]["status"], "fallback");
    assert_eq!(recs[1]["match"]["reason"], "no_valid_rays");
    assert_eq!(recs[2]["match"]["status"], "ok");
}

#[test]
fn a_bad_line_is_reported_with_file_and_line() {
    let input = simulated_level_scans(2);
    let mut text = String::from_utf8(input).unwrap();
    text.push_str("{\"nrays\": 2, \"readings\": [1.0]}\n");
    let file = TempFile::new("bad.jsonl", text.as_bytes());
    let out = bin().arg("match").arg(&file.0).output().unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.starts_with(&format!("{}:3:", file.0.display())),
        "message: {err}"
    );
}

#[test]
fn raw_multi_elevation_scans_are_refused_until_leveled() {
    // The user forgot `level`: scans of each pose at -5, 0 and 5 degrees.
    let raw = bin()
        .args(["simulate", plan("office").to_str().unwrap(), "--scans", "3"])
        .output()
        .unwrap();
    assert_ran(&raw);
    let out = run_with_stdin(&["match"], &raw.stdout);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(
        err.starts_with(
            "<stdin>:1: a raw scan at hinge elevation -5.0 deg; match takes 2D scans (level them \
             first"
        ),
        "{err}"
    );
    // Level's output of the same scans, and scans taken level (elevation 0), are matched.
    let leveled = run_with_stdin(&["level"], &raw.stdout);
    assert_ran(&leveled);
    assert!(!records(&run_with_stdin(&["match"], &leveled.stdout)).is_empty());
    assert_eq!(
        records(&run_with_stdin(&["match"], &simulated_level_scans(3))).len(),
        3
    );
}

#[test]
fn a_missing_file_is_an_error_not_a_panic() {
    let out = bin()
        .args(["match", "/nonexistent/scans.jsonl"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("/nonexistent/scans.jsonl"), "{err}");
    assert!(!err.contains("panicked"));
}

/// `levelscan match FILE FLAG=VALUE` fails, naming the flag, without a panic.
fn assert_refused_by_name(file: &Path, flag: &str, value: &str) {
    let out = bin()
        .arg("match")
        .arg(file)
        .arg(format!("{flag}={value}"))
        .output()
        .unwrap();
    assert!(!out.status.success(), "{flag} {value} was taken");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains(flag) && !err.contains("panicked"), "{err}");
}

#[test]
fn a_bad_covariance_or_search_flag_is_named() {
    let file = TempFile::new("cov.jsonl", &simulated_level_scans(2));
    for (flag, value) in [
        ("--cov-sampling", "-0.1"),
        ("--cov-sampling", "NaN"),
        ("--cov-sampling", "1e200"),
        ("--cov-inflation", "0"),
        ("--cov-inflation", "1e300"),
        ("--cov-knee", "1e-300"),
        // The coarse search's table: a huge window ran out of memory or overflowed.
        ("--window-xy", "1e300"),
        ("--window-theta", "1e300"),
    ] {
        assert_refused_by_name(&file.0, flag, value);
    }
    // 0 is allowed: the residuals alone, as before the sampling error.
    let out = bin()
        .arg("match")
        .arg(&file.0)
        .args(["--cov-sampling", "0"])
        .output()
        .unwrap();
    assert_ran(&out);
}

#[test]
fn help_shows_every_default() {
    let out = bin().args(["match", "--help"]).output().unwrap();
    let help = String::from_utf8_lossy(&out.stdout);
    // One block per option, from its flag line to the next flag line.
    let mut blocks: Vec<String> = Vec::new();
    for line in help.lines() {
        let indent = line.len() - line.trim_start().len();
        if line.trim_start().starts_with('-') && indent <= 6 {
            blocks.push(String::new());
        }
        if let Some(b) = blocks.last_mut() {
            b.push_str(line);
            b.push('\n');
        }
    }
    let without_default = [
        "--trajectory",
        "--reference-trajectory",
        "--output",
        "--help",
        "--version",
        // Bag topics default to what the bag holds.
        "--scan-topic",
        "--hinge-joint",
        "--odom-topic",
        "--truth-topic",
        // Output format: from the -o file name.
        "--format",
        // The rays' timing: the scans' own unless given.
        "--time-increment",
        // The range noise: the scans' own unless given.
        "--sigma",
    ];
    // Switches (flags without a value) have no default to show.
    let switches = [
        "--odometry-prior",
        "--one-way",
        "--whole-fallback",
        "--deskew",
    ];
    let mut checked = 0;
    for b in &blocks {
        let flag_line = b.lines().next().unwrap().trim();
        if without_default.iter().any(|f| flag_line.contains(f)) || switches.contains(&flag_line) {
            continue;
        }
        assert!(b.contains("[default:"), "no default shown:\n{b}");
        checked += 1;
    }
    assert!(checked >= 15, "only {checked} options found");
}

#[test]
fn eval_matching_on_a_plan_without_a_path_says_how_to_add_one() {
    let text = std::fs::read_to_string(plan("office")).unwrap();
    let mut room: Value = serde_json::from_str(&text).unwrap();
    room.as_object_mut().unwrap().remove("poses");
    let file = TempFile::new("no_path.wall", room.to_string().as_bytes());
    let out = bin()
        .args(["eval", "matching"])
        .arg(&file.0)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(
        err.starts_with(&format!(
            "{}:poses: the experiment needs a path of at least 2 poses, the plan has 0; add a \
             `poses` list",
            file.0.display()
        )),
        "{err}"
    );
}

#[test]
fn eval_matching_writes_a_table_and_maps() {
    let dir = std::env::temp_dir().join(format!("levelscan-evalm-{}", std::process::id()));
    let out = bin()
        .args(["eval", "matching", plan("office").to_str().unwrap()])
        .arg("--out")
        .arg(&dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let table = String::from_utf8(out.stdout).unwrap();
    // Header, rule, and level floor / raw / leveled, each pairwise and metascan; a blank line,
    // then the bound's header, rule and row.
    assert_eq!(table.lines().count(), 12, "{table}");
    assert!(
        table.lines().nth(11).unwrap().starts_with("| office | 0.0"),
        "{table}"
    );
    for name in [
        "matching.md",
        "matching.json",
        "office_pairwise.png",
        "office_pairwise.svg",
        "office_metascan.png",
        "office_metascan.svg",
    ] {
        assert!(dir.join(name).is_file(), "{name} missing");
    }
    let json: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("matching.json")).unwrap()).unwrap();
    let runs = json[0]["runs"].as_array().unwrap();
    assert_eq!(runs.len(), 6);
    let level_floor_metascan = runs
        .iter()
        .find(|r| r["kind"] == "level_floor" && r["mode"] == "metascan")
        .unwrap();
    assert!(level_floor_metascan["ate"]["rmse"].as_f64().unwrap() < 0.02);
    // The bound on the path: millimetres in a furnished office seen at 1 cm noise.
    let bound = &json[0]["bound"];
    for key in ["ate", "causal_rms"] {
        let b = bound[key].as_f64().unwrap();
        assert!(b > 1e-4 && b < 0.01, "{key} {b}");
    }
    let lines = json[0]["bound_walls_of_3_rays"]["ate"].as_f64().unwrap();
    assert!(
        lines >= bound["ate"].as_f64().unwrap() && lines < 0.01,
        "{lines}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn eval_real_scores_a_log_against_its_poses() {
    // A CARMEN log of a robot driving along a 4 m x 6 m box: the matcher beats the perturbed
    // odometry.
    let mut log = String::new();
    for k in 0..25 {
        let x = 0.05 * k as f64;
        let ranges: Vec<String> = (0..180)
            .map(|i| {
                let a = -std::f64::consts::FRAC_PI_2 + std::f64::consts::PI * i as f64 / 180.0;
                let (c, s) = (a.cos(), a.sin());
                let rx = if c > 1e-9 {
                    (3.0 - x) / c
                } else {
                    f64::INFINITY
                };
                let ry = if s.abs() > 1e-9 {
                    2.0 / s.abs()
                } else {
                    f64::INFINITY
                };
                format!("{:.4}", rx.min(ry))
            })
            .collect();
        log.push_str(&format!(
            "FLASER 180 {} {x} 0 0 {x} 0 0 {k}.0 nohost {k}.0\n",
            ranges.join(" ")
        ));
    }
    let file = TempFile::new("box.log", log.as_bytes());
    let out = bin().args(["eval", "real"]).arg(&file.0).output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let table = String::from_utf8(out.stdout).unwrap();
    let row = first_row(&table);
    // | log | scans | median | p95 | bad | odometry median | odometry bad | closure | ...
    assert_eq!(row[2], "25");
    let matched: f64 = row[3].parse().unwrap();
    let odometry: f64 = row[6].parse().unwrap();
    let closure: f64 = row[8].parse().unwrap();
    assert!(matched < odometry, "{table}");
    assert!(matched < 1.0, "{table}");
    assert!(closure < 1.0, "{table}");
    // The drift table: 1.2 m of path holds 1 m segments only.
    let drift: Vec<&str> = table
        .lines()
        .last()
        .unwrap()
        .split('|')
        .map(str::trim)
        .collect();
    let one_metre: f64 = drift[2].split('/').next().unwrap().trim().parse().unwrap();
    assert!(one_metre < 0.5, "{table}");
    assert_eq!(&drift[3..7], &["-", "-", "-", "-"], "{table}");

    // With --out, the three trajectories as TUM files (evo's format), one line per scan at
    // the log's timestamps; the reference is the log's own poses.
    let dir = std::env::temp_dir().join(format!("levelscan-real-out-{}", std::process::id()));
    let out = bin()
        .args(["eval", "real"])
        .arg(&file.0)
        .arg("--out")
        .arg(&dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stem = file
        .0
        .file_name()
        .unwrap()
        .to_string_lossy()
        .replace(".log", "");
    let read = |kind: &str| -> Vec<Vec<f64>> {
        let path = dir.join(format!("{stem}.{kind}.tum"));
        std::fs::read_to_string(&path)
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
            .lines()
            .map(|l| l.split(' ').map(|v| v.parse().unwrap()).collect())
            .collect()
    };
    let (reference, matched, odometry) = (read("reference"), read("matched"), read("odometry"));
    assert_eq!(
        (reference.len(), matched.len(), odometry.len()),
        (25, 25, 25)
    );
    for (k, ((r, m), o)) in reference.iter().zip(&matched).zip(&odometry).enumerate() {
        assert_eq!(r.len(), 8);
        assert_eq!((r[0], m[0], o[0]), (k as f64, k as f64, k as f64));
        assert!(
            (r[1] - 0.05 * k as f64).abs() < 1e-12 && r[2] == 0.0,
            "{r:?}"
        );
        // The matcher is within a few millimetres of the reference, odometry is not exact.
        assert!(
            (m[1] - r[1]).hypot(m[2] - r[2]) < 0.01,
            "{k}: {m:?} against {r:?}"
        );
    }
    assert!(odometry.iter().zip(&reference).any(|(o, r)| o[1] != r[1]));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn match_defaults_to_metascan_and_says_so() {
    let scans = simulated_level_scans(40);
    let default = run_match(&[], &scans);
    let metascan = run_match(&["--mode", "metascan"], &scans);
    let pairwise = run_match(&["--mode", "pairwise"], &scans);
    assert!(default.status.success() && pairwise.status.success());
    assert_eq!(default.stdout, metascan.stdout);
    assert_ne!(default.stdout, pairwise.stdout);
    let help = bin().args(["match", "--help"]).output().unwrap();
    let help = String::from_utf8(help.stdout).unwrap();
    assert!(help.contains("[default: metascan]"), "{help}");
}

/// `simulate | level` on the long hall (seed 1), checked to have run.
fn leveled_long_hall() -> Output {
    let sim = bin()
        .args([
            "simulate",
            plan("long_hall").to_str().unwrap(),
            "--seed",
            "1",
        ])
        .output()
        .unwrap();
    assert_ran(&sim);
    let level = run_with_stdin(&["level"], &sim.stdout);
    assert_ran(&level);
    level
}

#[test]
fn a_step_down_a_hall_keeps_what_the_scan_pins_and_says_what_came_from_odometry() {
    // simulate | level | match on the long hall: steps between pillars take the hall's
    // length from odometry; they stay `ok` and list that direction.
    let level = leveled_long_hall();
    for mode in ["pairwise", "metascan"] {
        let out = run_with_stdin(&["match", "--mode", mode], &level.stdout);
        assert!(out.status.success());
        let recs = records(&out);
        let mut partial = 0;
        for r in &recs {
            let m = &r["match"];
            let free = m["degenerate_directions"].as_array().unwrap();
            match m["status"].as_str().unwrap() {
                "ok" if !free.is_empty() => {
                    partial += 1;
                    // The hall runs along x: the free direction is (nearly) its length.
                    let d = floats(&free[0]);
                    assert!((d.iter().map(|v| v * v).sum::<f64>() - 1.0).abs() < 1e-9);
                    assert!(d[0].abs() > 0.9, "{mode}: {d:?}");
                }
                "ok" => {}
                _ => {
                    // Never thrown away for what the hall leaves free.
                    let reason = m["reason"].as_str().unwrap();
                    assert!(
                        ["no_valid_rays", "high_residual"].contains(&reason),
                        "{mode}: {m}"
                    );
                    assert_eq!(free.len(), 3);
                }
            }
        }
        assert!(partial >= 3, "{mode}: {partial} partial steps");
    }
}

/// A steady turn round a pillar (30 degrees a second, scans 0.1 s apart, each swept over
/// 25 ms while the robot turns on) as JSON Lines with timestamps, exact odometry and the truth;
/// with `ros_timing`, each record also carries a ROS LaserScan's `time_increment` as the bag
/// reader writes it.
fn swept_turn_log(ros_timing: bool) -> (Vec<u8>, f64) {
    let (rays, sweep) = (181, 0.025);
    let (truth, ranges) = matching_support::steady_turn(120, 0.1, sweep, rays);
    let dt = sweep / (rays - 1) as f64;
    let mut text = String::new();
    for (k, (pose, ranges)) in truth.iter().zip(&ranges).enumerate() {
        let theta: Vec<f64> = (0..rays)
            .map(|i| matching_support::bearing(i, rays))
            .collect();
        let valid: Vec<bool> = ranges.iter().map(Option::is_some).collect();
        let p = [pose.x, pose.y, pose.theta];
        let mut record = serde_json::json!({
            "nrays": rays, "theta": theta, "readings": ranges, "valid": valid,
            "odometry": p, "true_pose": p, "timestamp": [100 + k / 10, (k % 10) * 100_000],
        });
        if ros_timing {
            record["ros"] = serde_json::json!({"time_increment": dt});
        }
        text.push_str(&record.to_string());
        text.push('\n');
    }
    (text.into_bytes(), dt)
}

/// The matched run's heading error summed over its steps from the second on [deg].
fn heading_drift_deg(records: &[Value]) -> f64 {
    let poses: Vec<([f64; 3], [f64; 3])> = records
        .iter()
        .map(|r| (pose3(&r["estimate"]), pose3(&r["true_pose"])))
        .collect();
    poses
        .windows(2)
        .skip(1)
        .map(|w| {
            let d = (w[1].0[2] - w[0].0[2]) - (w[1].1[2] - w[0].1[2]);
            d.sin().atan2(d.cos()).to_degrees()
        })
        .sum()
}

#[test]
fn deskew_takes_the_turn_during_each_sweep_out_of_the_matched_heading() {
    let (log, dt) = swept_turn_log(false);
    let recorded = records(&run_match(&["--mode", "pairwise"], &log));
    let dt = format!("{dt}");
    let out = run_match(&["--mode", "pairwise", "--time-increment", &dt], &log);
    let deskewed = records(&out);
    let (before, after) = (heading_drift_deg(&recorded), heading_drift_deg(&deskewed));
    // About -1.6 degrees over the lap as recorded (tests/matching_deskew.rs has the model).
    assert!(before < -1.2, "as recorded {before}");
    assert!(
        after.abs() < 0.05 * before.abs(),
        "deskewed {after} against {before}"
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("deskewed 119 of 120 scans"), "{err}");
    assert!(!err.contains("warning"), "{err}");
    // Without timestamps nothing can be deskewed, and the run says so.
    let untimed: String = String::from_utf8_lossy(&log)
        .lines()
        .map(|l| {
            let mut v: Value = serde_json::from_str(l).unwrap();
            v.as_object_mut().unwrap().remove("timestamp");
            format!("{v}\n")
        })
        .collect();
    let out = run_match(&["--time-increment", &dt], untimed.as_bytes());
    assert_ran(&out);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("warning: deskewed 0 of 120 scans"), "{err}");
    // A bag's own time_increment serves --deskew alone: the same answers, to the float32
    // a LaserScan holds it in.
    let (ros_log, _) = swept_turn_log(true);
    let own = records(&run_match(&["--mode", "pairwise", "--deskew"], &ros_log));
    assert_eq!(own.len(), deskewed.len());
    for (a, b) in own.iter().zip(&deskewed) {
        let (a, b) = (pose3(&a["estimate"]), pose3(&b["estimate"]));
        assert!(
            (0..3).all(|i| (a[i] - b[i]).abs() < 1e-7),
            "{a:?} against {b:?}"
        );
    }
    // eval real takes the same flags.
    let file = TempFile::new("swept.jsonl", &log);
    let out = bin()
        .args(["eval", "real"])
        .arg(&file.0)
        .args(["--mode", "pairwise", "--time-increment", &dt])
        .output()
        .unwrap();
    assert_ran(&out);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("deskewed 119 of 120 scans"), "{err}");
}

#[test]
fn deskew_without_the_rays_timing_or_with_a_bad_one_is_refused_by_name() {
    // eval matching's robot scans standing still: the flags are refused, not ignored.
    let out = bin()
        .args([
            "eval",
            "matching",
            plan("office").to_str().unwrap(),
            "--deskew",
        ])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--deskew"));
    let (log, _) = swept_turn_log(false);
    let file = TempFile::new("untimed.jsonl", &log);
    let out = bin()
        .arg("match")
        .arg(&file.0)
        .arg("--deskew")
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    let at = format!("{}:1", file.0.display());
    assert!(
        err.contains(&at) && err.contains("time_increment") && err.contains("--time-increment"),
        "{err}"
    );
    for (flag, bad) in [
        ("--time-increment", "0.5"),
        ("--time-increment", "NaN"),
        ("--time-increment", "-inf"),
        ("--interlace", "0"),
        ("--interlace", "17"),
        ("--sweep-period", "0"),
        ("--sweep-period", "NaN"),
    ] {
        assert_refused_by_name(&file.0, flag, bad);
    }
}

/// `simulate` of two_rooms as CSM's tools make a log: flat, 1 cm range noise, with `extra`
/// flags (checked to have run).
fn flat_two_rooms(seed: &str, extra: &[&str]) -> Output {
    let sim = bin()
        .args(["simulate"])
        .arg(plan("two_rooms"))
        .args([
            "--flat",
            "--elevations",
            "0",
            "--sigma",
            "0.01",
            "--seed",
            seed,
        ])
        .args(extra)
        .output()
        .unwrap();
    assert_ran(&sim);
    sim
}

/// The cells of the first row of `eval real`'s table (after the log's name, `[1]`: scans,
/// `[3]`: RPE median, `[5]`: bad pairs, ...).
fn first_row(table: &str) -> Vec<&str> {
    table
        .lines()
        .nth(2)
        .unwrap()
        .split('|')
        .map(str::trim)
        .collect()
}

#[test]
fn eval_real_with_the_plan_puts_the_matchers_rpe_beside_the_cramer_rao_bound() {
    // A flat run simulated in two_rooms, as CSM's tools make them: the matcher's RPE median
    // lies above the bound's (an efficient matcher's), but within a third of it.
    let sim = flat_two_rooms("3", &[]);
    let file = TempFile::new("flat.jsonl", &sim.stdout);
    let dir = std::env::temp_dir().join(format!("levelscan-real-bound-{}", std::process::id()));
    let out = bin()
        .args([
            "eval", "real", "--mode", "pairwise", "--seed", "3", "--plan",
        ])
        .arg(plan("two_rooms"))
        .arg(&file.0)
        .arg("--out")
        .arg(&dir)
        .output()
        .unwrap();
    assert_ran(&out);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("Cramér-Rao bound over 319 consecutive pairs"),
        "{stderr}"
    );
    let json: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("real.json")).unwrap()).unwrap();
    let result = &json[0];
    let bound = &result["bound"];
    assert_eq!(bound["pairs"], 319);
    assert_eq!(bound["agreeing"], 1.0);
    let efficient = bound["median_translation"].as_f64().unwrap();
    let matched = result["matched"]["median_translation"].as_f64().unwrap();
    assert!((0.001..0.003).contains(&efficient), "{bound}");
    let ratio = matched / efficient;
    assert!(
        (1.0..1.35).contains(&ratio),
        "matched {matched}, bound {efficient}"
    );
    let table = String::from_utf8(out.stdout).unwrap();
    assert!(table.contains("| efficient median [mm] |"), "{table}");
    let _ = std::fs::remove_dir_all(&dir);

    // A log that was not simulated in the plan (the box log of the test above, or another
    // plan) is refused, naming the log, rather than bounded against walls it never saw.
    let out = bin()
        .args(["eval", "real", "--plan"])
        .arg(plan("office"))
        .arg(&file.0)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("flat.jsonl") && err.contains("office.wall") && err.contains("simulated in"),
        "{err}"
    );
    // And the noise must be a length.
    let out = bin()
        .args(["eval", "real", "--range-sigma", "0", "--plan"])
        .arg(plan("two_rooms"))
        .arg(&file.0)
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--range-sigma"));
}

#[test]
fn metascan_has_no_bad_pair_on_a_flat_run_with_poor_odometry() {
    // The CSM-style flat run with 10 cm and 5 degrees of odometry noise per step: early on, the
    // map of a few scans leaves a direction unpinned, which metascan took from an odometry it
    // thought good to 5 mm (8 cm off at step 4 of seed 1). eval real tells the matcher the
    // noise it adds.
    let sim = flat_two_rooms("1", &[]);
    let file = TempFile::new("flat-poor-odometry.jsonl", &sim.stdout);
    let out = bin()
        .args(["eval", "real", "--mode", "metascan", "--seed", "1"])
        .args(["--odo-trans-min", "0.1", "--odo-rot-min", "5"])
        .arg(&file.0)
        .output()
        .unwrap();
    assert_ran(&out);
    let table = String::from_utf8(out.stdout).unwrap();
    let row = first_row(&table);
    // | log | scans | median | p95 | bad pairs | ...
    assert_eq!(row[5], "0", "{table}");
    let median: f64 = row[3].parse().unwrap();
    assert!(median < 3.0, "{table}");
}

/// Steps of a `match` output off their true motion by more than 5 cm or 1 degree.
fn bad_steps(records: &[Value]) -> usize {
    let pose = |r: &Value, key: &str| {
        let [x, y, theta] = pose3(&r[key]);
        Pose2::new(x, y, theta)
    };
    records
        .windows(2)
        .filter(|w| {
            let step = |key| pose(&w[0], key).between(&pose(&w[1], key));
            let error = step("true_pose").between(&step("estimate"));
            error.translation().norm() > 0.05 || error.theta.abs() > 1f64.to_radians()
        })
        .count()
}

#[test]
fn poor_odometry_is_weighed_as_poor_told_or_found_out() {
    // A flat run whose odometry is off by 10 cm and 5 degrees a step. Under a model of 5 mm
    // and 0.5 degree, metascan took what its young map leaves unpinned from that odometry (8 cm
    // off at step 4 of seed 1). Told the noise (--prior-*, without --odometry-prior), or
    // finding it out from its own matches, it has no bad step.
    let sim = flat_two_rooms("1", &["--odo-trans-min", "0.1", "--odo-rot-min", "5"]);
    for flags in [
        &["--prior-trans-min", "0.1", "--prior-rot-min", "5"][..],
        &[],
    ] {
        let out = run_match(flags, &sim.stdout);
        assert_ran(&out);
        let recs = records(&out);
        assert_eq!(recs.len(), 320);
        assert_eq!(bad_steps(&recs), 0, "{flags:?}");
    }
}

#[test]
fn the_odometry_noise_flags_price_what_the_odometry_fills_in() {
    // Down the long hall, some pairwise steps take the hall's length from odometry; their
    // covariance along it is the odometry model's, which --prior-trans-min sets without
    // --odometry-prior (on steps of about 1.5 m, 2% + 5 cm against 2% + 5 mm: about five
    // times the variance; a step from a pose before a fallback spans more, and its share of
    // 2% grows).
    let level = leveled_long_hall();
    // The variance along each one-pose step's free direction d: dᵀ C d.
    let along_hall = |flags: &[&str]| -> Vec<f64> {
        let mut args = vec!["--mode", "pairwise"];
        args.extend_from_slice(flags);
        let out = run_match(&args, &level.stdout);
        assert_ran(&out);
        records(&out)
            .windows(2)
            .filter(|w| w[0]["match"]["status"] == "ok" && w[1]["match"]["status"] == "ok")
            .filter_map(|w| {
                let r = &w[1];
                let d = floats(r["match"]["degenerate_directions"].as_array()?.first()?);
                let c = floats(&r["match"]["covariance"]);
                Some(
                    (0..3)
                        .flat_map(|i| (0..3).map(move |j| (i, j)))
                        .map(|(i, j)| d[i] * c[3 * i + j] * d[j])
                        .sum(),
                )
            })
            .collect()
    };
    let (default, told) = (along_hall(&[]), along_hall(&["--prior-trans-min", "0.05"]));
    assert!(
        default.len() >= 3 && default.len() == told.len(),
        "{default:?} {told:?}"
    );
    for (d, t) in default.iter().zip(&told) {
        assert!(*t > 3.0 * d, "{d} {t}: {default:?} {told:?}");
    }
}

/// The two-room plan's first `poses` level scans at `sigma` of range noise, stating it in
/// `readings_sigma` when `with_sigma`.
fn noisy_level_scans(poses: usize, sigma: &str, with_sigma: bool) -> Vec<u8> {
    let mut cmd = bin();
    cmd.args(["simulate", plan("two_rooms").to_str().unwrap()])
        .args([
            "--flat",
            "--elevations",
            "0",
            "--seed",
            "3",
            "--sigma",
            sigma,
        ]);
    if with_sigma {
        cmd.arg("--with-sigma");
    }
    let out = cmd.output().unwrap();
    assert_ran(&out);
    let text = String::from_utf8(out.stdout).unwrap();
    let kept: Vec<&str> = text.lines().take(poses).collect();
    (kept.join("\n") + "\n").into_bytes()
}

fn estimates(out: &Output) -> Vec<[f64; 3]> {
    records(out).iter().map(|r| pose3(&r["estimate"])).collect()
}

/// The noise a scan states in `readings_sigma` and the noise given as `--sigma` are one: the
/// same matches. And at 5 cm it is not 1 cm: the lines come from runs of rays.
#[test]
fn stated_noise_and_sigma_flag_match_alike() {
    let stated = run_match(
        &["--mode", "metascan"],
        &noisy_level_scans(40, "0.05", true),
    );
    let unstated = noisy_level_scans(40, "0.05", false);
    let flagged = run_match(&["--mode", "metascan", "--sigma", "0.05"], &unstated);
    let plain = run_match(&["--mode", "metascan"], &unstated);
    for out in [&stated, &flagged, &plain] {
        assert_ran(out);
    }
    assert_eq!(estimates(&stated), estimates(&flagged));
    assert_ne!(estimates(&flagged), estimates(&plain));
    // The summary says so, and why; a scan at 1 cm and 1 degree has nothing to say.
    let said = |out: &Output| String::from_utf8_lossy(&out.stderr).to_string();
    assert!(
        said(&flagged).contains("40 of 40 scans fitted their local lines through the means of runs of 3 rays (for their range noise, up to 5.0 cm"),
        "{}",
        said(&flagged)
    );
    assert!(!said(&plain).contains("runs of"), "{}", said(&plain));
    // The flag wins over what the scans state: told 1 cm, they match as if unstated.
    let told_1cm = run_match(
        &["--mode", "metascan", "--sigma", "0.01"],
        &noisy_level_scans(40, "0.05", true),
    );
    assert_ran(&told_1cm);
    assert_eq!(estimates(&told_1cm), estimates(&plain));
}

#[test]
fn a_sigma_that_is_not_a_positive_number_is_refused() {
    // From a file: `match` refuses the flag before it reads a scan, so a pipe would break.
    let input = TempFile::new("bad-sigma.jsonl", &simulated_level_scans(3));
    for bad in ["0", "-0.01", "nan", "inf"] {
        let out = bin()
            .args([
                "match",
                input.0.to_str().unwrap(),
                &format!("--sigma={bad}"),
            ])
            .output()
            .unwrap();
        assert!(!out.status.success(), "--sigma {bad} accepted");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            err.contains("--sigma") && !err.contains("panicked"),
            "--sigma {bad}: {err}"
        );
    }
}

/// A placeholder `readings_sigma` (1 m on every ray, where the ranges scatter by 5 cm) is set
/// aside with a warning: the scans match as scans that state none.
#[test]
fn a_placeholder_readings_sigma_is_set_aside_with_a_warning() {
    let unstated = noisy_level_scans(30, "0.05", false);
    let placeholder: String = String::from_utf8(unstated.clone())
        .unwrap()
        .lines()
        .map(|l| {
            let mut v: Value = serde_json::from_str(l).unwrap();
            let n = v["nrays"].as_u64().unwrap() as usize;
            v["readings_sigma"] = serde_json::json!(vec![1.0; n]);
            v.to_string() + "\n"
        })
        .collect();
    let plain = run_match(&["--mode", "metascan"], &unstated);
    let set_aside = run_match(&["--mode", "metascan"], placeholder.as_bytes());
    assert_ran(&plain);
    assert_ran(&set_aside);
    assert_eq!(estimates(&plain), estimates(&set_aside));
    let said = String::from_utf8_lossy(&set_aside.stderr);
    assert!(
        said.contains("warning: 30 of 30 scans state a range noise (readings_sigma)")
            && said.contains("matched as scans that state none"),
        "{said}"
    );
}
