//! How good the odometry really is: each accepted match's step against the odometry's, in
//! units of the odometry model's sigma for that step.
//!
//! The odometry model (`MatcherParams::odometry`, the `--prior-*` flags) decides which
//! directions the degeneracy-aware solve may take from the odometry and what a fallback step is
//! worth. A model that is too kind makes the solve fill a young map's unpinned direction from
//! an odometry centimetres off (10 cm and 5 degrees a step against a model of
//! 5 mm and 0.5 degree: steps 8 cm off on a CSM-style flat run). The matches themselves measure
//! the odometry: their steps are millimetres from the truth, so the odometry's error on a step
//! is its difference from the match. When the run's recent median of that error, over the
//! model's sigma, says the odometry is more than [`TRUST_UP_TO`] times noisier than modelled,
//! the model's sigmas are scaled up by the median's factor (translation and heading apart);
//! within that, the model stands as given.

use super::OdometryPrior;
use crate::geometry::Pose2;
use std::collections::VecDeque;

/// Accepted matches whose errors make the run's recent level [-].
const HISTORY: usize = 16;
/// Fewest matches before the model is judged [-]: a young map is where a wrong model costs.
const MIN_SEEN: usize = 3;
/// The model stands while the odometry's median error is at most this many times the model's
/// median [-]: sixteen errors put their own median within about a third of the true one.
const TRUST_UP_TO: f64 = 2.0;
/// Median of `|e| / sigma` for `e` the translation error, Gaussian with `sigma` in x and y
/// each (Rayleigh): `sqrt(2 ln 2)`.
const RAYLEIGH_MEDIAN: f64 = 1.177_410_022_515_474_7;
/// Median of `|e| / sigma` for a Gaussian heading error (half-normal).
const HALF_NORMAL_MEDIAN: f64 = 0.674_489_750_196_081_7;

/// The run's recent odometry errors over the model's sigmas, translation and heading, and
/// the factors they put on the model's sigmas (judged once per recorded match, read by every
/// solve).
#[derive(Clone, Debug)]
pub(super) struct OdometryCheck {
    translation: VecDeque<f64>,
    heading: VecDeque<f64>,
    factors: (f64, f64),
}

impl Default for OdometryCheck {
    fn default() -> Self {
        Self {
            translation: VecDeque::new(),
            heading: VecDeque::new(),
            factors: (1.0, 1.0),
        }
    }
}

/// The factor on the model's sigmas that `history` shows: its median where above
/// [`TRUST_UP_TO`] (from [`MIN_SEEN`] errors on), else 1.
fn factor(history: &VecDeque<f64>) -> f64 {
    if history.len() < MIN_SEEN {
        return 1.0;
    }
    // A copy on the stack: no allocation per match.
    let mut v = [0.0; HISTORY];
    for (slot, &z) in v.iter_mut().zip(history) {
        *slot = z;
    }
    let v = &mut v[..history.len()];
    let mid = v.len() / 2;
    let (_, median, _) = v.select_nth_unstable_by(mid, f64::total_cmp);
    if *median > TRUST_UP_TO { *median } else { 1.0 }
}

impl OdometryCheck {
    /// Notes an accepted match's step against the odometry's, both from the previous scan's
    /// pose (`model` the odometry model as given).
    pub fn record(&mut self, model: &OdometryPrior, odometry_step: &Pose2, matched_step: &Pose2) {
        let cov = model.step_covariance(odometry_step);
        let (s_xy, s_th) = (cov[(0, 0)].sqrt(), cov[(2, 2)].sqrt());
        let error = odometry_step.between(matched_step);
        let t = error.translation().norm() / s_xy / RAYLEIGH_MEDIAN;
        let r = error.theta.abs() / s_th / HALF_NORMAL_MEDIAN;
        for (history, z) in [(&mut self.translation, t), (&mut self.heading, r)] {
            if !z.is_finite() {
                continue;
            }
            if history.len() == HISTORY {
                history.pop_front();
            }
            history.push_back(z);
        }
        self.factors = (factor(&self.translation), factor(&self.heading));
    }

    /// `model` with its sigmas scaled by what the recent matches show, where they show the
    /// odometry more than [`TRUST_UP_TO`] times noisier than modelled.
    pub fn judged(&self, model: &OdometryPrior) -> OdometryPrior {
        let (k_t, k_r) = self.factors;
        OdometryPrior {
            trans_per_m: model.trans_per_m * k_t,
            trans_const: model.trans_const * k_t,
            rot_per_rad: model.rot_per_rad * k_r,
            rot_const: model.rot_const * k_r,
            ..*model
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_model_within_twice_the_odometrys_noise_stands_and_a_worse_one_is_scaled() {
        let model = OdometryPrior::default();
        let step = Pose2::new(0.1, 0.0, 0.0);
        let cov = model.step_covariance(&step);
        let (s_xy, s_th) = (cov[(0, 0)].sqrt(), cov[(2, 2)].sqrt());
        let mut check = OdometryCheck::default();
        // Errors at the model's own medians: nothing changes.
        for _ in 0..HISTORY {
            let matched = step.compose(&Pose2::new(
                s_xy * RAYLEIGH_MEDIAN,
                0.0,
                s_th * HALF_NORMAL_MEDIAN,
            ));
            check.record(&model, &step, &matched);
        }
        assert_eq!(check.judged(&model), model);
        // Ten times the translation noise, the heading as modelled: only translation scales.
        for _ in 0..HISTORY {
            let matched = step.compose(&Pose2::new(
                0.0,
                10.0 * s_xy * RAYLEIGH_MEDIAN,
                s_th * HALF_NORMAL_MEDIAN,
            ));
            check.record(&model, &step, &matched);
        }
        let judged = check.judged(&model);
        assert!((judged.trans_const / model.trans_const - 10.0).abs() < 1e-9);
        assert!((judged.trans_per_m / model.trans_per_m - 10.0).abs() < 1e-9);
        assert_eq!(
            (judged.rot_const, judged.rot_per_rad),
            (model.rot_const, model.rot_per_rad)
        );
    }

    #[test]
    fn too_few_matches_leave_the_model_as_given() {
        let model = OdometryPrior::default();
        let step = Pose2::new(0.5, 0.0, 0.1);
        let mut check = OdometryCheck::default();
        for _ in 0..MIN_SEEN - 1 {
            check.record(&model, &step, &step.compose(&Pose2::new(1.0, 1.0, 0.5)));
        }
        assert_eq!(check.judged(&model), model);
        check.record(&model, &step, &step.compose(&Pose2::new(1.0, 1.0, 0.5)));
        assert!(check.judged(&model).trans_const > 10.0 * model.trans_const);
    }
}
