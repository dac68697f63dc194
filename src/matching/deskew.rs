//! The robot's motion during a scan ("deskewing"). A 2D scanner casts its rays one after
//! another, over a few to a few tens of milliseconds; a robot that moves or turns meanwhile
//! casts each ray from a slightly different pose, and a scan read as if taken at one instant is
//! warped. Turning is what matters: at a yaw rate ω over a sweep of `T` seconds through π of
//! bearing, the world's bearings are stretched by `1 + ωT/π`, so a match between two scans of a
//! steady turn of Δθ finds `Δθ / (1 + ωT/π)`, always short of a turn the way the rays sweep
//! (`docs/RESULTS.md`, the pairwise heading bias on Freiburg 079). Pairwise matching adds that
//! error at every step.
//!
//! Each ray's point is moved into the scanner's frame at the mean time of the scan's rays (the
//! instant a scan matched as one rigid body stands for, so that deskewing removes the warp and
//! leaves the pose's meaning), with the scanner's velocity taken constant over the sweep (a
//! body twist; the pose after `t` seconds is its SE(2) exponential, exact for a constant
//! twist). The velocity is the odometry's between the previous scan and this one. Ray `i` is
//! cast `i × time_increment` after the stamp, as a ROS `sensor_msgs/LaserScan` defines it, or,
//! for a scanner that builds a fine scan from several interleaved sweeps (a SICK LMS 2xx at half
//! a degree takes its even rays on one turn of its mirror and its odd rays on the next), as
//! [`RayTiming`] says.

use crate::geometry::Pose2;
use nalgebra::Point2;

/// Settings of deskewing. Units in brackets.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DeskewParams {
    /// Time between two consecutive rays \[s\], overriding the scans' own (a ROS bag's
    /// `time_increment`); negative when the rays are listed in the reverse of the order they
    /// were cast. `None`: each scan's own.
    pub time_increment: Option<f64>,
    /// Interleaved sweeps per scan [-]. Default 1.
    pub interlace: usize,
    /// Time from one interleaved sweep to the next \[s\] (the scanner's mirror period). Default
    /// 1/75 s, a SICK LMS 2xx's.
    pub sweep_period: f64,
    /// Longest gap between two scans whose odometry gives the velocity \[s\]. Default 0.5: the
    /// mean velocity over a longer gap misses an indoor robot's starts, stops and turns, and a
    /// wrong velocity warps a scan that was right; such a scan is matched as recorded.
    pub max_gap: f64,
    /// Fastest plausible speed \[m/s\] and yaw rate \[rad/s\]. Defaults 10 m/s and a turn a
    /// second: beyond them the odometry or the timestamps are wrong (two scans stamped a
    /// millisecond apart), and a scan deskewed with such a velocity would be torn apart;
    /// it is matched as recorded.
    pub max_speed: f64,
    pub max_yaw_rate: f64,
}

impl Default for DeskewParams {
    fn default() -> Self {
        Self {
            time_increment: None,
            interlace: 1,
            sweep_period: 1.0 / 75.0,
            max_gap: 0.5,
            max_speed: 10.0,
            max_yaw_rate: std::f64::consts::TAU,
        }
    }
}

/// When each ray of a scan is cast, after the scan's stamp.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RayTiming {
    /// Time between two rays of one sweep, per ray of the whole scan \[s\]: a sweep of `k`
    /// interleaved ones steps `k` rays in `k × time_increment` (with one sweep, a ROS
    /// LaserScan's `time_increment`).
    pub time_increment: f64,
    /// Interleaved sweeps [-]: ray `i` belongs to sweep `i mod interlace`.
    pub interlace: usize,
    /// Time from one sweep to the next \[s\].
    pub sweep_period: f64,
}

impl RayTiming {
    /// One sweep, `time_increment` between rays.
    pub fn linear(time_increment: f64) -> Self {
        Self {
            time_increment,
            interlace: 1,
            sweep_period: 0.0,
        }
    }

    /// The time ray `i` is cast after the stamp \[s\]: its sweep's start, then its place in
    /// the sweep.
    pub fn of_ray(&self, i: usize) -> f64 {
        let k = self.interlace.max(1);
        let (sweep, place) = (i % k, i / k);
        sweep as f64 * self.sweep_period + (place * k) as f64 * self.time_increment
    }

