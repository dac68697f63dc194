//! The fuzz targets' harness (`tests/fuzz_*.rs`): proptest runs of arbitrary bytes, of
//! arbitrary text over a format's alphabet, of byte mutations of the checked-in seeds and of
//! the target's own structured mutations, with one oracle per target. (cargo-fuzz needs a
//! nightly compiler; these run on stable, in `cargo test`.)
//!
//! - Seeds: `tests/fuzz/corpus/<target>/*`, small valid inputs (see its README).
//! - Cases: [`DEFAULT_CASES`] per target in a plain `cargo test`; `LEVELSCAN_FUZZ_CASES=100000`
//!   for a long run. `LEVELSCAN_FUZZ_SEED` (a number) changes the inputs; the default seed
//!   makes every run try the same inputs.
//! - Each input must be handled within [`HANG_LIMIT`], without a panic, and pass the target's
//!   oracle. A summary line (inputs, accepted, refused, slowest) goes to standard error.
#![allow(dead_code)]

use proptest::prelude::*;
use proptest::sample::Index;
use proptest::test_runner::{Config, RngAlgorithm, TestCaseError, TestRng, TestRunner};
use std::cell::RefCell;
use std::path::Path;
use std::time::{Duration, Instant};

/// Inputs per target in a plain `cargo test`: a few seconds each.
pub const DEFAULT_CASES: u32 = 3000;
/// Longest time one input may take: its size is at most tens of kilobytes, which parse in
/// microseconds; a hang shows up as seconds.
pub const HANG_LIMIT: Duration = Duration::from_secs(5);

/// Numbers (and would-be numbers) that reach edge cases: zero signs, limits of f64, of
/// integers, of this crate's caps (`formats::limits`), and forms JSON or Rust refuse.
pub const NUMBERS: [&str; 40] = [
    "0",
    "-0",
    "1",
    "-1",
    "2",
    "0.5",
    "3.0",
    "-7",
    "1e308",
    "-1e308",
    "1e-308",
    "5e-324",
    "1e400",
    "-1e400",
    "9007199254740993",
    "18446744073709551615",
    "18446744073709551616",
    "-9223372036854775809",
    "100000",
    "100001",
    "1000000",
    "6.2831853",
    "6.2832",
    "1e7",
    "10000001",
    "9e15",
    "1e300",
    "81.91",
    "NaN",
    "nan",
    "inf",
    "-inf",
    "Infinity",
    "1e",
    ".5",
    "5.",
    "+5",
    "0x10",
    "1_0",
    "--1",
];

/// How many inputs to try.
pub fn cases() -> u32 {
    cases_or(DEFAULT_CASES)
}

/// `LEVELSCAN_FUZZ_CASES`, else `default` (for targets whose inputs cost more).
pub fn cases_or(default: u32) -> u32 {
    std::env::var("LEVELSCAN_FUZZ_CASES")
        .ok()
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or(default)
}

fn seed() -> u64 {
    std::env::var("LEVELSCAN_FUZZ_SEED")
        .ok()
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or(20_250_101)
}

/// The seed inputs of `target`, in name order.
pub fn corpus(target: &str) -> Vec<Vec<u8>> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fuzz/corpus")
        .join(target);
    let mut paths: Vec<_> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_file())
        .collect();
    paths.sort();
    let seeds: Vec<Vec<u8>> = paths.iter().map(|p| std::fs::read(p).unwrap()).collect();
    assert!(!seeds.is_empty(), "{}: no seeds", dir.display());
    seeds
}

/// What the target made of one input.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Outcome {
    /// Read whole: this many records (scans, or 1 for a plan).
    Accepted(usize),
    /// Refused with a message, after this many records.
    Refused(usize),
}

#[derive(Default)]
struct Tally {
    inputs: u64,
    accepted: u64,
    refused: u64,
    records: u64,
    slowest: Duration,
}

/// Runs `check` on [`cases`] inputs from `inputs`, failing on a panic, an oracle's error or an
/// input slower than [`HANG_LIMIT`]; prints the tally.
pub fn run(
    target: &str,
    inputs: impl Strategy<Value = Vec<u8>>,
    check: impl Fn(&[u8]) -> Result<Outcome, String>,
) {
    run_cases(target, cases(), inputs, check)
}

