//! `levelscan match`: pairwise or metascan matching of 2D scans; fills in `estimate` and adds
//! the contract's `match` object to each record, streaming (one record in, one record out).

use super::bag_output::{BagOutput, Kind as BagKind, OutputFormat, output_format};
use super::open_output;
use super::reference_tum::ReferenceTum;
use super::scan_input::{BagArgs, open_scans, refuse_raw_scan};
use super::summary::{Kind, Tally};
use clap::ValueEnum;
use levelscan::formats::bag::convert::ros_number;
use levelscan::formats::{CarmenParams, write_tum};
use levelscan::geometry::Pose;
use levelscan::level::believed_range_sigma;
use levelscan::matching::{
    CheckParams, Coarse, CorrelativeParams, CovarianceParams, DeskewParams, IcpParams, Kernel,
    LineRuns, MapParams, MatchReport, MatchStatus, Matcher, MatcherParams, Metric, Mode,
    NormalParams, OdometryPrior, RangeParams, RayTiming, SweepTracker, deskew_summary, scan_points,
    timed_scan_points,
};
use levelscan::scan::Scan;
use nalgebra::Point2;
use serde_json::json;
use std::path::PathBuf;

#[derive(ValueEnum, Clone, Copy, Debug)]
pub enum ModeArg {
    /// Each scan against the previous one.
    Pairwise,
    /// Each scan against a map of all earlier matched scans.
    Metascan,
}

#[derive(ValueEnum, Clone, Copy, Debug)]
pub enum AlgoArg {
    /// Point-to-point ICP (Besl & McKay 1992).
    Icp,
    /// Point-to-line ICP (Censi 2008).
    Plicp,
}

#[derive(ValueEnum, Clone, Copy, Debug)]
pub enum CoarseArg {
    /// ICP starts from the odometry guess.
    Never,
    /// Only when ICP from the odometry guess looks bad.
    Auto,
    /// Before every match.
    Always,
}

#[derive(ValueEnum, Clone, Copy, Debug)]
pub enum KernelArg {
    None,
    Huber,
    Cauchy,
}

