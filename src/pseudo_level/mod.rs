//! Pseudo-level scans (paper sect. 6): one scan of the pose (the base scan) rotated into the
//! level frame with `level_from_robot`, its z dropped, keeping only points on walls so that
//! floor hits (phantom obstacles) never reach the 2D matcher.
//!
//! A point is kept when its ray had a return and it lies on a wall: inside a wall quad's span
//! or a grown wall patch (the paper's test; a quad only when its normal, leveled, is horizontal
//! within its uncertainty: one straddling a wall's top or foot is no wall), or, beyond the
//! paper, when the point in the same column of an adjacent scan lies nearly straight above or
//! below it after leveling (walls are vertical; on the floor the same two rays land far apart
//! horizontally at nearly the same height). That per-point test recovers corners and small
//! features that no quad covers.
//! Points at the floor's or ceiling's height (from floor/ceiling patches) are never kept. And a
//! point clearly above the floor (and below the ceiling, or below the scanner when no ceiling
//! was seen) is kept even when no other scan saw its wall: a far wall that only the highest
//! scan reaches before the others meet the floor is still a wall. The floor's height comes from
//! its patches, else from the lowest height at which many leveled points gather (a floor seen
//! by fewer scans than a patch needs is still a crowd of points at one height, and nothing
//! lies below it).
//! Then gaps of at most `max_gap` rays between kept points are filled, for rays with a return
//! (`keep.rs`). The base scan is the one whose points this test keeps most of (`base.rs`).

use crate::geometry::{Pose, rot_y};
use crate::level::LevelEstimate;
use crate::scan::Scan;
use nalgebra::{Matrix3, Vector3};

mod base;
mod keep;

/// Parameters of the pseudo-level scan.
#[derive(Clone, Debug, PartialEq)]
pub struct PseudoLevelParams {
    /// Gaps of at most this many rays between kept points are filled \[rays\]. Default 3.
    pub max_gap: usize,
    /// The per-point vertical test: a pair of points in adjacent scans is wall-like when its
    /// height difference exceeds this many times its horizontal distance (less noise) \[1\].
    /// Default 1.5; 0 turns the test off.
    pub vertical_ratio: f64,
    /// Points within this height of the floor or ceiling, plus three sigmas of their own
    /// vertical noise (the range noise times the leveled ray's vertical component,
    /// `sigma |u_z|`), are never kept \[m\]. It stands for what that noise model leaves out: a
    /// floor flat to about a centimetre, and its height's own error (the median of its
    /// patches' points, a few millimetres). Default 0.01: at 0.05, the wall hits within that
    /// band of the floor, a wall's foot, were two thirds of the wall hits lost (1.7-8% of the
    /// base scan's wall hits at 1-10 cm, docs/ESTIMATOR.md sect. 2), for no fewer floor hits
    /// kept.
    pub floor_margin: f64,
    /// Keep points that lie clear of the floor (and the ceiling) by their height alone, when
    /// the floor's height is known: by `floor_margin`, plus three sigmas of the range noise
    /// along the vertical, plus two sigmas of the attitude at the point's distance (two, not
    /// three: the floor's height, measured from the same leveled points, shares much of that
    /// error). Default true.
    pub height_test: bool,
}

impl Default for PseudoLevelParams {
    fn default() -> Self {
        Self {
            max_gap: 3,
            vertical_ratio: 1.5,
            floor_margin: 0.01,
            height_test: true,
        }
    }
}

/// Builds the pseudo-level 2D scan of a pose from its scans and their estimate. Metadata come
/// from the base scan: `sequence`, planar `odometry`/`true_pose`/`estimate`, `timestamp` and
/// unknown fields. A failed pose gives a scan with every ray invalid.
pub fn pseudo_level_scan(scans: &[Scan], est: &LevelEstimate, params: &PseudoLevelParams) -> Scan {
    pseudo_level_scan_and_base(scans, est, params).0
}

