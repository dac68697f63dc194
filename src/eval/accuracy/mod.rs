//! The paper's accuracy experiment (sect. 8.1, Table I and Fig. 6): random tilted poses in
//! floor plans, simulated multi-elevation scans, leveled, and compared with the truth.
//!
//! Pure: plans in, statistics out. Each pose is simulated once per (scan count, noise) cell and
//! leveled with every estimator asked for, so the estimators see identical data; its noise comes
//! from its own random stream (seed, plan, scan count, pose), never from the thread order.
//!
//! - [`pose`]: one pose leveled and scored ([`PoseOutcome`]);
//! - [`stats`]: a cell's outcomes pooled ([`CellStats`]);
//! - [`efficiency`]: errors and sigmas against each pose's Cramér-Rao bound.

pub mod efficiency;
pub mod pose;
pub mod stats;

pub use efficiency::Efficiency;
pub use pose::{PoseOutcome, evaluate_pose};
pub use stats::CellStats;

use super::bound::{WallPlanes, attitude_bound_cov, pose_rays, segmented_solution};
use super::true_segments::{fit_true_segments, last_stage_true_segments};
use crate::geometry::Pose;
use crate::level::{Estimator, LevelParams};
use crate::plan::{Plan, Segment};
use crate::pseudo_level::PseudoLevelParams;
use crate::scan::Scan;
use crate::simulate::{
    AdaptiveParams, NoiseModel, RandomPoseParams, ScannerParams, SimulateError, Stream, World,
    elevations_centred, random_poses, simulate_pose, simulate_pose_adaptive, stream_rng,
};
use rayon::prelude::*;

/// The paper's Table I, mean error \[deg\], rows 3 / 4 / 5 scans, columns 1 / 5 / 10 cm.
pub const PAPER_TABLE_I: [[f64; 3]; 3] = [
    [0.857, 2.083, 5.724],
    [0.649, 1.731, 4.260],
    [0.409, 1.172, 3.742],
];

/// The paper's mean error for a cell, when it has one.
pub fn paper_mean(scans: usize, noise: f64) -> Option<f64> {
    let row = [3, 4, 5].iter().position(|&s| s == scans)?;
    let col = [0.01, 0.05, 0.10]
        .iter()
        .position(|&n| (n - noise).abs() < 1e-9)?;
    Some(PAPER_TABLE_I[row][col])
}

/// Protocol of the experiment (issue 3, item 8).
#[derive(Clone, Debug)]
pub struct AccuracyParams {
    /// Scan counts per pose. Default 3, 4, 5.
    pub scans: Vec<usize>,
    /// Range noise figures \[m\]: sigmas, or uniform widths (`noise_model`). Default 0.01,
    /// 0.05, 0.10.
    pub noise: Vec<f64>,
    /// What a noise figure means. Default Gaussian (a standard deviation).
    pub noise_model: NoiseModel,
    /// Estimators to compare. Default both.
    pub estimators: Vec<Estimator>,
    /// Random poses per plan. Default 100.
    pub poses_per_plan: usize,
    /// Seed of poses and noise. Default 1.
    pub seed: u64,
    /// Elevation step between scans, centred on level \[deg\]. Default 5.
    pub step_deg: f64,
    /// Roll and pitch uniform in +-tilt \[deg\]. Default 20.
    pub tilt_deg: f64,
    /// Smallest distance of a pose from every wall \[m\]. Default 0.6.
    pub clearance: f64,
    /// Scanner height above the floor \[m\]. Default 0.45.
    pub height: f64,
    /// Rays per scan. Default 181.
    pub rays: usize,
    /// Field of view \[deg\]. Default 180.
    pub fov_deg: f64,
    /// Maximum range \[m\]. Default 30.
    pub max_range: f64,
    /// A pseudo-level point farther than this from every true wall is a phantom \[m\].
    /// Default 0.15.
    pub phantom_distance: f64,
    /// Take the scans with the adaptive robot, cleverRobot (sect. 7.2.2), as the paper's
    /// Table I did. Default false.
    pub adaptive: bool,
    /// A nodding laser: the hinge turns at this rate while each scan is taken \[deg/s\]
    /// ([`ScannerParams::sweep_rate`]). Default 0 (stop-and-scan, as the paper's robot).
    pub sweep_rate_deg: f64,
    /// Scans per second \[Hz\] ([`ScannerParams::scan_rate`]); with a sweep it sets how far
    /// the hinge turns within a scan. Default 40.
    pub scan_rate: f64,
    /// Level without the scans' per-ray elevations (`ray_elevation`), every ray at its scan's
    /// nominal elevation: what a leveler that ignores the sweep gets. The bound and the truth
    /// still use the rays as cast. (The adaptive robot's own leveling keeps them.) Default
    /// false.
    pub drop_ray_elevation: bool,
    /// Also fit the maximum-likelihood core ([`crate::level::ml`]) and the leveler's last
    /// stage to each pose's true segmentation, for the `true_segments_ml` and
    /// `true_segments_last_stage` statistics. Default true.
    pub true_segments_ml: bool,
    /// Level estimation parameters (the estimator field is overridden per run).
    pub level: LevelParams,
    /// Pseudo-level parameters.
    pub pseudo: PseudoLevelParams,
}

