//! Unit tests of scene building: placement, layers and decimation on known geometry.

use super::layers::{GREEN_FILL, RED_FILL};
use super::*;
use crate::geometry::Pose;
use nalgebra::Point2;
use serde_json::json;
use std::f64::consts::FRAC_PI_2;

/// The scene of one scan from one source, with default parameters.
fn scene_of(s: Scan) -> Scene {
    build_scene(
        None,
        &[Source {
            name: "a".into(),
            scans: vec![s],
        }],
        &ViewParams::default(),
    )
}

fn scan_with(readings: &[Option<f64>], bearings: &[f64]) -> Scan {
    let mut s = Scan {
        theta: bearings.to_vec(),
        readings: readings.to_vec(),
        valid: readings.iter().map(|r| r.is_some()).collect(),
        ..Scan::default()
    };
    s.sequence = Some(0);
    s
}

fn coords(line: &[Mm]) -> Vec<[Mm; 3]> {
    line.chunks(3).map(|c| [c[0], c[1], c[2]]).collect()
}

#[test]
fn raw_scan_is_placed_with_true_pose_in_millimetres() {
    // Yaw 90 degrees at (1, 2, 0.5): a 1 m reading straight ahead lands at (1, 3, 0.5),
    // one at bearing 0.2 rad (to the left) at (1 - sin 0.2, 2 + cos 0.2, 0.5).
    let mut s = scan_with(&[Some(1.0), Some(1.0)], &[0.0, 0.2]);
    s.elevation = Some(0.0);
    s.true_pose = Some(Pose::new(1.0, 2.0, 0.5, FRAC_PI_2, 0.0, 0.0));
    s.odometry = Some(Pose::planar(9.0, 9.0, 0.0));
    let scene = scene_of(s);
    let layer = scene.layer("scans").unwrap();
    assert_eq!(
        coords(&layer.lines[0]),
        vec![
            [1000, 3000, 500],
            [mm(1.0 - 0.2f64.sin()), mm(2.0 + 0.2f64.cos()), 500]
        ]
    );
    assert!(!scene.top_down);
}

#[test]
fn raw_scan_uses_elevation_downward() {
    // A beam tilted down by 30 degrees, range 2 m, from a level robot at height 1 m:
    // the point is 2 cos 30 ahead and 2 sin 30 = 1 m lower, on the floor.
    let e = 30f64.to_radians();
    let mut s = scan_with(&[Some(2.0), Some(2.0)], &[0.0, 0.0]);
    s.elevation = Some(e);
    s.true_pose = Some(Pose::new(0.0, 0.0, 1.0, 0.0, 0.0, 0.0));
    let scene = scene_of(s);
    let p = coords(&scene.layer("scans").unwrap().lines[0])[0];
    assert_eq!(p, [mm(2.0 * e.cos()), 0, 0]);
}

#[test]
fn invalid_ray_breaks_the_red_line() {
    let mut s = scan_with(
        &[Some(1.0), Some(1.0), None, Some(1.0), Some(1.0), Some(1.0)],
        &[0.0, 0.1, 0.2, 0.3, 0.4, 0.5],
    );
    s.elevation = Some(0.0);
    let scene = scene_of(s);
    let layer = scene.layer("scans").unwrap();
    assert_eq!(layer.lines.len(), 2);
    assert_eq!(layer.point_count(), 5);
    // No true pose, estimate or odometry: drawn at the origin, and the page says so.
    assert!(scene.notes.iter().any(|n| n.contains("origin")));
}

#[test]
fn depth_discontinuity_breaks_the_red_line() {
    // 1 m, 1 m, then 5 m along nearly the same bearing: the jump is not a surface.
    let mut s = scan_with(
        &[Some(1.0), Some(1.0), Some(5.0), Some(5.0)],
        &[0.0, 0.01, 0.02, 0.03],
    );
    s.elevation = Some(0.0);
    let scene = scene_of(s);
    let layer = scene.layer("scans").unwrap();
    assert_eq!(layer.lines.len(), 2);
    assert_eq!(layer.point_count(), 4);
}

