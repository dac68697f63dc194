//! Re-segmentation in the provisional level frame (`level::refine`): exact recovery, a wall's
//! foot kept out of the floor at high noise, and more poses leveled honestly at 10 cm.

mod common;

use common::{Room, elevations, scans_at};
use levelscan::geometry::Pose;
use levelscan::level::{
    FailCause, LevelEstimate, LevelParams, SurfaceKind, level_fits, level_pose, refine_estimate,
};
use levelscan::scan::{Hit, Scan};
use rand::{RngExt, SeedableRng};

fn deg(a: f64) -> f64 {
    a.to_radians()
}

fn without_refine() -> LevelParams {
    LevelParams {
        refine_passes: 0,
        ..LevelParams::default()
    }
}

/// The refined model of a pose whose first solution failed: re-segmented from the starts found
/// without a level frame.
fn refined(
    scans: &[Scan],
    params: &LevelParams,
) -> (LevelEstimate, levelscan::level::refine::Refined) {
    let est = level_pose(scans, &without_refine());
    let levels = level_fits(&est, params);
    let r = refine_estimate(&est, &levels, &Err(FailCause::SigmaAboveGate), params)
        .expect("a refined model");
    (est, r.refined)
}

/// What the simulator says grid point `i` hit.
fn hit_of(est: &LevelEstimate, scans: &[Scan], i: usize) -> Hit {
    let grid = est.grid.as_ref().unwrap();
    let scan = &scans[grid.scan_index[i / grid.cols]];
    scan.hit.as_ref().unwrap()[i % grid.cols]
}

#[test]
fn refined_box_room_without_noise_recovers_known_tilt_within_005_deg() {
    let room = Room::box_room(6.0, 5.0);
    let pose = Pose::new(2.5, 2.0, 0.45, deg(30.0), deg(8.0), deg(-12.0));
    let scans = scans_at(&room, &pose, &elevations(3, 5.0), 0.0, 1, 0);
    let params = LevelParams::default();
    let (_, r) = refined(&scans, &params);
    let err = r.solution.attitude().max_abs_error(&pose.attitude());
    assert!(err.to_degrees() < 0.05, "error {} deg", err.to_degrees());
    assert!(
        r.models
            .iter()
            .filter(|m| m.kind == SurfaceKind::Wall)
            .count()
            >= 2
    );
}

#[test]
fn refined_floor_takes_no_wall_foot_at_ten_centimetres() {
    // Pitched down towards a wall 4.5 m ahead: the lower scans meet the floor in front of the
    // wall's foot, the upper ones the wall; at 10 cm noise the foot lies within any floor
    // plane's tolerance.
    let room = Room::box_room(6.0, 5.0);
    let pose = Pose::new(1.5, 2.5, 0.45, deg(0.0), deg(10.0), deg(3.0));
    let scans = scans_at(&room, &pose, &elevations(5, 5.0), 0.10, 7, 0);
    let params = LevelParams::default();
    let (est, r) = refined(&scans, &params);
    let share = |kind: SurfaceKind, hit: Hit| -> Vec<f64> {
        r.models
            .iter()
            .filter(|m| m.kind == kind)
            .map(|m| {
                let n = m
                    .members
                    .iter()
                    .filter(|&&i| hit_of(&est, &scans, i) == hit)
                    .count();
                n as f64 / m.members.len() as f64
            })
            .collect()
    };
    let floors = share(SurfaceKind::Floor, Hit::Floor);
    assert_eq!(floors.len(), 1, "one floor expected");
    // Region growing's floor patch here holds 8 wall points in 334 (97.6%).
    assert!(floors[0] >= 0.99, "floor model {:.3} floor hits", floors[0]);
    let walls = share(SurfaceKind::Wall, Hit::Wall);
    assert!(!walls.is_empty());
    for w in walls {
        assert!(w >= 0.95, "wall model {w:.3} wall hits");
    }
    let err = r.solution.attitude().max_abs_error(&pose.attitude());
    let sig = r.solution.attitude_sigmas();
    assert!(
        err <= 3.0 * sig[0].max(sig[1]),
        "error {} deg, sigmas {sig:?}",
        err.to_degrees()
    );
}

