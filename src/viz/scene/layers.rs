//! One function per viewer layer, each drawing its layer from the placed records.

use super::lines::scan_polylines;
use super::place::{Kind, Placed};
use super::{Cone, Face, Layer, Mm, mm, push_mm};
use crate::geometry::Pose;
use crate::plan::Plan;
use crate::scan::Scan;
use nalgebra::Point3;

const RED: [u8; 3] = [210, 30, 30];
const BLUE: [u8; 3] = [20, 70, 220];
pub(super) const GREEN_FILL: [u8; 3] = [30, 170, 60];
pub(super) const RED_FILL: [u8; 3] = [220, 40, 40];
const WALL_FILL: [u8; 3] = [40, 40, 48];
const PATCH_FILL: [u8; 3] = [240, 150, 20];

fn of_kind<'g, 'a>(
    groups: &'g [&'g Placed<'a>],
    kind: Kind,
) -> impl Iterator<Item = &'g Placed<'a>> + 'g {
    groups.iter().copied().filter(move |g| g.kind == kind)
}

/// The floor plan's walls as dark translucent rectangles from the floor to the wall height.
pub(super) fn plan_walls(plan: Option<&Plan>) -> Layer {
    let mut layer = Layer::new("plan", "Floor plan walls", WALL_FILL, 1.0);
    let Some(plan) = plan else {
        return layer;
    };
    let h = mm(plan.wall_height);
    for seg in plan.segments() {
        let (ax, ay, bx, by) = (mm(seg.a.x), mm(seg.a.y), mm(seg.b.x), mm(seg.b.y));
        layer.faces.push(Face {
            p: vec![ax, ay, 0, bx, by, 0, bx, by, h, ax, ay, h],
            c: WALL_FILL,
            a: 0.22,
        });
    }
    layer
}

/// Raw multi-elevation scans in red, each ray at its hinge elevation from the robot's pose.
pub(super) fn raw_scans(groups: &[&Placed]) -> Layer {
    let mut layer = Layer::new("scans", "Scans (red)", RED, 1.0);
    for g in of_kind(groups, Kind::Raw) {
        let world_from_robot = g.pose.world_from_robot();
        for scan in &g.scans {
            layer.lines.extend(scan_polylines(scan, |i| {
                scan.point_in_robot(i)
                    .map(|p| world_from_robot.transform_point(&p))
            }));
        }
    }
    layer
}

/// Robot-frame corner lists under `key` of a `level` record (`wall_polygons`, `wall_patches`).
fn robot_polygons(scan: &Scan, key: &str) -> Vec<Vec<Point3<f64>>> {
    let Some(list) = scan.extra.get(key).and_then(|v| v.as_array()) else {
        return Vec::new();
    };
    list.iter()
        .filter_map(|poly| {
            let corners: Option<Vec<Point3<f64>>> = poly
                .as_array()?
                .iter()
                .map(|c| {
                    let c = c.as_array()?;
                    match c.as_slice() {
                        [x, y, z] => Some(Point3::new(x.as_f64()?, y.as_f64()?, z.as_f64()?)),
                        _ => None,
                    }
                })
                .collect();
            corners.filter(|c| c.len() >= 3)
        })
        .collect()
}

/// Each level record's `key` polygons, placed with the robot's pose, as `(world corners, k)`.
fn world_polygons<'g>(
    groups: &'g [&'g Placed],
    key: &'g str,
) -> impl Iterator<Item = (Vec<Mm>, usize)> + 'g {
    of_kind(groups, Kind::Leveled).flat_map(move |g| {
        let world_from_robot = g.pose.world_from_robot();
        robot_polygons(g.scans[0], key)
            .into_iter()
            .enumerate()
            .map(move |(k, poly)| {
                let mut p = Vec::with_capacity(poly.len() * 3);
                for c in &poly {
                    push_mm(&mut p, &world_from_robot.transform_point(c));
                }
                (p, k)
            })
    })
}

/// The wall polygons (`level --polygons`' quads), alternating translucent green and red.
pub(super) fn wall_polygons(groups: &[&Placed]) -> Layer {
    let mut layer = Layer::new("polygons", "Wall polygons (green/red)", RED_FILL, 1.0);
    layer.faces = world_polygons(groups, "wall_polygons")
        .map(|(p, k)| Face {
            p,
            c: if k % 2 == 0 { GREEN_FILL } else { RED_FILL },
            a: 0.35,
        })
        .collect();
    layer
}

/// Merged wall patches (`level --polygons` writes them as `wall_patches`); off at first, as
/// they cover the quads they were grown from.
pub(super) fn wall_patches(groups: &[&Placed]) -> Layer {
    let mut layer = Layer::new("patches", "Merged wall patches (orange)", PATCH_FILL, 1.0);
    layer.visible = false;
    layer.faces = world_polygons(groups, "wall_patches")
        .map(|(p, _)| Face {
            p,
            c: PATCH_FILL,
            a: 0.3,
        })
        .collect();
    layer
}

/// A 2D scan's points, `(r cos theta, r sin theta, 0)` in its own frame, placed by `frame`.
fn planar_polylines(scan: &Scan, frame: &Pose) -> Vec<Vec<Mm>> {
    let world_from_scan = frame.world_from_robot();
    scan_polylines(scan, |i| {
        let r = scan.range(i)?;
        let (s, c) = scan.theta[i].sin_cos();
        Some(world_from_scan.transform_point(&Point3::new(r * c, r * s, 0.0)))
    })
}

