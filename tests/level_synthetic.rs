//! Level estimation on analytic rooms: exact recovery, failure reasons, honesty of sigmas.
#![allow(clippy::needless_range_loop)]

mod common;

use common::{Room, elevations, example_plan, scans_at};
use levelscan::geometry::{Attitude, Pose};
use levelscan::level::{Estimator, FailReason, LevelParams, MlParams, level_pose};
use levelscan::pseudo_level::{PseudoLevelParams, pseudo_level_scan};
use levelscan::scan::Scan;
use levelscan::simulate::{ScannerParams, World, elevations_centred, simulate_pose};
use proptest::prelude::*;
use rand::{RngExt, SeedableRng};

fn deg(a: f64) -> f64 {
    a.to_radians()
}

fn params(estimator: Estimator) -> LevelParams {
    LevelParams {
        estimator,
        ..LevelParams::default()
    }
}

#[test]
fn box_room_without_noise_recovers_known_tilt_within_005_deg() {
    let room = Room::box_room(6.0, 5.0);
    let pose = Pose::new(2.5, 2.0, 0.45, deg(30.0), deg(8.0), deg(-12.0));
    let scans = scans_at(&room, &pose, &elevations(3, 5.0), 0.0, 1, 0);
    for est in [Estimator::Robust, Estimator::Paper] {
        let e = level_pose(&scans, &params(est));
        assert!(e.is_ok(), "{est}: {:?}", e.failure);
        let err = e.attitude.unwrap().max_abs_error(&pose.attitude());
        assert!(
            err.to_degrees() < 0.05,
            "{est}: error {} deg",
            err.to_degrees()
        );
    }
}

/// Pitched without roll, the hinge's sweep leaves the side walls (along the hinge axis) with
/// no vertical extent, and the floor ahead takes the lower scans: the robust estimator levels
/// these poses from the floor's lines, exactly, where the walls alone cannot. (Not every such
/// pose: pitched 8 degrees at heading 0.5 rad this one still fails as parallel_walls with
/// 181 rays, though it levels with 91.)
#[test]
fn box_room_pitched_without_roll_levels_exactly_from_the_floor() {
    let room = Room::polygon(
        &[[0.0, 0.0], [8.0, 0.0], [8.0, 6.0], [0.0, 6.0]],
        2.5,
        false,
    );
    for (pitch, yaw) in [(-8.0, 0.5), (6.0, 2.0), (10.0, -1.0)] {
        let pose = Pose::new(3.0, 2.0, 0.5, yaw, deg(pitch), 0.0);
        let scans = scans_at(&room, &pose, &elevations(3, 5.0), 0.0, 1, 0);
        let e = level_pose(&scans, &params(Estimator::Robust));
        let err = e
            .attitude
            .map(|a| a.max_abs_error(&pose.attitude()).to_degrees());
        assert!(
            err.is_some_and(|d| d < 0.05),
            "pitch {pitch} yaw {yaw}: {:?} {err:?}",
            e.failure
        );
    }
}

#[test]
fn corridor_fails_as_parallel_walls() {
    let room = Room::corridor();
    let pose = Pose::new(0.0, 1.0, 0.45, deg(0.0), deg(3.0), deg(4.0));
    let scans = scans_at(&room, &pose, &elevations(5, 5.0), 0.01, 2, 0);
    // The paper's walls-only estimate; with the floor taken as level, the floor seen between
    // the walls levels the pose (below).
    for est in [Estimator::Robust, Estimator::Paper] {
        let walls_only = LevelParams {
            level_surfaces: false,
            ..params(est)
        };
        let e = level_pose(&scans, &walls_only);
        assert_eq!(e.failure, Some(FailReason::ParallelWalls), "{est}");
        assert!(e.attitude.is_none() && e.sigmas.is_none());
    }
    let e = level_pose(&scans, &LevelParams::default());
    let err = e
        .attitude
        .map(|a| a.max_abs_error(&pose.attitude()).to_degrees());
    assert!(err.is_some_and(|d| d < 0.2), "{:?}: {err:?}", e.failure);
}

