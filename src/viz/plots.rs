//! Static figures with plotters: tables as grouped bar charts (the paper's Table I as a figure,
//! with the paper's own values beside ours), drawn on any plotters backend, and written as SVG
//! text (for self-contained reports) or PNG files.

use crate::eval::accuracy::paper_mean;
use crate::eval::matching::RunResult;
use crate::geometry::Pose2;
use crate::plan::Plan;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::Path;

/// A figure could not be drawn (e.g. no font for its text on this machine).
#[derive(Debug, thiserror::Error)]
#[error("cannot draw figure: {0}")]
pub struct PlotError(pub String);

fn plot_err<E: std::fmt::Debug>(e: E) -> PlotError {
    PlotError(format!("{e:?}"))
}

/// One series of a grouped bar chart: a value per group (`None` where there is none).
#[derive(Clone, Debug, PartialEq)]
pub struct Series {
    pub label: String,
    pub values: Vec<Option<f64>>,
    /// Fill colour, RGB.
    pub color: (u8, u8, u8),
    /// Drawn as an outline only (for reference values such as the paper's).
    pub outline: bool,
}

/// A grouped bar chart: groups along x (e.g. noise levels), one bar per series in each group.
#[derive(Clone, Debug, PartialEq)]
pub struct GroupedBars {
    pub title: String,
    pub y_label: String,
    pub groups: Vec<String>,
    pub series: Vec<Series>,
}

impl GroupedBars {
    fn max_value(&self) -> f64 {
        self.series
            .iter()
            .flat_map(|s| s.values.iter().flatten())
            .copied()
            .filter(|v| v.is_finite())
            .fold(0.0, f64::max)
    }

    /// The x span `[left, right)` of bar `s` in group `g`, in chart units (a group is 1 wide).
    pub fn bar_span(&self, g: usize, s: usize) -> (f64, f64) {
        let n = self.series.len().max(1) as f64;
        let width = 0.8 / n;
        let left = g as f64 + 0.1 + s as f64 * width;
        (left, left + width)
    }
}

/// One cell of a Table I run: mean attitude error at a noise level and number of scans.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AccuracyCell {
    /// Range noise sigma \[m\].
    pub noise: f64,
    /// Scans per pose.
    pub scans: usize,
    /// Mean of max(|dx|, |dy|) over leveled poses \[deg\].
    pub mean_deg: f64,
}

/// Table I as a figure: groups are noise levels, bars are scan counts, with the paper's value
/// (where it has one) as an outlined bar beside each of ours.
pub fn table_one_chart(cells: &[AccuracyCell]) -> GroupedBars {
    let mut noises: Vec<f64> = cells.iter().map(|c| c.noise).collect();
    noises.sort_by(f64::total_cmp);
    noises.dedup();
    let mut scans: Vec<usize> = cells.iter().map(|c| c.scans).collect();
    scans.sort_unstable();
    scans.dedup();
    let palette = [
        (31, 119, 180),
        (255, 127, 14),
        (44, 160, 44),
        (148, 103, 189),
    ];
    let mut series = Vec::new();
    for (k, &n) in scans.iter().enumerate() {
        let color = palette[k % palette.len()];
        let ours = noises
            .iter()
            .map(|&noise| {
                cells
                    .iter()
                    .find(|c| c.scans == n && (c.noise - noise).abs() < 1e-12)
                    .map(|c| c.mean_deg)
            })
            .collect();
        series.push(Series {
            label: format!("{n} scans (levelscan)"),
            values: ours,
            color,
            outline: false,
        });
        let paper: Vec<Option<f64>> = noises.iter().map(|&noise| paper_mean(n, noise)).collect();
        if paper.iter().any(Option::is_some) {
            series.push(Series {
                label: format!("{n} scans (paper)"),
                values: paper,
                color,
                outline: true,
            });
        }
    }
    GroupedBars {
        title: "Table I: mean attitude error".to_string(),
        y_label: "mean error [deg]".to_string(),
        groups: noises
            .iter()
            .map(|n| format!("{:.0} cm noise", n * 100.0))
            .collect(),
        series,
    }
}

