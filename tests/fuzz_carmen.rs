//! Fuzzing the CARMEN log reader (`formats::carmen`), in the pattern of `tests/fuzz_support`:
//! arbitrary bytes and text, byte mutations of the seeds in `tests/fuzz/corpus/carmen/`, and
//! structured mutations (tokens replaced by edge numbers, dropped or repeated, counts moved,
//! message names swapped, host fields cut, lines repeated).
//!
//! The oracle: no panic, no hang; `read_any` reads a log as the CARMEN reader does (or
//! refuses binary bytes up front, as a wrong kind of file); the
//! reader stops at its first error, one line naming the file and an existing line; and "no
//! garbage accepted": every scan keeps the invariants of `formats::limits` and writes back
//! as JSON Lines to the same scan (`fuzz_support::check_scan`), its line has exactly the
//! fields its counts announce (a `FLASER` of n readings: n + 8 numbers, then nothing or
//! `host logger_timestamp`), and a valid ray has a positive range.

mod fuzz_support;
use fuzz_support::*;

use levelscan::formats::kind::looks_binary;
use levelscan::formats::{CarmenParams, CarmenReader, read_any};
use levelscan::scan::Scan;
use proptest::prelude::*;
use proptest::sample::Index;
use std::io::Cursor;

const FILE: &str = "fuzz.log";
const ALPHABET: &str = "FLASERROBOTLASER1ODOMPARAM# \t\n0123456789.-+eE";
const TOKENS: &[&str] = &[
    "FLASER",
    "ROBOTLASER1",
    "ODOM",
    "PARAM",
    "robot_front_laser_max",
    "#",
    "nohost",
    " ",
    "\t",
    "\n",
    "\r\n",
    "\u{feff}",
    "{",
];
const NAMES: [&str; 9] = [
    "FLASER",
    "ROBOTLASER1",
    "ODOM",
    "PARAM",
    "flaser",
    "#",
    "NEFF",
    "RLASER",
    "{",
];

/// Token edits of one line of a seed.
fn structured(seeds: Vec<Vec<u8>>) -> impl Strategy<Value = Vec<u8>> {
    let edit = (0u8..9, any::<Index>(), any::<Index>());
    (
        prop::sample::select(seeds),
        prop::collection::vec(edit, 1..4),
        any::<Index>(),
    )
        .prop_map(|(seed, edits, line)| {
            let text = String::from_utf8(seed).expect("seeds are UTF-8");
            let mut lines: Vec<Vec<String>> = text
                .lines()
                .map(|l| l.split_ascii_whitespace().map(String::from).collect())
                .collect();
            let i = line.index(lines.len());
            for (kind, at, pick) in edits {
                edit_line(&mut lines, i, kind, at, pick.index(1 << 16));
            }
            let text: Vec<String> = lines.iter().map(|l| l.join(" ")).collect();
            (text.join("\n") + "\n").into_bytes()
        })
}

fn edit_line(lines: &mut Vec<Vec<String>>, i: usize, kind: u8, at: Index, pick: usize) {
    let line = &mut lines[i];
    let at = if line.is_empty() {
        0
    } else {
        at.index(line.len())
    };
    let number = NUMBERS[pick % NUMBERS.len()].to_string();
    match kind {
        0 if at < line.len() => line[at] = number,
        1 if at < line.len() => {
            line.remove(at);
        }
        2 if at < line.len() => {
            let t = line[at].clone();
            line.insert(at, t);
        }
        3 if line.len() > 1 => {
            // Move the count of readings.
            let n: i64 = line[1].parse().unwrap_or(0);
            line[1] = (n + [-2, -1, 1, 2, 1_000_000][pick % 5]).to_string();
        }
        4 if !line.is_empty() => line[0] = NAMES[pick % NAMES.len()].to_string(),
        5 => line.push([number, "nohost".into()][pick % 2].clone()),
        6 if line.len() > 2 => line.truncate(line.len() - 2),
        7 => {
            let copy = line.clone();
            lines.insert(i, copy);
        }
        8 => {
            lines.remove(i);
            lines.push(Vec::new());
        }
        _ => {}
    }
}

/// The fields of the line a scan came from agree with the scan.
fn check_fields(scan: &Scan, line: &str) -> Result<(), String> {
    let t: Vec<&str> = line.split_ascii_whitespace().collect();
    let n = scan.nrays();
    let rest = t.len() - 1;
    let number = |s: &str| s.parse::<f64>().is_ok();
    let expected = match t[0] {
        "FLASER" => {
            if t[1].parse::<f64>() != Ok(n as f64) {
                return Err(format!("{n} rays from a count of {}", t[1]));
            }
            n + 8
        }
        "ROBOTLASER1" => {
            let m: usize = t[9 + n].parse::<f64>().map_err(|e| e.to_string())? as usize;
            n + m + 21
        }
        other => return Err(format!("a scan from a {other} line")),
    };
    let host = rest == expected + 2 && !number(t[expected + 1]) && number(t[expected + 2]);
    if rest != expected && !host {
        return Err(format!(
            "{rest} fields after {}, {expected} expected: {line}",
            t[0]
        ));
    }
    for i in 0..n {
        if scan.valid[i] != scan.readings[i].is_some_and(|r| r > 0.0) {
            return Err(format!(
                "ray {i}: valid {} and reading {:?}",
                scan.valid[i], scan.readings[i]
            ));
        }
    }
    Ok(())
}

fn oracle(input: &[u8]) -> Result<Outcome, String> {
    let items: Vec<_> =
        CarmenReader::new(Cursor::new(input), FILE, CarmenParams::default()).collect();
    let first = input.iter().find(|b| !b.is_ascii_whitespace());
    if !matches!(first, None | Some(b'{')) && !input.starts_with(b"\xEF\xBB\xBF") {
        match read_any(Cursor::new(input), FILE, CarmenParams::default()) {
            // Binary bytes are refused up front, as a file of the wrong kind.
            Err(e) if looks_binary(input) => check_message(&e.to_string(), FILE, 0)?,
            any => {
                let any: Vec<_> = any.map_err(|e| e.to_string())?.collect();
                if any != items {
                    return Err(format!("read_any {any:?}\nCARMEN reader {items:?}"));
                }
            }
        }
    }
    check_records(&items, input, FILE, |scan, line| {
        check_fields(scan, &String::from_utf8_lossy(line))
    })
}

#[test]
fn fuzz_carmen() {
    let seeds = corpus("carmen");
    check_seeds(&seeds, oracle);
    run(
        "carmen",
        inputs(seeds.clone(), ALPHABET, TOKENS, structured(seeds)),
        oracle,
    );
}
