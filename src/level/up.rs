//! The global up vector from wall normals (paper sect. 5.3) and its uncertainty.
//!
//! Two estimators:
//! - [`up_paper`]: the paper's weighted sum of rectified cross products of all pairs of normals,
//!   `w_ij = a_i a_j (1 - |n_i . n_j|)`.
//! - [`up_robust`]: the closed-form least squares the paper's sect. 9 asks for: minimise
//!   `sum_i w_i (n_i . up)^2` over unit `up`, i.e. the eigenvector of the smallest eigenvalue of
//!   `sum_i w_i n_i n_i^T`, with `w_i = 1 / Var(n_i . up)` from each plane fit's normal covariance
//!   and Cauchy reweighting of `z_i = (n_i . up) / sd_i` against wrongly extracted planes.

use super::grid::PlaneFit;
use crate::level::params::up::*;
use nalgebra::{Matrix2, Matrix3, Vector2, Vector3};

/// A straight run of floor (or ceiling) points in one scan. A scan's plane meets a level
/// surface in a straight line, so the line's direction `dir` must be level: `dir . up = 0`
/// (one residual). Floor points seen at grazing incidence put their range noise almost along
/// the floor, so the line's vertical slope is precise even at high noise, and a floor seen
/// in one scan only (no plane: it is free to turn about the line) still pins up down across it.
#[derive(Clone, Copy, Debug)]
pub struct LevelLine {
    /// Unit direction in the robot frame (sign arbitrary).
    pub(crate) dir: Vector3<f64>,
    /// Mean of the points \[m\], robot frame.
    pub(crate) centroid: nalgebra::Point3<f64>,
    /// Points behind it.
    pub(crate) n: usize,
    /// `sum_i t_i^2 d_i d_i^T` over the points' positions `t_i` along the line (from the
    /// centroid) and their ray directions `d_i`.
    spread_dd: Matrix3<f64>,
    /// `sum_i t_i^2` [m^2].
    spread: f64,
    /// Noise floor of a point \[m\] (`min_sigma`).
    min_sigma: f64,
}

impl LevelLine {
    /// A line through `points` (position, unit ray direction), by total least squares with
    /// the range-noise bias removed from the scatter (as [`super::grid::PlaneAccumulator`]
    /// does for planes: grazing rays run nearly along the line, and their noise would tilt
    /// it). `None` with fewer than three points.
    pub(crate) fn fit(
        points: &[(nalgebra::Point3<f64>, Vector3<f64>)],
        sigma: f64,
        min_sigma: f64,
    ) -> Option<LevelLine> {
        let n = points.len();
        if n < 3 {
            return None;
        }
        let nf = n as f64;
        let c = points.iter().map(|(p, _)| p.coords).sum::<Vector3<f64>>() / nf;
        let outer = |v: Vector3<f64>| v * v.transpose();
        let scatter: Matrix3<f64> = points.iter().map(|(p, _)| outer(p.coords - c)).sum();
        let dd: Matrix3<f64> = points.iter().map(|(_, d)| outer(*d)).sum();
        let corrected = scatter - dd * (sigma * sigma * (nf - 1.0) / nf);
        let eig = super::eigen3::sym_eigen3(&corrected);
        let dir = eig.vectors[2].try_normalize(1e-300)?;
        // Each point's squared position along the line, `t_i^2`, alone and on its ray's `d d^T`.
        let (mut spread, mut spread_dd) = (0.0, Matrix3::zeros());
        for (p, d) in points {
            let t2 = dir.dot(&(p.coords - c)).powi(2);
            spread += t2;
            spread_dd += outer(*d) * t2;
        }
        (spread > 0.0).then_some(LevelLine {
            dir,
            centroid: nalgebra::Point3::from(c),
            n,
            spread_dd,
            spread,
            min_sigma,
        })
    }

    /// Variance of `dir . u` for a unit `u` perpendicular to `dir`, from first-order TLS
    /// perturbation: `sum_i t_i^2 Var(u . e_i) / (sum_i t_i^2)^2`, where each point's error
    /// `e_i` is its range noise along its ray plus the `min_sigma` floor.
    pub(crate) fn variance_along(&self, u: &Vector3<f64>, sigma: f64) -> f64 {
        let along = (u.transpose() * self.spread_dd * u)[0];
        (sigma * sigma * along + self.min_sigma * self.min_sigma * self.spread)
            / (self.spread * self.spread)
    }
}

