//! Leveling at high range noise (5-10 cm): floor patches that stay off the walls' feet, and
//! poses that the floor levels.

mod common;

use common::{Room, elevations, scans_at};
use levelscan::geometry::Pose;
use levelscan::level::{LevelParams, SurfaceKind, level_pose};
use levelscan::scan::{Hit, Scan};

fn deg(a: f64) -> f64 {
    a.to_radians()
}

/// Floor-patch points that the scanner's rays actually put on a wall, and all floor-patch points,
/// of the first segmentation (re-segmentation off: its models would replace the patches).
fn wall_points_in_floor_patches(scans: &[Scan], params: &LevelParams) -> (usize, usize) {
    let first = LevelParams {
        refine_passes: 0,
        ..params.clone()
    };
    let e = level_pose(scans, &first);
    let grid = e.grid.as_ref().unwrap();
    let (mut on_wall, mut all) = (0, 0);
    for p in e.patches.iter().filter(|p| p.kind == SurfaceKind::Floor) {
        for &i in &p.members {
            let scan = &scans[grid.scan_index[i / grid.cols]];
            all += 1;
            if scan.hit.as_ref().unwrap()[i % grid.cols] == Hit::Wall {
                on_wall += 1;
            }
        }
    }
    (on_wall, all)
}

/// A robot pitched towards the wall ahead, about 3 m away, sees the floor in front of the wall's
/// foot in every scan: at 10 cm noise a floor patch grown with an isotropic 3-sigma tolerance
/// (30 cm) runs up the wall; with each ray's own noise along the normal it stays on the floor.
/// Six poses pitched 14 degrees towards a wall about 3 m ahead, the floor in view in all
/// three scans.
fn facing_wall_over_floor(k: u64, noise: f64) -> (Pose, Vec<Scan>) {
    let room = Room::box_room(6.0, 5.0);
    let pose = Pose::new(
        3.2 - 0.1 * k as f64,
        2.5,
        0.45,
        deg(5.0 * k as f64 - 10.0),
        deg(14.0),
        deg(3.0),
    );
    let scans = scans_at(&room, &pose, &elevations(3, 5.0), noise, 40 + k, 0);
    (pose, scans)
}

#[test]
fn floor_patch_stays_off_the_wall_foot_at_10cm() {
    let mut fixed = (0, 0);
    for seed in 0..6 {
        let (_, scans) = facing_wall_over_floor(seed, 0.10);
        let on = wall_points_in_floor_patches(&scans, &LevelParams::default());
        fixed = (fixed.0 + on.0, fixed.1 + on.1);
    }
    assert!(fixed.1 > 200, "floor patches found: {fixed:?}");
    assert!(
        (fixed.0 as f64) < 0.05 * fixed.1 as f64,
        "wall points in floor patches: {fixed:?}"
    );
}

/// The same poses are leveled from the floor at 10 cm noise, within their sigmas and a degree,
/// and 0.2 degrees on average (0.29 with the floor patches grown isotropically).
#[test]
fn robot_facing_a_wall_over_the_floor_is_leveled_at_10cm() {
    let mut sum = 0.0;
    for k in 0..6 {
        let (pose, scans) = facing_wall_over_floor(k, 0.10);
        let e = level_pose(&scans, &LevelParams::default());
        assert!(e.is_ok(), "pose {k}: {:?}", e.failure);
        let (att, sig) = (e.attitude.unwrap(), e.sigmas.unwrap());
        let t = pose.attitude();
        let (dx, dy) = (
            (att.theta_x - t.theta_x).abs(),
            (att.theta_y - t.theta_y).abs(),
        );
        sum += dx.max(dy).to_degrees();
        assert!(
            dx.max(dy).to_degrees() < 1.0,
            "pose {k}: error {dx} {dy} rad"
        );
        assert!(
            dx <= 3.0 * sig[0] && dy <= 3.0 * sig[1],
            "pose {k}: {dx} {dy} vs {sig:?}"
        );
    }
    assert!(sum / 6.0 < 0.2, "mean error {} deg", sum / 6.0);
}

/// The floor seen only near one edge of the scans (office plan, random pose 5 of seed 1, rolled
/// steeply: the floor in the last few dozen rays of each scan) at 10 cm noise: the
/// wide seeds that 10 cm noise calls for do not fit there, and the pose failed as
/// parallel_walls with a single wall in view. The paper's narrow quads seed the floor.
#[test]
fn floor_seen_only_at_the_edge_of_the_scans_seeds_a_floor_patch_at_10cm() {
    use levelscan::formats::read_plan;
    use levelscan::simulate::{
        RandomPoseParams, ScannerParams, Stream, World, elevations_centred, random_poses,
        simulate_pose, stream_rng,
    };
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/plans/office.wall");
    let world = World::from_plan(&read_plan(std::path::Path::new(path)).unwrap());
    let pose_params = RandomPoseParams {
        tilt: deg(20.0),
        clearance: 0.6,
        height: 0.45,
        ..RandomPoseParams::default()
    };
    let pose = random_poses(&world, 6, &pose_params, 1).unwrap()[5];
    let scanner = ScannerParams {
        noise_sigma: 0.10,
        ..ScannerParams::default()
    };
    let mut rng = stream_rng(1 + (3 << 48), Stream::Scans, 5);
    let scans = simulate_pose(
        &world,
        5,
        &pose,
        &elevations_centred(3, deg(5.0)),
        &scanner,
        &mut rng,
    );
    let floors = |p: &LevelParams| {
        let e = level_pose(&scans, p);
        let n = e
            .patches
            .iter()
            .filter(|p| p.kind == SurfaceKind::Floor)
            .count();
        (e, n)
    };
    let (narrow, n) = floors(&LevelParams::default());
    assert!(n >= 1, "no floor patch");
    let (att, sig) = (narrow.attitude.unwrap(), narrow.sigmas.unwrap());
    let t = pose.attitude();
    assert!((att.theta_x - t.theta_x).abs() <= 3.0 * sig[0]);
    assert!((att.theta_y - t.theta_y).abs() <= 3.0 * sig[1]);
}