impl Default for AccuracyParams {
    fn default() -> Self {
        Self {
            scans: vec![3, 4, 5],
            noise: vec![0.01, 0.05, 0.10],
            noise_model: NoiseModel::Gaussian,
            estimators: vec![Estimator::Paper, Estimator::Robust],
            poses_per_plan: 100,
            seed: 1,
            step_deg: 5.0,
            tilt_deg: 20.0,
            clearance: 0.6,
            height: 0.45,
            rays: 181,
            fov_deg: 180.0,
            max_range: 30.0,
            phantom_distance: 0.15,
            adaptive: false,
            sweep_rate_deg: 0.0,
            scan_rate: ScannerParams::default().scan_rate,
            drop_ray_elevation: false,
            true_segments_ml: true,
            level: LevelParams::default(),
            pseudo: PseudoLevelParams::default(),
        }
    }
}

/// The random stream of the efficient estimator's draws (one per pose and cell).
const EFFICIENT_STREAM: Stream = Stream::Other(26);

/// A plan's scene, prepared once.
struct Scene {
    world: World,
    segments: Vec<Segment>,
    /// The ceiling's height, when the plan has one \[m\].
    ceiling: Option<f64>,
    planes: WallPlanes,
}

/// Why [`run_accuracy`] could not run.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum AccuracyError {
    /// A parameter of the simulated scanner is invalid.
    #[error(transparent)]
    Params(SimulateError),
    /// No random pose could be placed in plan `plan` (its index in `plans`), so that a caller
    /// can name the plan's file.
    #[error("plan {plan} (counting from 0): {source}")]
    Plan {
        plan: usize,
        #[source]
        source: SimulateError,
    },
}

/// Runs the experiment over `plans`. Returns one [`CellStats`] per (scans, noise, estimator),
/// in that nesting order.
pub fn run_accuracy(
    plans: &[Plan],
    params: &AccuracyParams,
) -> Result<Vec<CellStats>, AccuracyError> {
    run_accuracy_with(plans, params, &|| {})
}

/// [`run_accuracy`], calling `pose_done` once per pose (from any thread) as its cells finish,
/// for a caller's progress display: `plans.len() * poses_per_plan` calls in all.
pub fn run_accuracy_with(
    plans: &[Plan],
    params: &AccuracyParams,
    pose_done: &(dyn Fn() + Sync),
) -> Result<Vec<CellStats>, AccuracyError> {
    scanner_params(params, 0.0)
        .validate()
        .map_err(AccuracyError::Params)?;
    let pose_params = RandomPoseParams {
        tilt: params.tilt_deg.to_radians(),
        clearance: params.clearance,
        height: params.height,
        ..RandomPoseParams::default()
    };
    let mut tasks: Vec<(usize, usize, Pose)> = Vec::new();
    let mut scenes = Vec::new();
    for (pi, plan) in plans.iter().enumerate() {
        let world = World::from_plan(plan);
        let poses = random_poses(
            &world,
            params.poses_per_plan,
            &pose_params,
            params.seed.wrapping_add(pi as u64),
        )
        .map_err(|source| AccuracyError::Plan { plan: pi, source })?;
        tasks.extend(poses.into_iter().enumerate().map(|(k, p)| (pi, k, p)));
        let segments = plan.segments();
        let planes = WallPlanes::new(&segments);
        scenes.push(Scene {
            world,
            segments,
            ceiling: plan.ceiling.then_some(plan.wall_height),
            planes,
        });
    }
    let cells: Vec<(usize, f64)> = params
        .scans
        .iter()
        .flat_map(|&s| params.noise.iter().map(move |&n| (s, n)))
        .collect();
    // outcomes[task][cell][estimator]
    let outcomes: Vec<Vec<Vec<PoseOutcome>>> = tasks
        .par_iter()
        .map(|&(pi, k, pose)| {
            let pose_cells = cells
                .iter()
                .map(|&cell| run_pose_cell(&scenes[pi], (pi, k, &pose), cell, params))
                .collect();
            pose_done();
            pose_cells
        })
        .collect();
    let mut stats = Vec::new();
    for (ci, &(nscans, noise)) in cells.iter().enumerate() {
        for (ei, estimator) in params.estimators.iter().enumerate() {
            let pose_outcomes: Vec<&PoseOutcome> = outcomes.iter().map(|o| &o[ci][ei]).collect();
            stats.push(stats::cell_stats(
                nscans,
                noise,
                *estimator,
                params.level.max_sigma_deg,
                &pose_outcomes,
            ));
        }
    }
    Ok(stats)
}