#[test]
fn robot_pitched_down_at_the_floor_fails_as_facing_floor() {
    // Big room, walls beyond where the steeply pitched beams meet the floor.
    let room = Room::box_room(60.0, 60.0);
    let pose = Pose::new(30.0, 30.0, 0.45, deg(10.0), deg(35.0), deg(0.0));
    let scans = scans_at(&room, &pose, &elevations(3, 5.0), 0.01, 3, 0);
    // The paper's walls-only estimate; with the floor taken as level it levels (level_floor.rs).
    let walls_only = LevelParams {
        level_surfaces: false,
        ..LevelParams::default()
    };
    let e = level_pose(&scans, &walls_only);
    assert_eq!(e.failure, Some(FailReason::FacingFloor));
}

#[test]
fn two_scans_fail_as_too_few_scans() {
    let room = Room::box_room(6.0, 5.0);
    let pose = Pose::new(2.5, 2.0, 0.45, 0.0, 0.0, 0.0);
    let scans = scans_at(&room, &pose, &elevations(2, 5.0), 0.01, 4, 0);
    assert_eq!(
        level_pose(&scans, &LevelParams::default()).failure,
        Some(FailReason::TooFewScans)
    );
}

#[test]
fn scans_with_different_ray_counts_fail_as_inconsistent() {
    let room = Room::box_room(6.0, 5.0);
    let pose = Pose::new(2.5, 2.0, 0.45, 0.0, 0.0, 0.0);
    let mut scans = scans_at(&room, &pose, &elevations(3, 5.0), 0.01, 4, 0);
    scans[1].theta.pop();
    scans[1].readings.pop();
    scans[1].valid.pop();
    assert_eq!(
        level_pose(&scans, &LevelParams::default()).failure,
        Some(FailReason::InconsistentScans)
    );
}

fn room_l() -> Room {
    Room::polygon(
        &[
            [0.0, 0.0],
            [7.0, 0.0],
            [7.0, 3.0],
            [4.5, 5.5],
            [1.0, 5.5],
            [0.0, 4.0],
        ],
        3.0,
        false,
    )
}

/// Random pose at least 0.8 m from the walls of `room_l`, roll and pitch within +-20 deg.
fn random_pose(rng: &mut rand::rngs::ChaCha8Rng) -> Pose {
    loop {
        let x = rng.random_range(0.8..6.2);
        let y = rng.random_range(0.8..4.7);
        if y > 2.3 + 0.8 && x > 4.5 + (y - 3.0) {
            continue;
        }
        return Pose::new(
            x,
            y,
            0.45,
            rng.random_range(-3.1..3.1),
            deg(rng.random_range(-20.0..20.0)),
            deg(rng.random_range(-20.0..20.0)),
        );
    }
}

#[test]
fn reported_sigmas_are_honest_within_three_sigma_for_95_percent() {
    for &(noise, nscans) in &[(0.01, 3), (0.05, 4), (0.10, 5)] {
        let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(77);
        let (mut ok, mut inside) = (0, 0);
        for k in 0..60 {
            let pose = random_pose(&mut rng);
            let scans = scans_at(
                &room_l(),
                &pose,
                &elevations(nscans, 5.0),
                noise,
                1000 + k,
                k,
            );
            // No sigma gate: the point is whether the sigmas are honest, wherever they are.
            let params = LevelParams {
                max_sigma_deg: 1000.0,
                ..LevelParams::default()
            };
            let e = level_pose(&scans, &params);
            let (Some(att), Some(s)) = (e.attitude, e.sigmas) else {
                continue;
            };
            ok += 1;
            let truth = pose.attitude();
            if (att.theta_x - truth.theta_x).abs() <= 3.0 * s[0]
                && (att.theta_y - truth.theta_y).abs() <= 3.0 * s[1]
            {
                inside += 1;
            }
        }
        assert!(ok >= 20, "noise {noise}: only {ok} of 60 leveled");
        assert!(
            inside as f64 >= 0.95 * ok as f64,
            "noise {noise}: {inside} of {ok} within 3 sigma"
        );
    }
}