#[test]
fn refine_levels_more_poses_at_ten_centimetres_and_stays_honest() {
    let room = Room::polygon(
        &[
            [0.0, 0.0],
            [8.0, 0.0],
            [8.0, 3.0],
            [5.0, 3.0],
            [5.0, 6.0],
            [0.0, 6.0],
        ],
        2.6,
        false,
    );
    let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(11);
    let (mut leveled_on, mut leveled_off, mut outside_3_sigma) = (0, 0, 0);
    for k in 0..24u64 {
        // Inside the L, away from the walls.
        let (x, y) = if rng.random::<f64>() < 0.5 {
            (rng.random_range(0.8..7.2), rng.random_range(0.8..2.2))
        } else {
            (rng.random_range(0.8..4.2), rng.random_range(0.8..5.2))
        };
        let pose = Pose::new(
            x,
            y,
            0.45,
            rng.random_range(-3.0..3.0),
            deg(rng.random_range(-20.0..20.0)),
            deg(rng.random_range(-20.0..20.0)),
        );
        let scans = scans_at(&room, &pose, &elevations(4, 5.0), 0.10, 100 + k, k);
        let on = level_pose(&scans, &LevelParams::default());
        let off = level_pose(&scans, &without_refine());
        leveled_off += usize::from(off.is_ok());
        if let (Some(att), Some(sig)) = (on.attitude, on.sigmas) {
            leveled_on += 1;
            let t = pose.attitude();
            let (dx, dy) = (
                (att.theta_x - t.theta_x).abs(),
                (att.theta_y - t.theta_y).abs(),
            );
            assert!(dx.max(dy).to_degrees() < 5.0, "pose {k}: error {dx} {dy}");
            outside_3_sigma += usize::from(dx > 3.0 * sig[0] || dy > 3.0 * sig[1]);
        }
    }
    assert!(
        leveled_on > leveled_off,
        "refined {leveled_on} vs first {leveled_off} of 24"
    );
    assert!(outside_3_sigma <= 1, "{outside_3_sigma} outside 3 sigma");
}

#[test]
fn level_start_finds_the_floor_without_any_up() {
    // Facing the floor of a big room at 10 cm noise, walls far beyond the beams: the start
    // comes from the points whose range steps like a level surface's, with no up given.
    let room = Room::box_room(60.0, 60.0);
    let pose = Pose::new(30.0, 30.0, 0.45, deg(10.0), deg(14.0), deg(-9.0));
    let scans = scans_at(&room, &pose, &elevations(3, 5.0), 0.10, 9, 0);
    let est = level_pose(&scans, &without_refine());
    let grid = est.grid.as_ref().unwrap();
    let params = LevelParams::default();
    let steps = levelscan::level::refine::level_steps(grid, &params, 0.10);
    let start =
        levelscan::level::refine::level_start(grid, &steps, &params, 0.10).expect("a level start");
    let err = start.attitude().max_abs_error(&pose.attitude());
    assert!(err.to_degrees() < 1.0, "error {} deg", err.to_degrees());
}

/// Pose `k` of `count` drawn in the example plan `name`, as `eval accuracy
/// examples/plans/{office,angled,ceiling,two_rooms}.wall --seed SEED` draws and scans it: roll
/// and pitch within 20 degrees, the scanner 0.45 m up, `nscans` scans 5 degrees apart, range
/// noise `noise`.
struct ProtocolPose {
    name: &'static str,
    seed: u64,
    count: usize,
    k: usize,
    nscans: usize,
    noise: f64,
}

impl ProtocolPose {
    /// The true pose and its scans, taken by cleverRobot when `adaptive`.
    fn scans(&self, adaptive: bool) -> (Pose, Vec<Scan>) {
        // The plan's index in `eval accuracy`'s list seeds its poses and noise.
        let pi = ["office", "angled", "ceiling", "two_rooms"]
            .iter()
            .position(|&n| n == self.name)
            .expect("an example plan") as u64;
        use levelscan::simulate::{
            AdaptiveParams, RandomPoseParams, ScannerParams, Stream, World, elevations_centred,
            random_poses, simulate_pose, simulate_pose_adaptive, stream_rng,
        };
        let protocol = RandomPoseParams {
            tilt: deg(20.0),
            clearance: 0.6,
            height: 0.45,
            ..RandomPoseParams::default()
        };
        let path = format!(
            "{}/examples/plans/{}.wall",
            env!("CARGO_MANIFEST_DIR"),
            self.name
        );
        let world = World::from_plan(&levelscan::formats::read_plan(path.as_ref()).unwrap());
        let pose = random_poses(&world, self.count, &protocol, self.seed + pi).unwrap()[self.k];
        let scanner = ScannerParams {
            noise_sigma: self.noise,
            ..ScannerParams::default()
        };
        let stream = self.seed + (pi << 32) + ((self.nscans as u64) << 48);
        let mut rng = stream_rng(stream, Stream::Scans, self.k as u64);
        let elevations = elevations_centred(self.nscans, deg(5.0));
        let k = self.k as u64;
        let scans = if adaptive {
            let params = AdaptiveParams::default();
            simulate_pose_adaptive(&world, k, &pose, &elevations, &scanner, &params, &mut rng)
        } else {
            simulate_pose(&world, k, &pose, &elevations, &scanner, &mut rng)
        };
        (pose, scans)
    }

