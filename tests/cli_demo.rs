//! End-to-end runs of `levelscan demo`: what it writes, that leveling beats raw scans on its run,
//! and that the same seed gives the same numbers.

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_levelscan");

fn temp_dir(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("levelscan-cli-demo-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Runs the demo into `out` and returns its standard output and report.json.
fn demo(out: &Path) -> (String, Value) {
    let o = Command::new(BIN)
        .args([
            "demo",
            "--out",
            out.to_str().unwrap(),
            "--accuracy-poses",
            "4",
        ])
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "demo failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let json = std::fs::read_to_string(out.join("report.json")).unwrap();
    (
        String::from_utf8(o.stdout).unwrap(),
        serde_json::from_str(&json).unwrap(),
    )
}

fn ate(report: &Value, run: &str, mode: &str) -> f64 {
    report["matching"]
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["run"] == run && r["mode"] == mode)
        .unwrap_or_else(|| panic!("no {run} {mode} run"))["ate"]["rmse"]
        .as_f64()
        .unwrap()
}

#[test]
fn demo_writes_a_self_contained_report_where_leveling_beats_raw_scans() {
    let dir = temp_dir("report");
    let (stdout, report) = demo(&dir);
    assert!(
        stdout.contains(&format!("report: {}", dir.join("report.html").display())),
        "{stdout}"
    );
    for f in [
        "report.html",
        "scans_tilted.jsonl",
        "leveled.jsonl",
        "view_pose.html",
        "map_raw_metascan.png",
        "map_leveled_metascan.svg",
        "maps_raw_vs_leveled.png",
        "maps_raw_vs_leveled.svg",
        "table1.svg",
        "fig6_histogram.png",
    ] {
        assert!(dir.join(f).exists(), "{f} missing");
    }
    let page = std::fs::read_to_string(dir.join("report.html")).unwrap();
    for needle in ["src=\"http", "href=\"http", "<link", "<script src"] {
        assert!(!page.contains(needle), "report refers out: {needle}");
    }
    // Six matched runs: level floor, raw and leveled, each pairwise and metascan.
    assert_eq!(report["matching"].as_array().unwrap().len(), 6);
    assert_eq!(report["level"]["poses"], 30);
    // The paper's point (sect. 8.2): leveled scans match far better than raw ones, and
    // leveled metascan is within issue 4's 5 cm.
    let (raw, leveled) = (
        ate(&report, "raw", "metascan"),
        ate(&report, "leveled", "metascan"),
    );
    assert!(leveled < 0.05, "leveled metascan ATE {leveled}");
    assert!(raw > 3.0 * leveled, "raw {raw} vs leveled {leveled}");
    // Table I: 3 scan counts x 3 noise levels.
    assert_eq!(report["accuracy"].as_array().unwrap().len(), 9);
}

#[test]
fn demo_with_the_same_seed_gives_the_same_numbers_and_scans() {
    let (a, b) = (temp_dir("seed-a"), temp_dir("seed-b"));
    let (_, mut ra) = demo(&a);
    let (_, mut rb) = demo(&b);
    ra.as_object_mut().unwrap().remove("timings_s");
    rb.as_object_mut().unwrap().remove("timings_s");
    assert_eq!(ra, rb);
    for f in ["scans_tilted.jsonl", "leveled.jsonl"] {
        assert_eq!(
            std::fs::read(a.join(f)).unwrap(),
            std::fs::read(b.join(f)).unwrap(),
            "{f} differs"
        );
    }
}

#[test]
fn demo_rejects_too_few_scans_per_pose() {
    let dir = temp_dir("bad");
    let o = Command::new(BIN)
        .args(["demo", "--out", dir.to_str().unwrap(), "--scans", "2"])
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("--scans"), "{err}");
    assert!(!err.contains("panicked"));
}
