//! `levelscan eval matching` (paper Figs. 8-10, 12) and `levelscan eval real` (real CARMEN logs
//! with perturbed odometry).

use super::matching::{MatchOptions, ray_timing};
use super::scan_input::open_scans;
use super::{open_output, write_file};
use anyhow::Context;
use levelscan::eval::bound::WallPlanes;
use levelscan::eval::drift::{DRIFT_LENGTHS, Drift};
use levelscan::eval::matching::{ExperimentParams, matching_experiment};
use levelscan::eval::pair_bound::{RunBound, run_bound, scan_rays};
use levelscan::eval::path_bound::{PathBound, path_bound, seen_by_at_least};
use levelscan::eval::real::{RealLog, RealResult, RealSweep, evaluate_real};
use levelscan::formats::bag::BagOptions;
use levelscan::formats::{CarmenParams, read_plan};
use levelscan::matching::{
    DeskewParams, MatcherParams, Mode, OdometryPrior, deskew_summary, scan_points,
    timed_scan_points,
};
use levelscan::simulate::{
    AdaptiveParams, OdometryParams, ScannerParams, World, elevations_centred,
};
use levelscan::viz::plots::{MapPanel, map_panels_png, map_panels_svg, run_map_panel};
use std::fmt::Write as _;
use std::io::Write as _;
use std::path::PathBuf;

// The experiment matches every run both ways (pairwise and metascan), so `--mode` has nothing
// to choose here: hidden rather than shown and ignored.
#[derive(clap::Args, Debug)]
#[command(mut_arg("mode", |a| a.hide(true)))]
pub struct MatchingArgs {
    /// Floor plans (.wall) with a path of `poses` (tilted; the level-floor run zeroes the tilt).
    #[arg(required = true)]
    pub plans: Vec<PathBuf>,
    /// Directory for `matching.md`, `matching.json` and the maps (PNG and SVG).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Random seed, of the simulation: the same seed gives the same figures.
    #[arg(long, default_value_t = super::DEFAULT_SEED)]
    pub seed: u64,
    /// Range noise (m): the standard deviation of the simulated readings' errors. (Formerly
    /// `--noise`, still accepted.)
    #[arg(long, alias = "noise", default_value_t = ScannerParams::default().noise_sigma)]
    pub sigma: f64,
    /// Scans per pose of the tilted run, at elevations --step apart centred on level.
    #[arg(long, default_value_t = 3)]
    pub scans: usize,
    /// Elevation step between scans (deg), in the tilted run; positive elevations tilt the
    /// beams down.
    #[arg(long, allow_negative_numbers = true, default_value_t = 5.0)]
    pub step: f64,
    /// Take one set of scans per pose; by default cleverRobot takes the tilted run, retaking a
    /// pose's scans at other elevations when it cannot level them (as the paper's experiment).
    #[arg(long)]
    pub no_retakes: bool,
    #[command(flatten)]
    pub odometry: super::OdometryNoiseArgs,
    #[command(flatten)]
    pub options: MatchOptions,
}

