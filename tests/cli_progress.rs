//! Progress bars on standard error for the long runs, drawn only on a terminal: run under a
//! pseudo-terminal (`script`) the bar shows and is cleared at the end; with standard error a
//! pipe, nothing of it appears (issue 25 item 8).

mod cli_support;
use cli_support::*;

use std::path::{Path, PathBuf};
use std::process::Command;

fn plan(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("examples/plans/{name}.wall"))
}

/// What a terminal would have received from `levelscan ARGS` (stdout to /dev/null), or None
/// without util-linux `script` to give it a pseudo-terminal.
fn on_a_terminal(args: &[&str]) -> Option<String> {
    let status = Command::new("script").arg("--version").output().ok()?;
    if !status.status.success() {
        return None;
    }
    let line = format!(
        "{} {} > /dev/null",
        env!("CARGO_BIN_EXE_levelscan"),
        args.join(" ")
    );
    let out = Command::new("script")
        .args(["-qec", &line, "/dev/null"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
    Some(String::from_utf8_lossy(&out.stdout).to_string())
}

fn accuracy_args(plan: &str) -> Vec<&str> {
    let a = "eval accuracy PLAN --poses 60 --scans 3 --sigma 0.01 --estimator robust";
    a.split(' ')
        .map(|t| if t == "PLAN" { plan } else { t })
        .collect()
}

#[test]
fn eval_accuracy_shows_a_bar_on_a_terminal_only() {
    let office = plan("office");
    let args = accuracy_args(office.to_str().unwrap());
    let piped = bin().args(&args).output().unwrap();
    assert!(piped.status.success());
    let err = String::from_utf8_lossy(&piped.stderr);
    assert!(!err.contains("/60"), "a bar on a pipe: {err:?}");
    let Some(tty) = on_a_terminal(&args) else {
        eprintln!("no `script` here: the terminal half skipped");
        return;
    };
    // indicatif redraws in place: the last frames, then the line cleared (ESC [2K).
    assert!(tty.contains("eval accuracy ["), "{tty:?}");
    assert!(tty.contains("/60"), "{tty:?}");
    assert!(
        tty.trim_end().ends_with("\u{1b}[2K"),
        "not cleared: {tty:?}"
    );
}

#[test]
fn level_counts_poses_on_a_terminal_and_keeps_a_pipe_to_its_summary() {
    let dir = std::env::temp_dir().join(format!("levelscan-progress-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let scans = dir.join("scans.jsonl");
    let office = plan("office");
    let sim = bin()
        .args([
            "simulate",
            office.to_str().unwrap(),
            "--random",
            "1500",
            "--rays",
            "91",
        ])
        .args(["-o", scans.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(sim.status.success());
    let piped = bin()
        .args(["level", scans.to_str().unwrap(), "-o", "/dev/null"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&piped.stderr).to_string();
    assert_eq!(err.lines().count(), 1, "{err:?}");
    assert!(err.starts_with("levelscan level: 1500 poses: "), "{err:?}");
    if let Some(tty) = on_a_terminal(&["level", scans.to_str().unwrap()]) {
        assert!(tty.contains(" poses ("), "no counter: {tty:?}");
        // The summary comes after the counter was cleared.
        let last = tty.trim_end().rsplit("\u{1b}[2K").next().unwrap();
        assert!(last.starts_with("levelscan level: 1500 poses: "), "{tty:?}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
