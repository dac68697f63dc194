//! A tiny 2D ray caster for matcher tests: a level scanner in a room of segments.
#![allow(dead_code)]

use levelscan::geometry::Pose2;
use nalgebra::Point2;
use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, Normal};

pub type Segment = (Point2<f64>, Point2<f64>);

/// A 6 m x 4 m room with a partition and a square pillar: enough structure to pin every
/// direction.
pub fn office() -> Vec<Segment> {
    let p = Point2::new;
    let mut s = vec![
        (p(0.0, 0.0), p(6.0, 0.0)),
        (p(6.0, 0.0), p(6.0, 4.0)),
        (p(6.0, 4.0), p(0.0, 4.0)),
        (p(0.0, 4.0), p(0.0, 0.0)),
        (p(3.0, 4.0), p(3.0, 3.5)),
    ];
    let (cx, cy, h) = (3.0, 2.0, 0.25);
    s.push((p(cx - h, cy - h), p(cx + h, cy - h)));
    s.push((p(cx + h, cy - h), p(cx + h, cy + h)));
    s.push((p(cx + h, cy + h), p(cx - h, cy + h)));
    s.push((p(cx - h, cy + h), p(cx - h, cy - h)));
    s
}

/// Two long parallel walls 2 m apart: the degenerate case.
pub fn corridor() -> Vec<Segment> {
    let p = Point2::new;
    vec![
        (p(-100.0, -1.0), p(100.0, -1.0)),
        (p(-100.0, 1.0), p(100.0, 1.0)),
    ]
}

/// Range along a ray from `o` in direction `(c, s)` to the nearest segment.
fn cast(o: Point2<f64>, c: f64, s: f64, walls: &[Segment], max_range: f64) -> Option<f64> {
    let mut best: Option<f64> = None;
    for (a, b) in walls {
        let e = b - a;
        let denom = c * e.y - s * e.x;
        if denom.abs() < 1e-12 {
            continue;
        }
        let w = a - o;
        let t = (w.x * e.y - w.y * e.x) / denom;
        let u = (w.x * s - w.y * c) / denom;
        if t > 1e-9 && (-1e-12..=1.0 + 1e-12).contains(&u) && t <= max_range {
            best = Some(best.map_or(t, |b: f64| b.min(t)));
        }
    }
    best
}

/// Robot-frame points of a scan of `nrays` over 180 degrees at `pose`, with Gaussian range
/// noise `sigma` (0 for none).
pub fn scan_at(
    pose: &Pose2,
    walls: &[Segment],
    nrays: usize,
    sigma: f64,
    seed: u64,
) -> Vec<Point2<f64>> {
    let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(seed);
    let noise = Normal::new(0.0, sigma.max(1e-300)).unwrap();
    let half = std::f64::consts::FRAC_PI_2;
    (0..nrays)
        .filter_map(|i| {
            let bearing = -half + std::f64::consts::PI * i as f64 / (nrays - 1) as f64;
            let (s, c) = (pose.theta + bearing).sin_cos();
            let r = cast(Point2::new(pose.x, pose.y), c, s, walls, 30.0)?;
            let r = if sigma > 0.0 {
                r + noise.sample(&mut rng)
            } else {
                r
            };
            let (bs, bc) = bearing.sin_cos();
            Some(Point2::new(r * bc, r * bs))
        })
        .collect()
}

/// A smooth loop of `n` poses through the office, heading along the path.
pub fn office_loop(n: usize) -> Vec<Pose2> {
    (0..n)
        .map(|i| {
            let a = std::f64::consts::TAU * i as f64 / n as f64;
            let (x, y) = (3.0 + 1.9 * a.cos(), 2.0 + 1.2 * a.sin());
            Pose2::new(x, y, (1.2 * a.cos()).atan2(-1.9 * a.sin()))
        })
        .collect()
}

/// Odometry that is off by independent Gaussian noise per step.
pub fn noisy_odometry(truth: &[Pose2], sigma_xy: f64, sigma_theta: f64, seed: u64) -> Vec<Pose2> {
    let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(seed);
    let nxy = Normal::new(0.0, sigma_xy).unwrap();
    let nth = Normal::new(0.0, sigma_theta).unwrap();
    let mut odo = vec![truth[0]];
    for w in truth.windows(2) {
        let step = w[0].between(&w[1]);
        let noisy = Pose2::new(
            step.x + nxy.sample(&mut rng),
            step.y + nxy.sample(&mut rng),
            step.theta + nth.sample(&mut rng),
        );
        let last = *odo.last().unwrap();
        odo.push(last.compose(&noisy));
    }
    let _ = rng.random::<f64>();
    odo
}

/// The ranges of a scan of `nrays` over 180 degrees (bearings as [`scan_at`]'s) taken while
/// the scanner moves: ray `i` is cast `i * sweep / (nrays - 1)` seconds after the stamp, from
/// `start` moved on by `motion` for that long. Noise-free.
pub fn swept_ranges(
    start: &Pose2,
    motion: &levelscan::matching::SweepMotion,
    sweep: f64,
    walls: &[Segment],
    nrays: usize,
) -> Vec<Option<f64>> {
    (0..nrays)
        .map(|i| {
            let t = sweep * i as f64 / (nrays - 1) as f64;
            let pose = start.compose(&motion.pose_after(t));
            let (s, c) = (pose.theta + bearing(i, nrays)).sin_cos();
            cast(Point2::new(pose.x, pose.y), c, s, walls, 30.0)
        })
        .collect()
}

/// The bearing of ray `i` of `nrays` over 180 degrees, from -90 \[rad\].
pub fn bearing(i: usize, nrays: usize) -> f64 {
    -std::f64::consts::FRAC_PI_2 + std::f64::consts::PI * i as f64 / (nrays - 1) as f64
}

/// A steady turn round the office's pillar, 1.3 m from its centre, in `lap` scans `period`
/// seconds apart, each swept over `sweep` seconds while the robot moves on towards the next
/// pose ([`swept_ranges`], `nrays` rays): the true poses and each scan's ranges.
pub fn steady_turn(
    lap: usize,
    period: f64,
    sweep: f64,
    nrays: usize,
) -> (Vec<Pose2>, Vec<Vec<Option<f64>>>) {
    let truth: Vec<Pose2> = (0..lap)
        .map(|k| {
            let a = std::f64::consts::TAU * k as f64 / lap as f64;
            let (s, c) = a.sin_cos();
            Pose2::new(
                3.0 + 1.3 * c,
                2.0 + 1.3 * s,
                a + std::f64::consts::FRAC_PI_2,
            )
        })
        .collect();
    let walls = office();
    let ranges = (0..lap)
        .map(|k| {
            let next = truth[(k + 1) % lap];
            let motion =
                levelscan::matching::SweepMotion::between(&truth[k], &next, period).unwrap();
            swept_ranges(&truth[k], &motion, sweep, &walls, nrays)
        })
        .collect();
    (truth, ranges)
}