/// No leveled pose claims more precision than the Cramér-Rao bound allows (the bound knows
/// which surface every ray met; a leveler must also find that out), beyond the slack of a
/// noise level estimated from the data: reported sigmas below the bound are overconfident.
/// The maximum-likelihood stage reports the bound itself, at its own estimate and with the
/// noise level it estimated, which scatters by a few percent about the bound at the truth
/// (at 5 cm: 0.94-0.99 of it on the 6 of 251 poses below it): "below" means below
/// `AT_BOUND` of it.
#[test]
fn reported_sigmas_respect_the_cramer_rao_bound() {
    const AT_BOUND: f64 = 0.9;
    use levelscan::eval::bound::{WallPlanes, attitude_bound, pose_rays};
    use levelscan::simulate::{RandomPoseParams, random_poses};
    let (mut leveled, mut below) = (0, 0);
    for name in ["office", "two_rooms"] {
        let plan = example_plan(name);
        let world = World::from_plan(&plan);
        let planes = WallPlanes::new(&plan.segments());
        let pose_params = RandomPoseParams {
            tilt: deg(20.0),
            clearance: 0.6,
            height: 0.45,
            ..RandomPoseParams::default()
        };
        let poses = random_poses(&world, 60, &pose_params, 7).unwrap();
        for &(nscans, noise) in &[(3, 0.05), (3, 0.10), (5, 0.10)] {
            let scanner = ScannerParams {
                noise_sigma: noise,
                ..ScannerParams::default()
            };
            for (k, pose) in poses.iter().enumerate() {
                let scans = library_scans(&world, pose, nscans, &scanner, 500 + k as u64);
                let Some(sigma) = level_pose(&scans, &LevelParams::default()).sigmas else {
                    continue;
                };
                let rays = pose_rays(&world, &planes, &scans, pose, scanner.max_range);
                let bound = attitude_bound(&rays, pose, noise).unwrap_or([f64::INFINITY; 2]);
                leveled += 1;
                for a in 0..2 {
                    assert!(
                        sigma[a] >= 0.6 * bound[a],
                        "{name}, {nscans} scans, {noise} m, pose {k}: sigma {} deg, bound {} deg",
                        sigma[a].to_degrees(),
                        bound[a].to_degrees()
                    );
                }
                if sigma[0] < AT_BOUND * bound[0] || sigma[1] < AT_BOUND * bound[1] {
                    below += 1;
                }
            }
        }
    }
    assert!(leveled >= 150, "only {leveled} poses leveled");
    assert!(
        below * 50 <= leveled,
        "{below} of {leveled} poses claim sigmas below the bound"
    );
}

/// A robot tilted by 4 and 5 degrees in a 6 x 5 m box room, and its five scans at 1 cm
/// (sequence 7).
fn tilted_in_a_box() -> (Pose, Vec<Scan>) {
    let room = Room::box_room(6.0, 5.0);
    let pose = Pose::new(2.0, 2.5, 0.45, deg(20.0), deg(4.0), deg(5.0));
    let scans = scans_at(&room, &pose, &elevations(5, 5.0), 0.01, 9, 7);
    (pose, scans)
}

/// The estimate's shared bearing sines and cosines give the pseudo-level scan, to the bit,
/// that one sincos per ray gives.
#[test]
fn pseudo_level_scan_is_the_same_with_the_shared_bearing_trig() {
    let (_, scans) = tilted_in_a_box();
    let shared = level_pose(&scans, &LevelParams::default());
    assert!(shared.bearing_trig.is_some());
    let own = levelscan::level::LevelEstimate {
        bearing_trig: None,
        ..shared.clone()
    };
    let bits = |s: &Scan| -> Vec<u64> {
        let readings = s.readings.iter().map(|r| r.map_or(u64::MAX, f64::to_bits));
        s.theta
            .iter()
            .map(|t| t.to_bits())
            .chain(readings)
            .collect()
    };
    let params = PseudoLevelParams::default();
    let (a, b) = (
        pseudo_level_scan(&scans, &shared, &params),
        pseudo_level_scan(&scans, &own, &params),
    );
    assert_eq!(bits(&a), bits(&b));
    assert_eq!(a, b);
}

