//! End-to-end runs of `levelscan view`: what it sniffs, what the page embeds, and its errors.

mod cli_support;
use cli_support::*;

use serde_json::{Value, json};
use std::path::{Path, PathBuf};
use std::process::Output;

fn temp_dir(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("levelscan-cli-view-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn run(args: &[&str], stdin: Option<&str>) -> Output {
    run_with_stdin(args, stdin.unwrap_or("").as_bytes())
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// The scene JSON embedded in a viewer page.
fn embedded_scene(page: &str) -> Value {
    let open = "<script type=\"application/json\" id=\"viewer-data\">";
    let start = page.find(open).expect("scene data element") + open.len();
    let end = start + page[start..].find("</script>").unwrap();
    serde_json::from_str(&page[start..end]).expect("scene data is JSON")
}

fn layer<'a>(scene: &'a Value, id: &str) -> Option<&'a Value> {
    scene["layers"].as_array()?.iter().find(|l| l["id"] == id)
}

/// Point `i` of a flat `[x, y, z, ...]` millimetre array.
fn xyz(flat: &Value, i: usize) -> [i64; 3] {
    let a = flat.as_array().unwrap();
    [0, 1, 2].map(|d| a[3 * i + d].as_i64().unwrap())
}

fn points(layer: &Value) -> usize {
    layer["lines"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| l.as_array().unwrap().len() / 3)
        .sum()
}

const PLAN: &str = r#"{"version": "w0.1", "wallheight": 2.5,
  "walls": [[[0, 0], [8, 0], [8, 6], [0, 6], [0, 0]]]}"#;

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

/// Three scans of one pose: 3 rays each, the middle one invalid in the first scan.
fn raw_scans() -> String {
    let mut s = String::new();
    for (k, e) in [-0.1, 0.0, 0.1].into_iter().enumerate() {
        let readings = if k == 0 {
            json!([2.0, null, 2.0])
        } else {
            json!([2.0, 2.05, 2.0])
        };
        let line = json!({"sequence": 4, "nrays": 3, "elevation": e, "min_theta": -0.1,
            "max_theta": 0.1, "readings": readings, "true_pose": [1, 2, 0.45, 0.3, 0.05, 0.0]});
        s.push_str(&format!("{line}\n"));
    }
    s
}

