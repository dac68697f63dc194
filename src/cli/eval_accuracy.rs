//! `levelscan eval accuracy PLAN...`: the paper's Table I and Fig. 6 (sect. 8.1).

use super::{LevelArgs, open_output, write_file};
use anyhow::Context;
use levelscan::eval::accuracy::{
    AccuracyError, AccuracyParams, CellStats, Efficiency, run_accuracy_with,
};
use levelscan::eval::true_segments::TrueSegmentsFit;
use levelscan::formats::read_plan;
use levelscan::level::{Estimator, LevelParams};
use levelscan::simulate::NoiseModel;
use levelscan::viz::histogram::{Series, write_histogram};
use std::fmt::Write as _;
use std::io::Write as _;
use std::path::{Path, PathBuf};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Floor plans (.wall); poses are drawn in each and the statistics pooled.
    #[arg(required = true)]
    pub plans: Vec<PathBuf>,
    /// Scans per pose, at elevations --step apart centred on level; a comma-separated list,
    /// one table row each.
    #[arg(long, value_delimiter = ',', default_value = "3,4,5")]
    pub scans: Vec<usize>,
    /// Range noise (m): the standard deviations of the readings' errors, or with
    /// `--noise-model uniform` the full widths of uniform noise; a comma-separated list, one
    /// table column each. (Formerly `--noise`, still accepted.)
    #[arg(
        long,
        alias = "noise",
        value_delimiter = ',',
        default_value = "0.01,0.05,0.10"
    )]
    pub sigma: Vec<f64>,
    /// What --sigma means: `gaussian` (a standard deviation) or `uniform` (alias `paper`: a
    /// peak-to-peak width, the paper's "range of about 1 cm", appendix C).
    #[arg(long, value_enum, default_value_t = NoiseModel::Gaussian)]
    pub noise_model: NoiseModel,
    /// Coplanarity tolerance of the paper's quads (sect. 5.2), in sigmas of the range noise
    /// (estimated from the data).
    #[arg(long, default_value_t = LevelParams::default().coplanar_k)]
    pub quad_tolerance: f64,
    /// Up-vector estimator: a comma-separated list of those to compare (`paper`, `robust`).
    /// (Formerly `--estimators`, still accepted.)
    #[arg(
        long,
        alias = "estimators",
        value_enum,
        value_delimiter = ',',
        default_value = "paper,robust"
    )]
    pub estimator: Vec<Estimator>,
    /// Random poses per plan.
    #[arg(long, default_value_t = 100)]
    pub poses: usize,
    /// Random seed, of the poses and the noise: the same seed gives the same tables.
    #[arg(long, default_value_t = super::DEFAULT_SEED)]
    pub seed: u64,
    /// Elevation step between scans (deg); positive elevations tilt the beams down.
    #[arg(long, allow_negative_numbers = true, default_value_t = 5.0)]
    pub step: f64,
    /// Random poses: roll and pitch uniform in +-TILT (deg).
    #[arg(long, default_value_t = 20.0)]
    pub tilt: f64,
    #[command(flatten)]
    pub leveling: LevelArgs,
    /// The adaptive robot, cleverRobot (paper sect. 7.2.2): take the scans as it would,
    /// retaking a pose's scans at other elevations when it cannot level them, as the paper's
    /// Table I did.
    #[arg(long)]
    pub adaptive: bool,
    #[command(flatten)]
    pub sweep: super::SweepArgs,
    /// Level as if the hinge stood still during each scan: drop the per-ray elevations of a
    /// sweep, every ray at its scan's elevation (what ignoring the sweep costs).
    #[arg(long)]
    pub drop_ray_elevation: bool,
    /// Directory for accuracy.json, poses.jsonl (every pose's outcome) and the Fig. 6
    /// histograms (PNG, SVG); none written when absent.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    // Zero poses would print tables of 0/0.
    anyhow::ensure!(
        args.poses >= 1,
        "--poses 0: no poses to level; give the number of random poses per plan (1 or more)"
    );
    anyhow::ensure!(
        !args.scans.is_empty() && args.scans.iter().all(|&s| s >= 1),
        "--scans must list scan counts of at least 1"
    );
    anyhow::ensure!(
        args.sigma.iter().all(|n| n.is_finite() && *n >= 0.0),
        "--sigma must list non-negative sigmas in metres"
    );
    anyhow::ensure!(
        args.quad_tolerance.is_finite() && args.quad_tolerance > 0.0,
        "--quad-tolerance must be a positive number of sigmas"
    );
    // The scans' elevations are centred on level, `step` apart; `simulate`'s limit applies.
    let most = args.scans.iter().copied().max().unwrap_or(1);
    anyhow::ensure!(
        args.step.is_finite() && args.step > 0.0 && (most - 1) as f64 / 2.0 * args.step <= 360.0,
        "--step {:?} with --scans up to {most}: the elevations must lie within +-360 degrees and \
         the step be positive",
        args.step,
    );
    anyhow::ensure!(
        args.tilt.is_finite() && (0.0..=90.0).contains(&args.tilt),
        "--tilt must be between 0 and 90 degrees, got {:?}",
        args.tilt
    );
    let plans = args
        .plans
        .iter()
        .map(|p| read_plan(p).map_err(anyhow::Error::from))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let params = AccuracyParams {
        scans: args.scans.clone(),
        noise: args.sigma.clone(),
        noise_model: args.noise_model,
        estimators: args.estimator.clone(),
        poses_per_plan: args.poses,
        seed: args.seed,
        step_deg: args.step,
        tilt_deg: args.tilt,
        adaptive: args.adaptive,
        sweep_rate_deg: args.sweep.sweep_rate,
        scan_rate: args.sweep.scan_rate,
        drop_ray_elevation: args.drop_ray_elevation,
        level: LevelParams {
            coplanar_k: args.quad_tolerance,
            ..args.leveling.apply(LevelParams::default())
        },
        ..AccuracyParams::default()
    };
    let bar = super::progress_bar(
        (plans.len() * params.poses_per_plan) as u64,
        "eval accuracy",
    );
    let stats = run_accuracy_with(&plans, &params, &|| bar.inc(1)).map_err(|e| match e {
        AccuracyError::Plan { plan, source } => {
            anyhow::anyhow!("{}: {source}", args.plans[plan].display())
        }
        e => e.into(),
    })?;
    bar.finish_and_clear();
    let inputs: Vec<Option<&Path>> = args.plans.iter().map(|p| Some(p.as_path())).collect();
    let mut out = open_output(None, &inputs)?;
    out.write_all(markdown(&stats, &params).as_bytes())?;
    out.finish()?;
    if let Some(dir) = &args.out {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("{}: cannot create", dir.display()))?;
        let path = dir.join("accuracy.json");
        let json = serde_json::json!({
            "plans": args.plans.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
            "poses_per_plan": args.poses,
            "seed": args.seed,
            "step_deg": args.step,
            "tilt_deg": args.tilt,
            "noise_model": args.noise_model.to_string(),
            "quad_tolerance": args.quad_tolerance,
            "adaptive": args.adaptive,
            "sweep_rate_deg": args.sweep.sweep_rate,
            "scan_rate": args.sweep.scan_rate,
            "drop_ray_elevation": args.drop_ray_elevation,
            "cells": stats,
        });
        write_file(&path, serde_json::to_string_pretty(&json)?.as_bytes())?;
        write_file(
            &dir.join("poses.jsonl"),
            pose_lines(&stats, &args.plans).as_bytes(),
        )?;
        write_fig6(dir, &stats, &params);
        eprintln!("wrote {}", path.display());
    }
    Ok(())
}

