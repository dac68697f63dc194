//! The paper's matching experiment (sect. 8.2, Figs. 8-10 and 12): one path through a plan,
//! simulated three ways and each matched pairwise and metascan:
//!
//! - `level floor`: the same poses with roll and pitch zeroed, one scan at elevation 0 (Fig. 8);
//! - `raw`: the tilted poses, each pose's scan nearest elevation 0 used as it is (Fig. 9);
//! - `leveled`: the tilted poses' scans leveled (sect. 5) into pseudo-level scans (sect. 6)
//!   (Fig. 10). As in the paper, cleverRobot takes them (sect. 7.2.2: it retakes a pose's scans
//!   at other elevations when its leveling is poor); the raw run uses each pose's first set, as
//!   a robot that does not level would have taken it.
//!
//! Scored by ATE and RPE against the true planar poses. Pure: plan in, results out.

use super::metrics::{Ate, Rpe, ate, rpe};
use crate::geometry::{Pose, Pose2};
use crate::level::{LevelParams, believed_range_sigma, level_pose};
use crate::matching::{MatchReport, MatchStatus, Matcher, MatcherParams, Mode, scan_points};
use crate::plan::Plan;
use crate::pseudo_level::{PseudoLevelParams, pseudo_level_scan};
use crate::scan::Scan;
use crate::simulate::{
    AdaptiveParams, OdometryParams, ScannerParams, World, odometry, simulate_poses,
};
use nalgebra::Point2;
use rayon::prelude::*;
use serde::Serialize;

/// Settings of the experiment.
#[derive(Clone, Debug)]
pub struct ExperimentParams {
    /// Seed of the simulation (scans and odometry). Default 1.
    pub seed: u64,
    /// The scanner (rays, field of view, range noise). Default `ScannerParams::default()`.
    pub scanner: ScannerParams,
    /// Hinge elevations of the tilted run \[rad\]. Default -5, 0, 5 degrees.
    pub elevations: Vec<f64>,
    /// Odometry drift. Default `OdometryParams::default()`.
    pub odometry: OdometryParams,
    /// The robot that takes the tilted scans: cleverRobot with these settings (its `level` is
    /// replaced by the experiment's), or `None` for one set of scans per pose. Default
    /// cleverRobot, as in the paper's experiment.
    pub adaptive: Option<AdaptiveParams>,
    pub level: LevelParams,
    pub pseudo: PseudoLevelParams,
    /// Matcher settings; the mode is set per run.
    pub matcher: MatcherParams,
}

impl Default for ExperimentParams {
    fn default() -> Self {
        Self {
            seed: 1,
            scanner: ScannerParams::default(),
            elevations: [-5.0f64, 0.0, 5.0].iter().map(|d| d.to_radians()).collect(),
            odometry: OdometryParams::default(),
            adaptive: Some(AdaptiveParams::default()),
            level: LevelParams::default(),
            pseudo: PseudoLevelParams::default(),
            matcher: MatcherParams::default(),
        }
    }
}

/// Which scans a run matched.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum RunKind {
    LevelFloor,
    Raw,
    Leveled,
}

impl RunKind {
    pub fn label(&self) -> &'static str {
        match self {
            RunKind::LevelFloor => "level floor",
            RunKind::Raw => "raw",
            RunKind::Leveled => "leveled",
        }
    }
}

/// One matched run.
#[derive(Clone, Debug, Serialize)]
pub struct RunResult {
    pub kind: RunKind,
    #[serde(serialize_with = "mode_name")]
    pub mode: Mode,
    pub ate: Option<Ate>,
    pub rpe: Option<Rpe>,
    pub fallbacks: usize,
    pub scans: usize,
    /// Estimated poses after the ATE alignment onto the truth.
    #[serde(skip)]
    pub aligned: Vec<Pose2>,
    /// Each scan's points in its own frame (for maps).
    #[serde(skip)]
    pub points: Vec<Vec<Point2<f64>>>,
    /// Each scan's match report.
    #[serde(skip)]
    pub reports: Vec<MatchReport>,
}

fn mode_name<S: serde::Serializer>(mode: &Mode, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(match mode {
        Mode::Pairwise => "pairwise",
        Mode::Metascan => "metascan",
    })
}

/// The experiment on one plan: the true planar poses and the six runs (level floor, raw,
/// leveled; each pairwise then metascan). Deterministic for a seed, whatever the threads.
pub fn matching_experiment(plan: &Plan, params: &ExperimentParams) -> (Vec<Pose2>, Vec<RunResult>) {
    let world = World::from_plan(plan);
    let poses = &plan.poses;
    let odo = odometry(poses, &params.odometry, params.seed);
    let adaptive = params.adaptive.as_ref().map(|a| AdaptiveParams {
        level: params.level.clone(),
        ..a.clone()
    });
    let tilted = simulate_poses(
        &world,
        poses,
        Some(&odo),
        0,
        &params.elevations,
        &params.scanner,
        adaptive.as_ref(),
        params.seed,
    );
    let flat_poses: Vec<Pose> = poses
        .iter()
        .map(|p| Pose::new(p.x, p.y, p.z, p.rz, 0.0, 0.0))
        .collect();
    let flat: Vec<Scan> = simulate_poses(
        &world,
        &flat_poses,
        Some(&odo),
        0,
        &[0.0],
        &params.scanner,
        None,
        params.seed,
    )
    .into_iter()
    .flatten()
    .collect();
    let raw: Vec<Scan> = tilted.iter().map(|s| nearest_level_scan(s)).collect();
    let leveled: Vec<Scan> = tilted
        .par_iter()
        .map(|scans| pseudo_level_scan(scans, &level_pose(scans, &params.level), &params.pseudo))
        .collect();
    let truth: Vec<Pose2> = poses.iter().map(Pose::to_pose2).collect();
    let inputs = [
        (RunKind::LevelFloor, &flat),
        (RunKind::Raw, &raw),
        (RunKind::Leveled, &leveled),
    ];
    let jobs: Vec<(RunKind, &Vec<Scan>, Mode)> = inputs
        .iter()
        .flat_map(|&(k, s)| [Mode::Pairwise, Mode::Metascan].map(move |m| (k, s, m)))
        .collect();
    let runs = jobs
        .par_iter()
        .map(|&(kind, scans, mode)| match_scans(kind, scans, mode, &truth, &params.matcher))
        .collect();
    (truth, runs)
}

