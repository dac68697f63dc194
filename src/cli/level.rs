//! `levelscan level [SCANS]`: one pseudo-level scan per pose (paper sect. 5 and 6), in input
//! order, as the contract's "Output of level" lays it out.

use super::bag_output::{BagOutput, Kind as BagKind, OutputFormat, output_format};
use super::scan_input::{BagArgs, open_bag};
use super::summary::{Kind, Tally};
use super::{LevelArgs, open_input, open_output};
use levelscan::formats::level_record::level_record;
use levelscan::formats::{InputError, ParallelScanReader, write_scan};
use levelscan::level::{BearingTrigCache, Estimator, LevelParams, NoiseSource, level_pose_with};
use levelscan::pseudo_level::PseudoLevelParams;
use levelscan::scan::Scan;
use rayon::prelude::*;
use std::collections::HashSet;
use std::io::{BufRead, Write};
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scan JSON Lines with `sequence` and `elevation`, or a ROS bag (MCAP, rosbag2
    /// directory, ROS 1 .bag); standard input when absent or `-`.
    pub input: Option<PathBuf>,
    /// Output file; standard output when absent or `-`. A name ending in `.mcap` writes a
    /// ROS 2 bag (see --format).
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Range noise (m): the standard deviation of the readings' errors; default: the scans'
    /// `readings_sigma`, else estimated from the data.
    #[arg(long)]
    pub sigma: Option<f64>,
    /// Up-vector estimator: the paper's cross products over quads, or robust least squares
    /// over whole-wall patches.
    #[arg(long, value_enum, default_value_t = Estimator::Robust)]
    pub estimator: Estimator,
    /// Quad height (scans).
    #[arg(long, default_value_t = LevelParams::default().quad_rows)]
    pub quad_rows: usize,
    /// Quad width (rays).
    #[arg(long, default_value_t = LevelParams::default().quad_cols)]
    pub quad_cols: usize,
    #[command(flatten)]
    pub leveling: LevelArgs,
    /// Gaps of at most this many rays between wall points are filled (rays).
    #[arg(long, default_value_t = PseudoLevelParams::default().max_gap)]
    pub max_gap: usize,
    /// Also write `wall_polygons` (the quads) and `wall_patches` (merged walls), each a list of
    /// 4 corners [x, y, z] in the robot frame, for the 3D viewer.
    #[arg(long)]
    pub polygons: bool,
    #[command(flatten)]
    pub bag: BagArgs,
    /// Output format; default: mcap (a ROS 2 bag) when -o ends in .mcap, else jsonl.
    #[arg(long, value_enum)]
    pub format: Option<OutputFormat>,
}

/// Poses per parallel batch: bounds memory while keeping both cores busy.
const BATCH_POSES: usize = 256;

