//! The self-contained 3D viewer page: the paper's visualizer (sect. 7.2.3, Fig. 5), as one
//! offline HTML file with hand-written JavaScript (`viewer.js`, canvas 2D with its own projection).
//!
//! Building a [`Scene`] is pure: scans, level output and a floor plan go in, world-frame geometry
//! in layers comes out. The layers follow Fig. 5: multi-elevation scans as red lines joining
//! consecutive points, extracted wall polygons in alternating translucent green and red,
//! pseudo-level (and matched level) scans in blue, floor-plan walls as dark translucent
//! rectangles, and robot poses as flattened cones shaded from light to dark in time order.
//!
//! Which records are what is read from the records themselves:
//! - a record with a `level` object is `levelscan level` output: its scan is a pseudo-level scan in
//!   the level frame (heading kept, z dropped), its `wall_polygons` (with `--polygons`) are
//!   robot-frame quads;
//! - a record with a `match` object, or a 2D record (no `elevation`) with an `estimate`, is a
//!   matched 2D scan, placed at its `estimate` (the top-down mode is made for these);
//! - any other record is a raw scan, placed at `true_pose`, else `estimate`, else `odometry`,
//!   else the origin, and drawn in 3D with its hinge elevation and offset.

use crate::geometry::{Attitude, Pose};
use crate::plan::Plan;
use crate::scan::Scan;
use nalgebra::Point3;
use serde::Serialize;
use std::collections::HashMap;

/// The viewer's JavaScript, embedded so that pages work offline.
pub const VIEWER_JS: &str = include_str!("viewer.js");
/// The viewer's style sheet.
pub const VIEWER_CSS: &str = include_str!("viewer.css");

/// Parameters of scene building.
#[derive(Clone, Debug)]
pub struct ViewParams {
    /// Largest number of scan points embedded in a page; beyond it whole poses are skipped
    /// evenly (every k-th pose kept) so the page stays small and fluid. Default 250,000.
    pub max_points: usize,
    /// Scanner height above the floor \[m\] used to place `level` output when no 6-DOF pose of
    /// the same sequence is loaded (level output carries only `[x, y, rz]`). Default 0.45, the
    /// height of the paper's protocol (issue 3).
    pub default_height: f64,
    /// Page title. Default "levelscan view".
    pub title: String,
}

impl Default for ViewParams {
    fn default() -> Self {
        Self {
            max_points: 250_000,
            default_height: 0.45,
            title: "levelscan view".to_string(),
        }
    }
}

/// Coordinates are embedded as integer millimetres: compact JSON, and finer than any laser.
type Mm = i32;

fn mm(v: f64) -> Mm {
    (v * 1000.0).round().clamp(i32::MIN as f64, i32::MAX as f64) as Mm
}

fn push_mm(out: &mut Vec<Mm>, p: &Point3<f64>) {
    out.extend([mm(p.x), mm(p.y), mm(p.z)]);
}

/// A translucent filled polygon in the world frame.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Face {
    /// Corners as flat `[x, y, z, x, y, z, ...]`, millimetres.
    pub p: Vec<Mm>,
    /// RGB fill.
    pub c: [u8; 3],
    /// Opacity, 0..1.
    pub a: f32,
}

/// A robot pose, drawn as a flattened cone pointing forward (paper sect. 7.2.3).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Cone {
    /// `[x, y, z]` in millimetres.
    pub t: [Mm; 3],
    /// `[rz, ry, rx]` in radians (rounded to 1e-4).
    pub r: [f32; 3],
    /// Shade from 0 (white, first pose) to 1 (black, last pose).
    pub s: f32,
}

/// One toggleable layer of the scene.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Layer {
    /// Stable identifier, used for the toggle's element id (`lsv-toggle-<id>`).
    pub id: String,
    pub label: String,
    pub visible: bool,
    /// Line colour, RGB.
    pub color: [u8; 3],
    /// Line width in CSS pixels.
    pub width: f32,
    /// Polylines as flat `[x, y, z, ...]` millimetres.
    pub lines: Vec<Vec<Mm>>,
    pub faces: Vec<Face>,
    pub cones: Vec<Cone>,
}

