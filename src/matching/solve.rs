//! Closed-form weighted least squares for a planar rigid motion, for both ICP metrics.
//!
//! Censi 2008 ("An ICP variant using a point-to-line metric", sect. IV) writes each residual as
//! linear in `x = (tx, ty, cos θ, sin θ)` and minimises the quadratic subject to
//! `cos² θ + sin² θ = 1` with a Lagrange multiplier. Point-to-point (Besl & McKay 1992) is the
//! special case of two rows per pair with normals along the axes, so one solver serves both
//! and both are exact (no linearisation of the rotation).
//!
//! Here the translation is eliminated first (it is unconstrained), which leaves a quadratic in
//! `r = (cos θ, sin θ)` on the unit circle; its global minimum is the root of the trust-region
//! secular equation on the interval where `S + λI` is positive semidefinite.
//!
//! Where the scan does not pin the motion (a corridor leaves its length free), the solve keeps
//! the directions it observes and takes the others from an anchor, the odometry: solution
//! remapping (Zhang, Kaess and Singh 2016, "On degeneracy of optimization-based state
//! estimation problems", sect. IV), with the directions found as the eigenvectors of the
//! scan's information whitened by the anchor's (their eigenvalues are how many times more the
//! scan knows along them than the odometry does).

use crate::geometry::{Pose2, minor_axis_2x2, wrap_angle};
use nalgebra::{Matrix2, Matrix3, Matrix4, Point2, Vector2, Vector3, Vector4};

/// A Gaussian prior on the result (e.g. from odometry), as weights in the ICP cost's units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PosePrior {
    /// The prior pose (`target_from_source`).
    pub pose: Pose2,
    /// Weight of the squared translation difference [1/m² in residual units: (σ_r/σ_xy)²].
    pub weight_xy: f64,
    /// Weight of the squared heading difference [(σ_r/σ_θ)², m²/rad²].
    pub weight_theta: f64,
}

/// Accumulates weighted residual rows `n · (R p + t - q)` and solves for `(R, t)`.
#[derive(Clone, Debug, Default)]
pub struct RigidSolver {
    m: Matrix4<f64>,
    g: Vector4<f64>,
    rows: usize,
}

/// Why no motion could be solved for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SolveError {
    /// The translation block is singular: nothing constrains the motion in some direction.
    Degenerate,
}

impl RigidSolver {
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds the residual `n · (R p + t - q)` with weight `w` (`n` need not be unit length).
    #[inline]
    pub fn add_row(&mut self, n: Vector2<f64>, p: &Point2<f64>, q: &Point2<f64>, w: f64) {
        let a = Vector4::new(n.x, n.y, n.x * p.x + n.y * p.y, n.y * p.x - n.x * p.y);
        let b = n.x * q.x + n.y * q.y;
        self.m += (w * a) * a.transpose();
        self.g += (w * b) * a;
        self.rows += 1;
    }

    /// Point-to-point pair: two rows, along x and along y.
    #[inline]
    pub fn add_point(&mut self, p: &Point2<f64>, q: &Point2<f64>, w: f64) {
        self.add_row(Vector2::x(), p, q, w);
        self.add_row(Vector2::y(), p, q, w);
    }

    /// Point-to-line pair: one row along the reference normal `n` (unit length).
    #[inline]
    pub fn add_line(&mut self, n: Vector2<f64>, p: &Point2<f64>, q: &Point2<f64>, w: f64) {
        self.add_row(n, p, q, w);
    }

    /// A Gaussian prior on the solution: `w_xy |t - t_p|² + w_theta |r - r_p|²` with
    /// `r = (cos θ, sin θ)`, which is `w_theta (θ - θ_p)²` near the prior. Still exact: the
    /// rotation part only adds a constant on the unit circle plus a linear pull.
    pub fn add_prior(&mut self, prior: &Pose2, w_xy: f64, w_theta: f64) {
        let (s, c) = prior.theta.sin_cos();
        self.m[(0, 0)] += w_xy;
        self.m[(1, 1)] += w_xy;
        self.m[(2, 2)] += w_theta;
        self.m[(3, 3)] += w_theta;
        self.g += Vector4::new(w_xy * prior.x, w_xy * prior.y, w_theta * c, w_theta * s);
    }

    pub fn rows(&self) -> usize {
        self.rows
    }