#[test]
fn view_sniffs_plan_and_scans_in_any_order_and_writes_an_offline_page() {
    let dir = temp_dir("sniff");
    let plan = write(&dir, "room.wall", PLAN);
    let scans = write(&dir, "scans.jsonl", &raw_scans());
    let page_path = dir.join("v.html");
    // The plan given as a plain FILE, before the scans: sniffed, not told.
    let out = run(
        &[
            "view",
            plan.to_str().unwrap(),
            scans.to_str().unwrap(),
            "-o",
            page_path.to_str().unwrap(),
        ],
        None,
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let page = std::fs::read_to_string(&page_path).unwrap();
    assert!(page.starts_with("<!DOCTYPE html>"));
    // Offline: nothing is fetched from anywhere.
    for needle in ["http://", "https://", "src=\"", "<link"] {
        assert!(!page.contains(needle), "page refers out: {needle}");
    }
    let scene = embedded_scene(&page);
    assert_eq!(
        layer(&scene, "plan").unwrap()["faces"]
            .as_array()
            .unwrap()
            .len(),
        4
    );
    // 8 valid rays; the invalid ray breaks the first scan's line into two lone points, so
    // 8 points in 4 lines.
    let scans_layer = layer(&scene, "scans").unwrap();
    assert_eq!(scans_layer["lines"].as_array().unwrap().len(), 4);
    assert_eq!(points(scans_layer), 8);
    assert_eq!(
        layer(&scene, "poses").unwrap()["cones"][0]["t"],
        json!([1000, 2000, 450])
    );
    assert_eq!(scene["top_down"], json!(false));
}

#[test]
fn view_reads_level_output_polygons_and_pseudo_level_scan() {
    let dir = temp_dir("level");
    let record = json!({"sequence": 0, "nrays": 3, "theta": [-0.1, 0.0, 0.1],
        "readings": [3.0, 3.0, 3.0], "valid": [1, 1, 1], "true_pose": [0, 0, 0],
        "level": {"status": "ok", "reason": null, "theta_x": 0.0, "theta_y": 0.0,
                  "sigma_x": 0.001, "sigma_y": 0.001, "up": [0, 0, 1], "polygons": 2,
                  "base_elevation": 0.0},
        "wall_polygons": [[[3, -1, -0.2], [3, 1, -0.2], [3, 1, 0.2], [3, -1, 0.2]],
                          [[3, 1, -0.2], [3, 2, -0.2], [3, 2, 0.2], [3, 1, 0.2]]]});
    let input = write(&dir, "level.jsonl", &format!("{record}\n"));
    let page_path = dir.join("l.html");
    let out = run(
        &[
            "view",
            input.to_str().unwrap(),
            "-o",
            page_path.to_str().unwrap(),
            "--height",
            "1",
        ],
        None,
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let scene = embedded_scene(&std::fs::read_to_string(&page_path).unwrap());
    let polys = layer(&scene, "polygons").unwrap()["faces"]
        .as_array()
        .unwrap()
        .clone();
    assert_eq!(polys.len(), 2);
    // Level attitude zero and --height 1: robot-frame z -0.2 is 0.8 m above the floor.
    assert_eq!(xyz(&polys[0]["p"], 0), [3000, -1000, 800]);
    assert_ne!(polys[0]["c"], polys[1]["c"], "polygons alternate colours");
    let pseudo = layer(&scene, "pseudo").unwrap();
    assert_eq!(points(pseudo), 3);
    assert_eq!(xyz(&pseudo["lines"][0], 1), [3000, 0, 1000]);
}

#[test]
fn view_of_a_csm_log_on_stdin_opens_top_down_at_the_estimates() {
    let log = "{ \"nrays\": 2, \"min_theta\": 0, \"max_theta\": 0.2, \
               \"readings\": [1, 1], \"odometry\": [0, 0, 0], \"estimate\": [5, 0, 0], \
               \"true_pose\": [0, 0, 0], \"true_alpha\": [0, 0] }\n\
               { \"nrays\": 2, \"min_theta\": 0, \"max_theta\": 0.2, \
               \"readings\": [1, 1], \"odometry\": [1, 0, 0], \"estimate\": [null, null, null] }\n";
    let out = run(&["view", "-o", "-"], Some(log));
    assert!(out.status.success(), "{}", stderr(&out));
    let scene = embedded_scene(&String::from_utf8(out.stdout).unwrap());
    assert_eq!(scene["top_down"], json!(true));
    let matched = layer(&scene, "matched").unwrap();
    // First record at its estimate; the second has an unknown estimate, so a raw record at its
    // odometry.
    assert_eq!(xyz(&matched["lines"][0], 0), [6000, 0, 0]);
    assert_eq!(points(layer(&scene, "scans").unwrap()), 2);
}

#[test]
fn view_of_a_bad_scan_line_names_file_and_line() {
    let dir = temp_dir("bad");
    let good = raw_scans();
    let first = good.lines().next().unwrap();
    let bad = write(&dir, "bad.jsonl", &format!("{first}\n{{\"nrays\": 0}}\n"));
    let out = run(
        &[
            "view",
            bad.to_str().unwrap(),
            "-o",
            dir.join("x.html").to_str().unwrap(),
        ],
        None,
    );
    assert!(!out.status.success());
    let err = stderr(&out);
    assert!(err.starts_with(&format!("{}:2:", bad.display())), "{err}");
    assert!(!err.contains("panicked"));
    assert!(!dir.join("x.html").exists(), "no page for bad input");
}

#[test]
fn view_of_a_bad_plan_names_the_json_path() {
    let dir = temp_dir("badplan");
    let plan = write(
        &dir,
        "p.wall",
        r#"{"version": "w0.1", "wallheight": -1, "walls": [[[0, 0], [1, 0]]]}"#,
    );
    let out = run(
        &[
            "view",
            "--plan",
            plan.to_str().unwrap(),
            "-o",
            dir.join("x.html").to_str().unwrap(),
        ],
        None,
    );
    assert!(!out.status.success());
    let err = stderr(&out);
    assert!(
        err.starts_with(&format!("{}:wallheight:", plan.display())),
        "{err}"
    );
}

#[test]
fn view_of_a_missing_file_fails_with_its_name() {
    let out = run(&["view", "/nonexistent/scans.jsonl", "-o", "-"], None);
    assert!(!out.status.success());
    assert!(
        stderr(&out).starts_with("/nonexistent/scans.jsonl:"),
        "{}",
        stderr(&out)
    );
}

#[test]
fn view_decimates_big_input_and_says_so() {
    let mut text = String::new();
    for seq in 0..20 {
        let line = json!({"sequence": seq, "nrays": 50, "elevation": 0.0, "min_theta": -1,
            "max_theta": 1, "readings": vec![2.0; 50], "true_pose": [seq, 0, 0.4, 0, 0, 0]});
        text.push_str(&format!("{line}\n"));
    }
    let out = run(&["view", "--max-points", "250", "-o", "-"], Some(&text));
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stderr(&out).contains("1 pose in 4"), "{}", stderr(&out));
    let scene = embedded_scene(&String::from_utf8(out.stdout).unwrap());
    assert_eq!(points(layer(&scene, "scans").unwrap()), 250);
    assert!(scene["notes"][0].as_str().unwrap().contains("1 pose in 4"));
}

#[test]
fn view_reads_a_carmen_log_at_its_corrected_poses() {
    // FLASER n r1..rn x y theta odom_x odom_y odom_theta timestamp host logger_timestamp
    let log = format!(
        "# a comment\nFLASER 19 {} 1.0 2.0 0.0 1.1 2.1 0.0 10.0 host 10.0\n",
        vec!["2.0"; 19].join(" ")
    );
    let out = run(&["view", "-o", "-"], Some(&log));
    assert!(out.status.success(), "{}", stderr(&out));
    let scene = embedded_scene(&String::from_utf8(out.stdout).unwrap());
    assert_eq!(scene["top_down"], json!(true));
    // The middle beam (bearing 0) of the scan at the corrected pose (1, 2, heading 0).
    let scans = layer(&scene, "scans").unwrap();
    assert_eq!(points(scans), 19);
    assert_eq!(xyz(&scans["lines"][0], 9), [3000, 2000, 0]);
}

#[test]
fn a_long_matched_log_keeps_few_cones_its_whole_path_and_a_reference() {
    // 250 matched 2D records (CSM layout) along x, their true_pose 10 cm to the side.
    let mut text = String::new();
    for k in 0..250 {
        let x = f64::from(k) * 0.1;
        let line = json!({"nrays": 2, "theta": [0.0, 0.1], "readings": [1.0, 1.0],
                          "estimate": [x, 0.0, 0.0], "true_pose": [x, 0.1, 0.0]});
        text.push_str(&format!("{line}\n"));
    }
    let dir = temp_dir("long");
    let log = write(&dir, "matched.jsonl", &text);
    let page = dir.join("v.html");
    let out = run(
        &[
            "view",
            log.to_str().unwrap(),
            "--max-cones",
            "50",
            "-o",
            page.to_str().unwrap(),
        ],
        None,
    );
    assert!(out.status.success(), "{}", stderr(&out));
    // One pose in ceil(250 / 49) = 6 (0, 6, ..., 246) and the last: 43 cones, at most 50.
    assert!(
        stderr(&out).contains("250 poses: a cone at 1 pose in 6"),
        "{}",
        stderr(&out)
    );
    let scene = embedded_scene(&std::fs::read_to_string(&page).unwrap());
    assert_eq!(
        layer(&scene, "poses").unwrap()["cones"]
            .as_array()
            .unwrap()
            .len(),
        43
    );
    let path = layer(&scene, "path").unwrap();
    assert_eq!(points(path), 250);
    assert_eq!(path["label"], "Robot path (estimate, purple)");
    let reference = layer(&scene, "reference").unwrap();
    assert_eq!(reference["label"], "Reference path (true_pose, green)");
    assert_eq!(xyz(&reference["lines"][0], 1), [100, 100, 0]);
}

#[test]
fn without_o_the_page_goes_to_standard_output_like_every_command() {
    let log = "{ \"nrays\": 2, \"min_theta\": 0, \"max_theta\": 0.2, \"readings\": [1, 1], \
               \"estimate\": [0, 0, 0] }\n";
    let dir = temp_dir("stdout");
    let out = bin()
        .arg("view")
        .current_dir(&dir)
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .and_then(|mut child| {
            use std::io::Write;
            child.stdin.take().unwrap().write_all(log.as_bytes())?;
            child.wait_with_output()
        })
        .unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    let page = String::from_utf8(out.stdout).unwrap();
    assert!(
        page.starts_with("<!DOCTYPE html>"),
        "{}",
        &page[..page.len().min(80)]
    );
    assert!(layer(&embedded_scene(&page), "matched").is_some());
    // No file appears behind the user's back (it used to be view.html).
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 0);
    // `-o -` is the same page.
    assert_eq!(run(&["view", "-o", "-"], Some(log)).stdout, page.as_bytes());
}
