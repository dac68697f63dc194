//! A file of the wrong kind is named as what it is, with what the command wants (issue: "wrong
//! kind of file, misleading message"): one line, exit 1, no parser complaint about column 1.

mod cli_support;

use cli_support::bin;

fn plan() -> String {
    concat!(env!("CARGO_MANIFEST_DIR"), "/examples/plans/office.wall").to_string()
}

fn fails_with(args: &[&str], wanted: &[&str]) {
    let out = bin().args(args).output().unwrap();
    assert_eq!(out.status.code(), Some(1), "{args:?}");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.trim().lines().count(), 1, "one line: {err}");
    for w in wanted {
        assert!(err.contains(w), "{args:?}: {err:?} lacks {w:?}");
    }
}

fn scans(dir: &std::path::Path) -> String {
    let path = dir.join("scans.jsonl");
    let p = path.to_str().unwrap().to_string();
    let plan = plan();
    let out = bin()
        .args(["simulate", &plan, "--random", "3", "-o", &p])
        .output()
        .unwrap();
    assert!(out.status.success());
    p
}

#[test]
fn a_floor_plan_given_for_scans_is_named() {
    let plan = plan();
    for cmd in ["level", "match", "info"] {
        fails_with(
            &[cmd, &plan],
            &["office.wall", "floor plan", "levelscan simulate"],
        );
    }
}

#[test]
fn scans_or_a_bag_given_for_a_plan_are_named() {
    let dir = std::env::temp_dir().join(format!("levelscan-kinds-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let s = scans(&dir);
    fails_with(
        &["simulate", &s],
        &["scans.jsonl", "scan file", "floor plan (.wall) is wanted"],
    );
    let bag = dir.join("run.mcap");
    let b = bag.to_str().unwrap();
    let plan = plan();
    assert!(
        bin()
            .args(["simulate", &plan, "--random", "2", "-o", b])
            .output()
            .unwrap()
            .status
            .success()
    );
    fails_with(&["simulate", b], &["run.mcap", "MCAP bag", "floor plan"]);
    // Multi-elevation scans are not a 2D log for eval real.
    fails_with(
        &["eval", "real", &s],
        &["several scans per pose", "level them first"],
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_2d_carmen_log_given_to_level_is_named() {
    let dir = std::env::temp_dir().join(format!("levelscan-kinds-c-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let log = dir.join("run.log");
    std::fs::write(
        &log,
        "# CARMEN log\nFLASER 3 1.0 2.0 3.0 0 0 0 0 0 0 1.0 host 1.0\n",
    )
    .unwrap();
    fails_with(
        &["level", log.to_str().unwrap()],
        &["run.log", "CARMEN log", "match reads it"],
    );
    let bin_file = dir.join("noise.bin");
    std::fs::write(&bin_file, [0u8, 1, 2, 3, 200, 17, 0, 9]).unwrap();
    fails_with(
        &["level", bin_file.to_str().unwrap()],
        &["noise.bin", "unknown kind"],
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn an_image_given_for_scans_is_named_alike_by_every_command() {
    let dir = cli_support::TempDir::new("png");
    let png = dir.0.join("photo.png");
    // A PNG's signature and the start of its header chunk.
    std::fs::write(
        &png,
        b"\x89PNG\r\n\x1a\n\0\0\0\rIHDR\0\0\x01\0\0\0\x01\0\x08\x06\0\0\0",
    )
    .unwrap();
    let png = png.to_str().unwrap();
    for cmd in ["level", "info", "match", "map"] {
        fails_with(&[cmd, png], &["photo.png", "unknown kind"]);
    }
}

/// `bytes` with a UTF-8 byte order mark in front, as Windows editors save text.
fn with_bom(bytes: &[u8]) -> Vec<u8> {
    [b"\xEF\xBB\xBF".as_slice(), bytes].concat()
}

#[test]
fn a_byte_order_mark_is_skipped_by_every_command() {
    let dir = cli_support::TempDir::new("bom");
    let plan_bytes = std::fs::read(plan()).unwrap();
    let plan = dir.0.join("office.wall");
    std::fs::write(&plan, with_bom(&plan_bytes)).unwrap();
    let plan = plan.to_str().unwrap();
    let scans = dir.0.join("scans.jsonl");
    let out = bin()
        .args(["simulate", plan, "--random", "2", "--scans", "3"])
        .output()
        .unwrap();
    cli_support::assert_ran(&out);
    std::fs::write(&scans, with_bom(&out.stdout)).unwrap();
    let scans = scans.to_str().unwrap();
    let leveled = cli_support::run_with_stdin(&["level"], &out.stdout);
    cli_support::assert_ran(&leveled);
    let level = dir.0.join("level.jsonl");
    std::fs::write(&level, with_bom(&leveled.stdout)).unwrap();
    let level = level.to_str().unwrap();
    let html = dir.0.join("view.html");
    let html = html.to_str().unwrap();
    for args in [
        vec!["level", scans],
        vec!["info", scans],
        vec!["match", level],
        vec!["view", plan, "-o", html],
        vec!["view", scans, "-o", html],
        vec![
            "eval", "accuracy", plan, "--poses", "2", "--scans", "3", "--sigma", "0.01",
        ],
    ] {
        let out = bin().args(&args).output().unwrap();
        assert!(
            out.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    // On standard input too (level reads it by its own parallel reader).
    let leveled = cli_support::run_with_stdin(&["level"], &with_bom(&out.stdout));
    assert_eq!(cli_support::records(&leveled).len(), 2);
}
