//! `levelscan demo`: the whole system on a built-in plan, in one command (README's first).
//!
//! Simulates a tilted run through the office plan (the paper's Fig. 5c setting: partitions and
//! pillars, a path over an uneven floor) with the adaptive robot, levels every pose (sect.
//! 5-6), matches raw and leveled scans pairwise and against a growing map (sect. 8.2, Figs.
//! 8-10), runs Table I on the same plan (sect. 8.1), and writes `DIR/report.html`
//! (self-contained) with the JSON behind it.

use super::level::level_record;
use super::progress_bar;
use anyhow::Context;
use levelscan::eval::accuracy::{AccuracyParams, CellStats, run_accuracy};
use levelscan::eval::matching::{
    RunKind, RunResult, adaptive_attempt, match_scans, nearest_level_scan,
};
use levelscan::eval::metrics::{Ate, Rpe};
use levelscan::formats::{parse_plan, write_scan};
use levelscan::geometry::{Attitude, Pose, Pose2};
use levelscan::level::{LevelParams, level_pose};
use levelscan::matching::matcher::{MatcherParams, Mode};
use levelscan::plan::Plan;
use levelscan::pseudo_level::PseudoLevelParams;
use levelscan::scan::Scan;
use levelscan::simulate::adaptive::AdaptiveParams;
use levelscan::simulate::{
    OdometryParams, ScannerParams, World, elevations_centred, odometry, simulate_poses,
};
use levelscan::viz::histogram;
use levelscan::viz::html::{Source, ViewParams, build_scene, viewer_page};
use levelscan::viz::plots::{
    AccuracyCell, MapPanel, grouped_bars_png, grouped_bars_svg, map_panels_png, map_panels_svg,
    run_map_panel, table_one_chart,
};
use levelscan::viz::report::{Block, Figure, Panel, Report, Section, Table, render};
use rayon::prelude::*;
use serde::Serialize;
use serde_json::json;
use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The built-in plan: a 10 x 8 m office with partitions and pillars, 30 poses on a tilted path.
const OFFICE: &str = include_str!("../../examples/plans/office.wall");

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Directory for report.html, report.json, the figures and the run's scans.
    #[arg(long, default_value = "levelscan-demo")]
    pub out: PathBuf,
    /// Random seed (same seed, same report numbers).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Range noise of the simulated scanner \[m\].
    #[arg(long, default_value_t = 0.01)]
    pub noise: f64,
    /// Scans per pose, at elevations --step apart centred on level.
    #[arg(long, default_value_t = 5)]
    pub scans: usize,
    /// Elevation step between scans \[deg\].
    #[arg(long, default_value_t = 5.0)]
    pub step: f64,
    /// Random poses per cell of Table I (the paper's 100).
    #[arg(long, default_value_t = 100)]
    pub accuracy_poses: usize,
}

/// One matched run's numbers.
#[derive(Clone, Debug, Serialize)]
struct MatchRow {
    /// Which scans: "level floor", "raw" or "leveled".
    run: String,
    /// "pairwise" or "metascan".
    mode: String,
    ate: Option<Ate>,
    rpe: Option<Rpe>,
    /// Scans whose step came from odometry.
    fallbacks: usize,
    scans: usize,
}

impl From<&RunResult> for MatchRow {
    fn from(r: &RunResult) -> Self {
        MatchRow {
            run: r.kind.label().to_string(),
            mode: match r.mode {
                Mode::Pairwise => "pairwise",
                Mode::Metascan => "metascan",
            }
            .to_string(),
            ate: r.ate,
            rpe: r.rpe,
            fallbacks: r.fallbacks,
            scans: r.scans,
        }
    }
}

/// How leveling went on the demo's own run.
#[derive(Clone, Debug, Serialize)]
struct PoseLevel {
    sequence: u64,
    status: String,
    reason: Option<String>,
    /// The paper's error max(|dx|, |dy|) against the simulator's truth \[deg\].
    error_deg: Option<f64>,
    polygons: usize,
    valid_points: usize,
}

#[derive(Clone, Debug, Serialize)]
struct LevelSummary {
    poses: usize,
    leveled: usize,
    mean_error_deg: Option<f64>,
    max_error_deg: Option<f64>,
    per_pose: Vec<PoseLevel>,
}