/// The scan of a pose taken nearest elevation 0, unleveled (issue 4's raw run), from the
/// pose's first set of scans (cleverRobot's retakes are for leveling). A tilted scan is used
/// as if it were level: its points go into the plane as they are.
pub fn nearest_level_scan(scans: &[Scan]) -> Scan {
    scans
        .iter()
        .filter(|s| adaptive_attempt(s) == 0)
        .min_by(|a, b| {
            let ea = a.elevation.unwrap_or(0.0).abs();
            let eb = b.elevation.unwrap_or(0.0).abs();
            ea.total_cmp(&eb)
        })
        .cloned()
        .unwrap_or_default()
}

/// Which attempt of cleverRobot took a scan (0: the first set of elevations, or a scan not
/// taken by cleverRobot).
pub fn adaptive_attempt(scan: &Scan) -> u64 {
    scan.extra
        .get("adaptive")
        .and_then(|a| a.get("attempt"))
        .and_then(|a| a.as_u64())
        .unwrap_or(0)
}

/// Matches one run's scans with `mode` and scores it against the truth (ATE, RPE, fallbacks).
pub fn match_scans(
    kind: RunKind,
    scans: &[Scan],
    mode: Mode,
    truth: &[Pose2],
    matcher: &MatcherParams,
) -> RunResult {
    let params = MatcherParams { mode, ..*matcher };
    let inputs: Vec<(Vec<Point2<f64>>, Option<Pose2>)> = scans
        .iter()
        .map(|s| {
            (
                scan_points(s, &params.ranges),
                s.odometry.map(|p| p.to_pose2()),
            )
        })
        .collect();
    // Each scan's stated noise, as `match` takes it (level writes the one it estimated).
    let mut matcher = Matcher::new(params);
    let reports: Vec<MatchReport> = inputs
        .iter()
        .zip(scans)
        .map(|((p, o), s)| {
            let sigma = believed_range_sigma(std::slice::from_ref(s));
            matcher.push_with_sigma(p, *o, sigma)
        })
        .collect();
    let estimates: Vec<Pose2> = reports.iter().map(|r| r.estimate).collect();
    let ate_result = ate(&estimates, truth);
    let alignment = ate_result.map(|a| a.alignment).unwrap_or_default();
    RunResult {
        kind,
        mode,
        ate: ate_result,
        rpe: rpe(&estimates, truth),
        fallbacks: reports
            .iter()
            .filter(|r| matches!(r.status, MatchStatus::Fallback(_)))
            .count(),
        scans: scans.len(),
        aligned: estimates.iter().map(|e| alignment.compose(e)).collect(),
        points: inputs.into_iter().map(|(p, _)| p).collect(),
        reports,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::formats::parse_plan;

    #[test]
    fn nearest_level_scan_prefers_the_smallest_elevation() {
        let mk = |e: f64| Scan {
            elevation: Some(e),
            ..Scan::default()
        };
        let s = nearest_level_scan(&[mk(0.1), mk(-0.02), mk(0.05)]);
        assert_eq!(s.elevation, Some(-0.02));
    }

    #[test]
    fn level_floor_runs_beat_raw_runs_on_a_tilted_path() {
        // A 6 x 4 m room with a pillar; 30 poses along a line, tilted 8 degrees in pitch.
        let poses: Vec<String> = (0..30)
            .map(|i| format!("[{}, 1.5, 0.45, 10.0, 8.0, 0.0]", 1.0 + 0.12 * i as f64))
            .collect();
        let text = format!(
            r#"{{"version": "w0.1", "wallheight": 2.5,
              "walls": [[[0,0],[6,0],[6,4],[0,4],[0,0]], [[3,2.5],[3.4,2.5],[3.4,2.9],[3,2.9],[3,2.5]]],
              "poses": [{}]}}"#,
            poses.join(",")
        );
        let plan = parse_plan(&text, "test.wall").unwrap();
        let (truth, runs) = matching_experiment(&plan, &ExperimentParams::default());
        assert_eq!(truth.len(), 30);
        assert_eq!(runs.len(), 6);
        let get = |k: RunKind, m: Mode| {
            runs.iter()
                .find(|r| r.kind == k && r.mode == m)
                .and_then(|r| r.ate)
                .unwrap()
                .rmse
        };
        let level = get(RunKind::LevelFloor, Mode::Metascan);
        let raw = get(RunKind::Raw, Mode::Metascan);
        assert!(level < 0.02, "level floor ATE {level}");
        assert!(raw > level, "raw {raw} vs level floor {level}");
    }
}
