//! Scan JSON Lines: one scan per line in CSM's laser_data layout (the paper's Fig. 13, the
//! contract's table).
//!
//! The parser is a hand-written serde visitor rather than a derive with `#[serde(flatten)]`:
//! flatten buffers every field into an intermediate map, which is several times slower, and the
//! visitor lets each error name its field and index (`readings[3]: ...`). Unknown fields are
//! kept, in order, in [`Scan::extra`], so CSM's own logs (`true_alpha`, `cov_alpha`, `cluster`,
//! ...) pass through untouched.
//!
//! One file per role: `reader.rs` reads line by line, `parallel.rs` parses batches of lines on
//! every core, `record.rs` turns one line's fields into a checked [`Scan`] (with `fields.rs`,
//! the deserialisers of each field's value), and `writer.rs` writes scans back.

mod fields;
mod parallel;
mod reader;
mod record;
mod writer;

pub use parallel::ParallelScanReader;
pub use reader::ScanReader;
pub(crate) use reader::read_error;
pub use writer::write_scan;

use super::json_error_message;
use crate::scan::Scan;
use record::RawScanVisitor;
use serde::de;

/// Parses one line of scan JSON Lines into a [`Scan`]. The error is the message alone; the
/// readers add the file name and line number.
pub fn parse_scan_line(text: &str) -> Result<Scan, String> {
    parse_scan_line_with(text, false)
}

/// [`parse_scan_line`], skipping over the simulator's `hit` labels when `skip_hit` (they are
/// left out of the scan, unchecked): `level` never reads them (contract), and they are a
/// tenth of what a simulated line holds to parse.
fn parse_scan_line_with(text: &str, skip_hit: bool) -> Result<Scan, String> {
    let mut de = serde_json::Deserializer::from_str(text);
    let raw = de::DeserializeSeed::deserialize(RawScanVisitor { skip_hit }, &mut de)
        .and_then(|raw| de.end().map(|()| raw))
        .map_err(|e| {
            let message = json_error_message(&e);
            if is_non_finite_literal(text, &e) {
                format!("{message}; JSON has no NaN or Infinity: write null for no return")
            } else {
                message
            }
        })?;
    raw.into_scan()
}

/// Whether a syntax error stopped at a `NaN`, `Infinity` or `inf` literal, as Python's and
/// other JSON writers emit for missing ranges: serde then says only "expected value" (or
/// "invalid number" after a minus sign, "expected ident" for `nan`, read as a `null` begun).
fn is_non_finite_literal(text: &str, e: &serde_json::Error) -> bool {
    // Inside a field the error is re-raised with the field's name, so not as a syntax error.
    let text_of_error = e.to_string();
    let syntax = ["expected value", "invalid number", "expected ident"];
    if !syntax.iter().any(|m| text_of_error.contains(m)) || e.column() == 0 {
        return false;
    }
    // The column counts from 1 and stops at or just after the literal's first letter.
    let at = text
        .char_indices()
        .nth(e.column().saturating_sub(2))
        .map_or(text.len(), |(i, _)| i);
    let near: String = text[at..]
        .chars()
        .take(12)
        .collect::<String>()
        .to_lowercase();
    near.contains("nan") || near.contains("inf")
}

fn is_blank(line: &str) -> bool {
    line.bytes().all(|b| b.is_ascii_whitespace())
}

#[cfg(test)]
mod tests;