#[derive(Clone, Debug, Serialize)]
struct Settings {
    plan: String,
    poses: usize,
    scans_per_pose: usize,
    elevation_step_deg: f64,
    noise_m: f64,
    seed: u64,
    accuracy_poses: usize,
    robot: String,
}

/// Everything the report shows, as written to report.json.
#[derive(Clone, Debug, Serialize)]
struct DemoData {
    settings: Settings,
    level: LevelSummary,
    matching: Vec<MatchRow>,
    accuracy: Vec<CellStats>,
    timings_s: BTreeMap<String, f64>,
}

/// A matched run with what its maps need.
pub fn run(args: Args) -> anyhow::Result<()> {
    anyhow::ensure!(
        args.scans >= 3,
        "--scans: leveling needs at least 3 scans per pose"
    );
    anyhow::ensure!(args.noise >= 0.0, "--noise: must not be negative");
    let plan = parse_plan(OFFICE, "office.wall")?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("{}: cannot create directory", args.out.display()))?;
    let stages = progress_bar(6, "demo");
    let mut timings = BTreeMap::new();
    let mut clock = Instant::now();
    let mut lap = |name: &str, timings: &mut BTreeMap<String, f64>| {
        timings.insert(name.to_string(), clock.elapsed().as_secs_f64());
        clock = Instant::now();
    };

    // 1. Simulate: the tilted run, and the same path on a level floor as the reference.
    stages.set_message("simulate");
    let (tilted, flat, truth) = simulate_run(&plan, &args);
    let retook = tilted
        .iter()
        .filter(|scans| scans.iter().any(|s| adaptive_attempt(s) > 0))
        .count();
    write_jsonl(
        &args.out.join("scans_tilted.jsonl"),
        tilted.iter().flatten(),
    )?;
    stages.inc(1);
    lap("simulate", &mut timings);

    // 2. Level every pose (sect. 5) and make its pseudo-level scan (sect. 6).
    stages.set_message("level");
    let level_params = LevelParams::default();
    let pseudo_params = PseudoLevelParams::default();
    let leveled: Vec<(Scan, Option<Attitude>)> = tilted
        .par_iter()
        .map(|scans| {
            let est = level_pose(scans, &level_params);
            (
                level_record(scans, &est, &pseudo_params, true),
                est.attitude,
            )
        })
        .collect();
    write_jsonl(
        &args.out.join("leveled.jsonl"),
        leveled.iter().map(|(s, _)| s),
    )?;
    let level = level_summary(&tilted, &leveled);
    stages.inc(1);
    lap("level", &mut timings);

    // 3. Match level-floor, raw and leveled scans, pairwise and metascan (sect. 8.2).
    stages.set_message("match");
    let raw: Vec<Scan> = tilted
        .iter()
        .map(|scans| nearest_level_scan(scans))
        .collect();
    let leveled_scans: Vec<Scan> = leveled.iter().map(|(s, _)| s.clone()).collect();
    let inputs: [(RunKind, &[Scan]); 3] = [
        (RunKind::LevelFloor, &flat),
        (RunKind::Raw, &raw),
        (RunKind::Leveled, &leveled_scans),
    ];
    let jobs: Vec<(RunKind, &[Scan], Mode)> = inputs
        .iter()
        .flat_map(|&(kind, scans)| {
            [Mode::Pairwise, Mode::Metascan].map(move |mode| (kind, scans, mode))
        })
        .collect();
    let matcher = MatcherParams::default();
    let runs: Vec<RunResult> = jobs
        .par_iter()
        .map(|&(kind, scans, mode)| match_scans(kind, scans, mode, &truth, &matcher))
        .collect();
    stages.inc(1);
    lap("match", &mut timings);

    // 4. Table I on the same plan (sect. 8.1), the paper's protocol.
    stages.set_message("Table I");
    let accuracy_params = AccuracyParams {
        poses_per_plan: args.accuracy_poses,
        estimators: vec![level_params.estimator],
        seed: args.seed,
        ..AccuracyParams::default()
    };
    let accuracy = run_accuracy(std::slice::from_ref(&plan), &accuracy_params)
        .context("Table I: cannot place random poses in the office plan")?;
    stages.inc(1);
    lap("table_one", &mut timings);

    // 5. Figures, written beside the report and embedded in it.
    stages.set_message("figures");
    let data = DemoData {
        settings: Settings {
            plan: "office.wall (built in)".to_string(),
            poses: tilted.len(),
            scans_per_pose: args.scans,
            elevation_step_deg: args.step,
            noise_m: args.noise,
            seed: args.seed,
            accuracy_poses: args.accuracy_poses,
            robot: format!(
                "cleverRobot (simulate --adaptive): it levels its own scans at each pose and \
                 retakes them at other elevations when it faced the floor or the ceiling or \
                 could not level them; it retook scans at {retook} of {} poses",
                tilted.len()
            ),
        },
        level,
        matching: runs.iter().map(MatchRow::from).collect(),
        accuracy,
        timings_s: BTreeMap::new(),
    };
    let figures = make_figures(&args.out, &plan, &runs, &data.accuracy);
    stages.inc(1);
    lap("figures", &mut timings);

    // 6. The report and the JSON behind it.
    stages.set_message("report");
    let pose_view = pose_scene(&plan, &tilted, &leveled);
    let matched_view = matched_scene(&plan, &runs, &leveled_scans);
    std::fs::write(args.out.join("view_pose.html"), viewer_page(&pose_view))
        .with_context(|| format!("{}: cannot write", args.out.display()))?;
    let data = DemoData {
        timings_s: timings.clone(),
        ..data
    };
    let report = build_report(&data, figures, pose_view, matched_view);
    let report_path = args.out.join("report.html");
    std::fs::write(&report_path, render(&report))
        .with_context(|| format!("{}: cannot write", report_path.display()))?;
    let json_path = args.out.join("report.json");
    let json_text = serde_json::to_string_pretty(&data).context("report.json")?;
    std::fs::write(&json_path, json_text + "\n")
        .with_context(|| format!("{}: cannot write", json_path.display()))?;
    stages.inc(1);
    stages.finish_and_clear();
    print_summary(&data, &report_path)?;
    Ok(())
}

