//! One laser scan: the paper's `Laser_data` (its Fig. 13), on CSM's laser_data layout.
//!
//! A plain type with no I/O; `formats::scan_jsonl` reads and writes it.

use crate::geometry::{Pose, reading_in_robot};
use nalgebra::{Point2, Point3, Vector3};

/// What a simulated ray hit (the contract's `hit` field).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum Hit {
    Nothing = 0,
    Wall = 1,
    Floor = 2,
    Ceiling = 3,
}

impl Hit {
    pub fn from_code(code: u64) -> Option<Hit> {
        match code {
            0 => Some(Hit::Nothing),
            1 => Some(Hit::Wall),
            2 => Some(Hit::Floor),
            3 => Some(Hit::Ceiling),
            _ => None,
        }
    }
}

/// A scan timestamp as CSM writes it: `[sec, usec]`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct Timestamp {
    pub sec: i64,
    pub usec: i64,
}

impl Timestamp {
    pub fn seconds(&self) -> f64 {
        self.sec as f64 + self.usec as f64 * 1e-6
    }

    pub fn from_seconds(t: f64) -> Self {
        let sec = t.floor();
        Self {
            sec: sec as i64,
            usec: ((t - sec) * 1e6).round() as i64,
        }
    }
}

/// One scan. All per-ray vectors have `nrays` entries; `theta` is always filled in (from
/// `min_theta`/`max_theta` when the file had none).
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Scan {
    /// The pose this scan was taken at; scans of one pose share it.
    pub sequence: Option<u64>,
    /// Hinge elevation \[rad\]; positive tilts the beams down. With a hinge that moves while
    /// it scans, the scan's nominal (mid-scan) elevation.
    pub elevation: Option<f64>,
    /// Per-ray hinge elevation \[rad\], same sign as `elevation`, for a hinge that moves while
    /// it scans (a nodding laser: each ray is cast at the hinge angle of its own time). When
    /// present, it is what places each ray in 3D ([`Scan::point_in_robot`]).
    pub ray_elevation: Option<Vec<f64>>,
    /// Bearing of each ray \[rad\].
    pub theta: Vec<f64>,
    /// Range of each ray \[m\]; `None` where there was no return.
    pub readings: Vec<Option<f64>>,
    /// True where the ray hit something.
    pub valid: Vec<bool>,
    pub odometry: Option<Pose>,
    pub estimate: Option<Pose>,
    /// Ground truth; written by simulators, never read by `level` or `match`.
    pub true_pose: Option<Pose>,
    pub timestamp: Option<Timestamp>,
    /// Range noise per ray \[m\].
    pub readings_sigma: Option<Vec<Option<f64>>>,
    /// The scanner's origin seen from the hinge axis point, in the scanner's tilted frame \[m\].
    pub hinge_offset: Option<[f64; 3]>,
    /// Simulators only: what each ray hit.
    pub hit: Option<Vec<Hit>>,
    /// Fields this crate does not know, kept in input order for pass-through.
    pub extra: serde_json::Map<String, serde_json::Value>,
}

impl Scan {
    pub fn nrays(&self) -> usize {
        self.theta.len()
    }

    /// The range of ray `i` when it is valid, finite and positive (some logs write -1 or 0
    /// for "no return" and still mark the ray valid).
    pub fn range(&self, i: usize) -> Option<f64> {
        if !self.valid[i] {
            return None;
        }
        self.readings[i].filter(|r| r.is_finite() && *r > 0.0)
    }

    /// [`Scan::range`] of every ray in order, without per-ray bounds checks (hot loops).
    pub fn ranges(&self) -> impl ExactSizeIterator<Item = Option<f64>> + '_ {
        self.readings
            .iter()
            .zip(&self.valid)
            .map(|(r, &v)| r.filter(|r| v && r.is_finite() && *r > 0.0))
    }

    /// The scan's range noise as its `readings_sigma` states it \[m\]: the median over its valid
    /// rays of their finite, non-negative sigmas; `None` when no valid ray states one.
    pub fn stated_range_sigma(&self) -> Option<f64> {
        let sigmas = self.readings_sigma.as_ref()?;
        let mut given: Vec<f64> = self
            .ranges()
            .zip(sigmas)
            .filter_map(|(r, s)| r.and(*s))
            .filter(|s| s.is_finite() && *s >= 0.0)
            .collect();
        if given.is_empty() {
            return None;
        }
        let mid = given.len() / 2;
        let (_, m, _) = given.select_nth_unstable_by(mid, f64::total_cmp);
        Some(*m)
    }

    pub fn valid_count(&self) -> usize {
        (0..self.nrays())
            .filter(|&i| self.range(i).is_some())
            .count()
    }

    pub fn hinge_offset_vector(&self) -> Vector3<f64> {
        self.hinge_offset
            .map(|o| Vector3::new(o[0], o[1], o[2]))
            .unwrap_or_else(Vector3::zeros)
    }

    /// The hinge elevation ray `i` was cast at \[rad\]: its own `ray_elevation` when the scan
    /// has one, else the scan's `elevation` (0 when absent).
    pub fn elevation_of_ray(&self, i: usize) -> f64 {
        match &self.ray_elevation {
            Some(e) => e[i],
            None => self.elevation.unwrap_or(0.0),
        }
    }

    /// Ray `i` as a robot-frame 3D point, taking its elevation ([`Scan::elevation_of_ray`])
    /// and the hinge offset into account (paper sect. 5.1).
    pub fn point_in_robot(&self, i: usize) -> Option<Point3<f64>> {
        let r = self.range(i)?;
        Some(reading_in_robot(
            self.elevation_of_ray(i),
            self.theta[i],
            r,
            &self.hinge_offset_vector(),
        ))
    }

    /// Valid rays as 2D points in the scanner plane (x forward, y left), for planar matching.
    pub fn points_2d(&self) -> Vec<Point2<f64>> {
        (0..self.nrays())
            .filter_map(|i| {
                let r = self.range(i)?;
                let (s, c) = self.theta[i].sin_cos();
                Some(Point2::new(r * c, r * s))
            })
            .collect()
    }

    /// Builds a scan with evenly spread bearings from `min_theta` to `max_theta`.
    pub fn with_even_bearings(nrays: usize, min_theta: f64, max_theta: f64) -> Scan {
        Scan {
            theta: even_bearings(nrays, min_theta, max_theta),
            readings: vec![None; nrays],
            valid: vec![false; nrays],
            ..Scan::default()
        }
    }

    pub fn min_theta(&self) -> Option<f64> {
        self.theta.first().copied()
    }

    pub fn max_theta(&self) -> Option<f64> {
        self.theta.last().copied()
    }
}

