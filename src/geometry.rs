//! Frames, poses and rotations, fixed by the contract (ROS REP-103, right-handed).
//!
//! Robot frame: x forward, y left, z up. A 6-DOF pose `[x, y, z, rz, ry, rx]` (the paper's order,
//! sect. 3.4) maps a robot-frame point p to the world as `w = Rz(rz) · Ry(ry) · Rx(rx) · p + t`.
//! The robot's attitude to level is `theta_x = rx` (roll) and `theta_y = ry` (pitch), and
//! `level_from_robot = Ry(ry) · Rx(rx)`.
//!
//! Note: the paper's appendix A uses the opposite sign for `Ry`; the formulas here follow the
//! contract and are checked against the rotation matrices in the tests.

use nalgebra::{
    Isometry3, Matrix2, Matrix3, Point2, Point3, Rotation3, Translation3, UnitQuaternion, Vector2,
    Vector3,
};
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// Rotation about +x by `a` radians (right hand).
pub fn rot_x(a: f64) -> Rotation3<f64> {
    Rotation3::from_axis_angle(&Vector3::x_axis(), a)
}

/// Rotation about +y by `a` radians (right hand; positive tilts +x down towards -z).
pub fn rot_y(a: f64) -> Rotation3<f64> {
    Rotation3::from_axis_angle(&Vector3::y_axis(), a)
}

/// Rotation about +z by `a` radians (right hand).
pub fn rot_z(a: f64) -> Rotation3<f64> {
    Rotation3::from_axis_angle(&Vector3::z_axis(), a)
}

/// Wraps an angle to (-pi, pi].
pub fn wrap_angle(a: f64) -> f64 {
    let mut w = a.rem_euclid(2.0 * PI);
    if w > PI {
        w -= 2.0 * PI;
    }
    w
}

/// The robot's attitude to the level plane: roll `theta_x` and pitch `theta_y`, radians.
#[derive(Clone, Copy, Debug, PartialEq, Default, Serialize, Deserialize)]
pub struct Attitude {
    /// Roll, rotation about the robot's x axis \[rad\].
    pub theta_x: f64,
    /// Pitch, rotation about the robot's y axis \[rad\].
    pub theta_y: f64,
}

impl Attitude {
    pub fn new(theta_x: f64, theta_y: f64) -> Self {
        Self { theta_x, theta_y }
    }

    /// `level_from_robot = Ry(theta_y) · Rx(theta_x)`: takes robot-frame points to a frame
    /// whose z is the true up and whose heading is the robot's.
    pub fn level_from_robot(&self) -> Rotation3<f64> {
        rot_y(self.theta_y) * rot_x(self.theta_x)
    }

    /// The true up vector seen in the robot frame:
    /// `(-sin ry, cos ry · sin rx, cos ry · cos rx)`.
    pub fn up_in_robot(&self) -> Vector3<f64> {
        let (sx, cx) = self.theta_x.sin_cos();
        let (sy, cy) = self.theta_y.sin_cos();
        Vector3::new(-sy, cy * sx, cy * cx)
    }

    /// Recovers the attitude from the up vector in the robot frame (need not be unit length):
    /// `theta_x = atan2(up_y, up_z)`, `theta_y = atan2(-up_x, hypot(up_y, up_z))`.
    pub fn from_up(up: &Vector3<f64>) -> Self {
        Self {
            theta_x: up.y.atan2(up.z),
            theta_y: (-up.x).atan2(up.y.hypot(up.z)),
        }
    }

    /// The paper's error measure (sect. 8.1): `max(|dx|, |dy|)` in radians.
    pub fn max_abs_error(&self, truth: &Attitude) -> f64 {
        (self.theta_x - truth.theta_x)
            .abs()
            .max((self.theta_y - truth.theta_y).abs())
    }
}

/// A 6-DOF pose `[x, y, z, rz, ry, rx]` (metres, radians), the paper's order.
#[derive(Clone, Copy, Debug, PartialEq, Default, Serialize, Deserialize)]
pub struct Pose {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    /// Yaw \[rad\].
    pub rz: f64,
    /// Pitch \[rad\].
    pub ry: f64,
    /// Roll \[rad\].
    pub rx: f64,
}

impl Pose {
    pub fn new(x: f64, y: f64, z: f64, rz: f64, ry: f64, rx: f64) -> Self {
        Self {
            x,
            y,
            z,
            rz,
            ry,
            rx,
        }
    }

    /// A planar pose: `[x, y, rz]` with z, pitch and roll zero.
    pub fn planar(x: f64, y: f64, rz: f64) -> Self {
        Self::new(x, y, 0.0, rz, 0.0, 0.0)
    }

    /// From the paper's array order `[x, y, z, rz, ry, rx]`.
    pub fn from_array(a: [f64; 6]) -> Self {
        Self::new(a[0], a[1], a[2], a[3], a[4], a[5])
    }

    /// To the paper's array order `[x, y, z, rz, ry, rx]`.
    pub fn to_array(&self) -> [f64; 6] {
        [self.x, self.y, self.z, self.rz, self.ry, self.rx]
    }

