//! Scenes for the bounds' tests ([`super::pair_bound`], [`super::path_bound`]): walls from
//! coordinates, and the noise-free rays of 181-ray, 180-degree scans at given poses.

use super::bound::WallPlanes;
use super::pair_bound::{PairRay, scan_rays};
use crate::geometry::Pose2;
use crate::plan::Segment;
use crate::simulate::World;
use nalgebra::Point2;

/// A wall from `a` to `b` \[m\].
pub(crate) fn segment(a: (f64, f64), b: (f64, f64)) -> Segment {
    Segment {
        a: Point2::new(a.0, a.1),
        b: Point2::new(b.0, b.1),
    }
}

/// 181 bearings, one degree apart, over the half plane ahead.
fn bearings() -> impl Iterator<Item = f64> + Clone {
    (0..181).map(|i| -std::f64::consts::FRAC_PI_2 + i as f64 * std::f64::consts::PI / 180.0)
}

/// The walls of `segments` as lines, and the rays of scans at `poses` among them (walls 3 m
/// high, range 30 m).
pub(crate) fn rays_at(segments: &[Segment], poses: &[Pose2]) -> (WallPlanes, Vec<Vec<PairRay>>) {
    let world = World::from_segments(segments.to_vec(), 3.0, false);
    let planes = WallPlanes::new(segments);
    let rays = poses
        .iter()
        .map(|p| scan_rays(&world, &planes, p, bearings(), 30.0))
        .collect();
    (planes, rays)
}
