//! The demo's run (`levelscan demo`, README's first command): the whole system on the built-in
//! office plan, as the paper's sect. 8 runs it.
//!
//! 1. simulate a tilted run through the plan with the adaptive robot (sect. 7.2.2), and the
//!    same path on a level floor as the reference (Fig. 8);
//! 2. level every pose (sect. 5) and make its pseudo-level scan (sect. 6);
//! 3. match level-floor, raw and leveled scans, pairwise and metascan (sect. 8.2, Figs. 8-10);
//! 4. run Table I on the same plan (sect. 8.1).
//!
//! Pure apart from the clock behind [`DemoData::timings_s`]: what it returns is what the report
//! (`viz::demo_report`) shows and `report.json` holds. Writing files is the caller's.

use super::accuracy::{AccuracyError, AccuracyParams, CellStats, run_accuracy};
use super::matching::{RunKind, RunResult, adaptive_attempt, match_scans, nearest_level_scan};
use super::metrics::{Ate, Rpe};
use crate::formats::level_record::level_record;
use crate::formats::{InputError, parse_plan};
use crate::geometry::{Attitude, Pose, Pose2};
use crate::level::{LevelParams, level_pose};
use crate::matching::matcher::{MatcherParams, Mode};
use crate::plan::Plan;
use crate::pseudo_level::PseudoLevelParams;
use crate::scan::Scan;
use crate::simulate::adaptive::AdaptiveParams;
use crate::simulate::{
    OdometryParams, ScannerParams, SimulateError, World, elevations_centred, odometry,
    simulate_poses,
};
use rayon::prelude::*;
use serde::Serialize;
use std::collections::BTreeMap;
use std::time::Instant;

/// The built-in plan: a 10 x 8 m office with partitions and pillars, 30 poses on a tilted path
/// (the paper's Fig. 5c setting).
pub const OFFICE_PLAN: &str = include_str!("../../examples/plans/office.wall");

/// What the demo runs with.
#[derive(Clone, Debug, PartialEq)]
pub struct DemoParams {
    /// Seed of odometry, noise and Table I's poses. Default 1.
    pub seed: u64,
    /// Range noise sigma of the simulated scanner \[m\]. Default 0.01.
    pub noise: f64,
    /// Scans per pose (at least 3 to level). Default 5.
    pub scans: usize,
    /// Elevation step between scans, centred on level \[deg\]. Default 5.
    pub step_deg: f64,
    /// Random poses per cell of Table I (the paper's 100). Default 100.
    pub accuracy_poses: usize,
}

impl Default for DemoParams {
    fn default() -> Self {
        Self {
            seed: 1,
            noise: 0.01,
            scans: 5,
            step_deg: 5.0,
            accuracy_poses: 100,
        }
    }
}

/// The demo's stages, in order, for progress reports.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    Simulate,
    Level,
    Match,
    TableOne,
}

impl Stage {
    /// Short name (also the key of [`DemoData::timings_s`]).
    pub fn name(&self) -> &'static str {
        match self {
            Stage::Simulate => "simulate",
            Stage::Level => "level",
            Stage::Match => "match",
            Stage::TableOne => "table_one",
        }
    }
}