/// Pseudo-level scans in blue: in the level frame, so only heading and position apply.
pub(super) fn pseudo_level_scans(groups: &[&Placed]) -> Layer {
    let mut layer = Layer::new("pseudo", "Pseudo-level scans (blue)", BLUE, 1.6);
    for g in of_kind(groups, Kind::Leveled) {
        let p = g.pose;
        let world_from_level = Pose::new(p.x, p.y, p.z, p.rz, 0.0, 0.0);
        layer
            .lines
            .extend(planar_polylines(g.scans[0], &world_from_level));
    }
    layer
}

/// Matched 2D scans in blue, at their estimates.
pub(super) fn matched_scans(groups: &[&Placed]) -> Layer {
    let mut layer = Layer::new("matched", "Matched 2D scans (blue)", BLUE, 1.0);
    for g in of_kind(groups, Kind::Matched) {
        layer.lines.extend(planar_polylines(g.scans[0], &g.pose));
    }
    layer
}

/// The matched records' `true_pose` positions joined in time order, one line per source. It is
/// called a reference, not the truth: a log's `true_pose` is often a SLAM-corrected path.
pub(super) fn reference_path(groups: &[Placed]) -> Layer {
    let mut layer = Layer::new(
        "reference",
        "Reference path (true_pose, green)",
        [0, 140, 60],
        2.0,
    );
    let points = groups
        .iter()
        .filter(|g| g.kind == Kind::Matched)
        .filter_map(|g| {
            let t = g.scans[0].true_pose?;
            Some((g.source, Point3::new(t.x, t.y, 0.0)))
        });
    layer.lines = lines_per_source(points);
    layer
}

/// Where the robot was at every pose (decimated or not), joined in time order, one line per
/// source: the poses the scans are drawn from.
pub(super) fn robot_path(groups: &[Placed]) -> Layer {
    let path: Vec<&Placed> = groups.iter().filter(|g| g.cone).collect();
    let mut fields: Vec<&str> = path.iter().filter_map(|g| g.pose_from).collect();
    fields.dedup();
    let label = match fields.as_slice() {
        [field] => format!("Robot path ({field}, purple)"),
        _ => "Robot path (purple)".to_string(),
    };
    let mut layer = Layer::new("path", &label, [120, 60, 170], 1.5);
    let points = path
        .iter()
        .map(|g| (g.source, Point3::new(g.pose.x, g.pose.y, g.pose.z)));
    layer.lines = lines_per_source(points);
    layer
}

/// Polylines of `(source, point)` in order, a new line at each change of source; lines of one
/// point are left out (a path needs two).
fn lines_per_source(points: impl Iterator<Item = (usize, Point3<f64>)>) -> Vec<Vec<Mm>> {
    let mut lines: Vec<(usize, Vec<Mm>)> = Vec::new();
    for (source, p) in points {
        match lines.last_mut() {
            Some((s, line)) if *s == source => push_mm(line, &p),
            _ => {
                let mut line = Vec::new();
                push_mm(&mut line, &p);
                lines.push((source, line));
            }
        }
    }
    lines
        .into_iter()
        .map(|(_, l)| l)
        .filter(|l| l.len() >= 6)
        .collect()
}

fn cone(pose: &Pose, index: usize, count: usize) -> Cone {
    let s = if count > 1 {
        index as f32 / (count - 1) as f32
    } else {
        0.5
    };
    let r4 = |a: f64| ((a * 1e4).round() / 1e4) as f32;
    Cone {
        t: [mm(pose.x), mm(pose.y), mm(pose.z)],
        r: [r4(pose.rz), r4(pose.ry), r4(pose.rx)],
        s,
    }
}

/// The robot's poses as cones shaded light to dark in time order; the plan's poses when no
/// record gives one. Beyond `max_cones`, one pose in k keeps its cone (the first and the last
/// always), and `notes` says so: 900 cones hide the map they sit on.
pub(super) fn pose_cones(
    groups: &[&Placed],
    plan: Option<&Plan>,
    max_cones: usize,
    notes: &mut Vec<String>,
) -> Layer {
    let mut layer = Layer::new("poses", "Robot poses (light to dark)", [0, 0, 0], 1.0);
    let mut poses: Vec<Pose> = groups.iter().filter(|g| g.cone).map(|g| g.pose).collect();
    if poses.is_empty()
        && let Some(plan) = plan
    {
        poses.extend(plan.poses.iter().copied());
    }
    let n = poses.len();
    // One slot is kept for the last pose, so that at most `max_cones` are drawn.
    let stride = if n > max_cones {
        n.div_ceil(max_cones.saturating_sub(1).max(1))
    } else {
        1
    };
    if stride > 1 {
        notes.push(format!(
            "{n} poses: a cone at 1 pose in {stride} (--max-cones {max_cones}); the robot path joins them all."
        ));
    }
    layer.cones = poses
        .iter()
        .enumerate()
        .filter(|&(i, _)| i % stride == 0 || i + 1 == n)
        .map(|(i, p)| cone(p, i, n))
        .collect();
    layer
}

/// Flat 2D logs (CSM, matched scans) open in the top-down mode made for them: nothing 3D (a
/// tilted raw pose, a scan at a hinge elevation, polygons, pseudo-level scans) and something 2D.
pub(super) fn is_top_down(groups: &[&Placed], layers: &[Layer]) -> bool {
    let raw_3d = of_kind(groups, Kind::Raw).any(|g| {
        !g.pose.is_planar()
            || g.scans
                .iter()
                .any(|s| s.elevation.is_some_and(|e| e != 0.0))
    });
    let non_empty = |id: &str| layers.iter().any(|l| l.id == id && !l.is_empty());
    let has_3d = raw_3d || non_empty("polygons") || non_empty("pseudo");
    let has_2d = non_empty("matched") || non_empty("scans");
    !has_3d && has_2d
}
