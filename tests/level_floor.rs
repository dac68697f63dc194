//! The floor and ceiling taken as level planes (`LevelParams::level_surfaces`), beside the
//! paper's walls-only estimate.

mod common;

use common::{Room, elevations, scans_at};
use levelscan::geometry::Pose;
use levelscan::level::{FailCause, FailReason, LevelParams, level_pose};

fn deg(a: f64) -> f64 {
    a.to_radians()
}

fn walls_only() -> LevelParams {
    LevelParams {
        level_surfaces: false,
        ..LevelParams::default()
    }
}

/// Big room: the steeply pitched beams meet the floor long before any wall.
fn facing_floor_scans(noise: f64) -> (Pose, Vec<levelscan::scan::Scan>) {
    let room = Room::box_room(60.0, 60.0);
    let pose = Pose::new(30.0, 30.0, 0.45, deg(10.0), deg(35.0), deg(-6.0));
    let scans = scans_at(&room, &pose, &elevations(3, 5.0), noise, 3, 0);
    (pose, scans)
}

#[test]
fn robot_facing_the_floor_is_leveled_from_the_floor_exactly_without_noise() {
    let (pose, scans) = facing_floor_scans(0.0);
    let e = level_pose(&scans, &LevelParams::default());
    assert!(e.is_ok(), "{:?}", e.failure);
    let err = e
        .attitude
        .unwrap()
        .max_abs_error(&pose.attitude())
        .to_degrees();
    assert!(err < 0.05, "error {err} deg");
}

#[test]
fn robot_facing_the_floor_is_leveled_within_its_sigma_at_1cm() {
    let (pose, scans) = facing_floor_scans(0.01);
    let e = level_pose(&scans, &LevelParams::default());
    let (att, sig) = (e.attitude.unwrap(), e.sigmas.unwrap());
    let t = pose.attitude();
    assert!((att.theta_x - t.theta_x).abs() < 3.0 * sig[0]);
    assert!((att.theta_y - t.theta_y).abs() < 3.0 * sig[1]);
    assert!(sig[0].to_degrees() < 0.5 && sig[1].to_degrees() < 0.5);
}

#[test]
fn walls_only_keeps_the_papers_facing_floor_failure() {
    let (_, scans) = facing_floor_scans(0.01);
    assert_eq!(
        level_pose(&scans, &walls_only()).failure,
        Some(FailReason::FacingFloor)
    );
}

#[test]
fn corridor_is_parallel_walls_on_walls_alone_and_leveled_with_the_floor() {
    let room = Room::corridor();
    let pose = Pose::new(0.0, 1.0, 0.45, deg(0.0), deg(9.0), deg(4.0));
    let scans = scans_at(&room, &pose, &elevations(5, 5.0), 0.01, 2, 0);
    let walls = level_pose(&scans, &walls_only());
    assert_eq!(walls.failure, Some(FailReason::ParallelWalls));
    // The cause within the reason: the normals of two parallel walls fix no up at all.
    assert_eq!(walls.cause, Some(FailCause::NoUp));
    let e = level_pose(&scans, &LevelParams::default());
    assert!(e.is_ok(), "{:?}", e.failure);
    let err = e
        .attitude
        .unwrap()
        .max_abs_error(&pose.attitude())
        .to_degrees();
    assert!(err < 0.5, "error {err} deg");
}

/// A room whose front wall has a 0.2 m gap (a doorway), with nothing behind it but floor.
fn room_with_doorway() -> Room {
    Room {
        segments: vec![
            ([8.0, 3.1], [8.0, 6.0]),
            ([8.0, 6.0], [0.0, 6.0]),
            ([0.0, 6.0], [0.0, 0.0]),
            ([0.0, 0.0], [8.0, 0.0]),
            ([8.0, 0.0], [8.0, 2.9]),
        ],
        height: 2.5,
        ceiling: false,
    }
}

#[test]
fn gap_filling_keeps_no_floor_hit_seen_through_a_doorway() {
    use levelscan::pseudo_level::{PseudoLevelParams, pseudo_level_scan};
    let pose = Pose::new(4.0, 3.0, 0.5, 0.0, deg(-4.0), deg(6.0));
    let scans = scans_at(&room_with_doorway(), &pose, &elevations(3, 5.0), 0.0, 5, 0);
    let e = level_pose(&scans, &LevelParams::default());
    assert!(e.is_ok(), "{:?}", e.failure);
    let out = pseudo_level_scan(&scans, &e, &PseudoLevelParams::default());
    // Every kept point is on a wall: the farthest wall from (4, 3) is under 5 m away.
    for i in 0..out.nrays() {
        if let Some(r) = out.range(i) {
            assert!(
                r < 5.5,
                "ray {i} kept at {r} m: a floor hit beyond the doorway"
            );
        }
    }
    assert!(out.valid_count() > 150, "only {} kept", out.valid_count());
}