    /// The mean time of a scan's `nrays` rays after its stamp \[s\]: the instant a scan
    /// matched as one rigid body stands for (to first order), and the one deskewing moves its
    /// rays to, so that a deskewed scan's pose means what an undeskewed one's did.
    pub fn mean(&self, nrays: usize) -> f64 {
        if nrays == 0 {
            return 0.0;
        }
        (0..nrays).map(|i| self.of_ray(i)).sum::<f64>() / nrays as f64
    }
}

/// The scanner's velocity during one scan, in its own frame (a body twist, constant over the
/// sweep).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SweepMotion {
    /// Forward and leftward speed \[m/s\].
    pub vx: f64,
    pub vy: f64,
    /// Yaw rate \[rad/s\], counter-clockwise positive.
    pub yaw_rate: f64,
}

/// `sin(a) / a` and `(1 - cos(a)) / a`, with their series near 0 (the SE(2) exponential's
/// coefficients).
fn exp_coefficients(a: f64) -> (f64, f64) {
    if a.abs() < 1e-6 {
        (1.0 - a * a / 6.0, a / 2.0 - a * a * a / 24.0)
    } else {
        (a.sin() / a, (1.0 - a.cos()) / a)
    }
}

impl SweepMotion {
    /// The constant body velocity that moves the scanner from `from` to `to` in `dt` seconds
    /// (the SE(2) logarithm of the step over `dt`). `None` unless `dt` is positive and finite.
    pub fn between(from: &Pose2, to: &Pose2, dt: f64) -> Option<Self> {
        if !(dt.is_finite() && dt > 0.0) {
            return None;
        }
        let step = from.between(to);
        let a = step.theta;
        let (s, c) = exp_coefficients(a);
        // The exponential's translation is V(a) · u with V = [[s, -c], [c, s]]; invert it.
        let det = s * s + c * c;
        let ux = (s * step.x + c * step.y) / det;
        let uy = (-c * step.x + s * step.y) / det;
        let motion = Self {
            vx: ux / dt,
            vy: uy / dt,
            yaw_rate: a / dt,
        };
        [motion.vx, motion.vy, motion.yaw_rate]
            .iter()
            .all(|v| v.is_finite())
            .then_some(motion)
    }

    /// The scanner's pose `t` seconds after an instant (before it, for negative `t`), in its
    /// frame at that instant.
    pub fn pose_after(&self, t: f64) -> Pose2 {
        let a = self.yaw_rate * t;
        let (s, c) = exp_coefficients(a);
        let (ux, uy) = (self.vx * t, self.vy * t);
        Pose2::new(s * ux - c * uy, c * ux + s * uy, a)
    }
}

/// Moves each point from the scanner's frame when its ray was cast, `times[i]` seconds after
/// some instant (negative: before it), into the scanner's frame at that instant.
pub fn deskew(points: &mut [Point2<f64>], times: &[f64], motion: &SweepMotion) {
    for (p, &t) in points.iter_mut().zip(times) {
        *p = motion.pose_after(t).transform_point(p);
    }
}

/// The velocity of each scan of a run, from its odometry and time and the previous scan's:
/// `None` for the first scan, a scan without odometry or time, one more than `max_gap` after
/// the previous, or a velocity beyond the plausible (see [`DeskewParams`]).
#[derive(Clone, Debug, Default)]
pub struct SweepTracker {
    previous: Option<(Pose2, f64)>,
}

impl SweepTracker {
    pub fn new() -> Self {
        Self::default()
    }

    /// This scan's velocity; remembers its odometry and time for the next.
    pub fn next(
        &mut self,
        odometry: Option<Pose2>,
        time: Option<f64>,
        params: &DeskewParams,
    ) -> Option<SweepMotion> {
        let current = odometry.zip(time);
        let motion = match (self.previous, current) {
            (Some((from, t0)), Some((to, t1))) if t1 - t0 <= params.max_gap => {
                SweepMotion::between(&from, &to, t1 - t0)
            }
            _ => None,
        };
        self.previous = current;
        motion.filter(|m| {
            m.vx.hypot(m.vy) <= params.max_speed && m.yaw_rate.abs() <= params.max_yaw_rate
        })
    }

    /// [`Self::next`], and `points` (cast `times` after the mean ray time) deskewed with the
    /// velocity when there is one; whether there was.
    pub fn deskew_next(
        &mut self,
        points: &mut [Point2<f64>],
        times: &[f64],
        odometry: Option<Pose2>,
        time: Option<f64>,
        params: &DeskewParams,
    ) -> bool {
        let motion = self.next(odometry, time, params);
        if let Some(motion) = &motion {
            deskew(points, times, motion);
        }
        motion.is_some()
    }
}

