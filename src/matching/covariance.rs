//! The covariance of an ICP match over (x, y, yaw).
//!
//! ICP minimises `Σ w_i r_i(x)²` over the pose `x = (t_x, t_y, θ)`. At the minimum, with
//! `J_i = ∂r_i/∂x`, the Gauss-Newton information is `H = Σ w_i J_iᵀ J_i` and the spread of the
//! gradient is `B = Σ w_i² r_i² J_iᵀ J_i`; the estimate's covariance is the sandwich
//! `H⁻¹ B H⁻¹` (White 1980's heteroscedasticity-consistent estimator; Censi 2007, "An accurate
//! closed-form estimate of ICP's covariance", derives the same first-order propagation of the
//! measurement noise through the ICP minimum). It needs no assumed noise level: the residuals
//! themselves say how noisy the pairs are, and the weights cancel when they are only a scale.
//!
//! A pair's residual does not show the error of the line it is matched to where that line,
//! fitted through samples a beam spacing apart, misses the surface between them (far walls,
//! corners): the same in every iteration, so it biases the match rather than scattering it.
//! Its spread is therefore the residual and, in quadrature, `IcpParams::sampling_error` times
//! the pair's range.
//!
//! The sandwich treats pairs as independent. They are not (neighbouring rays share their
//! reference line, trimming keeps the smallest residuals), so the matcher widens it by
//! `inflation` before reporting it.

use nalgebra::{Matrix3, Point2, Vector3};

/// How the match's covariance is widened beyond the sandwich estimate ([`Sandwich`]).
/// The sandwich `H⁻¹ B H⁻¹` treats the kept residuals as independent; they are not: the
/// reference lines are fitted from the same noisy neighbours, trimming drops the largest
/// residuals, and a wall's discretisation differs between the scans. The factor below is
/// `noise_inflation · (1 + (rms / noise_knee)²) · max(1, rays per degree)` on every variance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CovarianceParams {
    /// Variance factor at low residuals [-]. Default 3.5: with it and `sampling_fraction` the
    /// true step error is within 3 sigma on 98.9-100% of ok steps on simulated runs in the
    /// example rooms (181 and 361 rays, 1 and 3 cm noise, both modes;
    /// tests/matching_covariance.rs), the mean NEES a tenth to two thirds of its Gaussian
    /// value: the errors have heavier tails than a Gaussian of their spread. 2.5 or 2 lets
    /// far walls' tails out again on the CARMEN logs' paths (docs/RESULTS.md).
    pub noise_inflation: f64,
    /// RMS residual at which the factor doubles \[m\]. Default 0.012: above about a centimetre
    /// of noise the reference lines' own error, which the residuals of the source scan do not
    /// show, grows faster than the residuals do.
    pub noise_knee: f64,
    /// A pair's surface error between samples, as a fraction of the scan's beam spacing at
    /// the pair's range [-] (`IcpParams::sampling_error`). Default 0.1: on simulated runs along
    /// the CARMEN logs' own paths and rooms (`scripts/log_to_plan.py`), far walls sampled every
    /// 35 cm and turns on the spot left 1.5-3% of steps beyond 3 sigma in yaw without it; with
    /// it every axis of every log is within 3 sigma on 99.5% or more (docs/RESULTS.md).
    pub sampling_fraction: f64,
}

impl Default for CovarianceParams {
    fn default() -> Self {
        Self {
            noise_inflation: 3.5,
            noise_knee: 0.012,
            sampling_fraction: 0.1,
        }
    }
}

/// Accumulates `H` and `B` over the final correspondences.
#[derive(Clone, Copy, Debug, Default)]
pub struct Sandwich {
    h: Matrix3<f64>,
    b: Matrix3<f64>,
}

impl Sandwich {
    /// Adds residual `r` with Jacobian `j` (w.r.t. t_x, t_y, θ) and weight `w`.
    #[inline]
    pub fn add(&mut self, j: Vector3<f64>, r: f64, w: f64) {
        let jj = j * j.transpose();
        self.h += w * jj;
        self.b += (w * w * r * r) * jj;
    }

    /// `H⁻¹ B H⁻¹`, symmetrised; `None` when `H` is singular (a direction nothing pins).
    pub fn covariance(&self) -> Option<Matrix3<f64>> {
        let scale = self.h.trace().abs();
        if scale.is_nan() || scale <= 0.0 || self.h.determinant().abs() <= 1e-15 * scale.powi(3) {
            return None;
        }
        let h_inv = self.h.try_inverse()?;
        let c = h_inv * self.b * h_inv;
        Some((c + c.transpose()) * 0.5)
    }