/// The matcher's settings as flags, shared by `match` and the `eval` commands.
#[derive(clap::Args, Debug, Clone)]
pub struct MatchOptions {
    /// Metascan (each scan against a map of all earlier ones; the default: it drifts least on
    /// long logs) or pairwise (each scan against the previous).
    //
    // Over 10 m of path on the CARMEN Intel, ACES, CSAIL and Freiburg 079 logs (`eval real
    // --seed N`, mean over seeds 1-10) metascan drifts 0.86, 0.99, 1.16 and 0.90% against
    // pairwise's 0.89, 1.45, 1.35 and 1.04%. One default for `match` and `eval real`; `eval
    // matching` runs both.
    #[arg(long, value_enum, default_value = "metascan")]
    pub mode: ModeArg,
    /// ICP metric: point-to-point (icp) or point-to-line (plicp).
    #[arg(long, value_enum, default_value = "plicp")]
    pub algo: AlgoArg,
    /// Coarse correlative search before ICP (Olson 2009).
    #[arg(long, value_enum, default_value = "auto")]
    pub coarse: CoarseArg,
    /// ICP iteration limit.
    #[arg(long, default_value_t = IcpParams::default().max_iterations)]
    pub max_iterations: usize,
    /// Pairs farther apart are never associated (m).
    #[arg(long, default_value_t = IcpParams::default().max_correspondence_distance)]
    pub max_correspondence_distance: f64,
    /// Smallest fraction of pairs trimming keeps (1 = no trimming) [0-1].
    #[arg(long, default_value_t = IcpParams::default().min_overlap)]
    pub min_overlap: f64,
    /// Robust kernel on the residuals.
    #[arg(long, value_enum, default_value = "huber")]
    pub kernel: KernelArg,
    /// Robust kernel scale (m).
    #[arg(long, default_value_t = IcpParams::default().kernel_scale)]
    pub kernel_scale: f64,
    /// Metascan voxel size (m).
    #[arg(long, default_value_t = MapParams::default().voxel_size)]
    pub voxel_size: f64,
    /// Coarse search: half-width of the translation window (m); a best on the window's edge
    /// is not used, so make it wider than the odometry's error between scans.
    #[arg(long, default_value_t = CorrelativeParams::default().window_xy)]
    pub window_xy: f64,
    /// Coarse search: half-width of the heading window (deg); a best on the window's edge is
    /// not used, so make it wider than the odometry's error between scans.
    #[arg(long, default_value_t = CorrelativeParams::default().window_theta.to_degrees())]
    pub window_theta: f64,
    /// Fall back to odometry with fewer kept pairs than this.
    #[arg(long, default_value_t = CheckParams::default().min_correspondences)]
    pub min_correspondences: usize,
    /// Fall back to odometry when the RMS residual is above this (m).
    #[arg(long, default_value_t = CheckParams::default().max_residual)]
    pub max_residual: f64,
    /// A corridor: when the pairs' normals pin one direction less than this, as λ_min/λ_max of
    /// their scatter, the pose along it comes from odometry (all of it with --whole-fallback).
    #[arg(long, default_value_t = CheckParams::default().min_constraint_ratio)]
    pub min_constraint_ratio: f64,
    /// Degeneracy-aware matching: along each direction of (x, y, yaw), the pose comes from the
    /// scan when the scan's information along it is at least this many times the odometry's,
    /// else from the odometry (the record's `degenerate_directions` lists those).
    #[arg(long, default_value_t = CheckParams::default().min_information_ratio.unwrap_or(10.0))]
    pub min_information_ratio: f64,
    /// A match that does not pin all three directions falls back to odometry whole (instead of
    /// taking only the unpinned ones from it).
    #[arg(long)]
    pub whole_fallback: bool,
    /// Ignore readings shorter than this (m).
    #[arg(long, default_value_t = RangeParams::default().min_range)]
    pub min_range: f64,
    /// Scanner's maximum range (m): a reading at or beyond it is no return, left out of the
    /// match (CARMEN logs write the maximum range for no return); given, it also marks
    /// CARMEN `FLASER` readings invalid as `info` does [default: 40 for the match; for
    /// reading `FLASER` lines the log's `PARAM robot_front_laser_max`, else 50].
    #[arg(long)]
    pub max_range: Option<f64>,
    /// A scan denser than this (rays per degree) takes its local lines from the means of runs
    /// of consecutive rays, spaced at most this density: the lines are fitted over a few rays
    /// each side, which at 0.25 degree (a Hokuyo UTM-30LX) span too little of a wall to beat
    /// the range noise. Every ray is still matched. 0 fits the lines through the raw rays
    #[arg(long, default_value_t = NormalParams::default().max_rays_per_degree)]
    pub max_rays_per_degree: f64,
    /// Pairwise: match each scan one way only (the default also matches the previous scan
    /// against it and takes the midpoint of the two motions).
    #[arg(long)]
    pub one_way: bool,
    /// Weigh the odometry as a Gaussian prior in every ICP solve (MAP instead of scans alone),
    /// with the noise model of the --prior-* flags.
    #[arg(long)]
    pub odometry_prior: bool,
    /// Odometry noise: translation sigma per metre of the step (x and y each): how far the
    /// odometry is trusted for directions a scan leaves unpinned, what a fallback step is
    /// worth, and the prior with --odometry-prior.
    #[arg(long, default_value_t = OdometryPrior::default().trans_per_m)]
    pub prior_trans: f64,
    /// Odometry noise: translation sigma added to every step (m), as --prior-trans.
    #[arg(long, default_value_t = OdometryPrior::default().trans_const)]
    pub prior_trans_min: f64,
    /// Odometry noise: heading sigma per radian of the step, as --prior-trans.
    #[arg(long, default_value_t = OdometryPrior::default().rot_per_rad)]
    pub prior_rot: f64,
    /// Odometry noise: heading sigma added to every step (deg), as --prior-trans.
    #[arg(long, default_value_t = OdometryPrior::default().rot_const.to_degrees())]
    pub prior_rot_min: f64,
    /// Odometry noise: sigma of one ICP residual, the scale between scans and odometry (m).
    #[arg(long, default_value_t = OdometryPrior::default().residual_sigma)]
    pub prior_residual_sigma: f64,
    /// Covariance: variance factor over the sandwich estimate at low residuals.
    #[arg(long, default_value_t = CovarianceParams::default().noise_inflation)]
    pub cov_inflation: f64,
    /// Covariance: RMS residual at which the variance factor doubles (m).
    #[arg(long, default_value_t = CovarianceParams::default().noise_knee)]
    pub cov_knee: f64,
    /// Covariance: a pair's surface error between samples, as a fraction of the beam spacing
    /// at its range, 0 to 10 (0 takes the residuals alone).
    #[arg(long, default_value_t = CovarianceParams::default().sampling_fraction)]
    pub cov_sampling: f64,
    /// Deskew: move each ray to where the scanner was at the mean time of the scan's rays, from
    /// the odometry's velocity between the previous scan and this one (at most 0.5 s before)
    /// and each ray's time (the scans' `time_increment`, as ROS bags give it, or
    /// --time-increment). For a robot that turns while it scans.
    #[arg(long)]
    pub deskew: bool,
    /// Deskew with this time between consecutive rays (s) instead of the scans' own; implies
    /// --deskew. Negative when the rays are listed in the reverse of the order they were cast.
    #[arg(long, allow_hyphen_values = true)]
    pub time_increment: Option<f64>,
    /// Deskew a scan made of this many interleaved sweeps, ray i from sweep i mod K (a SICK
    /// LMS 2xx at 0.5 degrees: 2, at 0.25: 4); --time-increment is then per ray of the whole
    /// scan. Implies --deskew.
    #[arg(long, default_value_t = DeskewParams::default().interlace)]
    pub interlace: usize,
    /// Time from one interleaved sweep to the next (s): the scanner's mirror period.
    #[arg(long, default_value_t = DeskewParams::default().sweep_period)]
    pub sweep_period: f64,
}

