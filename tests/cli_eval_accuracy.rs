//! End-to-end runs of `levelscan eval accuracy` and `simulate` as a user types them: the
//! efficiency figures against the bound, phantoms by hit label, and the noise models.

mod cli_support;
use cli_support::*;

use serde_json::Value;
use std::path::{Path, PathBuf};

fn plan(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("examples/plans/{name}.wall"))
}

fn out_dir(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("levelscan_eval_eff_{}_{name}", std::process::id()))
}

fn run_accuracy(dir: &Path, extra: &[&str]) -> (String, Value, Vec<Value>) {
    let out = bin()
        .args(["eval", "accuracy", plan("office").to_str().unwrap()])
        .args([
            "--poses", "12", "--scans", "3,4", "--sigma", "0.02", "--seed", "3",
        ])
        .args(["--out", dir.to_str().unwrap()])
        .args(extra)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json =
        serde_json::from_str(&std::fs::read_to_string(dir.join("accuracy.json")).unwrap()).unwrap();
    let poses = std::fs::read_to_string(dir.join("poses.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    (String::from_utf8(out.stdout).unwrap(), json, poses)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Every cell carries the efficiency figures, and they are the medians and shares of the
/// per-pose records in poses.jsonl.
#[test]
fn efficiency_figures_agree_with_the_pose_records() {
    let dir = out_dir("eff");
    let (md, json, poses) = run_accuracy(&dir, &["--estimator", "robust"]);
    assert!(md.contains("### Against each pose's bound"), "{md}");
    assert!(md.contains("ml, true segments"), "{md}");
    assert!(md.contains("last stage, true segments"), "{md}");
    assert!(md.contains("floor/ceiling kept"), "{md}");
    for c in json["cells"].as_array().unwrap() {
        let of_cell: Vec<&Value> = poses
            .iter()
            .filter(|p| p["scans"] == c["scans"] && p["estimator"] == c["estimator"])
            .collect();
        let leveled: Vec<&&Value> = of_cell.iter().filter(|p| p["status"] == "ok").collect();
        // A failed pose names its cause as well as its reason; a leveled one neither.
        for p in &of_cell {
            assert_eq!(p["status"] == "ok", p["cause"].is_null(), "{p}");
            assert_eq!(p["reason"].is_null(), p["cause"].is_null(), "{p}");
        }
        let ratios: Vec<f64> = leveled
            .iter()
            .map(|p| {
                let r = p["error_over_bound"].as_f64().unwrap();
                let want = p["error_deg"].as_f64().unwrap() / p["bound_deg"].as_f64().unwrap();
                assert!((r - want).abs() < 1e-9 * want.max(1.0), "{p}");
                r
            })
            .collect();
        assert_eq!(
            c["efficiency_poses"].as_u64().unwrap() as usize,
            ratios.len()
        );
        let got = c["error_over_bound"].as_f64().unwrap();
        assert!((got - median(ratios)).abs() < 1e-12, "{c}");
        // Within k sigma per axis: a share, growing with k.
        let w = &c["within_sigma"];
        for axis in 0..2 {
            let shares: Vec<f64> = (0..3).map(|k| w[k][axis].as_f64().unwrap()).collect();
            assert!(
                shares.windows(2).all(|s| s[0] <= s[1]) && shares[2] <= 1.0,
                "{w}"
            );
        }
        let ml = &c["true_segments_ml"];
        assert!(ml["efficiency_poses"].as_u64().unwrap() > 0, "{c}");
        let s = ml["sigma_over_bound"].as_f64().unwrap();
        assert!(
            (s - 1.0).abs() < 0.1,
            "the core's sigma is the bound's: {ml}"
        );
        // The last stage on the same segmentation fits a subset of its points (relabelling
        // leaves out those within reach of two surfaces) and only ever widens.
        let last = &c["true_segments_last_stage"];
        assert!(last["efficiency_poses"].as_u64().unwrap() > 0, "{c}");
        let s_last = last["sigma_over_bound"].as_f64().unwrap();
        assert!(s_last >= 0.98 * s, "{last} against {ml}");
        let within = c["true_segments_last_stage_within_gate"].as_f64().unwrap();
        assert!(
            within <= c["true_segments_ml_within_gate"].as_f64().unwrap() + 0.02,
            "{c}"
        );
        let rate = c["floor_kept_rate"].as_f64().unwrap();
        assert!((0.0..=1.0).contains(&rate));
        let kept: u64 = leveled
            .iter()
            .map(|p| p["floor_kept"].as_u64().unwrap())
            .sum();
        let valid: u64 = leveled
            .iter()
            .map(|p| p["pseudo_valid"].as_u64().unwrap())
            .sum();
        assert!((rate - kept as f64 / valid as f64).abs() < 1e-12);
    }
    std::fs::remove_dir_all(dir).ok();
}

/// The paper's reading of its noise: `--noise-model paper` is uniform noise of that full
/// width, recorded as such; the bound is computed from its standard deviation.
#[test]
fn paper_noise_model_is_uniform_and_recorded() {
    let (da, db) = (out_dir("gauss"), out_dir("uniform"));
    let (_, gauss, _) = run_accuracy(&da, &["--estimator", "paper"]);
    let (_, uniform, _) = run_accuracy(&db, &["--estimator", "paper", "--noise-model", "paper"]);
    assert_eq!(uniform["noise_model"], "uniform");
    assert_eq!(gauss["noise_model"], "gaussian");
    // Same poses and ray geometry; a uniform width of 2 cm is a sigma of 2 / sqrt 12 cm, so
    // each cell's median bound shrinks by sqrt 12.
    for (g, u) in gauss["cells"]
        .as_array()
        .unwrap()
        .iter()
        .zip(uniform["cells"].as_array().unwrap())
    {
        let ratio =
            g["bound_median_deg"].as_f64().unwrap() / u["bound_median_deg"].as_f64().unwrap();
        assert!((ratio - 12f64.sqrt()).abs() < 1e-6, "{ratio}");
    }
    std::fs::remove_dir_all(da).ok();
    std::fs::remove_dir_all(db).ok();
}

/// `simulate --noise-model uniform`: every reading within half the width of the noise-free
/// one, some near the edge, and `readings_sigma` the standard deviation.
#[test]
fn simulate_uniform_noise_stays_within_half_its_width() {
    let sim = |extra: &[&str]| {
        records(
            &bin()
                .args([
                    "simulate",
                    plan("office").to_str().unwrap(),
                    "--random",
                    "3",
                ])
                .args(["--seed", "5", "--with-sigma"])
                .args(extra)
                .output()
                .unwrap(),
        )
    };
    let clean = sim(&["--sigma", "0"]);
    let noisy = sim(&["--sigma", "0.04", "--noise-model", "uniform"]);
    assert_eq!(clean.len(), noisy.len());
    let mut largest: f64 = 0.0;
    for (c, n) in clean.iter().zip(&noisy) {
        let sigma = n["readings_sigma"][0].as_f64().unwrap();
        assert!((sigma - 0.04 / 12f64.sqrt()).abs() < 1e-12, "{sigma}");
        let (rc, rn) = (
            c["readings"].as_array().unwrap(),
            n["readings"].as_array().unwrap(),
        );
        for (a, b) in rc.iter().zip(rn) {
            if let (Some(a), Some(b)) = (a.as_f64(), b.as_f64()) {
                let d = (a - b).abs();
                assert!(d <= 0.02 + 1e-9, "{a} vs {b}");
                largest = largest.max(d);
            }
        }
    }
    assert!(largest > 0.019, "{largest}");
    let bad = bin()
        .args([
            "simulate",
            plan("office").to_str().unwrap(),
            "--noise-model",
            "laplace",
        ])
        .output()
        .unwrap();
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stderr).contains("laplace"));
}

#[test]
fn a_bad_quad_tolerance_is_refused_by_name() {
    let out = bin()
        .args(["eval", "accuracy", plan("office").to_str().unwrap()])
        .args(["--poses", "2", "--quad-tolerance", "0"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--quad-tolerance"));
}

#[test]
fn elevations_beyond_a_turn_and_tilts_beyond_90_degrees_are_refused_by_name() {
    for (args, flag) in [
        (["--step", "1e300"], "--step"),
        (["--scans", "200"], "--step"),
        (["--tilt", "1e9"], "--tilt"),
    ] {
        let out = bin()
            .args(["eval", "accuracy", plan("office").to_str().unwrap()])
            .args(["--poses", "2"])
            .args(args)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?} was taken");
        assert!(err.contains(flag) && !err.contains("panicked"), "{err}");
    }
}

/// A plan with no room for a random pose is named by its file, among several; a column built
/// half into a room's wall leaves the room free, so its plan runs.
#[test]
fn a_plan_without_free_space_is_named_and_a_column_in_a_wall_is_no_trap() {
    let dir = TempDir::new("eval_free_space");
    let column = dir.0.join("column.wall");
    std::fs::write(
        &column,
        r#"{"version": "w0.1", "wallheight": 3.0, "walls": [
            [[0, 0], [10, 0], [10, 8], [0, 8], [0, 0]],
            [[4, 7.6], [4.6, 7.6], [4.6, 8.4], [4, 8.4], [4, 7.6]]]}"#,
    )
    .unwrap();
    let cupboard = dir.0.join("cupboard.wall");
    std::fs::write(
        &cupboard,
        r#"{"version": "w0.1", "wallheight": 3.0, "walls": [[[0, 0], [1, 0], [1, 1], [0, 1], [0, 0]]]}"#,
    )
    .unwrap();
    let run = |plans: &[&Path]| {
        bin()
            .args(["eval", "accuracy"])
            .args(plans)
            .args(["--poses", "3", "--scans", "3", "--sigma", "0.01"])
            .output()
            .unwrap()
    };
    assert_ran(&run(&[column.as_path()]));
    let bad = run(&[column.as_path(), cupboard.as_path()]);
    let stderr = String::from_utf8_lossy(&bad.stderr);
    assert_eq!(bad.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("cupboard.wall: no free space found"),
        "{stderr}"
    );
    assert!(!stderr.contains("panicked"), "{stderr}");
}

#[test]
fn zero_poses_are_refused_not_tabled() {
    let out = bin()
        .args(["eval", "accuracy", plan("office").to_str().unwrap()])
        .args(["--poses", "0"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(out.stdout.is_empty(), "no tables of 0/0");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--poses 0: no poses to level"), "{err}");
}
