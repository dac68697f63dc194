//! End-to-end runs of `levelscan info` on each input it reads: simulator output, CSM logs,
//! CARMEN logs (plain and gzipped), empty input.

mod cli_support;
use cli_support::*;

use serde_json::{Value, json};
use std::io::Write;
use std::path::{Path, PathBuf};

fn info_of(input: &[u8]) -> Value {
    let out = run_with_stdin(&["info"], input);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn simulated_run_is_summarised() {
    let plan = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/plans/office.wall");
    let sim = bin()
        .arg("simulate")
        .arg(&plan)
        .args([
            "--random", "7", "--scans", "5", "--step", "4", "--seed", "3",
        ])
        .output()
        .unwrap();
    assert!(
        sim.status.success(),
        "{}",
        String::from_utf8_lossy(&sim.stderr)
    );
    let j = info_of(&sim.stdout);
    assert_eq!(j["format"], "jsonl");
    assert_eq!(j["file"], "<stdin>");
    assert_eq!(j["poses"], 7);
    assert_eq!(j["scans"], 35);
    assert_eq!(j["scans_per_pose"], json!({"min": 5, "max": 5}));
    assert_eq!(j["elevations_per_pose"], json!({"min": 5, "max": 5}));
    assert_eq!(j["poses_with_too_few_elevations"], 0);
    assert_eq!(j["poses_with_mixed_nrays"], 0);
    assert_eq!(j["returning_sequences"], 0);
    assert_eq!(j["rays"]["total"], 35 * 181);
    assert_eq!(j["rays"]["per_scan"], json!({"min": 181, "max": 181}));
    let deg = floats(&j["elevations"]["deg"]);
    assert_eq!(deg.len(), 5);
    for (d, want) in deg.iter().zip([-8.0, -4.0, 0.0, 4.0, 8.0]) {
        assert!((d - want).abs() < 1e-9, "{deg:?}");
    }
    assert_eq!(j["fields"]["true_pose"], 35);
    assert_eq!(j["fields"]["hit"], 35);
    let valid = j["valid_fraction"].as_f64().unwrap();
    assert!(valid > 0.3 && valid <= 1.0, "{valid}");
}

#[test]
fn csm_log_is_summarised_with_its_extra_fields() {
    let line = r#"{ "nrays": 4, "min_theta": -1.5, "max_theta": 1.5, "readings": [ 1.5, null, 2, 3 ], "valid": [ 1, 0, 1, 0 ], "true_alpha": [ null, null, null, null ], "odometry": [ 0, 0, 0 ], "estimate": [ null, null, null ], "timestamp": [ 12, 5 ] }"#;
    let j = info_of(format!("{line}\n{line}\n{line}\n").as_bytes());
    assert_eq!(
        j["poses"], 3,
        "records without sequence are numbered in order"
    );
    assert_eq!(j["scans"], 3);
    assert_eq!(j["valid_rays"], 6);
    assert_eq!(j["valid_fraction"], 0.5);
    assert_eq!(j["range_m"], json!({"min": 1.5, "max": 2.0}));
    assert_eq!(j["fields"]["odometry"], 3);
    assert_eq!(j["fields"]["estimate"], 0);
    assert_eq!(j["extra_fields"], json!(["true_alpha"]));
    assert_eq!(j["elevations"]["scans_without"], 3);
}

const CARMEN_LOG: &str = "# message formats defined: PARAM SYNC ODOM FLASER\n\
PARAM robot_front_laser_max 50 host 0\n\
ODOM 0 0 0 0 0 0 0.1 host 0.1\n\
FLASER 4 1.0 2.0 50.0 81.91 0.5 0.5 0 0.5 0.5 0 1.5 host 1.5\n\
NEFF 10\n\
FLASER 4 1.0 2.0 3.0 4.0 0.6 0.5 0 0.6 0.5 0 1.7 host 1.7\n";

#[test]
fn carmen_log_is_summarised() {
    let j = info_of(CARMEN_LOG.as_bytes());
    assert_eq!(j["format"], "carmen");
    assert_eq!(j["scans"], 2);
    assert_eq!(j["rays"]["total"], 8);
    assert_eq!(j["valid_rays"], 6, "50 and 81.91 are no return");
    assert_eq!(j["fields"]["true_pose"], 2);
    assert_eq!(j["fields"]["odometry"], 2);
    assert_eq!(j["fields"]["timestamp"], 2);
}

struct TempFile(PathBuf);

impl Drop for TempFile {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

#[test]
fn gzipped_carmen_file_is_read_and_max_range_applies() {
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    gz.write_all(CARMEN_LOG.as_bytes()).unwrap();
    let f = TempFile(
        std::env::temp_dir().join(format!("levelscan-info-{}.log.gz", std::process::id())),
    );
    std::fs::write(&f.0, gz.finish().unwrap()).unwrap();
    let out = bin()
        .args(["info", "--max-range", "3.5"])
        .arg(&f.0)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let j: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(j["file"], f.0.display().to_string());
    assert_eq!(j["format"], "carmen");
    // --max-range 3.5 overrides the log's 50: the 4.0 m reading is no return too.
    assert_eq!(j["valid_rays"], 5);
}

#[test]
fn empty_input_is_summarised_as_nothing() {
    let j = info_of(b"\n\n");
    assert_eq!(j["scans"], 0);
    assert_eq!(j["poses"], 0);
    assert_eq!(j["valid_fraction"], Value::Null);
}

#[test]
fn info_writes_to_o_like_the_other_commands() {
    let scans = bin()
        .args(["simulate", plan_path().to_str().unwrap(), "--random", "3"])
        .output()
        .unwrap();
    assert!(scans.status.success());
    let to_stdout = run_with_stdin(&["info"], &scans.stdout);
    assert!(to_stdout.status.success());
    let dash = run_with_stdin(&["info", "-o", "-"], &scans.stdout);
    assert_eq!(dash.stdout, to_stdout.stdout);
    let file = std::env::temp_dir().join(format!("levelscan-info-o-{}.json", std::process::id()));
    let out = run_with_stdin(&["info", "-o", file.to_str().unwrap()], &scans.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        out.stdout.is_empty(),
        "-o FILE leaves standard output empty"
    );
    assert_eq!(std::fs::read(&file).unwrap(), to_stdout.stdout);
    std::fs::remove_file(&file).unwrap();
}

fn plan_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/plans/office.wall")
}