/// The line a deskewed run ends with, `name` first: how many of `total` scans were deskewed,
/// why the others were not, and a warning when fewer than half were.
pub fn deskew_summary(name: &str, deskewed: usize, total: usize, params: &DeskewParams) -> String {
    let warning = if 2 * deskewed < total {
        "warning: "
    } else {
        ""
    };
    format!(
        "{name}: {warning}deskewed {deskewed} of {total} scans; {} as recorded (the first scan, \
         and any without odometry and a timestamp, more than {} s after the previous one, or \
         moving implausibly fast)",
        total - deskewed,
        params.max_gap
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    /// Where a ray at `bearing` from `pose` meets the walls of the square room |x|, |y| <= 4
    /// (in the room's frame); the scanner stays well inside.
    fn hit(pose: &Pose2, bearing: f64) -> Point2<f64> {
        let a = pose.theta + bearing;
        let (dy, dx) = a.sin_cos();
        let mut t = f64::INFINITY;
        for (d, o) in [(dx, pose.x), (dy, pose.y)] {
            for wall in [-4.0, 4.0] {
                let tw = (wall - o) / d;
                if tw > 0.0 {
                    t = t.min(tw);
                }
            }
        }
        Point2::new(pose.x + t * dx, pose.y + t * dy)
    }

    /// A scan of 181 rays over 180 degrees, ray i cast `timing.of_ray(i)` after the stamp
    /// from the pose the motion has reached by then (from `start`): points in each ray's own
    /// scanner frame, and their times.
    fn swept_scan(
        start: &Pose2,
        motion: &SweepMotion,
        timing: &RayTiming,
    ) -> (Vec<Point2<f64>>, Vec<f64>) {
        (0..181)
            .map(|i| {
                let t = timing.of_ray(i);
                let pose = start.compose(&motion.pose_after(t));
                let bearing = -PI / 2.0 + i as f64 * PI / 180.0;
                (pose.inverse().transform_point(&hit(&pose, bearing)), t)
            })
            .unzip()
    }

    fn on_a_wall(p: &Point2<f64>) -> f64 {
        (p.x.abs() - 4.0).abs().min((p.y.abs() - 4.0).abs())
    }

    /// The farthest of `points` (in the scanner's frame at `start`) from the room's walls.
    fn worst(start: &Pose2, points: &[Point2<f64>]) -> f64 {
        points
            .iter()
            .map(|p| on_a_wall(&start.transform_point(p)))
            .fold(0.0, f64::max)
    }

    #[test]
    fn a_swept_scan_deskewed_lies_on_the_walls_it_hit() {
        let start = Pose2::new(0.3, -0.7, 0.4);
        // A fast turn while driving: 90 degrees a second at 1 m/s, over a 100 ms sweep.
        let motion = SweepMotion {
            vx: 1.0,
            vy: 0.1,
            yaw_rate: PI / 2.0,
        };
        let (mut points, times) = swept_scan(&start, &motion, &RayTiming::linear(0.1 / 180.0));
        // Read as if taken at the stamp, the scan misses the walls by centimetres...
        assert!(worst(&start, &points) > 0.05, "{}", worst(&start, &points));
        deskew(&mut points, &times, &motion);
        // ...and deskewed it lies on them, to rounding.
        assert!(worst(&start, &points) < 1e-9, "{}", worst(&start, &points));
    }

    #[test]
    fn interleaved_sweeps_deskew_with_their_own_timing_only() {
        let start = Pose2::new(-0.5, 0.2, -1.0);
        let motion = SweepMotion {
            vx: 0.5,
            vy: 0.0,
            yaw_rate: 0.6,
        };
        // A SICK LMS 2xx at half a degree: even rays on one mirror turn, odd on the next.
        let two = RayTiming {
            time_increment: 1.0 / 75.0 / 2.0 / 180.0,
            interlace: 2,
            sweep_period: 1.0 / 75.0,
        };
        let (points, times) = swept_scan(&start, &motion, &two);
        let mut right = points.clone();
        deskew(&mut right, &times, &motion);
        assert!(worst(&start, &right) < 1e-9, "{}", worst(&start, &right));
        // Timed as one sweep, the odd rays stay a mirror turn off.
        let linear: Vec<f64> = (0..181)
            .map(|i| RayTiming::linear(two.time_increment).of_ray(i))
            .collect();
        let mut wrong = points;
        deskew(&mut wrong, &linear, &motion);
        assert!(worst(&start, &wrong) > 1e-3, "{}", worst(&start, &wrong));
    }

    #[test]
    fn the_mean_ray_time_is_the_middle_of_the_sweeps() {
        let linear = RayTiming::linear(0.001);
        assert!((linear.mean(5) - 0.002).abs() < 1e-15);
        assert_eq!(linear.mean(0), 0.0);
        // Two sweeps of 3 rays, 10 ms apart: 0, 2, 4 ms and 10, 12, 14 ms.
        let two = RayTiming {
            time_increment: 0.001,
            interlace: 2,
            sweep_period: 0.01,
        };
        assert!((two.mean(6) - 0.007).abs() < 1e-15, "{}", two.mean(6));
    }

    #[test]
    fn the_velocity_between_two_poses_reaches_the_second() {
        let from = Pose2::new(1.0, 2.0, -2.9);
        for to in [
            Pose2::new(1.3, 1.9, 3.0),
            Pose2::new(1.0, 2.0, -2.9),
            Pose2::new(0.5, 2.0, -2.9 + 1e-8),
            Pose2::new(2.0, 3.0, 0.5),
        ] {
            let dt = 0.25;
            let m = SweepMotion::between(&from, &to, dt).unwrap();
            let reached = from.compose(&m.pose_after(dt));
            let d = reached.between(&to);
            assert!(
                d.x.abs() + d.y.abs() + d.theta.abs() < 1e-12,
                "{to:?}: {d:?}"
            );
        }
        assert_eq!(SweepMotion::between(&from, &from, 0.0), None);
        assert_eq!(SweepMotion::between(&from, &from, f64::NAN), None);
    }

    #[test]
    fn a_still_scanner_or_a_zero_sweep_changes_nothing() {
        let mut points = vec![Point2::new(1.0, 2.0), Point2::new(-3.0, 0.5)];
        let before = points.clone();
        deskew(&mut points, &[0.0, 0.01], &SweepMotion::default());
        assert_eq!(points, before);
        let moving = SweepMotion {
            vx: 1.0,
            vy: 0.0,
            yaw_rate: 1.0,
        };
        deskew(&mut points, &[0.0, 0.0], &moving);
        assert_eq!(points, before);
    }

    #[test]
    fn interleaved_sweeps_time_each_ray_by_its_sweep_and_place() {
        let linear = RayTiming::linear(0.001);
        assert_eq!((linear.of_ray(0), linear.of_ray(3)), (0.0, 0.003));
        // Two sweeps 10 ms apart, each stepping its rays 2 ms: even rays 0, 2, 4 ms...;
        // odd rays 10, 12, 14 ms...
        let two = RayTiming {
            time_increment: 0.001,
            interlace: 2,
            sweep_period: 0.01,
        };
        let times: Vec<f64> = (0..6).map(|i| two.of_ray(i)).collect();
        let want = [0.0, 0.01, 0.002, 0.012, 0.004, 0.014];
        for (t, w) in times.iter().zip(want) {
            assert!((t - w).abs() < 1e-15, "{times:?}");
        }
    }

    #[test]
    fn the_tracker_takes_the_velocity_from_the_previous_scan_within_the_gap() {
        let mut tracker = SweepTracker::new();
        let params = DeskewParams::default();
        let a = Pose2::new(0.0, 0.0, 0.0);
        let b = Pose2::new(0.1, 0.0, 0.05);
        assert_eq!(tracker.next(Some(a), Some(10.0), &params), None);
        let m = tracker.next(Some(b), Some(10.2), &params).unwrap();
        assert!((m.yaw_rate - 0.25).abs() < 1e-12, "{m:?}");
        // Too long after: no velocity, but the scan still becomes the previous one.
        assert_eq!(tracker.next(Some(a), Some(11.0), &params), None);
        assert!(tracker.next(Some(b), Some(11.1), &params).is_some());
        // No odometry: none, and none for the next either.
        assert_eq!(tracker.next(None, Some(11.2), &params), None);
        assert_eq!(tracker.next(Some(a), Some(11.3), &params), None);
        // Stamped a millisecond after: 100 m/s is no robot's, so none.
        assert_eq!(tracker.next(Some(b), Some(11.301), &params), None);
    }
}
