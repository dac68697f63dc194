//! Top-down maps of matched runs (paper Figs. 8-10): the floor plan's walls, the matched scans'
//! points and the true and estimated paths, with axes in metres, a scale bar, and the legend in
//! a strip under the map (inside the frame it sat on a wall). Drawn with plotters on any
//! backend, as PNG files or SVG text.

use super::error::PlotError;
use super::legend::{Entry, Mark, ROW, draw_legend, draw_scale_bar, legend_height};
use crate::eval::matching::RunResult;
use crate::geometry::Pose2;
use crate::plan::Plan;
use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use std::path::Path;

/// One top-down map of a matched run, for side-by-side panels: the floor plan's walls (grey),
/// the matched scans' points placed with the (aligned) estimates, the true path (green) and the
/// estimated path (blue).
#[derive(Clone, Debug, PartialEq, Default)]
pub struct MapPanel {
    pub title: String,
    /// Wall segments of the true floor plan, `[x0, y0, x1, y1]` \[m\].
    pub walls: Vec<[f64; 4]>,
    /// Scan points in the world \[m\].
    pub points: Vec<[f64; 2]>,
    /// True positions in time order \[m\].
    pub truth: Vec<[f64; 2]>,
    /// Estimated positions in time order \[m\].
    pub estimate: Vec<[f64; 2]>,
}

impl MapPanel {
    /// Bounds of walls and paths (not the points: a failed match can throw them far away,
    /// and the map should still show the building) as `(min, max)`, with a margin.
    pub fn view_bounds(&self) -> ([f64; 2], [f64; 2]) {
        let mut lo = [f64::INFINITY; 2];
        let mut hi = [f64::NEG_INFINITY; 2];
        let walls = self.walls.iter().flat_map(|w| [[w[0], w[1]], [w[2], w[3]]]);
        for p in walls.chain(self.truth.iter().copied()) {
            for d in 0..2 {
                lo[d] = lo[d].min(p[d]);
                hi[d] = hi[d].max(p[d]);
            }
        }
        if !lo[0].is_finite() {
            return ([-1.0, -1.0], [1.0, 1.0]);
        }
        let margin = 0.05 * (hi[0] - lo[0]).max(hi[1] - lo[1]).max(1.0);
        (
            [lo[0] - margin, lo[1] - margin],
            [hi[0] + margin, hi[1] + margin],
        )
    }
}

/// Stretches `(lo, hi)` so its aspect ratio matches `width / height` pixels: metres stay square.
pub fn equal_aspect(lo: [f64; 2], hi: [f64; 2], width: u32, height: u32) -> ([f64; 2], [f64; 2]) {
    let (w, h) = (hi[0] - lo[0], hi[1] - lo[1]);
    let target = f64::from(width.max(1)) / f64::from(height.max(1));
    let c = [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0];
    let (w, h) = if w / h > target {
        (w, w / target)
    } else {
        (h * target, h)
    };
    (
        [c[0] - w / 2.0, c[1] - h / 2.0],
        [c[0] + w / 2.0, c[1] + h / 2.0],
    )
}

/// Pixel sizes of a map's frame: tick labels and axis names on the left and below, the legend
/// strip under everything.
const MARGIN: u32 = 10;
const X_LABELS: u32 = 44;
const Y_LABELS: u32 = 54;
/// Width of the scale bar's part of the strip under the map \[px\].
const SCALE_WIDTH: u32 = 190;
const TICK_FONT: u32 = 16;

