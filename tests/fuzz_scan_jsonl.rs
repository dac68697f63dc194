//! Fuzzing the scan JSON Lines readers (`formats::scan_jsonl`), in the pattern of
//! `tests/fuzz_support`: arbitrary bytes and text, byte mutations of the seeds in
//! `tests/fuzz/corpus/scan_jsonl/`, and structured mutations (JSON values edited: wrong types,
//! edge numbers, arrays cut or multiplied, fields renamed onto known ones, lines repeated).
//!
//! The oracle: no panic, no hang; the streaming and the parallel reader agree record for
//! record (and `read_any` with them); a reader stops at its first error, whose message is one
//! line naming the file and an existing line; and "no garbage accepted": every scan read
//! keeps the invariants of `formats::limits` and writes back to a line that reads back as the
//! same scan (`fuzz_support::check_scan`), as its own line parsed alone does.

mod fuzz_support;
use fuzz_support::*;

use levelscan::formats::{CarmenParams, ParallelScanReader, ScanReader, parse_scan_line, read_any};
use proptest::prelude::*;
use proptest::sample::Index;
use serde_json::Value;
use std::io::Cursor;

const FILE: &str = "fuzz.jsonl";
const ALPHABET: &str = "{}[],:\" \n\t\r0123456789.-+eEnulltruefalsthetareadingsvalidnraysq\\";
const TOKENS: &[&str] = &[
    "{",
    "}",
    "[",
    "]",
    ",",
    ":",
    "\"",
    "null",
    "true",
    "false",
    "\n",
    "\r\n",
    "\u{feff}",
    "\\u0000",
    "\\ud800",
    "\"nrays\": ",
    "\"theta\": ",
    "\"readings\": ",
    "\"valid\": ",
    "\"elevation\": ",
    "\"sequence\": ",
    "\"min_theta\": 0, \"max_theta\": ",
    "[1, 2]",
    "\"timestamp\": ",
    "\"hit\": [4]",
    "\"readings_sigma\": [-1]",
];
/// Known fields, and others, for renames.
const FIELDS: &[&str] = &[
    "sequence",
    "nrays",
    "elevation",
    "theta",
    "readings",
    "valid",
    "min_theta",
    "max_theta",
    "odometry",
    "estimate",
    "true_pose",
    "timestamp",
    "readings_sigma",
    "hinge_offset",
    "hit",
    "level",
    "match",
    "zz",
];

fn structured(seeds: Vec<Vec<u8>>) -> impl Strategy<Value = Vec<u8>> {
    (
        prop::sample::select(seeds),
        json_edits(),
        any::<Index>(),
        0u8..5,
    )
        .prop_map(|(seed, edits, line, layout)| {
            let text = String::from_utf8(seed).expect("seeds are UTF-8");
            let mut values: Vec<Value> = text
                .lines()
                .filter(|l| !l.trim().is_empty())
                .map(|l| serde_json::from_str(l).expect("seed lines are JSON"))
                .collect();
            let i = line.index(values.len());
            apply_json_edits(&mut values[i], &edits, FIELDS);
            let mut lines: Vec<String> = values
                .iter()
                .map(|v| match layout {
                    1 => serde_json::to_string_pretty(v).unwrap().replace('\n', " "),
                    _ => v.to_string(),
                })
                .collect();
            match layout {
                2 => lines.insert(i, lines[i].clone()),
                3 => {
                    lines.remove(i);
                }
                _ => {}
            }
            let sep = if layout == 4 { "\r\n\n" } else { "\n" };
            (lines.join(sep) + "\n").into_bytes()
        })
}

fn oracle(input: &[u8]) -> Result<Outcome, String> {
    let serial: Vec<_> = ScanReader::new(Cursor::new(input), FILE).collect();
    let parallel: Vec<_> = ParallelScanReader::new(Cursor::new(input), FILE).collect();
    if serial != parallel {
        return Err(format!("serial {serial:?}\nparallel {parallel:?}"));
    }
    let any = read_any(Cursor::new(input), FILE, CarmenParams::default());
    let first = input.iter().find(|b| !b.is_ascii_whitespace());
    if matches!(first, None | Some(b'{')) {
        let any: Vec<_> = any.map_err(|e| e.to_string())?.collect();
        if any != serial {
            return Err(format!("read_any {any:?}\nserial {serial:?}"));
        }
    } else if let Ok(source) = any {
        source.for_each(drop); // a CARMEN reader: must not panic either
    }
    check_records(&serial, input, FILE, |scan, own| {
        let own = std::str::from_utf8(own).map_err(|e| e.to_string())?;
        match parse_scan_line(own) {
            Ok(alone) if alone == *scan => Ok(()),
            other => Err(format!("the line parsed alone gives {other:?}")),
        }
    })
}

#[test]
fn fuzz_scan_jsonl() {
    let seeds = corpus("scan_jsonl");
    check_seeds(&seeds, oracle);
    run(
        "scan_jsonl",
        inputs(seeds.clone(), ALPHABET, TOKENS, structured(seeds)),
        oracle,
    );
}
