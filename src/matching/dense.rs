//! Local lines for scans denser than they are built for.
//!
//! A point's local line is fitted through its neighbours, `NormalParams::window` rays on each
//! side. At the SICK family's 0.5-1 degree spacing (the paper's scanner, the CARMEN logs) that
//! window spans enough of a wall for the fit to beat 1 cm of range noise. A Hokuyo UTM-30LX
//! (1081 rays over 270 degrees, 0.25 degree) puts the same window over a quarter of the wall:
//! most fits are too thick to give a line and those that pass have noisy normals. Metascan
//! through the two-room example then erred by 6-12 mm (ATE, level floor, 1 cm of noise), and
//! by 17-33 mm with 1081 rays over 180 degrees, against 2 mm with the paper's 181 rays
//! (docs/RESULTS.md, fifteenth session). So the lines of such a scan are fitted through the
//! means of runs of consecutive rays, spaced as the window was made for, with the noise cut
//! by `sqrt(k)` (as a Hokuyo's own grouping of steps does); every ray is still matched, with
//! its run's line. A scan at or below the density is left as it is.
//!
//! Noisier scanners need the same: the window was made for 1 cm of range noise, and at 5 cm a
//! wall's fit over nine rays is too thick to give a line. A line's normal through `n` points of
//! noise `s` spread over a length `L` has a sigma of about `s sqrt(12 / n) / L`; averaging runs
//! of `k` rays cuts `s` by `sqrt(k)` and, the window being counted in runs, stretches `L` by
//! `k`, so the normal's sigma falls as `k^1.5`. A scan whose range noise is stated
//! (`NormalParams::range_sigma`) takes the run length that brings its normals back to the
//! window's own: the nearest whole `k` to `(sigma / 1 cm)^(2/3)`, 2 from 1.84 cm, 3 at 5 cm,
//! 5 at 10 cm (docs/RESULTS.md, sixteenth session).

use super::reference::{Line, NormalParams, is_gap, lines_through};
use nalgebra::{Point2, Vector2};

/// How many consecutive rays to average for a scan of `rays_per_degree` to be at most
/// `max_rays_per_degree`: 1 (none) at or below it, and when the limit is off (0 or not finite).
/// A scan at the limit to within rounding (0.5 degree spacing read back as 2.0000001 rays a
/// degree) is at it.
pub(crate) fn group_size(rays_per_degree: f64, max_rays_per_degree: f64) -> usize {
    if !(max_rays_per_degree > 0.0
        && max_rays_per_degree.is_finite()
        && rays_per_degree.is_finite())
    {
        return 1;
    }
    let k = (rays_per_degree / max_rays_per_degree * (1.0 - 1e-6)).ceil();
    if k > 1.0 { k as usize } else { 1 }
}

/// The range noise the line window (`NormalParams::window`, four rays a side) was made for
/// \[m\]: the simulator's default and the paper's scanner.
pub(crate) const WINDOW_SIGMA: f64 = 0.01;

/// How many consecutive rays to average for lines whose normals are as good as the window's
/// at [`WINDOW_SIGMA`], for a scan of range noise `range_sigma` \[m\]: the nearest whole number
/// to `(range_sigma / WINDOW_SIGMA)^(2/3)`, at least 1 (also for a noise not finite).
pub(crate) fn noise_group_size(range_sigma: f64) -> usize {
    let k = (range_sigma / WINDOW_SIGMA).powf(2.0 / 3.0).round();
    if k > 1.0 && k.is_finite() {
        k as usize
    } else {
        1
    }
}

/// The run length for a scan of `rays_per_degree` under `params`: long enough for both its
/// density ([`group_size`]) and its range noise ([`noise_group_size`]).
pub(crate) fn run_length(rays_per_degree: f64, params: &NormalParams) -> usize {
    LineRuns::of(rays_per_degree, params).length
}

/// How a scan's local lines were fitted: through the means of runs of `length` rays (1: through
/// every ray), made longer than its density asks for by its range noise when `for_noise`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LineRuns {
    pub length: usize,
    pub for_noise: bool,
}

impl LineRuns {
    /// The runs for a scan of `rays_per_degree` under `params` ([`run_length`]).
    pub(crate) fn of(rays_per_degree: f64, params: &NormalParams) -> Self {
        let density = group_size(rays_per_degree, params.max_rays_per_degree);
        let noise = noise_group_size(params.range_sigma);
        LineRuns {
            length: density.max(noise),
            for_noise: noise > density,
        }
    }
}