/// Draws one map panel on a drawing area: title, the map with axes in metres (square metres),
/// and under it the legend and a scale bar.
pub fn draw_map<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    panel: &MapPanel,
) -> Result<(), PlotError> {
    area.fill(&WHITE).map_err(PlotError::drawing)?;
    let body = area
        .titled(&panel.title, ("sans-serif", 19))
        .map_err(PlotError::drawing)?;
    let (w, h) = body.dim_in_pixel();
    let entries = map_legend();
    let legend_w = w.saturating_sub(SCALE_WIDTH);
    let strip_h = legend_height(&body, &entries, legend_w)?;
    let (chart_area, strip) = body.split_vertically(h.saturating_sub(strip_h));
    let plot_w = w.saturating_sub(2 * MARGIN + Y_LABELS);
    let plot_h = (h.saturating_sub(strip_h)).saturating_sub(2 * MARGIN + X_LABELS);
    let (lo, hi) = panel.view_bounds();
    let (lo, hi) = equal_aspect(lo, hi, plot_w, plot_h);
    let mut ctx = ChartBuilder::on(&chart_area)
        .margin(MARGIN)
        .x_label_area_size(X_LABELS)
        .y_label_area_size(Y_LABELS)
        .build_cartesian_2d(lo[0]..hi[0], lo[1]..hi[1])
        .map_err(PlotError::drawing)?;
    ctx.configure_mesh()
        .light_line_style(WHITE)
        .bold_line_style(RGBColor(235, 235, 235))
        .x_desc("x [m]")
        .y_desc("y [m]")
        .label_style(("sans-serif", TICK_FONT))
        .axis_desc_style(("sans-serif", TICK_FONT + 1))
        .x_label_formatter(&|v| format!("{v:.0}"))
        .y_label_formatter(&|v| format!("{v:.0}"))
        .draw()
        .map_err(PlotError::drawing)?;
    draw_map_data(&mut ctx, panel, lo, hi)?;
    let px_per_metre = f64::from(plot_w) / (hi[0] - lo[0]).max(1e-9);
    let (legend, scale) = strip.split_horizontally(legend_w);
    draw_legend(&legend, &entries)?;
    let (scale, _) = scale.split_vertically(ROW as u32 + 12);
    draw_scale_bar(&scale, px_per_metre, SCALE_WIDTH as i32 - 12)?;
    Ok(())
}

/// What the map's colours mean.
fn map_legend() -> Vec<Entry> {
    vec![
        Entry::new(Mark::Line(WALL_GREY), "plan walls"),
        Entry::new(Mark::Dot(SCAN_RED), "matched points"),
        Entry::new(Mark::Line(GREEN), "true path"),
        Entry::new(Mark::Line(BLUE), "estimated path"),
    ]
}

const WALL_GREY: RGBColor = RGBColor(150, 150, 150);
const SCAN_RED: RGBColor = RGBColor(200, 30, 30);
const GREEN: RGBColor = RGBColor(0, 140, 60);
const BLUE: RGBColor = RGBColor(20, 70, 220);

type MapChart<'a, DB> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// The walls, the points inside the view and both paths.
fn draw_map_data<DB: DrawingBackend>(
    ctx: &mut MapChart<'_, DB>,
    panel: &MapPanel,
    lo: [f64; 2],
    hi: [f64; 2],
) -> Result<(), PlotError> {
    for wall in &panel.walls {
        ctx.draw_series(LineSeries::new(
            [(wall[0], wall[1]), (wall[2], wall[3])],
            WALL_GREY.stroke_width(2),
        ))
        .map_err(PlotError::drawing)?;
    }
    let inside = |p: &[f64; 2]| p[0] >= lo[0] && p[0] <= hi[0] && p[1] >= lo[1] && p[1] <= hi[1];
    let scan_color = SCAN_RED.mix(0.55);
    ctx.draw_series(
        panel
            .points
            .iter()
            .filter(|p| inside(p))
            .map(|p| Circle::new((p[0], p[1]), 1, scan_color.filled())),
    )
    .map_err(PlotError::drawing)?;
    for (path, color) in [(&panel.truth, GREEN), (&panel.estimate, BLUE)] {
        let pts: Vec<(f64, f64)> = path.iter().map(|p| (p[0], p[1])).collect();
        ctx.draw_series(LineSeries::new(pts.clone(), color.stroke_width(2)))
            .map_err(PlotError::drawing)?;
        ctx.draw_series(pts.iter().map(|&p| Circle::new(p, 3, color.filled())))
            .map_err(PlotError::drawing)?;
    }
    Ok(())
}