pub fn run_matching(args: MatchingArgs) -> anyhow::Result<()> {
    anyhow::ensure!(
        args.scans >= 3,
        "--scans: leveling needs at least 3 scans per pose"
    );
    // The simulated robot stands still while it scans: there is nothing to deskew.
    anyhow::ensure!(
        args.options.deskew().is_none(),
        "--deskew, --time-increment and --interlace are for match and eval real: eval matching \
         simulates a robot that stands still while it scans"
    );
    anyhow::ensure!(
        args.sigma.is_finite() && args.sigma >= 0.0,
        "--sigma must be >= 0"
    );
    let odometry = args.odometry.params()?;
    let mut matcher = told_the_odometry_noise(args.options.params()?, &odometry);
    // The simulated scanner's range noise, for the level-floor runs' local lines (a leveled
    // scan states the noise the leveler used in its `readings_sigma`).
    matcher.normals.range_sigma = args.sigma.max(f64::MIN_POSITIVE);
    let params = ExperimentParams {
        seed: args.seed,
        odometry,
        scanner: ScannerParams {
            noise_sigma: args.sigma,
            ..ScannerParams::default()
        },
        elevations: elevations_centred(args.scans, args.step.to_radians()),
        adaptive: (!args.no_retakes).then(AdaptiveParams::default),
        matcher,
        ..ExperimentParams::default()
    };
    if let Some(dir) = &args.out {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("{}: cannot create", dir.display()))?;
    }
    let mut table = String::from(
        "| plan | scans | mode | ATE [m] | RPE median [mm] | RPE p95 [mm] | bad pairs | fallbacks |\n\
         |---|---|---|---:|---:|---:|---:|---:|\n",
    );
    let mut bounds = String::from(
        "| plan | ATE bound [m] | causal sigma [m] | ATE bound, walls of 3+ rays [m] |\n\
         |---|---:|---:|---:|\n",
    );
    let mut all = Vec::new();
    for path in &args.plans {
        let plan = read_plan(path)?;
        anyhow::ensure!(
            plan.poses.len() >= 2,
            "{}:poses: the experiment needs a path of at least 2 poses, the plan has {}; add a \
             `poses` list to it, [[x, y, z, rz, ry, rx], ...] in metres and degrees, along the \
             robot's path (e.g. examples/plans/two_rooms.wall)",
            path.display(),
            plan.poses.len()
        );
        let stem = path
            .file_stem()
            .map_or("plan".to_string(), |s| s.to_string_lossy().into_owned());
        let bar = super::progress::spinner(&format!("eval matching: {}", path.display()));
        let (truth, runs) = matching_experiment(&plan, &params);
        bar.finish_and_clear();
        for r in &runs {
            let _ = writeln!(
                table,
                "| {stem} | {} | {} | {} | {} | {} | {} | {} |",
                r.kind.label(),
                mode_label(r.mode),
                r.ate.map_or("-".into(), |a| format!("{:.4}", a.rmse)),
                r.rpe
                    .map_or("-".into(), |x| format!("{:.2}", x.median_translation * 1e3)),
                r.rpe
                    .map_or("-".into(), |x| format!("{:.2}", x.p95_translation * 1e3)),
                r.rpe.map_or("-".into(), |x| x.bad_pairs.to_string()),
                r.fallbacks
            );
        }
        let [bound, lines] = [0, LINE_RAYS].map(|m| run_path_bound(&plan, &truth, &params, m));
        let _ = writeln!(
            bounds,
            "| {stem} | {} | {} | {} |",
            bound.map_or("-".into(), |b| format!("{:.4}", b.ate)),
            bound.map_or("-".into(), |b| format!("{:.4}", b.causal_rms)),
            lines.map_or("-".into(), |b| format!("{:.4}", b.ate)),
        );
        if let Some(dir) = &args.out {
            write_maps(dir, &stem, &plan, &runs, &truth)?;
        }
        all.push(serde_json::json!({
            "plan": stem, "poses": truth.len(), "runs": runs,
            "bound": bound, "bound_walls_of_3_rays": lines,
        }));
    }
    let table = format!("{table}\n{bounds}");
    write_stdout(&table, &args.plans)?;
    match &args.out {
        Some(dir) => write_tables(dir, "matching", &table, &all),
        None => Ok(()),
    }
}

/// Rays a scan must put on a wall for a line-based matcher to use it: `match` fits its local
/// lines through three neighbouring points at least.
const LINE_RAYS: usize = 3;

/// The bound on the level-floor run's path ([`path_bound`]): its scans' rays at the true
/// poses (those on walls a scan meets with at least `min_rays`), the simulated range noise
/// and odometry.
fn run_path_bound(
    plan: &levelscan::plan::Plan,
    truth: &[levelscan::geometry::Pose2],
    params: &ExperimentParams,
    min_rays: usize,
) -> Option<PathBound> {
    let world = World::from_plan(plan);
    let planes = WallPlanes::new(&plan.segments());
    let scanner = &params.scanner;
    let rays: Vec<_> = truth
        .iter()
        .map(|pose| scan_rays(&world, &planes, pose, scanner.bearings(), scanner.max_range))
        .collect();
    path_bound(
        &planes,
        truth,
        &seen_by_at_least(&rays, min_rays),
        scanner.range_sigma(),
        &params.odometry,
        params.seed,
    )
}

/// The maps of one plan's runs, pairwise and metascan, as PNG and SVG in `dir`.
fn write_maps(
    dir: &std::path::Path,
    stem: &str,
    plan: &levelscan::plan::Plan,
    runs: &[levelscan::eval::matching::RunResult],
    truth: &[levelscan::geometry::Pose2],
) -> anyhow::Result<()> {
    for mode in [Mode::Pairwise, Mode::Metascan] {
        let panels: Vec<MapPanel> = runs
            .iter()
            .filter(|r| r.mode == mode)
            .map(|r| run_map_panel(plan, r, truth))
            .collect();
        let name = format!("{stem}_{}", mode_label(mode));
        let size = (600 * panels.len() as u32, 520);
        map_panels_png(&panels, &dir.join(format!("{name}.png")), size)
            .map_err(|e| anyhow::anyhow!("{name}.png: {e}"))?;
        let svg = map_panels_svg(&panels, size).map_err(|e| anyhow::anyhow!("{name}.svg: {e}"))?;
        write_file(&dir.join(format!("{name}.svg")), svg.as_bytes())?;
    }
    Ok(())
}