/// Why the demo could not run.
#[derive(Debug, thiserror::Error)]
pub enum DemoError {
    #[error("the built-in plan: {0}")]
    Plan(#[from] InputError),
    #[error("Table I: cannot place random poses in the office plan: {0}")]
    TableOne(#[from] SimulateError),
    #[error("Table I: {0}")]
    Accuracy(#[from] AccuracyError),
}

/// One matched run's numbers.
#[derive(Clone, Debug, Serialize)]
pub struct MatchRow {
    /// Which scans: "level floor", "raw" or "leveled".
    pub run: String,
    /// "pairwise" or "metascan".
    pub mode: String,
    pub ate: Option<Ate>,
    pub rpe: Option<Rpe>,
    /// Scans whose step came from odometry.
    pub fallbacks: usize,
    pub scans: usize,
}

impl From<&RunResult> for MatchRow {
    fn from(r: &RunResult) -> Self {
        MatchRow {
            run: r.kind.label().to_string(),
            mode: mode_name(r.mode).to_string(),
            ate: r.ate,
            rpe: r.rpe,
            fallbacks: r.fallbacks,
            scans: r.scans,
        }
    }
}

/// "pairwise" or "metascan".
pub fn mode_name(mode: Mode) -> &'static str {
    match mode {
        Mode::Pairwise => "pairwise",
        Mode::Metascan => "metascan",
    }
}

/// How leveling went at one pose of the demo's run.
#[derive(Clone, Debug, Serialize)]
pub struct PoseLevel {
    pub sequence: u64,
    pub status: String,
    pub reason: Option<String>,
    /// The paper's error max(|dx|, |dy|) against the simulator's truth \[deg\].
    pub error_deg: Option<f64>,
    pub polygons: usize,
    pub valid_points: usize,
}

/// How leveling went on the demo's run.
#[derive(Clone, Debug, Serialize)]
pub struct LevelSummary {
    pub poses: usize,
    pub leveled: usize,
    pub mean_error_deg: Option<f64>,
    pub max_error_deg: Option<f64>,
    pub per_pose: Vec<PoseLevel>,
}

/// What the demo ran with, as the report states it.
#[derive(Clone, Debug, Serialize)]
pub struct Settings {
    pub plan: String,
    pub poses: usize,
    pub scans_per_pose: usize,
    pub elevation_step_deg: f64,
    pub noise_m: f64,
    pub seed: u64,
    pub accuracy_poses: usize,
    pub robot: String,
}

/// Everything the report shows, as written to report.json.
#[derive(Clone, Debug, Serialize)]
pub struct DemoData {
    pub settings: Settings,
    pub level: LevelSummary,
    pub matching: Vec<MatchRow>,
    pub accuracy: Vec<CellStats>,
    /// Seconds per stage ([`Stage::name`]); the report's own stages add theirs.
    pub timings_s: BTreeMap<String, f64>,
}

impl DemoData {
    /// The matched run of `run` scans ("raw", "leveled", "level floor") in `mode`.
    pub fn row(&self, run: &str, mode: &str) -> Option<&MatchRow> {
        self.matching
            .iter()
            .find(|r| r.run == run && r.mode == mode)
    }

    /// That run's ATE RMSE \[m\].
    pub fn ate_rmse(&self, run: &str, mode: &str) -> Option<f64> {
        self.row(run, mode).and_then(|r| r.ate.map(|a| a.rmse))
    }
}

/// One leveled pose: its `level` output record (with wall polygons) and attitude.
#[derive(Clone, Debug)]
pub struct LeveledPose {
    pub record: Scan,
    pub attitude: Option<Attitude>,
}

/// The demo's run: its data, and what the figures and viewers are drawn from.
#[derive(Clone, Debug)]
pub struct DemoRun {
    pub plan: Plan,
    /// Per pose, the scans cleverRobot took.
    pub tilted: Vec<Vec<Scan>>,
    /// One level scan per pose along the same path on a level floor.
    pub flat: Vec<Scan>,
    /// The true planar poses.
    pub truth: Vec<Pose2>,
    pub leveled: Vec<LeveledPose>,
    /// Six matched runs: level floor, raw and leveled, each pairwise and metascan.
    pub runs: Vec<RunResult>,
    pub data: DemoData,
}

impl DemoRun {
    /// The matched run of `kind` in `mode`.
    pub fn run(&self, kind: RunKind, mode: Mode) -> Option<&RunResult> {
        self.runs.iter().find(|r| r.kind == kind && r.mode == mode)
    }

    /// The leveled records as metascan matched them, like `match` output: each at its
    /// estimate (aligned onto the truth, as the ATE measures it), with a `match` object; the
    /// wall polygons dropped (they belong to the 3D view).
    pub fn matched_leveled(&self) -> Vec<Scan> {
        let Some(run) = self.run(RunKind::Leveled, Mode::Metascan) else {
            return Vec::new();
        };
        self.leveled
            .iter()
            .zip(&run.aligned)
            .map(|(l, e)| {
                let mut s = l.record.clone();
                s.estimate = Some(Pose::planar(e.x, e.y, e.theta));
                s.extra.remove("wall_polygons");
                s.extra.remove("wall_patches");
                s.extra
                    .insert("match".into(), serde_json::json!({"status": "ok"}));
                s
            })
            .collect()
    }
}

/// Runs the demo; `on_stage` is told each stage as it starts.
pub fn run_demo(
    params: &DemoParams,
    on_stage: &mut dyn FnMut(Stage),
) -> Result<DemoRun, DemoError> {
    let plan = parse_plan(OFFICE_PLAN, "office.wall")?;
    let mut timer = StageTimer::new(on_stage);

    timer.start(Stage::Simulate);
    let (tilted, flat, truth) = simulate_run(&plan, params);

    timer.start(Stage::Level);
    let leveled = level_run(&tilted);
    let level = level_summary(&tilted, &leveled);

    timer.start(Stage::Match);
    let runs = match_runs(&tilted, &flat, &leveled, &truth);

    timer.start(Stage::TableOne);
    let accuracy_params = AccuracyParams {
        poses_per_plan: params.accuracy_poses,
        estimators: vec![LevelParams::default().estimator],
        seed: params.seed,
        ..AccuracyParams::default()
    };
    let accuracy = run_accuracy(std::slice::from_ref(&plan), &accuracy_params)?;

    let data = DemoData {
        settings: settings(params, &tilted),
        level,
        matching: runs.iter().map(MatchRow::from).collect(),
        accuracy,
        timings_s: timer.finish(),
    };
    Ok(DemoRun {
        plan,
        tilted,
        flat,
        truth,
        leveled,
        runs,
        data,
    })
}

/// Times the stages: each `start` ends the stage before it.
struct StageTimer<'a> {
    on_stage: &'a mut dyn FnMut(Stage),
    current: Option<(Stage, Instant)>,
    timings: BTreeMap<String, f64>,
}

impl<'a> StageTimer<'a> {
    fn new(on_stage: &'a mut dyn FnMut(Stage)) -> Self {
        Self {
            on_stage,
            current: None,
            timings: BTreeMap::new(),
        }
    }

