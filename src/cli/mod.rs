//! Subcommands, one file each, and the input/output plumbing they share.

mod bag_output;
mod cloud;
mod demo;
mod eval;
mod eval_accuracy;
mod eval_matching;
mod eval_run;
mod info;
mod level;
mod map;
mod matching;
mod output;
mod progress;
mod reference_tum;
mod scan_input;
mod simulate;
mod summary;
mod view;

use anyhow::Context;
use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use levelscan::level::LevelParams;
use levelscan::simulate::OdometryParams;
use std::fs::File;
use std::io::{self, BufRead, BufReader, Read};
use std::path::Path;

pub use output::{open_output, write_file};

/// Planar laser localization on uneven floors: simulate tilted scans, level them, match them.
#[derive(Parser, Debug)]
#[command(name = "levelscan", version, about, long_about = None)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Run the whole system on a built-in example and write a report.
    Demo(demo::Args),
    /// Simulate multi-elevation laser scans from a floor plan (.wall).
    Simulate(Box<simulate::Args>),
    /// Estimate each pose's attitude and write one pseudo-level scan per pose.
    Level(level::Args),
    /// Match 2D scans against a growing map (metascan, the default) or pairwise; fills in
    /// `estimate`.
    Match(matching::Args),
    /// Parse a scan file and summarise it as one JSON object.
    Info(info::Args),
    /// Reproduce the paper's experiments.
    #[command(subcommand)]
    Eval(eval::EvalCommand),
    /// Write a self-contained HTML page with a 3D view of scans, polygons and plans.
    View(view::Args),
    /// Write an occupancy grid for ROS map_server (PGM + YAML) from matched scans.
    Map(map::Args),
    /// Write one pose's scans as a PLY point cloud in the robot frame.
    Cloud(cloud::Args),
}

pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Demo(a) => demo::run(a),
        Command::Simulate(a) => simulate::run(*a),
        Command::Level(a) => level::run(a),
        Command::Match(a) => matching::run(a),
        Command::Info(a) => info::run(a),
        Command::Eval(c) => eval::run(c),
        Command::View(a) => view::run(a),
        Command::Map(a) => map::run(a),
        Command::Cloud(a) => cloud::run(a),
    }
}

/// The `--seed` default of every command that draws random numbers (simulate, demo, eval):
/// one default, so that `simulate` and `eval` runs without `--seed` see the same draws.
pub const DEFAULT_SEED: u64 = 1;

/// The odometry noise model's flags (simulate, eval matching, eval real): per step, Gaussian
/// noise proportional to the step plus a constant (`simulate::OdometryParams`).
#[derive(clap::Args, Debug, Clone)]
pub struct OdometryNoiseArgs {
    /// Odometry noise: translation sigma per step, fraction of the step's length (x and y each).
    #[arg(long, default_value_t = OdometryParams::default().trans_per_m)]
    pub odo_trans: f64,
    /// Odometry noise: translation sigma added to every step (m).
    #[arg(long, default_value_t = OdometryParams::default().trans_const)]
    pub odo_trans_min: f64,
    /// Odometry noise: heading sigma per step, fraction of the step's rotation.
    #[arg(long, default_value_t = OdometryParams::default().rot_per_rad)]
    pub odo_rot: f64,
    /// Odometry noise: heading sigma added to every step (deg).
    #[arg(long, default_value_t = OdometryParams::default().rot_const.to_degrees())]
    pub odo_rot_min: f64,
}

impl OdometryNoiseArgs {
    /// The model, checked: every sigma finite and >= 0.
    pub fn params(&self) -> anyhow::Result<OdometryParams> {
        let p = OdometryParams {
            trans_per_m: self.odo_trans,
            trans_const: self.odo_trans_min,
            rot_per_rad: self.odo_rot,
            rot_const: self.odo_rot_min.to_radians(),
        };
        anyhow::ensure!(
            p.is_valid(),
            "--odo-trans, --odo-trans-min, --odo-rot and --odo-rot-min must be finite and >= 0"
        );
        Ok(p)
    }
}

/// The nodding-laser flags that `simulate` and `eval accuracy` share (`ScannerParams`).
#[derive(clap::Args, Debug, Clone)]
pub struct SweepArgs {
    /// Nodding laser: the hinge turns at this rate while each scan is taken (deg/s; positive
    /// tilts the beams further down), each ray cast at its own elevation, centred on the scan's,
    /// and written to the scan's `ray_elevation`. 0 stops the hinge for each scan.
    #[arg(
        long,
        default_value_t = 0.0,
        allow_hyphen_values = true,
        value_name = "DEG_PER_S"
    )]
    pub sweep_rate: f64,
    /// Scans per second (Hz): one scan's rays spread evenly over 1/rate seconds (what sets
    /// each ray's time, and so its elevation, when the hinge sweeps).
    #[arg(long, default_value_t = levelscan::simulate::ScannerParams::default().scan_rate, value_name = "HZ")]
    pub scan_rate: f64,
}