    /// The pose `T = (t, θ)` minimising `Σ w (n · (R p + t - q))²`, so that `T · p ≈ q`.
    pub fn solve(&self) -> Result<Pose2, SolveError> {
        self.solve_with(min_quadratic_on_circle)
    }

    /// [`solve`](Self::solve) as one step of a local method from heading `theta`: where the
    /// cost has two minima over the rotation, the one nearer `theta`. A scan that sees two
    /// walls and nothing else leaves its scale free (both lines pass through their corner,
    /// so scaling about it fits as well), and then the mirror image of the right rotation
    /// fits exactly as well as the rotation itself; the global minimum is a coin toss between
    /// them, where ICP from a good start wants the one it started near.
    pub fn solve_near(&self, theta: f64) -> Result<Pose2, SolveError> {
        let (sin, cos) = theta.sin_cos();
        self.solve_with(|s, h| min_quadratic_on_circle_near(s, h, &Vector2::new(cos, sin)))
    }

    fn solve_with(
        &self,
        min_on_circle: impl Fn(&Matrix2<f64>, &Vector2<f64>) -> Vector2<f64>,
    ) -> Result<Pose2, SolveError> {
        let a = self.m.fixed_view::<2, 2>(0, 0).into_owned();
        let b = self.m.fixed_view::<2, 2>(0, 2).into_owned();
        let d = self.m.fixed_view::<2, 2>(2, 2).into_owned();
        let gt = Vector2::new(self.g[0], self.g[1]);
        let gr = Vector2::new(self.g[2], self.g[3]);
        let scale = a.trace().abs().max(f64::MIN_POSITIVE);
        if a.determinant().abs() <= 1e-12 * scale * scale {
            return Err(SolveError::Degenerate);
        }
        let a_inv = a.try_inverse().ok_or(SolveError::Degenerate)?;
        // t = A⁻¹ (g_t - B r); substituting leaves r' S r - 2 h' r + const.
        let s = d - b.transpose() * a_inv * b;
        let s = (s + s.transpose()) * 0.5;
        let h = gr - b.transpose() * a_inv * gt;
        let r = min_on_circle(&s, &h);
        let t = a_inv * (gt - b * r);
        Ok(Pose2::new(t.x, t.y, r.y.atan2(r.x)))
    }
}

/// The anchor of a remapped solve: the odometry's pose and information, and how much more than
/// the odometry the scan must know along a direction to be trusted along it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Remap {
    /// The odometry's guess and its information, in the solve's (residual) units.
    pub anchor: PosePrior,
    /// Smallest ratio of the scan's information to the odometry's along a direction for the
    /// scan to set it [-] (`CheckParams::min_information_ratio`).
    pub min_ratio: f64,
    /// Below this `λ_min / λ_max` of the pairs' normal scatter, the scatter's minor axis is
    /// free whatever the information says [-] (`CheckParams::min_constraint_ratio`). Along a
    /// long wall the fitted normals' own noise (a few degrees at grazing rays, weighted up
    /// to 5 by incidence) looks like 10-40 times the odometry's information along it
    /// (measured on simulated 1.5 m steps through a hall), which re-association would not
    /// bear out: sliding along the wall finds the same wall.
    pub min_constraint_ratio: f64,
}

/// Which directions of (x, y, yaw) a remapped solve took from the anchor.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Remapped {
    /// Orthonormal eigenvectors of the whitened information (columns, coordinates `u` with
    /// pose `= anchor + scale ⊙ u`), the `free` ones first, then by rising eigenvalue.
    pub basis: Matrix3<f64>,
    /// How many leading columns of `basis` came from the anchor (0 to 3).
    pub free: usize,
    /// Whether the first column is the pairs' sliding axis (free whatever the information).
    pub sliding: bool,
    /// The whitening: the anchor's standard deviations in residual units, per (x, y, yaw).
    pub scale: Vector3<f64>,
    /// The eigenvalues of the whitened information, in `basis` order [-].
    pub ratios: Vector3<f64>,
}

