//! How close pairwise matching comes to the Cramér-Rao bound on a pair's motion
//! (`levelscan::eval::pair_bound`), by Monte Carlo in rooms of straight walls: the bound is
//! what no matcher can beat, so the matcher's root-mean-square error over many noisy pairs
//! must lie at or above it (within the Monte Carlo's own spread) and, for a matcher that uses
//! the walls' information well, not far above it.

use levelscan::eval::bound::WallPlanes;
use levelscan::eval::pair_bound::{PairRay, pair_bound, scan_rays};
use levelscan::geometry::Pose2;
use levelscan::matching::{Matcher, MatcherParams, Mode};
use levelscan::plan::Segment;
use levelscan::simulate::World;
use nalgebra::Point2;
use rand::SeedableRng;
use rand::rngs::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

const SIGMA: f64 = 0.01;
const TRIALS: usize = 300;

fn polygon(corners: &[(f64, f64)]) -> Vec<Segment> {
    corners
        .iter()
        .zip(corners.iter().cycle().skip(1))
        .map(|(a, b)| Segment {
            a: Point2::new(a.0, a.1),
            b: Point2::new(b.0, b.1),
        })
        .collect()
}

fn bearings() -> impl Iterator<Item = f64> {
    (0..181).map(|i| -std::f64::consts::FRAC_PI_2 + i as f64 * std::f64::consts::PI / 180.0)
}

/// The root-mean-square translation [m] and heading [rad] errors of pairwise matching over
/// noisy pairs of scans from `a` and `b`, and the bound's.
fn matched_and_bound(segments: &[Segment], a: Pose2, b: Pose2) -> ([f64; 2], [f64; 2]) {
    let world = World::from_segments(segments.to_vec(), 3.0, false);
    let planes = WallPlanes::new(segments);
    let rays_a = scan_rays(&world, &planes, &a, bearings(), 30.0);
    let rays_b = scan_rays(&world, &planes, &b, bearings(), 30.0);
    let bound = pair_bound(&planes, (&a, &rays_a), (&b, &rays_b), SIGMA).expect("observable");
    let truth = a.between(&b);
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let noise = Normal::new(0.0, SIGMA).unwrap();
    let mut noisy = |rays: &[PairRay]| -> Vec<Point2<f64>> {
        rays.iter()
            .map(|r| {
                let range = r.range + noise.sample(&mut rng);
                Point2::new(range * r.bearing.cos(), range * r.bearing.sin())
            })
            .collect()
    };
    let params = MatcherParams {
        mode: Mode::Pairwise,
        ..MatcherParams::default()
    };
    let (mut sum_t, mut sum_r) = (0.0, 0.0);
    for _ in 0..TRIALS {
        let (pa, pb) = (noisy(&rays_a), noisy(&rays_b));
        let mut matcher = Matcher::new(params);
        matcher.push(&pa, Some(a));
        let report = matcher.push(&pb, Some(b));
        let error = truth.between(&a.between(&report.estimate));
        sum_t += error.translation().norm_squared();
        sum_r += error.theta * error.theta;
    }
    let n = TRIALS as f64;
    (
        [(sum_t / n).sqrt(), (sum_r / n).sqrt()],
        [(bound[(0, 0)] + bound[(1, 1)]).sqrt(), bound[(2, 2)].sqrt()],
    )
}

fn assert_near_the_bound(name: &str, matched: [f64; 2], bound: [f64; 2], most: [f64; 2]) {
    let ratio = [matched[0] / bound[0], matched[1] / bound[1]];
    eprintln!(
        "{name}: matched {:.3} mm / {:.4} deg, bound {:.3} mm / {:.4} deg, ratio {:.3} / {:.3}",
        matched[0] * 1e3,
        matched[1].to_degrees(),
        bound[0] * 1e3,
        bound[1].to_degrees(),
        ratio[0],
        ratio[1]
    );
    // 300 trials estimate a root mean square to about 3-4%: at or above the bound within
    // that, and no more than `most` times it.
    for k in 0..2 {
        assert!(ratio[k] > 0.92, "{name}: below the bound? {ratio:?}");
        assert!(
            ratio[k] < most[k],
            "{name}: {ratio:?} against at most {most:?}"
        );
    }
}

#[test]
fn pairwise_matching_in_a_rectangular_room_is_within_a_tenth_or_so_of_the_bound() {
    let room = polygon(&[(0.0, 0.0), (6.0, 0.0), (6.0, 4.0), (0.0, 4.0)]);
    let (matched, bound) = matched_and_bound(
        &room,
        Pose2::new(2.0, 1.5, 0.1),
        Pose2::new(2.1, 1.52, 0.12),
    );
    assert_near_the_bound("rectangle", matched, bound, [1.15, 1.2]);
}

#[test]
fn pairwise_matching_among_a_pillars_corners_stays_near_the_bound() {
    // An L-shaped room with a pillar: corners where local line fits straddle two walls.
    let mut room = polygon(&[
        (0.0, 0.0),
        (7.0, 0.0),
        (7.0, 3.0),
        (4.0, 3.0),
        (4.0, 5.0),
        (0.0, 5.0),
    ]);
    room.extend(polygon(&[(4.0, 1.0), (4.4, 1.0), (4.4, 1.4), (4.0, 1.4)]));
    let (matched, bound) = matched_and_bound(
        &room,
        Pose2::new(1.5, 1.2, 0.3),
        Pose2::new(1.6, 1.15, 0.32),
    );
    assert_near_the_bound("L room with a pillar", matched, bound, [1.35, 1.35]);
}