#[test]
fn level_record_polygons_follow_raw_pose_of_same_sequence() {
    let raw_pose = Pose::new(2.0, 1.0, 0.45, 0.3, 0.1, -0.05);
    let mut raw = scan_with(&[Some(1.0), Some(1.0)], &[0.0, 0.1]);
    raw.elevation = Some(0.0);
    raw.sequence = Some(7);
    raw.true_pose = Some(raw_pose);
    let mut lev = scan_with(&[Some(1.0), Some(1.0)], &[0.0, 0.1]);
    lev.sequence = Some(7);
    lev.true_pose = Some(Pose::planar(2.0, 1.0, 0.3));
    lev.extra.insert(
        "level".into(),
        json!({"status": "ok", "theta_x": -0.05, "theta_y": 0.1}),
    );
    lev.extra.insert(
        "wall_polygons".into(),
        json!([
            [[1, 0, 0], [1, 1, 0], [1, 1, 1], [1, 0, 1]],
            [[2, 0, 0], [2, 1, 0], [2, 1, 1]]
        ]),
    );
    lev.extra.insert(
        "wall_patches".into(),
        json!([[[1, 0, 0], [1, 2, 0], [1, 2, 1], [1, 0, 1]]]),
    );
    let scene = build_scene(
        None,
        &[
            Source {
                name: "raw".into(),
                scans: vec![raw],
            },
            Source {
                name: "lev".into(),
                scans: vec![lev],
            },
        ],
        &ViewParams::default(),
    );
    let polys = &scene.layer("polygons").unwrap().faces;
    assert_eq!(polys.len(), 2);
    assert_eq!(polys[0].c, GREEN_FILL);
    assert_eq!(polys[1].c, RED_FILL);
    let w = raw_pose
        .world_from_robot()
        .transform_point(&Point3::new(1.0, 1.0, 1.0));
    assert_eq!(&polys[0].p[6..9], &[mm(w.x), mm(w.y), mm(w.z)]);
    // The pseudo-level point at bearing 0 is 1 m along the heading, at the raw pose's height.
    let pseudo = coords(&scene.layer("pseudo").unwrap().lines[0]);
    assert_eq!(
        pseudo[0],
        [mm(2.0 + 0.3f64.cos()), mm(1.0 + 0.3f64.sin()), 450]
    );
    let patches = scene.layer("patches").unwrap();
    assert!(!patches.visible, "patches start hidden");
    let w = raw_pose
        .world_from_robot()
        .transform_point(&Point3::new(1.0, 2.0, 1.0));
    assert_eq!(&patches.faces[0].p[6..9], &[mm(w.x), mm(w.y), mm(w.z)]);
    // One cone: the raw pose's; the level record does not add a second one.
    assert_eq!(scene.layer("poses").unwrap().cones.len(), 1);
}

#[test]
fn level_record_alone_uses_estimated_attitude_and_default_height() {
    let mut lev = scan_with(&[Some(1.0), Some(1.0)], &[0.0, 0.1]);
    lev.true_pose = Some(Pose::planar(0.0, 0.0, 0.0));
    lev.extra.insert(
        "level".into(),
        json!({"status": "ok", "theta_x": 0.0, "theta_y": 0.2}),
    );
    lev.extra.insert(
        "wall_polygons".into(),
        json!([[[1, 0, 0], [1, 1, 0], [1, 1, 1], [1, 0, 1]]]),
    );
    let params = ViewParams::default();
    let scene = build_scene(
        None,
        &[Source {
            name: "lev".into(),
            scans: vec![lev],
        }],
        &params,
    );
    let expect = Pose::new(0.0, 0.0, params.default_height, 0.0, 0.2, 0.0)
        .world_from_robot()
        .transform_point(&Point3::new(1.0, 0.0, 0.0));
    let p = &scene.layer("polygons").unwrap().faces[0].p;
    assert_eq!(&p[0..3], &[mm(expect.x), mm(expect.y), mm(expect.z)]);
    assert_eq!(scene.layer("poses").unwrap().cones.len(), 1);
    // No merged patches in the record: no patch layer.
    assert!(scene.layer("patches").is_none());
}

