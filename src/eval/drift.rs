//! Drift over path segments, the KITTI odometry benchmark's measure (Geiger, Lenz and Urtasun
//! 2012) in 2D: from every start pose, the segment ends at the first pose at least `L` metres of
//! reference path later; the error of the estimated relative motion against the reference's,
//! translation as a share of `L` and heading per metre, averaged over all segments.
//!
//! Why beside RPE: a SLAM-corrected reference jitters by centimetres from one scan to the next,
//! more than a good matcher errs per step, but that jitter does not accumulate, so over metres
//! of path the reference is good to a few centimetres while the matcher's drift grows.

use crate::geometry::{Pose2, wrap_angle};
use serde::Serialize;

/// The segment lengths `eval real` reports \[m\].
pub const DRIFT_LENGTHS: [f64; 4] = [1.0, 2.0, 5.0, 10.0];

/// Drift over segments of one length.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Drift {
    /// Reference path length of each segment \[m\].
    pub length: f64,
    /// Segments measured (start poses with a pose `length` later).
    pub segments: usize,
    /// Mean translational error over `length` \[%\].
    pub translation_percent: f64,
    /// Mean heading error per metre of path \[deg/m\].
    pub rotation_deg_per_m: f64,
}

/// Drift of `estimate` against `reference` (same length, same order) over segments of
/// `length` metres of reference path. `None` when the lengths differ, `length` is not positive,
/// or the path is shorter than `length`.
pub fn segment_drift(estimate: &[Pose2], reference: &[Pose2], length: f64) -> Option<Drift> {
    if estimate.len() != reference.len() || length.is_nan() || length <= 0.0 {
        return None;
    }
    // distance[i]: reference path length from the first pose to pose i.
    let mut distance = Vec::with_capacity(reference.len());
    let mut total = 0.0;
    for (i, p) in reference.iter().enumerate() {
        if i > 0 {
            total += (p.translation() - reference[i - 1].translation()).norm();
        }
        distance.push(total);
    }
    let (mut segments, mut trans, mut rot) = (0usize, 0.0, 0.0);
    let mut end = 0;
    for start in 0..reference.len() {
        // The end only moves forward as the start does: one pass over the path.
        end = end.max(start);
        while end < reference.len() && distance[end] - distance[start] < length {
            end += 1;
        }
        if end == reference.len() {
            break;
        }
        let truth = reference[start].between(&reference[end]);
        let est = estimate[start].between(&estimate[end]);
        let error = truth.between(&est);
        trans += error.translation().norm() / length;
        rot += wrap_angle(error.theta).abs() / length;
        segments += 1;
    }
    (segments > 0).then(|| Drift {
        length,
        segments,
        translation_percent: 100.0 * trans / segments as f64,
        rotation_deg_per_m: (rot / segments as f64).to_degrees(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn straight(n: usize, step: f64) -> Vec<Pose2> {
        (0..n)
            .map(|i| Pose2::new(step * i as f64, 0.0, 0.0))
            .collect()
    }

    #[test]
    fn a_perfect_estimate_has_no_drift_and_counts_every_full_segment() {
        let r = straight(21, 0.5); // 10 m of path
        let d = segment_drift(&r, &r, 2.0).unwrap();
        // Starts 0..=16 have a pose 2 m on (4 steps).
        assert_eq!(d.segments, 17);
        assert_eq!((d.translation_percent, d.rotation_deg_per_m), (0.0, 0.0));
        assert_eq!(segment_drift(&r, &r, 10.5), None);
        assert_eq!(segment_drift(&r, &r[1..], 1.0), None);
    }

    #[test]
    fn a_scale_error_drifts_by_its_own_share() {
        // Every step 1% too long: each segment ends 1% of its length off.
        let r = straight(41, 0.25);
        let e = straight(41, 0.2525);
        for length in DRIFT_LENGTHS {
            let d = segment_drift(&e, &r, length).unwrap();
            assert!((d.translation_percent - 1.0).abs() < 1e-9, "{d:?}");
            assert_eq!(d.rotation_deg_per_m, 0.0);
        }
    }

    #[test]
    fn a_constant_heading_error_per_step_is_degrees_per_metre() {
        // The estimate turns 0.1 degree per 0.5 m step on a straight reference: at the segment
        // end the heading is off by 0.2 deg per metre; the translation error is brute-forced.
        let r = straight(41, 0.5);
        let mut e = vec![Pose2::identity()];
        for _ in 1..41 {
            let last = *e.last().unwrap();
            e.push(last.compose(&Pose2::new(0.5, 0.0, 0.1f64.to_radians())));
        }
        let d = segment_drift(&e, &r, 5.0).unwrap();
        assert!((d.rotation_deg_per_m - 0.2).abs() < 1e-9, "{d:?}");
        let brute: f64 = (0..31)
            .map(|s| {
                let err = r[s].between(&r[s + 10]).between(&e[s].between(&e[s + 10]));
                err.translation().norm() / 5.0
            })
            .sum::<f64>()
            / 31.0;
        assert!((d.translation_percent - 100.0 * brute).abs() < 1e-9);
        assert_eq!(d.segments, 31);
    }
}
