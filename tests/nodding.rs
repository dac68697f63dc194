//! A hinge that moves while it scans (`Scan::ray_elevation`): every place that turns a reading
//! into a 3D point takes each ray's own elevation.

mod common;

use common::{Room, elevations, scans_at};
use levelscan::geometry::{Pose, reading_in_robot};
use levelscan::level::grid::PoseGrid;
use levelscan::level::{LevelParams, level_pose};
use levelscan::pseudo_level::{PseudoLevelParams, pseudo_level_scan};
use levelscan::scan::Scan;
use nalgebra::Vector3;

fn tilted_pose() -> Pose {
    Pose::new(0.3, -0.2, 0.4, 0.2, 2f64.to_radians(), -1.5f64.to_radians())
}

/// A constant `ray_elevation` equal to the scan's elevation gives the same estimate and the
/// same pseudo-level scan, to the bit.
#[test]
fn constant_ray_elevation_equals_the_scan_elevation() {
    let room = Room::box_room(6.0, 4.0);
    let scans = scans_at(&room, &tilted_pose(), &elevations(3, 5.0), 0.01, 7, 0);
    let mut per_ray = scans.clone();
    for s in &mut per_ray {
        s.ray_elevation = Some(vec![s.elevation.unwrap(); s.nrays()]);
    }
    let params = LevelParams::default();
    let (a, b) = (level_pose(&scans, &params), level_pose(&per_ray, &params));
    assert!(a.is_ok());
    assert_eq!(a.attitude, b.attitude);
    assert_eq!(a.sigmas, b.sigmas);
    let pl = PseudoLevelParams::default();
    assert_eq!(
        pseudo_level_scan(&scans, &a, &pl),
        pseudo_level_scan(&per_ray, &b, &pl)
    );
}

/// A moving hinge: each grid point lies at `Ry(e_i) (o + r (cos phi, sin phi, 0))` with the
/// ray's own `e_i`, while the row keeps the scan's nominal elevation.
#[test]
fn moving_hinge_points_take_their_own_elevation() {
    let mut scans: Vec<Scan> = (0..3)
        .map(|k| {
            let mut s = Scan::with_even_bearings(5, -1.0, 1.0);
            let e = (k as f64 - 1.0) * 0.1;
            s.elevation = Some(e);
            s.ray_elevation = Some((0..5).map(|i| e + 0.01 * (i as f64 - 2.0)).collect());
            s.hinge_offset = Some([0.05, 0.0, 0.1]);
            s.readings = (0..5).map(|i| Some(1.0 + i as f64)).collect();
            s.valid = vec![true; 5];
            s
        })
        .collect();
    let grid = PoseGrid::from_scans(&scans).unwrap();
    assert_eq!(grid.elevation, vec![-0.1, 0.0, 0.1]);
    let o = Vector3::new(0.05, 0.0, 0.1);
    for (row, s) in scans.iter().enumerate() {
        for i in 0..5 {
            let e = s.elevation.unwrap() + 0.01 * (i as f64 - 2.0);
            let want = reading_in_robot(e, s.theta[i], 1.0 + i as f64, &o);
            let g = grid.at(row, i).unwrap();
            assert!((g.p - want).norm() < 1e-12, "row {row} ray {i}");
            assert!((s.point_in_robot(i).unwrap() - want).norm() < 1e-12);
            let dir = (want - reading_in_robot(e, s.theta[i], 0.0, &o)) / g.range;
            assert!((g.dir - dir).norm() < 1e-12);
        }
    }
    // Dropping the per-ray elevations moves the off-centre rays: the test sees the difference.
    scans[0].ray_elevation = None;
    let nominal = PoseGrid::from_scans(&scans).unwrap();
    assert!((nominal.at(0, 0).unwrap().p - grid.at(0, 0).unwrap().p).norm() > 1e-3);
    assert_eq!(nominal.at(0, 2).unwrap().p, grid.at(0, 2).unwrap().p);
}
