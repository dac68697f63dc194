//! Roll and pitch from the up vector (paper sect. 5.4), and their uncertainty.
//!
//! The angles themselves are [`Attitude::from_up`]: the paper's equations (derived in its
//! appendix A) in the contract's signs, `theta_x = atan2(up_y, up_z)` and `theta_y =
//! atan2(-up_x, hypot(up_y, up_z))`. Their sigmas propagate up's tangent-plane covariance
//! through that map.

use super::{LevelParams, up::UpSolution};
use crate::geometry::Attitude;

impl UpSolution {
    pub fn attitude(&self) -> Attitude {
        Attitude::from_up(&self.up)
    }

    /// The larger of [`Self::attitude_sigmas`] \[rad\].
    pub(crate) fn max_attitude_sigma(&self) -> f64 {
        self.attitude_sigmas().iter().fold(0f64, |a, &b| a.max(b))
    }

    /// 1-sigma of theta_x and theta_y \[rad\], propagating `cov` through `Attitude::from_up`.
    pub fn attitude_sigmas(&self) -> [f64; 2] {
        let h = 1e-6;
        // The Jacobian of (theta_x, theta_y) along each tangent direction, by central differences.
        let column = |k: usize| {
            let a = Attitude::from_up(&(self.up + self.basis[k] * h));
            let b = Attitude::from_up(&(self.up - self.basis[k] * h));
            nalgebra::Vector2::new(a.theta_x - b.theta_x, a.theta_y - b.theta_y) / (2.0 * h)
        };
        let j = nalgebra::Matrix2::from_columns(&[column(0), column(1)]);
        let c = j * self.cov * j.transpose();
        // An undetermined direction's infinite variance comes out as NaN through the
        // Jacobian (0 times infinity); `max` would turn that into a sigma of zero.
        let sd = |v: f64| {
            if v.is_nan() {
                f64::INFINITY
            } else {
                v.max(0.0).sqrt()
            }
        };
        [sd(c[(0, 0)]), sd(c[(1, 1)])]
    }
}

/// The reported 1-sigma of theta_x and theta_y \[rad\]: the propagated covariance, scaled by
/// `sigma_inflation`.
pub(crate) fn attitude_sigmas(sol: &UpSolution, params: &LevelParams) -> [f64; 2] {
    sol.attitude_sigmas().map(|s| s * params.sigma_inflation)
}