/// The tilted run (scans per pose, taken by cleverRobot), the same path on a level floor (one
/// level scan per pose) and the true planar poses.
fn simulate_run(plan: &Plan, args: &Args) -> (Vec<Vec<Scan>>, Vec<Scan>, Vec<Pose2>) {
    let world = World::from_plan(plan);
    let poses = &plan.poses;
    let odo = odometry(poses, &OdometryParams::default(), args.seed);
    let scanner = ScannerParams {
        noise_sigma: args.noise,
        ..ScannerParams::default()
    };
    let elevations = elevations_centred(args.scans, args.step.to_radians());
    // cleverRobot (sect. 7.2.2): each pose levels its own scans and retakes them when it could
    // not level them or faced the floor or the ceiling.
    let tilted = simulate_poses(
        &world,
        poses,
        Some(&odo),
        0,
        &elevations,
        &scanner,
        Some(&AdaptiveParams::default()),
        args.seed,
    );
    let flat_poses: Vec<Pose> = poses
        .iter()
        .map(|p| Pose::new(p.x, p.y, p.z, p.rz, 0.0, 0.0))
        .collect();
    let flat = simulate_poses(
        &world,
        &flat_poses,
        Some(&odo),
        0,
        &[0.0],
        &scanner,
        None,
        args.seed,
    )
    .into_iter()
    .flatten()
    .collect();
    let truth = poses.iter().map(Pose::to_pose2).collect();
    (tilted, flat, truth)
}

