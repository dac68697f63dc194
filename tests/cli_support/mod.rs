//! Running the `levelscan` binary from the command-line tests.
#![allow(dead_code)]

use serde_json::Value;
use std::io::Write;
use std::process::{Command, Output, Stdio};

/// The binary under test.
pub fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_levelscan"))
}

/// Runs `levelscan ARGS` with `stdin` as standard input. The input is fed from a thread:
/// the commands stream, so they write output while input is still coming.
pub fn run_with_stdin(args: &[&str], stdin: &[u8]) -> Output {
    let mut child = bin()
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut pipe = child.stdin.take().unwrap();
    let data = stdin.to_vec();
    let feeder = std::thread::spawn(move || pipe.write_all(&data));
    let out = child.wait_with_output().unwrap();
    feeder.join().unwrap().unwrap();
    out
}

/// Fails the test with the run's standard error unless it succeeded.
pub fn assert_ran(out: &Output) {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The JSON Lines records a successful run wrote (fails the test with its stderr otherwise).
pub fn records(out: &Output) -> Vec<Value> {
    assert_ran(out);
    String::from_utf8(out.stdout.clone())
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

/// A JSON array of numbers as `f64`s (panics on anything else: a test's input).
pub fn floats(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap_or_else(|| panic!("not an array: {v}"))
        .iter()
        .map(|x| x.as_f64().unwrap_or_else(|| panic!("not a number: {x}")))
        .collect()
}

/// A directory removed when the test ends.
pub struct TempDir(pub std::path::PathBuf);

impl TempDir {
    /// A fresh directory under the system's temporary one, named after `name` and the process.
    pub fn new(name: &str) -> TempDir {
        let dir = std::env::temp_dir().join(format!("levelscan_{name}_{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        TempDir(dir)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// A Python 3 for the scripts under `scripts/` (standard library only): `LEVELSCAN_PYTHON`,
/// else `python3`. `None` after saying `test` is skipped, unless `LEVELSCAN_REQUIRE_INTEROP=1`
/// (CI), when a missing interpreter fails the test.
pub fn python_or_skip(test: &str) -> Option<String> {
    let python = std::env::var("LEVELSCAN_PYTHON").unwrap_or_else(|_| "python3".into());
    match Command::new(&python).arg("--version").output() {
        Ok(o) if o.status.success() => Some(python),
        _ if std::env::var("LEVELSCAN_REQUIRE_INTEROP").as_deref() == Ok("1") => {
            panic!("{test}: {python} does not run and LEVELSCAN_REQUIRE_INTEROP=1")
        }
        _ => {
            eprintln!("{test}: SKIPPED: no {python}");
            None
        }
    }
}
