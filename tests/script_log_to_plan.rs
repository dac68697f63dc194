//! `scripts/log_to_plan.py` end to end: a CARMEN log scanned in a known room becomes a plan
//! that `simulate` scans back into the same ranges along the same path (docs/RESULTS.md, the
//! control for `eval real`). Needs `python3` (standard library only; `LEVELSCAN_PYTHON` when
//! set); without one the test says it is skipped, unless `LEVELSCAN_REQUIRE_INTEROP=1` (CI).

mod cli_support;
use cli_support::*;

use serde_json::Value;
use std::fmt::Write as _;
use std::path::Path;
use std::process::Command;

/// A room of 6 x 4 m with a pillar, and a path through it (x, y, heading in degrees).
const ROOM: &str = r#"{"version": "w0.1", "wallheight": 3.0, "walls": [
    [[0, 0], [6, 0], [6, 4], [0, 4], [0, 0]],
    [[3.5, 1.8], [3.9, 1.8], [3.9, 2.2], [3.5, 2.2], [3.5, 1.8]]],
  "poses": [[1.0, 1.0, 0.3, 20, 0, 0], [1.6, 1.3, 0.3, 35, 0, 0], [2.1, 2.9, 0.3, -60, 0, 0],
            [4.8, 3.1, 0.3, -150, 0, 0], [5.0, 0.9, 0.3, 120, 0, 0]]}"#;

/// Noise-free flat scans of `plan` at its poses, 181 rays over 180 degrees.
fn scans_of(plan: &Path) -> Vec<Value> {
    let out = bin()
        .args([
            "simulate",
            plan.to_str().unwrap(),
            "--flat",
            "--elevations",
            "0",
        ])
        .args(["--sigma", "0", "--rays", "181", "--fov", "180"])
        .output()
        .unwrap();
    records(&out)
}

/// The scans as `FLASER` lines, or as `ROBOTLASER1` lines over the same bearings (a reading of
/// 0 where a ray met nothing), at their true poses.
fn carmen_log(scans: &[Value], robotlaser: bool) -> String {
    let mut log = String::new();
    for (k, s) in scans.iter().enumerate() {
        let ranges: Vec<f64> = s["readings"]
            .as_array()
            .unwrap()
            .iter()
            .zip(s["valid"].as_array().unwrap())
            .map(|(r, v)| if v == 1 { r.as_f64().unwrap() } else { 0.0 })
            .collect();
        let t = &s["true_pose"];
        let (x, y, th) = (
            t[0].as_f64().unwrap(),
            t[1].as_f64().unwrap(),
            t[3].as_f64().unwrap(),
        );
        let (pi, n) = (std::f64::consts::PI, ranges.len());
        if robotlaser {
            let res = pi / (n - 1) as f64;
            write!(log, "ROBOTLASER1 0 {} {pi} {res} 30 0.01 0 {n}", -pi / 2.0).unwrap();
        } else {
            write!(log, "FLASER {n}").unwrap();
        }
        for r in &ranges {
            write!(log, " {r:.4}").unwrap();
        }
        if robotlaser {
            writeln!(
                log,
                " 0 {x} {y} {th} {x} {y} {th} 0 0 0 0 0 {k}.0 test {k}.0"
            )
            .unwrap();
        } else {
            writeln!(log, " {x} {y} {th} {x} {y} {th} {k}.0 test {k}.0").unwrap();
        }
    }
    log
}

#[test]
fn a_log_becomes_a_plan_that_scans_back_into_its_own_ranges() {
    let Some(python) = python_or_skip("script_log_to_plan") else {
        return;
    };
    let dir = TempDir::new("l2p");
    let room = dir.0.join("room.wall");
    std::fs::write(&room, ROOM).unwrap();
    let original = scans_of(&room);
    assert_eq!(original.len(), 5);
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/log_to_plan.py");
    let plan_of = |name: &str, robotlaser: bool| {
        let log = dir.0.join(format!("{name}.log"));
        std::fs::write(&log, carmen_log(&original, robotlaser)).unwrap();
        let plan = dir.0.join(format!("{name}.wall"));
        let out = Command::new(&python)
            .arg(&script)
            .args([
                log.to_str().unwrap(),
                plan.to_str().unwrap(),
                "--every",
                "1",
            ])
            .args(["--eps", "0.002"])
            .output()
            .unwrap();
        assert_ran(&out);
        plan
    };
    // A file that is no laser log is refused by name, without a plan or a traceback.
    let not_a_log = dir.0.join("room_copy.wall");
    std::fs::write(&not_a_log, ROOM).unwrap();
    let out = Command::new(&python)
        .arg(&script)
        .args([
            not_a_log.to_str().unwrap(),
            dir.0.join("x.wall").to_str().unwrap(),
        ])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && !dir.0.join("x.wall").exists(),
        "{err}"
    );
    assert!(
        err.contains("room_copy.wall")
            && err.contains("not a CARMEN laser log")
            && !err.contains("Traceback"),
        "{err}"
    );
    let plan = plan_of("flaser", false);
    // The same scans as ROBOTLASER1 lines give the same plan.
    let robotlaser = plan_of("robotlaser", true);
    assert_eq!(
        std::fs::read_to_string(&plan).unwrap(),
        std::fs::read_to_string(&robotlaser).unwrap()
    );

    // The path is the log's, pose for pose.
    let made: Value = serde_json::from_str(&std::fs::read_to_string(&plan).unwrap()).unwrap();
    let poses = made["poses"].as_array().unwrap();
    assert_eq!(poses.len(), 5);
    for (p, s) in poses.iter().zip(&original) {
        let t = &s["true_pose"];
        assert!((p[0].as_f64().unwrap() - t[0].as_f64().unwrap()).abs() < 1e-4);
        assert!((p[1].as_f64().unwrap() - t[1].as_f64().unwrap()).abs() < 1e-4);
        let heading = p[3].as_f64().unwrap().to_radians();
        assert!((heading - t[3].as_f64().unwrap()).abs() < 1e-6);
    }

    // Scanned again, the plan gives back the ranges: simplified within 2 mm (noise-free
    // ranges), straight walls stay straight, so all but the rays that meet a corner's chamfer
    // (the polyline joins the samples on either side of it) or slip between two polylines
    // that end there agree to a few mm.
    let again = scans_of(&plan);
    assert_eq!(again.len(), original.len());
    let (mut close, mut total) = (0, 0);
    for (a, b) in original.iter().zip(&again) {
        let ra = a["readings"].as_array().unwrap();
        let rb = b["readings"].as_array().unwrap();
        for (i, (x, y)) in ra.iter().zip(rb).enumerate() {
            if a["valid"][i] != 1 {
                continue;
            }
            total += 1;
            if b["valid"][i] == 1 && (x.as_f64().unwrap() - y.as_f64().unwrap()).abs() < 0.005 {
                close += 1;
            }
        }
    }
    assert!(total > 800, "{total} valid rays");
    assert!(
        close as f64 >= 0.95 * total as f64,
        "{close} of {total} rays within 5 mm"
    );
}
