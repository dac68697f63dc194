//! The paper's accuracy experiment (sect. 8.1, Table I and Fig. 6): random tilted poses in
//! floor plans, simulated multi-elevation scans, leveled, and compared with the truth.
//!
//! Pure: plans in, statistics out. Each pose is simulated once per (scan count, noise) cell and
//! leveled with every estimator asked for, so the estimators see identical data; its noise comes
//! from its own random stream (seed, plan, scan count, pose), never from the thread order.

use super::bound::{WallPlanes, attitude_bound, pose_rays, segmented_solution};
use super::metrics::{median, nearest_rank};
use crate::geometry::Pose;
use crate::level::{Estimator, FailReason, LevelParams, level_pose};
use crate::plan::{Plan, Segment};
use crate::pseudo_level::{PseudoLevelParams, pseudo_level_scan};
use crate::scan::{Hit, Scan};
use crate::simulate::{
    AdaptiveParams, NoiseModel, RandomPoseParams, ScannerParams, SimulateError, Stream, World,
    elevations_centred, random_poses, simulate_pose, simulate_pose_adaptive, stream_rng,
};
use nalgebra::Point2;
use rayon::prelude::*;
use std::collections::BTreeMap;

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
            level: LevelParams::default(),
            pseudo: PseudoLevelParams::default(),
        }
    }
}

/// What happened at one pose in one cell with one estimator.
#[derive(Clone, Debug, PartialEq)]
pub struct PoseOutcome {
    /// Index of the pose's plan and of the pose in that plan's draw.
    pub plan: usize,
    pub pose: usize,
    /// True theta_x and theta_y \[deg\].
    pub truth_deg: [f64; 2],
    /// Estimated theta_x and theta_y \[deg\], when leveled.
    pub estimate_deg: Option<[f64; 2]>,
    pub failure: Option<FailReason>,
    /// The paper's error `max(|dtheta_x|, |dtheta_y|)` \[deg\], when leveled.
    pub error_deg: Option<f64>,
    /// True when leveled and both angle errors lie within 3 reported sigmas.
    pub within_3_sigma: bool,
    /// Valid pseudo-level points.
    pub pseudo_valid: usize,
    /// Valid pseudo-level points farther than `phantom_distance` from every true wall.
    pub phantoms: usize,
    /// Wall hits of the pose's best single scan (most wall hits).
    pub best_wall_hits: usize,
    /// The larger reported attitude sigma \[deg\], when leveled.
    pub sigma_deg: Option<f64>,
    /// The larger of the pose's Cramér-Rao bounds on theta_x and theta_y \[deg\]
    /// ([`super::bound`]); infinite when its rays cannot fix the attitude, `None` when not
    /// computed (no noise).
    pub bound_deg: Option<f64>,
    /// The larger sigma \[deg\] of up found from the true segmentation
    /// ([`super::bound::segmented_solution`]); infinite when that cannot fix up, `None` when not
    /// computed (no noise).
    pub segmented_deg: Option<f64>,
}

/// Statistics of one cell of Table I for one estimator.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct CellStats {
    pub scans: usize,
    pub noise: f64,
    pub estimator: String,
    pub poses: usize,
    pub leveled: usize,
    pub leveled_fraction: f64,
    /// Mean, median, 95th percentile and maximum error over leveled poses \[deg\].
    pub mean_deg: f64,
    pub median_deg: f64,
    pub p95_deg: f64,
    pub max_deg: f64,
    /// Leveled poses with an error above 5 degrees.
    pub wrong_over_5_deg: usize,
    /// Fraction of leveled poses whose error lies within 3 reported sigmas.
    pub within_3_sigma: f64,
    /// Phantom pseudo-level points over all valid pseudo-level points (leveled poses).
    pub phantom_rate: f64,
    /// Valid pseudo-level points over wall hits of each pose's best scan (leveled poses).
    pub coverage: f64,
    /// The paper's mean for this cell \[deg\], when it has one.
    pub paper_mean_deg: Option<f64>,
    /// Median over all poses of the larger Cramér-Rao bound on the attitude \[deg\]: what no
    /// leveler can beat ([`super::bound`]).
    pub bound_median_deg: f64,
    /// Poses whose bound lies within the leveling gate (`max_sigma`): the most a leveler with
    /// honest sigmas and that gate could level.
    pub bound_within_gate: f64,
    /// Poses whose sigma from the true segmentation lies within the leveling gate: what this
    /// estimator could level if it found every surface and nothing else.
    pub segmented_within_gate: f64,
    /// Median over leveled poses of the reported sigma over the bound (1 is a leveler that
    /// uses all the information in the ranges).
    pub sigma_over_bound: f64,
    /// Failed poses by reason.
    pub failures: BTreeMap<String, usize>,
    /// Every leveled pose's error \[deg\], in pose order (for histograms).
    pub errors_deg: Vec<f64>,
    /// Every pose's outcome, in pose order (written apart, as `poses.jsonl`).
    #[serde(skip)]
    pub outcomes: Vec<PoseOutcome>,
}

