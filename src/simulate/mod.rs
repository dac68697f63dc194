//! The laser scan simulator (paper sect. 7.2.1): tilted 2D scans of a floor plan.
//!
//! - [`raycast`]: the scene ([`World`]) and its ray caster, with the hit conventions (over
//!   the plan's spatial index, `plan::grid`, which keeps ray casting fast on big plans);
//! - [`scanner`]: the tilting scanner ([`ScannerParams`], [`simulate_pose`]);
//! - [`sweep`]: a hinge that moves while it scans (each ray's own elevation);
//! - [`random_poses`](mod@random_poses): poses in a plan's free space;
//! - [`odometry`](mod@odometry): drifting planar dead reckoning.
//!
//! Everything here is pure; randomness comes from [`stream_rng`], one stream per pose, so a
//! run's output depends on its seed only, never on the thread count.

pub mod adaptive;
pub mod clock;
pub mod noise_model;
pub mod odometry;
pub mod random_poses;
pub mod raycast;
pub mod scanner;
pub mod sweep;

pub use adaptive::{AdaptiveParams, simulate_pose_adaptive};
pub use noise_model::NoiseModel;
pub use odometry::{OdometryParams, odometry};
pub use random_poses::{RandomPoseParams, is_free, random_poses};
pub use raycast::{RayHit, World};
pub use scanner::{ScannerParams, elevations_centred, simulate_pose};

use crate::geometry::Pose;
use crate::scan::Scan;
use rand::SeedableRng;
use rand::rngs::ChaCha8Rng;
use rayon::prelude::*;

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SimulateError {
    #[error("invalid parameter: {0}")]
    InvalidParameter(String),
    #[error("the plan has no walls to place random poses among")]
    NoWalls,
    #[error(
        "no free space found: {tries} random positions were tried for one pose, none inside the \
         building and at least {clearance} m from every wall (are the rooms enclosed by walls, \
         and --clearance small enough for them?)"
    )]
    NoFreeSpace { tries: usize, clearance: f64 },
}

/// What a random stream is used for; each purpose gets independent streams.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stream {
    /// Range noise of the scans at one pose.
    Scans,
    /// Drawing one random pose.
    RandomPoses,
    /// Noise of one odometry step.
    Odometry,
    /// Free for callers (e.g. an adaptive robot's retakes).
    Other(u32),
}

impl Stream {
    fn key(self) -> u64 {
        match self {
            Stream::Scans => 0x5CA9_5CA9_0000_0001,
            Stream::RandomPoses => 0x9053_9053_0000_0002,
            Stream::Odometry => 0x0D0D_0D0D_0000_0003,
            Stream::Other(k) => 0x07E4_0000_0000_0000 | u64::from(k),
        }
    }
}

/// The random generator for item `index` (a pose, a step) of `purpose`, given the run's seed:
/// ChaCha8 keyed by (seed, purpose) on stream `index`. Independent of threads and of the
/// order in which items are simulated.
pub fn stream_rng(seed: u64, purpose: Stream, index: u64) -> ChaCha8Rng {
    // seed_from_u64 expands the key through PCG32, so nearby keys give unrelated seeds.
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ purpose.key());
    rng.set_stream(index);
    rng
}

/// Simulates the scans at `poses` in parallel; pose `k` gets `sequence = first_sequence + k`,
/// the odometry `odometry[k]` when given, and its noise from
/// `stream_rng(seed, Stream::Scans, sequence)`, and `timestamp`s from [`clock`]. With `adaptive`, cleverRobot takes each pose's
/// scans (its first set is the same as without). The result is in pose order and identical for
/// any number of threads, and simulating a run in chunks gives the same scans as all at once.
#[allow(clippy::too_many_arguments)]
pub fn simulate_poses(
    world: &World,
    poses: &[Pose],
    odometry: Option<&[Pose]>,
    first_sequence: u64,
    elevations: &[f64],
    params: &ScannerParams,
    adaptive: Option<&AdaptiveParams>,
    seed: u64,
) -> Vec<Vec<Scan>> {
    poses
        .par_iter()
        .enumerate()
        .map(|(k, pose)| {
            let sequence = first_sequence + k as u64;
            let mut rng = stream_rng(seed, Stream::Scans, sequence);
            let mut scans = match adaptive {
                Some(a) => {
                    simulate_pose_adaptive(world, sequence, pose, elevations, params, a, &mut rng)
                }
                None => simulate_pose(world, sequence, pose, elevations, params, &mut rng),
            };
            for (j, s) in scans.iter_mut().enumerate() {
                s.timestamp = Some(clock::scan_timestamp(sequence, j));
            }
            if let Some(odo) = odometry.and_then(|o| o.get(k)) {
                for s in &mut scans {
                    s.odometry = Some(*odo);
                }
            }
            scans
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::Plan;
    use nalgebra::Point2;

    #[test]
    fn chunked_and_threaded_runs_match_one_sequential_run() {
        let plan = Plan {
            wall_height: 3.0,
            walls: vec![vec![
                Point2::new(0.0, 0.0),
                Point2::new(6.0, 0.0),
                Point2::new(6.0, 5.0),
                Point2::new(0.0, 5.0),
                Point2::new(0.0, 0.0),
            ]],
            ceiling: false,
            poses: vec![],
        };
        let world = World::from_plan(&plan);
        let poses = random_poses(&world, 12, &RandomPoseParams::default(), 4).unwrap();
        let odo = odometry(&poses, &OdometryParams::default(), 4);
        let e = elevations_centred(3, 0.1);
        let p = ScannerParams::default();
        let all = simulate_poses(&world, &poses, Some(&odo), 0, &e, &p, None, 4);
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap()
            .install(|| simulate_poses(&world, &poses, Some(&odo), 0, &e, &p, None, 4));
        assert_eq!(all, one);
        let mut chunked = simulate_poses(&world, &poses[..5], Some(&odo[..5]), 0, &e, &p, None, 4);
        chunked.extend(simulate_poses(
            &world,
            &poses[5..],
            Some(&odo[5..]),
            5,
            &e,
            &p,
            None,
            4,
        ));
        assert_eq!(all, chunked);
        assert_eq!(all[7][0].sequence, Some(7));
        assert_eq!(all[7][2].odometry, Some(odo[7]));
        assert_ne!(
            all,
            simulate_poses(&world, &poses, Some(&odo), 0, &e, &p, None, 5)
        );
    }
}
