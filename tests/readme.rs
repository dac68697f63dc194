//! Every `levelscan` command the README shows runs as written: the fenced examples in order
//! (they chain: simulate writes what level reads), then the inline ones of "From a robot", in
//! a scratch directory with the repository's `examples/`, by bash (the README's brace
//! expansions), with the built binary first on PATH. Commands on data a reader must fetch
//! first (the real CARMEN logs) are listed in `NEEDS_DOWNLOAD` and skipped, by name.

use std::path::Path;
use std::process::Command;

/// Commands that read files not shipped with levelscan (see the README's eval section).
const NEEDS_DOWNLOAD: &[&str] = &["intel.log.gz"];

/// The README's `levelscan` command lines: fenced blocks first, then inline code spans.
fn commands(readme: &str) -> Vec<String> {
    let mut fenced = Vec::new();
    let mut inline = Vec::new();
    let mut in_block = false;
    for line in readme.lines() {
        if line.trim_start().starts_with("```") {
            in_block = !in_block;
            continue;
        }
        if in_block {
            if line.trim_start().starts_with("levelscan ") {
                fenced.push(line.trim().to_string());
            }
            continue;
        }
        for (i, span) in line.split('`').enumerate() {
            // Odd pieces are inside backticks.
            if i % 2 == 1 && span.starts_with("levelscan ") && !span.contains("...") {
                inline.push(span.to_string());
            }
        }
    }
    fenced.extend(
        inline
            .into_iter()
            .filter(|c| c.contains(" -o ") || c.starts_with("levelscan info")),
    );
    fenced
}

#[test]
fn every_readme_command_runs_as_written() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let readme = std::fs::read_to_string(root.join("README.md")).unwrap();
    let cmds = commands(&readme);
    assert!(cmds.len() >= 15, "found only {} commands", cmds.len());
    let dir = std::env::temp_dir().join(format!("levelscan-readme-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let link = dir.join("examples");
    if !link.exists() {
        std::os::unix::fs::symlink(root.join("examples"), &link).unwrap();
    }
    let bin_dir = Path::new(env!("CARGO_BIN_EXE_levelscan")).parent().unwrap();
    let path = format!(
        "{}:{}",
        bin_dir.display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let mut ran = 0;
    for cmd in &cmds {
        if NEEDS_DOWNLOAD.iter().any(|f| cmd.contains(f)) {
            eprintln!("skipped (needs a download): {cmd}");
            continue;
        }
        let out = Command::new("bash")
            .args(["-c", &format!("set -o pipefail; {cmd}")])
            .current_dir(&dir)
            .env("PATH", &path)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "README command failed: {cmd}\n{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            !err.contains("warning:"),
            "README command warns: {cmd}\n{err}"
        );
        ran += 1;
    }
    assert!(ran >= 14);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn the_readme_opens_with_the_two_commands() {
    let readme =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/README.md")).unwrap();
    let first_block: Vec<&str> = readme
        .split("```")
        .nth(1)
        .unwrap()
        .lines()
        .filter(|l| !l.trim().is_empty())
        .collect();
    assert_eq!(
        first_block,
        ["cargo run --release -- demo", "cargo test --release"]
    );
}