/// Runs the experiment over `plans`. Returns one [`CellStats`] per (scans, noise, estimator),
/// in that nesting order.
pub fn run_accuracy(
    plans: &[Plan],
    params: &AccuracyParams,
) -> Result<Vec<CellStats>, SimulateError> {
    let pose_params = RandomPoseParams {
        tilt: params.tilt_deg.to_radians(),
        clearance: params.clearance,
        height: params.height,
        ..RandomPoseParams::default()
    };
    let mut tasks: Vec<(usize, usize, Pose)> = Vec::new();
    let mut worlds = Vec::new();
    let mut segments: Vec<Vec<Segment>> = Vec::new();
    for (pi, plan) in plans.iter().enumerate() {
        let world = World::from_plan(plan);
        let poses = random_poses(
            &world,
            params.poses_per_plan,
            &pose_params,
            params.seed.wrapping_add(pi as u64),
        )?;
        tasks.extend(poses.into_iter().enumerate().map(|(k, p)| (pi, k, p)));
        worlds.push(world);
        segments.push(plan.segments());
    }
    let planes: Vec<WallPlanes> = segments.iter().map(|s| WallPlanes::new(s)).collect();
    let cells: Vec<(usize, f64)> = params
        .scans
        .iter()
        .flat_map(|&s| params.noise.iter().map(move |&n| (s, n)))
        .collect();
    // outcomes[task][cell][estimator]
    let outcomes: Vec<Vec<Vec<PoseOutcome>>> = tasks
        .par_iter()
        .map(|&(pi, k, pose)| {
            cells
                .iter()
                .map(|&(nscans, noise)| {
                    let scanner = ScannerParams {
                        rays: params.rays,
                        fov: params.fov_deg.to_radians(),
                        max_range: params.max_range,
                        noise_sigma: noise,
                        noise_model: params.noise_model,
                        ..ScannerParams::default()
                    };
                    let stream_seed = params
                        .seed
                        .wrapping_add((pi as u64) << 32)
                        .wrapping_add((nscans as u64) << 48);
                    let mut rng = stream_rng(stream_seed, Stream::Scans, k as u64);
                    let elevations = elevations_centred(nscans, params.step_deg.to_radians());
                    let scans = if params.adaptive {
                        let adaptive = AdaptiveParams {
                            level: params.level.clone(),
                            ..AdaptiveParams::default()
                        };
                        simulate_pose_adaptive(
                            &worlds[pi],
                            k as u64,
                            &pose,
                            &elevations,
                            &scanner,
                            &adaptive,
                            &mut rng,
                        )
                    } else {
                        simulate_pose(
                            &worlds[pi],
                            k as u64,
                            &pose,
                            &elevations,
                            &scanner,
                            &mut rng,
                        )
                    };
                    let sigma = params.noise_model.sigma(noise);
                    let (bound_deg, segmented_deg) = if noise > 0.0 {
                        let rays =
                            pose_rays(&worlds[pi], &planes[pi], &scans, &pose, params.max_range);
                        let bound = attitude_bound(&rays, &pose, sigma)
                            .map_or(f64::INFINITY, |b| b[0].max(b[1]).to_degrees());
                        let segmented = segmented_solution(&rays, sigma)
                            .map_or(f64::INFINITY, |s| s.max_attitude_sigma().to_degrees());
                        (Some(bound), Some(segmented))
                    } else {
                        (None, None)
                    };
                    params
                        .estimators
                        .iter()
                        .map(|&estimator| {
                            let level = LevelParams {
                                estimator,
                                ..params.level.clone()
                            };
                            PoseOutcome {
                                plan: pi,
                                pose: k,
                                bound_deg,
                                segmented_deg,
                                ..evaluate_pose(&scans, &pose, &segments[pi], &level, params)
                            }
                        })
                        .collect()
                })
                .collect()
        })
        .collect();
    let mut stats = Vec::new();
    for (ci, &(nscans, noise)) in cells.iter().enumerate() {
        for (ei, estimator) in params.estimators.iter().enumerate() {
            let pose_outcomes: Vec<&PoseOutcome> = outcomes.iter().map(|o| &o[ci][ei]).collect();
            stats.push(cell_stats(
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

/// Levels one pose's scans and scores the result against the truth (its `plan` and `pose`
/// indices are the caller's to set).
pub fn evaluate_pose(
    scans: &[Scan],
    truth: &Pose,
    walls: &[Segment],
    level: &LevelParams,
    params: &AccuracyParams,
) -> PoseOutcome {
    let est = level_pose(scans, level);
    let t = truth.attitude();
    let truth_deg = [t.theta_x.to_degrees(), t.theta_y.to_degrees()];
    let best_wall_hits = scans
        .iter()
        .map(|s| {
            s.hit
                .as_ref()
                .map_or(0, |h| h.iter().filter(|&&x| x == Hit::Wall).count())
        })
        .max()
        .unwrap_or(0);
    let (Some(att), Some(sig)) = (est.attitude, est.sigmas) else {
        return PoseOutcome {
            plan: 0,
            pose: 0,
            truth_deg,
            estimate_deg: None,
            failure: est.failure,
            error_deg: None,
            within_3_sigma: false,
            pseudo_valid: 0,
            phantoms: 0,
            best_wall_hits,
            sigma_deg: None,
            bound_deg: None,
            segmented_deg: None,
        };
    };
    let (dx, dy) = (
        (att.theta_x - t.theta_x).abs(),
        (att.theta_y - t.theta_y).abs(),
    );
    let pseudo = pseudo_level_scan(scans, &est, &params.pseudo);
    let planar = truth.to_pose2();
    let mut valid = 0;
    let mut phantoms = 0;
    for i in 0..pseudo.nrays() {
        let Some(r) = pseudo.range(i) else { continue };
        valid += 1;
        let (s, c) = pseudo.theta[i].sin_cos();
        let w = planar.transform_point(&Point2::new(r * c, r * s));
        let d = walls
            .iter()
            .map(|seg| seg.distance_to(&w))
            .fold(f64::INFINITY, f64::min);
        if d > params.phantom_distance {
            phantoms += 1;
        }
    }
    PoseOutcome {
        plan: 0,
        pose: 0,
        truth_deg,
        estimate_deg: Some([att.theta_x.to_degrees(), att.theta_y.to_degrees()]),
        failure: None,
        error_deg: Some(dx.max(dy).to_degrees()),
        within_3_sigma: dx <= 3.0 * sig[0] && dy <= 3.0 * sig[1],
        pseudo_valid: valid,
        phantoms,
        best_wall_hits,
        sigma_deg: Some(sig[0].max(sig[1]).to_degrees()),
        bound_deg: None,
        segmented_deg: None,
    }
}

fn cell_stats(
    scans: usize,
    noise: f64,
    estimator: Estimator,
    gate_deg: f64,
    o: &[&PoseOutcome],
) -> CellStats {
    let errors: Vec<f64> = o.iter().filter_map(|p| p.error_deg).collect();
    let sorted = sorted_copy(&errors);
    let n = sorted.len();
    let bounds: Vec<f64> = o.iter().filter_map(|p| p.bound_deg).collect();
    let segmented: Vec<f64> = o.iter().filter_map(|p| p.segmented_deg).collect();
    let over_bound: Vec<f64> = o
        .iter()
        .filter_map(|p| Some(p.sigma_deg? / p.bound_deg?))
        .collect();
    let mut failures = BTreeMap::new();
    for p in o {
        if let Some(f) = p.failure {
            *failures.entry(f.as_str().to_string()).or_insert(0) += 1;
        }
    }
    let leveled: Vec<&&PoseOutcome> = o.iter().filter(|p| p.error_deg.is_some()).collect();
    let valid: usize = leveled.iter().map(|p| p.pseudo_valid).sum();
    let phantoms: usize = leveled.iter().map(|p| p.phantoms).sum();
    let walls: usize = leveled.iter().map(|p| p.best_wall_hits).sum();
    let ratio = |a: usize, b: usize| {
        if b == 0 {
            f64::NAN
        } else {
            a as f64 / b as f64
        }
    };
    let within_gate = |sigmas: &[f64]| {
        ratio(
            sigmas.iter().filter(|&&s| s <= gate_deg).count(),
            sigmas.len(),
        )
    };
    CellStats {
        scans,
        noise,
        estimator: estimator.to_string(),
        poses: o.len(),
        leveled: n,
        leveled_fraction: ratio(n, o.len()),
        mean_deg: if n == 0 {
            f64::NAN
        } else {
            errors.iter().sum::<f64>() / n as f64
        },
        median_deg: median(&sorted),
        p95_deg: nearest_rank(&sorted, 0.95),
        max_deg: sorted.last().copied().unwrap_or(f64::NAN),
        wrong_over_5_deg: errors.iter().filter(|&&e| e > 5.0).count(),
        within_3_sigma: ratio(leveled.iter().filter(|p| p.within_3_sigma).count(), n),
        phantom_rate: ratio(phantoms, valid),
        coverage: ratio(valid, walls),
        paper_mean_deg: paper_mean(scans, noise),
        bound_median_deg: median(&sorted_copy(&bounds)),
        bound_within_gate: within_gate(&bounds),
        segmented_within_gate: within_gate(&segmented),
        sigma_over_bound: median(&sorted_copy(&over_bound)),
        failures,
        errors_deg: errors,
        outcomes: o.iter().map(|&p| p.clone()).collect(),
    }
}

fn sorted_copy(v: &[f64]) -> Vec<f64> {
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    v
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

    #[test]
    fn cell_stats_on_known_errors() {
        let mk = |e: Option<f64>| PoseOutcome {
            plan: 0,
            pose: 0,
            truth_deg: [0.0, 0.0],
            estimate_deg: e.map(|x| [x, 0.0]),
            failure: if e.is_none() {
                Some(FailReason::ParallelWalls)
            } else {
                None
            },
            error_deg: e,
            within_3_sigma: e.is_some_and(|x| x < 2.0),
            pseudo_valid: 10,
            phantoms: 1,
            best_wall_hits: 20,
            sigma_deg: e.map(|x| x / 2.0),
            bound_deg: Some(if e.is_none() { f64::INFINITY } else { 0.25 }),
            segmented_deg: Some(if e == Some(1.0) { 0.5 } else { 2.0 }),
        };
        let outcomes = [mk(Some(1.0)), mk(Some(3.0)), mk(None), mk(Some(6.0))];
        let refs: Vec<&PoseOutcome> = outcomes.iter().collect();
        let s = cell_stats(3, 0.01, Estimator::Robust, 1.5, &refs);
        assert_eq!(s.leveled, 3);
        assert!((s.mean_deg - 10.0 / 3.0).abs() < 1e-12);
        assert_eq!(s.median_deg, 3.0);
        assert_eq!(s.max_deg, 6.0);
        assert_eq!(s.wrong_over_5_deg, 1);
        assert_eq!(s.failures.get("parallel_walls"), Some(&1));
        assert!((s.phantom_rate - 0.1).abs() < 1e-12);
        assert!((s.coverage - 0.5).abs() < 1e-12);
        // Bounds 0.25, 0.25, inf, 0.25: three of four within the gate.
        assert_eq!(s.bound_median_deg, 0.25);
        assert!((s.bound_within_gate - 0.75).abs() < 1e-12);
        // From the true segmentation 0.5, 2, 2, 2: one of four.
        assert!((s.segmented_within_gate - 0.25).abs() < 1e-12);
        // Sigmas 0.5, 1.5, 3.0 over 0.25.
        assert!((s.sigma_over_bound - 6.0).abs() < 1e-12);
    }
}
