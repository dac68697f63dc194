//! `levelscan demo`: the whole system on a built-in plan, in one command (README's first).
//!
//! The run is `eval::demo` (simulate, level, match, Table I), the report `viz::demo_report`
//! around `viz::demo_figures`; this file checks the flags, shows progress and writes
//! `DIR/report.html` (self-contained) with the JSON and the files behind it.

use super::progress_bar;
use anyhow::Context;
use levelscan::eval::demo::{DemoData, DemoParams, run_demo};
use levelscan::formats::pgm_map::{Classes, pgm_bytes, yaml_text};
use levelscan::formats::ply::{pose_cloud, write_ply};
use levelscan::formats::write_scan;
use levelscan::occupancy::{GridParams, PlacedScan, build_grid};
use levelscan::scan::Scan;
use levelscan::viz::demo_figures::{make_figures, shown_pose};
use levelscan::viz::demo_report::{build_report, fmt_m};
use levelscan::viz::html::viewer_page;
use levelscan::viz::report::render;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Directory for report.html, report.json, the figures and the run's scans.
    #[arg(long, default_value = "levelscan-demo")]
    pub out: PathBuf,
    /// Random seed: the same seed gives the same report numbers.
    #[arg(long, default_value_t = super::DEFAULT_SEED)]
    pub seed: u64,
    /// Range noise (m): the standard deviation of the simulated readings' errors. (Formerly
    /// `--noise`, still accepted.)
    #[arg(long, alias = "noise", default_value_t = DemoParams::default().noise)]
    pub sigma: f64,
    /// Scans per pose, at elevations --step apart centred on level.
    #[arg(long, default_value_t = DemoParams::default().scans)]
    pub scans: usize,
    /// Elevation step between scans (deg); positive elevations tilt the beams down.
    #[arg(long, allow_negative_numbers = true, default_value_t = DemoParams::default().step_deg)]
    pub step: f64,
    /// Random poses per cell of Table I (the paper's 100).
    #[arg(long, default_value_t = DemoParams::default().accuracy_poses)]
    pub accuracy_poses: usize,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    anyhow::ensure!(
        args.scans >= 3,
        "--scans: leveling needs at least 3 scans per pose"
    );
    anyhow::ensure!(args.sigma >= 0.0, "--sigma: must not be negative");
    let params = DemoParams {
        seed: args.seed,
        noise: args.sigma,
        scans: args.scans,
        step_deg: args.step,
        accuracy_poses: args.accuracy_poses,
    };
    let dir = &args.out;
    std::fs::create_dir_all(dir)
        .with_context(|| format!("{}: cannot create directory", dir.display()))?;
    let stages = progress_bar(6, "demo");
    let mut started = false;
    let mut demo = run_demo(&params, &mut |stage| {
        if std::mem::replace(&mut started, true) {
            stages.inc(1);
        }
        stages.set_message(stage.name());
    })?;
    stages.inc(1);
    write_jsonl(
        &dir.join("scans_tilted.jsonl"),
        demo.tilted.iter().flatten(),
    )?;
    write_jsonl(
        &dir.join("leveled.jsonl"),
        demo.leveled.iter().map(|l| &l.record),
    )?;
    let matched = demo.matched_leveled();
    write_jsonl(&dir.join("matched.jsonl"), matched.iter())?;
    write_map(dir, &matched)?;
    if let Some(scans) = demo.tilted.get(shown_pose(&demo.leveled)) {
        write_cloud(dir, scans)?;
    }

    stages.set_message("figures");
    let clock = Instant::now();
    let figures = make_figures(dir, &demo);
    demo.data
        .timings_s
        .insert("figures".into(), clock.elapsed().as_secs_f64());
    stages.inc(1);

    stages.set_message("report");
    write(
        &dir.join("view_pose.html"),
        &viewer_page(&figures.pose_view),
    )?;
    let report_path = dir.join("report.html");
    write(&report_path, &render(&build_report(&demo.data, figures)))?;
    let json = serde_json::to_string_pretty(&demo.data).context("report.json")?;
    write(&dir.join("report.json"), &(json + "\n"))?;
    stages.inc(1);
    stages.finish_and_clear();
    print_summary(&demo.data, &report_path)?;
    Ok(())
}

/// The occupancy grid of the leveled scans as metascan placed them, for ROS map_server.
fn write_map(dir: &Path, matched: &[Scan]) -> anyhow::Result<()> {
    let placed: Vec<PlacedScan> = matched
        .iter()
        .filter_map(|s| {
            Some(PlacedScan {
                pose: s.estimate?.to_pose2(),
                hits: s.points_2d(),
            })
        })
        .collect();
    let grid = build_grid(&placed, &GridParams::default()).context("map.yaml")?;
    std::fs::write(dir.join("map.pgm"), pgm_bytes(&grid, &Classes::default()))
        .with_context(|| format!("{}: cannot write map.pgm", dir.display()))?;
    write(&dir.join("map.yaml"), &yaml_text("map.pgm", &grid))
}

/// The 3D view's pose as a point cloud, robot frame.
fn write_cloud(dir: &Path, scans: &[Scan]) -> anyhow::Result<()> {
    let points = pose_cloud(scans);
    let sequence = scans.first().and_then(|s| s.sequence).unwrap_or(0);
    let comments = [
        format!("levelscan demo, sequence {sequence}"),
        "frame robot (REP-103: x forward, y left, z up), metres".to_string(),
    ];
    let mut bytes = Vec::new();
    write_ply(&mut bytes, &points, &comments, false).context("pose.ply")?;
    std::fs::write(dir.join("pose.ply"), bytes)
        .with_context(|| format!("{}: cannot write pose.ply", dir.display()))
}

fn write(path: &Path, text: &str) -> anyhow::Result<()> {
    std::fs::write(path, text).with_context(|| format!("{}: cannot write", path.display()))
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

/// The run in a few lines on standard output (written with `open_output`: a full disk is an
/// error naming `<stdout>`, not a panic).
fn print_summary(data: &DemoData, report: &Path) -> anyhow::Result<()> {
    use std::fmt::Write as _;
    let mut text = String::new();
    let s = &data.settings;
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
            fmt_m(data.ate_rmse("raw", mode)),
            fmt_m(data.ate_rmse("leveled", mode)),
            fmt_m(data.ate_rmse("level floor", mode)),
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