    /// Levels the pose's scans ([`Self::scans`]) and asserts that they fail or come out honest:
    /// each angle within three of its reported sigmas of the truth (under the 1.5-degree gate,
    /// within 4.5 degrees). Returns how many scans there were.
    fn fails_or_is_honest(&self, adaptive: bool) -> usize {
        let (pose, scans) = self.scans(adaptive);
        let est = level_pose(&scans, &LevelParams::default());
        if let (Some(att), Some(sigmas)) = (est.attitude, est.sigmas) {
            let truth = pose.attitude();
            let errors = [att.theta_x - truth.theta_x, att.theta_y - truth.theta_y];
            let (name, seed, k) = (self.name, self.seed, self.k);
            for (e, s) in errors.iter().zip(sigmas) {
                assert!(
                    e.abs() <= 3.0 * s,
                    "{name} seed {seed} pose {k}: {:.2} deg off, sigma {:.2} deg",
                    e.to_degrees(),
                    s.to_degrees()
                );
            }
        }
        scans.len()
    }
}

/// Poses of the accuracy protocol (`eval accuracy examples/plans/{office,angled,ceiling,
/// two_rooms}.wall`, its random streams) once reported ok while degrees off. In the office,
/// each traced to a floor that could not be one: a wall's line and the next scan's floor line,
/// parallel, as a "floor" 13 degrees off (seed 8); a loose start's floor lost among wall
/// points (seed 14); a wall line 14 cm above its foot taken as a third floor line (seed 1). In
/// the ceiling room at 10 cm, the first and the re-segmented solutions 4-5 degrees apart with
/// sigmas near one degree, the kept one 6 degrees off (seeds 4 and 8). In the office at 10 cm
/// with five scans, a floor over all five rows, about a fifth in each, refused for lack of
/// rows with a fifth of its points: the walls alone ended 8 degrees off (seed 7). A first
/// solution 5-6 degrees off with sigmas of 1.2-1.5 degrees, whose re-segmentation failed the
/// gate 3-18 degrees away (office seeds 8 and 13, ceiling seed 6, two rooms seed 16). A first
/// solution that failed, and a refined one 5 degrees off with a sigma of 1.4 degrees, far from
/// the start it grew from (two rooms seed 28). At 5-10 cm with three scans, a "floor" on two
/// scan lines, a wall's and the floor's below it, 7 and 6 degrees off with sigmas of 0.4 and
/// 1.5 degrees (angled seed 15, office seed 14). At 1 cm with four scans, pitched 19 degrees
/// up, a far wall's plane through its corner with the ceiling, 7 degrees off vertical, 7
/// degrees off with a sigma of 1.4 (ceiling seed 108). Each now fails or lies within three of
/// its sigmas.
#[test]
fn traced_poses_reported_ok_and_wrong_now_fail_or_are_right() {
    // (plan, seed, poses drawn, pose, scans, noise)
    for (name, seed, count, k, nscans, noise) in [
        ("office", 8u64, 100, 39usize, 3usize, 0.05),
        ("office", 14, 150, 15, 3, 0.05),
        ("office", 1, 200, 110, 3, 0.05),
        ("ceiling", 4, 100, 94, 5, 0.10),
        ("ceiling", 8, 100, 81, 5, 0.10),
        ("office", 7, 100, 37, 5, 0.10),
        ("office", 8, 100, 13, 3, 0.10),
        ("office", 13, 100, 19, 3, 0.05),
        ("ceiling", 6, 100, 36, 5, 0.10),
        ("two_rooms", 16, 100, 41, 5, 0.10),
        ("two_rooms", 28, 150, 115, 5, 0.05),
        ("angled", 15, 100, 75, 3, 0.05),
        ("office", 14, 100, 58, 3, 0.10),
        ("ceiling", 108, 100, 24, 4, 0.01),
    ] {
        let protocol = ProtocolPose {
            name,
            seed,
            count,
            k,
            nscans,
            noise,
        };
        protocol.fails_or_is_honest(false);
    }
}