/// `NAME.md` (the table) and `NAME.json` (`json`) in `dir`.
fn write_tables(
    dir: &std::path::Path,
    name: &str,
    table: &str,
    json: &impl serde::Serialize,
) -> anyhow::Result<()> {
    write_file(&dir.join(format!("{name}.md")), table.as_bytes())?;
    let json = serde_json::to_string_pretty(json)? + "\n";
    write_file(&dir.join(format!("{name}.json")), json.as_bytes())
}

/// The table on standard output; `inputs` are the files the run read.
fn write_stdout(table: &str, inputs: &[PathBuf]) -> anyhow::Result<()> {
    let inputs: Vec<Option<&std::path::Path>> = inputs.iter().map(|p| Some(p.as_path())).collect();
    let mut out = open_output(None, &inputs)?;
    out.write_all(table.as_bytes())?;
    out.finish()
}

fn mode_label(mode: Mode) -> &'static str {
    match mode {
        Mode::Pairwise => "pairwise",
        Mode::Metascan => "metascan",
    }
}

#[derive(clap::Args, Debug)]
pub struct RealArgs {
    /// Logs whose poses are a reference trajectory (CARMEN corrected logs, or JSON Lines with
    /// `true_pose`), optionally gzipped.
    #[arg(required = true)]
    pub logs: Vec<PathBuf>,
    /// Random seed, of the odometry perturbation: the same seed gives the same scores.
    #[arg(long, default_value_t = super::DEFAULT_SEED)]
    pub seed: u64,
    #[command(flatten)]
    pub odometry: super::OdometryNoiseArgs,
    /// Directory for `real.md`, `real.json` and each log's reference, matched and odometry
    /// trajectories (`NAME.reference.tum`, `NAME.matched.tum`, `NAME.odometry.tum`: TUM, as
    /// evo reads); none written when absent.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// A floor plan, the one the logs were simulated in (`simulate PLAN --flat`): adds the
    /// Cramér-Rao bound on each consecutive pair's motion, and the RPE median an efficient
    /// matcher would show over the pairs beside the run's own.
    #[arg(long)]
    pub plan: Option<PathBuf>,
    /// Range noise the logs were simulated with, for `--plan` (m, a standard deviation).
    #[arg(long, default_value_t = 0.01, requires = "plan")]
    pub range_sigma: f64,
    #[command(flatten)]
    pub options: MatchOptions,
    #[command(flatten)]
    pub bag: super::scan_input::BagArgs,
}

/// The matcher told the odometry noise the experiment adds (`--odo-*`), as a user tells it
/// their odometry's, unless `--prior-*` say otherwise (any of them off its default): the
/// degeneracy-aware solve weighs the odometry for what the scans leave unpinned by it.
fn told_the_odometry_noise(mut params: MatcherParams, noise: &OdometryParams) -> MatcherParams {
    let (m, d) = (params.odometry, OdometryPrior::default());
    // The sigmas as given; the residual scale is not the odometry's.
    if (OdometryPrior {
        residual_sigma: d.residual_sigma,
        ..m
    }) == d
    {
        params.odometry = OdometryPrior {
            trans_per_m: noise.trans_per_m,
            trans_const: noise.trans_const,
            rot_per_rad: noise.rot_per_rad,
            rot_const: noise.rot_const,
            ..m
        };
    }
    params
}

/// The scene of `eval real --plan`: the plan's world and its walls as lines.
struct BoundScene {
    name: String,
    world: World,
    planes: WallPlanes,
    sigma: f64,
}

impl BoundScene {
    fn read(args: &RealArgs) -> anyhow::Result<Option<Self>> {
        let Some(path) = &args.plan else {
            return Ok(None);
        };
        let sigma = args.range_sigma;
        if !(sigma.is_finite() && sigma > 0.0) {
            anyhow::bail!("--range-sigma must be a positive number of metres (got {sigma})");
        }
        let plan = read_plan(path)?;
        Ok(Some(BoundScene {
            name: path.display().to_string(),
            world: World::from_plan(&plan),
            planes: WallPlanes::new(&plan.segments()),
            sigma,
        }))
    }