/// What one piece of evidence says about up.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Evidence<'a> {
    /// A wall plane: vertical, so `n . up = 0` (one residual).
    Wall(&'a PlaneFit),
    /// A floor or ceiling plane taken as level: up along its normal, so `e_k . up = 0` for
    /// both of its in-plane axes `e_k` (two residuals).
    Level(&'a PlaneFit),
    /// A line on a level surface ([`LevelLine`]): `dir . up = 0` (one residual).
    LevelLine(&'a LevelLine),
}

/// A piece of evidence with a variance inflation (>= 1) for misfit.
#[derive(Clone, Copy, Debug)]
pub(crate) struct PlaneObs<'a> {
    pub(crate) evidence: Evidence<'a>,
    /// Multiplies the evidence's variance.
    pub(crate) inflate: f64,
}

/// One scalar residual `a . up` with its variance.
type Term = (Vector3<f64>, f64);

impl PlaneObs<'_> {
    /// A wall plane.
    pub(crate) fn wall(fit: &PlaneFit, inflate: f64) -> PlaneObs<'_> {
        let evidence = Evidence::Wall(fit);
        PlaneObs { evidence, inflate }
    }

    /// A floor or ceiling plane taken as level.
    pub(crate) fn level(fit: &PlaneFit, inflate: f64) -> PlaneObs<'_> {
        let evidence = Evidence::Level(fit);
        PlaneObs { evidence, inflate }
    }

    /// A line on a floor or ceiling.
    pub(crate) fn level_line(line: &LevelLine, inflate: f64) -> PlaneObs<'_> {
        let evidence = Evidence::LevelLine(line);
        PlaneObs { evidence, inflate }
    }

    /// The single constrained direction `a` (with `a . up = 0`) of one-residual evidence;
    /// `None` for a level plane's two residuals.
    fn single(&self) -> Option<Vector3<f64>> {
        match self.evidence {
            Evidence::Wall(f) => Some(f.normal),
            Evidence::LevelLine(l) => Some(l.dir),
            Evidence::Level(_) => None,
        }
    }

    /// The residual directions of this evidence and their variances at the current `up`.
    fn terms(&self, up: &Vector3<f64>, sigma: f64) -> ([Term; 2], usize) {
        // The unit direction, perpendicular to `a`, in which an error of `a` moves `a . up`.
        let across = |a: &Vector3<f64>| (up - a * a.dot(up)).try_normalize(1e-12).unwrap_or(*up);
        let inflated = |var: f64| (self.inflate * var).max(1e-14);
        let (a, var) = match self.evidence {
            Evidence::Level(fit) => {
                let var = |u: &Vector3<f64>| inflated(fit.normal_variance_along(u, sigma));
                let [(_, e1), (_, e2)] = fit.in_plane;
                return ([(e1, var(&e1)), (e2, var(&e2))], 2);
            }
            Evidence::Wall(f) => (f.normal, f.normal_variance_along(&across(&f.normal), sigma)),
            Evidence::LevelLine(l) => (l.dir, l.variance_along(&across(&l.dir), sigma)),
        };
        // One residual: the second term is padding.
        ([(a, inflated(var)), (a, f64::INFINITY)], 1)
    }

    /// Squared Mahalanobis distance of `up` from this evidence's constraint, per residual.
    fn z2(&self, up: &Vector3<f64>, sigma: f64) -> f64 {
        let (terms, k) = self.terms(up, sigma);
        z2_of(&terms[..k], up)
    }

    /// Its share of the unweighted start matrix: the constrained directions' outer products,
    /// weighted by the points behind them.
    fn start_matrix(&self) -> Matrix3<f64> {
        match self.evidence {
            Evidence::Level(f) => {
                let [(_, e1), (_, e2)] = f.in_plane;
                (e1 * e1.transpose() + e2 * e2.transpose()) * f.n as f64
            }
            Evidence::Wall(f) => f.normal * f.normal.transpose() * f.n as f64,
            Evidence::LevelLine(l) => l.dir * l.dir.transpose() * l.n as f64,
        }
    }
}

