//! `levelscan simulate PLAN.wall`: tilted multi-elevation scans of a floor plan as scan JSON
//! Lines (paper sect. 7.2.1), a thin layer over [`levelscan::simulate`].

use super::bag_output::{OutputFormat, output_format};
use super::{open_output, progress_bar};
use anyhow::{Context, bail};
use levelscan::formats::bag::BagWriter;
use levelscan::formats::bag::simulated::{self, SimMessage};
use levelscan::formats::bag::write::NoSeek;
use levelscan::formats::{InputError, read_plan_from, write_scan};
use levelscan::geometry::Pose;
use levelscan::plan::Plan;
use levelscan::scan::Scan;
use levelscan::simulate::{
    AdaptiveParams, NoiseModel, RandomPoseParams, ScannerParams, World, elevations_centred,
    odometry, random_poses, simulate_poses,
};
use std::path::PathBuf;

/// Poses simulated in parallel between writes: bounds memory, and fixed so that the output
/// does not depend on the thread count.
const CHUNK: usize = 64;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Floor plan (.wall); its `poses` are used unless --random is given. Standard input
    /// when absent or `-`.
    pub plan: Option<PathBuf>,

    /// Rays per scan, spread evenly over the field of view.
    #[arg(long, default_value_t = 181)]
    pub rays: usize,
    /// Field of view centred on the robot's forward axis (deg).
    #[arg(long, default_value_t = 180.0)]
    pub fov: f64,
    /// Scanner's maximum range (m): a reading at or beyond it is no return (rays that meet
    /// nothing within it are invalid).
    #[arg(long, default_value_t = 30.0)]
    pub max_range: f64,
    /// Range noise (m): the standard deviation of the readings' errors, or with
    /// `--noise-model uniform` the full width of uniform noise. (Formerly `--noise`, still
    /// accepted.)
    #[arg(long, alias = "noise", default_value_t = 0.01)]
    pub sigma: f64,
    /// What --sigma means: `gaussian` (a standard deviation) or `uniform` (alias `paper`: a
    /// peak-to-peak width, the paper's "range of about 1 cm", appendix C).
    #[arg(long, value_enum, default_value_t = NoiseModel::Gaussian)]
    pub noise_model: NoiseModel,
    /// Random seed: the same seed gives the same output bytes, whatever the thread count.
    /// (The default is 1 as in every command; it was 0 here: `--seed 0` redoes older runs.)
    #[arg(long, default_value_t = super::DEFAULT_SEED)]
    pub seed: u64,

    /// Scans per pose, at elevations --step apart centred on level.
    #[arg(long, default_value_t = 3)]
    pub scans: usize,
    /// Elevation step between scans (deg); positive elevations tilt the beams down.
    #[arg(long, allow_negative_numbers = true, default_value_t = 5.0)]
    pub step: f64,
    /// Explicit elevations instead of --scans/--step [deg, comma separated], e.g. -5,0,5.
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true, conflicts_with_all = ["scans", "step"])]
    pub elevations: Option<Vec<f64>>,

    /// Simulate N random poses in the plan's free space instead of the plan's poses.
    #[arg(long, value_name = "N")]
    pub random: Option<usize>,
    /// Random poses: roll and pitch uniform in +-TILT (deg).
    #[arg(long, default_value_t = 20.0)]
    pub tilt: f64,
    /// Random poses: smallest distance to every wall (m).
    #[arg(long, default_value_t = 0.5)]
    pub clearance: f64,
    /// Scanner height above the floor, the pose's z (m) [default: 0.45 for random poses; plan
    /// poses keep their own z unless this is given].
    #[arg(long)]
    pub height: Option<f64>,
    /// Level floor: set every pose's roll and pitch to 0 (reference runs without tilt).
    #[arg(long)]
    pub flat: bool,
    /// Hinge offset x,y,z (m): the scanner's origin seen from the hinge axis, in the scanner's
    /// tilted frame (written to each scan's `hinge_offset`) [default: none].
    #[arg(
        long,
        value_delimiter = ',',
        allow_hyphen_values = true,
        value_name = "X,Y,Z"
    )]
    pub hinge_offset: Option<Vec<f64>>,

    #[command(flatten)]
    pub sweep: super::SweepArgs,

    #[command(flatten)]
    pub odometry: super::OdometryNoiseArgs,

    /// The adaptive robot, cleverRobot (paper sect. 7.2.2): take the scans as it would, level
    /// each pose's scans and, when the estimate is poor, retake them at other elevations:
    /// tilted the other way when they face the floor or the ceiling, away from the floor (or
    /// the ceiling) when the walls seen cannot pin the attitude down. Retaken scans keep the pose's
    /// `sequence`; every scan records `"adaptive": {"attempt": k, "shift": rad}`.
    #[arg(long)]
    pub adaptive: bool,
    /// Adaptive robot: retakes allowed per pose.
    #[arg(long, default_value_t = levelscan::simulate::AdaptiveParams::default().max_retakes)]
    pub max_retakes: usize,

    /// Write each scan's `readings_sigma` (the noise sigma). Off by default: `level` estimates
    /// the noise itself.
    #[arg(long)]
    pub with_sigma: bool,
    /// Output file; standard output when absent or `-`. A name ending in `.mcap` writes a
    /// ROS 2 bag (see --format).
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Output format: `jsonl` (scan JSON Lines) or `mcap` (a ROS 2 bag: /scan, /joint_states
    /// with joint `hinge`, /odom, /ground_truth; pose k at 1000 + 2k s, its scans 0.1 s
    /// apart) [default: mcap for an output file named *.mcap, else jsonl].
    #[arg(long, value_enum)]
    pub format: Option<OutputFormat>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let scanner = scanner_params(&args)?;
    let odo = args.odometry.params()?;
    let elevations: Vec<f64> = match &args.elevations {
        Some(list) => list.iter().map(|e| e.to_radians()).collect(),
        None => elevations_centred(args.scans, args.step.to_radians()),
    };
    check_limits(&args, &elevations)?;

    let (plan, name) = load_plan(args.plan.as_deref())?;
    let world = World::from_plan(&plan);
    let poses = poses_of(&args, &plan, &name, &world, &scanner)?;
    let odometry = odometry(&poses, &odo, args.seed);

    let adaptive = args.adaptive.then(|| AdaptiveParams {
        max_retakes: args.max_retakes,
        ..AdaptiveParams::default()
    });
    let format = output_format(args.format, args.output.as_deref());
    if format == OutputFormat::Mcap && elevations.len() > simulated::MAX_SCANS_PER_POSE {
        bail!(
            "a bag holds at most {} scans per pose ({} s apart within the pose's {} s); \
             {} elevations were asked for",
            simulated::MAX_SCANS_PER_POSE,
            simulated::SCAN_SPACING,
            simulated::POSE_PERIOD,
            elevations.len()
        );
    }
    let mut sink = open_sink(&args, format)?;
    let bar = progress_bar(poses.len() as u64, "simulate");
    for (c, chunk) in poses.chunks(CHUNK).enumerate() {
        let first = c * CHUNK;
        let scans = simulate_poses(
            &world,
            chunk,
            Some(&odometry[first..first + chunk.len()]),
            first as u64,
            &elevations,
            &scanner,
            adaptive.as_ref(),
            args.seed,
        );
        for (k, pose_scans) in scans.iter().enumerate() {
            sink.write_pose((first + k) as u64, pose_scans, &scanner)?;
        }
        bar.inc(chunk.len() as u64);
    }
    sink.finish()?;
    bar.finish_and_clear();
    Ok(())
}

