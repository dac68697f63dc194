//! Scan JSON Lines parsed in batches on every core (rayon), yielded in input order.

use super::{is_blank, parse_scan_line_with, read_error};
use crate::formats::{InputError, limits};
use crate::scan::Scan;
use rayon::prelude::*;
use std::collections::VecDeque;
use std::io::BufRead;

/// Lines per batch of [`ParallelScanReader`]; enough to keep every core busy.
const BATCH_LINES: usize = 1024;
/// Bytes per batch of [`ParallelScanReader`], so that memory stays bounded for long lines.
const BATCH_BYTES: usize = 8 << 20;

/// Like [`ScanReader`], but parses batches of lines in parallel (rayon) and yields them in input
/// order: for big files. While one batch is parsed the next is read, so decompression and I/O
/// overlap the parsing. Memory is bounded by two batches (each at most 1024 lines or about
/// 8 MB).
pub struct ParallelScanReader<R> {
    source: LineSource<R>,
    /// Read ahead, not parsed yet.
    next: Batch,
    /// The batch being parsed; its line buffers are reused.
    current: Batch,
    ready: VecDeque<Result<(usize, Scan), InputError>>,
    started: bool,
    done: bool,
    skip_hit: bool,
}

struct LineSource<R> {
    reader: R,
    name: String,
    line: usize,
}

/// Lines read in one go: (line number, text), of which the first `used` are this batch's.
#[derive(Default)]
struct Batch {
    lines: Vec<(usize, String)>,
    used: usize,
    /// The batch ended because the input did (end of file or a read error).
    last: bool,
    read_err: Option<InputError>,
}

impl<R: BufRead> LineSource<R> {
    /// Fills `batch` with the next non-blank lines.
    fn read_batch(&mut self, batch: &mut Batch) {
        batch.used = 0;
        batch.last = false;
        batch.read_err = None;
        let mut bytes = 0;
        while batch.used < BATCH_LINES && bytes < BATCH_BYTES {
            if batch.used == batch.lines.len() {
                batch.lines.push((0, String::new()));
            }
            let slot = &mut batch.lines[batch.used];
            slot.1.clear();
            match limits::read_line_capped(&mut self.reader, &mut slot.1) {
                Ok(0) => {
                    batch.last = true;
                    return;
                }
                Ok(n) => {
                    self.line += 1;
                    if is_blank(&slot.1) {
                        continue;
                    }
                    slot.0 = self.line;
                    bytes += n;
                    batch.used += 1;
                }
                Err(e) => {
                    batch.last = true;
                    batch.read_err = Some(read_error(&self.name, self.line + 1, &e));
                    return;
                }
            }
        }
    }
}

impl<R: BufRead + Send> ParallelScanReader<R> {
    /// `name` is the file's name as the user gave it (or `<stdin>`), for error messages.
    pub fn new(reader: R, name: impl Into<String>) -> Self {
        Self {
            source: LineSource {
                reader,
                name: name.into(),
                line: 0,
            },
            next: Batch::default(),
            current: Batch::default(),
            ready: VecDeque::new(),
            started: false,
            done: false,
            skip_hit: false,
        }
    }

    /// Skips over `hit` labels without reading them (see [`parse_scan_line`]); for `level`,
    /// which never reads them.
    pub fn skipping_hit(mut self) -> Self {
        self.skip_hit = true;
        self
    }

    /// Parses the read-ahead batch while reading the one after it.
    fn fill(&mut self) {
        if !self.started {
            self.source.read_batch(&mut self.next);
            self.started = true;
        }
        std::mem::swap(&mut self.current, &mut self.next);
        let current = &self.current;
        let name = self.source.name.clone();
        let (source, next) = (&mut self.source, &mut self.next);
        let skip_hit = self.skip_hit;
        let (parsed, ()) = rayon::join(
            || {
                current.lines[..current.used]
                    .par_iter()
                    .map(|(line, text)| {
                        parse_scan_line_with(text, skip_hit)
                            .map(|scan| (*line, scan))
                            .map_err(|m| InputError::at_line(&name, *line, m))
                    })
                    .collect::<Vec<_>>()
            },
            || {
                if !current.last {
                    source.read_batch(next);
                }
            },
        );
        for item in parsed {
            let bad = item.is_err();
            self.ready.push_back(item);
            if bad {
                self.done = true;
                return;
            }
        }
        if let Some(e) = self.current.read_err.take() {
            self.ready.push_back(Err(e));
        }
        self.done = self.current.last;
    }
}

impl<R: BufRead + Send> Iterator for ParallelScanReader<R> {
    type Item = Result<(usize, Scan), InputError>;

    fn next(&mut self) -> Option<Self::Item> {
        while self.ready.is_empty() && !self.done {
            self.fill();
        }
        self.ready.pop_front()
    }
}