#[test]
fn pseudo_level_scan_keeps_walls_and_drops_floor_hits() {
    let (pose, scans) = tilted_in_a_box();
    let e = level_pose(&scans, &LevelParams::default());
    assert!(
        e.is_ok(),
        "{:?} walls {} patches {}",
        e.failure,
        e.wall_polygons(),
        e.patches.len()
    );
    let out = pseudo_level_scan(&scans, &e, &PseudoLevelParams::default());
    let base =
        &scans[levelscan::pseudo_level::base_scan_index(&scans, &e, &PseudoLevelParams::default())];
    assert_eq!(out.nrays(), base.nrays());
    assert_eq!(out.sequence, Some(7));
    assert!(out.true_pose.unwrap().is_planar());
    let hits = base.hit.as_ref().unwrap();
    let mut walls = 0;
    for i in 0..out.nrays() {
        assert_eq!(out.valid[i], out.readings[i].is_some());
        if out.valid[i] {
            assert_eq!(
                hits[i],
                levelscan::scan::Hit::Wall,
                "ray {i} kept but not a wall"
            );
            // The leveled point lies on the box's walls, seen from the true planar pose.
            let r = out.readings[i].unwrap();
            let (s, c) = (pose.rz + out.theta[i]).sin_cos();
            let (x, y) = (pose.x + r * c, pose.y + r * s);
            let d = x.min(6.0 - x).abs().min(y.abs()).min((5.0 - y).abs());
            assert!(d < 0.15, "ray {i} at ({x}, {y}) is {d} m off every wall");
        }
        if hits[i] == levelscan::scan::Hit::Wall {
            walls += 1;
        }
    }
    let kept = out.valid.iter().filter(|&&v| v).count();
    assert!(
        kept as f64 >= 0.9 * walls as f64,
        "kept {kept} of {walls} wall hits"
    );
}

proptest! {
    // A fixed seed: about one random pose in 1500 still fools the wall extraction (a plane
    // through a wall's scan lines and the floor in front of it, next to two parallel walls),
    // and CI must not fail by lot. The case is a known weakness, not a passing property.
    #![proptest_config(ProptestConfig {
        cases: 24,
        rng_seed: proptest::test_runner::RngSeed::Fixed(20081122),
        ..ProptestConfig::default()
    })]
    #[test]
    fn attitude_recovered_over_random_poses(seed in 0u64..10_000) {
        let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(seed);
        let pose = random_pose(&mut rng);
        let scans = scans_at(&room_l(), &pose, &elevations(4, 5.0), 0.01, seed, 0);
        let e = level_pose(&scans, &LevelParams::default());
        if let Some(att) = e.attitude {
            // Within five of its own sigmas (honest), and never far off.
            let s = e.sigmas.unwrap();
            let truth = pose.attitude();
            prop_assert!((att.theta_x - truth.theta_x).abs() <= 5.0 * s[0] + 1e-4, "{:?} {:?}", att, pose);
            prop_assert!((att.theta_y - truth.theta_y).abs() <= 5.0 * s[1] + 1e-4, "{:?} {:?}", att, pose);
            prop_assert!(att.max_abs_error(&truth).to_degrees() < 5.0);
        } else {
            // Failing is allowed only with a reason that says the view is poor.
            prop_assert!(e.failure.is_some());
        }
    }
}

#[test]
fn attitude_from_up_matches_truth_sign_conventions() {
    let a = Attitude::new(deg(10.0), deg(-5.0));
    let back = Attitude::from_up(&a.up_in_robot());
    assert!((back.theta_x - a.theta_x).abs() < 1e-12);
}

/// A 7 m x 5 m room with a ceiling and a 0.4 m box 2.3 m ahead of a robot pitched towards the
/// floor: the lowest scan meets the floor at the box's foot, at nearly the box's range, and the
/// box is the only thing that pins the pitch (the side walls are parallel).
fn room_with_a_box_at_the_floor_line() -> (Room, Pose) {
    let room = Room::polygon(&[[0.0, 0.0], [7.0, 0.0], [7.0, 5.0], [0.0, 5.0]], 2.4, true)
        .with_box([3.3, 2.3], [3.7, 2.7]);
    let pose = Pose::new(1.0, 1.0, 0.45, deg(-2.717), deg(6.732), 0.0);
    (room, pose)
}