/// Fig. 6 at the noise nearest 5 cm, one file per estimator (a warning when one cannot be
/// written: the tables are the result).
fn write_fig6(dir: &std::path::Path, stats: &[CellStats], params: &AccuracyParams) {
    let fig_noise = params
        .noise
        .iter()
        .copied()
        .min_by(|a, b| (a - 0.05).abs().total_cmp(&(b - 0.05).abs()));
    let Some(noise) = fig_noise else { return };
    for est in &params.estimators {
        let series: Vec<Series> = stats
            .iter()
            .filter(|s| s.noise == noise && s.estimator == est.to_string())
            .map(|s| Series {
                label: format!("{} scans", s.scans),
                errors_deg: s.errors_deg.clone(),
            })
            .collect();
        let title = format!(
            "Level estimation error, {} cm noise, {est} estimator",
            noise * 100.0
        );
        if let Err(e) = write_histogram(dir, &format!("fig6_{est}"), &title, &series) {
            eprintln!("warning: histogram not written: {e}");
        }
    }
}

/// One JSON line per pose, cell and estimator: what it was, what the leveler said, how far
/// off it was, so that a user can find and re-run the poses behind a statistic.
fn pose_lines(stats: &[CellStats], plans: &[PathBuf]) -> String {
    let mut out = String::new();
    for cell in stats {
        for o in &cell.outcomes {
            let line = serde_json::json!({
                "scans": cell.scans,
                "noise": cell.noise,
                "estimator": cell.estimator,
                "plan": plans.get(o.plan).map(|p| p.display().to_string()),
                "pose": o.pose,
                "status": if o.failure.is_none() { "ok" } else { "failed" },
                "reason": o.failure.map(|r| r.as_str()),
                "cause": o.cause.map(|c| c.as_str()),
                "truth_deg": o.truth_deg,
                "estimate_deg": o.estimate_deg,
                "sigma_deg": o.sigma_deg,
                "error_deg": o.error_deg,
                "sigmas_deg": o.sigmas_deg,
                "bound_deg": o.bound_deg.filter(|b| b.is_finite()),
                "error_over_bound": o.error_over_bound(),
                "sigma_over_bound": o.sigma_over_bound(),
                "efficient_over_bound": o.efficient_over_bound,
                "segmented_deg": o.segmented_deg.filter(|b| b.is_finite()),
                "true_segments_ml": o.true_segments.map(fit_json),
                "true_segments_last_stage": o.true_segments_last_stage.map(fit_json),
                "pseudo_valid": o.pseudo_valid,
                "phantoms": o.phantoms,
                "floor_kept": o.floor_kept,
            });
            let _ = writeln!(out, "{line}");
        }
    }
    out
}