impl MatchOptions {
    pub fn params(&self) -> anyhow::Result<MatcherParams> {
        self.check()?;
        Ok(self.unchecked_params())
    }

    /// Readings at or beyond this are left out of the match [m]: `--max-range`, else the
    /// matcher's default.
    fn match_max_range(&self) -> f64 {
        self.max_range.unwrap_or(RangeParams::default().max_range)
    }

    /// How CARMEN `FLASER` lines are read: `--max-range` when given (one meaning of the
    /// flag: the scanner's maximum range), else the log's own.
    pub fn carmen(&self) -> CarmenParams {
        CarmenParams {
            max_range: self.max_range,
        }
    }

    /// Every flag in its range, or an error naming the flag.
    fn check(&self) -> anyhow::Result<()> {
        let positive = [
            (
                "--max-correspondence-distance",
                self.max_correspondence_distance,
            ),
            ("--kernel-scale", self.kernel_scale),
            ("--voxel-size", self.voxel_size),
            ("--window-xy", self.window_xy),
            ("--max-residual", self.max_residual),
            ("--max-range", self.match_max_range()),
            ("--prior-residual-sigma", self.prior_residual_sigma),
            ("--cov-inflation", self.cov_inflation),
            ("--cov-knee", self.cov_knee),
            ("--min-information-ratio", self.min_information_ratio),
        ];
        let prior_sigmas = [
            self.prior_trans,
            self.prior_trans_min,
            self.prior_rot,
            self.prior_rot_min,
        ];
        if prior_sigmas.iter().any(|v| !(v.is_finite() && *v >= 0.0))
            || self.prior_trans_min + self.prior_rot_min <= 0.0
        {
            anyhow::bail!("--prior-*: sigmas must be >= 0 with positive constant parts");
        }
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                anyhow::bail!("{name} must be a positive number, got {v}");
            }
        }
        if !(self.max_rays_per_degree.is_finite() && self.max_rays_per_degree >= 0.0) {
            anyhow::bail!(
                "--max-rays-per-degree must be 0 (off) or a positive number, got {}",
                self.max_rays_per_degree
            );
        }
        if !(self.min_overlap > 0.0 && self.min_overlap <= 1.0) {
            anyhow::bail!("--min-overlap must be in (0, 1], got {}", self.min_overlap);
        }
        if !(0.0..=180.0).contains(&self.window_theta) {
            anyhow::bail!(
                "--window-theta must be between 0 and 180 degrees (180 tries every heading), got {:?}",
                self.window_theta
            );
        }
        // The search's table grows with the window's area: at 25 m it holds a million cells.
        if self.window_xy > 25.0 {
            anyhow::bail!(
                "--window-xy must be at most 25 m (an odometry error between two scans, not a \
                 map's size), got {:?}",
                self.window_xy
            );
        }
        // Beyond these the reported covariance overflows to infinity (written as null).
        if self.cov_knee < 1e-6 || self.cov_inflation > 1e6 {
            anyhow::bail!(
                "--cov-knee must be at least 1e-6 m and --cov-inflation at most 1e6, got {:?} and {:?}",
                self.cov_knee,
                self.cov_inflation
            );
        }
        // A fraction of the beam spacing: more than ten spacings is no longer a sampling error.
        if !(0.0..=10.0).contains(&self.cov_sampling) {
            anyhow::bail!(
                "--cov-sampling must be between 0 and 10 (a fraction of the beam spacing), got {:?}",
                self.cov_sampling
            );
        }
        if self.max_iterations == 0 {
            anyhow::bail!("--max-iterations must be at least 1");
        }
        if !(1..=16).contains(&self.interlace) {
            anyhow::bail!("--interlace must be 1 to 16 sweeps, got {}", self.interlace);
        }
        if !(self.sweep_period > 0.0 && self.sweep_period <= 1.0) {
            anyhow::bail!(
                "--sweep-period must be above 0 and at most 1 s, got {:?}",
                self.sweep_period
            );
        }
        // A hundredth of a second between rays is already a sweep of seconds.
        if let Some(dt) = self.time_increment
            && !(dt.is_finite() && dt.abs() <= 0.01)
        {
            anyhow::bail!(
                "--time-increment must be at most 0.01 s either way (the time between two rays), got {dt:?}"
            );
        }
        Ok(())
    }

    /// Deskewing's settings, when --deskew or --time-increment asks for it.
    pub fn deskew(&self) -> Option<DeskewParams> {
        (self.deskew || self.time_increment.is_some() || self.interlace > 1).then(|| DeskewParams {
            time_increment: self.time_increment,
            interlace: self.interlace,
            sweep_period: self.sweep_period,
            ..DeskewParams::default()
        })
    }

    /// The matcher's parameters from these flags, as given ([`Self::check`] vets them).
    fn unchecked_params(&self) -> MatcherParams {
        MatcherParams {
            mode: match self.mode {
                ModeArg::Pairwise => Mode::Pairwise,
                ModeArg::Metascan => Mode::Metascan,
            },
            icp: IcpParams {
                metric: match self.algo {
                    AlgoArg::Icp => Metric::PointToPoint,
                    AlgoArg::Plicp => Metric::PointToLine,
                },
                max_iterations: self.max_iterations,
                max_correspondence_distance: self.max_correspondence_distance,
                min_overlap: self.min_overlap,
                kernel: match self.kernel {
                    KernelArg::None => Kernel::None,
                    KernelArg::Huber => Kernel::Huber,
                    KernelArg::Cauchy => Kernel::Cauchy,
                },
                kernel_scale: self.kernel_scale,
                ..IcpParams::default()
            },
            normals: NormalParams {
                max_rays_per_degree: self.max_rays_per_degree,
                ..NormalParams::default()
            },
            coarse: match self.coarse {
                CoarseArg::Never => Coarse::Never,
                CoarseArg::Auto => Coarse::Auto,
                CoarseArg::Always => Coarse::Always,
            },
            correlative: CorrelativeParams {
                window_xy: self.window_xy,
                window_theta: self.window_theta.to_radians(),
                ..CorrelativeParams::default()
            },
            map: MapParams {
                voxel_size: self.voxel_size,
                ..MapParams::default()
            },
            checks: CheckParams {
                min_correspondences: self.min_correspondences,
                max_residual: self.max_residual,
                min_constraint_ratio: self.min_constraint_ratio,
                min_information_ratio: (!self.whole_fallback).then_some(self.min_information_ratio),
                ..CheckParams::default()
            },
            ranges: RangeParams {
                min_range: self.min_range,
                max_range: self.match_max_range(),
            },
            symmetric: !self.one_way,
            local_tolerance_factor: MatcherParams::default().local_tolerance_factor,
            odometry: OdometryPrior {
                trans_per_m: self.prior_trans,
                trans_const: self.prior_trans_min,
                rot_per_rad: self.prior_rot,
                rot_const: self.prior_rot_min.to_radians(),
                residual_sigma: self.prior_residual_sigma,
            },
            odometry_prior: self.odometry_prior,
            covariance: CovarianceParams {
                noise_inflation: self.cov_inflation,
                noise_knee: self.cov_knee,
                sampling_fraction: self.cov_sampling,
            },
        }
    }
}