impl Layer {
    fn new(id: &str, label: &str, color: [u8; 3], width: f32) -> Self {
        Self {
            id: id.to_string(),
            label: label.to_string(),
            visible: true,
            color,
            width,
            lines: Vec::new(),
            faces: Vec::new(),
            cones: Vec::new(),
        }
    }

    fn is_empty(&self) -> bool {
        self.lines.is_empty() && self.faces.is_empty() && self.cones.is_empty()
    }

    /// Points in the layer's polylines.
    pub fn point_count(&self) -> usize {
        self.lines.iter().map(|l| l.len() / 3).sum()
    }
}

/// Everything a viewer page shows.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Scene {
    pub title: String,
    /// Remarks shown under the view (what was decimated, what could not be placed).
    pub notes: Vec<String>,
    /// Open in the top-down 2D mode (set when nothing in the scene is 3D).
    pub top_down: bool,
    pub layers: Vec<Layer>,
}

impl Scene {
    pub fn layer(&self, id: &str) -> Option<&Layer> {
        self.layers.iter().find(|l| l.id == id)
    }
}

/// A named set of records, as read from one file.
#[derive(Clone, Debug, Default)]
pub struct Source {
    pub name: String,
    pub scans: Vec<Scan>,
}

const RED: [u8; 3] = [210, 30, 30];
const BLUE: [u8; 3] = [20, 70, 220];
const GREEN_FILL: [u8; 3] = [30, 170, 60];
const RED_FILL: [u8; 3] = [220, 40, 40];
const WALL_FILL: [u8; 3] = [40, 40, 48];
const PATCH_FILL: [u8; 3] = [240, 150, 20];

#[derive(Clone, Copy, PartialEq, Eq)]
enum Kind {
    Raw,
    Leveled,
    Matched,
}

/// A record that went through `match` is shown where the matcher put it, even when it was
/// `level` output before.
fn kind_of(scan: &Scan) -> Kind {
    if scan.extra.contains_key("match") {
        Kind::Matched
    } else if scan.extra.contains_key("level") {
        Kind::Leveled
    } else if scan.elevation.is_none() && scan.estimate.is_some() {
        Kind::Matched
    } else {
        Kind::Raw
    }
}

/// Where a raw record is: `true_pose`, else `estimate`, else `odometry`, else the origin.
fn raw_pose(scan: &Scan) -> Option<Pose> {
    scan.true_pose.or(scan.estimate).or(scan.odometry)
}

/// Where a matched record is: what the matcher concluded first.
fn matched_pose(scan: &Scan) -> Option<Pose> {
    scan.estimate.or(scan.odometry).or(scan.true_pose)
}

/// The estimated attitude of a `level` record, when it leveled.
fn level_attitude(scan: &Scan) -> Option<Attitude> {
    let level = scan.extra.get("level")?;
    let tx = level.get("theta_x")?.as_f64()?;
    let ty = level.get("theta_y")?.as_f64()?;
    Some(Attitude::new(tx, ty))
}

/// The `wall_polygons` (or `wall_patches`) of a `level` record: robot-frame corner lists.
fn wall_polygons(scan: &Scan, key: &str) -> Vec<Vec<Point3<f64>>> {
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

/// Consecutive points farther apart than this plus [`JUMP_FRACTION`] of the nearer range are
/// not joined: they lie on different surfaces (a depth discontinuity) \[m\].
const JUMP_MIN: f64 = 0.3;
/// See [`JUMP_MIN`] \[1\].
const JUMP_FRACTION: f64 = 0.15;

/// Splits a scan into polylines of consecutive valid rays, mapped by `f`; an invalid ray or a
/// depth discontinuity breaks the line, so no segment is drawn across what the laser did not see.
/// A point left alone is a polyline of one point (the viewer draws it as a dot).
fn scan_polylines(scan: &Scan, f: impl Fn(usize) -> Option<Point3<f64>>) -> Vec<Vec<Mm>> {
    let mut lines = Vec::new();
    let mut current = Vec::new();
    let mut last: Option<(Point3<f64>, f64)> = None;
    for i in 0..scan.nrays() {
        let point = scan.range(i).zip(f(i));
        if let (Some((r, p)), Some((q, rq))) = (point, last)
            && (p - q).norm() > JUMP_MIN + JUMP_FRACTION * r.min(rq)
        {
            if !current.is_empty() {
                lines.push(std::mem::take(&mut current));
            }
            current.clear();
        }
        last = point.map(|(r, p)| (p, r));
        match point {
            Some((_, p)) => push_mm(&mut current, &p),
            None => {
                if !current.is_empty() {
                    lines.push(std::mem::take(&mut current));
                }
                current.clear();
            }
        }
    }
    if !current.is_empty() {
        lines.push(current);
    }
    lines
}

/// A pose group: consecutive records of one source with the same sequence (or one record when
/// sequences are absent), the unit of decimation and of a pose cone.
struct Group<'a> {
    kind: Kind,
    sequence: Option<u64>,
    scans: Vec<&'a Scan>,
}

