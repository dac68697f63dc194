//! Trajectory metrics: absolute trajectory error (ATE) and relative pose error (RPE), after
//! Sturm et al. 2012 ("A benchmark for the evaluation of RGB-D SLAM systems") in the plane,
//! and Kümmerle et al. 2009 for RPE over consecutive pairs.

use crate::geometry::{Pose2, wrap_angle};
use crate::matching::solve::RigidSolver;
use serde::Serialize;

/// ATE: RMSE of the positions after the best rigid SE(2) alignment of the estimate onto the
/// truth (closed form, least squares over positions).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Ate {
    /// Root mean square position error \[m\].
    pub rmse: f64,
    /// Largest position error \[m\].
    pub max: f64,
    /// The alignment applied to the estimate: `truth_from_estimate`.
    #[serde(skip)]
    pub alignment: Pose2,
    pub poses: usize,
}

/// RPE over consecutive pairs: how far each estimated step is from the true step.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Rpe {
    /// Median translation error of a step \[m\].
    pub median_translation: f64,
    /// 95th percentile (nearest rank) of the translation error \[m\].
    pub p95_translation: f64,
    /// Median heading error of a step \[rad\].
    pub median_rotation: f64,
    /// 95th percentile of the heading error \[rad\].
    pub p95_rotation: f64,
    /// Steps off by more than the bad-pair thresholds.
    pub bad_pairs: usize,
    pub pairs: usize,
}

/// A step is bad when off by more than this \[m\] (issue 4).
pub const BAD_PAIR_TRANSLATION: f64 = 0.05;
/// ... or by more than this \[rad\] (1 degree).
pub const BAD_PAIR_ROTATION: f64 = std::f64::consts::PI / 180.0;

/// ATE of `estimate` against `truth` (same length, same order). `None` when empty or when the
/// lengths differ.
pub fn ate(estimate: &[Pose2], truth: &[Pose2]) -> Option<Ate> {
    if estimate.is_empty() || estimate.len() != truth.len() {
        return None;
    }
    let mut solver = RigidSolver::new();
    for (e, t) in estimate.iter().zip(truth) {
        solver.add_point(&e.translation().into(), &t.translation().into(), 1.0);
    }
    // One pose, or all estimates at one spot: only a translation is defined.
    let alignment = solver.solve().unwrap_or_else(|_| {
        let n = estimate.len() as f64;
        let d = truth
            .iter()
            .zip(estimate)
            .fold(nalgebra::Vector2::zeros(), |acc, (t, e)| {
                acc + t.translation() - e.translation()
            })
            / n;
        Pose2::new(d.x, d.y, 0.0)
    });
    let errors: Vec<f64> = estimate
        .iter()
        .zip(truth)
        .map(|(e, t)| {
            (alignment.transform_point(&e.translation().into()) - t.translation())
                .coords
                .norm()
        })
        .collect();
    let rmse = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt();
    Some(Ate {
        rmse,
        max: errors.iter().copied().fold(0.0, f64::max),
        alignment,
        poses: errors.len(),
    })
}

/// The error of each consecutive step: (translation \[m\], |heading| \[rad\]).
pub fn step_errors(estimate: &[Pose2], truth: &[Pose2]) -> Vec<(f64, f64)> {
    estimate
        .windows(2)
        .zip(truth.windows(2))
        .map(|(e, t)| {
            let step_e = e[0].between(&e[1]);
            let step_t = t[0].between(&t[1]);
            let err = step_t.between(&step_e);
            (err.translation().norm(), wrap_angle(err.theta).abs())
        })
        .collect()
}

/// RPE over consecutive pairs. `None` with fewer than two poses or different lengths.
pub fn rpe(estimate: &[Pose2], truth: &[Pose2]) -> Option<Rpe> {
    if estimate.len() < 2 || estimate.len() != truth.len() {
        return None;
    }
    let errors = step_errors(estimate, truth);
    let mut tr: Vec<f64> = errors.iter().map(|e| e.0).collect();
    let mut rot: Vec<f64> = errors.iter().map(|e| e.1).collect();
    tr.sort_by(f64::total_cmp);
    rot.sort_by(f64::total_cmp);
    Some(Rpe {
        median_translation: median(&tr),
        p95_translation: nearest_rank(&tr, 0.95),
        median_rotation: median(&rot),
        p95_rotation: nearest_rank(&rot, 0.95),
        bad_pairs: errors
            .iter()
            .filter(|(t, r)| *t > BAD_PAIR_TRANSLATION || *r > BAD_PAIR_ROTATION)
            .count(),
        pairs: errors.len(),
    })
}

/// Median of sorted values (mean of the middle two for an even count); NaN when empty.
pub(crate) fn median(sorted: &[f64]) -> f64 {
    let n = sorted.len();
    if n == 0 {
        f64::NAN
    } else if n % 2 == 1 {
        sorted[n / 2]
    } else {
        0.5 * (sorted[n / 2 - 1] + sorted[n / 2])
    }
}