/// `points` (one scan in ray order, seen from `sensor`) with each run of `k` consecutive points
/// averaged into one, and for each point the index of its run's mean: a run ends after `k`
/// points or at a step between points that lie on no one surface (the local lines' own gap
/// test, so a run never straddles a depth edge).
pub(crate) fn averaged(
    points: &[Point2<f64>],
    sensor: &Point2<f64>,
    k: usize,
    normals: &NormalParams,
) -> (Vec<Point2<f64>>, Vec<usize>) {
    let k = k.max(1);
    let mut means = Vec::with_capacity(points.len() / k + 1);
    let mut run_of = Vec::with_capacity(points.len());
    let (mut sum, mut count) = (Vector2::zeros(), 0usize);
    for (i, p) in points.iter().enumerate() {
        let breaks =
            count == k || (count > 0 && is_gap(points[i - 1] - sensor, p - sensor, normals));
        if breaks {
            means.push(Point2::from(sum / count as f64));
            (sum, count) = (Vector2::zeros(), 0);
        }
        sum += p.coords;
        count += 1;
        run_of.push(means.len());
    }
    if count > 0 {
        means.push(Point2::from(sum / count as f64));
    }
    (means, run_of)
}

/// The local lines of a scan whose rays are averaged in runs of `k` ([`averaged`]): fitted
/// through the runs' means, each point taking its run's line, anchored where the point
/// projects onto it. Every point is still matched: averaging serves only the fits, so a pair's
/// information is what it was (a scan of fewer, averaged points would leave a hall's length
/// to the odometry sooner).
pub(crate) fn lines_from_runs(
    points: &[Point2<f64>],
    sensor: &Point2<f64>,
    k: usize,
    normals: &NormalParams,
) -> Vec<Option<Line>> {
    let (means, run_of) = averaged(points, sensor, k, normals);
    let run_lines = lines_through(&means, sensor, normals);
    points
        .iter()
        .zip(&run_of)
        .map(|(p, &run)| {
            run_lines[run].map(|l| Line {
                normal: l.normal,
                anchor: p - l.normal * l.normal.dot(&(p - l.anchor)),
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fan of `n` rays over `fov_deg` at range `r` (a circle: every ray on one surface).
    fn fan(n: usize, fov_deg: f64, r: impl Fn(usize) -> f64) -> Vec<Point2<f64>> {
        (0..n)
            .map(|i| {
                let t = (-fov_deg / 2.0 + fov_deg * i as f64 / (n - 1) as f64).to_radians();
                Point2::new(r(i) * t.cos(), r(i) * t.sin())
            })
            .collect()
    }

    #[test]
    fn group_size_leaves_the_sick_family_alone_and_thins_the_dense() {
        // 181 over 180, 361 over 180 (0.5 degree, also as read back with rounding), 360 over
        // 180: untouched; 1081 over 270 (0.25 degree) in pairs; 1081 over 180 in threes.
        assert_eq!(group_size(1.0, 2.0), 1);
        assert_eq!(group_size(2.0, 2.0), 1);
        assert_eq!(group_size(2.000_000_1, 2.0), 1);
        assert_eq!(group_size(359.0 / 180.0, 2.0), 1);
        assert_eq!(group_size(4.0, 2.0), 2);
        assert_eq!(group_size(6.0, 2.0), 3);
        assert_eq!(group_size(2.85, 2.0), 2);
        // Off.
        assert_eq!(group_size(6.0, 0.0), 1);
        assert_eq!(group_size(6.0, f64::INFINITY), 1);
        assert_eq!(group_size(f64::NAN, 2.0), 1);
    }

    #[test]
    fn noise_group_size_brings_the_normals_back_to_the_windows_own() {
        // The window's own noise and anything up to 1.84 cm: untouched.
        assert_eq!(noise_group_size(WINDOW_SIGMA), 1);
        assert_eq!(noise_group_size(0.0), 1);
        assert_eq!(noise_group_size(0.018), 1);
        assert_eq!(noise_group_size(0.02), 2);
        assert_eq!(noise_group_size(0.05), 3);
        assert_eq!(noise_group_size(0.1), 5);
        assert_eq!(noise_group_size(f64::NAN), 1);
        assert_eq!(noise_group_size(f64::INFINITY), 1);
        // Brute force: k is the whole number whose normal sigma, (s / 1 cm) / k^1.5 of the
        // window's, lies nearest to it on the scale of k^1.5 (the rounding of its 2/3 power).
        for mm in 1..300 {
            let s = mm as f64 * 1e-3;
            let target = (s / WINDOW_SIGMA).powf(2.0 / 3.0);
            let best = (1..50usize)
                .min_by(|a, b| {
                    let da = (*a as f64 - target).abs();
                    let db = (*b as f64 - target).abs();
                    da.partial_cmp(&db).unwrap()
                })
                .unwrap();
            assert_eq!(noise_group_size(s), best, "{mm} mm");
        }
    }

    #[test]
    fn run_length_takes_the_longer_of_density_and_noise() {
        let at = |range_sigma: f64| NormalParams {
            range_sigma,
            ..NormalParams::default()
        };
        assert_eq!(run_length(1.0, &at(0.01)), 1);
        assert_eq!(run_length(6.0, &at(0.01)), 3);
        assert_eq!(run_length(1.0, &at(0.05)), 3);
        assert_eq!(run_length(4.0, &at(0.05)), 3);
        assert_eq!(run_length(6.0, &at(0.1)), 5);
    }

    #[test]
    fn averaging_takes_means_of_consecutive_runs() {
        // Twin: every output point is the mean of its run of k inputs, in order.
        let pts = fan(1081, 270.0, |i| 3.0 + 0.001 * (i % 7) as f64);
        let k = 3;
        let (out, run_of) = averaged(&pts, &Point2::origin(), k, &NormalParams::default());
        assert_eq!(out.len(), pts.len().div_ceil(k));
        assert!(run_of.iter().enumerate().all(|(i, &r)| r == i / k));
        for (j, q) in out.iter().enumerate() {
            let run = &pts[j * k..((j + 1) * k).min(pts.len())];
            let mean = run.iter().fold(Vector2::zeros(), |a, p| a + p.coords) / run.len() as f64;
            assert!((q.coords - mean).norm() < 1e-12, "point {j}");
        }
    }

    /// A wall 3 m ahead seen by 1081 rays over 180 degrees with 1 cm of range noise: the raw
    /// rays' lines are mostly refused as too thick and the rest are noisy (122 of 547 points,
    /// 14 degrees RMS); the lines of the runs' means cover the wall (547, 2.2 degrees).
    #[test]
    fn a_dense_noisy_wall_gets_lines_from_its_runs() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(5);
        let noise = Normal::new(0.0, 0.01).unwrap();
        // The wall x = 3 between bearings -45 and 45 degrees.
        let pts: Vec<Point2<f64>> = fan(1081, 180.0, |_| 1.0)
            .into_iter()
            .filter(|d| d.x > 0.7)
            .map(|d| {
                let r = 3.0 / d.x + noise.sample(&mut rng);
                Point2::from(d.coords * r)
            })
            .collect();
        let params = NormalParams::default();
        let dense = crate::matching::estimate_lines(&pts, &Point2::origin(), &params);
        let raw = lines_through(&pts, &Point2::origin(), &params);
        // Angle of each line's normal from the wall's (-1, 0), degrees.
        let errors = |lines: &[Option<Line>]| -> Vec<f64> {
            lines
                .iter()
                .flatten()
                .map(|l| (-l.normal.x).clamp(-1.0, 1.0).acos().to_degrees())
                .collect()
        };
        let (d, r) = (errors(&dense), errors(&raw));
        let rms = |e: &[f64]| (e.iter().map(|x| x * x).sum::<f64>() / e.len() as f64).sqrt();
        assert!(
            d.len() as f64 > 0.95 * pts.len() as f64,
            "{} of {}",
            d.len(),
            pts.len()
        );
        assert!(
            (r.len() as f64) < 0.8 * pts.len() as f64,
            "{} of {}",
            r.len(),
            pts.len()
        );
        assert!(
            rms(&d) < 3.0 && rms(&d) < 0.5 * rms(&r),
            "{} vs {}",
            rms(&d),
            rms(&r)
        );
        // Each point keeps its own place along the wall: its anchor lies on its run's line,
        // within the noise of where it is.
        for (p, l) in pts.iter().zip(&dense) {
            let l = l.unwrap();
            assert!((l.anchor - p).norm() < 0.05);
        }
    }

    #[test]
    fn a_group_never_straddles_a_depth_edge() {
        // Rays 0-9 at 2 m, 10-19 at 5 m: with k = 4 the runs are 4, 4, 2 | 4, 4, 2.
        let pts = fan(20, 5.0, |i| if i < 10 { 2.0 } else { 5.0 });
        let (out, _) = averaged(&pts, &Point2::origin(), 4, &NormalParams::default());
        assert_eq!(out.len(), 6);
        let ranges: Vec<f64> = out.iter().map(|p| p.coords.norm()).collect();
        for r in &ranges[..3] {
            assert!((r - 2.0).abs() < 1e-3, "{ranges:?}");
        }
        for r in &ranges[3..] {
            assert!((r - 5.0).abs() < 1e-3, "{ranges:?}");
        }
    }
}