#[derive(clap::Args, Debug)]
pub struct Args {
    /// 2D scans: `level` output or CSM logs (JSON Lines), or CARMEN logs (`FLASER`,
    /// `ROBOTLASER1`), optionally gzipped; standard input when absent or `-`.
    pub scans: Option<PathBuf>,
    #[command(flatten)]
    pub options: MatchOptions,
    /// Range noise (m): the standard deviation of the readings' errors; default: each scan's
    /// `readings_sigma` (level writes the noise it used) when its ranges' scatter bears it out,
    /// else 0.01, what the local lines are made for. A noisier scan fits its lines through the means of runs of rays (3 at 5
    /// cm, 5 at 10 cm): single rays give none at that noise
    #[arg(long)]
    pub sigma: Option<f64>,
    /// Also write the estimated trajectory in TUM format (`timestamp x y z qx qy qz qw`).
    #[arg(long)]
    pub trajectory: Option<PathBuf>,
    /// Also write the reference trajectory, each record's `true_pose` (x, y, yaw as
    /// --trajectory, at the same times), in TUM format; records without one are left out.
    #[arg(long)]
    pub reference_trajectory: Option<PathBuf>,
    /// Output file; standard output when absent or `-`. A name ending in `.mcap` writes a
    /// ROS 2 bag (see --format).
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    #[command(flatten)]
    pub bag: BagArgs,
    /// Output format; default: mcap (a ROS 2 bag) when -o ends in .mcap, else jsonl.
    #[arg(long, value_enum)]
    pub format: Option<OutputFormat>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let params = args.options.params()?;
    if let Some(s) = args.sigma.filter(|s| !(s.is_finite() && *s > 0.0)) {
        anyhow::bail!("--sigma must be a positive number of metres, got {s}");
    }
    let input = open_scans(
        args.scans.as_deref(),
        args.options.carmen(),
        &args.bag.options(false, Some("/scan_level")),
    )?;
    let out = open_output(args.output.as_deref(), &[args.scans.as_deref()])?;
    let (mut out, mut bag_out) = match output_format(args.format, args.output.as_deref()) {
        OutputFormat::Jsonl => (Some(out), None),
        OutputFormat::Mcap => {
            let shown = args
                .output
                .as_deref()
                .map_or("<stdout>".to_string(), |p| p.display().to_string());
            (
                None,
                Some(BagOutput::new(
                    out,
                    &shown,
                    input.bag.clone(),
                    BagKind::Match,
                )?),
            )
        }
    };
    let mut tum = match &args.trajectory {
        Some(p) => Some(open_output(
            Some(p),
            &[args.scans.as_deref(), args.output.as_deref()],
        )?),
        None => None,
    };
    let mut reference = ReferenceTum::open(
        args.reference_trajectory.as_deref(),
        &[args.scans.as_deref(), args.output.as_deref()],
    )?;
    let mut matcher = Matcher::new(params);
    let mut tally = Tally::new(Kind::Match);
    let mut sweep = args.options.deskew().map(Sweep::new);
    let mut runs = RunLengths::default();
    for (index, item) in input.source.enumerate() {
        let (line, mut scan) = item?;
        // A raw bag (no /scan_level) is still matched as it is: its /odom_matched per /scan
        // message is a documented output (tests/bag_interop_output.rs), so only text input,
        // where forgetting `level` is the usual slip, is refused.
        if input.survey.is_none() {
            refuse_raw_scan(
                &input.name,
                line,
                &scan,
                "match",
                "level them first: levelscan level SCANS | levelscan match",
            )?;
        }
        let points = match sweep.as_mut() {
            Some(sweep) => sweep.points(&scan, &params.ranges, &input.name, line)?,
            None => scan_points(&scan, &params.ranges),
        };
        let odometry = scan.odometry.map(|p| p.to_pose2());
        let sigma = args.sigma.or_else(|| {
            let believed = believed_range_sigma(std::slice::from_ref(&scan));
            if believed.is_none() && scan.stated_range_sigma().is_some() {
                tally.note_noise_set_aside();
            }
            believed
        });
        let report = matcher.push_with_sigma(&points, odometry, sigma);
        runs.add(
            matcher.line_runs(),
            sigma.unwrap_or(params.normals.range_sigma),
        );
        annotate(&mut scan, &report);
        tally.add_matched(&scan);
        reference.push(&scan, index)?;
        match (&mut out, &mut bag_out) {
            (Some(out), _) => levelscan::formats::write_scan(out, &scan)?,
            (None, Some(bag)) => bag.match_record(&scan)?,
            (None, None) => unreachable!("one output is open"),
        }
        if let Some(t) = tum.as_mut() {
            let time = scan.timestamp.map_or(index as f64, |t| t.seconds());
            write_tum(t, time, &report.estimate)?;
        }
    }
    if let Some(out) = out {
        out.finish()?;
    }
    if let Some(bag) = bag_out {
        bag.finish()?;
    }
    if let Some(t) = tum {
        t.finish()?;
    }
    reference.finish(&input.name)?;
    tally.report(&input.name);
    if let Some(line) = runs.summary() {
        eprintln!("{line}");
    }
    if let Some(sweep) = sweep {
        eprintln!("{}", sweep.summary());
    }
    Ok(())
}