    /// The sandwich of the estimate's part along `basis` (pose-space vectors, the directions a
    /// remapped solve took from the scan): with `x = x₀ + G z`, the rows' Jacobians over `z`
    /// are `Gᵀ J`, so `H_z = Gᵀ H G`, `B_z = Gᵀ B G` and the covariance is
    /// `G H_z⁻¹ B_z H_z⁻¹ Gᵀ` (rank `basis.len()`). `None` when `H_z` is singular.
    pub fn covariance_along(&self, basis: &[Vector3<f64>]) -> Option<Matrix3<f64>> {
        let g = nalgebra::Matrix3xX::from_columns(basis);
        let h = g.transpose() * self.h * &g;
        let scale = h.trace().abs();
        if scale.is_nan() || scale <= 0.0 {
            return None;
        }
        let h_inv = h.clone().cholesky()?.inverse();
        let c = &g * (&h_inv * (g.transpose() * self.b * &g) * &h_inv) * g.transpose();
        let c = Matrix3::from_iterator(c.iter().copied());
        Some((c + c.transpose()) * 0.5)
    }
}

/// The variance factor for what the sandwich cannot see:
/// `noise_inflation · (1 + (rms / noise_knee)²) · max(1, rays per degree)`. Denser scans do
/// not pin the pose better in proportion to their rays, because neighbouring rays' errors are
/// correlated through the lines fitted to them; one ray per degree is where the simulated runs
/// stop gaining.
pub(crate) fn inflation(params: &CovarianceParams, rms: f64, rays_per_degree: f64) -> f64 {
    let knee = params.noise_knee.max(f64::MIN_POSITIVE);
    params.noise_inflation * (1.0 + (rms / knee).powi(2)) * rays_per_degree.max(1.0)
}

/// Angular density of a scan's rays [1/deg]: the inverse of the median bearing gap between
/// consecutive points (robot frame, ray order). The median ignores the gaps of dropped rays.
/// 0 with fewer than two points.
pub fn rays_per_degree(points: &[Point2<f64>]) -> f64 {
    rays_per_degree_from(points, &Point2::origin())
}

/// [`rays_per_degree`] of points seen from `sensor`.
pub(crate) fn rays_per_degree_from(points: &[Point2<f64>], sensor: &Point2<f64>) -> f64 {
    let bearings: Vec<f64> = points
        .iter()
        .map(|p| (p.y - sensor.y).atan2(p.x - sensor.x))
        .collect();
    let mut gaps: Vec<f64> = bearings
        .windows(2)
        .map(|w| crate::geometry::wrap_angle(w[1] - w[0]).abs())
        .filter(|g| *g > 0.0)
        .collect();
    if gaps.is_empty() {
        return 0.0;
    }
    let mid = gaps.len() / 2;
    let (_, median, _) = gaps.select_nth_unstable_by(mid, f64::total_cmp);
    1.0 / median.to_degrees()
}

/// A covariance over (x, y, yaw) whose (x, y) are in the world frame, expressed in a frame
/// rotated by `frame_theta` from it: `Rᵀ Σ R` on the translation block. The pose relative to a
/// fixed reference at heading θ_r is `(R(θ_r)ᵀ (t - t_r), θ - θ_r)`, whose Jacobian is
/// `diag(R(θ_r)ᵀ, 1)`.
pub(crate) fn rotate_into(cov: &Matrix3<f64>, frame_theta: f64) -> Matrix3<f64> {
    let (s, c) = frame_theta.sin_cos();
    let j = Matrix3::new(c, s, 0.0, -s, c, 0.0, 0.0, 0.0, 1.0);
    let r = j * cov * j.transpose();
    // Exactly symmetric, as consumers of the 9 numbers expect.
    (r + r.transpose()) * 0.5
}

