//! Time series of the signals a scan is interpolated in: the hinge joint's position, odometry
//! and ground truth. Plain data, no I/O.

use crate::geometry::Pose;

/// Samples `(t [s], value)`, sorted by time once collected.
#[derive(Clone, Debug, Default)]
pub struct Series<T> {
    samples: Vec<(f64, T)>,
}

/// Values that can be interpolated linearly between two samples.
pub trait Lerp: Copy {
    fn lerp(a: Self, b: Self, s: f64) -> Self;
}

impl Lerp for f64 {
    fn lerp(a: f64, b: f64, s: f64) -> f64 {
        a + (b - a) * s
    }
}

/// Shortest signed angle from `a` to `b` (rad), so that yaw interpolates across +-pi.
pub(crate) fn angle_diff(a: f64, b: f64) -> f64 {
    let d = (b - a).rem_euclid(std::f64::consts::TAU);
    if d > std::f64::consts::PI {
        d - std::f64::consts::TAU
    } else {
        d
    }
}

impl Lerp for Pose {
    fn lerp(a: Pose, b: Pose, s: f64) -> Pose {
        let angle = |x: f64, y: f64| {
            let v = x + angle_diff(x, y) * s;
            // Back into (-pi, pi].
            v - std::f64::consts::TAU * ((v + std::f64::consts::PI) / std::f64::consts::TAU).floor()
        };
        Pose::new(
            f64::lerp(a.x, b.x, s),
            f64::lerp(a.y, b.y, s),
            f64::lerp(a.z, b.z, s),
            angle(a.rz, b.rz),
            f64::lerp(a.ry, b.ry, s),
            f64::lerp(a.rx, b.rx, s),
        )
    }
}

impl<T: Lerp> Series<T> {
    pub fn push(&mut self, t: f64, value: T) {
        self.samples.push((t, value));
    }

    pub fn len(&self) -> usize {
        self.samples.len()
    }

    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    /// Sorts by time (stable: samples of equal time keep their order). Bags are mostly in
    /// order already, so this is close to linear.
    pub fn finish(&mut self) {
        self.samples.sort_by(|a, b| a.0.total_cmp(&b.0));
    }

    /// The value at `t`, interpolated linearly between the samples either side; outside the
    /// samples' span the nearest end. `None` when no sample lies within `tolerance` seconds of
    /// `t` (the nearer neighbour counts), or there are no samples.
    pub fn at(&self, t: f64, tolerance: f64) -> Option<T> {
        let i = self.samples.partition_point(|(ts, _)| *ts < t);
        let after = self.samples.get(i);
        let before = i.checked_sub(1).and_then(|j| self.samples.get(j));
        let near = |s: Option<&(f64, T)>| s.is_some_and(|(ts, _)| (ts - t).abs() <= tolerance);
        if !near(before) && !near(after) {
            return None;
        }
        Some(match (before, after) {
            (Some(&(t0, a)), Some(&(t1, b))) if t1 > t0 => T::lerp(a, b, (t - t0) / (t1 - t0)),
            (_, Some(&(_, b))) => b,
            (Some(&(_, a)), None) => a,
            (None, None) => unreachable!("near() of two Nones is false"),
        })
    }

    /// The time of the sample nearest to `t`.
    pub fn nearest_time(&self, t: f64) -> Option<f64> {
        let i = self.samples.partition_point(|(ts, _)| *ts < t);
        [i.checked_sub(1), Some(i)]
            .into_iter()
            .flatten()
            .filter_map(|j| self.samples.get(j).map(|s| s.0))
            .min_by(|a, b| (a - t).abs().total_cmp(&(b - t).abs()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn series(points: &[(f64, f64)]) -> Series<f64> {
        let mut s = Series::default();
        for &(t, v) in points {
            s.push(t, v);
        }
        s.finish();
        s
    }

    #[test]
    fn interpolates_linearly_and_holds_the_ends() {
        let s = series(&[(2.0, 1.0), (1.0, 0.0), (3.0, 5.0)]);
        assert_eq!(s.at(1.5, 0.5), Some(0.5));
        assert_eq!(s.at(2.5, 1.0), Some(3.0));
        assert_eq!(s.at(0.95, 0.1), Some(0.0));
        assert_eq!(s.at(3.05, 0.1), Some(5.0));
        assert_eq!(s.at(0.5, 0.1), None);
        // Inside the span but both samples too far: none within the tolerance.
        assert_eq!(s.at(1.5, 0.1), None);
        assert_eq!(series(&[(1.0, 0.0), (3.0, 2.0)]).at(2.0, 0.1), None);
        assert_eq!(Series::<f64>::default().at(0.0, 1.0), None);
    }

    #[test]
    fn yaw_interpolates_across_pi() {
        let a = Pose::planar(0.0, 0.0, 3.1);
        let b = Pose::planar(2.0, 0.0, -3.1);
        let m = Pose::lerp(a, b, 0.5);
        assert!((m.rz.abs() - std::f64::consts::PI).abs() < 1e-9, "{}", m.rz);
        assert!((m.x - 1.0).abs() < 1e-12);
    }

    proptest! {
        /// Brute force: the interpolated value lies between the two samples that bracket t.
        #[test]
        fn value_lies_between_its_neighbours(
            mut pts in proptest::collection::vec((0.0..10.0f64, -5.0..5.0f64), 2..30),
            t in 0.0..10.0f64,
        ) {
            pts.sort_by(|a, b| a.0.total_cmp(&b.0));
            pts.dedup_by(|a, b| a.0 == b.0);
            let s = series(&pts);
            if let Some(v) = s.at(t, 100.0) {
                let before = pts.iter().rev().find(|p| p.0 < t).map(|p| p.1);
                let after = pts.iter().find(|p| p.0 >= t).map(|p| p.1);
                let (lo, hi) = match (before, after) {
                    (Some(a), Some(b)) => (a.min(b), a.max(b)),
                    (Some(a), None) | (None, Some(a)) => (a, a),
                    (None, None) => unreachable!(),
                };
                prop_assert!(v >= lo - 1e-9 && v <= hi + 1e-9);
            }
        }
    }
}