/// [`run`] with `cases` inputs.
pub fn run_cases(
    target: &str,
    cases: u32,
    inputs: impl Strategy<Value = Vec<u8>>,
    check: impl Fn(&[u8]) -> Result<Outcome, String>,
) {
    let config = Config {
        cases,
        failure_persistence: None,
        max_shrink_iters: 2000,
        ..Config::default()
    };
    let mut key = [0u8; 32];
    key[..8].copy_from_slice(&seed().to_le_bytes());
    let mut runner =
        TestRunner::new_with_rng(config, TestRng::from_seed(RngAlgorithm::ChaCha, &key));
    let tally = RefCell::new(Tally::default());
    let result = runner.run(&inputs, |input| {
        let start = Instant::now();
        let outcome = check(&input).map_err(TestCaseError::fail)?;
        let took = start.elapsed();
        if took > HANG_LIMIT {
            return Err(TestCaseError::fail(format!("took {took:?}")));
        }
        let mut t = tally.borrow_mut();
        t.inputs += 1;
        t.slowest = t.slowest.max(took);
        match outcome {
            Outcome::Accepted(n) => {
                t.accepted += 1;
                t.records += n as u64;
            }
            Outcome::Refused(n) => {
                t.refused += 1;
                t.records += n as u64;
            }
        }
        Ok(())
    });
    let t = tally.into_inner();
    eprintln!(
        "fuzz {target}: {} inputs (seed {}): {} read whole, {} refused with a message, {} \
         records read; slowest {:?}",
        t.inputs,
        seed(),
        t.accepted,
        t.refused,
        t.records,
        t.slowest
    );
    if let Err(e) = result {
        panic!("fuzz {target}: {e}");
    }
}

/// The inputs of a target: arbitrary bytes, arbitrary text over `alphabet`, byte mutations
/// of the seeds, and `structured` (the target's mutations of the seeds, then maybe some
/// byte mutations on top).
pub fn inputs(
    seeds: Vec<Vec<u8>>,
    alphabet: &'static str,
    tokens: &'static [&'static str],
    structured: impl Strategy<Value = Vec<u8>> + 'static,
) -> impl Strategy<Value = Vec<u8>> {
    let chars: Vec<char> = alphabet.chars().collect();
    let text = prop::collection::vec(prop::sample::select(chars), 0..400)
        .prop_map(|c| c.into_iter().collect::<String>().into_bytes());
    let mutated = (prop::sample::select(seeds), byte_edits())
        .prop_map(move |(seed, edits)| apply_byte_edits(&seed, &edits, tokens));
    let structured = (structured, prop::collection::vec(byte_edit(), 0..2))
        .prop_map(move |(bytes, edits)| apply_byte_edits(&bytes, &edits, tokens));
    prop_oneof![
        1 => prop::collection::vec(any::<u8>(), 0..400),
        1 => text,
        3 => mutated,
        4 => structured,
    ]
}

/// One byte-level edit: what, where, how much, and a choice among the tokens.
#[derive(Clone, Debug)]
pub struct ByteEdit {
    kind: u8,
    at: Index,
    len: u8,
    pick: Index,
}

fn byte_edit() -> impl Strategy<Value = ByteEdit> {
    (0u8..8, any::<Index>(), any::<u8>(), any::<Index>()).prop_map(|(kind, at, len, pick)| {
        ByteEdit {
            kind,
            at,
            len,
            pick,
        }
    })
}

/// A few byte edits.
pub fn byte_edits() -> impl Strategy<Value = Vec<ByteEdit>> {
    prop::collection::vec(byte_edit(), 1..5)
}

/// Applies `edits` in turn: flip a bit, insert or overwrite a byte, delete, duplicate or
/// move a run, insert one of `tokens` (or of [`NUMBERS`]), cut the input short.
pub fn apply_byte_edits(seed: &[u8], edits: &[ByteEdit], tokens: &[&str]) -> Vec<u8> {
    let mut b = seed.to_vec();
    for e in edits {
        let at = if b.is_empty() { 0 } else { e.at.index(b.len()) };
        let end = (at + 1 + e.len as usize % 24).min(b.len());
        match e.kind {
            0 if at < b.len() => b[at] ^= 1 << (e.len % 8),
            1 => b.insert(at, e.len),
            2 if at < b.len() => b[at] = e.len,
            3 => {
                b.drain(at..end);
            }
            4 => {
                let run = b[at..end].to_vec();
                b.splice(at..at, run);
            }
            5 => {
                let t = if e.len % 2 == 0 {
                    tokens[e.pick.index(tokens.len())]
                } else {
                    NUMBERS[e.pick.index(NUMBERS.len())]
                };
                b.splice(at..at, t.bytes());
            }
            6 if at < b.len() => b.truncate(at),
            7 => {
                // Replace the number under `at` (if any) by one of NUMBERS.
                let number = |c: u8| c.is_ascii_digit() || b"+-.eE".contains(&c);
                let start = (0..at)
                    .rev()
                    .take_while(|&i| number(b[i]))
                    .last()
                    .unwrap_or(at);
                let stop = (at..b.len())
                    .take_while(|&i| number(b[i]))
                    .last()
                    .map_or(at, |i| i + 1);
                b.splice(start..stop, NUMBERS[e.pick.index(NUMBERS.len())].bytes());
            }
            _ => {}
        }
    }
    b
}

