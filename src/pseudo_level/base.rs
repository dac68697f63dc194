//! The base scan of the pseudo-level scan (sect. 6): the paper takes "the scan with the most
//! wall points". Counted on the leveler's wall patches, that misjudges which scan sees most
//! wall when the noise is high (the patches' points are not the points the keep test keeps);
//! counted as the points the keep test itself keeps, the choice is the quantity the
//! pseudo-level scan delivers. Measured (robust estimator, the example plans at seed 1): the
//! chosen scan's wall hits over the best single scan's rose from 0.87-0.96 to 0.99-1.00.

use super::PseudoLevelParams;
use super::keep::{Surfaces, kept_in_row};
use crate::level::LevelEstimate;
use nalgebra::Matrix3;
use std::cmp::Reverse;

/// The grid row whose scan keeps most wall points, with its kept mask (one per column), for a
/// leveled pose; `None` for a failed one. Ties go to the estimate's own base scan (most
/// points on walls), then to the scan nearest level elevation.
pub(super) fn most_kept_row(
    est: &LevelEstimate,
    params: &PseudoLevelParams,
    level_from_robot: &Matrix3<f64>,
) -> Option<(usize, Vec<bool>)> {
    let grid = est.grid.as_ref().filter(|_| est.is_ok())?;
    let surfaces = Surfaces::of(grid, est, params, level_from_robot);
    (0..grid.rows())
        .map(|row| {
            let kept = kept_in_row(grid, est, params, &surfaces, row, level_from_robot);
            (row, kept)
        })
        .max_by_key(|(row, kept)| {
            let n = kept.iter().filter(|&&k| k).count();
            let own = est.base_scan == Some(grid.scan_index[*row]);
            // Elevations in micro-radians: an integer key, as `max_by_key` needs.
            let level = Reverse((grid.elevation[*row].abs() * 1e6) as i64);
            (n, own, level)
        })
}

/// The index among the pose's scans of [`most_kept_row`]'s scan.
pub(super) fn most_kept(est: &LevelEstimate, params: &PseudoLevelParams) -> Option<usize> {
    let level_from_robot = level_from_robot(est);
    let (row, _) = most_kept_row(est, params, &level_from_robot)?;
    est.grid.as_ref().map(|g| g.scan_index[row])
}

/// The estimate's rotation from the robot frame into the level frame (identity when failed).
pub(super) fn level_from_robot(est: &LevelEstimate) -> Matrix3<f64> {
    *est.attitude.unwrap_or_default().level_from_robot().matrix()
}