fn level_summary(tilted: &[Vec<Scan>], leveled: &[(Scan, Option<Attitude>)]) -> LevelSummary {
    let per_pose: Vec<PoseLevel> = tilted
        .iter()
        .zip(leveled)
        .map(|(scans, (record, attitude))| {
            let level = record.extra.get("level");
            let field = |k: &str| level.and_then(|l| l.get(k));
            let truth = scans
                .first()
                .and_then(|s| s.true_pose)
                .map(|p| p.attitude());
            PoseLevel {
                sequence: record.sequence.unwrap_or(0),
                status: field("status")
                    .and_then(|v| v.as_str())
                    .unwrap_or("failed")
                    .to_string(),
                reason: field("reason").and_then(|v| v.as_str()).map(str::to_string),
                error_deg: attitude
                    .zip(truth)
                    .map(|(a, t)| a.max_abs_error(&t).to_degrees()),
                polygons: field("polygons").and_then(|v| v.as_u64()).unwrap_or(0) as usize,
                valid_points: record.valid_count(),
            }
        })
        .collect();
    let errors: Vec<f64> = per_pose.iter().filter_map(|p| p.error_deg).collect();
    LevelSummary {
        poses: per_pose.len(),
        leveled: per_pose.iter().filter(|p| p.status == "ok").count(),
        mean_error_deg: (!errors.is_empty())
            .then(|| errors.iter().sum::<f64>() / errors.len() as f64),
        max_error_deg: errors.iter().copied().reduce(f64::max),
        per_pose,
    }
}

fn write_jsonl<'a>(path: &Path, scans: impl Iterator<Item = &'a Scan>) -> anyhow::Result<()> {
    let file = std::fs::File::create(path)
        .with_context(|| format!("{}: cannot create", path.display()))?;
    let mut w = std::io::BufWriter::new(file);
    for s in scans {
        write_scan(&mut w, s).with_context(|| format!("{}: cannot write", path.display()))?;
    }
    w.flush()
        .with_context(|| format!("{}: cannot write", path.display()))
}

/// The figures of the report.
struct Figures {
    /// Raw vs leveled metascan maps (the headline), then pairwise.
    metascan: [Figure; 2],
    pairwise: [Figure; 2],
    level_floor: Figure,
    table_one: Figure,
    histogram: Figure,
}

/// Writes one map as PNG and SVG in `dir`, and returns the PNG for embedding (smaller than
/// the SVG's thousands of points).
fn map_figure(dir: &Path, stem: &str, panels: &[MapPanel], size: (u32, u32)) -> Figure {
    let png = dir.join(format!("{stem}.png"));
    let result = map_panels_png(panels, &png, size)
        .and_then(|_| map_panels_svg(panels, size))
        .map_err(|e| e.to_string())
        .and_then(|svg| {
            std::fs::write(dir.join(format!("{stem}.svg")), svg).map_err(|e| e.to_string())?;
            std::fs::read(&png).map_err(|e| e.to_string())
        });
    match result {
        Ok(bytes) => Figure::Png(bytes),
        Err(e) => Figure::Missing(e),
    }
}