/// Two independent Gaussian estimates of the same pose fused: the information adds. `None`
/// when either is not invertible.
pub(crate) fn fuse(a: &Matrix3<f64>, b: &Matrix3<f64>) -> Option<Matrix3<f64>> {
    let info = a.try_inverse()? + b.try_inverse()?;
    let c = info.try_inverse()?;
    Some((c + c.transpose()) * 0.5)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_sandwich_of_homoscedastic_rows_is_sigma_squared_times_the_inverse_information() {
        // Rows along x, y and a yaw lever with the same |r| = sigma: H⁻¹ B H⁻¹ = σ² H⁻¹.
        let mut s = Sandwich::default();
        let sigma = 0.01;
        let js = [
            Vector3::new(1.0, 0.0, 0.5),
            Vector3::new(0.0, 1.0, -2.0),
            Vector3::new(0.7, 0.7, 3.0),
            Vector3::new(1.0, -0.2, 0.0),
        ];
        let mut h = Matrix3::zeros();
        for (k, j) in js.iter().enumerate() {
            s.add(*j, if k % 2 == 0 { sigma } else { -sigma }, 1.0);
            h += j * j.transpose();
        }
        let expected = h.try_inverse().unwrap() * sigma * sigma;
        assert!((s.covariance().unwrap() - expected).norm() < 1e-15);
    }

    #[test]
    fn a_constant_weight_cancels() {
        let mut a = Sandwich::default();
        let mut b = Sandwich::default();
        for k in 0..10 {
            let t = k as f64;
            let j = Vector3::new(t.cos(), t.sin(), 0.3 * t);
            a.add(j, 0.01 * (1.0 + t), 1.0);
            b.add(j, 0.01 * (1.0 + t), 7.0);
        }
        let (ca, cb) = (a.covariance().unwrap(), b.covariance().unwrap());
        assert!((ca - cb).norm() <= 1e-12 * ca.norm());
    }

    #[test]
    fn the_sandwich_along_a_basis_is_the_full_one_over_all_three_and_pins_only_its_span() {
        let mut s = Sandwich::default();
        for k in 0..10 {
            let t = k as f64;
            s.add(
                Vector3::new(t.cos(), t.sin(), 0.3 * t),
                0.01 * (1.0 + t),
                1.0,
            );
        }
        let axes = [Vector3::x(), Vector3::y(), Vector3::z()];
        let full = s.covariance().unwrap();
        assert!((s.covariance_along(&axes).unwrap() - full).norm() < 1e-12 * full.norm());
        // Over y and yaw only: nothing along x, and the 2x2 sandwich of those rows.
        let part = s.covariance_along(&axes[1..]).unwrap();
        assert!(part.row(0).norm() == 0.0 && part.column(0).norm() == 0.0);
        let mut sub = Sandwich::default();
        for k in 0..10 {
            let t = k as f64;
            sub.add(Vector3::new(0.0, t.sin(), 0.3 * t), 0.01 * (1.0 + t), 1.0);
        }
        let h = sub.h.fixed_view::<2, 2>(1, 1).into_owned();
        let b = sub.b.fixed_view::<2, 2>(1, 1).into_owned();
        let h_inv = h.try_inverse().unwrap();
        let expected = h_inv * b * h_inv;
        let got = part.fixed_view::<2, 2>(1, 1).into_owned();
        assert!((got - expected).norm() < 1e-9 * expected.norm());
    }

    #[test]
    fn parallel_rows_pin_nothing_across_them() {
        let mut s = Sandwich::default();
        for k in 0..10 {
            s.add(Vector3::new(0.0, 1.0, k as f64 * 0.1), 0.01, 1.0);
        }
        assert!(s.covariance().is_none());
    }

    #[test]
    fn rays_per_degree_of_an_even_fan_ignores_dropped_rays() {
        let fan = |n: usize| -> Vec<Point2<f64>> {
            (0..n)
                .filter(|i| i % 7 != 3)
                .map(|i| {
                    let a = -std::f64::consts::FRAC_PI_2
                        + std::f64::consts::PI * i as f64 / (n - 1) as f64;
                    Point2::new(2.0 * a.cos(), 2.0 * a.sin())
                })
                .collect()
        };
        assert!((rays_per_degree(&fan(181)) - 1.0).abs() < 1e-9);
        assert!((rays_per_degree(&fan(361)) - 2.0).abs() < 1e-9);
        assert_eq!(rays_per_degree(&[Point2::new(1.0, 0.0)]), 0.0);
    }

    #[test]
    fn rotating_into_the_reference_frame_turns_the_ellipse_back() {
        // Long along the world's x; seen from a frame turned by 90 degrees it is long along y.
        let c = Matrix3::from_diagonal(&Vector3::new(4.0, 1.0, 0.5));
        let r = rotate_into(&c, std::f64::consts::FRAC_PI_2);
        let expected = Matrix3::from_diagonal(&Vector3::new(1.0, 4.0, 0.5));
        assert!((r - expected).norm() < 1e-12);
    }

    #[test]
    fn fusing_equal_estimates_halves_the_covariance() {
        let c = Matrix3::new(2.0, 0.3, 0.1, 0.3, 1.0, 0.0, 0.1, 0.0, 0.5);
        assert!((fuse(&c, &c).unwrap() - c * 0.5).norm() < 1e-12);
    }

    #[test]
    fn inflation_follows_its_formula() {
        let p = CovarianceParams {
            noise_inflation: 2.0,
            noise_knee: 0.01,
            ..CovarianceParams::default()
        };
        assert!((inflation(&p, 0.01, 0.5) - 4.0).abs() < 1e-12);
        assert!((inflation(&p, 0.0, 2.0) - 4.0).abs() < 1e-12);
    }
}
