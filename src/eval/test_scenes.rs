//! Scenes for the bounds' tests ([`super::pair_bound`], [`super::path_bound`]): walls from
//! coordinates, and the noise-free rays of 181-ray, 180-degree scans at given poses; and for
//! the last stage's ([`super::true_segments`], `level::ml::discover`): a tilted pose's scans
//! in a box room.

use super::bound::WallPlanes;
use super::pair_bound::{PairRay, scan_rays};
use crate::geometry::{Pose, Pose2};
use crate::plan::{Segment, box_plan};
use crate::scan::Scan;
use crate::simulate::{ScannerParams, World, elevations_centred, simulate_pose};
use nalgebra::Point2;
use rand::SeedableRng;
use rand::rngs::ChaCha8Rng;

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

/// A pose at (2, 1.5) in a 6 x 4 m room with a ceiling `height` m high, tilted by `(ry, rx)`
/// \[rad\], met by four scans 5 degrees apart at range noise `noise` (stream `seed`): the
/// truth, the scans, the world and its walls as planes.
pub(crate) fn tilted_room_scans(
    height: f64,
    (ry, rx): (f64, f64),
    noise: f64,
    seed: u64,
) -> (Pose, Vec<Scan>, World, WallPlanes) {
    let plan = box_plan(6.0, 4.0, height, true);
    let world = World::from_plan(&plan);
    let truth = Pose {
        x: 2.0,
        y: 1.5,
        z: 0.45,
        rz: 0.4,
        ry,
        rx,
    };
    let scanner = ScannerParams {
        noise_sigma: noise,
        ..ScannerParams::default()
    };
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let elevations = elevations_centred(4, 5.0_f64.to_radians());
    let scans = simulate_pose(&world, 0, &truth, &elevations, &scanner, &mut rng);
    (truth, scans, world, WallPlanes::new(&plan.segments()))
}