/// Draws a grouped bar chart on any plotters drawing area.
pub fn draw_grouped_bars<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    chart: &GroupedBars,
) -> Result<(), PlotError> {
    area.fill(&WHITE).map_err(plot_err)?;
    let top = (chart.max_value() * 1.15).max(1e-3);
    let groups = chart.groups.len().max(1);
    let mut ctx = ChartBuilder::on(area)
        .caption(&chart.title, ("sans-serif", 20))
        .margin(12)
        .x_label_area_size(34)
        .y_label_area_size(56)
        .build_cartesian_2d(0.0..groups as f64, 0.0..top)
        .map_err(plot_err)?;
    let labels = chart.groups.clone();
    ctx.configure_mesh()
        .disable_x_mesh()
        .x_labels(groups * 2 + 1)
        .x_label_formatter(&|x| {
            // Label each group at its centre only.
            let g = (x - 0.5).round();
            if (x - 0.5 - g).abs() < 1e-6 && g >= 0.0 {
                labels.get(g as usize).cloned().unwrap_or_default()
            } else {
                String::new()
            }
        })
        .y_desc(&chart.y_label)
        .draw()
        .map_err(plot_err)?;
    for (s, series) in chart.series.iter().enumerate() {
        let color = RGBColor(series.color.0, series.color.1, series.color.2);
        let style = if series.outline {
            color.stroke_width(2)
        } else {
            color.filled()
        };
        let bars: Vec<Rectangle<(f64, f64)>> = series
            .values
            .iter()
            .enumerate()
            .filter_map(|(g, v)| {
                let v = (*v)?;
                let (l, r) = chart.bar_span(g, s);
                Some(Rectangle::new([(l, 0.0), (r, v)], style))
            })
            .collect();
        ctx.draw_series(bars)
            .map_err(plot_err)?
            .label(&series.label)
            .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 14, y + 5)], style));
    }
    ctx.configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.3))
        .draw()
        .map_err(plot_err)?;
    area.present().map_err(plot_err)?;
    Ok(())
}

/// The chart as SVG text, for embedding in a report.
pub fn grouped_bars_svg(chart: &GroupedBars, size: (u32, u32)) -> Result<String, PlotError> {
    let mut svg = String::new();
    {
        let area = SVGBackend::with_string(&mut svg, size).into_drawing_area();
        draw_grouped_bars(&area, chart)?;
    }
    Ok(svg)
}

/// The chart as a PNG file.
pub fn grouped_bars_png(
    chart: &GroupedBars,
    path: &Path,
    size: (u32, u32),
) -> Result<(), PlotError> {
    let area = BitMapBackend::new(path, size).into_drawing_area();
    draw_grouped_bars(&area, chart)
}

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

/// Draws one map panel on a drawing area.
pub fn draw_map<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    panel: &MapPanel,
) -> Result<(), PlotError> {
    area.fill(&WHITE).map_err(plot_err)?;
    let (w, h) = area.dim_in_pixel();
    // The plotting area loses the caption and a small margin; keep metres square inside it.
    let (lo, hi) = panel.view_bounds();
    let (lo, hi) = equal_aspect(lo, hi, w.saturating_sub(24), h.saturating_sub(56));
    let mut ctx = ChartBuilder::on(area)
        .caption(&panel.title, ("sans-serif", 18))
        .margin(12)
        .build_cartesian_2d(lo[0]..hi[0], lo[1]..hi[1])
        .map_err(plot_err)?;
    let grey = RGBColor(150, 150, 150);
    for wall in &panel.walls {
        ctx.draw_series(LineSeries::new(
            [(wall[0], wall[1]), (wall[2], wall[3])],
            grey.stroke_width(2),
        ))
        .map_err(plot_err)?;
    }
    let inside = |p: &[f64; 2]| p[0] >= lo[0] && p[0] <= hi[0] && p[1] >= lo[1] && p[1] <= hi[1];
    let scan_color = RGBColor(200, 30, 30).mix(0.55);
    ctx.draw_series(
        panel
            .points
            .iter()
            .filter(|p| inside(p))
            .map(|p| Circle::new((p[0], p[1]), 1, scan_color.filled())),
    )
    .map_err(plot_err)?;
    let green = RGBColor(0, 140, 60);
    let blue = RGBColor(20, 70, 220);
    for (path, color, label) in [
        (&panel.truth, green, "true path"),
        (&panel.estimate, blue, "estimated path"),
    ] {
        let pts: Vec<(f64, f64)> = path.iter().map(|p| (p[0], p[1])).collect();
        ctx.draw_series(LineSeries::new(pts.clone(), color.stroke_width(2)))
            .map_err(plot_err)?
            .label(label)
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 16, y)], color.stroke_width(2)));
        ctx.draw_series(pts.iter().map(|&p| Circle::new(p, 3, color.filled())))
            .map_err(plot_err)?;
    }
    ctx.configure_series_labels()
        .position(SeriesLabelPosition::LowerRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.3))
        .draw()
        .map_err(plot_err)?;
    Ok(())
}

