//! The measurement model of the maximum-likelihood refinement: a ray's range as a function of
//! the attitude and of the plane it met, and its derivatives.
//!
//! For a ray from `o` along `u` (robot frame) meeting the plane `n . x = d` of the yaw-free
//! level frame (`L = level_from_robot = Ry(theta_y) Rx(theta_x)`), the predicted range is
//! `r^ = (d - n . L o) / (n . L u)` and the normalised residual `rho = (r - r^) / sigma`: the
//! range noise along each ray, as the Cramér-Rao bound takes it ([`crate::eval::bound`]).
//! A wall is a vertical plane, `n = (cos a, sin a, 0)` (a 2D line of the level frame), the
//! floor and the ceiling are level, `n = (0, 0, 1)`, each at its own height `d`.
//!
//! The residuals and derivatives here are the model written plainly, point by point; the
//! refinement's passes ([`super::evaluate`]) compute the same quantities rearranged, and the
//! tests hold the two equal.

use super::{LabelledPoint, Surface};
use crate::geometry::{rot_x, rot_y};
use nalgebra::{Matrix2, Matrix3, Point3, SymmetricEigen, Vector2, Vector3};

/// Smallest `|n . L u|` a prediction divides by: a ray grazing its plane (the residual's
/// derivatives grow without bound there; the robust kernel then discounts the point).
pub(crate) const MIN_INCIDENCE: f64 = 1e-3;

/// The attitude's rotation and its derivatives by `theta_x` and `theta_y`.
#[derive(Clone, Debug)]
pub(crate) struct Rotations {
    pub level_from_robot: Matrix3<f64>,
    pub by_theta: [Matrix3<f64>; 2],
}

impl Rotations {
    pub fn at(theta: &Vector2<f64>) -> Self {
        let (sx, cx) = theta.x.sin_cos();
        let (sy, cy) = theta.y.sin_cos();
        let d_rot_x = Matrix3::new(0.0, 0.0, 0.0, 0.0, -sx, -cx, 0.0, cx, -sx);
        let d_rot_y = Matrix3::new(-sy, 0.0, cy, 0.0, 0.0, 0.0, -cy, 0.0, -sy);
        let (rx, ry) = (*rot_x(theta.x).matrix(), *rot_y(theta.y).matrix());
        Rotations {
            level_from_robot: ry * rx,
            by_theta: [ry * d_rot_x, d_rot_y * rx],
        }
    }
}

/// A surface's placement: for a wall the azimuth `a` of its normal and its offset `d`, for
/// the floor or ceiling its height `d` (`a` unused).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Placement {
    pub offset: f64,
    pub azimuth: f64,
}

impl Placement {
    /// The floor's or ceiling's placement at `height`.
    pub fn level(height: f64) -> Self {
        Placement {
            offset: height,
            azimuth: 0.0,
        }
    }

    pub fn normal(&self, surface: Surface) -> Vector3<f64> {
        match surface {
            Surface::Wall(_) => {
                let (s, c) = self.azimuth.sin_cos();
                Vector3::new(c, s, 0.0)
            }
            Surface::Floor | Surface::Ceiling => Vector3::z(),
        }
    }
}

/// A surface's plane at one state: what every residual on it needs, computed once per state
/// rather than per point (a wall's normal takes a sine and a cosine).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Plane {
    pub normal: Vector3<f64>,
    /// The wall's tangent `(-n_y, n_x, 0)` in the level frame; `None` for the floor or ceiling.
    pub tangent: Option<Vector3<f64>>,
    pub offset: f64,
}

impl Plane {
    pub fn at(placement: &Placement, surface: Surface) -> Self {
        let n = placement.normal(surface);
        Plane {
            normal: n,
            tangent: match surface {
                Surface::Wall(_) => Some(Vector3::new(-n.y, n.x, 0.0)),
                Surface::Floor | Surface::Ceiling => None,
            },
            offset: placement.offset,
        }
    }
}

/// One point's normalised residual and its derivatives: by `(theta_x, theta_y)` and by its
/// surface's `(offset, azimuth)` (the azimuth's is zero for the floor and ceiling).
#[derive(Clone, Copy, Debug)]
#[cfg(test)]
pub(crate) struct Linearized {
    pub rho: f64,
    pub by_attitude: Vector2<f64>,
    pub by_placement: Vector2<f64>,
}

/// The point's distance from its plane along the plane's normal, in sigmas of its noise along
/// that normal at the frozen incidence `incidence` (`|n . L u|` of an earlier state): the
/// residual of the approach from far away. Unlike the range residual it is nearly linear in
/// the parameters and has no pole where a ray turns parallel to its plane, which a floor ray
/// near the horizon does under a wrong attitude; at a fixed incidence its magnitude is the
/// range residual's.
#[cfg(test)]
pub(crate) fn linearize_plane(
    point: &LabelledPoint,
    plane: &Plane,
    rot: &Rotations,
    incidence: f64,
) -> Linearized {
    let n = &plane.normal;
    let q = point.origin.coords + point.dir * point.range;
    let lq = rot.level_from_robot * q;
    let scale = 1.0 / (point.sigma * incidence.max(MIN_INCIDENCE));
    let azimuth = plane.tangent.map_or(0.0, |t| t.dot(&lq));
    Linearized {
        rho: (n.dot(&lq) - plane.offset) * scale,
        by_attitude: Vector2::new(n.dot(&(rot.by_theta[0] * q)), n.dot(&(rot.by_theta[1] * q)))
            * scale,
        by_placement: Vector2::new(-1.0, azimuth) * scale,
    }
}

