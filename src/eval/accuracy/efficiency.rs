//! Per-pose efficiency against the Cramér-Rao bound (issue 26, item 3): each pose's error and
//! sigma over its own bound, what an efficient estimator would score on the same poses, and
//! whether the sigmas are honest (the share of errors within 1, 2, 3 sigmas per axis, against
//! the normal's 68.3, 95.4 and 99.7%).

use super::pose::PoseOutcome;
use crate::eval::metrics::{median, median_interval};
use crate::eval::true_segments::TrueSegmentsFit;
use nalgebra::{Matrix2, Vector2};
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};

/// One pose's attitude error and sigmas per axis, and its bound.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AxisRecord {
    /// Estimate minus truth, per axis (any unit shared with `sigma` and `bound`).
    pub error: [f64; 2],
    /// Reported 1-sigma per axis.
    pub sigma: [f64; 2],
    /// The larger of the pose's two per-axis bounds.
    pub bound: f64,
    /// An efficient estimator's `max(|ex|, |ey|) / bound` on this pose.
    pub efficient: f64,
}

impl AxisRecord {
    /// The estimator's records: leveled poses with a finite bound.
    pub fn of_leveled(o: &PoseOutcome) -> Option<Self> {
        Some(AxisRecord {
            error: o.axis_errors_deg()?,
            sigma: o.sigmas_deg?,
            bound: o.bound_deg.filter(|b| b.is_finite())?,
            efficient: o.efficient_over_bound?,
        })
    }

    /// The maximum-likelihood core's records on the true segmentation.
    pub fn of_true_segments(o: &PoseOutcome) -> Option<Self> {
        Self::of_fit(o, o.true_segments?)
    }

    /// The leveler's last stage's records on the true segmentation.
    pub fn of_true_segments_last_stage(o: &PoseOutcome) -> Option<Self> {
        Self::of_fit(o, o.true_segments_last_stage?)
    }

    fn of_fit(o: &PoseOutcome, fit: TrueSegmentsFit) -> Option<Self> {
        let deg = fit.attitude.map(f64::to_degrees);
        Some(AxisRecord {
            error: [deg[0] - o.truth_deg[0], deg[1] - o.truth_deg[1]],
            sigma: fit.sigmas.map(f64::to_degrees),
            bound: o.bound_deg.filter(|b| b.is_finite())?,
            efficient: o.efficient_over_bound?,
        })
    }
}

/// Efficiency statistics over a set of poses.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Efficiency {
    /// Poses counted (with an estimate and a finite bound).
    pub efficiency_poses: usize,
    /// Median of `max(|ex|, |ey|)` over the larger bound: about 0.8 for an efficient
    /// estimator (below 1: the axes are unequal and correlated).
    pub error_over_bound: f64,
    /// A 95% interval for that median ([`median_interval`]): a cell of a few hundred poses
    /// knows it to about +-0.05 (docs/ESTIMATOR.md, section 22).
    pub error_over_bound_interval: [f64; 2],
    /// Median of the larger reported sigma over the larger bound: 1 for an efficient
    /// estimator with honest sigmas.
    pub sigma_over_bound: f64,
    /// Median of the same error for an efficient estimator on the same poses (errors drawn
    /// from each pose's bound covariance).
    pub efficient_over_bound: f64,
    /// Share of poses whose error lies within 1, 2 and 3 reported sigmas, per axis
    /// (`[k-1][axis]`, theta_x then theta_y); honest Gaussian sigmas give 0.683, 0.954, 0.997.
    pub within_sigma: [[f64; 2]; 3],
}

