//! File formats: scan JSON Lines (CSM's laser_data layout), `.wall` floor plans, CARMEN logs
//! and TUM trajectories. Every reader reports bad input as `FILE:LINE: what is wrong` (for
//! `.wall` files, `FILE:JSON.PATH: what is wrong`), the contract's one-line message.
//!
//! - [`scan_jsonl`]: read ([`ScanReader`], [`ParallelScanReader`]) and write ([`write_scan`])
//!   scan JSON Lines.
//! - [`wall`]: read, validate and write `.wall` floor plans.
//! - [`carmen`]: read CARMEN logs (`FLASER`, `ROBOTLASER1`).
//! - [`tum`]: write (and read back) TUM trajectories.
//! - [`read_any`]: scans from either JSON Lines or CARMEN, told apart by the first character.
//! - [`limits`]: the caps on sizes and the ranges of values every reader enforces.

pub mod bag;
pub mod carmen;
pub mod kind;
pub mod level_record;
pub mod limits;
pub mod pgm_map;
pub mod ply;
pub mod scan_jsonl;
pub mod tum;
pub mod wall;

pub use carmen::{CarmenParams, CarmenReader};
pub use scan_jsonl::{ParallelScanReader, ScanReader, parse_scan_line, write_scan};
pub use tum::write_tum;
pub use wall::{parse_plan, read_plan, read_plan_from, write_plan};

use crate::scan::Scan;
use std::fmt;
use std::io::BufRead;

/// Scans from a file in either format: JSON Lines (parsed in parallel batches) or a CARMEN log.
/// Yields `(line number, scan)` and stops after the first error, like the readers it wraps.
pub enum ScanSource<R> {
    /// Boxed: the parallel reader carries two batches of line buffers.
    JsonLines(Box<ParallelScanReader<R>>),
    Carmen(CarmenReader<R>),
    /// A ROS bag's scans (see [`bag::BagScans`]); the reader `R` is not used.
    Bag(Box<bag::BagScans>, bag::BagKind),
}

impl<R: BufRead + Send> ScanSource<R> {
    /// The format's name, for summaries: `"jsonl"` or `"carmen"`.
    pub fn format(&self) -> &'static str {
        match self {
            ScanSource::JsonLines(_) => "jsonl",
            ScanSource::Carmen(_) => "carmen",
            ScanSource::Bag(_, kind) => kind.name(),
        }
    }
}

impl<R: BufRead + Send> Iterator for ScanSource<R> {
    type Item = Result<(usize, Scan), InputError>;

    fn next(&mut self) -> Option<Self::Item> {
        match self {
            ScanSource::JsonLines(r) => r.next(),
            ScanSource::Carmen(r) => r.next(),
            ScanSource::Bag(r, _) => r.next(),
        }
    }
}

/// Opens scans in whichever format `reader` holds: JSON Lines when its first non-blank
/// character is `{`, a CARMEN log otherwise. Only looks at the reader's buffer, so nothing
/// is consumed and line numbers stay right; a buffer of nothing but blanks reads as JSON Lines
/// (no scans either way). `name` is for error messages.
pub fn read_any<R: BufRead + Send>(
    mut reader: R,
    name: impl Into<String>,
    carmen: CarmenParams,
) -> Result<ScanSource<R>, InputError> {
    let name = name.into();
    // A UTF-8 byte order mark (some editors write one) is not part of the first line.
    if reader
        .fill_buf()
        .map_err(|e| scan_jsonl::read_error(&name, 1, &e))?
        .starts_with(b"\xEF\xBB\xBF")
    {
        reader.consume(3);
    }
    let head = reader
        .fill_buf()
        .map_err(|e| scan_jsonl::read_error(&name, 1, &e))?;
    match kind::sniff(head) {
        kind::FileKind::Mcap | kind::FileKind::Ros1Bag => {
            // Bags are read in two passes (topics and joints first), so they need a path.
            return Err(InputError::new(
                name,
                "",
                "a ROS bag on a stream: give the bag's path as the input file instead",
            ));
        }
        // Other text is a CARMEN log whose unknown lines are skipped (as CARMEN readers do);
        // binary (an image, say) is named as a wrong kind, as `level` names it, rather than
        // read as a log and refused for its bytes.
        kind::FileKind::Unknown if kind::looks_binary(head) => {
            return Err(kind::wrong_kind(
                &name,
                kind::FileKind::Unknown,
                "scans are wanted (JSON Lines, a CARMEN log or a ROS bag)",
            ));
        }
        k @ (kind::FileKind::FloorPlan | kind::FileKind::Sqlite) => {
            return Err(kind::wrong_kind(
                &name,
                k,
                "scans are wanted (JSON Lines, a CARMEN log or a ROS bag)",
            ));
        }
        _ => {}
    }
    let first = head.iter().copied().find(|b| !b.is_ascii_whitespace());
    Ok(match first {
        None | Some(b'{') => ScanSource::JsonLines(Box::new(ParallelScanReader::new(reader, name))),
        Some(_) => ScanSource::Carmen(CarmenReader::new(reader, name, carmen)),
    })
}

