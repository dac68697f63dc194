//! Scan lines: a scan's points joined in ray order, broken where the laser did not see one
//! surface (an invalid ray or a depth discontinuity).

use super::{Mm, push_mm};
use crate::scan::Scan;
use nalgebra::Point3;

/// Consecutive points farther apart than this plus [`JUMP_FRACTION`] of the nearer range are
/// not joined: they lie on different surfaces (a depth discontinuity) \[m\].
const JUMP_MIN: f64 = 0.3;
/// See [`JUMP_MIN`] \[1\].
const JUMP_FRACTION: f64 = 0.15;

/// Splits a scan into polylines of consecutive valid rays, mapped by `f`; an invalid ray or a
/// depth discontinuity breaks the line, so no segment is drawn across what the laser did not see.
/// A point left alone is a polyline of one point (the viewer draws it as a dot).
pub(super) fn scan_polylines(
    scan: &Scan,
    f: impl Fn(usize) -> Option<Point3<f64>>,
) -> Vec<Vec<Mm>> {
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