/// [`pseudo_level_scan`] and its base scan's index in `scans` ([`base_scan_index`]), for a
/// caller that needs both: the choice tries every scan's keep test, once.
pub fn pseudo_level_scan_and_base(
    scans: &[Scan],
    est: &LevelEstimate,
    params: &PseudoLevelParams,
) -> (Scan, usize) {
    let level_from_robot = base::level_from_robot(est);
    // The base scan and its kept rays: for a leveled pose, the scan that keeps most.
    let (base_index, kept) = match base::most_kept_row(est, params, &level_from_robot) {
        Some((row, kept)) => (
            est.grid.as_ref().map_or(0, |g| g.scan_index[row]),
            Some(kept),
        ),
        None => (base_scan_index(scans, est, params), None),
    };
    let Some(base) = scans.get(base_index) else {
        return (Scan::default(), base_index);
    };
    let n = base.nrays();
    let keep = kept
        .filter(|k| k.len() == n)
        .unwrap_or_else(|| vec![false; n]);
    let elevation = base.elevation.unwrap_or(0.0);
    // Beam directions: `level_from_robot · Ry(e) · (cos phi, sin phi, 0)` (contract), with the
    // rotations composed once.
    let level_from_scanner: Matrix3<f64> = level_from_robot * rot_y(elevation).matrix();
    let mut out = Scan {
        sequence: base.sequence,
        odometry: base.odometry.map(planar),
        true_pose: base.true_pose.map(planar),
        estimate: base.estimate.map(planar),
        timestamp: base.timestamp,
        extra: base.extra.clone(),
        theta: Vec::with_capacity(n),
        readings: Vec::with_capacity(n),
        valid: Vec::with_capacity(n),
        ..Scan::default()
    };
    // `Scan::point_in_robot`'s arithmetic, with its rotation and offset built once per scan
    // and one sincos per ray shared with the direction.
    let robot_from_scanner = rot_y(elevation);
    let offset = base.hinge_offset_vector();
    // The estimate's sines and cosines are those of every scan's bearings, the base's too.
    let trig = est.bearing_trig.as_deref().filter(|t| t.len() == n);
    for (i, &kept) in keep.iter().enumerate() {
        let (sp, cp) = trig.map_or_else(|| base.theta[i].sin_cos(), |t| t[i]);
        let ray = Vector3::new(cp, sp, 0.0);
        // A hinge that moved while it scanned: this ray's own elevation (`Scan::ray_elevation`).
        let own = base.ray_elevation.as_ref().map(|e| rot_y(e[i]));
        let robot_from_ray = own.as_ref().unwrap_or(&robot_from_scanner);
        let point = base
            .range(i)
            .map(|r| level_from_robot * (robot_from_ray * (offset + r * ray)));
        let bearing = match &point {
            Some(p) if p.x != 0.0 || p.y != 0.0 => p.y.atan2(p.x),
            _ => {
                let dir = match &own {
                    Some(rot) => level_from_robot * (rot * ray),
                    None => level_from_scanner * ray,
                };
                dir.y.atan2(dir.x)
            }
        };
        out.theta.push(bearing);
        match (kept, point) {
            (true, Some(p)) => {
                out.readings.push(Some(p.x.hypot(p.y)));
                out.valid.push(true);
            }
            _ => {
                out.readings.push(None);
                out.valid.push(false);
            }
        }
    }
    out.readings_sigma = Some(readings_sigma(&out, est.range_sigma));
    (out, base_index)
}

/// The pseudo-level scan's `readings_sigma`: on each kept ray the range noise the leveler used
/// (the scans' own when the data bear it out, else estimated; to 0.1 mm), so that a matcher
/// can fit its lines to it; null where the reading is. A leveled range is the ray's range times
/// the cosine of the ray's small angle to the level plane: the ray's noise.
fn readings_sigma(out: &Scan, range_sigma: f64) -> Vec<Option<f64>> {
    let used = ((range_sigma * 1e4).round() / 1e4).max(1e-4);
    out.readings.iter().map(|r| r.map(|_| used)).collect()
}

/// The index of the base scan in `scans` (sect. 6): for a leveled pose, the scan whose
/// pseudo-level scan keeps most wall points (`base.rs`); for a failed pose, the one
/// the estimate chose (most points on walls), or, when it failed before choosing (too few
/// scans, inconsistent scans), the scan nearest level elevation.
pub fn base_scan_index(scans: &[Scan], est: &LevelEstimate, params: &PseudoLevelParams) -> usize {
    base::most_kept(est, params)
        .or(est.base_scan)
        .or_else(|| {
            (0..scans.len()).min_by(|&a, &b| {
                let ea = scans[a].elevation.unwrap_or(0.0).abs();
                let eb = scans[b].elevation.unwrap_or(0.0).abs();
                ea.total_cmp(&eb)
            })
        })
        .unwrap_or(0)
}

fn planar(p: Pose) -> Pose {
    Pose::planar(p.x, p.y, p.rz)
}