impl Remapped {
    /// The free directions as unit vectors over (x [m], y [m], yaw [rad]).
    pub fn free_directions(&self) -> impl Iterator<Item = Vector3<f64>> + '_ {
        (0..self.free).map(|k| self.scale.component_mul(&self.basis.column(k)).normalize())
    }

    /// The observed directions in pose coordinates (not unit length): the scan's subspace.
    pub fn observed_basis(&self) -> impl Iterator<Item = Vector3<f64>> + '_ {
        (self.free..3).map(|k| self.scale.component_mul(&self.basis.column(k)))
    }

    /// The same directions seen from a frame turned by `theta` (x, y rotated by `R(θ)ᵀ`);
    /// the whitening is the same along x and y, so the basis stays orthonormal.
    pub fn rotated_into(&self, theta: f64) -> Remapped {
        let (s, c) = theta.sin_cos();
        let r = Matrix3::new(c, s, 0.0, -s, c, 0.0, 0.0, 0.0, 1.0);
        let same_xy = (self.scale.x - self.scale.y).abs() <= 1e-12 * self.scale.x.abs();
        debug_assert!(same_xy, "anisotropic whitening does not rotate");
        Remapped {
            basis: r * self.basis,
            ..*self
        }
    }

    /// `Σ_f s f fᵀ s` over the free whitened directions `f`, `s` the given standard deviations
    /// per (x, y, yaw): the covariance an anchor with those deviations gives the free part.
    pub fn free_covariance(&self, sigma: &Vector3<f64>) -> Matrix3<f64> {
        (0..self.free)
            .map(|k| {
                let v = sigma.component_mul(&self.basis.column(k));
                v * v.transpose()
            })
            .sum()
    }
}

impl RigidSolver {
    /// The Gauss-Newton information over (t_x, t_y, θ) at heading `theta`: `Jᵀ M J` with
    /// `J = ∂(t_x, t_y, cos θ, sin θ) / ∂(t_x, t_y, θ)`, the same `H` as the sandwich's.
    pub fn information_at(&self, theta: f64) -> Matrix3<f64> {
        let j = lift_jacobian(theta);
        j.transpose() * self.m * j
    }

    /// Half the cost's gradient over (t_x, t_y, θ) at `pose`: `Jᵀ (M x - g)`.
    fn half_gradient(&self, pose: &Pose2) -> Vector3<f64> {
        let (s, c) = pose.theta.sin_cos();
        let x = Vector4::new(pose.x, pose.y, c, s);
        lift_jacobian(pose.theta).transpose() * (self.m * x - self.g)
    }

    /// The motion over the directions the scan observes, the rest held at the anchor
    /// (solution remapping). With nothing free this is [`solve`](Self::solve) exactly; with
    /// something free, Gauss-Newton steps from `at` (projected onto the anchor's subspace)
    /// within the observed subspace, to convergence on these rows (the ICP loop re-associates
    /// and calls again). All three free is [`SolveError::Degenerate`]. `sliding`, a unit
    /// translation direction, is free in any case (the normal scatter's minor axis in a
    /// corridor).
    pub fn solve_remapped(
        &self,
        remap: &Remap,
        at: &Pose2,
        sliding: Option<Vector2<f64>>,
    ) -> Result<(Pose2, Remapped), SolveError> {
        let a = &remap.anchor;
        let inv_sqrt = |w: f64| 1.0 / w.max(f64::MIN_POSITIVE).sqrt();
        let scale = Vector3::new(
            inv_sqrt(a.weight_xy),
            inv_sqrt(a.weight_xy),
            inv_sqrt(a.weight_theta),
        );
        let d = Matrix3::from_diagonal(&scale);
        let info = d * self.information_at(at.theta) * d;
        let (basis, forced) = match sliding {
            None => (eigen_sorted(&info, Matrix3::identity(), 3), 0),
            // The sliding axis (whitened: x and y share one scale), then the eigenvectors of
            // the information on the plane orthogonal to it.
            Some(v) => {
                let e = Vector3::new(v.x, v.y, 0.0).normalize();
                let b1 = Vector3::new(-e.y, e.x, 0.0);
                let frame = Matrix3::from_columns(&[e, b1, Vector3::z()]);
                (eigen_sorted(&info, frame, 2), 1)
            }
        };
        let ratios = (basis.transpose() * info * basis).diagonal();
        let free = forced
            + (forced..3)
                .filter(|&k| ratios[k] < remap.min_ratio || ratios[k].is_nan())
                .count();
        let remapped = Remapped {
            basis,
            free,
            sliding: forced == 1,
            scale,
            ratios,
        };
        match free {
            0 => return self.solve_near(at.theta).map(|p| (p, remapped)),
            3 => return Err(SolveError::Degenerate),
            _ => {}
        }
        // u: whitened offset from the anchor; its free components are zeroed (set to the
        // anchor's), the observed ones move by Gauss-Newton.
        let offset = |p: &Pose2| {
            let dx = Vector3::new(
                p.x - a.pose.x,
                p.y - a.pose.y,
                wrap_angle(p.theta - a.pose.theta),
            );
            dx.component_div(&scale)
        };
        let pose_of = |u: &Vector3<f64>| {
            let dx = scale.component_mul(u);
            Pose2::new(a.pose.x + dx.x, a.pose.y + dx.y, a.pose.theta + dx.z)
        };
        let u0 = basis.transpose() * offset(at);
        let mut z: Vector3<f64> = Vector3::from_fn(|k, _| if k < free { 0.0 } else { u0[k] });
        let mut pose = pose_of(&(basis * z));
        for _ in 0..20 {
            let h = basis.transpose() * d * self.information_at(pose.theta) * d * basis;
            let grad = basis.transpose() * d * self.half_gradient(&pose);
            let obs = 3 - free;
            let h_obs = h.view((free, free), (obs, obs)).into_owned();
            let g_obs = grad.rows(free, obs).into_owned();
            let step = h_obs
                .cholesky()
                .ok_or(SolveError::Degenerate)?
                .solve(&g_obs);
            for k in 0..obs {
                z[free + k] -= step[k];
            }
            pose = pose_of(&(basis * z));
            if step.norm() < 1e-12 * (1.0 + z.norm()) {
                break;
            }
        }
        Ok((pose, remapped))
    }
}