/// [`linearize_plane`]'s residual alone (the cost of a trial step needs no derivatives).
#[cfg(test)]
pub(crate) fn plane_rho(
    point: &LabelledPoint,
    plane: &Plane,
    rot: &Rotations,
    incidence: f64,
) -> f64 {
    let q = point.origin.coords + point.dir * point.range;
    let lq = rot.level_from_robot * q;
    let scale = 1.0 / (point.sigma * incidence.max(MIN_INCIDENCE));
    (plane.normal.dot(&lq) - plane.offset) * scale
}

/// `|n . L u|` of `point` on a plane of normal `n`: the share of its range noise along the
/// normal.
#[cfg(test)]
pub(crate) fn incidence_on(point: &LabelledPoint, n: &Vector3<f64>, rot: &Rotations) -> f64 {
    n.dot(&(rot.level_from_robot * point.dir)).abs()
}

/// The range `r^` the model predicts for `point` on `plane` and the divisor `b = n . L u` it
/// took (kept from zero by [`MIN_INCIDENCE`]).
#[cfg(test)]
pub(crate) fn predict(point: &LabelledPoint, plane: &Plane, rot: &Rotations) -> (f64, f64) {
    let lu = rot.level_from_robot * point.dir;
    let lo = rot.level_from_robot * point.origin.coords;
    predict_level(plane, &lu, &lo)
}

/// [`predict`] given the ray's direction `lu = L u` and origin `lo = L o` in the level frame
/// (a caller that tries one ray on several planes levels it once).
pub(crate) fn predict_level(plane: &Plane, lu: &Vector3<f64>, lo: &Vector3<f64>) -> (f64, f64) {
    let n = &plane.normal;
    let b = off_grazing(n.dot(lu));
    ((plane.offset - n.dot(lo)) / b, b)
}

/// The divisor `b = n . L u` a prediction takes: kept at least [`MIN_INCIDENCE`] from zero,
/// with its sign.
pub(crate) fn off_grazing(raw: f64) -> f64 {
    if raw.abs() < MIN_INCIDENCE {
        MIN_INCIDENCE.copysign(raw)
    } else {
        raw
    }
}

/// The residual of `point` on its surface at `placement`, under the attitude `rot`.
#[cfg(test)]
pub(crate) fn linearize(
    point: &LabelledPoint,
    placement: &Placement,
    rot: &Rotations,
) -> Linearized {
    linearize_on(point, &Plane::at(placement, point.surface), rot)
}

/// The residual of `point` and its derivatives on its surface's plane at the state.
#[cfg(test)]
pub(crate) fn linearize_on(point: &LabelledPoint, plane: &Plane, rot: &Rotations) -> Linearized {
    linearize_predicted(point, plane, rot, predict(point, plane, rot))
}

/// [`linearize_on`] given [`predict`]'s `(r^, b)` at the same state.
#[cfg(test)]
pub(crate) fn linearize_predicted(
    point: &LabelledPoint,
    plane: &Plane,
    rot: &Rotations,
    (predicted, b): (f64, f64),
) -> Linearized {
    let n = &plane.normal;
    let q = point.origin.coords + point.dir * predicted;
    // d r^ / d theta = -n . L' q / b; d r^ / d d = 1 / b; d r^ / d a = -t . L q / b.
    let by_attitude = Vector2::new(
        n.dot(&(rot.by_theta[0] * q)) / b,
        n.dot(&(rot.by_theta[1] * q)) / b,
    ) / point.sigma;
    let azimuth = plane
        .tangent
        .map_or(0.0, |t| t.dot(&(rot.level_from_robot * q)) / b);
    Linearized {
        rho: (point.range - predicted) / point.sigma,
        by_attitude,
        by_placement: Vector2::new(-1.0 / b, azimuth) / point.sigma,
    }
}

/// A surface's placement fitted to its points leveled with `rot`: the mean height for the
/// floor or ceiling, the total-least-squares line of the points' level-frame `(x, y)` for a
/// wall. `None` when a wall's points do not span a line.
pub(crate) fn initial_placement(
    points: &[&LabelledPoint],
    surface: Surface,
    rot: &Rotations,
) -> Option<Placement> {
    if points.is_empty() {
        return None;
    }
    let level: Vec<Point3<f64>> = points
        .iter()
        .map(|p| Point3::from(rot.level_from_robot * (p.origin.coords + p.dir * p.range)))
        .collect();
    let n = level.len() as f64;
    match surface {
        Surface::Floor | Surface::Ceiling => {
            Some(Placement::level(level.iter().map(|p| p.z).sum::<f64>() / n))
        }
        Surface::Wall(_) => {
            let c = level
                .iter()
                .fold(Vector2::zeros(), |a, p| a + Vector2::new(p.x, p.y))
                / n;
            let scatter = level.iter().fold(Matrix2::zeros(), |a, p| {
                let d = Vector2::new(p.x, p.y) - c;
                a + d * d.transpose()
            });
            let eig = SymmetricEigen::new(scatter);
            let (small, large) = if eig.eigenvalues[0] <= eig.eigenvalues[1] {
                (0, 1)
            } else {
                (1, 0)
            };
            // A line needs two places: points spread along it by less than their noise (the
            // rays along the hinge axis meet one spot in every scan) leave its azimuth free.
            let noise = points.iter().map(|p| p.sigma * p.sigma).sum::<f64>();
            if eig.eigenvalues[large] <= noise {
                return None;
            }
            let normal = eig.eigenvectors.column(small).into_owned();
            Some(Placement {
                offset: normal.dot(&c),
                azimuth: normal.y.atan2(normal.x),
            })
        }
    }
}
