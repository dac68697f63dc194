//! Scan JSON Lines read one line at a time, in the caller's thread.

use super::{is_blank, parse_scan_line};
use crate::formats::{InputError, limits};
use crate::scan::Scan;
use std::io::{self, BufRead};

/// Reads scan JSON Lines one line at a time: memory stays at one line whatever the file's
/// length. Yields `(line number, scan)` with 1-based line numbers; blank lines are skipped. After
/// the first error it yields nothing more, since the contract stops at the first bad line.
pub struct ScanReader<R> {
    reader: R,
    name: String,
    line: usize,
    buf: String,
    done: bool,
}

impl<R: BufRead> ScanReader<R> {
    /// `name` is the file's name as the user gave it (or `<stdin>`), for error messages.
    pub fn new(reader: R, name: impl Into<String>) -> Self {
        Self {
            reader,
            name: name.into(),
            line: 0,
            buf: String::new(),
            done: false,
        }
    }
}

impl<R: BufRead> Iterator for ScanReader<R> {
    type Item = Result<(usize, Scan), InputError>;

    fn next(&mut self) -> Option<Self::Item> {
        while !self.done {
            self.buf.clear();
            match limits::read_line_capped(&mut self.reader, &mut self.buf) {
                Ok(0) => self.done = true,
                Ok(_) => {
                    self.line += 1;
                    if is_blank(&self.buf) {
                        continue;
                    }
                    let parsed = parse_scan_line(&self.buf)
                        .map(|scan| (self.line, scan))
                        .map_err(|m| InputError::at_line(&self.name, self.line, m));
                    self.done = parsed.is_err();
                    return Some(parsed);
                }
                Err(e) => {
                    self.done = true;
                    return Some(Err(read_error(&self.name, self.line + 1, &e)));
                }
            }
        }
        None
    }
}

pub(crate) fn read_error(name: &str, line: usize, e: &io::Error) -> InputError {
    let what = if limits::is_line_too_long(e) {
        e.to_string()
    } else if e.kind() == io::ErrorKind::InvalidData {
        "is not valid UTF-8 text".to_string()
    } else {
        format!("cannot read: {e}")
    };
    InputError::at_line(name, line, what)
}