#[test]
fn matched_2d_log_opens_top_down_at_estimates() {
    let mut a = scan_with(&[Some(1.0), Some(1.0)], &[0.0, 0.1]);
    a.sequence = None;
    a.estimate = Some(Pose::planar(5.0, 0.0, 0.0));
    a.true_pose = Some(Pose::planar(0.0, 0.0, 0.0));
    let mut b = a.clone();
    b.estimate = Some(Pose::planar(6.0, 0.0, 0.0));
    b.true_pose = Some(Pose::planar(1.0, 0.0, 0.0));
    let scene = build_scene(
        None,
        &[Source {
            name: "m".into(),
            scans: vec![a, b],
        }],
        &ViewParams::default(),
    );
    assert!(scene.top_down);
    let m = scene.layer("matched").unwrap();
    assert_eq!(coords(&m.lines[0])[0], [6000, 0, 0]);
    assert_eq!(coords(&m.lines[1])[0], [7000, 0, 0]);
    let cones = &scene.layer("poses").unwrap().cones;
    assert_eq!((cones[0].s, cones[1].s), (0.0, 1.0));
    assert_eq!(
        coords(&scene.layer("reference").unwrap().lines[0]),
        vec![[0, 0, 0], [1000, 0, 0]]
    );
}

#[test]
fn plan_walls_become_rectangles_and_plan_poses_cones() {
    let plan = Plan {
        wall_height: 2.5,
        walls: vec![vec![
            Point2::new(0.0, 0.0),
            Point2::new(4.0, 0.0),
            Point2::new(4.0, 3.0),
        ]],
        ceiling: false,
        poses: vec![Pose::new(1.0, 1.0, 0.4, 0.0, 0.0, 0.0)],
    };
    let scene = build_scene(Some(&plan), &[], &ViewParams::default());
    let walls = &scene.layer("plan").unwrap().faces;
    assert_eq!(walls.len(), 2);
    assert_eq!(
        walls[1].p,
        vec![4000, 0, 0, 4000, 3000, 0, 4000, 3000, 2500, 4000, 0, 2500]
    );
    assert_eq!(scene.layer("poses").unwrap().cones[0].t, [1000, 1000, 400]);
}

#[test]
fn big_input_is_decimated_by_whole_poses() {
    let scans: Vec<Scan> = (0..10)
        .map(|k| {
            let mut s = scan_with(&vec![Some(1.0); 100], &vec![0.0; 100]);
            s.sequence = Some(k);
            s.elevation = Some(0.0);
            s
        })
        .collect();
    let params = ViewParams {
        max_points: 300,
        ..ViewParams::default()
    };
    let scene = build_scene(
        None,
        &[Source {
            name: "big".into(),
            scans,
        }],
        &params,
    );
    // 1000 points over a cap of 300: every 4th pose, i.e. poses 0, 4 and 8.
    assert_eq!(scene.layer("scans").unwrap().point_count(), 300);
    assert_eq!(scene.layer("poses").unwrap().cones.len(), 3);
    assert!(
        scene
            .notes
            .iter()
            .any(|n| n.contains("1 pose in 4 (3 poses)"))
    );
}

#[test]
fn matched_log_names_its_true_pose_a_reference_and_draws_the_robot_path() {
    let scans: Vec<Scan> = (0..3)
        .map(|k| {
            let mut s = scan_with(&[Some(1.0)], &[0.0]);
            s.sequence = None;
            s.estimate = Some(Pose::planar(k as f64, 1.0, 0.0));
            s.true_pose = Some(Pose::planar(k as f64, 0.0, 0.0));
            s
        })
        .collect();
    let scene = build_scene(
        None,
        &[Source {
            name: "m".into(),
            scans,
        }],
        &ViewParams::default(),
    );
    let reference = scene.layer("reference").unwrap();
    assert_eq!(reference.label, "Reference path (true_pose, green)");
    assert!(scene.layers.iter().all(|l| !l.label.contains("True")));
    let path = scene.layer("path").unwrap();
    assert_eq!(path.label, "Robot path (estimate, purple)");
    assert_eq!(
        coords(&path.lines[0]),
        vec![[0, 1000, 0], [1000, 1000, 0], [2000, 1000, 0]]
    );
}

