//! Choosing between JSON Lines and a ROS 2 bag (MCAP) for a command's output, and opening the
//! bag on an [`Output`] (a staged file or standard output, written front to back).

use super::output::Output;
use levelscan::formats::bag::write::NoSeek;
use levelscan::formats::bag::{BagWriteError, BagWriter};
use std::path::Path;

/// What a command writes.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum OutputFormat {
    /// Scan JSON Lines.
    Jsonl,
    /// A ROS 2 bag: one MCAP file (profile ros2, CDR messages).
    Mcap,
}

impl OutputFormat {
    /// The format asked for with `--format`, else MCAP for an output file named `*.mcap`
    /// (any case), else JSON Lines.
    pub fn choose(asked: Option<OutputFormat>, output: Option<&Path>) -> OutputFormat {
        asked.unwrap_or_else(|| {
            let mcap = output
                .and_then(Path::extension)
                .is_some_and(|e| e.eq_ignore_ascii_case("mcap"));
            if mcap {
                OutputFormat::Mcap
            } else {
                OutputFormat::Jsonl
            }
        })
    }
}

/// A bag written to an [`Output`].
pub type OutputBag = BagWriter<NoSeek<Output>>;

/// Starts a bag on `out`, named `name` in errors.
pub fn open_bag(out: Output, name: &str) -> Result<OutputBag, BagWriteError> {
    BagWriter::unseekable(out, name)
}

/// Writes the bag's summary and footer, then finishes the output (sync and rename).
pub fn finish_bag(bag: OutputBag) -> anyhow::Result<()> {
    bag.finish()?.into_inner().finish()
}
