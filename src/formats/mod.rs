//! File formats: scan JSON Lines (CSM's laser_data layout), `.wall` floor plans, CARMEN logs
//! and TUM trajectories. Every reader reports bad input as `FILE:LINE: what is wrong` (for
//! `.wall` files, `FILE:JSON.PATH: what is wrong`), the contract's one-line message.
//!
//! - [`scan_jsonl`]: read ([`ScanReader`], [`ParallelScanReader`]) and write ([`write_scan`])
//!   scan JSON Lines.
//! - [`wall`]: read, validate and write `.wall` floor plans.

pub mod scan_jsonl;
pub mod wall;

pub use scan_jsonl::{ParallelScanReader, ScanReader, parse_scan_line, write_scan};
pub use wall::{parse_plan, read_plan, write_plan};

use std::fmt;

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
