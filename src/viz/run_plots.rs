//! The plots of one run ([`crate::eval::run`]): roll and pitch over time, the estimate with its
//! 3-sigma band against the truth, failed poses marked; and the position error along the
//! trajectory, as the path coloured by the error and as the error over the distance travelled.

use super::error::PlotError;
use super::legend::{Entry, Mark, draw_legend};
use super::map_plot::equal_aspect;
use crate::eval::run::{RunEvaluation, RunPose};
use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use std::path::Path;

/// Size of both figures \[px\]: the width of a report's full row.
pub const SIZE: (u32, u32) = (1240, 540);

const FONT: u32 = 16;
const TRUTH: RGBColor = RGBColor(20, 20, 20);
const ESTIMATE: RGBColor = RGBColor(20, 70, 220);
const FAILED: RGBColor = RGBColor(210, 30, 30);
const REFERENCE: RGBColor = RGBColor(150, 150, 150);

/// The x of each pose: its time when every pose has one, else its index; and the axis name.
fn time_axis(poses: &[RunPose]) -> (Vec<f64>, &'static str) {
    match poses.iter().map(|p| p.time_s).collect::<Option<Vec<f64>>>() {
        Some(t) if !t.is_empty() => (t, "time [s]"),
        _ => ((0..poses.len()).map(|k| k as f64).collect(), "pose"),
    }
}

fn span(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    if lo.is_finite() {
        let pad = ((hi - lo) * 0.08).max(0.25);
        (lo - pad, hi + pad)
    } else {
        (-1.0, 1.0)
    }
}

type Chart<'a, DB> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// The 3-sigma band `(low, high)` per pose at times `t`, one polygon per run of consecutive
/// poses that have one.
fn draw_band<DB: DrawingBackend>(
    ctx: &mut Chart<'_, DB>,
    band: &[Option<(f64, f64)>],
    t: &[f64],
) -> Result<(), PlotError> {
    let pairs: Vec<(&Option<(f64, f64)>, &f64)> = band.iter().zip(t).collect();
    for run in pairs.split(|(b, _)| b.is_none()).filter(|r| !r.is_empty()) {
        let mut outline: Vec<(f64, f64)> = run
            .iter()
            .filter_map(|&(b, x)| Some((*x, b.as_ref()?.1)))
            .collect();
        outline.extend(
            run.iter()
                .rev()
                .filter_map(|&(b, x)| Some((*x, b.as_ref()?.0))),
        );
        ctx.draw_series(std::iter::once(Polygon::new(
            outline,
            ESTIMATE.mix(0.18).filled(),
        )))
        .map_err(PlotError::drawing)?;
    }
    Ok(())
}

/// Roll (`axis` 0) or pitch (1) of every pose in one panel.
fn draw_angle<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    poses: &[RunPose],
    axis: usize,
    name: &str,
) -> Result<(), PlotError> {
    let (t, t_name) = time_axis(poses);
    let deg = |v: f64| v.to_degrees();
    let band: Vec<Option<(f64, f64)>> = poses
        .iter()
        .map(|p| {
            let (a, s) = (p.attitude?[axis], p.sigma?[axis]);
            Some((deg(a - 3.0 * s), deg(a + 3.0 * s)))
        })
        .collect();
    let values = poses
        .iter()
        .flat_map(|p| {
            [
                p.attitude.map(|a| deg(a[axis])),
                p.true_attitude.map(|a| deg(a[axis])),
            ]
        })
        .flatten()
        .chain(band.iter().flatten().flat_map(|b| [b.0, b.1]));
    let (lo, hi) = span(values);
    let (t0, t1) = span(t.iter().copied());
    let mut ctx = ChartBuilder::on(area)
        .margin(8)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(t0..t1, lo..hi)
        .map_err(PlotError::drawing)?;
    ctx.configure_mesh()
        .light_line_style(WHITE)
        .x_desc(t_name)
        .y_desc(format!("{name} [deg]"))
        .label_style(("sans-serif", FONT))
        .axis_desc_style(("sans-serif", FONT + 1))
        .draw()
        .map_err(PlotError::drawing)?;
    draw_band(&mut ctx, &band, &t)?;
    let line = |f: &dyn Fn(&RunPose) -> Option<f64>| -> Vec<(f64, f64)> {
        poses
            .iter()
            .zip(&t)
            .filter_map(|(p, &x)| Some((x, f(p)?)))
            .collect()
    };
    let truth = line(&|p| p.true_attitude.map(|a| deg(a[axis])));
    let estimate = line(&|p| p.attitude.map(|a| deg(a[axis])));
    ctx.draw_series(LineSeries::new(truth, TRUTH.stroke_width(2)))
        .map_err(PlotError::drawing)?;
    ctx.draw_series(LineSeries::new(estimate.clone(), ESTIMATE.stroke_width(2)))
        .map_err(PlotError::drawing)?;
    ctx.draw_series(
        estimate
            .iter()
            .map(|&p| Circle::new(p, 3, ESTIMATE.filled())),
    )
    .map_err(PlotError::drawing)?;
    let failed = poses.iter().zip(&t).filter(|(p, _)| p.attitude.is_none());
    ctx.draw_series(failed.map(|(_, &x)| TriangleMarker::new((x, lo), 6, FAILED.filled())))
        .map_err(PlotError::drawing)?;
    Ok(())
}