/// The paper's estimator (eq. of sect. 5.3); `None` when no pair of normals is independent.
pub(crate) fn up_paper(normals: &[(Vector3<f64>, f64)]) -> Option<Vector3<f64>> {
    let mut sum = Vector3::zeros();
    for (i, (ni, ai)) in normals.iter().enumerate() {
        for (nj, aj) in &normals[i + 1..] {
            let c = ni.cross(nj);
            let norm = c.norm();
            if norm < 1e-12 {
                continue;
            }
            let w = ai * aj * (1.0 - ni.dot(nj).abs());
            // s_ij: the robot is never upside down, so up has a positive z in its frame.
            let s = if c.z < 0.0 { -1.0 } else { 1.0 };
            sum += c * (w * s / norm);
        }
    }
    sum.try_normalize(1e-300)
}

/// An up vector with its uncertainty.
#[derive(Clone, Copy, Debug)]
pub struct UpSolution {
    /// Unit up vector in the robot frame, `z > 0`.
    pub up: Vector3<f64>,
    /// Orthonormal basis of the tangent plane at `up`.
    pub basis: [Vector3<f64>; 2],
    /// Covariance of up's tangent-plane perturbation in `basis` [rad^2].
    pub cov: Matrix2<f64>,
    /// Eigenvalues (smaller, larger) of the information matrix; their ratio says how well the
    /// walls' directions pin up down in both tangent directions (tiny for parallel walls).
    pub info_eigenvalues: (f64, f64),
}

impl UpSolution {
    /// Its covariance expressed in another tangent `basis` (of a nearby up): `J cov J^T` with
    /// `J[i][j] = basis[i] . self.basis[j]`.
    pub(crate) fn cov_in(&self, basis: &[Vector3<f64>; 2]) -> Matrix2<f64> {
        let j = Matrix2::from_fn(|i, k| basis[i].dot(&self.basis[k]));
        j * self.cov * j.transpose()
    }

    /// Another `up`'s coordinates in this solution's tangent plane (its `basis`): the distance
    /// between the two, to first order \[rad\].
    pub(crate) fn offset_to(&self, up: &Vector3<f64>) -> Vector2<f64> {
        Vector2::new(up.dot(&self.basis[0]), up.dot(&self.basis[1]))
    }
}

/// The squared Mahalanobis distance `d^T cov^-1 d` of an offset `d` under `cov`; `None` when
/// `cov` is singular.
pub(crate) fn mahalanobis2(d: &Vector2<f64>, cov: &Matrix2<f64>) -> Option<f64> {
    Some((d.transpose() * cov.try_inverse()? * d)[(0, 0)])
}

/// Unit vector along the smallest eigenvalue of a symmetric matrix, rectified to `z >= 0`.
fn smallest_eigenvector(m: &Matrix3<f64>) -> Option<Vector3<f64>> {
    let v = super::eigen3::sym_eigen3(m).vectors[0].try_normalize(1e-300)?;
    Some(if v.z < 0.0 { -v } else { v })
}

fn tangent_basis(up: &Vector3<f64>) -> [Vector3<f64>; 2] {
    // Robot x projected off up, then the third axis: stable for tilts far below 90 degrees.
    let t1 = (Vector3::x() - up * up.x)
        .try_normalize(1e-9)
        .unwrap_or_else(|| (Vector3::y() - up * up.y).normalize());
    [t1, up.cross(&t1)]
}