pub fn run(args: Args) -> anyhow::Result<()> {
    let params = LevelParams {
        sigma: args.sigma,
        estimator: args.estimator,
        quad_rows: args.quad_rows,
        quad_cols: args.quad_cols,
        ..args.leveling.apply(LevelParams::default())
    };
    if let Some(s) = params.sigma {
        anyhow::ensure!(
            s >= 0.0 && s.is_finite(),
            "--sigma must be a non-negative number of metres"
        );
    }
    anyhow::ensure!(
        params.quad_rows >= 2 && params.quad_cols >= 2,
        "--quad-rows and --quad-cols must be at least 2"
    );
    let pseudo = PseudoLevelParams {
        max_gap: args.max_gap,
        ..PseudoLevelParams::default()
    };
    // A bag is read by its own reader (two passes, on its thread); text in parallel batches.
    let opened = open_bag(args.input.as_deref(), &args.bag.options(true, None))?;
    let input_bag = opened.as_ref().and_then(|b| b.bag.clone());
    let (name, scans): (String, Scans) = match opened {
        Some(bag) => (bag.name, Box::new(bag.source)),
        None => {
            let mut input = open_input(args.input.as_deref())?;
            let name = input.name.clone();
            refuse_other_kinds(&name, input.reader.fill_buf()?)?;
            let reader = ParallelScanReader::new(input.reader, name.clone()).skipping_hit();
            (name, Box::new(reader))
        }
    };
    let input_name = name.clone();
    let mut tally = Tally::new(Kind::Level);
    let mut sink = open_sink(&args, input_bag)?;
    // Reading and grouping run on their own thread, a couple of batches ahead, so that the
    // serial part of reading overlaps with leveling (both use the rayon pool for the heavy work).
    let (tx, rx) = std::sync::mpsc::sync_channel::<PoseBatch>(2);
    let reader_thread = std::thread::spawn(move || read_poses(scans, &name, &tx));
    let mut result = Ok(());
    for (batch, failure) in rx {
        if let Err(e) = write_batch(
            &mut sink,
            &batch,
            &params,
            &pseudo,
            args.polygons,
            &mut tally,
        ) {
            result = Err(e);
            break;
        }
        if let Some(e) = failure {
            result = Err(e.into());
            break;
        }
    }
    // The reader ends on its own once the channel is dropped.
    drop(reader_thread);
    // A failed run leaves an `-o` file as it was (standard output keeps what was written).
    result.and_then(|()| sink.finish())?;
    tally.report(&input_name);
    Ok(())
}

/// The input's scans with their line numbers, from a bag's reader or a text file's.
type Scans = Box<dyn Iterator<Item = Result<(usize, Scan), InputError>> + Send>;

/// A batch of whole poses (each its scans), and the input error that ended the input, if any.
type PoseBatch = (Vec<Vec<Scan>>, Option<InputError>);

/// Groups the scans into poses and sends them to `tx` in batches of [`BATCH_POSES`], until the
/// input ends, an input error (sent with the last batch), or the receiver hangs up.
fn read_poses(mut reader: Scans, name: &str, tx: &std::sync::mpsc::SyncSender<PoseBatch>) {
    let mut grouper = Grouper::default();
    let mut batch: Vec<Vec<Scan>> = Vec::with_capacity(BATCH_POSES);
    loop {
        let item = reader.next();
        let exhausted = item.is_none();
        let mut failure = None;
        match item {
            Some(Ok((line, scan))) => match grouper.push(name, line, scan) {
                Ok(Some(pose)) => batch.push(pose),
                Ok(None) => {}
                Err(e) => failure = Some(e),
            },
            Some(Err(e)) => failure = Some(e),
            None => {
                if let Some(pose) = grouper.finish() {
                    batch.push(pose);
                }
            }
        }
        let end = exhausted || failure.is_some();
        if batch.len() >= BATCH_POSES || end {
            let full = std::mem::replace(&mut batch, Vec::with_capacity(BATCH_POSES));
            // A closed channel means the writer stopped (e.g. a broken pipe): stop too.
            if tx.send((full, failure)).is_err() {
                return;
            }
        }
        if end {
            return;
        }
    }
}

/// The output `-o` (or standard output) as JSON Lines, or as a bag that copies `input_bag`.
fn open_sink(args: &Args, input_bag: Option<levelscan::formats::bag::Bag>) -> anyhow::Result<Sink> {
    let out = open_output(args.output.as_deref(), &[args.input.as_deref()])?;
    Ok(match output_format(args.format, args.output.as_deref()) {
        OutputFormat::Jsonl => Sink::Jsonl(out),
        OutputFormat::Mcap => {
            let shown = args
                .output
                .as_deref()
                .map_or("<stdout>".to_string(), |p| p.display().to_string());
            Sink::Bag(Box::new(BagOutput::new(
                out,
                &shown,
                input_bag,
                BagKind::Level,
            )?))
        }
    })
}

