//! A hinge that moves while it scans (a nodding laser): the elevation each ray is cast at.
//!
//! A 2D scanner takes its rays one after another over one scan period; on a hinge turning at a
//! steady rate, each ray meets the world at the hinge angle of its own time. The scan is
//! centred on its nominal elevation: the middle ray (or the midpoint between the two middle
//! rays) is cast at it, so that a sweep changes each scan's geometry without moving it as a
//! whole, and `Scan::elevation` stays what the stop-and-scan robot would have used.

/// The time between two successive rays of a scan \[s\]: the rays spread evenly over the
/// scan period `scan_time`, as a spinning mirror sends them (a LaserScan's `time_increment`).
/// 0 for an empty scan.
pub fn time_increment(nrays: usize, scan_time: f64) -> f64 {
    if nrays == 0 {
        0.0
    } else {
        scan_time / nrays as f64
    }
}

/// The hinge elevation of each of `nrays` rays of a scan \[rad\] whose hinge turns at `rate`
/// \[rad/s\] (positive tilts the beams further down as time goes on) over a scan period
/// `scan_time` \[s\]: ray `i` leaves at `t_i = i * dt` (`dt` = [`time_increment`]) and is
/// cast at `nominal + rate * (t_i - t_mid)`, with `t_mid = (nrays - 1) / 2 * dt` the middle
/// of the rays' times. `None` when the rate is zero: the hinge stands still and every ray
/// takes the scan's elevation (stop-and-scan).
pub fn ray_elevations(nominal: f64, nrays: usize, rate: f64, scan_time: f64) -> Option<Vec<f64>> {
    if rate == 0.0 {
        return None;
    }
    let dt = time_increment(nrays, scan_time);
    let mid = (nrays as f64 - 1.0) / 2.0;
    Some(
        (0..nrays)
            .map(|i| nominal + rate * ((i as f64 - mid) * dt))
            .collect(),
    )
}

/// The largest distance of a ray's elevation from its scan's nominal one \[rad\]: half the
/// hinge's travel between the first ray and the last.
pub fn half_travel(nrays: usize, rate: f64, scan_time: f64) -> f64 {
    let n = nrays.max(1) as f64;
    rate.abs() * (n - 1.0) / 2.0 * time_increment(nrays, scan_time)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_still_hinge_gives_no_per_ray_elevation() {
        assert_eq!(ray_elevations(0.1, 181, 0.0, 0.025), None);
        assert_eq!(half_travel(181, 0.0, 0.025), 0.0);
    }

    #[test]
    fn rays_are_centred_on_the_nominal_elevation() {
        // 5 rays over 0.1 s: dt = 0.02 s; at 1 rad/s the rays step 0.02 rad, the middle one
        // at the nominal elevation.
        let e = ray_elevations(0.5, 5, 1.0, 0.1).unwrap();
        let want = [0.46, 0.48, 0.5, 0.52, 0.54];
        for (a, b) in e.iter().zip(want) {
            assert!((a - b).abs() < 1e-15, "{e:?}");
        }
        assert!((half_travel(5, 1.0, 0.1) - 0.04).abs() < 1e-15);
        // An even count: the nominal elevation lies between the two middle rays.
        let e = ray_elevations(0.0, 4, -2.0, 0.1).unwrap();
        assert!((e[1] + e[2]).abs() < 1e-15 && e[1] > 0.0, "{e:?}");
        assert!((e[0] - 0.075).abs() < 1e-15, "{e:?}");
        assert_eq!(ray_elevations(0.3, 1, 1.0, 0.1), Some(vec![0.3]));
        assert_eq!(ray_elevations(0.3, 0, 1.0, 0.1), Some(vec![]));
    }

    #[test]
    fn time_increment_spreads_rays_over_the_scan_period() {
        assert_eq!(time_increment(4, 0.1), 0.025);
        assert_eq!(time_increment(0, 0.1), 0.0);
    }
}
