//! The paper's Fig. 6: how the attitude errors distribute over 0.5 degree buckets, one bar
//! series per scan count, as PNG and SVG (plotters).
//!
//! The axis is fitted to the data: it ends at the first multiple of 0.5 degrees that holds 99%
//! of the errors (at least 1, at most the paper's 5 degrees), and a last, overflow bin counts
//! every error beyond it, so that no pose drops off the chart (the paper's 5 degree axis lost
//! 3.5% of the poses at 10 cm noise, and left most of the chart empty where errors stop near 2).

use super::error::PlotError;
use super::legend::{Entry, Mark, draw_legend};
use crate::eval::metrics::nearest_rank;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::Path;

/// Bucket width \[deg\] of the paper's Fig. 6.
pub const BUCKET_DEG: f64 = 0.5;
/// The paper's axis end, the longest this one gets \[deg\].
pub const MAX_AXIS_DEG: f64 = 5.0;
/// The shortest axis \[deg\].
pub const MIN_AXIS_DEG: f64 = 1.0;
/// Share of the errors the axis holds before the overflow bin.
pub const AXIS_QUANTILE: f64 = 0.99;

/// Figure size \[px\]: drawn at about the size the report shows it, so its text stays readable.
pub const SIZE: (u32, u32) = (640, 420);

/// Where the axis ends \[deg\]: the first multiple of [`BUCKET_DEG`] at or above the
/// [`AXIS_QUANTILE`] of every error of every series, within [`MIN_AXIS_DEG`, `MAX_AXIS_DEG`].
pub fn axis_end_deg(series: &[Series]) -> f64 {
    let mut all: Vec<f64> = series
        .iter()
        .flat_map(|s| s.errors_deg.iter().copied())
        .filter(|e| e.is_finite())
        .collect();
    if all.is_empty() {
        return MAX_AXIS_DEG;
    }
    all.sort_by(f64::total_cmp);
    let q = nearest_rank(&all, AXIS_QUANTILE);
    ((q / BUCKET_DEG).ceil() * BUCKET_DEG).clamp(MIN_AXIS_DEG, MAX_AXIS_DEG)
}

/// Percentage of `errors_deg` in each bucket `(k * 0.5, (k + 1) * 0.5]` up to `end_deg` (the
/// paper files an error under the smallest multiple of 0.5 above it), then the overflow bin of
/// every error above `end_deg`: `end_deg / 0.5 + 1` values that sum to 100.
pub fn bucket_percentages(errors_deg: &[f64], end_deg: f64) -> Vec<f64> {
    let buckets = (end_deg / BUCKET_DEG).round() as usize;
    let mut counts = vec![0usize; buckets + 1];
    for &e in errors_deg {
        let k = ((e / BUCKET_DEG).ceil() as i64 - 1).max(0) as usize;
        counts[k.min(buckets)] += 1;
    }
    let n = errors_deg.len().max(1) as f64;
    counts.iter().map(|&c| 100.0 * c as f64 / n).collect()
}

/// One bar series: its label and its errors \[deg\].
pub struct Series {
    pub label: String,
    pub errors_deg: Vec<f64>,
}

/// Writes the histogram as `<stem>.png` and `<stem>.svg` in `dir`.
pub fn write_histogram(
    dir: &Path,
    stem: &str,
    title: &str,
    series: &[Series],
) -> Result<(), String> {
    let png = dir.join(format!("{stem}.png"));
    let svg = dir.join(format!("{stem}.svg"));
    {
        let root = BitMapBackend::new(&png, SIZE).into_drawing_area();
        draw(&root, title, series).map_err(|e| e.to_string())?;
        root.present()
            .map_err(|e| format!("{}: {e}", png.display()))?;
    }
    {
        let root = SVGBackend::new(&svg, SIZE).into_drawing_area();
        draw(&root, title, series).map_err(|e| e.to_string())?;
        root.present()
            .map_err(|e| format!("{}: {e}", svg.display()))?;
    }
    Ok(())
}

const PALETTE: [RGBColor; 4] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
];

/// Label under bin `k` of `n` (the last is the overflow): its upper bound, or "> end".
fn bin_label(k: usize, n: usize, end_deg: f64) -> String {
    if k + 1 == n {
        format!("> {end_deg:.1}")
    } else {
        format!("{:.1}", (k + 1) as f64 * BUCKET_DEG)
    }
}