#[test]
fn a_wall_line_with_a_floor_line_at_its_foot_never_levels_a_pose_wrongly() {
    let (room, pose) = room_with_a_box_at_the_floor_line();
    let unguarded = LevelParams {
        max_misfit_sigmas: 0.0,
        min_stacked_share: 0.0,
        max_row_bend_sigmas: 0.0,
        ..LevelParams::default()
    };
    let (mut wrong_unguarded, mut wrong) = (0, 0);
    for seed in 0..20 {
        let scans = scans_at(&room, &pose, &elevations(3, 5.0), 0.01, seed, 0);
        let off = |p: &LevelParams| {
            level_pose(&scans, p)
                .attitude
                .is_some_and(|a| a.max_abs_error(&pose.attitude()).to_degrees() > 2.0)
        };
        wrong_unguarded += usize::from(off(&unguarded));
        wrong += usize::from(off(&LevelParams::default()));
    }
    // The case is real: without the guards some of these poses are leveled degrees off.
    assert!(
        wrong_unguarded > 0,
        "the scene no longer fools the extraction"
    );
    assert_eq!(wrong, 0);
}

/// An example plan for the library's own simulator.
fn example_world(name: &str) -> World {
    World::from_plan(&example_plan(name))
}

/// The library simulator's scans of `pose` at `scans` elevations 5 degrees apart, centred on
/// level, with the noise stream `seed`.
fn library_scans(
    world: &World,
    pose: &Pose,
    scans: usize,
    scanner: &ScannerParams,
    seed: u64,
) -> Vec<Scan> {
    let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(seed);
    simulate_pose(
        world,
        0,
        pose,
        &elevations_centred(scans, deg(5.0)),
        scanner,
        &mut rng,
    )
}

/// The office example's walls (examples/plans/office.wall), in the twin ray caster.
fn office_room() -> Room {
    let mut room = Room::polygon(
        &[[0.0, 0.0], [10.0, 0.0], [10.0, 8.0], [0.0, 8.0]],
        3.0,
        false,
    )
    .with_box([4.6, 4.4], [5.0, 4.8])
    .with_box([5.0, 1.8], [5.4, 2.2]);
    room.segments.extend([
        ([3.0, 0.0], [3.0, 3.0]),
        ([0.0, 5.2], [2.4, 5.2]),
        ([7.0, 8.0], [7.0, 5.5]),
        ([6.2, 2.6], [8.6, 2.6]),
    ]);
    room
}

/// Rolled 19.6 degrees with its scans tilted down (elevations 0, 5 and 10 degrees), a robot
/// sees the wall ahead-right only in its two upper scans, in different columns, and the floor
/// below both in the third. Taken as one stacked "wall" (every column had two rows), that
/// plane tilted 22 degrees decided the attitude against the one other wall: in the simulator
/// 6 of 30 noise seeds were leveled 12-21 degrees off with sigmas near 1 degree, and here
/// seed 1 was 20.4 degrees off. Only rows next to each other now stack.
#[test]
fn two_wall_lines_over_a_floor_line_never_level_a_pose_wrongly() {
    let room = office_room();
    let pose = Pose::new(5.638, 6.050, 0.45, 1.1520, -0.06199, 0.34266);
    let down: Vec<f64> = [0.0, 5.0, 10.0].iter().map(|&e| deg(e)).collect();
    let mut leveled = 0;
    for seed in 0..30 {
        let scans = scans_at(&room, &pose, &down, 0.01, seed, 0);
        let est = level_pose(&scans, &LevelParams::default());
        if let Some(a) = est.attitude {
            leveled += 1;
            let err = a.max_abs_error(&pose.attitude()).to_degrees();
            assert!(err < 5.0, "seed {seed}: leveled {err:.1} deg off");
        }
    }
    // The scene still levels sometimes: the test is not passed by failing every pose.
    assert!(leveled > 0);
}