/// Iteratively reweighted least squares for up over plane fits with range noise `sigma` \[m\].
///
/// A wrongly extracted plane (a seed across a wall's foot, clutter) can outweigh the good ones
/// in a plain weighted fit, and reweighting from a bad start only confirms it. So the start is
/// chosen robustly: every pair of planes proposes up as the cross product of their normals
/// (the paper's two-polygon solution, sect. 5.3), as does the plain weighted fit, and the
/// proposal with the least total Cauchy loss over all planes wins; only proposals within
/// 50 degrees of the robot's own up are considered. `None` with fewer than two planes or when
/// no proposal qualifies.
pub(crate) fn up_robust(planes: &[PlaneObs], sigma: f64, iterations: usize) -> Option<UpSolution> {
    let constraints: usize = planes.iter().map(|p| p.single().map_or(2, |_| 1)).sum();
    if constraints < 2 {
        return None;
    }
    // A level plane proposes its normal.
    let level = |p: &PlaneObs| match p.evidence {
        Evidence::Level(f) => Some(f.normal),
        _ => None,
    };
    let mut candidates: Vec<Vector3<f64>> = planes.iter().filter_map(level).collect();
    let start: Matrix3<f64> = planes.iter().map(|p| p.start_matrix()).sum();
    candidates.extend(smallest_eigenvector(&start));
    // Walls and level lines: each pair proposes the direction normal to both.
    let singles: Vec<Vector3<f64>> = planes.iter().filter_map(|p| p.single()).collect();
    for (i, a) in singles.iter().enumerate() {
        for b in &singles[i + 1..] {
            // Nearly parallel normals propose nothing reliable.
            candidates.extend(a.cross(b).try_normalize(PARALLEL_PROPOSAL_SIN));
        }
    }
    let loss = |up: &Vector3<f64>| -> f64 {
        planes
            .iter()
            .map(|p| (1.0 + p.z2(up, sigma) / (CAUCHY_C * CAUCHY_C)).ln())
            .sum()
    };
    let mut up = candidates
        .into_iter()
        .map(|c| if c.z < 0.0 { -c } else { c })
        .filter(within_max_tilt)
        .map(|c| (loss(&c), c))
        .min_by(|a, b| a.0.total_cmp(&b.0))?
        .1;
    for _ in 0..iterations.max(1) {
        let mut m = Matrix3::zeros();
        for p in planes {
            let (terms, k) = p.terms(&up, sigma);
            let w = cauchy2(z2_of(&terms[..k], &up));
            for (a, var) in &terms[..k] {
                m += a * a.transpose() * (w / var);
            }
        }
        let next = smallest_eigenvector(&m)?;
        let change = (next - up).norm();
        up = next;
        if change < 1e-10 {
            break;
        }
    }
    // The result is held to the same limit.
    within_max_tilt(&up).then(|| solution_at(up, planes, sigma, true))
}

/// [`Check::MaxTilt`](super::checks::Check::MaxTilt): whether a unit `up` (`z >= 0`) lies
/// within `MAX_TILT_DEG` of the robot's z axis, as every candidate of [`up_robust`] must.
pub(crate) fn within_max_tilt(up: &Vector3<f64>) -> bool {
    up.z >= MAX_TILT.cos()
}

/// [`PlaneObs::z2`] from the evidence's terms.
fn z2_of(terms: &[Term], up: &Vector3<f64>) -> f64 {
    terms
        .iter()
        .map(|(a, v)| a.dot(up).powi(2) / v)
        .sum::<f64>()
        / terms.len() as f64
}

/// Cauchy weight for a squared standardised residual.
fn cauchy2(z2: f64) -> f64 {
    1.0 / (1.0 + z2 / (CAUCHY_C * CAUCHY_C))
}