/// `level` reads scan JSON Lines (or a bag, opened before): any other kind of file is named
/// as what it is, with what `level` wants.
fn refuse_other_kinds(name: &str, head: &[u8]) -> Result<(), InputError> {
    use levelscan::formats::kind::{FileKind, sniff, wrong_kind};
    let wanted = "level wants scans at several hinge elevations per pose \
                  (scan JSON Lines with sequence and elevation, or a ROS bag)";
    match sniff(head) {
        FileKind::ScanJsonLines | FileKind::Empty => Ok(()),
        FileKind::Carmen => Err(wrong_kind(
            name,
            FileKind::Carmen,
            &format!("{wanted}; a 2D log has one elevation only (match reads it as it is)"),
        )),
        FileKind::Mcap | FileKind::Ros1Bag => Err(InputError::new(
            name,
            "",
            "a ROS bag on a stream: give the bag's path as the input file instead",
        )),
        other => Err(wrong_kind(name, other, wanted)),
    }
}

/// Where the records go: JSON Lines, or a ROS 2 bag.
enum Sink {
    Jsonl(super::output::Output),
    Bag(Box<BagOutput>),
}

impl Sink {
    fn finish(self) -> anyhow::Result<()> {
        match self {
            Sink::Jsonl(out) => out.finish(),
            Sink::Bag(bag) => bag.finish(),
        }
    }
}

fn write_batch(
    sink: &mut Sink,
    batch: &[Vec<Scan>],
    params: &LevelParams,
    pseudo: &PseudoLevelParams,
    polygons: bool,
    tally: &mut Tally,
) -> anyhow::Result<()> {
    let (records, outcomes): (Vec<Scan>, Vec<_>) = batch
        .par_iter()
        .map_init(BearingTrigCache::default, |cache, scans| {
            let est = level_pose_with(scans, params, cache);
            let record = level_record(scans, &est, pseudo, polygons);
            (record, (est.cause, est.noise_source))
        })
        .unzip();
    for (record, (cause, noise)) in records.iter().zip(outcomes) {
        tally.add_leveled(record, cause);
        if noise == NoiseSource::SetAside {
            tally.note_noise_set_aside();
        }
    }
    match sink {
        Sink::Jsonl(out) => {
            let lines: Vec<Vec<u8>> = records
                .par_iter()
                .map(|record| {
                    let mut buf = Vec::with_capacity(8192);
                    // Writing to a Vec cannot fail.
                    let _ = write_scan(&mut buf, record);
                    buf
                })
                .collect();
            for l in lines {
                out.write_all(&l)?;
            }
        }
        Sink::Bag(bag) => {
            for record in &records {
                bag.level_record(record)?;
            }
        }
    }
    Ok(())
}

/// Groups consecutive scans by `sequence` (contract: a sequence that comes back later is an
/// input error; `level` needs `sequence` and `elevation` on every scan).
#[derive(Default)]
struct Grouper {
    current: Vec<Scan>,
    current_seq: Option<u64>,
    done: HashSet<u64>,
}

impl Grouper {
    fn push(
        &mut self,
        file: &str,
        line: usize,
        scan: Scan,
    ) -> Result<Option<Vec<Scan>>, InputError> {
        let Some(seq) = scan.sequence else {
            return Err(InputError::at_line(
                file,
                line,
                "sequence is missing (level groups the scans of a pose by it)",
            ));
        };
        if scan.elevation.is_none() {
            return Err(InputError::at_line(
                file,
                line,
                "elevation is missing (level needs the hinge elevation of every scan)",
            ));
        }
        if self.current_seq == Some(seq) {
            self.current.push(scan);
            return Ok(None);
        }
        if self.done.contains(&seq) {
            return Err(InputError::at_line(
                file,
                line,
                format!(
                    "sequence {seq} comes back after other poses (the scans of one pose must be consecutive)"
                ),
            ));
        }
        let finished = self.finish();
        self.current_seq = Some(seq);
        self.current.push(scan);
        Ok(finished)
    }

    fn finish(&mut self) -> Option<Vec<Scan>> {
        let seq = self.current_seq.take()?;
        self.done.insert(seq);
        Some(std::mem::take(&mut self.current))
    }
}