/// An orthonormal basis from `frame` (orthonormal columns): its first `3 - n` columns as they
/// are, then the eigenvectors of `info` restricted to its last `n` columns, by rising
/// eigenvalue.
fn eigen_sorted(info: &Matrix3<f64>, frame: Matrix3<f64>, n: usize) -> Matrix3<f64> {
    let keep = 3 - n;
    let sub = frame.columns(keep, n).into_owned();
    let eig = (sub.transpose() * info * &sub).symmetric_eigen();
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&i, &j| eig.eigenvalues[i].total_cmp(&eig.eigenvalues[j]));
    let mut basis = frame;
    for (slot, &k) in order.iter().enumerate() {
        basis.set_column(keep + slot, &(&sub * eig.eigenvectors.column(k)));
    }
    basis
}

/// `∂(t_x, t_y, cos θ, sin θ) / ∂(t_x, t_y, θ)`.
fn lift_jacobian(theta: f64) -> nalgebra::Matrix4x3<f64> {
    let (s, c) = theta.sin_cos();
    nalgebra::Matrix4x3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, -s, 0.0, 0.0, c)
}

/// Minimises `r' S r - 2 h' r` over unit vectors `r` (S symmetric 2x2).
fn min_quadratic_on_circle(s: &Matrix2<f64>, h: &Vector2<f64>) -> Vector2<f64> {
    CircleQuadratic::new(s, h).global_minimum()
}

/// [`min_quadratic_on_circle`]'s minimum, or the other local minimum on the circle where there
/// is one and it lies nearer `current` (a unit vector). A quadratic on a circle has at most
/// two local minima (Martínez 1994, "Local minimizers of quadratic functions on Euclidean
/// balls and spheres"): the global one, whose multiplier makes `S + λI` positive
/// semidefinite, and at most one more, with `λ` between `-s2` and `-s1`, on the rising
/// branch of the secular function between its poles. In the eigenbasis it lies on the other
/// side of the axis `v2` from the global one: where `S` is singular (`s1 = h1 = 0`) the two are
/// mirror images across it and tie.
fn min_quadratic_on_circle_near(
    s: &Matrix2<f64>,
    h: &Vector2<f64>,
    current: &Vector2<f64>,
) -> Vector2<f64> {
    let q = CircleQuadratic::new(s, h);
    let global = q.global_minimum();
    match q.other_minimum(&global) {
        Some(r) if r.iter().all(|v| v.is_finite()) && r.dot(current) > global.dot(current) => r,
        _ => global,
    }
}

/// `r' S r - 2 h' r` in the eigenbasis of `S` (`s1 <= s2`, unit eigenvectors `v1`, `v2`):
/// its stationary points on the unit circle are `r(mu) = v1 h1 / mu + v2 h2 / (mu + gap)`
/// where the secular function `h1²/mu² + h2²/(mu + gap)²` is 1, `mu = λ + s1` for the
/// multiplier `λ`.
struct CircleQuadratic {
    v1: Vector2<f64>,
    v2: Vector2<f64>,
    h1: f64,
    h2: f64,
    /// `s2 - s1`.
    gap: f64,
}