    /// The bound over `log`'s consecutive pairs; an error when the log's readings do not
    /// meet the plan's walls where its poses say (not simulated in this plan, or a real log).
    fn bound(&self, log: &RealLog) -> anyhow::Result<Option<RunBound>> {
        let bound = run_bound(
            &self.world,
            &self.planes,
            &log.reference,
            &log.points,
            self.sigma,
        );
        if let Some(b) = &bound
            && b.agreeing < MIN_AGREEING
        {
            anyhow::bail!(
                "{}: only {:.1}% of its readings lie where {}'s walls are from the scans' poses: \
                 --plan wants the plan the log was simulated in",
                log.name,
                100.0 * b.agreeing,
                self.name
            );
        }
        Ok(bound)
    }
}

/// The share of a log's readings that must agree with `--plan` (a simulated log in its plan
/// agrees on all but the rare reading more than five sigmas off).
const MIN_AGREEING: f64 = 0.9;

/// Reads a log's scans and reference poses.
fn load_real_log(
    path: &std::path::Path,
    ranges: &levelscan::matching::RangeParams,
    carmen: CarmenParams,
    bag: &BagOptions,
    deskew: Option<DeskewParams>,
) -> anyhow::Result<RealLog> {
    let input = open_scans(Some(path), carmen, bag)?;
    let name = input.name.clone();
    let mut log = RealLog {
        name: path
            .file_name()
            .map_or(name.clone(), |n| n.to_string_lossy().into_owned()),
        points: Vec::new(),
        reference: Vec::new(),
        times: Vec::new(),
        sweep: deskew.map(|params| RealSweep {
            params,
            ray_times: Vec::new(),
            stamps: Vec::new(),
        }),
    };
    let bag = input.survey.is_some();
    let mut last_sequence = None;
    for item in input.source {
        let (line, scan) = item?;
        // Several scans of one pose are a tilting scanner's, not a 2D log: RPE between them
        // would be nonsense.
        if scan.sequence.is_some() && scan.sequence == last_sequence && scan.elevation.is_some() {
            anyhow::bail!(
                "{name}:{line}: several scans per pose (a tilting scanner's multi-elevation scans); \
                 eval real wants one 2D scan per pose: level them first (levelscan level {name} -o level.jsonl)"
            );
        }
        last_sequence = scan.sequence;
        let reference = scan.true_pose.with_context(|| {
            if bag {
                format!("{name}: scan {line} has no reference pose (a /ground_truth PoseStamped within 0.1 s)")
            } else {
                format!("{name}:{line}: no reference pose (a CARMEN pose or `true_pose`)")
            }
        })?;
        match &mut log.sweep {
            Some(real) => {
                let timing = ray_timing(&real.params, &scan, &name, line)?;
                let (points, times) = timed_scan_points(&scan, ranges, &timing);
                log.points.push(points);
                real.ray_times.push(times);
                real.stamps.push(scan.timestamp.map(|t| t.seconds()));
            }
            None => log.points.push(scan_points(&scan, ranges)),
        }
        log.reference.push(reference.to_pose2());
        let index = log.times.len() as f64;
        log.times
            .push(scan.timestamp.map_or(index, |t| t.seconds()));
    }
    Ok(log)
}

pub fn run_real(args: RealArgs) -> anyhow::Result<()> {
    let noise = args.odometry.params()?;
    let params = told_the_odometry_noise(args.options.params()?, &noise);
    let scene = BoundScene::read(&args)?;
    let mut results: Vec<RealResult> = Vec::new();
    if let Some(dir) = &args.out {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("{}: cannot create", dir.display()))?;
    }
    for path in &args.logs {
        let bar = super::progress::spinner(&format!("eval real: {}", path.display()));
        let log = load_real_log(
            path,
            &params.ranges,
            args.options.carmen(),
            &args.bag.options(false, Some("/scan_level")),
            args.options.deskew(),
        )?;
        let mut result = evaluate_real(&log, &params, &noise, args.seed)
            .with_context(|| format!("{}: fewer than two scans", path.display()))?;
        if let Some(scene) = &scene {
            result.bound = scene.bound(&log)?;
        }
        bar.finish_and_clear();
        eprintln!(
            "{}: {} scans, RPE median {:.2} mm (odometry {:.2} mm), drift at 10 m {}",
            result.name,
            result.scans,
            result.matched.median_translation * 1e3,
            result.odometry.median_translation * 1e3,
            result
                .drift
                .iter()
                .find(|d| d.length == 10.0)
                .map_or("-".into(), |d| format!("{:.2}%", d.translation_percent))
        );
        if let Some(b) = &result.bound {
            eprintln!(
                "{}: Cramér-Rao bound over {} consecutive pairs: an efficient matcher's RPE median {:.2} mm; this run's is {:.2} times it",
                result.name,
                b.pairs,
                b.median_translation * 1e3,
                result.matched.median_translation / b.median_translation
            );
        }
        if let (Some(n), Some(sweep)) = (result.deskewed, &log.sweep) {
            let line = deskew_summary(&result.name, n, result.scans, &sweep.params);
            eprintln!("{line}");
        }
        if let Some(dir) = &args.out {
            write_trajectories(dir, &log, &result)?;
        }
        results.push(result);
    }
    let mut table = real_table(&results);
    if let Some(scene) = &scene {
        table.push_str(&bound_table(&results, scene));
    }
    write_stdout(&table, &args.logs)?;
    if let Some(dir) = &args.out {
        write_tables(dir, "real", &table, &results)?;
    }
    Ok(())
}

