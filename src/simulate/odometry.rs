//! Planar dead reckoning with drift: what the robot's wheel odometry would report.
//!
//! Each step between consecutive true poses is measured in the robot's frame (x, y, heading),
//! corrupted by independent Gaussian noise whose spread grows with the step (the usual
//! odometry motion model, Thrun, Burgard & Fox, "Probabilistic Robotics", sect. 5.4), and
//! composed onto the previous odometry pose, so errors accumulate as drift. The first pose's
//! odometry is its true planar pose. Odometry is planar: z, pitch and roll are 0.

use super::{Stream, stream_rng};
use crate::geometry::{Pose, Pose2, wrap_angle};
use rand_distr::{Distribution, StandardNormal};

/// Noise of one odometry step. Defaults follow the perturbation issue 4 uses on real logs:
/// 2% of the distance + 5 mm, and 2% of the rotation + 0.5 degree.
#[derive(Clone, Debug, PartialEq)]
pub struct OdometryParams {
    /// Translation sigma per metre travelled, for x and y each [m/m]. Default 0.02.
    pub trans_per_m: f64,
    /// Translation sigma added to every step, for x and y each \[m\]. Default 0.005.
    pub trans_const: f64,
    /// Heading sigma per radian turned [rad/rad]. Default 0.02.
    pub rot_per_rad: f64,
    /// Heading sigma added to every step \[rad\]. Default 0.5 deg.
    pub rot_const: f64,
}

impl Default for OdometryParams {
    fn default() -> Self {
        Self {
            trans_per_m: 0.02,
            trans_const: 0.005,
            rot_per_rad: 0.02,
            rot_const: 0.5_f64.to_radians(),
        }
    }
}

impl OdometryParams {
    /// No noise: odometry equals the true planar poses.
    pub fn exact() -> Self {
        Self {
            trans_per_m: 0.0,
            trans_const: 0.0,
            rot_per_rad: 0.0,
            rot_const: 0.0,
        }
    }

    pub fn is_valid(&self) -> bool {
        [
            self.trans_per_m,
            self.trans_const,
            self.rot_per_rad,
            self.rot_const,
        ]
        .iter()
        .all(|v| *v >= 0.0 && v.is_finite())
    }
}

/// The odometry of each of `poses` (in chronological order), as 6-poses whose x, y and yaw
/// drift and whose z, pitch and roll are 0. Step `i`'s noise comes from its own random
/// stream, derived from `seed` and `i`.
pub fn odometry(poses: &[Pose], params: &OdometryParams, seed: u64) -> Vec<Pose> {
    let mut out = Vec::with_capacity(poses.len());
    let Some(first) = poses.first() else {
        return out;
    };
    let mut current = first.to_pose2();
    out.push(planar(&current));
    for (i, pair) in poses.windows(2).enumerate() {
        let step = pair[0].to_pose2().between(&pair[1].to_pose2());
        let mut rng = stream_rng(seed, Stream::Odometry, i as u64 + 1);
        let dist = step.x.hypot(step.y);
        let s_t = params.trans_per_m * dist + params.trans_const;
        let s_r = params.rot_per_rad * step.theta.abs() + params.rot_const;
        let mut n = || -> f64 { StandardNormal.sample(&mut rng) };
        let noisy = Pose2::new(
            step.x + s_t * n(),
            step.y + s_t * n(),
            wrap_angle(step.theta + s_r * n()),
        );
        current = current.compose(&noisy);
        out.push(planar(&current));
    }
    out
}

fn planar(p: &Pose2) -> Pose {
    Pose::planar(p.x, p.y, p.theta)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn path(n: usize) -> Vec<Pose> {
        (0..n)
            .map(|i| {
                let a = i as f64 * 0.05;
                Pose::new(3.0 * a.cos(), 3.0 * a.sin(), 0.45, a + 1.5, 0.1, -0.05)
            })
            .collect()
    }

    #[test]
    fn exact_odometry_is_the_planar_truth() {
        let poses = path(50);
        let odo = odometry(&poses, &OdometryParams::exact(), 1);
        for (o, p) in odo.iter().zip(&poses) {
            assert!((o.x - p.x).abs() < 1e-9 && (o.y - p.y).abs() < 1e-9);
            assert!(wrap_angle(o.rz - p.rz).abs() < 1e-9);
            assert!(o.z == 0.0 && o.ry == 0.0 && o.rx == 0.0);
        }
    }

    #[test]
    fn noisy_odometry_starts_true_and_drifts() {
        let poses = path(200);
        let odo = odometry(&poses, &OdometryParams::default(), 5);
        assert_eq!(odo[0], Pose::planar(poses[0].x, poses[0].y, poses[0].rz));
        let last = odo.last().unwrap();
        let truth = poses.last().unwrap();
        // 199 steps with 0.5 deg heading noise each: about 7 deg of drift; never exact.
        assert!((last.x - truth.x).hypot(last.y - truth.y) > 1e-3);
        // Steps stay close to the true steps: drift, not jumps.
        for (w, t) in odo.windows(2).zip(poses.windows(2)) {
            let so = w[0].to_pose2().between(&w[1].to_pose2());
            let st = t[0].to_pose2().between(&t[1].to_pose2());
            assert!((so.x - st.x).hypot(so.y - st.y) < 0.1);
        }
    }

    #[test]
    fn step_noise_depends_on_seed_and_step_only() {
        let poses = path(30);
        let a = odometry(&poses, &OdometryParams::default(), 9);
        let b = odometry(&poses[..10], &OdometryParams::default(), 9);
        assert_eq!(&a[..10], &b[..]);
        assert_ne!(a, odometry(&poses, &OdometryParams::default(), 10));
    }
}
