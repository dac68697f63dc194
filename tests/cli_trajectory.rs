//! `match --reference-trajectory` writes the records' `true_pose` as TUM beside the estimate's
//! `--trajectory`, at the same times; simulated scans carry timestamps for those times
//! (issue 25 item 9).

mod cli_support;
use cli_support::*;

use std::path::{Path, PathBuf};

fn plan(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("examples/plans/{name}.wall"))
}

struct TempDir(PathBuf);

impl TempDir {
    fn new(name: &str) -> TempDir {
        let p = std::env::temp_dir().join(format!("levelscan-traj-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&p);
        std::fs::create_dir_all(&p).unwrap();
        TempDir(p)
    }

    fn path(&self, name: &str) -> String {
        self.0.join(name).to_str().unwrap().to_string()
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn tum_rows(path: &str) -> Vec<Vec<f64>> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .map(|l| l.split(' ').map(|t| t.parse().unwrap()).collect())
        .collect()
}

#[test]
fn simulated_scans_are_stamped_two_seconds_a_pose_a_tenth_a_scan() {
    let out = bin()
        .args(["simulate", plan("office").to_str().unwrap(), "--scans", "3"])
        .output()
        .unwrap();
    let scans = records(&out);
    assert_eq!(scans.len(), 90);
    for (i, s) in scans.iter().enumerate() {
        let (k, j) = (i / 3, i % 3);
        assert_eq!(s["sequence"], k);
        let want = serde_json::json!([1000 + 2 * k, 100_000 * j]);
        assert_eq!(s["timestamp"], want, "scan {i}");
    }
}

#[test]
fn reference_trajectory_is_the_true_pose_at_the_estimates_times() {
    let d = TempDir::new("ref");
    let scans = bin()
        .args(["simulate", plan("office").to_str().unwrap()])
        .output()
        .unwrap();
    let leveled = run_with_stdin(&["level"], &scans.stdout);
    let (est, reference, matched) = (d.path("est.tum"), d.path("ref.tum"), d.path("m.jsonl"));
    let out = run_with_stdin(
        &[
            "match",
            "--trajectory",
            &est,
            "--reference-trajectory",
            &reference,
            "-o",
            &matched,
        ],
        &leveled.stdout,
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let records: Vec<serde_json::Value> = std::fs::read_to_string(&matched)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let (est, reference) = (tum_rows(&est), tum_rows(&reference));
    assert_eq!(records.len(), 30);
    assert_eq!(reference.len(), 30);
    assert_eq!(est.len(), 30);
    for (k, ((r, e), rec)) in reference.iter().zip(&est).zip(&records).enumerate() {
        // The base scan's time: pose k at 1000 + 2k s, its scans 0.1 s apart.
        assert_eq!(r[0], e[0]);
        let stamp = &rec["timestamp"];
        assert_eq!(stamp[0], 1000 + 2 * k, "row {k}");
        let usec = stamp[1].as_i64().unwrap();
        assert!([0, 100_000, 200_000].contains(&usec), "row {k}: {usec}");
        assert_eq!(r[0], (1000 + 2 * k) as f64 + usec as f64 * 1e-6, "row {k}");
        let truth = rec["true_pose"].as_array().unwrap();
        let (x, y, yaw) = (
            truth[0].as_f64().unwrap(),
            truth[1].as_f64().unwrap(),
            truth[2].as_f64().unwrap(),
        );
        assert_eq!((r[1], r[2], r[3], r[4], r[5]), (x, y, 0.0, 0.0, 0.0));
        let (qz, qw) = (yaw / 2.0).sin_cos();
        assert!((r[6] - qz).abs() < 1e-15 && (r[7] - qw).abs() < 1e-15);
    }
    // The estimate follows the truth on the office path (its start is the odometry's).
    let worst = reference
        .iter()
        .zip(&est)
        .map(|(r, e)| (r[1] - e[1]).hypot(r[2] - e[2]))
        .fold(0.0, f64::max);
    assert!(worst < 0.5, "estimate {worst} m from the reference");
}

#[test]
fn a_carmen_logs_corrected_pose_is_its_reference() {
    let d = TempDir::new("carmen");
    let log = d.path("real.log");
    std::fs::write(
        &log,
        "FLASER 3 1 2 3 0.5 -1 0.25 0 0 0 10.5 h 1\nFLASER 3 1 2 3 0.6 -1 0.3 0.1 0 0 11.25 h 2\n",
    )
    .unwrap();
    let reference = d.path("ref.tum");
    let out = bin()
        .args([
            "match",
            &log,
            "--reference-trajectory",
            &reference,
            "-o",
            &d.path("m.jsonl"),
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let rows = tum_rows(&reference);
    assert_eq!(rows.len(), 2);
    let (qz, qw) = (0.3f64 / 2.0).sin_cos();
    assert_eq!(rows[1], [11.25, 0.6, -1.0, 0.0, 0.0, 0.0, qz, qw]);
    assert_eq!(rows[0][..3], [10.5, 0.5, -1.0]);
}

#[test]
fn a_log_without_true_pose_is_refused_naming_it_and_no_file_written() {
    let d = TempDir::new("none");
    let log = d.path("scans.jsonl");
    std::fs::write(
        &log,
        "{\"nrays\": 3, \"theta\": [-1, 0, 1], \"readings\": [1, 2, 3]}\n\
         {\"nrays\": 3, \"theta\": [-1, 0, 1], \"readings\": [1, 2, 3]}\n",
    )
    .unwrap();
    let reference = d.path("ref.tum");
    let out = bin()
        .args([
            "match",
            &log,
            "--reference-trajectory",
            &reference,
            "-o",
            &d.path("m.jsonl"),
        ])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(
        err.trim_end(),
        format!(
            "{log}: no record has a true_pose, so there is no reference trajectory for \
             {reference} (it comes from simulate's output, a CARMEN log's corrected pose or a \
             bag's --truth-topic)"
        )
    );
    assert!(!Path::new(&reference).exists());
    // The matched records themselves were written whole.
    assert_eq!(
        std::fs::read_to_string(d.path("m.jsonl"))
            .unwrap()
            .lines()
            .count(),
        2
    );
}
