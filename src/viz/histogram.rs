//! The paper's Fig. 6: how the attitude errors distribute over 0.5 degree buckets up to
//! 5 degrees, one bar series per scan count, as PNG and SVG (plotters).

use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::Path;

/// Bucket width \[deg\] and count of the paper's Fig. 6.
pub const BUCKET_DEG: f64 = 0.5;
pub const BUCKETS: usize = 10;

/// Percentage of `errors_deg` in each bucket `(k * 0.5, (k + 1) * 0.5]` (the paper files an
/// error under the smallest multiple of 0.5 above it); errors above 5 degrees fall in none.
pub fn bucket_percentages(errors_deg: &[f64]) -> [f64; BUCKETS] {
    let mut counts = [0usize; BUCKETS];
    for &e in errors_deg {
        let k = (e / BUCKET_DEG).ceil() as i64 - 1;
        let k = k.max(0) as usize;
        if k < BUCKETS {
            counts[k] += 1;
        }
    }
    let n = errors_deg.len().max(1) as f64;
    counts.map(|c| 100.0 * c as f64 / n)
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
        let root = BitMapBackend::new(&png, (900, 540)).into_drawing_area();
        draw(&root, title, series)?;
        root.present()
            .map_err(|e| format!("{}: {e}", png.display()))?;
    }
    {
        let root = SVGBackend::new(&svg, (900, 540)).into_drawing_area();
        draw(&root, title, series)?;
        root.present()
            .map_err(|e| format!("{}: {e}", svg.display()))?;
    }
    Ok(())
}

fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    title: &str,
    series: &[Series],
) -> Result<(), String> {
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    root.fill(&WHITE).map_err(err)?;
    let data: Vec<[f64; BUCKETS]> = series
        .iter()
        .map(|s| bucket_percentages(&s.errors_deg))
        .collect();
    let top = data
        .iter()
        .flat_map(|d| d.iter().copied())
        .fold(10.0f64, f64::max)
        * 1.1;
    let mut chart = ChartBuilder::on(root)
        .caption(title, ("sans-serif", 22))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(55)
        .build_cartesian_2d(0.0..(BUCKETS as f64 * BUCKET_DEG), 0.0..top)
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("error bucket upper bound [deg]")
        .y_desc("poses [%]")
        .x_labels(BUCKETS + 1)
        .disable_x_mesh()
        .draw()
        .map_err(err)?;
    let palette = [
        RGBColor(31, 119, 180),
        RGBColor(255, 127, 14),
        RGBColor(44, 160, 44),
        RGBColor(214, 39, 40),
    ];
    let width = BUCKET_DEG * 0.8 / series.len().max(1) as f64;
    for (si, (s, d)) in series.iter().zip(&data).enumerate() {
        let color = palette[si % palette.len()];
        chart
            .draw_series(d.iter().enumerate().map(|(k, &pct)| {
                let x0 = k as f64 * BUCKET_DEG + BUCKET_DEG * 0.1 + si as f64 * width;
                Rectangle::new([(x0, 0.0), (x0 + width, pct)], color.filled())
            }))
            .map_err(err)?
            .label(s.label.clone())
            .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 12, y + 5)], color.filled()));
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(err)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn buckets_follow_the_papers_rounding_up() {
        let p = bucket_percentages(&[0.1, 0.5, 0.51, 4.99, 7.0]);
        assert_eq!(p[0], 40.0); // 0.1 and exactly 0.5 go to (0, 0.5]
        assert_eq!(p[1], 20.0);
        assert_eq!(p[9], 20.0);
        assert!((p.iter().sum::<f64>() - 80.0).abs() < 1e-9); // 7 deg is off the chart
    }
}