impl CircleQuadratic {
    fn new(s: &Matrix2<f64>, h: &Vector2<f64>) -> Self {
        let (s1, s2, v1) = symmetric_eigen_2x2(s);
        let v2 = Vector2::new(-v1.y, v1.x);
        Self {
            v1,
            v2,
            h1: v1.dot(h),
            h2: v2.dot(h),
            gap: s2 - s1,
        }
    }

    fn secular(&self, mu: f64) -> f64 {
        (self.h1 / mu).powi(2) + (self.h2 / (mu + self.gap)).powi(2)
    }

    /// The stationary point at `mu`, scaled onto the circle.
    fn point(&self, mu: f64) -> Vector2<f64> {
        let r = self.v1 * (self.h1 / mu) + self.v2 * (self.h2 / (mu + self.gap));
        r / r.norm()
    }

    fn global_minimum(&self) -> Vector2<f64> {
        let (v1, v2, h1, h2, gap) = (self.v1, self.v2, self.h1, self.h2, self.gap);
        let hn = h1.hypot(h2);
        if hn == 0.0 {
            return v1;
        }
        // Secular equation in mu = λ + s1 > 0: decreasing in mu, and <= 1 at mu = |h|. The
        // global minimum of a quadratic on a sphere has S + λI >= 0.
        let at_zero = if h1 == 0.0 {
            (h2 / gap).powi(2)
        } else {
            f64::INFINITY
        };
        if at_zero <= 1.0 {
            // The "hard case": the multiplier sits at -s1 and the rest of r lies along v1.
            let r2 = if gap > 0.0 { h2 / gap } else { 0.0 };
            let r1 = (1.0 - r2 * r2).max(0.0).sqrt();
            return v1 * r1 + v2 * r2;
        }
        self.point(bisect(0.0, hn, |mu| self.secular(mu), false))
    }

    /// The local minimum other than `global` (the global one), if there is one.
    fn other_minimum(&self, global: &Vector2<f64>) -> Option<Vector2<f64>> {
        let (v1, h1, h2, gap) = (self.v1, self.h1, self.h2, self.gap);
        if h1 == 0.0 {
            // The hard case (or no pull at all): the mirror image across v2 ties.
            Some(global - 2.0 * v1.dot(global) * v1)
        } else if h2 == 0.0 {
            // r2 = 0 at any multiplier: the other candidate is -v1 sign(h1), a minimum while
            // the curvature across v1 (gap) beats the pull |h1|.
            (h1.abs() < gap).then(|| -v1 * h1.signum())
        } else if gap > 0.0 {
            // mu in (-gap, 0): the secular function has its least value where
            // (-mu) / (mu + gap) = (h1² / h2²)^(1/3); a second minimum needs it below 1, and
            // lies on the rising branch above it.
            let k = (h1 * h1 / (h2 * h2)).cbrt();
            let low = -k * gap / (1.0 + k);
            (self.secular(low) < 1.0)
                .then(|| self.point(bisect(low, 0.0, |mu| self.secular(mu), true)))
        } else {
            None
        }
    }
}