    /// True when only x, y and yaw are set, so `[x, y, rz]` says all of it.
    pub fn is_planar(&self) -> bool {
        self.z == 0.0 && self.ry == 0.0 && self.rx == 0.0
    }

    pub fn attitude(&self) -> Attitude {
        Attitude::new(self.rx, self.ry)
    }

    /// `Rz(rz) · Ry(ry) · Rx(rx)`.
    pub fn world_from_robot_rotation(&self) -> Rotation3<f64> {
        rot_z(self.rz) * rot_y(self.ry) * rot_x(self.rx)
    }

    pub fn world_from_robot(&self) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(self.x, self.y, self.z),
            UnitQuaternion::from_rotation_matrix(&self.world_from_robot_rotation()),
        )
    }

    /// The planar part `(x, y, rz)`.
    pub fn to_pose2(&self) -> Pose2 {
        Pose2::new(self.x, self.y, self.rz)
    }
}

/// A planar pose in SE(2): position (metres) and heading (radians).
#[derive(Clone, Copy, Debug, PartialEq, Default, Serialize, Deserialize)]
pub struct Pose2 {
    pub x: f64,
    pub y: f64,
    pub theta: f64,
}

impl Pose2 {
    pub fn new(x: f64, y: f64, theta: f64) -> Self {
        Self { x, y, theta }
    }

    pub fn identity() -> Self {
        Self::default()
    }

    /// `self ⊕ other`: the pose `other`, given in self's frame, seen in self's parent frame.
    pub fn compose(&self, other: &Pose2) -> Pose2 {
        let (s, c) = self.theta.sin_cos();
        Pose2::new(
            self.x + c * other.x - s * other.y,
            self.y + s * other.x + c * other.y,
            wrap_angle(self.theta + other.theta),
        )
    }

    pub fn inverse(&self) -> Pose2 {
        let (s, c) = self.theta.sin_cos();
        Pose2::new(
            -(c * self.x + s * self.y),
            -(-s * self.x + c * self.y),
            wrap_angle(-self.theta),
        )
    }

    /// `self⁻¹ ⊕ other`: where `other` is, seen from `self`.
    pub fn between(&self, other: &Pose2) -> Pose2 {
        self.inverse().compose(other)
    }

    /// Maps a point from this pose's frame to the parent frame.
    pub fn transform_point(&self, p: &Point2<f64>) -> Point2<f64> {
        let (s, c) = self.theta.sin_cos();
        Point2::new(self.x + c * p.x - s * p.y, self.y + s * p.x + c * p.y)
    }

    pub fn translation(&self) -> Vector2<f64> {
        Vector2::new(self.x, self.y)
    }
}

/// Direction of a beam at `bearing` with the hinge at `elevation`, in the robot frame:
/// `Ry(e) · (cos phi, sin phi, 0)`. Positive elevation tilts the beam down (REP-103 pitch).
pub fn beam_direction(elevation: f64, bearing: f64) -> Vector3<f64> {
    let (sp, cp) = bearing.sin_cos();
    rot_y(elevation) * Vector3::new(cp, sp, 0.0)
}

/// Origin of the beams in the robot frame: `Ry(e) · o` for hinge offset `o`
/// (the scanner's origin seen from the hinge axis point, in the scanner's tilted frame).
pub fn beam_origin(elevation: f64, hinge_offset: &Vector3<f64>) -> Point3<f64> {
    Point3::from(rot_y(elevation) * hinge_offset)
}

/// The robot-frame point of a reading `range` at `bearing`:
/// `Ry(e) · (o + r · (cos phi, sin phi, 0))` (paper sect. 5.1, contract).
pub fn reading_in_robot(
    elevation: f64,
    bearing: f64,
    range: f64,
    hinge_offset: &Vector3<f64>,
) -> Point3<f64> {
    let (sp, cp) = bearing.sin_cos();
    Point3::from(rot_y(elevation) * (hinge_offset + range * Vector3::new(cp, sp, 0.0)))
}

/// Smallest angle between two unit vectors' lines, ignoring sign, in radians.
pub fn angle_between_lines(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    a.dot(b).abs().min(1.0).acos()
}

/// The unit eigenvector of the smaller eigenvalue of a symmetric 2x2 matrix (a scatter's: the
/// normal of the total-least-squares line through its points). Shared by the leveler's wall
/// lines and the scan matcher's local lines.
pub fn minor_axis_2x2(m: &Matrix2<f64>) -> Vector2<f64> {
    let (a, b, c) = (m[(0, 0)], 0.5 * (m[(0, 1)] + m[(1, 0)]), m[(1, 1)]);
    // The major axis is at angle phi = atan2(2b, a - c) / 2; the minor one is perpendicular.
    let phi = 0.5 * (2.0 * b).atan2(a - c);
    let (s, co) = phi.sin_cos();
    Vector2::new(-s, co)
}

