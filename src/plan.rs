//! A floor plan (the paper's `.wall` file, its Fig. 14): vertical walls over polylines, the floor
//! plane z = 0, an optional ceiling, and optional robot poses. A plain type with no I/O;
//! `formats::wall` reads and validates it.

use crate::geometry::Pose;
use nalgebra::Point2;

#[derive(Clone, Debug, PartialEq)]
pub struct Plan {
    /// Height of every wall above the floor \[m\]; > 0.
    pub wall_height: f64,
    /// Polylines of at least two points; each segment is a wall from z = 0 to `wall_height`.
    pub walls: Vec<Vec<Point2<f64>>>,
    /// A ceiling plane at `wall_height`.
    pub ceiling: bool,
    /// Robot poses in chronological order (angles in radians here; degrees in the file).
    pub poses: Vec<Pose>,
}

/// One straight wall piece.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Segment {
    pub a: Point2<f64>,
    pub b: Point2<f64>,
}

impl Segment {
    pub fn length(&self) -> f64 {
        (self.b - self.a).norm()
    }

    /// Distance from `p` to the closest point of the segment.
    pub fn distance_to(&self, p: &Point2<f64>) -> f64 {
        let ab = self.b - self.a;
        let len2 = ab.norm_squared();
        let t = if len2 > 0.0 {
            ((p - self.a).dot(&ab) / len2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        (p - (self.a + ab * t)).norm()
    }
}

impl Plan {
    /// Every wall segment of every polyline (zero-length pieces skipped).
    pub fn segments(&self) -> Vec<Segment> {
        self.walls
            .iter()
            .flat_map(|w| w.windows(2).map(|p| Segment { a: p[0], b: p[1] }))
            .filter(|s| s.length() > 0.0)
            .collect()
    }

    /// Distance from `p` to the nearest wall, infinite for a plan with no walls.
    pub fn distance_to_walls(&self, p: &Point2<f64>) -> f64 {
        self.segments()
            .iter()
            .map(|s| s.distance_to(p))
            .fold(f64::INFINITY, f64::min)
    }

    /// Axis-aligned bounds of all wall points: (min, max).
    pub fn bounds(&self) -> Option<(Point2<f64>, Point2<f64>)> {
        let mut pts = self.walls.iter().flatten();
        let first = *pts.next()?;
        Some(pts.fold((first, first), |(lo, hi), p| {
            (
                Point2::new(lo.x.min(p.x), lo.y.min(p.y)),
                Point2::new(hi.x.max(p.x), hi.y.max(p.y)),
            )
        }))
    }
}

/// A rectangular room `w` x `h` with its corner at the origin: the scene of many unit tests.
#[cfg(test)]
pub(crate) fn box_plan(w: f64, h: f64, height: f64, ceiling: bool) -> Plan {
    Plan {
        wall_height: height,
        walls: vec![vec![
            Point2::new(0.0, 0.0),
            Point2::new(w, 0.0),
            Point2::new(w, h),
            Point2::new(0.0, h),
            Point2::new(0.0, 0.0),
        ]],
        ceiling,
        poses: vec![],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segment_distance_known_values() {
        let s = Segment {
            a: Point2::new(0.0, 0.0),
            b: Point2::new(4.0, 0.0),
        };
        assert_eq!(s.distance_to(&Point2::new(2.0, 3.0)), 3.0);
        assert_eq!(s.distance_to(&Point2::new(7.0, 4.0)), 5.0);
    }
}