fn make_figures(dir: &Path, plan: &Plan, runs: &[RunResult], accuracy: &[CellStats]) -> Figures {
    let truth: Vec<Pose2> = plan.poses.iter().map(Pose::to_pose2).collect();
    let find = |kind: RunKind, mode: Mode| {
        runs.iter()
            .find(|r| r.kind == kind && r.mode == mode)
            .map(|r| run_map_panel(plan, r, &truth))
            .unwrap_or_default()
    };
    let one = |stem: &str, panel: MapPanel| map_figure(dir, stem, &[panel], (620, 520));
    let metascan = [
        one("map_raw_metascan", find(RunKind::Raw, Mode::Metascan)),
        one(
            "map_leveled_metascan",
            find(RunKind::Leveled, Mode::Metascan),
        ),
    ];
    let pairwise = [
        one("map_raw_pairwise", find(RunKind::Raw, Mode::Pairwise)),
        one(
            "map_leveled_pairwise",
            find(RunKind::Leveled, Mode::Pairwise),
        ),
    ];
    let level_floor = map_figure(
        dir,
        "map_level_floor",
        &[
            find(RunKind::LevelFloor, Mode::Pairwise),
            find(RunKind::LevelFloor, Mode::Metascan),
        ],
        (1240, 520),
    );
    // Side by side in one picture too, for papers and slides (the report embeds them apart,
    // so each keeps its own caption).
    let _ = map_figure(
        dir,
        "maps_raw_vs_leveled",
        &[
            find(RunKind::Raw, Mode::Metascan),
            find(RunKind::Leveled, Mode::Metascan),
        ],
        (1240, 520),
    );
    let cells: Vec<AccuracyCell> = accuracy
        .iter()
        .map(|c| AccuracyCell {
            noise: c.noise,
            scans: c.scans,
            mean_deg: c.mean_deg,
        })
        .collect();
    let chart = table_one_chart(&cells);
    let table_one = match grouped_bars_svg(&chart, (760, 420)) {
        Ok(svg) => {
            let _ = std::fs::write(dir.join("table1.svg"), &svg);
            let _ = grouped_bars_png(&chart, &dir.join("table1.png"), (760, 420));
            Figure::Svg(svg)
        }
        Err(e) => Figure::Missing(e.to_string()),
    };
    // The paper's Fig. 6 shows 5 cm noise; take the noisiest level run when 5 cm is absent.
    let noise = accuracy
        .iter()
        .map(|c| c.noise)
        .min_by(|a, b| (a - 0.05).abs().total_cmp(&(b - 0.05).abs()))
        .unwrap_or(0.05);
    let series: Vec<histogram::Series> = accuracy
        .iter()
        .filter(|c| c.noise == noise)
        .map(|c| histogram::Series {
            label: format!("{} scans", c.scans),
            errors_deg: c.errors_deg.clone(),
        })
        .collect();
    let title = format!(
        "Distribution of error, {:.0} cm noise (paper Fig. 6)",
        noise * 100.0
    );
    let histogram = match histogram::write_histogram(dir, "fig6_histogram", &title, &series) {
        Ok(()) => std::fs::read_to_string(dir.join("fig6_histogram.svg"))
            .map(Figure::Svg)
            .unwrap_or_else(|e| Figure::Missing(e.to_string())),
        Err(e) => Figure::Missing(e),
    };
    Figures {
        metascan,
        pairwise,
        level_floor,
        table_one,
        histogram,
    }
}

/// The 3D view of one pose (the paper's Fig. 5a): its scans, the wall polygons, the
/// pseudo-level scan and the plan. The pose shown is the leveled one with most wall polygons.
fn pose_scene(
    plan: &Plan,
    tilted: &[Vec<Scan>],
    leveled: &[(Scan, Option<Attitude>)],
) -> levelscan::viz::html::Scene {
    let polygons = |s: &Scan| {
        s.extra
            .get("wall_polygons")
            .and_then(|v| v.as_array())
            .map_or(0, Vec::len)
    };
    let best = (0..leveled.len())
        .max_by_key(|&k| (leveled[k].1.is_some(), polygons(&leveled[k].0)))
        .unwrap_or(0);
    let (Some(scans), Some((record, _))) = (tilted.get(best), leveled.get(best)) else {
        return build_scene(Some(plan), &[], &ViewParams::default());
    };
    let sources = [
        Source {
            name: "tilted scans".into(),
            scans: scans.clone(),
        },
        Source {
            name: "level output".into(),
            scans: vec![record.clone()],
        },
    ];
    let params = ViewParams {
        title: format!(
            "Pose {best}: {} scans, {} wall polygons, pseudo-level scan",
            scans.len(),
            polygons(record)
        ),
        ..ViewParams::default()
    };
    build_scene(Some(plan), &sources, &params)
}

/// The leveled scans as matched by metascan, top down (the paper's Fig. 5b).
fn matched_scene(plan: &Plan, runs: &[RunResult], leveled: &[Scan]) -> levelscan::viz::html::Scene {
    let run = runs
        .iter()
        .find(|r| r.kind == RunKind::Leveled && r.mode == Mode::Metascan);
    let scans: Vec<Scan> = match run {
        Some(run) => leveled
            .iter()
            .zip(&run.aligned)
            .map(|(s, e)| {
                let mut s = s.clone();
                s.estimate = Some(Pose::planar(e.x, e.y, e.theta));
                s.extra.remove("wall_polygons");
                s.extra.remove("wall_patches");
                s.extra.insert("match".into(), json!({"status": "ok"}));
                s
            })
            .collect(),
        None => Vec::new(),
    };
    let params = ViewParams {
        title: "Leveled scans matched with metascan, top down".into(),
        ..ViewParams::default()
    };
    build_scene(
        Some(plan),
        &[Source {
            name: "matched".into(),
            scans,
        }],
        &params,
    )
}