#[test]
fn a_far_wall_only_the_top_scan_reaches_is_kept() {
    use levelscan::pseudo_level::{PseudoLevelParams, pseudo_level_scan};
    use levelscan::scan::Hit;
    // Pitched 5 degrees towards the floor: the top scan is level and meets the wall 10 m ahead;
    // the lower two meet the floor 5 and 2.6 m ahead. The side walls and a pillar 2 m ahead
    // level the pose.
    let room = Room::box_room(12.0, 6.0).with_box([4.0, 4.0], [4.6, 4.6]);
    let pose = Pose::new(2.0, 3.0, 0.45, 0.0, deg(5.0), deg(0.0));
    let scans = scans_at(&room, &pose, &elevations(3, 5.0), 0.01, 4, 0);
    let e = level_pose(&scans, &LevelParams::default());
    assert!(e.is_ok(), "{:?}", e.failure);
    let base = levelscan::pseudo_level::base_scan_index(&scans, &e, &PseudoLevelParams::default());
    let out = pseudo_level_scan(&scans, &e, &PseudoLevelParams::default());
    let hits = scans[base].hit.as_ref().unwrap();
    let mut front = 0;
    for (i, hit) in hits.iter().enumerate() {
        let Some(r) = out.range(i) else { continue };
        assert_eq!(*hit, Hit::Wall, "ray {i} kept but not a wall");
        if pose.x + r * out.theta[i].cos() > 11.5 {
            front += 1;
        }
    }
    // The front wall spans about 33 degrees of the top scan (|y| <= 3 at 10 m).
    assert!(front >= 25, "{front} front-wall points kept");
    let without = PseudoLevelParams {
        height_test: false,
        ..PseudoLevelParams::default()
    };
    let old = pseudo_level_scan(&scans, &e, &without);
    assert!(old.valid_count() + 25 <= out.valid_count());
}

#[test]
fn floor_hits_at_a_walls_foot_are_not_kept_when_two_scans_see_the_floor() {
    use levelscan::pseudo_level::{PseudoLevelParams, pseudo_level_scan};
    use levelscan::scan::Hit;
    // Pitched 6.7 degrees down, 4 m from the wall ahead: the level-most scan meets the wall,
    // the middle one the floor 0.16 m before it (right under the wall's points), the lowest
    // the floor at 2.2 m. Those floor hits look vertical against the wall points above them.
    // A pillar ahead on the right pins the pitch.
    let room = Room::box_room(6.0, 5.2).with_box([2.4, 2.6], [2.8, 3.0]);
    let pose = Pose::new(1.2, 1.2, 0.45, deg(86.1), deg(6.7), 0.0);
    for seed in 0..5 {
        let scans = scans_at(&room, &pose, &elevations(3, 5.0), 0.01, seed, 0);
        let e = level_pose(&scans, &LevelParams::default());
        assert!(e.is_ok(), "{:?}", e.failure);
        let base =
            levelscan::pseudo_level::base_scan_index(&scans, &e, &PseudoLevelParams::default());
        let hits = scans[base].hit.as_ref().unwrap();
        let out = pseudo_level_scan(&scans, &e, &PseudoLevelParams::default());
        let floor_kept = hits
            .iter()
            .enumerate()
            .filter(|&(i, h)| out.valid[i] && *h == Hit::Floor)
            .count();
        // Without the floor's band about 36 are kept; a stray at the band's edge may remain.
        assert!(floor_kept <= 2, "seed {seed}: {floor_kept} floor hits kept");
        assert!(out.valid_count() > 100, "only {} kept", out.valid_count());
    }
}

/// A pose refused after re-segmentation is named by the same facing test as a first solution:
/// `eval accuracy`'s pose 26 of ceiling.wall (seed 1, 3 scans, 10 cm), whose floor quads
/// outnumber its wall quads, was reported as parallel_walls by the second gate.
#[test]
fn a_pose_refused_after_resegmentation_facing_the_floor_is_facing_floor() {
    use levelscan::simulate::{
        RandomPoseParams, ScannerParams, Stream, World, elevations_centred, random_poses,
        simulate_pose, stream_rng,
    };
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/plans/ceiling.wall");
    let world = World::from_plan(&levelscan::formats::read_plan(path.as_ref()).unwrap());
    // As `eval accuracy` draws them: the third plan given (seed 1 + 2), clearance 0.6 m.
    let pose_params = RandomPoseParams {
        clearance: 0.6,
        ..RandomPoseParams::default()
    };
    let poses = random_poses(&world, 100, &pose_params, 3).unwrap();
    let (k, nscans) = (26usize, 3usize);
    let stream = 1u64 + (2u64 << 32) + ((nscans as u64) << 48);
    let mut rng = stream_rng(stream, Stream::Scans, k as u64);
    let scanner = ScannerParams {
        noise_sigma: 0.1,
        ..ScannerParams::default()
    };
    let elevations = elevations_centred(nscans, deg(5.0));
    let scans = simulate_pose(&world, k as u64, &poses[k], &elevations, &scanner, &mut rng);
    let est = level_pose(&scans, &LevelParams::default());
    assert_eq!(est.facing(), Some(FailReason::FacingFloor));
    assert_eq!(est.failure, Some(FailReason::FacingFloor));
    assert_eq!(est.cause, Some(FailCause::FacingFloor));
    // Without re-segmentation the first gate refuses it, with the same reason.
    let first_only = LevelParams {
        refine_passes: 0,
        ..LevelParams::default()
    };
    let first = level_pose(&scans, &first_only);
    assert_eq!(first.failure, Some(FailReason::FacingFloor));
}
