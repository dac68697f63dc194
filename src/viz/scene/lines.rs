//! Scan lines: a scan's points joined in ray order, broken where the laser did not see one
//! surface: an invalid ray, or a range discontinuity found by the adaptive breakpoint detector of
//! Borges and Aldon ("Line extraction in 2D range images for mobile robotics", J. Intelligent
//! and Robotic Systems 40, 2004, eq. 10). Without the breaks, clutter and doorways become long
//! chords across free space: a spider web on views of many poses.

use super::{Mm, push_mm};
use crate::scan::Scan;
use nalgebra::Point3;

/// The shallowest angle between a ray and a surface that still counts as one surface \[rad\]
/// (Borges and Aldon's lambda, 10 degrees): two consecutive points farther apart than a surface
/// this oblique would put them lie on different surfaces.
const LAMBDA: f64 = 10.0 * std::f64::consts::PI / 180.0;
/// Range noise allowed for on top of the geometric distance \[m\] (their sigma_r; 3 sigma_r is
/// added): 2 cm, a typical 2D lidar's.
const SIGMA_R: f64 = 0.02;

/// The largest distance between the points of rays `dphi` apart, the first at range `r`, that
/// still lie on one surface (the adaptive breakpoint detector's D_max). Sparse rays (`dphi` near
/// lambda) widen lambda to three ray steps, so a scan of few rays still draws lines.
pub(super) fn max_joined_distance(r: f64, dphi: f64) -> f64 {
    let dphi = dphi.abs();
    let lambda = LAMBDA.max(3.0 * dphi);
    r * dphi.sin() / (lambda - dphi).sin() + 3.0 * SIGMA_R
}

/// Splits a scan into polylines of consecutive valid rays, mapped by `f`; an invalid ray or a
/// range discontinuity breaks the line, so no segment is drawn across what the laser did not see.
/// A point left alone is a polyline of one point (the viewer draws it as a dot).
pub(super) fn scan_polylines(
    scan: &Scan,
    f: impl Fn(usize) -> Option<Point3<f64>>,
) -> Vec<Vec<Mm>> {
    let mut lines = Vec::new();
    let mut current = Vec::new();
    // The last valid ray: its point, range and bearing.
    let mut last: Option<(Point3<f64>, f64, f64)> = None;
    for i in 0..scan.nrays() {
        let point = scan.range(i).zip(f(i));
        let bearing = scan.theta.get(i).copied().unwrap_or(0.0);
        let joined = match (point, last) {
            (Some((_, p)), Some((q, rq, bq))) => {
                (p - q).norm() <= max_joined_distance(rq, bearing - bq)
            }
            _ => false,
        };
        if !joined && !current.is_empty() {
            lines.push(std::mem::take(&mut current));
        }
        last = point.map(|(r, p)| (p, r, bearing));
        if let Some((_, p)) = point {
            push_mm(&mut current, &p);
        }
    }
    if !current.is_empty() {
        lines.push(current);
    }
    lines
}