/// Roll and pitch over time: estimate, 3-sigma band, truth; failed poses as red marks.
pub fn draw_attitude<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    poses: &[RunPose],
    title: &str,
) -> Result<(), PlotError> {
    area.fill(&WHITE).map_err(PlotError::drawing)?;
    let body = area
        .titled(title, ("sans-serif", 19))
        .map_err(PlotError::drawing)?;
    let (_, h) = body.dim_in_pixel();
    let (charts, strip) = body.split_vertically(h.saturating_sub(34));
    let panels = charts.split_evenly((1, 2));
    draw_angle(&panels[0], poses, 0, "roll theta_x")?;
    draw_angle(&panels[1], poses, 1, "pitch theta_y")?;
    let entries = [
        Entry::new(Mark::Line(ESTIMATE), "level's estimate"),
        Entry::new(Mark::Band(ESTIMATE), "estimate +- 3 sigma"),
        Entry::new(Mark::Line(TRUTH), "truth (true_pose)"),
        Entry::new(Mark::Dot(FAILED), "pose level could not level"),
    ];
    draw_legend(&strip.margin(0, 0, 60, 0), &entries)
}

/// A colour from green (no error) through yellow to red (`max` and beyond).
pub fn error_color(e: f64, max: f64) -> RGBColor {
    let t = (e / max.max(1e-12)).clamp(0.0, 1.0);
    let (r, g) = if t < 0.5 {
        (2.0 * t, 1.0)
    } else {
        (1.0, 2.0 * (1.0 - t))
    };
    RGBColor((40.0 + 190.0 * r) as u8, (40.0 + 150.0 * g) as u8, 40)
}

/// The error along the trajectory: left, the reference path with each aligned estimate
/// coloured by its position error; right, the error over the distance travelled.
pub fn draw_trajectory_error<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    poses: &[RunPose],
    eval: &RunEvaluation,
    title: &str,
) -> Result<(), PlotError> {
    area.fill(&WHITE).map_err(PlotError::drawing)?;
    let body = area
        .titled(title, ("sans-serif", 19))
        .map_err(PlotError::drawing)?;
    let (w, h) = body.dim_in_pixel();
    let (charts, strip) = body.split_vertically(h.saturating_sub(34));
    let (left, right) = charts.split_horizontally(w / 2);
    let max = eval
        .position_error_m
        .iter()
        .flatten()
        .copied()
        .fold(0.0, f64::max);
    draw_error_path(&left, poses, eval, max)?;
    draw_error_distance(&right, eval, max)?;
    let entries = [
        Entry::new(Mark::Line(REFERENCE), "reference path (true_pose)"),
        Entry::new(Mark::Dot(error_color(0.0, 1.0)), "estimate, error 0"),
        Entry::new(
            Mark::Dot(error_color(0.5, 1.0)),
            &format!("{:.3} m", max / 2.0),
        ),
        Entry::new(
            Mark::Dot(error_color(1.0, 1.0)),
            &format!("{max:.3} m (largest)"),
        ),
    ];
    draw_legend(&strip.margin(0, 0, 60, 0), &entries)
}

