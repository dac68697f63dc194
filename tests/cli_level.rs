//! End-to-end runs of `levelscan level` on simulated scans.

mod cli_support;
use cli_support::*;

use levelscan::formats::write_scan;
use levelscan::geometry::Pose;
use levelscan::plan::Plan;
use levelscan::simulate::{ScannerParams, World, elevations_centred, simulate_pose};
use nalgebra::Point2;
use rand::SeedableRng;
use serde_json::Value;
use std::path::PathBuf;
use std::process::Command;

fn room() -> World {
    let p = |x: f64, y: f64| Point2::new(x, y);
    World::from_plan(&Plan {
        wall_height: 3.0,
        walls: vec![vec![
            p(0.0, 0.0),
            p(7.0, 0.0),
            p(7.0, 5.0),
            p(3.0, 6.0),
            p(0.0, 5.0),
            p(0.0, 0.0),
        ]],
        ceiling: false,
        poses: vec![],
    })
}

/// Writes `poses` x 4 scans of the room to a temporary file; returns its path.
fn scan_file(name: &str, poses: &[Pose]) -> PathBuf {
    let world = room();
    let mut buf = Vec::new();
    let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(5);
    let e = elevations_centred(4, 5f64.to_radians());
    for (k, pose) in poses.iter().enumerate() {
        for s in simulate_pose(
            &world,
            k as u64,
            pose,
            &e,
            &ScannerParams::default(),
            &mut rng,
        ) {
            write_scan(&mut buf, &s).unwrap();
        }
    }
    let path = std::env::temp_dir().join(format!(
        "levelscan_cli_level_{}_{name}.jsonl",
        std::process::id()
    ));
    std::fs::write(&path, buf).unwrap();
    path
}

fn level(args: &[&str]) -> std::process::Output {
    bin().arg("level").args(args).output().unwrap()
}

fn poses() -> Vec<Pose> {
    let d = |a: f64| a.to_radians();
    vec![
        Pose::new(3.0, 2.5, 0.45, d(10.0), d(6.0), d(-8.0)),
        Pose::new(2.0, 2.0, 0.45, d(-60.0), d(-10.0), d(4.0)),
        Pose::new(4.5, 3.0, 0.45, d(170.0), d(3.0), d(12.0)),
    ]
}