/// How many scans fitted their local lines through the means of runs of rays, how long, and
/// why, so that a user of a dense or noisy scanner sees why its lines differ from a SICK's.
#[derive(Default)]
struct RunLengths {
    /// Scans per run length above 1.
    scans: std::collections::BTreeMap<usize, usize>,
    total: usize,
    /// The largest stated range noise of the scans whose runs their noise made longer \[m\].
    noise: Option<f64>,
}

impl RunLengths {
    /// Counts one scan whose lines took `runs`, at range noise `sigma` \[m\].
    fn add(&mut self, runs: LineRuns, sigma: f64) {
        self.total += 1;
        if runs.length > 1 {
            *self.scans.entry(runs.length).or_default() += 1;
            if runs.for_noise {
                self.noise = Some(self.noise.unwrap_or(0.0).max(sigma));
            }
        }
    }

    fn summary(&self) -> Option<String> {
        let (&k, _) = self.scans.iter().max_by_key(|(_, n)| **n)?;
        let n: usize = self.scans.values().sum();
        let why = match self.noise {
            Some(s) => format!("for their range noise, up to {:.1} cm; --sigma", s * 100.0),
            None => "for their density; --max-rays-per-degree".to_string(),
        };
        Some(format!(
            "levelscan match: {n} of {} scans fitted their local lines through the means of runs \
             of {k} rays ({why})",
            self.total
        ))
    }
}