/// Where `f` crosses 1 in `(lo, hi)`, bisected to the last representable midpoint: `f` rising
/// through it when `rising`, falling otherwise.
fn bisect(mut lo: f64, mut hi: f64, f: impl Fn(f64) -> f64, rising: bool) -> f64 {
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi {
            break;
        }
        if (f(mid) > 1.0) == rising {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    0.5 * (lo + hi)
}

/// Eigen-decomposition of a symmetric 2x2 matrix in closed form:
/// `(λ_min, λ_max, unit eigenvector of λ_min)`. nalgebra's iterative solver costs about a
/// microsecond, too much for once per reference point.
pub fn symmetric_eigen_2x2(m: &Matrix2<f64>) -> (f64, f64, Vector2<f64>) {
    let (lo, hi) = symmetric_eigenvalues_2x2(m);
    (lo, hi, minor_axis_2x2(m))
}

/// `(λ_min, λ_max)` of [`symmetric_eigen_2x2`] alone (the same arithmetic, so the same values),
/// for callers that need the axis of only some of their matrices: it costs an `atan2` and a
/// `sin_cos`.
pub(crate) fn symmetric_eigenvalues_2x2(m: &Matrix2<f64>) -> (f64, f64) {
    let (a, b, c) = (m[(0, 0)], 0.5 * (m[(0, 1)] + m[(1, 0)]), m[(1, 1)]);
    let mean = 0.5 * (a + c);
    let radius = (0.5 * (a - c)).hypot(b);
    (mean - radius, mean + radius)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Matrix3;
    use proptest::prelude::*;

    fn apply(t: &Pose2, p: &Point2<f64>) -> Point2<f64> {
        t.transform_point(p)
    }

    #[test]
    fn point_to_point_recovers_exact_motion() {
        let truth = Pose2::new(0.3, -0.2, 0.7);
        let ps = [
            Point2::new(1.0, 0.0),
            Point2::new(0.0, 2.0),
            Point2::new(-1.0, 0.5),
            Point2::new(3.0, -1.0),
        ];
        let mut s = RigidSolver::new();
        for p in &ps {
            s.add_point(p, &apply(&truth, p), 1.0);
        }
        let est = s.solve().unwrap();
        assert!((est.x - truth.x).abs() < 1e-12);
        assert!((est.y - truth.y).abs() < 1e-12);
        assert!((est.theta - truth.theta).abs() < 1e-12);
    }

    #[test]
    fn a_prior_alone_is_its_own_solution_and_pulls_a_weak_fit() {
        let prior = Pose2::new(0.4, -0.3, 0.2);
        let mut s = RigidSolver::new();
        s.add_prior(&prior, 1.0, 1.0);
        let est = s.solve().unwrap();
        assert!((est.x - 0.4).abs() < 1e-12 && (est.y + 0.3).abs() < 1e-12);
        assert!((est.theta - 0.2).abs() < 1e-9);
        // A corridor pins y only; the prior supplies x.
        let mut s = RigidSolver::new();
        for i in 0..10 {
            let p = Point2::new(i as f64, 1.0);
            s.add_line(Vector2::y(), &p, &Point2::new(0.0, 1.5), 1.0);
        }
        s.add_prior(&Pose2::new(0.7, 0.0, 0.0), 1e-3, 1e-3);
        let est = s.solve().unwrap();
        assert!(
            (est.x - 0.7).abs() < 1e-6 && (est.y - 0.5).abs() < 1e-3,
            "{est:?}"
        );
    }

    fn remap(anchor: Pose2) -> Remap {
        Remap {
            anchor: PosePrior {
                pose: anchor,
                weight_xy: 0.1,
                weight_theta: 1.0,
            },
            min_ratio: 10.0,
            min_constraint_ratio: 0.02,
        }
    }

    /// Rows of a noise-free corridor along x (walls at y = +-1) seen after motion `truth`.
    fn corridor(truth: &Pose2) -> RigidSolver {
        let inv = truth.inverse();
        let mut s = RigidSolver::new();
        for i in 0..20 {
            for y in [-1.0, 1.0] {
                let q = Point2::new(-3.0 + 0.4 * i as f64, y);
                s.add_line(Vector2::y(), &apply(&inv, &q), &Point2::new(0.0, y), 1.0);
            }
        }
        s
    }

    #[test]
    fn remapping_a_corridor_takes_its_length_from_the_anchor_exactly() {
        let truth = Pose2::new(0.5, 0.1, 0.05);
        let anchor = Pose2::new(0.57, 0.06, 0.03);
        let s = corridor(&truth);
        assert_eq!(s.solve(), Err(SolveError::Degenerate));
        // Found by the information alone, or named as the sliding axis: the same answer.
        for sliding in [None, Some(Vector2::x())] {
            let (est, how) = s.solve_remapped(&remap(anchor), &truth, sliding).unwrap();
            assert_eq!(how.free, 1);
            assert_eq!(how.sliding, sliding.is_some());
            let f: Vec<_> = how.free_directions().collect();
            assert!((f[0].x.abs() - 1.0).abs() < 1e-12, "{f:?}");
            assert!((est.x - anchor.x).abs() < 1e-12, "{est:?}");
            assert!((est.y - truth.y).abs() < 1e-9 && (est.theta - truth.theta).abs() < 1e-9);
            // The free part's covariance is the anchor's along x alone.
            let c = how.free_covariance(&Vector3::new(0.03, 0.03, 0.01));
            assert!((c - Matrix3::from_diagonal(&Vector3::new(9e-4, 0.0, 0.0))).norm() < 1e-12);
        }
    }

    #[test]
    fn remapping_with_nothing_free_is_the_exact_solve() {
        let truth = Pose2::new(0.3, -0.2, 0.7);
        let mut s = RigidSolver::new();
        for k in 0..12 {
            let p = Point2::new((k as f64).cos() * 3.0, (k as f64 * 1.7).sin() * 2.0);
            s.add_point(&p, &apply(&truth, &p), 1.0);
        }
        let (est, how) = s
            .solve_remapped(&remap(Pose2::identity()), &truth, None)
            .unwrap();
        assert_eq!(how.free, 0);
        assert_eq!(Ok(est), s.solve());
        // Its information is the sandwich's H: Jᵀ M J against the rows' own Jacobians.
        let h = s.information_at(0.7);
        let mut brute = Matrix3::zeros();
        let (sn, c) = 0.7f64.sin_cos();
        for k in 0..12 {
            let p = Point2::new((k as f64).cos() * 3.0, (k as f64 * 1.7).sin() * 2.0);
            let lever = Vector2::new(-sn * p.x - c * p.y, c * p.x - sn * p.y);
            for n in [Vector2::x(), Vector2::y()] {
                let j = Vector3::new(n.x, n.y, n.dot(&lever));
                brute += j * j.transpose();
            }
        }
        assert!((h - brute).norm() < 1e-9 * brute.norm());
    }

    #[test]
    fn a_pull_along_one_eigenvector_leaves_its_opposite_a_local_minimum() {
        // f = 2 sin² φ - cos φ: the global minimum at φ = 0, a local one at φ = π.
        let s = Matrix2::new(0.0, 0.0, 0.0, 2.0);
        let h = Vector2::new(0.5, 0.0);
        let near = |a: f64| min_quadratic_on_circle_near(&s, &h, &Vector2::new(a.cos(), a.sin()));
        assert!((near(0.4) - Vector2::new(1.0, 0.0)).norm() < 1e-12);
        assert!((near(3.0) - Vector2::new(-1.0, 0.0)).norm() < 1e-12);
        // Pulled harder than the curvature holds, φ = π is no minimum: the global one.
        let strong = Vector2::new(3.0, 0.0);
        let r = min_quadratic_on_circle_near(&s, &strong, &Vector2::new(-1.0, 0.0));
        assert!((r - Vector2::new(1.0, 0.0)).norm() < 1e-12);
    }

    #[test]
    fn parallel_lines_are_degenerate() {
        let mut s = RigidSolver::new();
        for i in 0..10 {
            let p = Point2::new(i as f64, 1.0);
            s.add_line(Vector2::y(), &p, &p, 1.0);
        }
        assert_eq!(s.solve(), Err(SolveError::Degenerate));
    }

    proptest! {
        #[test]
        fn closed_form_eigen_matches_nalgebra(a in -5.0f64..5.0, b in -5.0f64..5.0, c in -5.0f64..5.0) {
            let m = Matrix2::new(a, b, b, c);
            let (lo, hi, v) = symmetric_eigen_2x2(&m);
            let e = m.symmetric_eigen().eigenvalues;
            prop_assert!((lo - e[0].min(e[1])).abs() < 1e-9 && (hi - e[0].max(e[1])).abs() < 1e-9);
            prop_assert!((m * v - v * lo).norm() < 1e-9);
            prop_assert!((v.norm() - 1.0).abs() < 1e-12);
        }

        #[test]
        fn point_to_line_recovers_motion_from_two_wall_directions(
            x in -1.0f64..1.0, y in -1.0f64..1.0, th in -3.0f64..3.0,
        ) {
            // Points on the two walls of a corner, matched to the walls' lines (anywhere on them).
            let truth = Pose2::new(x, y, th);
            let inv = truth.inverse();
            let mut s = RigidSolver::new();
            for i in 0..8 {
                let qa = Point2::new(2.0, -1.0 + 0.3 * i as f64);
                let qb = Point2::new(-1.0 + 0.25 * i as f64, 3.0);
                // Slide the match along the wall: point-to-line must not care.
                s.add_line(Vector2::x(), &apply(&inv, &qa), &Point2::new(2.0, 7.0), 1.0);
                s.add_line(Vector2::y(), &apply(&inv, &qb), &Point2::new(-5.0, 3.0), 1.0);
            }
            // A third direction pins the rotation.
            let n = Vector2::new(1.0, 1.0).normalize();
            for i in 0..4 {
                let q = Point2::new(i as f64, -(i as f64));
                s.add_line(n, &apply(&inv, &q), &Point2::new(0.0, 0.0), 1.0);
            }
            let est = s.solve().unwrap();
            prop_assert!((est.x - x).abs() < 1e-8 && (est.y - y).abs() < 1e-8);
            prop_assert!(crate::geometry::wrap_angle(est.theta - th).abs() < 1e-8);
        }

        #[test]
        fn two_walls_alone_leave_a_mirror_image_and_the_local_solve_keeps_its_start(
            x in -1.0f64..1.0, y in -1.0f64..1.0, th in -3.0f64..3.0, off in -0.2f64..0.2,
        ) {
            // The corner's two walls and nothing else: scaling about the corner fits too, and
            // the rotation's mirror image fits exactly as well (the global solve picks one).
            let truth = Pose2::new(x, y, th);
            let inv = truth.inverse();
            let mut s = RigidSolver::new();
            for i in 0..8 {
                let qa = Point2::new(2.0, -1.0 + 0.3 * i as f64);
                let qb = Point2::new(-1.0 + 0.25 * i as f64, 3.0);
                s.add_line(Vector2::x(), &apply(&inv, &qa), &qa, 1.0);
                s.add_line(Vector2::y(), &apply(&inv, &qb), &qb, 1.0);
            }
            let est = s.solve_near(th + off).unwrap();
            prop_assert!((est.x - x).abs() < 1e-6 && (est.y - y).abs() < 1e-6, "{est:?}");
            prop_assert!(crate::geometry::wrap_angle(est.theta - th).abs() < 1e-6, "{est:?}");
        }

        #[test]
        fn the_local_circle_minimum_is_the_sampled_minimum_nearest_the_start(
            s11 in -5.0f64..5.0, s12 in -5.0f64..5.0, s22 in -5.0f64..5.0,
            h1 in -5.0f64..5.0, h2 in -5.0f64..5.0, start in -3.2f64..3.2,
        ) {
            let s = Matrix2::new(s11, s12, s12, s22);
            let h = Vector2::new(h1, h2);
            let f = |a: f64| {
                let r = Vector2::new(a.cos(), a.sin());
                (r.transpose() * s * r)[0] - 2.0 * h.dot(&r)
            };
            // Brute force: every sampled local minimum of f on the circle.
            let n = 7200;
            let step = std::f64::consts::TAU / n as f64;
            let values: Vec<f64> = (0..n).map(|k| f(k as f64 * step)).collect();
            let minima: Vec<f64> = (0..n)
                .filter(|&k| {
                    let (prev, next) = (values[(k + n - 1) % n], values[(k + 1) % n]);
                    values[k] < prev && values[k] <= next
                })
                .map(|k| k as f64 * step)
                .collect();
            prop_assume!(!minima.is_empty() && minima.len() <= 2);
            let current = Vector2::new(start.cos(), start.sin());
            let got = min_quadratic_on_circle_near(&s, &h, &current);
            let got = got.y.atan2(got.x);
            let gap = |a: f64, b: f64| crate::geometry::wrap_angle(a - b).abs();
            // The answer is one of the sampled minima, and the one nearest the start.
            let nearest = minima
                .iter()
                .copied()
                .min_by(|a, b| gap(*a, start).total_cmp(&gap(*b, start)))
                .unwrap();
            prop_assert!(minima.iter().any(|m| gap(*m, got) < 2.0 * step), "{got} not in {minima:?}");
            prop_assert!(gap(nearest, got) < 2.0 * step, "{got} against {nearest} of {minima:?}");
        }

        #[test]
        fn circle_minimum_beats_dense_sampling(
            s11 in -5.0f64..5.0, s12 in -5.0f64..5.0, s22 in -5.0f64..5.0,
            h1 in -5.0f64..5.0, h2 in -5.0f64..5.0,
        ) {
            let s = Matrix2::new(s11, s12, s12, s22);
            let h = Vector2::new(h1, h2);
            let f = |r: &Vector2<f64>| (r.transpose() * s * r)[0] - 2.0 * h.dot(r);
            let best = min_quadratic_on_circle(&s, &h);
            prop_assert!((best.norm() - 1.0).abs() < 1e-9);
            let fb = f(&best);
            for k in 0..3600 {
                let a = k as f64 * std::f64::consts::TAU / 3600.0;
                prop_assert!(fb <= f(&Vector2::new(a.cos(), a.sin())) + 1e-7);
            }
        }
    }
}