/// A distribution-free 95% interval for the median of sorted values: the order statistics
/// `n/2 -+ 1.96 sqrt(n) / 2` places from the middle (the number of values below the median
/// is binomial(n, 1/2), here in its normal approximation). NaN when empty; the whole range
/// when `n` is too small for the interval to lie inside it.
pub(crate) fn median_interval(sorted: &[f64]) -> [f64; 2] {
    let n = sorted.len();
    if n == 0 {
        return [f64::NAN; 2];
    }
    let half = 1.96 * (n as f64).sqrt() / 2.0;
    let centre = n as f64 / 2.0;
    // 1-based ranks, rounded outwards.
    let lo = (centre - half).floor().max(1.0) as usize;
    let hi = ((centre + half).ceil() as usize).min(n);
    [sorted[lo - 1], sorted[hi - 1]]
}

/// Nearest-rank percentile of sorted values, `q` in (0, 1]; NaN when empty.
pub(crate) fn nearest_rank(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let rank = (q * sorted.len() as f64).ceil() as usize;
    sorted[rank.clamp(1, sorted.len()) - 1]
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn square_loop() -> Vec<Pose2> {
        (0..40)
            .map(|i| {
                let a = i as f64 * 0.157;
                Pose2::new(3.0 * a.cos(), 2.0 * a.sin(), a + 1.0)
            })
            .collect()
    }

    /// 100 values: the interval runs from the 40th to the 60th (50 -+ 9.8, rounded outwards);
    /// one value is its own interval; none gives none.
    #[test]
    fn median_interval_takes_the_binomial_ranks() {
        let v: Vec<f64> = (1..=100).map(f64::from).collect();
        assert_eq!(median_interval(&v), [40.0, 60.0]);
        assert_eq!(median_interval(&[7.0]), [7.0, 7.0]);
        assert_eq!(median_interval(&[1.0, 2.0]), [1.0, 2.0]);
        assert!(median_interval(&[]).iter().all(|x| x.is_nan()));
    }

    /// Over repeated samples the interval holds the true median about 95% of the time.
    #[test]
    fn median_interval_covers_the_median_as_often_as_it_says() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(3);
        let trials = 2000;
        let covered = (0..trials)
            .filter(|_| {
                let mut v: Vec<f64> = (0..301).map(|_| rng.random_range(0.0..1.0)).collect();
                v.sort_by(f64::total_cmp);
                let [lo, hi] = median_interval(&v);
                lo <= 0.5 && 0.5 <= hi
            })
            .count();
        let share = covered as f64 / trials as f64;
        assert!((0.935..=0.975).contains(&share), "{share}");
    }

    #[test]
    fn ate_is_zero_for_a_rigidly_moved_copy() {
        let truth = square_loop();
        let offset = Pose2::new(5.0, -2.0, 2.5);
        let moved: Vec<Pose2> = truth.iter().map(|p| offset.compose(p)).collect();
        let a = ate(&moved, &truth).unwrap();
        assert!(a.rmse < 1e-9, "{a:?}");
        // The alignment undoes the offset.
        let undo = a.alignment.compose(&offset);
        assert!(undo.translation().norm() < 1e-9 && wrap_angle(undo.theta).abs() < 1e-9);
    }

    #[test]
    fn ate_of_a_two_point_stretch_is_known() {
        // Truth 2 m apart, estimate 2.2 m apart on the same line: best alignment centres them,
        // each end is off by 0.1 m.
        let truth = [Pose2::new(0.0, 0.0, 0.0), Pose2::new(2.0, 0.0, 0.0)];
        let est = [Pose2::new(0.0, 0.0, 0.0), Pose2::new(2.2, 0.0, 0.0)];
        let a = ate(&est, &truth).unwrap();
        assert!((a.rmse - 0.1).abs() < 1e-12);
    }

    #[test]
    fn rpe_counts_one_bad_step_exactly() {
        let truth: Vec<Pose2> = (0..11).map(|i| Pose2::new(i as f64, 0.0, 0.0)).collect();
        let mut est = truth.clone();
        // Step 4 -> 5 is 6 cm too long; every later pose carries the offset, so only that step
        // is off.
        for p in est.iter_mut().skip(5) {
            p.x += 0.06;
        }
        let r = rpe(&est, &truth).unwrap();
        assert_eq!(r.pairs, 10);
        assert_eq!(r.bad_pairs, 1);
        assert!(r.median_translation.abs() < 1e-12);
        assert!((r.p95_translation - 0.06).abs() < 1e-12);
    }

    #[test]
    fn rpe_flags_a_heading_error_over_one_degree() {
        let truth: Vec<Pose2> = (0..3).map(|i| Pose2::new(i as f64, 0.0, 0.0)).collect();
        let mut est = truth.clone();
        est[2].theta = 1.5f64.to_radians();
        let r = rpe(&est, &truth).unwrap();
        assert_eq!(r.bad_pairs, 1);
        assert!((r.p95_rotation - 1.5f64.to_radians()).abs() < 1e-12);
    }

    proptest! {
        #[test]
        fn rpe_ignores_a_global_rigid_motion(x in -10.0f64..10.0, y in -10.0f64..10.0, t in -3.0f64..3.0) {
            let truth = square_loop();
            let offset = Pose2::new(x, y, t);
            let moved: Vec<Pose2> = truth.iter().map(|p| offset.compose(p)).collect();
            let r = rpe(&moved, &truth).unwrap();
            prop_assert!(r.p95_translation < 1e-9 && r.p95_rotation < 1e-9);
            prop_assert_eq!(r.bad_pairs, 0);
        }
    }
}