/// Edits of a JSON value, for the JSON formats' structured mutations.
#[derive(Clone, Debug)]
pub struct JsonEdit {
    kind: u8,
    node: Index,
    pick: Index,
    count: u8,
}

/// A few JSON edits.
pub fn json_edits() -> impl Strategy<Value = Vec<JsonEdit>> {
    let edit = (0u8..10, any::<Index>(), any::<Index>(), any::<u8>()).prop_map(
        |(kind, node, pick, count)| JsonEdit {
            kind,
            node,
            pick,
            count,
        },
    );
    prop::collection::vec(edit, 1..5)
}

use serde_json::{Number, Value};

fn node_count(v: &Value) -> usize {
    1 + match v {
        Value::Array(a) => a.iter().map(node_count).sum(),
        Value::Object(m) => m.values().map(node_count).sum(),
        _ => 0,
    }
}

/// The `n`-th node of `v` in pre-order.
fn nth_node(v: &mut Value, n: usize) -> &mut Value {
    if n == 0 {
        return v;
    }
    let mut n = n - 1;
    let children: Vec<&mut Value> = match v {
        Value::Array(a) => a.iter_mut().collect(),
        Value::Object(m) => m.values_mut().collect(),
        _ => unreachable!("n counts within the node"),
    };
    for c in children {
        let size = node_count(c);
        if n < size {
            return nth_node(c, n);
        }
        n -= size;
    }
    unreachable!("n counts within the node")
}

/// A JSON number from [`NUMBERS`] where it is one JSON can hold, else an edge value.
fn edge_number(pick: usize) -> Value {
    let text = NUMBERS[pick % NUMBERS.len()];
    serde_json::from_str::<Value>(text)
        .ok()
        .filter(Value::is_number)
        .unwrap_or_else(|| Value::Number(Number::from(u64::MAX)))
}

/// Applies `edits` to `v`: replace a node by an edge number, `null`, a boolean, a string or
/// an empty container; delete, duplicate or multiply an element or member; wrap a node in an
/// array; rename a member to one of `names` (known fields: duplicates and wrong types).
pub fn apply_json_edits(v: &mut Value, edits: &[JsonEdit], names: &[&str]) {
    for e in edits {
        let n = e.node.index(node_count(v));
        let node = nth_node(v, n);
        let pick = e.pick.index(1 << 16);
        match (e.kind, &mut *node) {
            (0, _) => *node = edge_number(pick),
            (1, _) => *node = [Value::Null, Value::Bool(pick % 2 == 0)][pick % 2].clone(),
            (2, _) => *node = Value::String(["", "x", "1.5", "\u{0}", "null"][pick % 5].into()),
            (3, Value::Array(a)) if !a.is_empty() => {
                a.remove(pick % a.len());
            }
            (3, Value::Object(m)) if !m.is_empty() => {
                let key = m.keys().nth(pick % m.len()).unwrap().clone();
                m.shift_remove(&key);
            }
            (4, Value::Array(a)) if !a.is_empty() => {
                let item = a[pick % a.len()].clone();
                let copies = 1 + e.count as usize % 8;
                a.extend(std::iter::repeat_n(item, copies));
            }
            (5, Value::Array(a)) => a.truncate(pick % (a.len() + 1)),
            (6, _) => *node = Value::Array(vec![node.take()]),
            (7, Value::Object(m)) if !m.is_empty() => {
                let key = m.keys().nth(pick % m.len()).unwrap().clone();
                let value = m.shift_remove(&key).unwrap();
                m.insert(names[e.count as usize % names.len()].to_string(), value);
            }
            (8, Value::Number(x)) => {
                let f = x.as_f64().unwrap_or(0.0);
                let scaled = [-f, f * 1e300, f + 0.5, f * 1e-300, f * 7.0][pick % 5];
                *node = Number::from_f64(scaled).map_or(Value::Null, Value::Number);
            }
            (9, _) => {
                *node = [Value::Array(vec![]), Value::Object(Default::default())][pick % 2].clone()
            }
            _ => {}
        }
    }
}

/// The lines of `text` as `read_line` counts them (the last one may lack its newline).
pub fn line_count(input: &[u8]) -> usize {
    input.split(|&b| b == b'\n').count()
}

/// Checks an error message: one line, starting with `FILE:` and a location that exists.
pub fn check_message(message: &str, file: &str, lines: usize) -> Result<(), String> {
    if message.contains('\n') || message.trim().is_empty() {
        return Err(format!("not a one-line message: {message:?}"));
    }
    let rest = message
        .strip_prefix(file)
        .and_then(|r| r.strip_prefix(':'))
        .ok_or_else(|| format!("message does not name {file}: {message:?}"))?;
    if let Some((line, _)) = rest.split_once(": ")
        && let Ok(line) = line.parse::<usize>()
        && (line == 0 || line > lines)
    {
        return Err(format!(
            "line {line} of an input of {lines} lines: {message:?}"
        ));
    }
    Ok(())
}