fn draw_error_path<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    poses: &[RunPose],
    eval: &RunEvaluation,
    max: f64,
) -> Result<(), PlotError> {
    let refs: Vec<(f64, f64)> = poses
        .iter()
        .filter_map(|p| p.reference.map(|r| (r.x, r.y)))
        .collect();
    let (x0, x1) = span(refs.iter().map(|p| p.0));
    let (y0, y1) = span(refs.iter().map(|p| p.1));
    let (w, h) = area.dim_in_pixel();
    let (lo, hi) = equal_aspect(
        [x0, y0],
        [x1, y1],
        w.saturating_sub(76),
        h.saturating_sub(56),
    );
    let mut ctx = ChartBuilder::on(area)
        .margin(8)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(lo[0]..hi[0], lo[1]..hi[1])
        .map_err(PlotError::drawing)?;
    ctx.configure_mesh()
        .light_line_style(WHITE)
        .x_desc("x [m]")
        .y_desc("y [m]")
        .label_style(("sans-serif", FONT))
        .axis_desc_style(("sans-serif", FONT + 1))
        .draw()
        .map_err(PlotError::drawing)?;
    ctx.draw_series(LineSeries::new(refs, REFERENCE.stroke_width(2)))
        .map_err(PlotError::drawing)?;
    let dots = eval.aligned.iter().zip(&eval.position_error_m);
    ctx.draw_series(dots.filter_map(|(p, e)| {
        let (p, e) = (p.as_ref()?, (*e)?);
        Some(Circle::new((p.x, p.y), 5, error_color(e, max).filled()))
    }))
    .map_err(PlotError::drawing)?;
    Ok(())
}

fn draw_error_distance<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    eval: &RunEvaluation,
    max: f64,
) -> Result<(), PlotError> {
    let pts: Vec<(f64, f64)> = eval
        .distance_m
        .iter()
        .zip(&eval.position_error_m)
        .filter_map(|(d, e)| Some(((*d)?, (*e)?)))
        .collect();
    let (d0, d1) = span(pts.iter().map(|p| p.0));
    let mut ctx = ChartBuilder::on(area)
        .margin(8)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(d0.max(0.0)..d1, 0.0..(max * 1.15).max(1e-3))
        .map_err(PlotError::drawing)?;
    ctx.configure_mesh()
        .light_line_style(WHITE)
        .x_desc("distance travelled [m]")
        .y_desc("position error [m]")
        .label_style(("sans-serif", FONT))
        .axis_desc_style(("sans-serif", FONT + 1))
        .draw()
        .map_err(PlotError::drawing)?;
    ctx.draw_series(LineSeries::new(pts.clone(), ESTIMATE.stroke_width(2)))
        .map_err(PlotError::drawing)?;
    ctx.draw_series(
        pts.iter()
            .map(|&(d, e)| Circle::new((d, e), 4, error_color(e, max).filled())),
    )
    .map_err(PlotError::drawing)?;
    Ok(())
}

/// Figure `k`: 0 the attitude, 1 the trajectory error.
fn draw_figure<DB: DrawingBackend>(
    k: usize,
    area: &DrawingArea<DB, Shift>,
    poses: &[RunPose],
    eval: &RunEvaluation,
) -> Result<(), PlotError> {
    if k == 0 {
        draw_attitude(area, poses, "Roll and pitch over the run")
    } else {
        let ate = eval.ate.map_or("-".into(), |a| format!("{:.3} m", a.rmse));
        let title = format!("Position error along the trajectory (ATE {ate})");
        draw_trajectory_error(area, poses, eval, &title)
    }
}

/// Draws both figures into `dir` as `<prefix>attitude.{png,svg}` and
/// `<prefix>trajectory_error.{png,svg}`; returns the two SVG texts.
pub fn write_run_figures(
    dir: &Path,
    prefix: &str,
    poses: &[RunPose],
    eval: &RunEvaluation,
) -> Result<[String; 2], PlotError> {
    let mut svgs = [String::new(), String::new()];
    for (k, stem) in ["attitude", "trajectory_error"].into_iter().enumerate() {
        let png = dir.join(format!("{prefix}{stem}.png"));
        {
            let area = BitMapBackend::new(&png, SIZE).into_drawing_area();
            draw_figure(k, &area, poses, eval)?;
            area.present().map_err(PlotError::drawing)?;
        }
        {
            let area = SVGBackend::with_string(&mut svgs[k], SIZE).into_drawing_area();
            draw_figure(k, &area, poses, eval)?;
            area.present().map_err(PlotError::drawing)?;
        }
        std::fs::write(dir.join(format!("{prefix}{stem}.svg")), &svgs[k])
            .map_err(|e| PlotError(format!("{}: {e}", dir.display())))?;
    }
    Ok(svgs)
}
