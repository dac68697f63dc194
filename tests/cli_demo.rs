//! End-to-end runs of `levelscan demo`: what it writes, that leveling beats raw scans on its run,
//! and that the same seed gives the same numbers.

mod cli_support;
use cli_support::TempDir;
use serde_json::Value;
use std::path::Path;
use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_levelscan");

/// A fresh directory for one test's demo, removed when the test ends.
fn temp_dir(tag: &str) -> TempDir {
    TempDir::new(&format!("cli-demo-{tag}"))
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
    let tmp = temp_dir("report");
    let dir = &tmp.0;
    let (stdout, report) = demo(dir);
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
        "matched.jsonl",
        "map.yaml",
        "map.pgm",
        "pose.ply",
        "run_attitude.svg",
        "run_trajectory_error.png",
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
    // The map is the one map_server reads: its image beside it, 5 cm cells.
    let yaml = std::fs::read_to_string(dir.join("map.yaml")).unwrap();
    assert!(
        yaml.starts_with("image: map.pgm\nmode: trinary\nresolution: 0.05\n"),
        "{yaml}"
    );
    assert!(
        std::fs::read(dir.join("map.pgm"))
            .unwrap()
            .starts_with(b"P5\n")
    );
    let ply = std::fs::read(dir.join("pose.ply")).unwrap();
    assert!(ply.starts_with(b"ply\nformat binary_little_endian 1.0\n"));
}

#[test]
fn eval_run_plots_the_demos_run_as_a_user_would() {
    let tmp = temp_dir("eval-run");
    let dir = &tmp.0;
    demo(dir);
    let out = Command::new(BIN)
        .args(["eval", "run"])
        .arg(dir.join("scans_tilted.jsonl"))
        .arg(dir.join("matched.jsonl"))
        .arg("--out")
        .arg(dir.join("run"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let table = String::from_utf8(out.stdout).unwrap();
    assert!(
        table.starts_with("| poses | leveled | roll RMSE [deg]"),
        "{table}"
    );
    let run: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("run/run.json")).unwrap()).unwrap();
    assert_eq!(run["summary"]["poses"], 30);
    assert_eq!(run["poses"].as_array().unwrap().len(), 30);
    // Truth joined from the raw scans: every leveled pose has its true attitude and error.
    let rmse = run["summary"]["attitude_rmse_deg"][0].as_f64().unwrap();
    assert!(rmse > 0.0 && rmse < 1.0, "roll RMSE {rmse}");
    assert!(run["poses"][0]["true_attitude"].is_array());
    let ate = run["summary"]["ate"]["rmse"].as_f64().unwrap();
    assert!(ate < 0.05, "{ate}");
    for f in [
        "attitude.svg",
        "attitude.png",
        "trajectory_error.svg",
        "trajectory_error.png",
    ] {
        assert!(dir.join("run").join(f).exists(), "{f} missing");
    }
    let svg = std::fs::read_to_string(dir.join("run/attitude.svg")).unwrap();
    assert!(svg.contains("roll theta_x [deg]") && svg.contains("truth (true_pose)"));
    // Only raw scans: nothing to evaluate, and the user is told what to give.
    let out = Command::new(BIN)
        .args(["eval", "run"])
        .arg(dir.join("scans_tilted.jsonl"))
        .arg("--out")
        .arg(dir.join("run2"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("no level or match output"));
}

#[test]
fn demo_with_the_same_seed_gives_the_same_numbers_and_scans() {
    let (ta, tb) = (temp_dir("seed-a"), temp_dir("seed-b"));
    let (a, b) = (&ta.0, &tb.0);
    let (_, mut ra) = demo(a);
    let (_, mut rb) = demo(b);
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
    let tmp = temp_dir("bad");
    let dir = &tmp.0;
    let o = Command::new(BIN)
        .args(["demo", "--out", dir.to_str().unwrap(), "--scans", "2"])
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("--scans"), "{err}");
    assert!(!err.contains("panicked"));
}
