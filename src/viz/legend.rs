//! Legends and scale bars drawn in an area of their own, beside or under a chart, so they never
//! cover data (a legend inside a map's frame sat on a wall). Entries flow left to right and
//! wrap to the next row when the area is too narrow.

use super::error::PlotError;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

/// Font size of legend and scale text [px] as plotters takes it (its SVG writes 1/1.24 of it:
/// 16 is 12.9 px, readable at the report's size).
pub const LEGEND_FONT: u32 = 16;

/// How an entry is drawn before its label.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Mark {
    /// A short line.
    Line(RGBColor),
    /// A filled box.
    Box(RGBColor),
    /// An outlined box.
    Outline(RGBColor),
    /// A dot.
    Dot(RGBColor),
    /// A translucent band.
    Band(RGBColor),
}

/// One legend entry.
#[derive(Clone, Debug, PartialEq)]
pub struct Entry {
    pub mark: Mark,
    pub label: String,
}

impl Entry {
    pub fn new(mark: Mark, label: &str) -> Self {
        Self {
            mark,
            label: label.to_string(),
        }
    }
}

const SWATCH: i32 = 18;
const GAP: i32 = 6;
const SPACING: i32 = 18;

/// The top-left corner of each entry laid out in an area `width` wide, given each entry's
/// label width: left to right, wrapping; rows `row_height` apart.
pub fn layout(label_widths: &[u32], width: i32, row_height: i32) -> Vec<(i32, i32)> {
    let (mut x, mut y) = (GAP, GAP);
    label_widths
        .iter()
        .map(|&w| {
            let need = SWATCH + GAP + w as i32;
            if x > GAP && x + need > width - GAP {
                x = GAP;
                y += row_height;
            }
            let at = (x, y);
            x += need + SPACING;
            at
        })
        .collect()
}

/// Height of one legend row \[px\].
pub const ROW: i32 = LEGEND_FONT as i32 + 8;

fn label_style() -> TextStyle<'static> {
    TextStyle::from(("sans-serif", LEGEND_FONT).into_font()).pos(Pos::new(HPos::Left, VPos::Center))
}

fn label_widths<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    entries: &[Entry],
) -> Result<Vec<u32>, PlotError> {
    let style = label_style();
    entries
        .iter()
        .map(|e| area.estimate_text_size(&e.label, &style).map(|s| s.0))
        .collect::<Result<_, _>>()
        .map_err(PlotError::drawing)
}

/// The height \[px\] `entries` take when laid out `width` pixels wide on `area`'s backend.
pub fn legend_height<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    entries: &[Entry],
    width: u32,
) -> Result<u32, PlotError> {
    let widths = label_widths(area, entries)?;
    let bottom = layout(&widths, width as i32, ROW)
        .last()
        .map_or(0, |&(_, y)| y + ROW + GAP);
    Ok(bottom as u32)
}

/// Draws `entries` in `area`.
pub fn draw_legend<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    entries: &[Entry],
) -> Result<(), PlotError> {
    let style = label_style();
    let widths = label_widths(area, entries)?;
    let row = ROW;
    let (width, _) = area.dim_in_pixel();
    for (e, (x, y)) in entries.iter().zip(layout(&widths, width as i32, row)) {
        let mid = y + row / 2;
        let (a, b) = ((x, mid - 5), (x + SWATCH, mid + 5));
        match e.mark {
            Mark::Line(c) => area.draw(&PathElement::new(
                [(x, mid), (x + SWATCH, mid)],
                c.stroke_width(2),
            )),
            Mark::Box(c) => area.draw(&Rectangle::new([a, b], c.filled())),
            Mark::Outline(c) => area.draw(&Rectangle::new([a, b], c.stroke_width(2))),
            Mark::Dot(c) => area.draw(&Circle::new((x + SWATCH / 2, mid), 3, c.filled())),
            Mark::Band(c) => area.draw(&Rectangle::new([a, b], c.mix(0.3).filled())),
        }
        .map_err(PlotError::drawing)?;
        area.draw(&Text::new(
            e.label.clone(),
            (x + SWATCH + GAP, mid),
            style.clone(),
        ))
        .map_err(PlotError::drawing)?;
    }
    Ok(())
}

/// A length that reads well on a scale bar: 1, 2 or 5 times a power of ten metres, the longest
/// drawn at most `max_px` long at `px_per_metre`.
pub fn nice_length(px_per_metre: f64, max_px: f64) -> f64 {
    let raw = max_px / px_per_metre.max(1e-12);
    let p = 10f64.powf(raw.log10().floor());
    [5.0, 2.0, 1.0]
        .into_iter()
        .map(|m| m * p)
        .find(|&l| l <= raw * (1.0 + 1e-9))
        .unwrap_or(p)
}

/// "2 m", "50 cm".
pub fn length_label(metres: f64) -> String {
    if metres >= 1.0 {
        format!("{metres} m")
    } else {
        format!("{:.0} cm", metres * 100.0)
    }
}

/// Draws a scale bar ending `right` pixels from the area's left, vertically centred: a bar
/// with end ticks, its length in metres beside it. Returns the bar's length in pixels.
pub fn draw_scale_bar<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    px_per_metre: f64,
    right: i32,
) -> Result<i32, PlotError> {
    let metres = nice_length(px_per_metre, 120.0);
    let px = (metres * px_per_metre).round() as i32;
    let (_, h) = area.dim_in_pixel();
    let y = h as i32 / 2;
    let left = right - px;
    let black = BLACK.stroke_width(2);
    area.draw(&PathElement::new(
        [(left, y - 5), (left, y + 4), (right, y + 4), (right, y - 5)],
        black,
    ))
    .map_err(PlotError::drawing)?;
    let style = TextStyle::from(("sans-serif", LEGEND_FONT).into_font())
        .pos(Pos::new(HPos::Right, VPos::Center));
    area.draw(&Text::new(
        format!("scale {}", length_label(metres)),
        (left - GAP, y),
        style,
    ))
    .map_err(PlotError::drawing)?;
    Ok(px)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn entries_flow_and_wrap_inside_the_area() {
        // Each entry needs 18 + 6 + 100 = 124 px, then 18 px of spacing.
        let at = layout(&[100, 100, 100], 300, 22);
        assert_eq!(at, vec![(6, 6), (148, 6), (6, 28)]);
        for (&(x, _), w) in at.iter().zip([100, 100, 100]) {
            assert!(x + 24 + w <= 300 - 6);
        }
        // A label wider than the area still gets a row of its own.
        assert_eq!(layout(&[500, 10], 300, 22), vec![(6, 6), (6, 28)]);
    }

    #[test]
    fn scale_bar_lengths_are_round_and_fit() {
        assert_eq!(nice_length(50.0, 120.0), 2.0); // 2.4 m fit: 2 m (100 px)
        assert_eq!(nice_length(20.0, 120.0), 5.0); // 6 m fit: 5 m
        assert_eq!(nice_length(1000.0, 120.0), 0.1);
        assert_eq!(nice_length(24.0, 120.0), 5.0); // exactly 5 m fits
        assert_eq!(length_label(2.0), "2 m");
        assert_eq!(length_label(0.5), "50 cm");
    }
}