/// The inverse of a symmetric 2x2 matrix on the directions it fixes (eigenvalues above 1e-12
/// of the largest), zero on the others: eliminating a block of normal equations (a surface's
/// or a wall's placement, by the Schur complement) where the data leave part of it free, whose
/// free directions then couple to nothing either. `None` when the matrix is not finite.
pub(crate) fn pseudo_inverse_2x2(m: &Matrix2<f64>) -> Option<Matrix2<f64>> {
    if !m.iter().all(|v| v.is_finite()) {
        return None;
    }
    let eig = m.symmetric_eigen();
    let top = eig.eigenvalues.amax();
    let mut inv = Matrix2::zeros();
    for k in 0..2 {
        let l = eig.eigenvalues[k];
        if l > top * 1e-12 && l > 0.0 {
            let v = eig.eigenvectors.column(k);
            inv += v * v.transpose() / l;
        }
    }
    Some(inv)
}

/// Builds `Ry(ry) · Rx(rx)` as a plain matrix, for hot loops.
pub fn level_from_robot_matrix(att: &Attitude) -> Matrix3<f64> {
    *att.level_from_robot().matrix()
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const EPS: f64 = 1e-12;

    #[test]
    fn pseudo_inverse_2x2_inverts_what_is_fixed_and_leaves_the_free_direction() {
        let m = Matrix2::new(4.0, 1.0, 1.0, 3.0);
        let inv = pseudo_inverse_2x2(&m).unwrap();
        assert!((inv * m - Matrix2::identity()).norm() < EPS);
        // Rank one: 2 v v^T inverts to v v^T / 2, zero along the perpendicular.
        let v = Vector2::new(0.6, 0.8);
        let inv = pseudo_inverse_2x2(&(2.0 * v * v.transpose())).unwrap();
        assert!((inv - v * v.transpose() / 2.0).norm() < EPS);
        assert!(pseudo_inverse_2x2(&Matrix2::new(f64::NAN, 0.0, 0.0, 1.0)).is_none());
    }

    #[test]
    fn rot_y_positive_tilts_forward_beam_down() {
        let d = beam_direction(0.1, 0.0);
        assert!(d.z < 0.0);
        assert!((d.z + 0.1f64.sin()).abs() < EPS);
    }

    #[test]
    fn up_formula_matches_rotation_transpose() {
        let att = Attitude::new(0.3, -0.2);
        let pose = Pose::new(1.0, 2.0, 0.5, 0.7, att.theta_y, att.theta_x);
        let up = pose.world_from_robot_rotation().inverse() * Vector3::z();
        assert!((up - att.up_in_robot()).norm() < EPS);
        // Levelling the up vector gives the world's z axis.
        assert!((att.level_from_robot() * up - Vector3::z()).norm() < EPS);
    }

    #[test]
    fn pose2_compose_known_values() {
        let a = Pose2::new(1.0, 0.0, PI / 2.0);
        let b = Pose2::new(1.0, 0.0, 0.0);
        let c = a.compose(&b);
        assert!((c.x - 1.0).abs() < EPS && (c.y - 1.0).abs() < EPS);
        assert!((c.theta - PI / 2.0).abs() < EPS);
    }

    #[test]
    fn hinge_offset_is_rotated_with_the_scanner() {
        let o = Vector3::new(0.1, 0.0, 0.05);
        let p = reading_in_robot(PI / 2.0, 0.0, 1.0, &o);
        // Tilted straight down: forward (x) becomes -z, up (z) becomes +x.
        assert!((p - Point3::new(0.05, 0.0, -1.1)).norm() < 1e-12);
    }

    proptest! {
        #[test]
        fn attitude_roundtrips_through_up(rx in -1.2f64..1.2, ry in -1.2f64..1.2, scale in 0.1f64..10.0) {
            let att = Attitude::new(rx, ry);
            let back = Attitude::from_up(&(att.up_in_robot() * scale));
            prop_assert!((back.theta_x - rx).abs() < 1e-9);
            prop_assert!((back.theta_y - ry).abs() < 1e-9);
        }

        #[test]
        fn pose2_inverse_composes_to_identity(x in -50.0f64..50.0, y in -50.0f64..50.0, t in -4.0f64..4.0) {
            let p = Pose2::new(x, y, t);
            let i = p.compose(&p.inverse());
            prop_assert!(i.x.abs() < 1e-9 && i.y.abs() < 1e-9 && wrap_angle(i.theta).abs() < 1e-9);
        }

        #[test]
        fn world_from_robot_then_inverse_is_identity(
            x in -20.0f64..20.0, rz in -3.0f64..3.0, ry in -0.7f64..0.7, rx in -0.7f64..0.7,
            px in -5.0f64..5.0, py in -5.0f64..5.0, pz in -5.0f64..5.0,
        ) {
            let pose = Pose::new(x, -x, 0.4, rz, ry, rx);
            let iso = pose.world_from_robot();
            let p = Point3::new(px, py, pz);
            let back = iso.inverse_transform_point(&iso.transform_point(&p));
            prop_assert!((back - p).norm() < 1e-9);
        }
    }
}