    fn start(&mut self, stage: Stage) {
        self.stop();
        (self.on_stage)(stage);
        self.current = Some((stage, Instant::now()));
    }

    fn stop(&mut self) {
        if let Some((stage, start)) = self.current.take() {
            let seconds = start.elapsed().as_secs_f64();
            self.timings.insert(stage.name().to_string(), seconds);
        }
    }

    fn finish(mut self) -> BTreeMap<String, f64> {
        self.stop();
        self.timings
    }
}

fn settings(params: &DemoParams, tilted: &[Vec<Scan>]) -> Settings {
    let retook = tilted
        .iter()
        .filter(|scans| scans.iter().any(|s| adaptive_attempt(s) > 0))
        .count();
    Settings {
        plan: "office.wall (built in)".to_string(),
        poses: tilted.len(),
        scans_per_pose: params.scans,
        elevation_step_deg: params.step_deg,
        noise_m: params.noise,
        seed: params.seed,
        accuracy_poses: params.accuracy_poses,
        robot: format!(
            "cleverRobot (simulate --adaptive): it levels its own scans at each pose and \
             retakes them at other elevations when it faced the floor or the ceiling or \
             could not level them; it retook scans at {retook} of {} poses",
            tilted.len()
        ),
    }
}

/// The tilted run (scans per pose, taken by cleverRobot), the same path on a level floor (one
/// level scan per pose) and the true planar poses.
fn simulate_run(plan: &Plan, params: &DemoParams) -> (Vec<Vec<Scan>>, Vec<Scan>, Vec<Pose2>) {
    let world = World::from_plan(plan);
    let poses = &plan.poses;
    let odo = odometry(poses, &OdometryParams::default(), params.seed);
    let scanner = ScannerParams {
        noise_sigma: params.noise,
        ..ScannerParams::default()
    };
    let elevations = elevations_centred(params.scans, params.step_deg.to_radians());
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
        params.seed,
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
        params.seed,
    )
    .into_iter()
    .flatten()
    .collect();
    let truth = poses.iter().map(Pose::to_pose2).collect();
    (tilted, flat, truth)
}

/// Levels every pose (sect. 5) and makes its `level` record with wall polygons (sect. 6).
fn level_run(tilted: &[Vec<Scan>]) -> Vec<LeveledPose> {
    let level_params = LevelParams::default();
    let pseudo_params = PseudoLevelParams::default();
    tilted
        .par_iter()
        .map(|scans| {
            let est = level_pose(scans, &level_params);
            LeveledPose {
                record: level_record(scans, &est, &pseudo_params, true),
                attitude: est.attitude,
            }
        })
        .collect()
}

/// Matches level-floor, raw and leveled scans, pairwise and metascan (sect. 8.2).
fn match_runs(
    tilted: &[Vec<Scan>],
    flat: &[Scan],
    leveled: &[LeveledPose],
    truth: &[Pose2],
) -> Vec<RunResult> {
    let raw: Vec<Scan> = tilted.iter().map(|s| nearest_level_scan(s)).collect();
    let leveled_scans: Vec<Scan> = leveled.iter().map(|l| l.record.clone()).collect();
    let inputs: [(RunKind, &[Scan]); 3] = [
        (RunKind::LevelFloor, flat),
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
    jobs.par_iter()
        .map(|&(kind, scans, mode)| match_scans(kind, scans, mode, truth, &matcher))
        .collect()
}

fn level_summary(tilted: &[Vec<Scan>], leveled: &[LeveledPose]) -> LevelSummary {
    let per_pose: Vec<PoseLevel> = tilted
        .iter()
        .zip(leveled)
        .map(|(scans, l)| {
            let level = l.record.extra.get("level");
            let field = |k: &str| level.and_then(|v| v.get(k));
            let truth = scans
                .first()
                .and_then(|s| s.true_pose)
                .map(|p| p.attitude());
            PoseLevel {
                sequence: l.record.sequence.unwrap_or(0),
                status: field("status")
                    .and_then(|v| v.as_str())
                    .unwrap_or("failed")
                    .to_string(),
                reason: field("reason").and_then(|v| v.as_str()).map(str::to_string),
                error_deg: l
                    .attitude
                    .zip(truth)
                    .map(|(a, t)| a.max_abs_error(&t).to_degrees()),
                polygons: field("polygons").and_then(|v| v.as_u64()).unwrap_or(0) as usize,
                valid_points: l.record.valid_count(),
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