/// Panels side by side in one picture.
pub fn draw_side_by_side<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    panels: &[MapPanel],
) -> Result<(), PlotError> {
    area.fill(&WHITE).map_err(plot_err)?;
    for (sub, panel) in area
        .split_evenly((1, panels.len().max(1)))
        .iter()
        .zip(panels)
    {
        draw_map(sub, panel)?;
    }
    area.present().map_err(plot_err)?;
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

    fn cells() -> Vec<AccuracyCell> {
        let mut v = Vec::new();
        for (i, noise) in [0.01, 0.05].into_iter().enumerate() {
            for scans in [3, 5] {
                v.push(AccuracyCell {
                    noise,
                    scans,
                    mean_deg: 0.25 * (i + 1) as f64 * scans as f64,
                });
            }
        }
        v
    }

    #[test]
    fn table_one_chart_pairs_each_scan_count_with_the_papers_values() {
        let chart = table_one_chart(&cells());
        assert_eq!(chart.groups, vec!["1 cm noise", "5 cm noise"]);
        let labels: Vec<&str> = chart.series.iter().map(|s| s.label.as_str()).collect();
        assert_eq!(
            labels,
            vec![
                "3 scans (levelscan)",
                "3 scans (paper)",
                "5 scans (levelscan)",
                "5 scans (paper)"
            ]
        );
        assert_eq!(chart.series[0].values, vec![Some(0.75), Some(1.5)]);
        assert_eq!(chart.series[1].values, vec![Some(0.857), Some(2.083)]);
        assert_eq!(chart.series[3].values, vec![Some(0.409), Some(1.172)]);
        assert!(chart.series[1].outline && !chart.series[0].outline);
    }

    #[test]
    fn noise_the_paper_did_not_run_has_no_reference_bar() {
        let chart = table_one_chart(&[AccuracyCell {
            noise: 0.02,
            scans: 6,
            mean_deg: 1.0,
        }]);
        assert_eq!(chart.series.len(), 1);
    }

    #[test]
    fn bars_of_a_group_stay_inside_it_and_do_not_overlap() {
        let chart = table_one_chart(&cells());
        for g in 0..chart.groups.len() {
            let mut last = g as f64;
            for s in 0..chart.series.len() {
                let (l, r) = chart.bar_span(g, s);
                assert!(l >= last - 1e-12 && r > l && r <= g as f64 + 1.0);
                last = r;
            }
        }
    }

    #[test]
    fn svg_has_one_bar_per_value() {
        let chart = GroupedBars {
            title: "t".into(),
            y_label: "y".into(),
            groups: vec!["a".into(), "b".into()],
            series: vec![Series {
                label: "s".into(),
                values: vec![Some(1.0), None],
                color: (10, 20, 30),
                outline: false,
            }],
        };
        let svg = grouped_bars_svg(&chart, (400, 300)).unwrap();
        assert!(svg.starts_with("<svg"));
        // The one bar and its legend swatch are the rectangles filled in that colour.
        assert_eq!(svg.matches("fill=\"#0A141E\"").count(), 2, "{svg}");
    }

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
