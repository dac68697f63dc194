//! End-to-end runs of `levelscan simulate` (the binary), on the example plans.

mod cli_support;
use cli_support::*;

use levelscan::formats::read_plan;
use levelscan::simulate::{World, is_free};
use serde_json::Value;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Output, Stdio};

const PLANS: [&str; 5] = ["office", "angled", "ceiling", "corridor", "two_rooms"];

fn plan(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("examples/plans/{name}.wall"))
}

fn simulate(args: &[&str]) -> Output {
    bin().arg("simulate").args(args).output().unwrap()
}

/// A temporary file that is removed when dropped.
struct TempFile(PathBuf);

impl TempFile {
    fn new(name: &str, text: &str) -> TempFile {
        let path =
            std::env::temp_dir().join(format!("levelscan-sim-{}-{name}", std::process::id()));
        std::fs::File::create(&path)
            .unwrap()
            .write_all(text.as_bytes())
            .unwrap();
        TempFile(path)
    }
}

impl Drop for TempFile {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

#[test]
fn random_poses_piped_into_info_are_counted() {
    let mut sim = bin()
        .args(["simulate", plan("office").to_str().unwrap()])
        .args(["--random", "50", "--scans", "5"])
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let info = bin()
        .arg("info")
        .stdin(sim.stdout.take().unwrap())
        .output()
        .unwrap();
    assert!(sim.wait().unwrap().success());
    assert!(
        info.status.success(),
        "{}",
        String::from_utf8_lossy(&info.stderr)
    );
    let summary: Value = serde_json::from_slice(&info.stdout).unwrap();
    assert_eq!(summary["poses"], 50);
    assert_eq!(summary["scans"], 250);
    assert_eq!(summary["elevations"]["distinct"], 5);
}

#[test]
fn output_is_identical_across_thread_counts_and_depends_on_seed() {
    let run = |threads: &str, seed: &str| {
        let out = bin()
            .env("RAYON_NUM_THREADS", threads)
            .args(["simulate", plan("two_rooms").to_str().unwrap()])
            .args(["--random", "150", "--seed", seed])
            .output()
            .unwrap();
        assert!(out.status.success());
        out.stdout
    };
    let one = run("1", "11");
    assert!(!one.is_empty());
    assert_eq!(one, run("2", "11"));
    assert_eq!(one, run("3", "11"));
    assert_ne!(one, run("2", "12"));
}

#[test]
fn plan_poses_give_ordered_sequences_and_ground_truth_fields() {
    let path = plan("office");
    let plan_poses = read_plan(&path).unwrap().poses;
    let recs = records(&simulate(&[path.to_str().unwrap(), "--scans", "4"]));
    assert_eq!(recs.len(), plan_poses.len() * 4);
    for (k, r) in recs.iter().enumerate() {
        let pose = k / 4;
        assert_eq!(r["sequence"], pose as u64);
        assert_eq!(r["nrays"], 181);
        assert_eq!(r["true_pose"].as_array().unwrap().len(), 6);
        let tp = r["true_pose"][0].as_f64().unwrap();
        assert!((tp - plan_poses[pose].x).abs() < 1e-12);
        let odo = r["odometry"].as_array().unwrap();
        assert_eq!(odo.len(), 3, "planar odometry is written [x, y, rz]");
        assert_eq!(r["hit"].as_array().unwrap().len(), 181);
        assert!(r.get("readings_sigma").is_none());
        assert!(r.get("hinge_offset").is_none());
        // Elevations -7.5, -2.5, 2.5, 7.5 degrees, in that order.
        let e = r["elevation"].as_f64().unwrap().to_degrees();
        assert!((e - (-7.5 + 5.0 * (k % 4) as f64)).abs() < 1e-9);
    }
    // The first pose's odometry is its true planar pose.
    let p0 = plan_poses[0];
    let odo0 = floats(&recs[0]["odometry"]);
    assert!((odo0[0] - p0.x).abs() < 1e-12 && (odo0[2] - p0.rz).abs() < 1e-12);
}

#[test]
fn options_reach_the_output() {
    let out = TempFile::new("options.jsonl", "");
    let status = bin()
        .args(["simulate", plan("ceiling").to_str().unwrap()])
        .args(["--rays", "91", "--fov", "90", "--elevations", "-30,0,10,20"])
        .args([
            "--hinge-offset",
            "0.1,0,-0.05",
            "--with-sigma",
            "--sigma",
            "0.03",
        ])
        .args(["--height", "0.8", "--flat", "-o", out.0.to_str().unwrap()])
        .status()
        .unwrap();
    assert!(status.success());
    let text = std::fs::read_to_string(&out.0).unwrap();
    let recs: Vec<Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(recs.len() % 4, 0);
    let r = &recs[3];
    assert_eq!(r["nrays"], 91);
    assert!((r["theta"][0].as_f64().unwrap().to_degrees() + 45.0).abs() < 1e-9);
    assert!((r["elevation"].as_f64().unwrap().to_degrees() - 20.0).abs() < 1e-9);
    assert_eq!(r["hinge_offset"], serde_json::json!([0.1, 0.0, -0.05]));
    assert_eq!(r["readings_sigma"][0], 0.03);
    let tp = r["true_pose"].as_array().unwrap();
    assert_eq!(tp[2], 0.8);
    assert_eq!((tp[4].as_f64(), tp[5].as_f64()), (Some(0.0), Some(0.0)));
    // Beams tilted 30 degrees up from a room with a ceiling meet it somewhere.
    let hits_ceiling = recs
        .iter()
        .any(|r| r["hit"].as_array().unwrap().iter().any(|h| h == 3));
    assert!(hits_ceiling);
}

#[test]
fn every_example_plan_simulates_and_its_poses_are_in_free_space() {
    for name in PLANS {
        let path = plan(name);
        let p = read_plan(&path).unwrap();
        assert!(!p.poses.is_empty(), "{name}");
        let world = World::from_plan(&p);
        assert!(world.outline_closed(), "{name}: outer walls closed");
        for (i, pose) in p.poses.iter().enumerate() {
            let q = nalgebra::Point2::new(pose.x, pose.y);
            assert!(is_free(&world, &q, 0.5, 30.0), "{name}: pose {i}");
        }
        let recs = records(&simulate(&[path.to_str().unwrap(), "--scans", "3"]));
        assert_eq!(recs.len(), p.poses.len() * 3, "{name}");
    }
    let two_rooms = read_plan(&plan("two_rooms")).unwrap();
    assert_eq!(two_rooms.poses.len(), 320);
    for w in two_rooms.poses.windows(2) {
        let step = (w[1].x - w[0].x).hypot(w[1].y - w[0].y);
        assert!((0.05..=0.3).contains(&step), "two_rooms step {step}");
    }
}

#[test]
fn bad_plans_name_the_file_and_json_path() {
    let cases = [
        (
            "one_point.wall",
            r#"{"version": "w0.1", "wallheight": 3, "walls": [[[0,0],[4,0]], [[1,1]]]}"#,
            "walls[1]",
        ),
        (
            "zero_height.wall",
            r#"{"version": "w0.1", "wallheight": 0, "walls": [[[0,0],[4,0]]]}"#,
            "wallheight",
        ),
        (
            "bad_pose.wall",
            r#"{"wallheight": 3, "walls": [[[0,0],[4,0]]], "poses": [[1,1,0.4,0,0]]}"#,
            "poses[0]",
        ),
    ];
    for (name, text, where_) in cases {
        let f = TempFile::new(name, text);
        let out = simulate(&[f.0.to_str().unwrap()]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{name}");
        let want = format!("{}:{where_}", f.0.display());
        assert!(err.contains(&want), "{name}: {err}");
        assert!(!err.contains("panicked"), "{name}: {err}");
    }
}

#[test]
fn missing_file_no_poses_and_bad_flags_fail_cleanly() {
    let out = simulate(&["/nonexistent/plan.wall"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("/nonexistent/plan.wall"));

    let f = TempFile::new(
        "no_poses.wall",
        r#"{"wallheight": 3, "walls": [[[0,0],[4,0],[4,4],[0,4],[0,0]]]}"#,
    );
    let out = simulate(&[f.0.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("no poses"), "{err}");
    // ... but random poses work in it.
    let recs = records(&simulate(&[f.0.to_str().unwrap(), "--random", "3"]));
    assert_eq!(recs.len(), 9);

    for args in [
        &["--rays", "0"][..],
        &["--hinge-offset", "1,2"],
        &["--sigma", "-1"],
        &["--random", "2", "--clearance", "3"],
    ] {
        let out = simulate(&[&[f.0.to_str().unwrap()][..], args].concat());
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?}");
        assert!(
            !err.is_empty() && !err.contains("panicked"),
            "{args:?}: {err}"
        );
    }
}

#[test]
fn zero_random_poses_are_refused_not_written_as_nothing() {
    let out = simulate(&[plan("office").to_str().unwrap(), "--random", "0"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(out.stdout.is_empty());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--random 0: no poses to simulate"), "{err}");
}

#[test]
fn scans_of_a_pose_at_one_elevation_are_refused() {
    let office = plan("office");
    let office = office.to_str().unwrap();
    for (args, want) in [
        (
            &["--step", "0"][..],
            "--step 0 puts all 3 scans of a pose at one elevation",
        ),
        (
            &["--elevations", "5,5,5"],
            "--elevations lists 5 degrees 3 times; the scans of a pose must lie at distinct",
        ),
        (&["--elevations", "-5,0,-5"], "lists -5 degrees 2 times"),
    ] {
        let out = simulate(&[&[office][..], args].concat());
        assert_eq!(out.status.code(), Some(1), "{args:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(want), "{args:?}: {err}");
    }
    // One scan per pose is one elevation, as a 2D log's.
    assert_eq!(
        records(&simulate(&[office, "--step", "0", "--scans", "1"])).len(),
        30
    );
}

#[test]
fn a_negative_step_is_a_value_not_a_flag() {
    let office = plan("office");
    let office = office.to_str().unwrap();
    // From +5 down to -5 degrees.
    let elevations: Vec<f64> = records(&simulate(&[office, "--random", "2", "--step", "-5"]))
        .iter()
        .map(|r| r["elevation"].as_f64().unwrap().to_degrees())
        .collect();
    assert_eq!(elevations.len(), 6);
    for (got, want) in elevations.iter().zip([5.0, 0.0, -5.0].iter().cycle()) {
        assert!((got - want).abs() < 1e-9, "{elevations:?}");
    }
    // eval accuracy wants a positive step and says so itself, not clap's advice.
    let out = bin()
        .args(["eval", "accuracy", office, "--poses", "1", "--step", "-5"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("the step be positive"), "{err}");
}

#[test]
fn old_flag_spellings_and_the_seed_default_still_hold() {
    let office = plan("office");
    let office = office.to_str().unwrap();
    let run = |args: &[&str]| {
        let out = simulate(&[&[office, "--random", "4"][..], args].concat());
        assert!(
            out.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        out.stdout
    };
    // `--noise` is the hidden old name of `--sigma`: the same bytes.
    let sigma = run(&["--sigma", "0.03"]);
    assert_eq!(sigma, run(&["--noise", "0.03"]));
    assert_ne!(sigma, run(&["--sigma", "0.01"]));
    // One seed default in every command: 1 (simulate's was 0).
    let default = run(&[]);
    assert_eq!(default, run(&["--seed", "1"]));
    assert_ne!(default, run(&["--seed", "0"]));
}