/// The information matrix and covariance of `up` given the planes. With `robust`, the
/// Cauchy weights of the fit are applied. The covariance is inflated by the weighted
/// chi-square per degree of freedom (with `CHI2_PRIOR_DOF` pseudo degrees of freedom at
/// one) when that exceeds one, so that a model that explains the normals worse than their
/// noise predicts reports a larger, honest sigma.
pub(crate) fn solution_at(
    up: Vector3<f64>,
    planes: &[PlaneObs],
    sigma: f64,
    robust: bool,
) -> UpSolution {
    let basis = tangent_basis(&up);
    let mut h = Matrix2::zeros();
    let mut chi2 = 0.0;
    let mut wsum = 0.0;
    for p in planes {
        let (terms, k) = p.terms(&up, sigma);
        let w = if robust {
            cauchy2(z2_of(&terms[..k], &up))
        } else {
            1.0
        };
        for (a, var) in &terms[..k] {
            let g = Vector2::new(a.dot(&basis[0]), a.dot(&basis[1]));
            h += g * g.transpose() * (w / var);
            chi2 += w * a.dot(&up).powi(2) / var;
            wsum += w;
        }
    }
    let dof = wsum - 2.0;
    let scale = if dof >= 1.0 {
        ((chi2 + CHI2_PRIOR_DOF) / (dof + CHI2_PRIOR_DOF)).max(1.0)
    } else {
        1.0
    };
    let eig = nalgebra::SymmetricEigen::new(h);
    let (lo, hi) = (
        eig.eigenvalues.min().max(0.0),
        eig.eigenvalues.max().max(0.0),
    );
    let cov = h
        .try_inverse()
        .map(|c| c * scale)
        .unwrap_or_else(|| Matrix2::identity() * f64::INFINITY);
    UpSolution {
        up,
        basis,
        cov,
        info_eigenvalues: (lo, hi),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Attitude;

    /// A covariance carried into its own basis is unchanged; into the basis turned a quarter
    /// turn about up, its variances swap.
    #[test]
    fn covariance_follows_the_basis() {
        let up = Vector3::new(0.1, -0.2, 1.0).normalize();
        let basis = tangent_basis(&up);
        let sol = UpSolution {
            up,
            basis,
            cov: Matrix2::new(4.0, 1.0, 1.0, 9.0),
            info_eigenvalues: (1.0, 1.0),
        };
        assert!((sol.cov_in(&basis) - sol.cov).norm() < 1e-12);
        let turned = [basis[1], -basis[0]];
        let c = sol.cov_in(&turned);
        assert!(
            (c[(0, 0)] - 9.0).abs() < 1e-12 && (c[(1, 1)] - 4.0).abs() < 1e-12,
            "{c}"
        );
        assert!((c[(0, 1)] + 1.0).abs() < 1e-12, "{c}");
    }

    /// One wall leaves up free to turn about its normal: that direction's sigma is infinite,
    /// not zero (an undetermined direction once claimed a sigma of 0 and won the choice of a
    /// start over a pose's floor lines).
    #[test]
    fn one_wall_leaves_an_infinite_sigma() {
        let fit = PlaneFit {
            centroid: nalgebra::Point3::new(3.0, 0.0, 0.0),
            normal: Vector3::x(),
            in_plane: [(10.0, Vector3::y()), (20.0, Vector3::z())],
            n: 100,
            weight: 100.0,
            dn2: 1.0,
            residual_ss: 0.01,
        };
        let sol = solution_at(Vector3::z(), &[PlaneObs::wall(&fit, 1.0)], 0.01, false);
        let s = sol.attitude_sigmas();
        assert!(s[0].is_infinite() || s[1].is_infinite(), "{s:?}");
        assert!(!s[0].is_nan() && !s[1].is_nan());
    }

    /// Walls at even azimuths, each tilted so that its normal meets up (z) at `tilt`: the
    /// variance of `n . up` is `sigma^2 dn2 / lambda` = 1e-4 (the direction it is taken along
    /// is the in-plane vertical exactly), so each wall's squared z-score is `tilt^2 / 1e-4`.
    fn tilted_walls(count: usize, tilt: f64) -> Vec<PlaneFit> {
        (0..count)
            .map(|i| {
                let a = std::f64::consts::PI * i as f64 / count as f64;
                let normal = Vector3::new(a.cos(), a.sin(), tilt).normalize();
                let e1 = Vector3::new(-a.sin(), a.cos(), 0.0);
                PlaneFit {
                    centroid: nalgebra::Point3::from(normal * 3.0),
                    normal,
                    in_plane: [(4.0, e1), (1.0, normal.cross(&e1))],
                    n: 100,
                    weight: 100.0,
                    dn2: 1.0,
                    residual_ss: 0.01,
                }
            })
            .collect()
    }

    /// The covariance's misfit scale is the chi-square per degree of freedom with
    /// `CHI2_PRIOR_DOF` pseudo degrees of freedom at one: three walls each at two sigmas
    /// (chi-square 12 over one degree of freedom) scale it by 17 / 6, not 12; thirty (120
    /// over 28) by 125 / 33, nearer their own ratio of 4.3.
    #[test]
    fn few_misfitting_walls_scale_the_covariance_less_than_many() {
        let tilt: f64 = 0.02;
        // Normalised, the normals meet up at a little less than `tilt`, and their own
        // information is smaller by `1 + tilt^2`.
        let (shrink, z2) = (1.0 + tilt * tilt, tilt * tilt / (1.0 + tilt * tilt) / 1e-4);
        for (count, roughly) in [(3, 17.0 / 6.0), (30, 125.0 / 33.0)] {
            let cov = |walls_tilt: f64| {
                let fits = tilted_walls(count, walls_tilt);
                let obs: Vec<PlaneObs> = fits.iter().map(|f| PlaneObs::wall(f, 1.0)).collect();
                solution_at(Vector3::z(), &obs, 0.01, false).cov
            };
            let (fitting, misfitting) = (cov(0.0), cov(tilt));
            let dof = count as f64 - 2.0;
            let expected = (count as f64 * z2 + CHI2_PRIOR_DOF) / (dof + CHI2_PRIOR_DOF);
            assert!((expected - roughly).abs() < 0.01, "{expected}");
            for k in 0..2 {
                let ratio = misfitting[(k, k)] / fitting[(k, k)] / shrink;
                assert!(
                    (ratio - expected).abs() < 1e-9,
                    "{count} walls: {ratio} vs {expected}"
                );
            }
        }
    }

    #[test]
    fn paper_estimator_on_two_exact_walls_is_exact() {
        let att = Attitude::new(0.2, -0.1);
        let r = att.level_from_robot().inverse();
        let n1 = r * Vector3::x();
        let n2 = r * Vector3::new(1.0, 1.0, 0.0).normalize();
        let up = up_paper(&[(n1, 1.0), (n2, 2.0)]).unwrap();
        assert!((up - att.up_in_robot()).norm() < 1e-12);
    }

    /// Noise-free floor points along one scan's line, seen from a tilted robot.
    fn floor_line(att: &Attitude, y0: f64) -> Vec<(nalgebra::Point3<f64>, Vector3<f64>)> {
        let robot_from_level = att.level_from_robot().inverse();
        (0..20)
            .map(|k| {
                let q = Vector3::new(0.5 + 0.2 * k as f64, y0 + 0.05 * k as f64, -0.45);
                let p = robot_from_level * q;
                (nalgebra::Point3::from(p), p.normalize())
            })
            .collect()
    }

    #[test]
    fn level_line_fit_on_exact_floor_points_is_level() {
        let att = Attitude::new(0.15, -0.2);
        let line = LevelLine::fit(&floor_line(&att, -1.0), 0.0, 0.001).unwrap();
        assert!(line.dir.dot(&att.up_in_robot()).abs() < 1e-12);
        // Grazing rays: the slope's sigma is far below the range noise over the line's length.
        let u = (att.up_in_robot() - line.dir * line.dir.dot(&att.up_in_robot())).normalize();
        let sd = line.variance_along(&u, 0.05).sqrt();
        assert!(sd > 0.0 && sd < 0.05 / 4.0, "slope sigma {sd}");
    }

    #[test]
    fn one_wall_and_one_floor_line_fix_up_exactly() {
        let att = Attitude::new(-0.1, 0.25);
        let r = att.level_from_robot().inverse();
        let wall = super::super::grid::PlaneAccumulator::default();
        // A wall x = 3 in the level frame, as an exact plane fit.
        let mut acc = wall;
        for i in 0..6 {
            for j in 0..4 {
                let q = Vector3::new(3.0, -1.0 + 0.4 * i as f64, -0.3 + 0.3 * j as f64);
                let p = r * q;
                acc.add(&super::super::grid::GridPoint {
                    p: nalgebra::Point3::from(p),
                    dir: p.normalize(),
                    range: p.norm(),
                });
            }
        }
        let fit = acc.fit(0.0).unwrap();
        let line = LevelLine::fit(&floor_line(&att, -1.0), 0.0, 0.001).unwrap();
        let obs = [PlaneObs::wall(&fit, 1.0), PlaneObs::level_line(&line, 1.0)];
        let sol = up_robust(&obs, 0.01, 10).unwrap();
        assert!((sol.up - att.up_in_robot()).norm() < 1e-9);
        // The wall alone does not fix up.
        assert!(up_robust(&obs[..1], 0.01, 10).is_none());
    }
}