impl Efficiency {
    pub fn of(records: &[AxisRecord]) -> Self {
        let sorted = |f: &dyn Fn(&AxisRecord) -> f64| {
            let mut v: Vec<f64> = records.iter().map(f).collect();
            v.sort_by(f64::total_cmp);
            v
        };
        let error_over_bound = sorted(&|r| r.error[0].abs().max(r.error[1].abs()) / r.bound);
        let n = records.len();
        let mut within = [[f64::NAN; 2]; 3];
        if n > 0 {
            for (k, row) in within.iter_mut().enumerate() {
                for (axis, cell) in row.iter_mut().enumerate() {
                    let inside = records
                        .iter()
                        .filter(|r| r.error[axis].abs() <= (k + 1) as f64 * r.sigma[axis])
                        .count();
                    *cell = inside as f64 / n as f64;
                }
            }
        }
        Efficiency {
            efficiency_poses: n,
            error_over_bound: median(&error_over_bound),
            error_over_bound_interval: median_interval(&error_over_bound),
            sigma_over_bound: median(&sorted(&|r| r.sigma[0].max(r.sigma[1]) / r.bound)),
            efficient_over_bound: median(&sorted(&|r| r.efficient)),
            within_sigma: within,
        }
    }
}

/// An efficient estimator's error on a pose with bound covariance `cov`: `e = C^1/2 z` for a
/// standard normal `z` drawn from `rng`, scored as `max(|ex|, |ey|)` over the larger of the
/// two per-axis bounds. `None` when `cov` is not positive definite.
pub fn efficient_over_bound<R: Rng + ?Sized>(cov: &Matrix2<f64>, rng: &mut R) -> Option<f64> {
    let chol = cov.cholesky()?;
    let z = Vector2::new(StandardNormal.sample(rng), StandardNormal.sample(rng));
    let e = chol.l() * z;
    Some(e.x.abs().max(e.y.abs()) / cov[(0, 0)].sqrt().max(cov[(1, 1)].sqrt()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand::rngs::ChaCha8Rng;

    /// Errors drawn from the bound itself, with the bound as sigma: the shares within 1, 2, 3
    /// sigma are the normal's, sigma over bound is 1, and the error over bound is the
    /// efficient estimator's.
    #[test]
    fn an_efficient_honest_estimator_scores_as_the_normal_says() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let cov = Matrix2::new(4.0, 1.2, 1.2, 1.0);
        let chol = cov.cholesky().unwrap();
        let records: Vec<AxisRecord> = (0..20_000)
            .map(|_| {
                let z = Vector2::new(
                    StandardNormal.sample(&mut rng),
                    StandardNormal.sample(&mut rng),
                );
                let e = chol.l() * z;
                AxisRecord {
                    error: [e.x, e.y],
                    sigma: [2.0, 1.0],
                    bound: 2.0,
                    efficient: efficient_over_bound(&cov, &mut rng).unwrap(),
                }
            })
            .collect();
        let eff = Efficiency::of(&records);
        for (k, want) in [0.6827, 0.9545, 0.9973].iter().enumerate() {
            for axis in 0..2 {
                let got = eff.within_sigma[k][axis];
                assert!((got - want).abs() < 0.01, "{k} {axis}: {got}");
            }
        }
        assert_eq!(eff.sigma_over_bound, 1.0);
        assert!(
            (eff.error_over_bound - eff.efficient_over_bound).abs() < 0.03,
            "{eff:?}"
        );
        // x's error alone over its own sigma: the median of |z| is 0.674; the larger of two
        // correlated errors lies above it.
        assert!(
            eff.error_over_bound > 0.674 && eff.error_over_bound < 1.0,
            "{eff:?}"
        );
    }

    #[test]
    fn no_records_give_no_figures() {
        let eff = Efficiency::of(&[]);
        assert_eq!(eff.efficiency_poses, 0);
        assert!(eff.error_over_bound.is_nan() && eff.within_sigma[0][0].is_nan());
        assert_eq!(
            efficient_over_bound(
                &Matrix2::new(1.0, 2.0, 2.0, 1.0),
                &mut ChaCha8Rng::seed_from_u64(1)
            ),
            None
        );
    }
}