/// A robot near a wall of the ceiling example, with a hinge offset (0.05, 0.02, 0.08) m and
/// four scans at 2 cm noise: the lowest scan meets the floor within centimetres of the far
/// wall's foot, and the wall's patch took that floor line in, tilted by about 18 degrees. Fitted
/// with the line, the plane absorbs most of its offset; the other rows' plane shows it plainly,
/// and the line goes.
#[test]
fn the_floor_line_at_a_walls_foot_is_trimmed_from_the_wall() {
    let world = example_world("ceiling");
    let pose = Pose::new(4.803, 0.7095, 0.45, -0.32333, 0.09450, -0.08848);
    let scanner = ScannerParams {
        noise_sigma: 0.02,
        hinge_offset: Some([0.05, 0.02, 0.08]),
        ..ScannerParams::default()
    };
    // Either test takes the line out: the edge row's, or the one of runs at the rows' ends.
    // The control leaves out the last stage too: its fit of the same segmentation leaves such
    // a wrong answer, and the pose then fails as `last_stage_disagrees`, a second guard.
    let untrimmed = LevelParams {
        trim_sigmas: 0.0,
        front_end_sigmas: 0.0,
        ml: MlParams {
            enabled: false,
            ..MlParams::default()
        },
        ..LevelParams::default()
    };
    let untrimmed_with_last_stage = LevelParams {
        ml: MlParams::default(),
        ..untrimmed.clone()
    };
    let (mut wrong, mut wrong_untrimmed, mut leveled) = (0, 0, 0);
    for seed in 0..30 {
        let scans = library_scans(&world, &pose, 4, &scanner, seed);
        let off = |p: &LevelParams| {
            level_pose(&scans, p)
                .attitude
                .map(|a| a.max_abs_error(&pose.attitude()).to_degrees() > 5.0)
        };
        wrong_untrimmed += usize::from(off(&untrimmed) == Some(true));
        // The second guard alone: the last stage's refusal fails the wrong reading.
        assert_ne!(off(&untrimmed_with_last_stage), Some(true), "seed {seed}");
        match off(&LevelParams::default()) {
            Some(true) => wrong += 1,
            Some(false) => leveled += 1,
            None => {}
        }
    }
    assert!(
        wrong_untrimmed > 0,
        "the scene no longer fools the extraction"
    );
    assert_eq!(wrong, 0);
    assert!(leveled >= 10, "only {leveled} of 30 leveled");
}

/// A robot in the two-room example's doorway region, hinge offset (0.1, 0, 0.1) m, three
/// scans: its walls alone cannot fix up (the first solution fails), and re-segmentation
/// started from them, 13-16 degrees off with sigmas of 9-23 degrees, settled on a wall ahead
/// that had taken in floor points and reported the pose 7 degrees off with sigmas near one
/// degree. Re-segmentation now starts only from starts within 11.5 degrees (one sigma), and
/// only within 2.9 degrees from floor lines found without a level frame.
#[test]
fn a_loose_start_does_not_settle_on_wrong_planes() {
    let world = example_world("two_rooms");
    let pose = Pose::new(1.1253, 1.1178, 0.45, 1.47801, 0.071695, -0.009343);
    for noise in [0.02, 0.03] {
        let scanner = ScannerParams {
            noise_sigma: noise,
            hinge_offset: Some([0.1, 0.0, 0.1]),
            ..ScannerParams::default()
        };
        for seed in 0..30 {
            let scans = library_scans(&world, &pose, 3, &scanner, seed);
            if let Some(a) = level_pose(&scans, &LevelParams::default()).attitude {
                let err = a.max_abs_error(&pose.attitude()).to_degrees();
                assert!(
                    err < 5.0,
                    "{noise} m, seed {seed}: leveled {err:.1} deg off"
                );
            }
        }
    }
}

/// Pitched 18 degrees in the angled example with five scans at 1 cm: a wall line and the
/// floor line at its foot, coplanar, with the true wall's row on top and a few stray points
/// below. The edge-row trim took the true wall's row for the odd one out, and the rest,
/// passing for a wall over four rows, leveled the pose 28 degrees off. A trimmed patch must
/// keep three adjacent rows that each hold a fair share of its points.
#[test]
fn the_edge_row_trim_never_keeps_a_wall_line_over_its_floor_line() {
    let world = example_world("angled");
    let pose = Pose::new(6.4854, 1.2815, 0.45, -1.043983, 0.313965, 0.164457);
    let mut leveled = 0;
    for seed in 0..40 {
        let scans = library_scans(&world, &pose, 5, &ScannerParams::default(), seed);
        if let Some(a) = level_pose(&scans, &LevelParams::default()).attitude {
            leveled += 1;
            let err = a.max_abs_error(&pose.attitude()).to_degrees();
            assert!(err < 5.0, "seed {seed}: leveled {err:.1} deg off");
        }
    }
    assert!(leveled >= 35, "only {leveled} of 40 leveled");
}