fn fmt_deg(x: f64) -> String {
    if x.is_finite() {
        format!("{x:.3}")
    } else {
        "-".to_string()
    }
}

fn fmt_pct(x: f64) -> String {
    if x.is_finite() {
        format!("{:.1}%", 100.0 * x)
    } else {
        "-".to_string()
    }
}

/// Table I per estimator (mean error, the paper's value in parentheses), then every cell's
/// details.
fn markdown(stats: &[CellStats], params: &AccuracyParams) -> String {
    let mut s = String::new();
    for est in &params.estimators {
        let name = est.to_string();
        let _ = writeln!(
            s,
            "### Table I, {name} estimator: mean error [deg] (paper's)\n"
        );
        let _ = write!(s, "| scans |");
        for n in &params.noise {
            let _ = write!(s, " {} cm |", n * 100.0);
        }
        let _ = write!(s, "\n|---|");
        for _ in &params.noise {
            let _ = write!(s, "---|");
        }
        s.push('\n');
        for &sc in &params.scans {
            let _ = write!(s, "| {sc} |");
            for &n in &params.noise {
                let cell = stats
                    .iter()
                    .find(|c| c.scans == sc && c.noise == n && c.estimator == name);
                let text = cell.map_or("-".to_string(), |c| match c.paper_mean_deg {
                    Some(p) => format!("{} ({p:.3})", fmt_deg(c.mean_deg)),
                    None => fmt_deg(c.mean_deg),
                });
                let _ = write!(s, " {text} |");
            }
            s.push('\n');
        }
        s.push('\n');
    }
    let _ = writeln!(s, "### Every cell\n");
    let _ = writeln!(
        s,
        "| estimator | scans | noise [m] | leveled | mean | rms | median | p95 | max | ok > 5 deg | within 3 sigma | phantom | floor/ceiling kept | coverage | bound | bound within gate | true segments within gate | failures |"
    );
    let _ = writeln!(
        s,
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
    );
    for c in stats {
        let failures: Vec<String> = c.failures.iter().map(|(k, v)| format!("{k} {v}")).collect();
        let _ = writeln!(
            s,
            "| {} | {} | {} | {}/{} ({}) | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            c.estimator,
            c.scans,
            c.noise,
            c.leveled,
            c.poses,
            fmt_pct(c.leveled_fraction),
            fmt_deg(c.mean_deg),
            fmt_deg(c.rms_deg),
            fmt_deg(c.median_deg),
            fmt_deg(c.p95_deg),
            fmt_deg(c.max_deg),
            c.wrong_over_5_deg,
            fmt_pct(c.within_3_sigma),
            fmt_pct(c.phantom_rate),
            fmt_pct(c.floor_kept_rate),
            fmt_pct(c.coverage),
            fmt_deg(c.bound_median_deg),
            fmt_pct(c.bound_within_gate),
            fmt_pct(c.segmented_within_gate),
            failures.join(", ")
        );
    }
    s.push('\n');
    s.push_str(&efficiency_table(stats));
    s
}