/// Three decimals, or "-" for a missing or undefined number (a cell with no leveled pose).
fn fmt_m(v: Option<f64>) -> String {
    v.filter(|v| v.is_finite())
        .map_or("-".into(), |v| format!("{v:.3}"))
}

/// A fraction as a percentage, or "-" when undefined (no leveled pose to count over).
fn percent(v: f64, decimals: usize) -> String {
    if v.is_finite() {
        format!("{:.*}%", decimals, v * 100.0)
    } else {
        "-".into()
    }
}

fn row_of<'a>(data: &'a DemoData, run: &str, mode: &str) -> Option<&'a MatchRow> {
    data.matching
        .iter()
        .find(|r| r.run == run && r.mode == mode)
}

fn ate_of(data: &DemoData, run: &str, mode: &str) -> Option<f64> {
    row_of(data, run, mode).and_then(|r| r.ate.map(|a| a.rmse))
}

fn verdict(data: &DemoData) -> String {
    match (
        ate_of(data, "raw", "metascan"),
        ate_of(data, "leveled", "metascan"),
    ) {
        (Some(raw), Some(lev)) if lev < raw => format!(
            "Leveling works: on this tilted run, metascan matching of leveled scans ends with ATE \
             {lev:.3} m, against {raw:.3} m for the raw scans ({:.0}x smaller).",
            raw / lev.max(1e-6)
        ),
        (Some(raw), Some(lev)) => format!(
            "On this run leveling did not help metascan matching: ATE {lev:.3} m leveled, \
             {raw:.3} m raw."
        ),
        _ => "The matching runs did not produce trajectories to compare.".to_string(),
    }
}

