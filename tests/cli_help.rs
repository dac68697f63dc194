//! `--help` as a user reads it: every subcommand's help text is plain text, without the
//! rustdoc escapes (`\[m\]`) that doc comments need but clap prints verbatim.

mod cli_support;

use cli_support::bin;

/// Subcommand paths, found from the top-level help and `eval`'s, so that a new command is
/// checked without editing this test.
fn subcommands(prefix: &[&str]) -> Vec<Vec<String>> {
    let out = bin().args(prefix).arg("--help").output().unwrap();
    assert!(out.status.success(), "{prefix:?} --help failed");
    let text = String::from_utf8(out.stdout).unwrap();
    let mut paths = Vec::new();
    let mut in_commands = false;
    for line in text.lines() {
        if line.starts_with("Commands:") {
            in_commands = true;
            continue;
        }
        if in_commands {
            let Some(name) = line.split_whitespace().next() else {
                break;
            };
            if !line.starts_with("  ") {
                break;
            }
            // A wrapped description continues deeper than the names.
            if line.starts_with("   ") {
                continue;
            }
            if name != "help" {
                let mut path: Vec<String> = prefix.iter().map(|s| s.to_string()).collect();
                path.push(name.to_string());
                paths.push(path);
            }
        }
    }
    paths
}

#[test]
fn help_text_has_no_rustdoc_escapes() {
    let mut paths = subcommands(&[]);
    assert!(paths.len() >= 8, "found only {paths:?}");
    let nested: Vec<Vec<String>> = paths
        .iter()
        .flat_map(|p| {
            let p: Vec<&str> = p.iter().map(String::as_str).collect();
            subcommands(&p)
        })
        .collect();
    assert!(
        nested.iter().any(|p| p[0] == "eval"),
        "eval's subcommands were not found"
    );
    paths.extend(nested);
    paths.push(Vec::new());
    for path in &paths {
        let out = bin().args(path).arg("--help").output().unwrap();
        assert!(out.status.success(), "{path:?} --help failed");
        let text = String::from_utf8(out.stdout).unwrap();
        for (i, line) in text.lines().enumerate() {
            assert!(
                !line.contains("\\[") && !line.contains("\\]"),
                "levelscan {} --help, line {}: {line}",
                path.join(" "),
                i + 1
            );
        }
    }
}