/// The poses to simulate: the plan's own (at `--height` when given) or `--random N` drawn in
/// its free space, with roll and pitch zeroed for `--flat`.
fn poses_of(
    args: &Args,
    plan: &Plan,
    name: &str,
    world: &World,
    scanner: &ScannerParams,
) -> anyhow::Result<Vec<Pose>> {
    let poses: Vec<Pose> = match args.random {
        Some(n) => {
            let params = RandomPoseParams {
                tilt: args.tilt.to_radians(),
                clearance: args.clearance,
                height: args.height.unwrap_or(RandomPoseParams::default().height),
                enclosure_range: scanner.max_range,
                ..RandomPoseParams::default()
            };
            if !(params.tilt.is_finite() && params.clearance >= 0.0) {
                bail!("--tilt must be finite and --clearance >= 0");
            }
            random_poses(world, n, &params, args.seed).with_context(|| name.to_string())?
        }
        None => {
            if plan.poses.is_empty() {
                return Err(InputError::new(
                    name,
                    "poses",
                    "the plan has no poses; give --random N to draw some",
                )
                .into());
            }
            let mut poses = plan.poses.clone();
            if let Some(h) = args.height {
                poses.iter_mut().for_each(|p| p.z = h);
            }
            poses
        }
    };
    Ok(if args.flat {
        poses
            .into_iter()
            .map(|p| Pose::new(p.x, p.y, p.z, p.rz, 0.0, 0.0))
            .collect()
    } else {
        poses
    })
}

/// The output `-o` (or standard output), as scan JSON Lines or a ROS 2 bag.
fn open_sink(args: &Args, format: OutputFormat) -> anyhow::Result<Sink> {
    let out = open_output(args.output.as_deref(), &[args.plan.as_deref()])?;
    Ok(match format {
        OutputFormat::Jsonl => Sink::Jsonl(out),
        OutputFormat::Mcap => {
            let name = args
                .output
                .as_deref()
                .filter(|p| p.as_os_str() != "-")
                .map_or(super::output::STDOUT.to_string(), |p| {
                    p.display().to_string()
                });
            Sink::Bag(Box::new(BagWriter::unseekable(out, &name)?))
        }
    })
}

/// Where the simulated scans go.
enum Sink {
    Jsonl(super::output::Output),
    Bag(Box<BagWriter<NoSeek<super::output::Output>>>),
}

