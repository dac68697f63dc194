//! `level` and `match` end with one line on standard error saying how the run went (poses
//! leveled and failed by reason, scans matched and fallen back by reason), warn when most of
//! the run failed, and say so when the input held nothing; the exit stays 0 (issue 25 item 2).

mod cli_support;
use cli_support::*;

use std::path::{Path, PathBuf};
use std::process::Output;

fn plan(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("examples/plans/{name}.wall"))
}

fn simulate(args: &[&str]) -> Vec<u8> {
    let plan = plan("office");
    let mut all = vec!["simulate", plan.to_str().unwrap()];
    all.extend_from_slice(args);
    let out = bin().args(&all).output().unwrap();
    assert!(out.status.success());
    out.stdout
}

/// Standard error of a successful run, as lines.
fn stderr_lines(out: &Output) -> Vec<String> {
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(out.status.success(), "{err}");
    err.lines().map(str::to_string).collect()
}

#[test]
fn two_scans_per_pose_fail_every_pose_and_level_says_so() {
    let scans = simulate(&["--scans", "2"]);
    let out = run_with_stdin(&["level"], &scans);
    let poses = records(&out);
    assert_eq!(poses.len(), 30);
    assert!(
        poses
            .iter()
            .all(|p| p["level"]["reason"] == "too_few_scans")
    );
    assert_eq!(
        stderr_lines(&out),
        [
            "levelscan level: 30 poses: 30 failed (too_few_scans 30)",
            "levelscan level: warning: 30 of 30 poses failed, most often too_few_scans: a pose \
             needs scans at three or more distinct elevations; check the scans' elevation values \
             (simulate: --scans 3 or more, a --step other than 0)"
        ]
    );
}

/// `parallel_walls` stands for every way the gate refuses a pose; the warning says which ways
/// these were, with the hint for the most common: here a gate far tighter than 5 cm of range
/// noise allows.
#[test]
fn a_tight_gate_is_named_behind_parallel_walls() {
    let scans = simulate(&["--sigma", "0.05"]);
    let out = run_with_stdin(&["level", "--max-sigma", "0.1"], &scans);
    let failed = records(&out)
        .iter()
        .filter(|p| p["level"]["reason"] == "parallel_walls")
        .count();
    assert!(failed > 15, "{failed}");
    let lines = stderr_lines(&out);
    assert_eq!(lines.len(), 2, "{lines:?}");
    let warning = &lines[1];
    let head = "most often parallel_walls (sigma above --max-sigma ";
    let split = warning
        .split_once(head)
        .map(|(_, rest)| rest)
        .unwrap_or_else(|| panic!("{warning}"));
    // The split's counts add up to the records' parallel_walls.
    let (counts, hint) = split.split_once("): ").unwrap();
    let total: usize = counts
        .split(", ")
        .map(|part| part.rsplit(' ').next().unwrap().parse::<usize>().unwrap())
        .sum();
    assert_eq!(total, failed, "{warning}");
    assert!(
        hint.starts_with("the walls, floor and ceiling in view do not pin roll and pitch")
            && hint.ends_with("a larger --max-sigma accepts looser attitudes"),
        "{hint}"
    );
}

#[test]
fn a_good_run_gets_one_line_with_its_counts() {
    let out = run_with_stdin(&["level"], &simulate(&[]));
    let poses = records(&out);
    let ok = poses
        .iter()
        .filter(|p| p["level"]["status"] == "ok")
        .count();
    assert_eq!(ok, 30);
    assert_eq!(
        stderr_lines(&out),
        ["levelscan level: 30 poses: 30 leveled"]
    );
    let leveled: Vec<u8> = out.stdout;
    let out = run_with_stdin(&["match"], &leveled);
    let scans = records(&out);
    let status = |s: &str, r: Option<&str>| {
        scans
            .iter()
            .filter(|m| m["match"]["status"] == s && m["match"]["reason"].as_str() == r)
            .count()
    };
    let lines = stderr_lines(&out);
    assert_eq!(lines.len(), 1, "{lines:?}");
    // The line's counts are the records' own.
    let mut want = format!("levelscan match: 30 scans: {} matched", status("ok", None));
    let fallback = scans.len() - status("ok", None) - 1;
    if fallback > 0 {
        want.push_str(&format!(", {fallback} fell back to odometry ("));
    }
    assert!(lines[0].starts_with(&want), "{} vs {want}", lines[0]);
    assert!(lines[0].ends_with(", 1 first scan"), "{}", lines[0]);
    assert!(fallback * 2 <= 29, "most of the office path should match");
}

#[test]
fn unrelated_random_poses_warn_that_matching_failed() {
    // Pairwise: each scan against the previous, which here saw another part of the office
    // (metascan's map of the whole office places most of them).
    let scans = simulate(&["--random", "20", "--seed", "3"]);
    let level = run_with_stdin(&["level"], &scans);
    let out = run_with_stdin(&["match", "--mode", "pairwise"], &level.stdout);
    let scans = records(&out);
    let fallback = scans
        .iter()
        .filter(|m| m["match"]["status"] == "fallback")
        .count();
    assert!(fallback * 2 > 19, "{fallback} of 19 fell back");
    let lines = stderr_lines(&out);
    assert_eq!(lines.len(), 2, "{lines:?}");
    assert!(lines[0].starts_with("levelscan match: 20 scans: "));
    assert!(
        lines[1].starts_with(&format!(
            "levelscan match: warning: {fallback} of 19 scans fell back to odometry, most often "
        )),
        "{}",
        lines[1]
    );
    assert!(lines[1].contains("consecutive scans must overlap"));
}

#[test]
fn matching_poses_level_failed_blames_the_leveling_not_the_input() {
    // At 20 cm of noise level fails most poses; their records have no valid ray.
    let level = run_with_stdin(&["level"], &simulate(&["--sigma", "0.2", "--scans", "5"]));
    let failed = records(&level)
        .iter()
        .filter(|p| p["level"]["status"] == "failed")
        .count();
    assert!(failed * 2 > 30, "{failed} of 30 failed");
    let lines = stderr_lines(&run_with_stdin(&["match"], &level.stdout));
    assert!(
        lines[1].contains(&format!(
            "most often no_valid_rays: {failed} are poses level could not level"
        )),
        "{lines:?}"
    );
    assert!(!lines[1].contains("are the scans leveled"), "{lines:?}");
}

#[test]
fn an_empty_input_says_it_held_nothing() {
    let dir = std::env::temp_dir().join(format!("levelscan-summary-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let empty = dir.join("empty.jsonl");
    std::fs::write(&empty, b"").unwrap();
    let name = empty.to_str().unwrap();
    for command in ["level", "match"] {
        let out = bin().args([command, name]).output().unwrap();
        assert!(out.stdout.is_empty());
        assert_eq!(
            stderr_lines(&out),
            [format!(
                "levelscan {command}: warning: {name} holds no scans; nothing to {command}"
            )]
        );
        let out = run_with_stdin(&[command], b"");
        assert_eq!(
            stderr_lines(&out),
            [format!(
                "levelscan {command}: warning: <stdin> holds no scans; nothing to {command}"
            )]
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