/// Bad input: which file, where in it, and what is wrong.
///
/// Displays as `FILE:LOCATION: message`, e.g.
/// `scans.jsonl:17: readings has 180 entries but nrays is 181`; when there is no location (a file
/// that cannot be opened) as `FILE: message`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub struct InputError {
    /// The file's name as the user gave it, or `<stdin>`.
    pub file: String,
    /// A 1-based line number, or a JSON path such as `walls[3]` for `.wall` files; may be empty.
    pub location: String,
    /// What is wrong, naming the field.
    pub message: String,
}

impl InputError {
    pub fn new(
        file: impl Into<String>,
        location: impl Into<String>,
        message: impl Into<String>,
    ) -> Self {
        Self {
            file: file.into(),
            location: location.into(),
            message: message.into(),
        }
    }

    /// An error at a 1-based line.
    pub fn at_line(file: impl Into<String>, line: usize, message: impl Into<String>) -> Self {
        Self::new(file, line.to_string(), message)
    }
}

impl fmt::Display for InputError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.location.is_empty() {
            write!(f, "{}: {}", self.file, self.message)
        } else {
            write!(f, "{}:{}: {}", self.file, self.location, self.message)
        }
    }
}

/// serde_json appends ` at line L column C` to its messages; callers name the line themselves,
/// so keep only the message and the column.
pub(crate) fn json_error_message(e: &serde_json::Error) -> String {
    let text = e.to_string();
    let message = match text.rfind(" at line ") {
        Some(i) if e.line() > 0 => text[..i].to_string(),
        _ => text,
    };
    if e.column() > 0 {
        format!("{message} (column {})", e.column())
    } else {
        message
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Cursor;

    #[test]
    fn read_any_tells_json_lines_from_carmen() {
        let json = "\n  {\"nrays\": 1, \"theta\": [0], \"readings\": [2]}\n";
        let src = read_any(Cursor::new(json), "a.jsonl", CarmenParams::default()).unwrap();
        assert_eq!(src.format(), "jsonl");
        let scans: Vec<_> = src.collect::<Result<_, _>>().unwrap();
        assert_eq!(scans.len(), 1);
        assert_eq!(scans[0].0, 2, "the blank first line still counts");

        let log = "# CARMEN\nFLASER 2 1 2 0 0 0 0 0 0 5 h 5\n";
        let src = read_any(Cursor::new(log), "a.log", CarmenParams::default()).unwrap();
        assert_eq!(src.format(), "carmen");
        let scans: Vec<_> = src.collect::<Result<_, _>>().unwrap();
        assert_eq!(scans.len(), 1);
        assert_eq!(scans[0].0, 2);
        assert_eq!(scans[0].1.readings, vec![Some(1.0), Some(2.0)]);
    }

    #[test]
    fn read_any_of_empty_input_yields_nothing() {
        let src = read_any(Cursor::new(""), "e", CarmenParams::default()).unwrap();
        assert_eq!(src.count(), 0);
    }

    #[test]
    fn input_error_displays_file_line_message() {
        let e = InputError::at_line(
            "scans.jsonl",
            17,
            "readings has 180 entries but nrays is 181",
        );
        assert_eq!(
            e.to_string(),
            "scans.jsonl:17: readings has 180 entries but nrays is 181"
        );
    }

    #[test]
    fn input_error_displays_json_path() {
        let e = InputError::new("room.wall", "walls[3]", "a wall needs at least 2 points");
        assert_eq!(
            e.to_string(),
            "room.wall:walls[3]: a wall needs at least 2 points"
        );
    }

    #[test]
    fn input_error_without_location_has_no_empty_field() {
        let e = InputError::new("gone.jsonl", "", "cannot open: not found");
        assert_eq!(e.to_string(), "gone.jsonl: cannot open: not found");
    }
}