/// Panels side by side in one picture.
pub fn draw_side_by_side<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    panels: &[MapPanel],
) -> Result<(), PlotError> {
    area.fill(&WHITE).map_err(PlotError::drawing)?;
    for (sub, panel) in area
        .split_evenly((1, panels.len().max(1)))
        .iter()
        .zip(panels)
    {
        draw_map(sub, panel)?;
    }
    area.present().map_err(PlotError::drawing)?;
    Ok(())
}

/// Map panels side by side as a PNG file.
pub fn map_panels_png(panels: &[MapPanel], path: &Path, size: (u32, u32)) -> Result<(), PlotError> {
    let area = BitMapBackend::new(path, size).into_drawing_area();
    draw_side_by_side(&area, panels)
}

/// Map panels side by side as SVG text.
pub fn map_panels_svg(panels: &[MapPanel], size: (u32, u32)) -> Result<String, PlotError> {
    let mut svg = String::new();
    {
        let area = SVGBackend::with_string(&mut svg, size).into_drawing_area();
        draw_side_by_side(&area, panels)?;
    }
    Ok(svg)
}

/// A top-down map of one matched run (paper Figs. 8-10): the plan's walls, every scan placed at
/// its estimate after the ATE alignment, and the true and estimated paths.
pub fn run_map_panel(plan: &Plan, run: &RunResult, truth: &[Pose2]) -> MapPanel {
    let mode = match run.mode {
        crate::matching::Mode::Pairwise => "pairwise",
        crate::matching::Mode::Metascan => "metascan",
    };
    let ate = run
        .ate
        .map(|a| format!("ATE {:.3} m", a.rmse))
        .unwrap_or_default();
    MapPanel {
        title: format!("{} scans, {mode}: {ate}", run.kind.label()),
        walls: plan
            .segments()
            .iter()
            .map(|s| [s.a.x, s.a.y, s.b.x, s.b.y])
            .collect(),
        points: run
            .aligned
            .iter()
            .zip(&run.points)
            .flat_map(|(pose, pts)| {
                pts.iter().map(|p| {
                    let w = pose.transform_point(p);
                    [w.x, w.y]
                })
            })
            .collect(),
        truth: truth.iter().map(|p| [p.x, p.y]).collect(),
        estimate: run.aligned.iter().map(|p| [p.x, p.y]).collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn equal_aspect_keeps_metres_square_and_contains_the_box() {
        let (lo, hi) = equal_aspect([0.0, 0.0], [10.0, 2.0], 400, 400);
        assert_eq!(hi[0] - lo[0], hi[1] - lo[1]);
        assert!(lo[1] <= 0.0 && hi[1] >= 2.0 && lo[0] == 0.0 && hi[0] == 10.0);
        let (lo, hi) = equal_aspect([0.0, 0.0], [2.0, 10.0], 800, 400);
        assert_eq!((hi[0] - lo[0]) / (hi[1] - lo[1]), 2.0);
        assert!(lo[0] <= 0.0 && hi[0] >= 2.0);
    }

    #[test]
    fn map_view_follows_walls_and_truth_not_stray_points() {
        let panel = MapPanel {
            walls: vec![[0.0, 0.0, 10.0, 0.0], [10.0, 0.0, 10.0, 8.0]],
            points: vec![[500.0, -300.0]],
            truth: vec![[1.0, 1.0]],
            ..MapPanel::default()
        };
        let (lo, hi) = panel.view_bounds();
        assert!(lo[0] < 0.0 && lo[0] > -1.0 && hi[0] > 10.0 && hi[0] < 11.0);
        assert!(hi[1] > 8.0 && hi[1] < 9.0);
    }

    #[test]
    fn side_by_side_svg_has_both_titles() {
        let a = MapPanel {
            title: "raw".into(),
            truth: vec![[0.0, 0.0], [1.0, 0.0]],
            estimate: vec![[0.0, 0.0], [1.0, 0.5]],
            points: vec![[0.5, 0.5]],
            ..MapPanel::default()
        };
        let b = MapPanel {
            title: "leveled".into(),
            ..a.clone()
        };
        let svg = map_panels_svg(&[a, b], (800, 400)).unwrap();
        let raw = svg.find(">\nraw\n<").unwrap();
        let leveled = svg.find(">\nleveled\n<").unwrap();
        assert!(raw < leveled);
    }
}
