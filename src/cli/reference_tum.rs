//! `match --reference-trajectory FILE`: the records' reference poses (`true_pose`: the
//! simulator's truth, a CARMEN log's corrected laser pose, a bag's ground-truth topic) as a TUM trajectory beside the estimate's
//! (`--trajectory`), so that trajectory tools (evo's `evo_ape tum REF EST`) compare the two
//! without the user writing the truth out by hand (issue 25 item 9).
//!
//! Both files take each record's time the same way (the contract: `timestamp`, else the
//! record's index) and the same planar pose (x, y, yaw; z and roll/pitch 0), so their rows
//! associate by time one to one and compare like with like.

use super::open_output;
use super::output::Output;
use levelscan::formats::write_tum;
use levelscan::scan::Scan;
use std::path::Path;

/// The reference trajectory being written, when asked for.
pub(crate) struct ReferenceTum {
    out: Option<(Output, String)>,
    rows: usize,
}

impl ReferenceTum {
    /// Opens `path` (none: writes nothing) through the output helper, refusing an input.
    pub fn open(path: Option<&Path>, inputs: &[Option<&Path>]) -> anyhow::Result<ReferenceTum> {
        let out = match path {
            Some(p) => Some((open_output(Some(p), inputs)?, p.display().to_string())),
            None => None,
        };
        Ok(ReferenceTum { out, rows: 0 })
    }

    /// One row for record `index` when it has a `true_pose`; records without one are left
    /// out (TUM rows are matched by time, so a gap is no error).
    pub fn push(&mut self, scan: &Scan, index: usize) -> anyhow::Result<()> {
        let (Some((out, _)), Some(truth)) = (self.out.as_mut(), scan.true_pose) else {
            return Ok(());
        };
        let time = scan.timestamp.map_or(index as f64, |t| t.seconds());
        write_tum(out, time, &truth.to_pose2())?;
        self.rows += 1;
        Ok(())
    }

    /// Renames the file into place; a run none of whose records had a `true_pose` is an error
    /// naming the input, and the file is not written.
    pub fn finish(self, input: &str) -> anyhow::Result<()> {
        let Some((out, name)) = self.out else {
            return Ok(());
        };
        anyhow::ensure!(
            self.rows > 0,
            "{input}: no record has a true_pose, so there is no reference trajectory for \
             {name} (it comes from simulate's output, a CARMEN log's corrected pose or a \
             bag's --truth-topic)"
        );
        out.finish()
    }
}
