//! The 3D viewer's scene: the paper's visualizer (sect. 7.2.3, Fig. 5) as world-frame geometry in
//! toggleable layers, drawn by `viewer.js` (see [`super::html`] for the page).
//!
//! Building a [`Scene`] is pure: scans, level output and a floor plan go in, layers come out.
//! First every record is placed ([`place`]): which kind it is and where the robot was; then each
//! layer is drawn from the placed records by a function of its own ([`layers`]). The layers
//! follow Fig. 5: multi-elevation scans as red lines joining consecutive points (broken where
//! the laser did not see a surface, [`lines`]), extracted wall polygons in alternating
//! translucent green and red, pseudo-level (and matched level) scans in blue, floor-plan walls as
//! dark translucent rectangles, and robot poses as flattened cones shaded from light to dark in
//! time order (thinned on long logs), joined by the robot's path; a matched log's `true_pose`
//! is drawn as a reference path.
//!
//! Which records are what is read from the records themselves:
//! - a record with a `level` object is `levelscan level` output: its scan is a pseudo-level scan in
//!   the level frame (heading kept, z dropped), its `wall_polygons` (with `--polygons`) are
//!   robot-frame quads;
//! - a record with a `match` object, or a 2D record (no `elevation`) with an `estimate`, is a
//!   matched 2D scan, placed at its `estimate` (the top-down mode is made for these);
//! - any other record is a raw scan, placed at `true_pose`, else `estimate`, else `odometry`,
//!   else the origin, and drawn in 3D with its hinge elevation and offset.

mod layers;
mod lines;
mod place;
#[cfg(test)]
mod tests;

use crate::plan::Plan;
use crate::scan::Scan;
use nalgebra::Point3;
use serde::Serialize;

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
    /// Most pose cones drawn; beyond it one pose in k keeps its cone (the robot path still
    /// joins every pose). Default 100: a long log's hundreds of cones hide its map.
    pub max_cones: usize,
    /// Page title. Default "levelscan view".
    pub title: String,
}

impl Default for ViewParams {
    fn default() -> Self {
        Self {
            max_points: 250_000,
            default_height: 0.45,
            max_cones: 100,
            title: "levelscan view".to_string(),
        }
    }
}

/// Coordinates are embedded as integer millimetres: compact JSON, and finer than any laser.
pub type Mm = i32;

pub(crate) fn mm(v: f64) -> Mm {
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

/// Builds the scene of a floor plan and any number of scan sources.
pub fn build_scene(plan: Option<&Plan>, sources: &[Source], params: &ViewParams) -> Scene {
    let placed = place::place(sources, params);
    let drawn: Vec<&place::Placed> = placed.groups.iter().filter(|g| g.drawn).collect();
    let mut notes = placed.notes.clone();
    let mut layers = vec![
        layers::plan_walls(plan),
        layers::raw_scans(&drawn),
        layers::wall_polygons(&drawn),
        layers::wall_patches(&drawn),
        layers::pseudo_level_scans(&drawn),
        layers::matched_scans(&drawn),
        layers::reference_path(&placed.groups),
        layers::robot_path(&placed.groups),
        layers::pose_cones(&drawn, plan, params.max_cones, &mut notes),
    ];
    let top_down = layers::is_top_down(&drawn, &layers);
    layers.retain(|l| !l.is_empty());
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