/// When the rays of the scan at `line` of `name` were cast, for deskewing: the time between
/// rays from --time-increment, else the scan's own (a ROS LaserScan's), and the interleaving;
/// an error naming the scan when neither gives the time.
pub fn ray_timing(
    params: &DeskewParams,
    scan: &Scan,
    name: &str,
    line: usize,
) -> anyhow::Result<RayTiming> {
    let time_increment = params
        .time_increment
        .or_else(|| ros_number(scan, "time_increment"))
        .unwrap_or(0.0);
    if time_increment == 0.0 || !time_increment.is_finite() {
        anyhow::bail!(
            "{name}:{line}: --deskew needs the time between rays, and this scan has no \
             time_increment (a ROS LaserScan's): give it with --time-increment SECONDS"
        );
    }
    Ok(RayTiming {
        time_increment,
        interlace: params.interlace,
        sweep_period: params.sweep_period,
    })
}

/// Deskewing a run as it streams (`--deskew`): each scan's points, moved to the scanner's frame
/// at the mean time of its rays where the odometry gives a velocity.
pub struct Sweep {
    params: DeskewParams,
    tracker: SweepTracker,
    deskewed: usize,
    total: usize,
}

impl Sweep {
    pub fn new(params: DeskewParams) -> Self {
        Self {
            params,
            tracker: SweepTracker::new(),
            deskewed: 0,
            total: 0,
        }
    }

