//! Static figures with plotters (the maps are in [`super::map_plot`], re-exported here): tables
//! as grouped bar charts (the paper's Table I as a figure,
//! with the paper's own values beside ours), drawn on any plotters backend, and written as SVG
//! text (for self-contained reports) or PNG files.

pub use super::error::PlotError;
use super::legend::{Entry, Mark, draw_legend};
pub use super::map_plot::{MapPanel, map_panels_png, map_panels_svg, run_map_panel};
use crate::eval::accuracy::paper_mean;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::Path;

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

/// Width of the legend column right of a grouped bar chart \[px\].
const LEGEND_WIDTH: u32 = 190;

/// Draws a grouped bar chart on any plotters drawing area: title, bars, and the legend in a
/// column of its own on the right (inside the chart it covered bars).
pub fn draw_grouped_bars<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    chart: &GroupedBars,
) -> Result<(), PlotError> {
    area.fill(&WHITE).map_err(PlotError::drawing)?;
    let top = (chart.max_value() * 1.15).max(1e-3);
    let groups = chart.groups.len().max(1);
    let body = area
        .titled(&chart.title, ("sans-serif", 19))
        .map_err(PlotError::drawing)?;
    let (w, _) = body.dim_in_pixel();
    let (plot, legend) = body.split_horizontally(w.saturating_sub(LEGEND_WIDTH));
    let mut ctx = ChartBuilder::on(&plot)
        .margin(10)
        .x_label_area_size(36)
        .y_label_area_size(54)
        .build_cartesian_2d(0.0..groups as f64, 0.0..top)
        .map_err(PlotError::drawing)?;
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
        .label_style(("sans-serif", 16))
        .axis_desc_style(("sans-serif", 17))
        .draw()
        .map_err(PlotError::drawing)?;
    let mut entries = Vec::new();
    for (s, series) in chart.series.iter().enumerate() {
        let color = RGBColor(series.color.0, series.color.1, series.color.2);
        let (style, mark) = if series.outline {
            (color.stroke_width(2), Mark::Outline(color))
        } else {
            (color.filled(), Mark::Box(color))
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
        ctx.draw_series(bars).map_err(PlotError::drawing)?;
        entries.push(Entry::new(mark, &series.label));
    }
    draw_legend(&legend.margin(20, 0, 0, 0), &entries)?;
    area.present().map_err(PlotError::drawing)?;
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
}