/// The leveling flags that `level` and `eval accuracy` share (`level::LevelParams`).
#[derive(clap::Args, Debug, Clone)]
pub struct LevelArgs {
    /// A pose whose attitude sigma exceeds this fails as parallel_walls (deg).
    #[arg(long, default_value_t = LevelParams::default().max_sigma_deg)]
    pub max_sigma: f64,
    /// Use walls alone, as the paper does: do not take the floor and ceiling seen as level.
    /// For places where the visible floor itself slopes (long ramps, rubble).
    #[arg(long)]
    pub walls_only: bool,
    /// Do not use each scan's floor (or ceiling) points as a line that must be level where
    /// no floor plane is found (on by default: it levels poses that see the floor in one
    /// scan only).
    #[arg(long)]
    pub no_floor_lines: bool,
    /// Passes of re-segmentation in the provisional level frame (robust estimator): points
    /// re-assigned to the floor and ceiling by height and to walls as vertical planes, then
    /// up re-estimated. 0 turns it off.
    #[arg(long, default_value_t = LevelParams::default().refine_passes)]
    pub refine_passes: usize,
}

impl LevelArgs {
    /// `params` with these flags applied.
    pub fn apply(&self, params: LevelParams) -> LevelParams {
        LevelParams {
            max_sigma_deg: self.max_sigma,
            level_surfaces: !self.walls_only,
            level_lines: !self.no_floor_lines,
            refine_passes: self.refine_passes,
            ..params
        }
    }
}

/// True when the error is a closed output pipe (e.g. `levelscan simulate ... | head`).
pub fn is_broken_pipe(e: &anyhow::Error) -> bool {
    e.chain().any(|c| {
        c.downcast_ref::<io::Error>()
            .is_some_and(|io| io.kind() == io::ErrorKind::BrokenPipe)
    })
}

/// An opened input: its display name (for `FILE:LINE:` messages) and a buffered reader.
pub struct Input {
    pub name: String,
    pub reader: Box<dyn BufRead + Send>,
}

/// A UTF-8 byte order mark.
const UTF8_BOM: &[u8] = b"\xEF\xBB\xBF";

/// Opens a file argument, or standard input for `None` or `-`. Gzip files (by their magic
/// bytes) are decompressed on the fly, so CARMEN `.log.gz` files can be read as they are; a
/// leading UTF-8 byte order mark is skipped.
pub fn open_input(path: Option<&Path>) -> anyhow::Result<Input> {
    let (name, raw): (String, Box<dyn Read + Send>) = match path {
        None => ("<stdin>".to_string(), Box::new(io::stdin())),
        Some(p) if p == Path::new("-") => ("<stdin>".to_string(), Box::new(io::stdin())),
        Some(p) => {
            let f = File::open(p).with_context(|| format!("{}: cannot open", p.display()))?;
            (p.display().to_string(), Box::new(f))
        }
    };
    let mut buffered = BufReader::with_capacity(1 << 16, raw);
    let is_gzip = buffered
        .fill_buf()
        .with_context(|| format!("{name}: cannot read"))?
        .starts_with(&[0x1f, 0x8b]);
    let mut reader: Box<dyn BufRead + Send> = if is_gzip {
        Box::new(BufReader::with_capacity(
            1 << 16,
            flate2::read::MultiGzDecoder::new(buffered),
        ))
    } else {
        Box::new(buffered)
    };
    // A UTF-8 byte order mark (Windows editors write one) is not part of the first line:
    // skipped here, every command's text input (scans, plans, trajectories) reads as without.
    if reader
        .fill_buf()
        .with_context(|| format!("{name}: cannot read"))?
        .starts_with(UTF8_BOM)
    {
        reader.consume(UTF8_BOM.len());
    }
    Ok(Input { name, reader })
}

/// A progress bar on standard error; indicatif hides it when standard error is not a terminal.
pub fn progress_bar(len: u64, what: &str) -> ProgressBar {
    let bar = ProgressBar::new(len);
    bar.set_style(
        ProgressStyle::with_template("{msg:>12} [{bar:40}] {pos}/{len} ({eta})")
            .expect("static template")
            .progress_chars("=> "),
    );
    bar.set_message(what.to_string());
    bar
}