fn groups(source: &Source) -> Vec<Group<'_>> {
    let mut out: Vec<Group> = Vec::new();
    for scan in &source.scans {
        let kind = kind_of(scan);
        if let Some(last) = out.last_mut()
            && kind == Kind::Raw
            && last.kind == Kind::Raw
            && scan.sequence.is_some()
            && last.sequence == scan.sequence
        {
            last.scans.push(scan);
            continue;
        }
        out.push(Group {
            kind,
            sequence: scan.sequence,
            scans: vec![scan],
        });
    }
    out
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

/// Builds the scene of a floor plan and any number of scan sources.
pub fn build_scene(plan: Option<&Plan>, sources: &[Source], params: &ViewParams) -> Scene {
    let mut notes = Vec::new();
    let mut plan_layer = Layer::new("plan", "Floor plan walls", WALL_FILL, 1.0);
    let mut scans_layer = Layer::new("scans", "Scans (red)", RED, 1.0);
    let mut polys_layer = Layer::new("polygons", "Wall polygons (green/red)", RED_FILL, 1.0);
    // Merged wall patches (`level --polygons` writes them as `wall_patches`); off at first, as
    // they cover the quads they were grown from.
    let mut patches_layer = Layer::new("patches", "Merged wall patches (orange)", PATCH_FILL, 1.0);
    patches_layer.visible = false;
    let mut pseudo_layer = Layer::new("pseudo", "Pseudo-level scans (blue)", BLUE, 1.6);
    let mut matched_layer = Layer::new("matched", "Matched 2D scans (blue)", BLUE, 1.0);
    let mut truth_layer = Layer::new("truth", "True path (green)", [0, 140, 60], 2.0);
    let mut poses_layer = Layer::new("poses", "Robot poses (light to dark)", [0, 0, 0], 1.0);

    if let Some(plan) = plan {
        for seg in plan.segments() {
            let h = plan.wall_height;
            plan_layer.faces.push(Face {
                p: vec![
                    mm(seg.a.x),
                    mm(seg.a.y),
                    0,
                    mm(seg.b.x),
                    mm(seg.b.y),
                    0,
                    mm(seg.b.x),
                    mm(seg.b.y),
                    mm(h),
                    mm(seg.a.x),
                    mm(seg.a.y),
                    mm(h),
                ],
                c: WALL_FILL,
                a: 0.22,
            });
        }
    }

    // Raw 6-DOF poses by sequence, so level output of the same run lands where its raw scans are.
    let mut raw_by_sequence: HashMap<u64, Pose> = HashMap::new();
    for source in sources {
        for scan in &source.scans {
            if kind_of(scan) == Kind::Raw
                && let (Some(seq), Some(pose)) = (scan.sequence, raw_pose(scan))
            {
                raw_by_sequence.entry(seq).or_insert(pose);
            }
        }
    }

    let all_groups: Vec<(usize, Group)> = sources
        .iter()
        .enumerate()
        .flat_map(|(i, s)| groups(s).into_iter().map(move |g| (i, g)))
        .collect();
    let total_points: usize = all_groups
        .iter()
        .flat_map(|(_, g)| g.scans.iter())
        .map(|s| s.valid_count())
        .sum();
    let stride = total_points.div_ceil(params.max_points.max(1)).max(1);
    if stride > 1 {
        let kept = all_groups.len().div_ceil(stride);
        notes.push(format!(
            "{total_points} scan points in {} poses: keeping 1 pose in {stride} ({kept} poses) to keep the page small (--max-points {}).",
            all_groups.len(),
            params.max_points
        ));
    }

    let mut pose_cones: Vec<Pose> = Vec::new();
    let mut truth_path: Vec<Mm> = Vec::new();
    let mut unplaced = 0usize;
    // Whether any raw scan needs 3D: tilted, or taken at a hinge elevation.
    let mut raw_3d = false;
    for (k, (_, group)) in all_groups.iter().enumerate() {
        if k % stride != 0 {
            continue;
        }
        match group.kind {
            Kind::Raw => {
                let pose = raw_pose(group.scans[0]);
                if pose.is_none() {
                    unplaced += 1;
                }
                let pose = pose.unwrap_or_default();
                let world_from_robot = pose.world_from_robot();
                raw_3d |= !pose.is_planar()
                    || group
                        .scans
                        .iter()
                        .any(|s| s.elevation.is_some_and(|e| e != 0.0));
                for scan in &group.scans {
                    scans_layer.lines.extend(scan_polylines(scan, |i| {
                        scan.point_in_robot(i)
                            .map(|p| world_from_robot.transform_point(&p))
                    }));
                }
                pose_cones.push(pose);
            }
            Kind::Leveled => {
                let scan = group.scans[0];
                let planar = raw_pose(scan);
                if planar.is_none() {
                    unplaced += 1;
                }
                let planar = planar.unwrap_or_default();
                let attitude = level_attitude(scan);
                // Prefer the loaded raw pose (true attitude and height) so polygons sit on the
                // red scans; else the record's planar pose with the estimated attitude.
                let robot_pose = scan
                    .sequence
                    .and_then(|s| raw_by_sequence.get(&s).copied())
                    .unwrap_or_else(|| {
                        let att = attitude.unwrap_or_default();
                        Pose::new(
                            planar.x,
                            planar.y,
                            params.default_height,
                            planar.rz,
                            att.theta_y,
                            att.theta_x,
                        )
                    });
                // The pseudo-level scan is in the level frame: only heading and position apply.
                let world_from_level = Pose::new(
                    robot_pose.x,
                    robot_pose.y,
                    robot_pose.z,
                    robot_pose.rz,
                    0.0,
                    0.0,
                )
                .world_from_robot();
                pseudo_layer.lines.extend(scan_polylines(scan, |i| {
                    let r = scan.range(i)?;
                    let (s, c) = scan.theta[i].sin_cos();
                    Some(world_from_level.transform_point(&Point3::new(r * c, r * s, 0.0)))
                }));
                let world_from_robot = robot_pose.world_from_robot();
                for poly in wall_polygons(scan, "wall_patches") {
                    let mut p = Vec::with_capacity(poly.len() * 3);
                    for c in &poly {
                        push_mm(&mut p, &world_from_robot.transform_point(c));
                    }
                    patches_layer.faces.push(Face {
                        p,
                        c: PATCH_FILL,
                        a: 0.3,
                    });
                }
                for (j, poly) in wall_polygons(scan, "wall_polygons").iter().enumerate() {
                    let mut p = Vec::with_capacity(poly.len() * 3);
                    for c in poly {
                        push_mm(&mut p, &world_from_robot.transform_point(c));
                    }
                    let (c, a) = if j % 2 == 0 {
                        (GREEN_FILL, 0.35)
                    } else {
                        (RED_FILL, 0.35)
                    };
                    polys_layer.faces.push(Face { p, c, a });
                }
                if !raw_by_sequence.contains_key(&scan.sequence.unwrap_or(u64::MAX)) {
                    pose_cones.push(robot_pose);
                }
            }
            Kind::Matched => {
                let scan = group.scans[0];
                let pose = matched_pose(scan);
                if pose.is_none() {
                    unplaced += 1;
                }
                let pose = pose.unwrap_or_default();
                let planar = Pose::new(pose.x, pose.y, 0.0, pose.rz, 0.0, 0.0);
                let world_from_scan = planar.world_from_robot();
                matched_layer.lines.extend(scan_polylines(scan, |i| {
                    let r = scan.range(i)?;
                    let (s, c) = scan.theta[i].sin_cos();
                    Some(world_from_scan.transform_point(&Point3::new(r * c, r * s, 0.0)))
                }));
                if let Some(t) = scan.true_pose {
                    push_mm(&mut truth_path, &Point3::new(t.x, t.y, 0.0));
                }
                pose_cones.push(planar);
            }
        }
    }
    if unplaced > 0 {
        notes.push(format!(
            "{unplaced} poses had no true_pose, estimate or odometry and are drawn at the origin."
        ));
    }
    if truth_path.len() >= 6 {
        truth_layer.lines.push(truth_path);
    }
    if pose_cones.is_empty()
        && let Some(plan) = plan
    {
        pose_cones.extend(plan.poses.iter().copied());
    }
    let n = pose_cones.len();
    poses_layer.cones = pose_cones
        .iter()
        .enumerate()
        .map(|(i, p)| cone(p, i, n))
        .collect();

    // Flat 2D logs (CSM, matched scans) open in the top-down mode made for them.
    let has_3d = raw_3d || !polys_layer.is_empty() || !pseudo_layer.is_empty();
    let has_2d = !matched_layer.is_empty() || !scans_layer.is_empty();
    let top_down = !has_3d && has_2d;
    let layers: Vec<Layer> = [
        plan_layer,
        scans_layer,
        polys_layer,
        patches_layer,
        pseudo_layer,
        matched_layer,
        truth_layer,
        poses_layer,
    ]
    .into_iter()
    .filter(|l| !l.is_empty())
    .collect();
    if layers.is_empty() {
        notes.push("Nothing to show: no walls, scans or poses were given.".to_string());
    }
    Scene {
        title: params.title.clone(),
        notes,
        top_down,
        layers,
    }
}

