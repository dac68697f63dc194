//! The core as the leveler's last stage ([`super::from_segmentation`]), through the whole
//! pipeline ([`crate::level::level_pose`]).

use crate::eval::bound::{WallPlanes, attitude_bound_cov, pose_rays};
use crate::geometry::Pose;
use crate::level::{LevelEstimate, LevelParams, MlParams, level_pose};
use crate::plan::{Plan, box_plan};
use crate::scan::Scan;
use crate::simulate::{ScannerParams, World, elevations_centred, simulate_pose};
use rand::SeedableRng;
use rand::rngs::ChaCha8Rng;

const DEG: f64 = std::f64::consts::PI / 180.0;
/// The range sigma the leveler is told (noise-free scans still need one to weigh by) \[m\].
const SIGMA: f64 = 0.01;

fn scans(plan: &Plan, truth: &Pose, n: usize, noise: f64) -> Vec<Scan> {
    let world = World::from_plan(plan);
    let scanner = ScannerParams {
        noise_sigma: noise,
        ..ScannerParams::default()
    };
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    simulate_pose(
        &world,
        0,
        truth,
        &elevations_centred(n, 5.0 * DEG),
        &scanner,
        &mut rng,
    )
}

/// The stage on, the rest of its parameters at their defaults.
fn on() -> MlParams {
    MlParams {
        enabled: true,
        ..MlParams::default()
    }
}

fn params(ml: MlParams) -> LevelParams {
    LevelParams {
        sigma: Some(SIGMA),
        ml,
        ..LevelParams::default()
    }
}

fn attitude(est: &LevelEstimate) -> [f64; 2] {
    let a = est.attitude.expect("leveled");
    [a.theta_x, a.theta_y]
}

/// A noise-free box room leveled through the pipeline: the exact attitude (to a thousandth of
/// a sigma, the refinement's stopping rule), and sigmas at the
/// Cramér-Rao bound of all the pose's rays (`eval::bound`, computed apart from world normals);
/// above it only by the points the segmentation leaves out (corners, feet of walls, grazing
/// rays), which carry a few percent of the information (sigmas 5% above the bound here since
/// the feet are judged over a window of bearings, [`super::MlParams::relabel_window`]). (Not yet exact: a pose whose model has
/// no floor, where floor points within the tolerance of a wall's foot stay on the wall, as at
/// 15 degrees of roll here, `(3, 1, -1, 3, 15)`: 1.8e-5 rad off, 0.005 sigma.)
#[test]
fn a_noise_free_room_is_leveled_exactly_with_sigmas_at_the_bound() {
    let plan = box_plan(6.0, 4.0, 2.4, false);
    let world = World::from_plan(&plan);
    let planes = WallPlanes::new(&plan.segments());
    for (x, y, rz, ry, rx) in [(2.0, 1.5, 0.4, 8.0, -5.0), (4.0, 2.5, 2.0, -12.0, 10.0)] {
        let truth = Pose {
            x,
            y,
            z: 0.45,
            rz,
            ry: ry * DEG,
            rx: rx * DEG,
        };
        let seen = scans(&plan, &truth, 4, 0.0);
        let est = level_pose(&seen, &params(on()));
        let a = attitude(&est);
        let rays = pose_rays(&world, &planes, &seen, &truth, 30.0);
        let bound = attitude_bound_cov(&rays, &truth, SIGMA).unwrap();
        // Exact to the refinement's stopping rule: a step below `step_sigmas` (a hundredth)
        // of the sigma is not taken.
        let step = crate::level::MlParams::default().step_sigmas;
        let tolerance = step * bound[(0, 0)].min(bound[(1, 1)]).sqrt();
        assert!((a[0] - truth.rx).abs() < tolerance, "{a:?} vs {truth:?}");
        assert!((a[1] - truth.ry).abs() < tolerance, "{a:?} vs {truth:?}");
        let sig = est.sigmas.unwrap();
        for (s, b) in sig.iter().zip([bound[(0, 0)].sqrt(), bound[(1, 1)].sqrt()]) {
            let ratio = s / b;
            assert!((1.0 - 1e-9..1.06).contains(&ratio), "sigma/bound {ratio}");
        }
    }
}