/// Draws the histogram: bins along x in bin units (bin k spans `[k, k + 1)`), the legend in a
/// strip under the chart.
pub fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    title: &str,
    series: &[Series],
) -> Result<(), PlotError> {
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| PlotError(e.to_string());
    root.fill(&WHITE).map_err(err)?;
    let end = axis_end_deg(series);
    let data: Vec<Vec<f64>> = series
        .iter()
        .map(|s| bucket_percentages(&s.errors_deg, end))
        .collect();
    let bins = data.first().map_or(1, Vec::len);
    let top = data.iter().flatten().copied().fold(10.0f64, f64::max) * 1.1;
    let body = root.titled(title, ("sans-serif", 19)).map_err(err)?;
    let (_, h) = body.dim_in_pixel();
    let (chart_area, strip) = body.split_vertically(h.saturating_sub(34));
    let mut chart = ChartBuilder::on(&chart_area)
        .margin(10)
        .x_label_area_size(46)
        .y_label_area_size(54)
        .build_cartesian_2d(0.0..bins as f64, 0.0..top)
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("error, bucket upper bound [deg]")
        .y_desc("leveled poses [%]")
        .x_labels(bins * 2 + 1)
        .x_label_formatter(&|x| {
            let k = (x - 0.5).round();
            if (x - 0.5 - k).abs() < 1e-6 && k >= 0.0 && (k as usize) < bins {
                bin_label(k as usize, bins, end)
            } else {
                String::new()
            }
        })
        .y_label_formatter(&|y| format!("{y:.0}"))
        .label_style(("sans-serif", 16))
        .axis_desc_style(("sans-serif", 17))
        .disable_x_mesh()
        .draw()
        .map_err(err)?;
    let width = 0.8 / series.len().max(1) as f64;
    for (si, d) in data.iter().enumerate() {
        let color = PALETTE[si % PALETTE.len()];
        chart
            .draw_series(d.iter().enumerate().map(|(k, &pct)| {
                let x0 = k as f64 + 0.1 + si as f64 * width;
                let style = if k + 1 == bins {
                    color.stroke_width(2)
                } else {
                    color.filled()
                };
                Rectangle::new([(x0, 0.0), (x0 + width, pct)], style)
            }))
            .map_err(err)?;
    }
    // The overflow bin is apart: a dashed-looking separator before it.
    let sep = (bins - 1) as f64;
    chart
        .draw_series(LineSeries::new(
            [(sep, 0.0), (sep, top)],
            BLACK.mix(0.4).stroke_width(1),
        ))
        .map_err(err)?;
    let mut entries: Vec<Entry> = series
        .iter()
        .enumerate()
        .map(|(si, s)| Entry::new(Mark::Box(PALETTE[si % PALETTE.len()]), &s.label))
        .collect();
    entries.push(Entry::new(
        Mark::Outline(RGBColor(90, 90, 90)),
        &format!("beyond {end:.1} deg"),
    ));
    draw_legend(&strip.margin(0, 0, 54, 0), &entries)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn series(errors: Vec<f64>) -> Vec<Series> {
        vec![Series {
            label: "s".into(),
            errors_deg: errors,
        }]
    }

    #[test]
    fn buckets_follow_the_papers_rounding_up_and_overflow_keeps_the_rest() {
        let p = bucket_percentages(&[0.1, 0.5, 0.51, 4.99, 7.0], 5.0);
        assert_eq!(p.len(), 11);
        assert_eq!(p[0], 40.0); // 0.1 and exactly 0.5 go to (0, 0.5]
        assert_eq!(p[1], 20.0);
        assert_eq!(p[9], 20.0);
        assert_eq!(p[10], 20.0); // 7 deg: in the overflow bin, not lost
        assert!((p.iter().sum::<f64>() - 100.0).abs() < 1e-9);
        // A shorter axis moves what lies beyond it into the overflow bin.
        let p = bucket_percentages(&[0.1, 0.5, 0.51, 4.99, 7.0], 1.0);
        assert_eq!(p, vec![40.0, 20.0, 40.0]);
    }

    #[test]
    fn axis_ends_where_the_data_do() {
        // 100 errors up to 1.98 deg: the axis ends at 2.0, not at 5.
        let e: Vec<f64> = (0..100).map(|i| f64::from(i) * 0.02).collect();
        assert_eq!(axis_end_deg(&series(e)), 2.0);
        // A long tail beyond 5 deg: the axis stops at the paper's 5, the tail overflows.
        let mut tail: Vec<f64> = vec![0.3; 90];
        tail.extend([8.0; 10]);
        assert_eq!(axis_end_deg(&series(tail)), 5.0);
        // Tiny errors still get a 1 degree axis; no errors, the paper's.
        assert_eq!(axis_end_deg(&series(vec![0.1; 10])), 1.0);
        assert_eq!(axis_end_deg(&series(vec![])), 5.0);
    }

    #[test]
    fn svg_names_the_overflow_bin() {
        let mut svg = String::new();
        {
            let root = SVGBackend::with_string(&mut svg, SIZE).into_drawing_area();
            // 99% of the errors within 1.2 deg: the axis ends at 1.5; 9 deg overflows.
            let mut e = vec![0.2; 50];
            e.extend([0.7; 30]);
            e.extend([1.2; 19]);
            e.push(9.0);
            draw(&root, "t", &series(e)).unwrap();
        }
        assert!(svg.contains("&gt; 1.5") || svg.contains("> 1.5"), "{svg}");
        assert!(svg.contains("beyond 1.5 deg"));
    }
}