/// The scene as JSON that is safe inside a `<script>` element (`</` is escaped).
pub fn scene_json(scene: &Scene) -> String {
    let json = serde_json::to_string(scene).unwrap_or_else(|_| "{}".to_string());
    escape_script(&json)
}

/// Escapes text for embedding in a `<script>` element: a literal `</` would end it early.
pub fn escape_script(json: &str) -> String {
    json.replace("</", "<\\/")
}

/// Escapes text for HTML element content and attribute values.
pub fn escape_html(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for ch in s.chars() {
        match ch {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

/// The HTML fragment of one viewer: its container, the scene data and the call that mounts
/// it. The page must include [`VIEWER_JS`] and [`VIEWER_CSS`] once (see [`page_head_assets`]).
pub fn viewer_fragment(scene: &Scene, element_id: &str) -> String {
    viewer_fragment_with_class(scene, element_id, "lsv")
}

fn viewer_fragment_with_class(scene: &Scene, element_id: &str, class: &str) -> String {
    let id = escape_html(element_id);
    format!(
        "<div class=\"{class}\" id=\"{id}\"></div>\n\
         <script type=\"application/json\" id=\"{id}-data\">{json}</script>\n\
         <script>LevelscanViewer.mount(document.getElementById(\"{id}\"), \
         JSON.parse(document.getElementById(\"{id}-data\").textContent));</script>\n",
        json = scene_json(scene),
    )
}

/// The viewer's style and script, for a page's `<head>`.
pub fn page_head_assets() -> String {
    format!("<style>\n{VIEWER_CSS}</style>\n<script>\n{VIEWER_JS}</script>\n")
}

/// A whole self-contained page with one full-window viewer.
pub fn viewer_page(scene: &Scene) -> String {
    format!(
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
         <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n\
         <title>{title}</title>\n{assets}</head>\n<body class=\"lsv-page\">\n\
         <h1 class=\"lsv-title\">{title}</h1>\n{viewer}</body>\n</html>\n",
        title = escape_html(&scene.title),
        assets = page_head_assets(),
        viewer = viewer_fragment_with_class(scene, "viewer", "lsv lsv-full"),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
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
            coords(&scene.layer("truth").unwrap().lines[0]),
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
    fn script_end_tag_in_title_cannot_break_the_page() {
        let scene = Scene {
            title: "</script><b>".into(),
            notes: vec![],
            top_down: false,
            layers: vec![],
        };
        let page = viewer_page(&scene);
        assert_eq!(page.matches("</script>").count(), 3);
        assert!(page.contains("&lt;/script&gt;&lt;b&gt;"));
        assert!(scene_json(&scene).contains("<\\/script>"));
    }
}