impl Sink {
    fn write_pose(
        &mut self,
        k: u64,
        scans: &[Scan],
        scanner: &ScannerParams,
    ) -> anyhow::Result<()> {
        match self {
            Sink::Jsonl(out) => {
                for scan in scans {
                    write_scan(out, scan)?;
                }
            }
            Sink::Bag(bag) => {
                let msgs =
                    simulated::pose_messages(k, scans, scanner).map_err(anyhow::Error::msg)?;
                for (t, m) in &msgs {
                    match m {
                        SimMessage::Scan(x) => bag.write(m.topic(), *t, x)?,
                        SimMessage::Joint(x) => bag.write(m.topic(), *t, x)?,
                        SimMessage::Odom(x) => bag.write(m.topic(), *t, x.as_ref())?,
                        SimMessage::Truth(x) => bag.write(m.topic(), *t, x)?,
                    }
                }
            }
        }
        Ok(())
    }

    fn finish(self) -> anyhow::Result<()> {
        match self {
            Sink::Jsonl(out) => out.finish(),
            Sink::Bag(bag) => bag.finish()?.into_inner().finish(),
        }
    }
}

/// Most random poses per run: their poses and odometry are held in memory (run several seeds
/// for more).
const MAX_RANDOM_POSES: usize = 1_000_000;

/// The elevations and sizes, checked; what the scan readers would refuse
/// (`formats::limits`) is refused here, before simulating.
fn check_limits(args: &Args, elevations: &[f64]) -> anyhow::Result<()> {
    use levelscan::formats::limits::{MAX_ANGLE, MAX_POSITION, MAX_RAYS};
    if elevations.is_empty() {
        bail!("--scans must be at least 1");
    }
    if elevations.iter().any(|e| !e.is_finite()) {
        bail!("elevations must be finite numbers of degrees");
    }
    // Scans of one pose at one elevation give `level` nothing to level from (too_few_scans,
    // whatever --scans said).
    if args.elevations.is_none() && args.step == 0.0 && elevations.len() > 1 {
        bail!(
            "--step 0 puts all {} scans of a pose at one elevation; give a step other than 0 \
             (level needs scans at three or more distinct elevations)",
            elevations.len()
        );
    }
    if let Some(list) = &args.elevations
        && let Some(e) = list
            .iter()
            .find(|e| list.iter().filter(|f| f == e).count() > 1)
    {
        bail!(
            "--elevations lists {e} degrees {} times; the scans of a pose must lie at distinct \
             elevations (level needs three or more)",
            list.iter().filter(|f| *f == e).count()
        );
    }
    if let Some(h) = args.height
        && !h.is_finite()
    {
        bail!("--height must be a finite number of metres");
    }
    anyhow::ensure!(
        args.rays <= MAX_RAYS,
        "--rays {} is more than {MAX_RAYS}, the limit of rays per scan",
        args.rays
    );
    anyhow::ensure!(
        elevations.iter().all(|e| e.abs() <= MAX_ANGLE),
        "elevations must lie within +-360 degrees"
    );
    let lengths = args.height.iter().chain(args.hinge_offset.iter().flatten());
    anyhow::ensure!(
        lengths.into_iter().all(|v| v.abs() <= MAX_POSITION),
        "--height and --hinge-offset must lie within +-{MAX_POSITION:e} m"
    );
    if let Some(n) = args.random {
        // Zero poses would write nothing and exit 0: surely not what was asked for.
        anyhow::ensure!(
            n >= 1,
            "--random 0: no poses to simulate; give the number of random poses (1 or more), or \
             leave --random out to use the plan's poses"
        );
        anyhow::ensure!(
            n <= MAX_RANDOM_POSES,
            "--random {n} is more than {MAX_RANDOM_POSES} poses per run; run several seeds"
        );
    }
    Ok(())
}

fn scanner_params(args: &Args) -> anyhow::Result<ScannerParams> {
    let hinge_offset = match args.hinge_offset.as_deref() {
        None => None,
        Some(&[x, y, z]) => Some([x, y, z]),
        Some(v) => bail!("--hinge-offset needs 3 numbers x,y,z, not {}", v.len()),
    };
    let params = ScannerParams {
        rays: args.rays,
        fov: args.fov.to_radians(),
        max_range: args.max_range,
        noise_sigma: args.sigma,
        noise_model: args.noise_model,
        hinge_offset,
        write_sigma: args.with_sigma,
        sweep_rate: args.sweep.sweep_rate.to_radians(),
        scan_rate: args.sweep.scan_rate,
    };
    params.validate()?;
    Ok(params)
}

/// Reads and validates the floor plan from a file, or standard input for `None` or `-`.
fn load_plan(path: Option<&std::path::Path>) -> anyhow::Result<(Plan, String)> {
    let input = super::open_input(path)?;
    Ok((read_plan_from(input.reader, &input.name)?, input.name))
}