fn build_report(
    data: &DemoData,
    figures: Figures,
    pose_view: levelscan::viz::html::Scene,
    matched_view: levelscan::viz::html::Scene,
) -> Report {
    let s = &data.settings;
    let metric = |run: &str, mode: &str| format!("ATE {} m", fmt_m(ate_of(data, run, mode)));
    let [raw_meta, lev_meta] = figures.metascan;
    let [raw_pair, lev_pair] = figures.pairwise;
    let headline = vec![
        Panel {
            title: "Raw scans, metascan".into(),
            metric: metric("raw", "metascan"),
            caption: "Each pose's scan nearest level, used as it is: floor hits and tilted walls \
                      become phantom obstacles (the paper's Fig. 9b)."
                .into(),
            figure: raw_meta,
        },
        Panel {
            title: "Leveled scans, metascan".into(),
            metric: metric("leveled", "metascan"),
            caption: "Pseudo-level scans from levelscan level (the paper's Fig. 10b). Grey: true \
                      walls; red: matched points; green: true path; blue: estimated path."
                .into(),
            figure: lev_meta,
        },
    ];
    let matching_rows = data
        .matching
        .iter()
        .map(|r| {
            vec![
                r.run.clone(),
                r.mode.clone(),
                fmt_m(r.ate.map(|a| a.rmse)),
                fmt_m(r.ate.map(|a| a.max)),
                r.rpe.map_or("-".into(), |p| {
                    format!("{:.1}", p.median_translation * 1000.0)
                }),
                r.rpe
                    .map_or("-".into(), |p| format!("{:.1}", p.p95_translation * 1000.0)),
                r.rpe.map_or("-".into(), |p| {
                    format!("{:.2}", p.median_rotation.to_degrees())
                }),
                r.rpe
                    .map_or("-".into(), |p| format!("{} / {}", p.bad_pairs, p.pairs)),
                format!("{} / {}", r.fallbacks, r.scans),
            ]
        })
        .collect();
    let matching = Section {
        id: "matching".into(),
        title: "Scan matching: raw vs leveled (sect. 8.2)".into(),
        blocks: vec![Block::Table(Table {
            caption: "ATE: RMSE of positions after the best SE(2) alignment. RPE over \
                          consecutive pairs; a bad pair is off by more than 5 cm or 1 degree. \
                          Fallback: the step came from odometry."
                .into(),
            header: [
                "scans",
                "mode",
                "ATE [m]",
                "ATE max [m]",
                "RPE median [mm]",
                "RPE p95 [mm]",
                "RPE median [deg]",
                "bad pairs",
                "fallbacks",
            ]
            .map(String::from)
            .to_vec(),
            rows: matching_rows,
        })],
    };
    let accuracy_rows = data
        .accuracy
        .iter()
        .map(|c| {
            vec![
                format!("{} scans, {:.0} cm", c.scans, c.noise * 100.0),
                fmt_m(Some(c.mean_deg)),
                fmt_m(c.paper_mean_deg),
                fmt_m(Some(c.median_deg)),
                fmt_m(Some(c.p95_deg)),
                fmt_m(Some(c.max_deg)),
                percent(c.leveled_fraction, 0),
                c.wrong_over_5_deg.to_string(),
                percent(c.phantom_rate, 2),
                percent(c.floor_kept_rate, 2),
                percent(c.coverage, 0),
            ]
        })
        .collect();
    let accuracy = Section {
        id: "accuracy".into(),
        title: "Level accuracy: Table I (sect. 8.1)".into(),
        blocks: vec![
            Block::Text(format!(
                "{} random poses per cell in the office plan, with the paper's protocol: roll \
                 and pitch uniform in +-20 degrees, scanner 0.45 m high, 181 rays over 180 \
                 degrees, elevations 5 degrees apart, Gaussian range noise. Error = \
                 max(|dtheta_x|, |dtheta_y|) over leveled poses. `levelscan eval accuracy` runs \
                 it over several plans and both estimators.",
                s.accuracy_poses
            )),
            Block::Table(Table {
                caption: "Mean error in degrees, beside the paper's Table I.".into(),
                header: [
                    "cell",
                    "mean [deg]",
                    "paper [deg]",
                    "median",
                    "p95",
                    "max",
                    "leveled",
                    "ok but > 5 deg",
                    "phantoms",
                    "floor/ceiling kept",
                    "coverage",
                ]
                .map(String::from)
                .to_vec(),
                rows: accuracy_rows,
            }),
            Block::Panels(vec![
                Panel {
                    title: "Table I as a figure".into(),
                    metric: String::new(),
                    caption: "Filled bars: levelscan; outlined: the paper's values.".into(),
                    figure: figures.table_one,
                },
                Panel {
                    title: "Distribution of error (Fig. 6)".into(),
                    metric: String::new(),
                    caption: "Share of leveled poses per 0.5 degree bucket.".into(),
                    figure: figures.histogram,
                },
            ]),
        ],
    };
    let lv = &data.level;
    let level_text = format!(
        "On the demo run, {} of {} poses were leveled; mean attitude error {} deg, largest {} deg \
         (against the simulator's truth).",
        lv.leveled,
        lv.poses,
        lv.mean_error_deg.map_or("-".into(), |e| format!("{e:.3}")),
        lv.max_error_deg.map_or("-".into(), |e| format!("{e:.3}")),
    );
    let viewer = Section {
        id: "viewer".into(),
        title: "3D view of a pose (Fig. 5a)".into(),
        blocks: vec![
            Block::Text(level_text),
            Block::Text(
                "Red: the pose's scans at each hinge elevation; green and red: the wall polygons \
                 found; blue: the pseudo-level scan; grey: the floor plan. Drag to orbit, wheel to \
                 zoom, untick a layer to hide it."
                    .into(),
            ),
            Block::Viewer(Box::new(pose_view)),
        ],
    };
    let maps = Section {
        id: "maps".into(),
        title: "Matched maps (Figs. 8-10)".into(),
        blocks: vec![
            Block::Panels(vec![
                Panel {
                    title: "Raw scans, pairwise".into(),
                    metric: metric("raw", "pairwise"),
                    caption: "The paper's Fig. 9a.".into(),
                    figure: raw_pair,
                },
                Panel {
                    title: "Leveled scans, pairwise".into(),
                    metric: metric("leveled", "pairwise"),
                    caption: "The paper's Fig. 10a.".into(),
                    figure: lev_pair,
                },
            ]),
            Block::Panels(vec![Panel {
                title: "Reference: the same path on a level floor".into(),
                metric: format!(
                    "pairwise {}, metascan {}",
                    metric("level floor", "pairwise"),
                    metric("level floor", "metascan")
                ),
                caption: "The paper's Fig. 8: what matching achieves when the floor is flat."
                    .into(),
                figure: figures.level_floor,
            }]),
            Block::Viewer(Box::new(matched_view)),
        ],
    };
    let timings: Vec<String> = data
        .timings_s
        .iter()
        .map(|(k, v)| format!("{k} {v:.2} s"))
        .collect();
    let about = Section {
        id: "data".into(),
        title: "Data and reproduction".into(),
        blocks: vec![
            Block::Text(format!(
                "Settings: {} poses of {}, {} scans per pose {} degrees apart, {:.0} mm range \
                 noise, seed {}; robot: {}. Timings: {}.",
                s.poses,
                s.plan,
                s.scans_per_pose,
                s.elevation_step_deg,
                s.noise_m * 1000.0,
                s.seed,
                s.robot,
                timings.join(", ")
            )),
            Block::Text(
                "Beside this page: report.json (every number here), scans_tilted.jsonl (the \
                 simulated scans), leveled.jsonl (level output with wall polygons), \
                 view_pose.html, and the figures as PNG and SVG. The same steps by hand:"
                    .into(),
            ),
            Block::Code(
                "levelscan simulate examples/plans/office.wall --scans 5 > scans.jsonl\n\
                 levelscan level --polygons scans.jsonl > leveled.jsonl\n\
                 levelscan match --mode metascan leveled.jsonl > matched.jsonl\n\
                 levelscan view scans.jsonl leveled.jsonl --plan examples/plans/office.wall -o view.html"
                    .into(),
            ),
        ],
    };
    Report {
        title: "levelscan demo: leveling scans taken on an uneven floor".into(),
        subtitle: format!(
            "{} poses through {}, {} scans per pose, {:.0} mm noise, seed {}",
            s.poses,
            s.plan,
            s.scans_per_pose,
            s.noise_m * 1000.0,
            s.seed
        ),
        verdict: verdict(data),
        headline,
        sections: vec![matching, accuracy, viewer, maps, about],
    }
}