/// `n` bearings spread evenly from `min` to `max`, both included.
pub fn even_bearings(n: usize, min: f64, max: f64) -> Vec<f64> {
    match n {
        0 => Vec::new(),
        1 => vec![min],
        _ => (0..n)
            .map(|i| min + (max - min) * i as f64 / (n - 1) as f64)
            .collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `ranges` is `range` of every ray: invalid, missing, zero, negative, non-finite.
    #[test]
    fn ranges_are_range_of_each_ray() {
        let readings = [
            Some(1.5),
            Some(2.0),
            None,
            Some(0.0),
            Some(-1.0),
            Some(f64::INFINITY),
            Some(f64::NAN),
            Some(1e-300),
        ];
        let s = Scan {
            theta: vec![0.0; readings.len()],
            readings: readings.to_vec(),
            valid: vec![true, false, true, true, true, true, true, true],
            ..Scan::default()
        };
        let each: Vec<Option<f64>> = (0..s.nrays()).map(|i| s.range(i)).collect();
        assert_eq!(s.ranges().collect::<Vec<_>>(), each);
        assert_eq!(each.iter().flatten().count(), 2);
    }

    #[test]
    fn stated_range_sigma_is_the_median_over_valid_rays() {
        let s = Scan {
            theta: vec![0.0; 6],
            readings: vec![Some(1.0), Some(2.0), Some(3.0), None, Some(4.0), Some(5.0)],
            valid: vec![true, true, true, true, false, true],
            // Ray 3 has no reading and ray 4 is invalid: their sigmas do not count; ray 5's
            // is not finite.
            readings_sigma: Some(vec![
                Some(0.03),
                Some(0.01),
                Some(0.02),
                Some(9.0),
                Some(9.0),
                Some(f64::NAN),
            ]),
            ..Scan::default()
        };
        assert_eq!(s.stated_range_sigma(), Some(0.02));
        let none = Scan {
            readings_sigma: None,
            ..s.clone()
        };
        assert_eq!(none.stated_range_sigma(), None);
        let nulls = Scan {
            readings_sigma: Some(vec![None; 6]),
            ..s
        };
        assert_eq!(nulls.stated_range_sigma(), None);
    }

    #[test]
    fn even_bearings_include_both_ends() {
        let b = even_bearings(
            181,
            -std::f64::consts::FRAC_PI_2,
            std::f64::consts::FRAC_PI_2,
        );
        assert_eq!(b.len(), 181);
        assert!((b[0] + std::f64::consts::FRAC_PI_2).abs() < 1e-15);
        assert!((b[180] - std::f64::consts::FRAC_PI_2).abs() < 1e-15);
        assert!((b[90]).abs() < 1e-15);
    }

    #[test]
    fn invalid_rays_have_no_point() {
        let mut s = Scan::with_even_bearings(3, -0.1, 0.1);
        s.readings[1] = Some(2.0);
        s.valid[1] = true;
        s.readings[2] = Some(2.0); // a reading that is marked invalid stays invalid
        s.readings[0] = Some(-1.0); // "no return" in some logs, even when marked valid
        s.valid[0] = true;
        assert!(s.point_in_robot(0).is_none());
        assert!(s.point_in_robot(2).is_none());
        let p = s.point_in_robot(1).unwrap();
        assert!((p.coords.norm() - 2.0).abs() < 1e-12);
        assert_eq!(s.valid_count(), 1);
    }

    /// A per-ray elevation places each ray at its own hinge angle; without it, the scan's
    /// elevation does.
    #[test]
    fn ray_elevation_places_each_ray() {
        let mut s = Scan::with_even_bearings(2, 0.0, 0.0);
        s.readings = vec![Some(2.0); 2];
        s.valid = vec![true; 2];
        s.elevation = Some(0.1);
        let nominal = s.point_in_robot(1).unwrap();
        assert!(
            (nominal - Point3::new(2.0 * 0.1f64.cos(), 0.0, -2.0 * 0.1f64.sin())).norm() < 1e-12
        );
        s.ray_elevation = Some(vec![0.0, 0.3]);
        let flat = s.point_in_robot(0).unwrap();
        let tilted = s.point_in_robot(1).unwrap();
        assert!((flat - Point3::new(2.0, 0.0, 0.0)).norm() < 1e-12);
        assert!(
            (tilted - Point3::new(2.0 * 0.3f64.cos(), 0.0, -2.0 * 0.3f64.sin())).norm() < 1e-12
        );
        assert_eq!(s.elevation_of_ray(1), 0.3);
    }

    #[test]
    fn timestamp_seconds_roundtrip() {
        let t = Timestamp::from_seconds(1234.5678);
        assert_eq!(t.sec, 1234);
        assert_eq!(t.usec, 567800);
        assert!((t.seconds() - 1234.5678).abs() < 1e-6);
    }
}
