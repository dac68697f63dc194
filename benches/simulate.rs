//! Benchmarks (divan): run with `cargo bench --bench simulate`.
//!
//! Ray casting on plans of 100 and 10,000 random short wall segments in a 60 x 60 m box (the
//! spatial index should keep the cost per ray within about 2x), and a whole 5-scan pose.

use divan::{Bencher, black_box};
use levelscan::geometry::Pose;
use levelscan::plan::Segment;
use levelscan::simulate::{ScannerParams, World, elevations_centred, simulate_pose};
use nalgebra::{Point2, Point3, Vector3};
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};

fn main() {
    divan::main();
}

const SIDE: f64 = 60.0;
const RAYS: usize = 1000;

/// The four walls of the square `[0, side]^2`.
fn square(side: f64) -> Vec<Segment> {
    let c = [[0.0, 0.0], [side, 0.0], [side, side], [0.0, side]].map(|[x, y]| Point2::new(x, y));
    (0..4)
        .map(|i| Segment {
            a: c[i],
            b: c[(i + 1) % 4],
        })
        .collect()
}

/// Adds random pieces inside the square `[inset, side - inset]^2` until there are `n`
/// segments, each of the length `length` draws.
fn add_clutter(
    segments: &mut Vec<Segment>,
    n: usize,
    rng: &mut ChaCha8Rng,
    inset: f64,
    side: f64,
    length: impl Fn(&mut ChaCha8Rng) -> f64,
) {
    while segments.len() < n {
        let a = Point2::new(
            rng.random_range(inset..side - inset),
            rng.random_range(inset..side - inset),
        );
        let t = rng.random_range(0.0..std::f64::consts::TAU);
        let l = length(rng);
        segments.push(Segment {
            a,
            b: a + nalgebra::Vector2::new(t.cos(), t.sin()) * l,
        });
    }
}

/// The four walls of the box plus `n - 4` random segments 0.2-1.0 m long inside it.
fn box_with_clutter(n: usize) -> World {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let mut segments = square(SIDE);
    add_clutter(&mut segments, n, &mut rng, 1.0, SIDE, |r| {
        r.random_range(0.2..1.0)
    });
    World::from_segments(segments, 3.0, false)
}

/// `RAYS` rays from random points of the square `[lo, hi]^2` at scanner height, in random
/// directions within 20 degrees of level.
fn random_rays(seed: u64, lo: f64, hi: f64) -> Vec<(Point3<f64>, Vector3<f64>)> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..RAYS)
        .map(|_| {
            let o = Point3::new(rng.random_range(lo..hi), rng.random_range(lo..hi), 0.45);
            let az = rng.random_range(0.0..std::f64::consts::TAU);
            let el = rng.random_range(-0.35f64..0.35);
            (
                o,
                Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin()),
            )
        })
        .collect()
}

/// 1000 rays per iteration: divide the time by 1000 for the cost of one ray (divan's
/// throughput counter shows rays per second).
#[divan::bench(args = [100, 10_000])]
fn cast_rays(bencher: Bencher, segments: usize) {
    let world = box_with_clutter(segments);
    let rays = random_rays(2, 1.0, SIDE - 1.0);
    bencher
        .counter(divan::counter::ItemsCount::new(RAYS))
        .bench(|| {
            let mut hits = 0usize;
            for (o, d) in &rays {
                hits += usize::from(world.cast(black_box(o), black_box(d), 30.0).is_some());
            }
            hits
        });
}

/// The linear scan over all segments, for comparison with the index.
#[divan::bench(args = [100, 10_000])]
fn cast_rays_brute_force(bencher: Bencher, segments: usize) {
    let world = box_with_clutter(segments);
    let rays = random_rays(2, 1.0, SIDE - 1.0);
    bencher
        .counter(divan::counter::ItemsCount::new(RAYS))
        .bench(|| {
            let mut hits = 0usize;
            for (o, d) in &rays {
                hits += usize::from(
                    world
                        .cast_brute_force(black_box(o), black_box(d), 30.0)
                        .is_some(),
                );
            }
            hits
        });
}

const ROOM: f64 = 6.0;

/// `tiles` x `tiles` copies of one 6 x 6 m room of 100 segments (4 walls + 96 random short
/// pieces), side by side: the same local scene in a plan 1 or 100 times as large.
fn tiled_rooms(tiles: usize) -> World {
    let mut rng = ChaCha8Rng::seed_from_u64(4);
    let mut room = square(ROOM);
    add_clutter(&mut room, 100, &mut rng, 0.5, ROOM, |_| 0.3);
    let mut segments = Vec::new();
    for i in 0..tiles {
        for j in 0..tiles {
            let shift = nalgebra::Vector2::new(i as f64 * ROOM, j as f64 * ROOM);
            segments.extend(room.iter().map(|s| Segment {
                a: s.a + shift,
                b: s.b + shift,
            }));
        }
    }
    World::from_segments(segments, 3.0, false)
}

/// The same room alone (100 segments) and among 99 copies (10,000 segments): what the size of
/// the plan alone costs each ray.
#[divan::bench(args = [1, 10])]
fn cast_rays_tiled_rooms(bencher: Bencher, tiles: usize) {
    let world = tiled_rooms(tiles);
    // Rays from the middle room, which is the same in every plan size.
    let base = (tiles / 2) as f64 * ROOM;
    let rays = random_rays(5, base + 0.2, base + ROOM - 0.2);
    bencher
        .counter(divan::counter::ItemsCount::new(RAYS))
        .bench(|| {
            let mut hits = 0usize;
            for (o, d) in &rays {
                hits += usize::from(world.cast(black_box(o), black_box(d), 30.0).is_some());
            }
            hits
        });
}

/// One pose: 5 scans of 181 rays in a 10,000-segment plan, with noise.
#[divan::bench]
fn simulate_one_pose_5x181(bencher: Bencher) {
    let world = box_with_clutter(10_000);
    let pose = Pose::new(30.0, 30.0, 0.45, 0.3, 0.1, -0.15);
    let elevations = elevations_centred(5, 5f64.to_radians());
    let params = ScannerParams::default();
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    bencher
        .counter(divan::counter::ItemsCount::new(5usize * 181))
        .bench_local(|| simulate_pose(&world, 0, &pose, &elevations, &params, &mut rng));
}
