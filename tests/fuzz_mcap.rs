//! Fuzzing the MCAP reader (`formats::bag`), in the pattern of `tests/fuzz_support`: valid
//! MCAP files (made here, tests/bag_support: zstd, lz4 and uncompressed chunks, no chunks,
//! small chunks so there are several) mutated at the byte level and structurally: bytes
//! flipped inside a chosen record (a chunk's compressed or plain records, a schema, a
//! channel, the summary), a record's length set to 0, off by a few, past the end or huge,
//! records dropped or repeated, the file cut inside or between records.
//!
//! Each input goes through the library as `levelscan info`/`level` use it: `Bag::detect`,
//! `survey` (first pass), `read_scans` (second pass). The oracle: no panic, no hang (each input
//! within `fuzz_support::HANG_LIMIT`); an error is one line naming the file; every scan read
//! keeps the crate's invariants (`fuzz_support::check_scan`).
//!
//! 500 inputs in a plain `cargo test`;
//! `LEVELSCAN_FUZZ_CASES=100000 cargo test --release --test fuzz_mcap -- --nocapture` for a
//! long run; `LEVELSCAN_FUZZ_SEED` changes the inputs.

mod bag_support;
mod fuzz_support;
use bag_support::*;
use fuzz_support::*;

use levelscan::formats::bag::{Bag, BagOptions, read_scans, survey};
use proptest::prelude::*;
use proptest::sample::Index;
use std::ops::ControlFlow;
use std::path::PathBuf;

/// Inputs in a plain `cargo test`: a few seconds.
const DEFAULT_MCAP_CASES: u32 = 500;

const TOKENS: &[&str] = &[
    "MCAP0\r\n",
    "\0\0\0\0\0\0\0\0",
    "zstd",
    "lz4",
    "ros2",
    "cdr",
    "ros2msg",
    "/scan",
    "\u{7f}\u{7f}\u{7f}\u{7f}",
];

/// Valid files: 2 poses of 3 scans, 31 rays, in each layout.
fn seeds() -> Vec<Vec<u8>> {
    let scans = simulated_scans(2, 31, 11);
    let msgs = bag_messages(&scans, &BagSpec::default());
    let small = 1500; // bytes: several chunks per file
    [
        Layout {
            chunk_size: small,
            ..Layout::default()
        },
        Layout {
            compression: None,
            chunk_size: small,
            ..Layout::default()
        },
        Layout {
            compression: Some(mcap::Compression::Lz4),
            chunk_size: small,
            ..Layout::default()
        },
        Layout {
            use_chunks: false,
            ..Layout::default()
        },
    ]
    .iter()
    .map(|l| mcap_bytes(&msgs, *l))
    .collect()
}

/// One structural edit of an MCAP file, on its top-level records.
#[derive(Clone, Debug)]
struct RecordEdit {
    kind: u8,
    record: Index,
    at: Index,
    value: u64,
}

fn record_edit() -> impl Strategy<Value = RecordEdit> {
    (0u8..7, any::<Index>(), any::<Index>(), any::<u64>()).prop_map(|(kind, record, at, value)| {
        RecordEdit {
            kind,
            record,
            at,
            value,
        }
    })
}

fn apply_record_edit(bytes: &mut Vec<u8>, e: &RecordEdit) {
    let records = top_level_records(bytes);
    if records.is_empty() {
        return;
    }
    let (start, _, body, len) = records[e.record.index(records.len())];
    let end = body + len;
    match e.kind {
        // Flip bits in the body: inside a chunk this hits compressed data or plain records.
        0 | 1 if len > 0 => {
            let i = body + e.at.index(len);
            bytes[i] ^= (e.value as u8) | 1;
        }
        // The record's length: 0, a few off, past the end, or huge.
        2 => {
            let new = match e.value % 5 {
                0 => 0,
                1 => len as u64 + 1 + e.value % 8,
                2 => (len as u64).saturating_sub(1 + e.value % 8),
                3 => (bytes.len() - body) as u64 + 1,
                _ => u64::MAX - e.value % 3,
            };
            bytes[start + 1..start + 9].copy_from_slice(&new.to_le_bytes());
        }
        // A length-like u32 or u64 field inside the body (string, array, chunk size) made huge.
        3 if len >= 8 => {
            let i = body + e.at.index(len - 7);
            let big = if e.value % 2 == 0 {
                u32::MAX as u64 - 1
            } else {
                e.value
            };
            let w = if e.value % 3 == 0 { 8 } else { 4 };
            bytes[i..i + w].copy_from_slice(&big.to_le_bytes()[..w]);
        }
        4 => {
            bytes.drain(start..end);
        }
        5 => {
            let copy = bytes[start..end].to_vec();
            bytes.splice(end..end, copy);
        }
        // Cut inside or at the end of the record.
        _ => bytes.truncate(start + e.at.index(end - start + 1)),
    }
}

