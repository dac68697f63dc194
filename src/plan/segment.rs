//! A wall piece and the 2D primitives on it that the ray caster, its grid and the outline
//! tests share: distance to a point, where a horizontal ray meets it, and bounds.
//!
//! The ray conventions (see `simulate::raycast`): a hit exactly at a segment's end counts,
//! and the ends are extended by a relative [`END_SLACK`] so that a ray through the joint of
//! two segments of a polyline cannot slip between them by rounding; a ray along a segment's
//! own line meets its nearer end; ranges below [`MIN_RANGE`] do not count.

use nalgebra::{Point2, Vector2};

/// Relative extension of each segment at both ends (fraction of its length).
pub(crate) const END_SLACK: f64 = 1e-9;
/// Smallest range that counts as a hit \[m\]: a ray starting on a surface does not hit it.
pub(crate) const MIN_RANGE: f64 = 1e-9;

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

fn cross(a: &Vector2<f64>, b: &Vector2<f64>) -> f64 {
    a.x * b.y - a.y * b.x
}

/// Range `t >= MIN_RANGE` at which the 2D ray `p + t·d` meets segment `s`, if it does.
/// `d` is the horizontal part of a unit 3D direction, so `t` is the 3D range.
pub(crate) fn ray_segment(p: &Point2<f64>, d: &Vector2<f64>, s: &Segment) -> Option<f64> {
    let e = s.b - s.a;
    let ap = s.a - p;
    let denom = cross(d, &e);
    if denom != 0.0 {
        // p + t·d = a + u·e, solved with 2D cross products.
        let t = cross(&ap, &e) / denom;
        let u = cross(&ap, d) / denom;
        (t >= MIN_RANGE && (-END_SLACK..=1.0 + END_SLACK).contains(&u)).then_some(t)
    } else {
        // Parallel: only a ray along the wall's own line meets it, at the nearer end (the
        // wall seen edge-on). A ray starting on the wall itself passes along it unhindered.
        let dd = d.norm_squared();
        if dd == 0.0 || cross(&ap, d) != 0.0 {
            return None;
        }
        let ta = ap.dot(d) / dd;
        let tb = (s.b - p).dot(d) / dd;
        let near = ta.min(tb);
        (near >= MIN_RANGE).then_some(near)
    }
}

/// Where the ray from `p` towards +x crosses `s`, by the half-open rule on y (a segment
/// counts when exactly one end lies above `p.y`, so a ray through a polyline's vertex meets
/// one of its two segments there, and horizontal segments never): the crossing's x, when it
/// lies beyond `p.x`.
pub(crate) fn crossing_x(s: &Segment, p: &Point2<f64>) -> Option<f64> {
    if (s.a.y > p.y) == (s.b.y > p.y) {
        return None;
    }
    let x = s.a.x + (p.y - s.a.y) / (s.b.y - s.a.y) * (s.b.x - s.a.x);
    (x > p.x).then_some(x)
}

/// Axis-aligned bounds of the points: (min, max); `None` for no points.
pub(crate) fn bounds(
    points: impl IntoIterator<Item = Point2<f64>>,
) -> Option<(Point2<f64>, Point2<f64>)> {
    let mut pts = points.into_iter();
    let first = pts.next()?;
    Some(pts.fold((first, first), |(lo, hi), p| {
        (
            Point2::new(lo.x.min(p.x), lo.y.min(p.y)),
            Point2::new(hi.x.max(p.x), hi.y.max(p.y)),
        )
    }))
}

/// The end points of the segments, for [`bounds`].
pub(crate) fn end_points(segments: &[Segment]) -> impl Iterator<Item = Point2<f64>> + '_ {
    segments.iter().flat_map(|s| [s.a, s.b])
}

/// The segment from (ax, ay) to (bx, by): the unit tests' shorthand.
#[cfg(test)]
pub(crate) fn seg(ax: f64, ay: f64, bx: f64, by: f64) -> Segment {
    Segment {
        a: Point2::new(ax, ay),
        b: Point2::new(bx, by),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segment_distance_known_values() {
        let s = seg(0.0, 0.0, 4.0, 0.0);
        assert_eq!(s.distance_to(&Point2::new(2.0, 3.0)), 3.0);
        assert_eq!(s.distance_to(&Point2::new(7.0, 4.0)), 5.0);
        let point = seg(1.0, 1.0, 1.0, 1.0);
        assert_eq!(point.distance_to(&Point2::new(4.0, 5.0)), 5.0);
    }

    #[test]
    fn crossings_follow_the_half_open_rule() {
        let p = Point2::new(0.0, 1.0);
        assert_eq!(crossing_x(&seg(2.0, 0.0, 2.0, 2.0), &p), Some(2.0));
        assert_eq!(crossing_x(&seg(-2.0, 0.0, -2.0, 2.0), &p), None, "behind");
        assert_eq!(crossing_x(&seg(0.0, 1.0, 5.0, 1.0), &p), None, "horizontal");
        // Through a vertex: the segment above it counts, the one ending there does not.
        assert_eq!(crossing_x(&seg(3.0, 1.0, 3.0, 2.0), &p), Some(3.0));
        assert_eq!(crossing_x(&seg(3.0, 0.0, 3.0, 1.0), &p), None);
    }

    #[test]
    fn bounds_of_points() {
        assert_eq!(bounds(std::iter::empty()), None);
        let b = bounds(end_points(&[
            seg(1.0, 5.0, -2.0, 3.0),
            seg(0.0, 0.0, 0.5, 9.0),
        ]));
        assert_eq!(b, Some((Point2::new(-2.0, 0.0), Point2::new(1.0, 9.0))));
    }
}