#[test]
fn level_writes_one_contract_record_per_pose_in_order() {
    let poses = poses();
    let path = scan_file("layout", &poses);
    let out = level(&[path.to_str().unwrap(), "--polygons"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    let records: Vec<Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(records.len(), poses.len());
    for (k, (r, pose)) in records.iter().zip(&poses).enumerate() {
        assert_eq!(r["sequence"], k as u64);
        let n = r["nrays"].as_u64().unwrap() as usize;
        for key in ["theta", "readings", "valid", "readings_sigma"] {
            assert_eq!(r[key].as_array().unwrap().len(), n, "{key}");
        }
        for i in 0..n {
            let valid = r["valid"][i].as_u64().unwrap();
            assert_eq!(valid == 1, r["readings"][i].is_number(), "ray {i}");
            assert!(r["theta"][i].is_number());
            // Each kept ray states the noise the leveler estimated (1 cm simulated).
            assert_eq!(valid == 1, r["readings_sigma"][i].is_number(), "ray {i}");
            if let Some(s) = r["readings_sigma"][i].as_f64() {
                assert!((0.007..0.014).contains(&s), "ray {i}: {s}");
            }
        }
        assert_eq!(r["min_theta"], r["theta"][0]);
        assert_eq!(
            r["true_pose"].as_array().unwrap().len(),
            3,
            "planar [x, y, rz]"
        );
        assert!(r.get("elevation").is_none(), "a 2D scan has no elevation");
        let lv = &r["level"];
        assert_eq!(lv["status"], "ok", "{lv}");
        assert!(lv["reason"].is_null());
        let err_x = (lv["theta_x"].as_f64().unwrap() - pose.rx).abs();
        let err_y = (lv["theta_y"].as_f64().unwrap() - pose.ry).abs();
        assert!(err_x.max(err_y).to_degrees() < 1.0, "pose {k}: {lv}");
        assert!(lv["sigma_x"].as_f64().unwrap() > 0.0);
        assert_eq!(lv["up"].as_array().unwrap().len(), 3);
        assert!(lv["polygons"].as_u64().unwrap() > 0);
        assert!(lv["base_elevation"].is_number());
        let polys = r["wall_polygons"].as_array().unwrap();
        assert_eq!(polys.len() as u64, lv["polygons"].as_u64().unwrap());
        assert_eq!(polys[0].as_array().unwrap().len(), 4);
        assert_eq!(polys[0][0].as_array().unwrap().len(), 3);
        assert!(!r["wall_patches"].as_array().unwrap().is_empty());
        assert!(
            r["valid"]
                .as_array()
                .unwrap()
                .iter()
                .filter(|v| v.as_u64() == Some(1))
                .count()
                > 50
        );
    }
    std::fs::remove_file(path).ok();
}

/// The noise given as `--sigma` is the noise each kept ray states, for `match` to fit to.
#[test]
fn level_states_the_noise_it_used_on_every_kept_ray() {
    let path = scan_file("stated", &poses());
    let out = level(&[path.to_str().unwrap(), "--sigma", "0.03"]);
    assert_ran(&out);
    for r in records(&out) {
        let sigmas = r["readings_sigma"].as_array().unwrap();
        let kept = sigmas.iter().filter(|s| !s.is_null()).count();
        assert!(kept > 50, "{kept} rays state a noise");
        assert!(sigmas.iter().flat_map(|s| s.as_f64()).all(|s| s == 0.03));
    }
    std::fs::remove_file(path).ok();
}

/// `simulate PLAN --random N --seed S EXTRA...`'s scans, checked to have run.
fn simulated(plan: &std::path::Path, poses: &str, seed: &str, extra: &[&str]) -> String {
    let out = bin()
        .arg("simulate")
        .arg(plan)
        .args(["--random", poses, "--seed", seed])
        .args(extra)
        .output()
        .unwrap();
    assert_ran(&out);
    String::from_utf8(out.stdout).unwrap()
}

/// Scans that state their true noise pass it on: every kept ray states it.
#[test]
fn level_passes_on_the_noise_the_scans_state() {
    let plan = plan_file("stated");
    let sim = simulated(&plan, "4", "2", &["--sigma", "0.02", "--with-sigma"]);
    let out = run_with_stdin(&["level"], sim.as_bytes());
    assert_ran(&out);
    let mut stated = 0;
    for r in records(&out) {
        for (reading, sigma) in r["readings"]
            .as_array()
            .unwrap()
            .iter()
            .zip(r["readings_sigma"].as_array().unwrap())
        {
            assert_eq!(reading.is_null(), sigma.is_null());
            if let Some(s) = sigma.as_f64() {
                assert_eq!(s, 0.02);
                stated += 1;
            }
        }
    }
    assert!(stated > 100, "{stated} rays state a noise");
    std::fs::remove_file(plan).ok();
}

/// A converter's placeholder in `readings_sigma` (1 m on every ray, where the ranges scatter by
/// 1 cm) is set aside: the poses level as if the scans stated nothing, and the output states
/// the noise level used instead.
#[test]
fn a_placeholder_readings_sigma_is_set_aside() {
    let plan = plan_file("placeholder");
    let sim = |extra: &[&str]| simulated(&plan, "6", "4", extra);
    let plain = sim(&[]);
    let placeholder: String = sim(&["--with-sigma"])
        .lines()
        .map(|l| {
            let mut v: Value = serde_json::from_str(l).unwrap();
            let n = v["readings_sigma"].as_array().unwrap().len();
            v["readings_sigma"] = serde_json::json!(vec![1.0; n]);
            v.to_string() + "\n"
        })
        .collect();
    let attitudes = |out: &std::process::Output| -> Vec<(Value, Value)> {
        records(out)
            .iter()
            .map(|r| (r["level"]["theta_x"].clone(), r["level"]["theta_y"].clone()))
            .collect()
    };
    let a = run_with_stdin(&["level"], plain.as_bytes());
    let b = run_with_stdin(&["level"], placeholder.as_bytes());
    assert_ran(&a);
    assert_ran(&b);
    assert_eq!(attitudes(&a), attitudes(&b));
    // Said once, with the count; a run stating nothing, or its true noise, says nothing.
    let said = String::from_utf8_lossy(&b.stderr);
    assert!(
        said.contains(
            "warning: 6 of 6 poses state a range noise (readings_sigma) over 3 times off"
        ),
        "{said}"
    );
    assert!(!String::from_utf8_lossy(&a.stderr).contains("readings_sigma"));
    let told = run_with_stdin(&["level"], sim(&["--with-sigma"]).as_bytes());
    assert_ran(&told);
    assert!(!String::from_utf8_lossy(&told.stderr).contains("readings_sigma"));
    for r in records(&b) {
        for s in r["readings_sigma"]
            .as_array()
            .unwrap()
            .iter()
            .flat_map(|s| s.as_f64())
        {
            assert!((0.005..0.02).contains(&s), "{s}");
        }
    }
    std::fs::remove_file(plan).ok();
}

#[test]
fn level_reads_standard_input_and_fails_a_two_scan_pose_with_a_reason() {
    let path = scan_file("stdin", &poses()[..1]);
    // Keep only the first two scans: too few elevations.
    let text = std::fs::read_to_string(&path).unwrap();
    let two: String = text.lines().take(2).map(|l| format!("{l}\n")).collect();
    let out = run_with_stdin(&["level"], two.as_bytes());
    assert!(out.status.success());
    let r: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(r["level"]["status"], "failed");
    assert_eq!(r["level"]["reason"], "too_few_scans");
    assert!(r["level"]["theta_x"].is_null() && r["level"]["up"].is_null());
    // Only the angles, sigmas and up are null for a failed pose (contract); the base scan is
    // still named by its elevation.
    assert!(r["level"]["base_elevation"].is_number(), "{}", r["level"]);
    assert!(
        r["valid"]
            .as_array()
            .unwrap()
            .iter()
            .all(|v| v.as_u64() == Some(0))
    );
    assert!(r["readings"].as_array().unwrap().iter().all(Value::is_null));
    std::fs::remove_file(path).ok();
}

#[test]
fn missing_elevation_is_an_input_error_with_file_and_line() {
    let path = scan_file("noelev", &poses()[..1]);
    let text = std::fs::read_to_string(&path).unwrap();
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    let mut v: Value = serde_json::from_str(&lines[2]).unwrap();
    v.as_object_mut().unwrap().remove("elevation");
    lines[2] = v.to_string();
    std::fs::write(&path, lines.join("\n") + "\n").unwrap();
    let out = level(&[path.to_str().unwrap()]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains(&format!("{}:3:", path.display())), "{err}");
    assert!(err.contains("elevation"), "{err}");
    std::fs::remove_file(path).ok();
}

#[test]
fn a_sequence_that_comes_back_is_an_input_error() {
    let path = scan_file("seq", &poses()[..2]);
    let text = std::fs::read_to_string(&path).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    // pose 0, pose 1, then pose 0 again.
    let back = format!("{}\n{}\n", text.trim_end(), lines[0]);
    std::fs::write(&path, back).unwrap();
    let out = level(&[path.to_str().unwrap()]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains(&format!("{}:9:", path.display())), "{err}");
    assert!(err.contains("sequence 0"), "{err}");
    std::fs::remove_file(path).ok();
}

#[test]
fn a_missing_file_is_an_error_naming_it() {
    let out = level(&["/nonexistent/scans.jsonl"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("/nonexistent/scans.jsonl"));
}

/// A small room with a pillar as a `.wall` file in the temporary directory.
fn plan_file(name: &str) -> PathBuf {
    let path = std::env::temp_dir().join(format!(
        "levelscan_cli_level_{}_{name}.wall",
        std::process::id()
    ));
    std::fs::write(
        &path,
        r#"{"version": "w0.1", "wallheight": 3.0, "walls": [
            [[0, 0], [8, 0], [8, 6], [3, 7], [0, 6], [0, 0]],
            [[5, 2], [5.5, 2], [5.5, 2.5], [5, 2.5], [5, 2]]]}"#,
    )
    .unwrap();
    path
}

#[test]
fn eval_accuracy_writes_table_i_json_and_fig6() {
    let plan = plan_file("eval");
    let dir = std::env::temp_dir().join(format!("levelscan_eval_acc_{}", std::process::id()));
    let out = Command::new(env!("CARGO_BIN_EXE_levelscan"))
        .args(["eval", "accuracy", plan.to_str().unwrap(), "--poses", "6"])
        .args(["--scans", "3,5", "--sigma", "0.01,0.05", "--seed", "2"])
        .args(["--out", dir.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let md = String::from_utf8(out.stdout).unwrap();
    assert!(md.contains("### Table I, robust estimator"), "{md}");
    assert!(md.contains("### Table I, paper estimator"), "{md}");
    assert!(
        md.contains("(0.857)"),
        "the paper's 3-scan 1 cm mean beside ours: {md}"
    );
    let json: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("accuracy.json")).unwrap()).unwrap();
    let cells = json["cells"].as_array().unwrap();
    assert_eq!(cells.len(), 2 * 2 * 2, "scans x noise x estimators");
    for c in cells {
        assert_eq!(c["poses"], 6);
        let leveled = c["leveled"].as_u64().unwrap() as usize;
        assert_eq!(c["errors_deg"].as_array().unwrap().len(), leveled);
    }
    for f in ["fig6_robust.png", "fig6_robust.svg", "fig6_paper.svg"] {
        assert!(dir.join(f).exists(), "{f}");
    }
    // Every pose of every cell, and its record agrees with the cell's statistics.
    let poses: Vec<Value> = std::fs::read_to_string(dir.join("poses.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(poses.len(), cells.len() * 6);
    for c in cells {
        let of_cell: Vec<&Value> = poses
            .iter()
            .filter(|p| {
                p["scans"] == c["scans"]
                    && p["noise"] == c["noise"]
                    && p["estimator"] == c["estimator"]
            })
            .collect();
        let mut index: Vec<u64> = of_cell
            .iter()
            .map(|p| p["pose"].as_u64().unwrap())
            .collect();
        index.sort_unstable();
        assert_eq!(index, (0..6).collect::<Vec<_>>());
        let ok: Vec<&&Value> = of_cell.iter().filter(|p| p["status"] == "ok").collect();
        assert_eq!(ok.len() as u64, c["leveled"].as_u64().unwrap());
        for p in &ok {
            let (t, e) = (&p["truth_deg"], &p["estimate_deg"]);
            let err = (0..2)
                .map(|k| (t[k].as_f64().unwrap() - e[k].as_f64().unwrap()).abs())
                .fold(0.0, f64::max);
            assert!((err - p["error_deg"].as_f64().unwrap()).abs() < 1e-9, "{p}");
            assert!(p["plan"].as_str().unwrap().ends_with(".wall"));
        }
        for p in of_cell.iter().filter(|p| p["status"] == "failed") {
            assert!(
                p["reason"].is_string() && p["estimate_deg"].is_null(),
                "{p}"
            );
        }
    }
    std::fs::remove_dir_all(dir).ok();
    std::fs::remove_file(plan).ok();
}

#[test]
fn adaptive_simulation_levels_and_records_its_attempts() {
    let plan = plan_file("adaptive");
    let sim = Command::new(env!("CARGO_BIN_EXE_levelscan"))
        .args([
            "simulate",
            plan.to_str().unwrap(),
            "--random",
            "12",
            "--scans",
            "3",
        ])
        .args(["--adaptive", "--seed", "4"])
        .output()
        .unwrap();
    assert!(
        sim.status.success(),
        "{}",
        String::from_utf8_lossy(&sim.stderr)
    );
    let text = String::from_utf8(sim.stdout).unwrap();
    let scans: Vec<Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert!(scans.len() >= 36);
    assert!(scans.iter().all(|s| s["adaptive"]["attempt"].is_u64()));
    // Retakes keep their pose's sequence, so sequences stay consecutive and run 0..12.
    let mut seqs: Vec<u64> = scans
        .iter()
        .map(|s| s["sequence"].as_u64().unwrap())
        .collect();
    assert!(seqs.windows(2).all(|w| w[0] <= w[1]));
    seqs.dedup();
    assert_eq!(seqs, (0..12).collect::<Vec<u64>>());
    let path = std::env::temp_dir().join(format!(
        "levelscan_cli_level_{}_adaptive.jsonl",
        std::process::id()
    ));
    std::fs::write(&path, &text).unwrap();
    let out = level(&[path.to_str().unwrap()]);
    assert!(out.status.success());
    assert_eq!(String::from_utf8(out.stdout).unwrap().lines().count(), 12);
    std::fs::remove_file(path).ok();
    std::fs::remove_file(plan).ok();
}

/// `bytes` gunzipped (panics when they are not gzip).
fn gunzip(bytes: &[u8]) -> Vec<u8> {
    use std::io::Read;
    assert!(bytes.starts_with(&[0x1f, 0x8b]), "not gzip");
    let mut out = Vec::new();
    flate2::read::MultiGzDecoder::new(bytes)
        .read_to_end(&mut out)
        .unwrap();
    out
}

#[test]
fn an_output_named_gz_is_gzipped_and_reads_back() {
    let dir = TempDir::new("gz_out");
    let plan = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/plans/office.wall");
    let path = |name: &str| dir.0.join(name).to_str().unwrap().to_string();
    let run = |args: &[&str]| {
        let out = Command::new(env!("CARGO_BIN_EXE_levelscan"))
            .args(args)
            .output()
            .unwrap();
        assert_ran(&out);
        out.stdout
    };
    let (scans, level, matched) = (path("s.jsonl.gz"), path("l.jsonl.gz"), path("m.jsonl.gz"));
    run(&["simulate", plan, "-o", &scans]);
    run(&["level", &scans, "-o", &level]);
    run(&["match", &level, "-o", &matched]);
    // Each is the plain output, compressed.
    let plain_scans = run(&["simulate", plan]);
    assert_eq!(gunzip(&std::fs::read(&scans).unwrap()), plain_scans);
    let plain_level = run(&["level", &scans]);
    assert_eq!(gunzip(&std::fs::read(&level).unwrap()), plain_level);
    assert_eq!(
        gunzip(&std::fs::read(&matched).unwrap()),
        run(&["match", &level])
    );
}