/// The log's reference, matched and perturbed-odometry trajectories as TUM files in `dir`
/// (`NAME.reference.tum`, `NAME.matched.tum`, `NAME.odometry.tum`), for `evo` and the like.
fn write_trajectories(
    dir: &std::path::Path,
    log: &RealLog,
    result: &RealResult,
) -> anyhow::Result<()> {
    let stem = log.name.trim_end_matches(".gz").trim_end_matches(".log");
    for (kind, poses) in [
        ("reference", &log.reference),
        ("matched", &result.matched_poses),
        ("odometry", &result.odometry_poses),
    ] {
        let mut text = Vec::new();
        for (t, pose) in log.times.iter().zip(poses) {
            levelscan::formats::write_tum(&mut text, *t, pose)?;
        }
        write_file(&dir.join(format!("{stem}.{kind}.tum")), &text)?;
    }
    Ok(())
}

/// The bound's table (`--plan`): each run's RPE median beside an efficient matcher's.
fn bound_table(results: &[RealResult], scene: &BoundScene) -> String {
    let mut s = format!(
        "\nCramér-Rao bound on consecutive pairs ({}, range sigma {} m): what an efficient matcher would show\n\n\
         | log | pairs | unobservable | RPE median [mm] | efficient median [mm] | ratio | bound RMS [mm] | bound RMS heading [deg] |\n\
         |---|---:|---:|---:|---:|---:|---:|---:|\n",
        scene.name, scene.sigma
    );
    for r in results {
        let Some(b) = &r.bound else {
            let _ = writeln!(s, "| {} | - | - | - | - | - | - | - |", r.name);
            continue;
        };
        let _ = writeln!(
            s,
            "| {} | {} | {} | {:.2} | {:.2} | {:.2} | {:.2} | {:.4} |",
            r.name,
            b.pairs,
            b.unobservable,
            r.matched.median_translation * 1e3,
            b.median_translation * 1e3,
            r.matched.median_translation / b.median_translation,
            b.rms_translation * 1e3,
            b.rms_rotation.to_degrees()
        );
    }
    s
}

/// The results as a markdown table.
fn real_table(results: &[RealResult]) -> String {
    let mut s = String::from(
        "| log | scans | RPE median [mm] | RPE p95 [mm] | bad pairs | odometry median [mm] | odometry bad pairs | closure median [mm] | fallbacks | coarse |\n\
         |---|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for r in results {
        let _ = writeln!(
            s,
            "| {} | {} | {:.2} | {:.2} | {} | {:.2} | {} | {} | {} | {} |",
            r.name,
            r.scans,
            r.matched.median_translation * 1e3,
            r.matched.p95_translation * 1e3,
            r.matched.bad_pairs,
            r.odometry.median_translation * 1e3,
            r.odometry.bad_pairs,
            r.closure
                .map_or("-".into(), |c| format!("{:.2}", c.median_translation * 1e3)),
            r.fallbacks,
            r.coarse
        );
    }
    s.push_str(
        "\nDrift over segments of reference path (KITTI-style): translation [%] / heading [deg/m]\n\n\
         | log | 1 m | 2 m | 5 m | 10 m | odometry 10 m |\n|---|---:|---:|---:|---:|---:|\n",
    );
    for r in results {
        let cell = |d: &[Drift], length: f64| {
            d.iter()
                .find(|d| d.length == length)
                .map_or("-".into(), |d| {
                    format!("{:.2} / {:.3}", d.translation_percent, d.rotation_deg_per_m)
                })
        };
        let cells: Vec<String> = DRIFT_LENGTHS.iter().map(|l| cell(&r.drift, *l)).collect();
        let _ = writeln!(
            s,
            "| {} | {} | {} |",
            r.name,
            cells.join(" | "),
            cell(&r.odometry_drift, 10.0)
        );
    }
    s
}
