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

/// Every subcommand path (`simulate`, `eval accuracy`, ...), found from the help texts.
fn all_subcommands() -> Vec<Vec<String>> {
    let mut paths = subcommands(&[]);
    let nested: Vec<Vec<String>> = paths
        .iter()
        .flat_map(|p| {
            let p: Vec<&str> = p.iter().map(String::as_str).collect();
            subcommands(&p)
        })
        .collect();
    paths.retain(|p| !nested.iter().any(|n| n[0] == p[0]));
    paths.extend(nested);
    paths
}

/// The options of one `--help` text: (long flag, its help joined into one line, defaults
/// included). Reads both of clap's layouts: the long one (flag on its own line, help indented
/// below) and the compact one (help after two spaces on the flag's line).
fn options(help: &str) -> Vec<(String, String)> {
    let mut found: Vec<(String, String)> = Vec::new();
    let mut in_options = false;
    for line in help.lines() {
        if line.starts_with("Options:") {
            in_options = true;
            continue;
        }
        if !in_options || line.trim().is_empty() {
            continue;
        }
        let indent = line.len() - line.trim_start().len();
        let text = line.trim();
        if indent <= 6 && text.starts_with('-') {
            let (spec, help) = text.split_once("  ").unwrap_or((text, ""));
            let flag = spec
                .split([' ', ','])
                .find(|t| t.starts_with("--"))
                .unwrap_or_else(|| panic!("no long flag in {line:?}"));
            found.push((flag.to_string(), help.trim().to_string()));
        } else if let Some((_, h)) = found.last_mut() {
            if !h.is_empty() {
                h.push(' ');
            }
            h.push_str(text);
        }
    }
    found
}

/// One vocabulary across commands: a flag that several subcommands take means the same thing,
/// in the same unit, in each. A row here is a flag whose help differs from command to command
/// (each adds its own default or detail): every command's help must begin with the meaning.
/// A shared flag without a row must have the very same help everywhere (one definition).
const VOCABULARY: &[(&str, &str)] = &[
    ("--seed", "Random seed"),
    ("--sigma", "Range noise (m): the standard deviation"),
    (
        "--max-range",
        "Scanner's maximum range (m): a reading at or beyond it is no return",
    ),
    ("--output", "Output file"),
    ("--plan", "A floor plan"),
    ("--out", "Directory for"),
    ("--format", "Output format"),
    ("--estimator", "Up-vector estimator"),
    ("--scans", "Scans per pose"),
    ("--step", "Elevation step between scans (deg)"),
    (
        "--tilt",
        "Random poses: roll and pitch uniform in +-TILT (deg)",
    ),
    (
        "--height",
        "Scanner height above the floor, the pose's z (m)",
    ),
    (
        "--adaptive",
        "The adaptive robot, cleverRobot (paper sect. 7.2.2)",
    ),
];

#[test]
fn one_flag_one_meaning_across_subcommands() {
    let paths = all_subcommands();
    assert!(paths.len() >= 10, "found only {paths:?}");
    // flag -> [(command, help)]
    let mut uses: std::collections::BTreeMap<String, Vec<(String, String)>> = Default::default();
    for path in &paths {
        let out = bin().args(path).arg("--help").output().unwrap();
        assert!(out.status.success(), "{path:?} --help failed");
        let text = String::from_utf8(out.stdout).unwrap();
        for (flag, help) in options(&text) {
            if flag != "--help" && flag != "--version" {
                uses.entry(flag).or_default().push((path.join(" "), help));
            }
        }
    }
    for (flag, meaning) in VOCABULARY {
        let Some(list) = uses.get(*flag) else {
            panic!("{flag}: in the vocabulary but no subcommand takes it");
        };
        for (command, help) in list {
            assert!(
                help.starts_with(meaning),
                "levelscan {command} {flag}: help should begin with {meaning:?}, is {help:?}"
            );
        }
    }
    for (flag, list) in &uses {
        if list.len() < 2 || VOCABULARY.iter().any(|(f, _)| f == flag) {
            continue;
        }
        let (first_command, first) = &list[0];
        for (command, help) in &list[1..] {
            assert_eq!(
                help, first,
                "{flag} reads differently in `{first_command}` and `{command}`: make the help \
                 one (or add a vocabulary row that both begin with)"
            );
        }
    }
    // One seed default: runs without --seed draw the same numbers in every command.
    for (command, help) in &uses["--seed"] {
        assert!(
            help.ends_with("[default: 1]"),
            "levelscan {command} --seed: the default is 1 everywhere, help is {help:?}"
        );
    }
    // The old spellings still parse but are not shown: one name per meaning in --help.
    for old in ["--noise", "--estimators"] {
        assert!(!uses.contains_key(old), "{old} is shown in --help");
    }
}