use levelscan::formats::limits::{MAX_ANGLE, MAX_POSITION, MAX_RAYS, MAX_SECONDS};
use levelscan::formats::{parse_scan_line, write_scan};
use levelscan::geometry::Pose;
use levelscan::scan::Scan;

/// "No garbage accepted" for a scan a reader returned: the invariants the rest of the crate
/// relies on hold (`formats::limits`), and the scan written back as JSON Lines reads back as
/// the same scan.
pub fn check_scan(scan: &Scan) -> Result<(), String> {
    let n = scan.theta.len();
    let lengths = [
        Some(scan.readings.len()),
        Some(scan.valid.len()),
        scan.readings_sigma.as_ref().map(Vec::len),
        scan.hit.as_ref().map(Vec::len),
    ];
    if !(1..=MAX_RAYS).contains(&n) || lengths.iter().flatten().any(|&l| l != n) {
        return Err(format!("{n} rays, per-ray arrays of {lengths:?}"));
    }
    let angle = |v: f64| v.is_finite() && v.abs() <= MAX_ANGLE;
    if !scan.theta.iter().all(|&t| angle(t)) || !scan.elevation.is_none_or(angle) {
        return Err(format!("bearing or elevation beyond one turn: {scan:?}"));
    }
    if !scan.readings.iter().flatten().all(|r| r.is_finite()) {
        return Err("a reading that is not finite".into());
    }
    let sigma_ok = |s: &f64| s.is_finite() && *s >= 0.0;
    if !scan.readings_sigma.iter().flatten().flatten().all(sigma_ok) {
        return Err("a negative or non-finite sigma".into());
    }
    let pose_ok = |p: &Pose| {
        let a = p.to_array();
        a.iter().all(|v| v.is_finite()) && a[..3].iter().all(|v| v.abs() <= MAX_POSITION)
    };
    if ![&scan.odometry, &scan.estimate, &scan.true_pose]
        .into_iter()
        .flatten()
        .all(pose_ok)
    {
        return Err("a pose beyond the limits".into());
    }
    if !scan
        .hinge_offset
        .is_none_or(|o| o.iter().all(|v| v.is_finite() && v.abs() <= MAX_POSITION))
        || !scan
            .timestamp
            .is_none_or(|t| t.seconds().abs() < MAX_SECONDS)
    {
        return Err("a hinge offset or timestamp beyond the limits".into());
    }
    let mut line = Vec::new();
    write_scan(&mut line, scan).map_err(|e| e.to_string())?;
    let text = String::from_utf8(line).map_err(|e| e.to_string())?;
    match parse_scan_line(&text) {
        Ok(back) if back == *scan => Ok(()),
        Ok(back) => Err(format!(
            "written back as {text}, read back differently: {back:?}"
        )),
        Err(e) => Err(format!("written back as {text}, does not read back: {e}")),
    }
}

/// The text of 1-based line `n` of `input`.
pub fn line_text(input: &[u8], n: usize) -> &[u8] {
    input.split(|&b| b == b'\n').nth(n - 1).unwrap_or(b"")
}

/// Checks what a scan reader made of `input`: each scan passes [`check_scan`] and `more`
/// (given its line number and the line's text), and an error comes last, as a message
/// [`check_message`] takes.
pub fn check_records(
    items: &[Result<(usize, Scan), levelscan::formats::InputError>],
    input: &[u8],
    file: &str,
    more: impl Fn(&Scan, &[u8]) -> Result<(), String>,
) -> Result<Outcome, String> {
    let mut records = 0;
    for (k, item) in items.iter().enumerate() {
        match item {
            Ok((line, scan)) => {
                check_scan(scan)
                    .and_then(|()| more(scan, line_text(input, *line)))
                    .map_err(|e| format!("line {line}: {e}"))?;
                records += 1;
            }
            Err(e) => {
                if k + 1 != items.len() {
                    return Err(format!("read on after an error: {e}"));
                }
                check_message(&e.to_string(), file, line_count(input))?;
                return Ok(Outcome::Refused(records));
            }
        }
    }
    Ok(Outcome::Accepted(records))
}

/// Every seed of a scan target is read whole, into at least one record.
pub fn check_seeds(seeds: &[Vec<u8>], oracle: impl Fn(&[u8]) -> Result<Outcome, String>) {
    for (i, s) in seeds.iter().enumerate() {
        let got = oracle(s);
        assert!(
            matches!(got, Ok(Outcome::Accepted(n)) if n > 0),
            "seed {i} is not read whole: {got:?}"
        );
    }
}