/// The run in a few lines on standard output (written with `open_output`: a full disk is an
/// error naming `<stdout>`, not a panic).
fn print_summary(data: &DemoData, report: &Path) -> anyhow::Result<()> {
    use std::fmt::Write as _;
    let s = &data.settings;
    let mut text = String::new();
    let _ = writeln!(
        text,
        "levelscan demo: {} poses through {}, {} scans each, {:.0} mm noise, seed {}",
        s.poses,
        s.plan,
        s.scans_per_pose,
        s.noise_m * 1000.0,
        s.seed
    );
    let _ = writeln!(text, "  robot:    {}", s.robot);
    let _ = writeln!(
        text,
        "  level:    {} of {} poses leveled, mean attitude error {} deg",
        data.level.leveled,
        data.level.poses,
        data.level
            .mean_error_deg
            .map_or("-".into(), |e| format!("{e:.3}"))
    );
    for mode in ["pairwise", "metascan"] {
        let _ = writeln!(
            text,
            "  {mode:<9} ATE: raw {} m, leveled {} m, level floor {} m",
            fmt_m(ate_of(data, "raw", mode)),
            fmt_m(ate_of(data, "leveled", mode)),
            fmt_m(ate_of(data, "level floor", mode)),
        );
    }
    let cells: Vec<String> = data
        .accuracy
        .iter()
        .map(|c| {
            format!(
                "{}x{:.0}cm {}",
                c.scans,
                c.noise * 100.0,
                fmt_m(Some(c.mean_deg))
            )
        })
        .collect();
    let _ = writeln!(text, "  Table I mean error [deg]: {}", cells.join(", "));
    let _ = writeln!(text, "report: {}", report.display());
    let mut out = super::open_output(None, &[])?;
    std::io::Write::write_all(&mut out, text.as_bytes())?;
    out.finish()
}