/// Per-pose efficiency against the Cramér-Rao bound: each estimator over its leveled poses,
/// then the maximum-likelihood core told the true segmentation over every pose (once a cell).
fn efficiency_table(stats: &[CellStats]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "### Against each pose's bound (medians; normal: 68.3/95.4/99.7%)\n"
    );
    let _ = writeln!(
        s,
        "| estimator | scans | noise [m] | poses | error / bound (95%) | sigma / bound | efficient estimator | within 1 sigma x/y | 2 sigma x/y | 3 sigma x/y |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|");
    let row = |s: &mut String, name: &str, c: &CellStats, e: &Efficiency| {
        let within = |k: usize| {
            format!(
                "{}/{}",
                fmt_pct(e.within_sigma[k][0]),
                fmt_pct(e.within_sigma[k][1])
            )
        };
        let _ = writeln!(
            s,
            "| {name} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            c.scans,
            c.noise,
            e.efficiency_poses,
            with_interval(e.error_over_bound, e.error_over_bound_interval),
            fmt_two(e.sigma_over_bound),
            fmt_two(e.efficient_over_bound),
            within(0),
            within(1),
            within(2)
        );
    };
    for (i, c) in stats.iter().enumerate() {
        row(&mut s, &c.estimator, c, &c.efficiency);
        let last_of_cell = stats
            .get(i + 1)
            .is_none_or(|n| n.scans != c.scans || n.noise != c.noise);
        if last_of_cell && c.true_segments_ml.efficiency_poses > 0 {
            let name = format!(
                "ml, true segments ({} within gate)",
                fmt_pct(c.true_segments_ml_within_gate)
            );
            row(&mut s, &name, c, &c.true_segments_ml);
        }
        if last_of_cell && c.true_segments_last_stage.efficiency_poses > 0 {
            let name = format!(
                "last stage, true segments ({} within gate)",
                fmt_pct(c.true_segments_last_stage_within_gate)
            );
            row(&mut s, &name, c, &c.true_segments_last_stage);
        }
    }
    s
}

/// A fit on the true segmentation as `poses.jsonl` writes it.
fn fit_json(f: TrueSegmentsFit) -> serde_json::Value {
    serde_json::json!({
        "estimate_deg": f.attitude.map(f64::to_degrees),
        "sigmas_deg": f.sigmas.map(f64::to_degrees),
        "inflation": f.inflation,
        "converged": f.converged,
    })
}

/// A median and its 95% interval: `0.96 (0.89-1.03)`.
fn with_interval(median: f64, [lo, hi]: [f64; 2]) -> String {
    if median.is_finite() && lo.is_finite() && hi.is_finite() {
        format!("{median:.2} ({lo:.2}-{hi:.2})")
    } else {
        fmt_two(median)
    }
}

fn fmt_two(x: f64) -> String {
    if x.is_finite() {
        format!("{x:.2}")
    } else {
        "-".to_string()
    }
}