#[test]
fn long_logs_keep_one_cone_in_k_and_the_whole_path() {
    // 251 poses over a cap of 100 cones: every 3rd pose (0, 3, ..., 249) and the last (250).
    let scans: Vec<Scan> = (0..251)
        .map(|k| {
            let mut s = scan_with(&[Some(1.0)], &[0.0]);
            s.sequence = Some(k);
            s.elevation = Some(0.0);
            s.true_pose = Some(Pose::planar(k as f64 * 0.1, 0.0, 0.0));
            s
        })
        .collect();
    let scene = build_scene(
        None,
        &[Source {
            name: "log".into(),
            scans,
        }],
        &ViewParams::default(),
    );
    let cones = &scene.layer("poses").unwrap().cones;
    assert_eq!(cones.len(), 85);
    assert_eq!(cones[1].t[0], 300);
    assert_eq!((cones[84].t[0], cones[84].s), (25_000, 1.0));
    assert!(scene.notes.iter().any(|n| n.contains("1 pose in 3")));
    let path = scene.layer("path").unwrap();
    assert_eq!(path.label, "Robot path (true_pose, purple)");
    assert_eq!(path.point_count(), 251);
}

/// A scan's bearings and ranges, valid everywhere, one degree apart from `first_deg`.
fn scan_deg(first_deg: f64, ranges: &[f64]) -> Scan {
    let bearings: Vec<f64> = (0..ranges.len())
        .map(|i| (first_deg + i as f64).to_radians())
        .collect();
    let readings: Vec<Option<f64>> = ranges.iter().map(|&r| Some(r)).collect();
    let mut s = scan_with(&readings, &bearings);
    s.elevation = Some(0.0);
    s
}

#[test]
fn breakpoint_distance_is_borges_and_aldons() {
    // D = r sin(dphi) / sin(lambda - dphi) + 3 sigma_r, lambda 10 deg, sigma_r 2 cm.
    let (r, dphi) = (5.0, 1f64.to_radians());
    let d = r * dphi.sin() / (10f64.to_radians() - dphi).sin() + 0.06;
    assert!((super::lines::max_joined_distance(r, dphi) - d).abs() < 1e-12);
    assert!((super::lines::max_joined_distance(r, -dphi) - d).abs() < 1e-12);
}

#[test]
fn clutter_at_alternating_depths_is_not_joined_into_a_web() {
    // 3 m and 3.5 m on alternate rays one degree apart: points 0.5 m apart, each on its own
    // surface (a fixed 0.3 m + 15% of the range would join them all).
    let ranges: Vec<f64> = (0..20)
        .map(|i| if i % 2 == 0 { 3.0 } else { 3.5 })
        .collect();
    let scene = scene_of(scan_deg(0.0, &ranges));
    let layer = scene.layer("scans").unwrap();
    assert_eq!(layer.lines.len(), 20);
}

#[test]
fn an_oblique_wall_stays_one_line() {
    // The wall x = 2 seen from the origin at bearings 0 to 70 degrees: range 2 / cos(bearing),
    // up to 5.8 m and points 0.3 m apart at the far end, still one surface.
    let ranges: Vec<f64> = (0..=70)
        .map(|d| 2.0 / f64::from(d).to_radians().cos())
        .collect();
    let scene = scene_of(scan_deg(0.0, &ranges));
    let layer = scene.layer("scans").unwrap();
    assert_eq!(layer.lines.len(), 1);
    assert_eq!(layer.point_count(), 71);
}