    /// The usable points of the scan at `line` of `name`, deskewed when the odometry gives a
    /// velocity; an error when neither the scan nor --time-increment gives its rays' timing.
    pub fn points(
        &mut self,
        scan: &Scan,
        ranges: &RangeParams,
        name: &str,
        line: usize,
    ) -> anyhow::Result<Vec<Point2<f64>>> {
        let timing = ray_timing(&self.params, scan, name, line)?;
        let time = scan.timestamp.map(|t| t.seconds());
        let odometry = scan.odometry.map(|p| p.to_pose2());
        self.total += 1;
        let (mut points, times) = timed_scan_points(scan, ranges, &timing);
        if self
            .tracker
            .deskew_next(&mut points, &times, odometry, time, &self.params)
        {
            self.deskewed += 1;
        }
        Ok(points)
    }

    /// How many scans were deskewed, and why the others were not.
    pub fn summary(&self) -> String {
        deskew_summary("levelscan match", self.deskewed, self.total, &self.params)
    }
}

/// Fills in `estimate` and the contract's `match` object.
pub fn annotate(scan: &mut Scan, report: &MatchReport) {
    let e = report.estimate;
    scan.estimate = Some(Pose::planar(e.x, e.y, e.theta));
    let (status, reason) = match report.status {
        MatchStatus::First => ("ok", Some("first_scan")),
        MatchStatus::Ok => ("ok", None),
        MatchStatus::Fallback(r) => ("fallback", Some(r.as_str())),
    };
    scan.extra.insert(
        "match".to_string(),
        json!({
            "status": status,
            "reason": reason,
            "iterations": report.iterations,
            "correspondences": report.correspondences,
            "residual": report.residual,
            "coarse": report.coarse,
            "covariance": report.covariance_row_major(),
            "degenerate_directions": report.degenerate_directions(),
        }),
    );
}