/// Where the core refuses (here: every estimate tilted beyond `max_tilt_deg`, and a floor or
/// ceiling always within `min_level_clearance` of the scanner), the leveler's own answer stands,
/// bit for bit as with the stage off; where it answers, the answer differs.
#[test]
fn a_pose_the_core_refuses_keeps_the_levelers_answer() {
    let plan = box_plan(6.0, 4.0, 2.4, false);
    let truth = Pose {
        x: 2.0,
        y: 1.5,
        z: 0.45,
        rz: 0.4,
        ry: 8.0 * DEG,
        rx: -5.0 * DEG,
    };
    let seen = scans(&plan, &truth, 4, 0.01);
    let off = level_pose(
        &seen,
        &params(MlParams {
            enabled: false,
            ..on()
        }),
    );
    for refusing in [
        MlParams {
            max_tilt_deg: 1.0,
            ..on()
        },
        MlParams {
            min_level_clearance: 100.0,
            ..on()
        },
    ] {
        let est = level_pose(&seen, &params(refusing));
        assert_eq!(attitude(&est), attitude(&off));
        assert_eq!(est.sigmas, off.sigmas);
        assert_eq!(est.up, off.up);
    }
    let ml = level_pose(&seen, &params(on()));
    assert_ne!(attitude(&ml), attitude(&off));
    let error = |est: &LevelEstimate| {
        let a = attitude(est);
        (a[0] - truth.rx).abs().max((a[1] - truth.ry).abs())
    };
    // Both honest here, the core's sigma the tighter.
    for est in [&ml, &off] {
        let s = est.sigmas.unwrap();
        assert!(error(est) < 3.0 * s[0].max(s[1]));
    }
    assert!(ml.sigmas.unwrap()[0] < off.sigmas.unwrap()[0]);
}

/// A pose every solution of which failed the gate stays failed when the core refuses.
#[test]
fn a_failed_pose_stays_failed_when_the_core_refuses() {
    // A corridor: two parallel walls, no floor in view at this pose's tilt.
    let plan = box_plan(30.0, 2.0, 2.4, false);
    let truth = Pose {
        x: 15.0,
        y: 1.0,
        z: 0.45,
        rz: 0.0,
        ry: -10.0 * DEG,
        rx: 0.0,
    };
    let seen = scans(&plan, &truth, 3, 0.02);
    let off = level_pose(
        &seen,
        &params(MlParams {
            enabled: false,
            ..on()
        }),
    );
    let refused = level_pose(
        &seen,
        &params(MlParams {
            max_tilt_deg: 1.0,
            ..on()
        }),
    );
    assert!(off.failure.is_some());
    assert_eq!(refused.failure, off.failure);
    assert_eq!(refused.attitude.is_none(), off.attitude.is_none());
}

/// At 10 cm of range noise the covariance also takes in the fit without the floor's edges
/// (`level_edges_above`): the stage's answer stays where it was, its sigmas only widen (by
/// `d d^T / 2`, positive semi-definite), and on some poses they do. Where the widened answer
/// fails the gate the leveler's own answer stands.
#[test]
fn above_level_edges_above_the_fit_without_the_floors_edges_widens_the_sigmas() {
    let plan = box_plan(6.0, 4.0, 2.4, false);
    let noisy = |ml: MlParams| LevelParams {
        sigma: Some(0.1),
        ml,
        ..LevelParams::default()
    };
    let without_rival = MlParams {
        level_edges_above: f64::INFINITY,
        ..on()
    };
    let leveler_alone = MlParams {
        enabled: false,
        ..on()
    };
    let mut widened = 0;
    for (i, (x, y, ry, rx)) in [
        (2.0, 1.5, 8.0, -5.0),
        (4.0, 2.5, -12.0, 10.0),
        (3.0, 2.0, 3.0, 6.0),
        (1.5, 3.0, -6.0, -4.0),
        (4.5, 1.0, 10.0, 2.0),
    ]
    .into_iter()
    .enumerate()
    {
        let truth = Pose {
            x,
            y,
            z: 0.45,
            rz: 0.3 * i as f64,
            ry: ry * DEG,
            rx: rx * DEG,
        };
        let seen = scans(&plan, &truth, 4, 0.1);
        let with = level_pose(&seen, &noisy(on()));
        let without = level_pose(&seen, &noisy(without_rival.clone()));
        let (Some(sw), Some(so)) = (with.sigmas, without.sigmas) else {
            continue;
        };
        if with.attitude == without.attitude {
            assert!(sw[0] >= so[0] && sw[1] >= so[1], "{sw:?} < {so:?}");
            widened += usize::from(sw != so);
        } else {
            let alone = level_pose(&seen, &noisy(leveler_alone.clone()));
            assert_eq!(with.attitude, alone.attitude);
            assert_eq!(with.sigmas, alone.sigmas);
        }
    }
    assert!(widened > 0, "no pose widened");
}