/// One pose in one (scans, noise) cell: simulated once, the data's bound computed, then
/// leveled by every estimator.
fn run_pose_cell(
    scene: &Scene,
    (pi, k, pose): (usize, usize, &Pose),
    (nscans, noise): (usize, f64),
    params: &AccuracyParams,
) -> Vec<PoseOutcome> {
    let stream_seed = params
        .seed
        .wrapping_add((pi as u64) << 32)
        .wrapping_add((nscans as u64) << 48);
    let scans = simulate_cell(scene, (k, pose), (nscans, noise), stream_seed, params);
    let reference = if noise > 0.0 {
        // The efficient draws' stream depends on the noise too, unlike the scans' (whose
        // noise is scaled from one draw): each cell gets its own.
        let draw_seed = stream_seed ^ noise.to_bits();
        let mut rng = stream_rng(draw_seed, EFFICIENT_STREAM, k as u64);
        data_reference(
            scene,
            &scans,
            pose,
            params.noise_model.sigma(noise),
            &mut rng,
            params,
        )
    } else {
        PoseOutcome::default()
    };
    params
        .estimators
        .iter()
        .map(|&estimator| {
            let level = LevelParams {
                estimator,
                ..params.level.clone()
            };
            let scored = evaluate_pose(
                &scans,
                pose,
                (&scene.segments, scene.ceiling),
                &level,
                params,
            );
            PoseOutcome {
                plan: pi,
                pose: k,
                bound_deg: reference.bound_deg,
                efficient_over_bound: reference.efficient_over_bound,
                segmented_deg: reference.segmented_deg,
                true_segments: reference.true_segments,
                true_segments_last_stage: reference.true_segments_last_stage,
                ..scored
            }
        })
        .collect()
}

/// The scanner of the experiment at range noise `noise`.
fn scanner_params(params: &AccuracyParams, noise: f64) -> ScannerParams {
    ScannerParams {
        rays: params.rays,
        fov: params.fov_deg.to_radians(),
        max_range: params.max_range,
        noise_sigma: noise,
        noise_model: params.noise_model,
        sweep_rate: params.sweep_rate_deg.to_radians(),
        scan_rate: params.scan_rate,
        ..ScannerParams::default()
    }
}

/// The pose's scans for one cell, from its own random stream.
fn simulate_cell(
    scene: &Scene,
    (k, pose): (usize, &Pose),
    (nscans, noise): (usize, f64),
    stream_seed: u64,
    params: &AccuracyParams,
) -> Vec<Scan> {
    let scanner = scanner_params(params, noise);
    let mut rng = stream_rng(stream_seed, Stream::Scans, k as u64);
    let elevations = elevations_centred(nscans, params.step_deg.to_radians());
    if params.adaptive {
        let adaptive = AdaptiveParams {
            level: params.level.clone(),
            ..AdaptiveParams::default()
        };
        simulate_pose_adaptive(
            &scene.world,
            k as u64,
            pose,
            &elevations,
            &scanner,
            &adaptive,
            &mut rng,
        )
    } else {
        simulate_pose(
            &scene.world,
            k as u64,
            pose,
            &elevations,
            &scanner,
            &mut rng,
        )
    }
}

/// What the data allow at a pose, whatever the estimator: the bound, an efficient
/// estimator's draw, the robust estimator and the maximum-likelihood core on the true
/// segmentation (range noise `sigma`, a standard deviation).
fn data_reference<R: rand::Rng + ?Sized>(
    scene: &Scene,
    scans: &[Scan],
    pose: &Pose,
    sigma: f64,
    rng: &mut R,
    params: &AccuracyParams,
) -> PoseOutcome {
    let rays = pose_rays(&scene.world, &scene.planes, scans, pose, params.max_range);
    let cov = attitude_bound_cov(&rays, pose, sigma);
    let bound = cov.map_or(f64::INFINITY, |c| {
        c[(0, 0)].max(c[(1, 1)]).sqrt().to_degrees()
    });
    let robust = segmented_solution(&rays, sigma);
    let segmented = robust
        .as_ref()
        .map_or(f64::INFINITY, |s| s.max_attitude_sigma().to_degrees());
    // The core refines a leveler's estimate; here the robust estimator's on the same
    // segmentation, else the robot's own up.
    let start = robust.map_or_else(nalgebra::Vector3::z, |s| s.up);
    PoseOutcome {
        bound_deg: Some(bound),
        efficient_over_bound: cov.and_then(|c| efficiency::efficient_over_bound(&c, rng)),
        segmented_deg: Some(segmented),
        true_segments: params
            .true_segments_ml
            .then(|| fit_true_segments(&rays, sigma, &start))
            .flatten(),
        true_segments_last_stage: params
            .true_segments_ml
            .then(|| last_stage_true_segments(&rays, scans, sigma, &start, &params.level))
            .flatten(),
        ..PoseOutcome::default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paper_table_lookup_matches_the_paper() {
        assert_eq!(paper_mean(3, 0.01), Some(0.857));
        assert_eq!(paper_mean(5, 0.10), Some(3.742));
        assert_eq!(paper_mean(6, 0.10), None);
    }
}