/// A cleverRobot pose of the protocol (`eval accuracy ... --adaptive`, two rooms, seed 1, four
/// scans at 10 cm) once reported ok 14.6 degrees off with sigmas near one degree. Its retakes
/// gave 12 scans over +-27.5 degrees; the first solution failed, and re-segmentation from the
/// ungated solution (25 degrees off) settled on walls that were not vertical, while from the
/// walls with the floor's lines it settled 1.2 degrees off, as tight. Re-segmenting from every
/// start and keeping both readings in view, it now fails or lies within three of its sigmas.
#[test]
fn cleverrobot_pose_with_two_self_consistent_readings_fails_or_is_honest() {
    let protocol = ProtocolPose {
        name: "two_rooms",
        seed: 1,
        count: 100,
        k: 61,
        nscans: 4,
        noise: 0.10,
    };
    let scans = protocol.fails_or_is_honest(true);
    assert!(scans > protocol.nscans, "the robot retook scans");
}

/// A pose of the protocol (office, seed 1, four scans at 5 cm) whose Cramér-Rao bound is 0.03
/// degrees: one scan meets the floor from 2.6 to 4 m, the next one only in the last 0.1-0.6 m
/// before a wall's foot. Those 19 points step less to the wall above them than open floor does,
/// and were no floor-line candidates: the walls alone left 1.7 degrees of sigma and the pose
/// failed. With both floor lines it levels within a tenth of a degree.
#[test]
fn floor_just_in_front_of_a_wall_foot_levels_a_pose_its_walls_cannot() {
    let protocol = ProtocolPose {
        name: "office",
        seed: 1,
        count: 100,
        k: 92,
        nscans: 4,
        noise: 0.05,
    };
    let (pose, scans) = protocol.scans(false);
    let est = level_pose(&scans, &LevelParams::default());
    let (att, sigmas) = (est.attitude.expect("leveled"), est.sigmas.unwrap());
    let truth = pose.attitude();
    let errors = [att.theta_x - truth.theta_x, att.theta_y - truth.theta_y];
    for (e, s) in errors.iter().zip(sigmas) {
        assert!(e.abs() < deg(0.1), "{:.3} deg off", e.to_degrees());
        assert!(s < deg(0.3), "sigma {:.3} deg", s.to_degrees());
        assert!(e.abs() <= 3.0 * s);
    }
}

/// A corridor (30 m by 2 m, no ceiling) seen from inside, the scanner facing a side wall or
/// looking along it: the walls in view are parallel and the floor shows only in the last rays
/// of each scan, where the three scans meet nearly the same spots (no quad, no floor-like range
/// steps, under 30 points). The sweep over the walls' free angle finds the floor's height and
/// levels these poses honestly; they failed as `no_up` before (docs/ESTIMATOR.md section 17).
#[test]
fn a_corridor_pose_that_sees_the_floor_only_at_the_scans_ends_levels() {
    let corridor = Room::polygon(
        &[[0.0, 0.0], [30.0, 0.0], [30.0, 2.0], [0.0, 2.0]],
        3.0,
        false,
    );
    // (x, y, yaw, pitch, roll) [m, deg]: poses `simulate corridor.wall --random 100 --seed 5`
    // failed.
    let poses = [
        (8.96, 1.49, 68.46, -1.78, 2.80),
        (14.50, 1.33, -83.95, -18.55, 17.26),
        (4.97, 0.83, 4.68, -1.01, 17.80),
        (6.64, 0.95, -67.83, -17.24, -8.48),
    ];
    let mut leveled = 0;
    for (k, &(x, y, yaw, pitch, roll)) in poses.iter().enumerate() {
        let pose = Pose::new(x, y, 0.45, deg(yaw), deg(pitch), deg(roll));
        let scans = scans_at(
            &corridor,
            &pose,
            &elevations(3, 5.0),
            0.01,
            40 + k as u64,
            k as u64,
        );
        let est = level_pose(&scans, &LevelParams::default());
        let Some(att) = est.attitude else {
            continue;
        };
        leveled += 1;
        let (truth, sigmas) = (pose.attitude(), est.sigmas.unwrap());
        for (e, s) in [att.theta_x - truth.theta_x, att.theta_y - truth.theta_y]
            .iter()
            .zip(sigmas)
        {
            assert!(
                e.abs() <= 3.0 * s && e.abs() < deg(1.0),
                "pose {k}: {:.3} deg off, sigma {:.3}",
                e.to_degrees(),
                s.to_degrees()
            );
        }
    }
    assert!(leveled >= 3, "{leveled} of 4 leveled");
}