fn structured(seeds: Vec<Vec<u8>>) -> impl Strategy<Value = Vec<u8>> {
    (
        prop::sample::select(seeds),
        prop::collection::vec(record_edit(), 1..4),
    )
        .prop_map(|(seed, edits)| {
            let mut b = seed;
            for e in &edits {
                apply_record_edit(&mut b, e);
            }
            b
        })
}

fn inputs(seeds: Vec<Vec<u8>>) -> impl Strategy<Value = Vec<u8>> {
    let mutated = (prop::sample::select(seeds.clone()), byte_edits())
        .prop_map(|(seed, edits)| apply_byte_edits(&seed, &edits, TOKENS));
    let both = (structured(seeds.clone()), byte_edits())
        .prop_map(|(b, edits)| apply_byte_edits(&b, &edits[..1], TOKENS));
    prop_oneof![2 => mutated, 5 => structured(seeds), 2 => both]
}

struct Scratch(PathBuf);

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

/// Reads `input` as `level` would: detect, survey, then every scan; with `invariants`, every
/// scan read must also keep the crate's invariants.
fn oracle(path: &std::path::Path, input: &[u8], invariants: bool) -> Result<Outcome, String> {
    std::fs::write(path, input).map_err(|e| e.to_string())?;
    let name = path.display().to_string();
    let mut scans = 0usize;
    let mut garbage = None;
    let result = (|| -> Result<(), levelscan::formats::InputError> {
        let Some(bag) = Bag::detect(path)? else {
            return Ok(());
        };
        let s = survey(&bag, &BagOptions::default())?;
        if s.scan_topic_error.is_some() {
            return Ok(());
        }
        read_scans(&bag, &s, &mut |_, scan| {
            scans += 1;
            if let Err(e) = check_scan(&scan).map_err(|e| e + &format!(" in {scan:?}"))
                && invariants
            {
                garbage = Some(e);
                return Ok(ControlFlow::Break(()));
            }
            Ok(ControlFlow::Continue(()))
        })
    })();
    if let Some(e) = garbage {
        return Err(format!("garbage accepted: {e}"));
    }
    match result {
        Ok(()) => Ok(Outcome::Accepted(scans)),
        Err(e) => {
            let text = e.to_string();
            if text.contains('\n') || !text.starts_with(&name) {
                return Err(format!("error is not one line naming {name}: {text:?}"));
            }
            Ok(Outcome::Refused(scans))
        }
    }
}

/// The seeds read whole, then `cases` mutated inputs go through the oracle.
fn fuzz(target: &str, invariants: bool) {
    let seeds = seeds();
    let path = std::env::temp_dir().join(format!("levelscan-{target}-{}.mcap", std::process::id()));
    let scratch = Scratch(path);
    for (i, s) in seeds.iter().enumerate() {
        match oracle(&scratch.0, s, invariants) {
            Ok(Outcome::Accepted(6)) => {}
            other => panic!("seed {i} should read whole, 6 scans: {other:?}"),
        }
    }
    // Each input is a file read twice (about 7 ms): fewer inputs than the text targets.
    run_cases(
        target,
        cases_or(DEFAULT_MCAP_CASES),
        inputs(seeds),
        |input| oracle(&scratch.0, input, invariants),
    );
}

/// No panic, no hang, errors one line naming the file.
#[test]
fn fuzz_mcap_never_panics() {
    fuzz("mcap", false);
}

/// No garbage accepted: what the reader returns from a damaged file keeps the limits the
/// JSON Lines reader enforces (`formats::limits`: positions within 1e7 m, bearings within a
/// turn, ...), which the rest of the crate relies on.
#[test]
fn fuzz_mcap_accepts_no_garbage() {
    fuzz("mcap-invariants", true);
}
