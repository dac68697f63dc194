//! Benchmarks (divan): leveling one pose of 5 x 181 rays. Run with `cargo bench --bench level`.

use levelscan::geometry::Pose;
use levelscan::level::{Estimator, LevelParams, level_pose};
use levelscan::plan::Plan;
use levelscan::pseudo_level::{PseudoLevelParams, pseudo_level_scan};
use levelscan::scan::Scan;
use levelscan::simulate::{ScannerParams, World, elevations_centred, simulate_pose};
use nalgebra::Point2;
use rand::SeedableRng;

fn main() {
    divan::main();
}

fn pose_scans(noise: f64) -> Vec<Scan> {
    let p = |x: f64, y: f64| Point2::new(x, y);
    let world = World::from_plan(&Plan {
        wall_height: 3.0,
        walls: vec![
            vec![
                p(0.0, 0.0),
                p(10.0, 0.0),
                p(10.0, 7.0),
                p(4.0, 8.0),
                p(0.0, 7.0),
                p(0.0, 0.0),
            ],
            vec![
                p(6.0, 3.0),
                p(6.5, 3.0),
                p(6.5, 3.5),
                p(6.0, 3.5),
                p(6.0, 3.0),
            ],
        ],
        ceiling: false,
        poses: vec![],
    });
    let pose = Pose::new(3.0, 3.0, 0.45, 0.3, 0.12, -0.15);
    let scanner = ScannerParams {
        noise_sigma: noise,
        ..ScannerParams::default()
    };
    let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(1);
    simulate_pose(
        &world,
        0,
        &pose,
        &elevations_centred(5, 5f64.to_radians()),
        &scanner,
        &mut rng,
    )
}

/// Levels the bench pose's scans at `noise` with `params`.
fn bench_level(bencher: divan::Bencher, noise: f64, params: LevelParams) {
    let scans = pose_scans(noise);
    bencher.bench(|| level_pose(divan::black_box(&scans), &params));
}

#[divan::bench(args = [0.01, 0.10])]
fn level_one_pose_robust(bencher: divan::Bencher, noise: f64) {
    bench_level(bencher, noise, LevelParams::default());
}

/// The robust estimator without re-segmentation in the level frame: the cost of `refine`.
#[divan::bench(args = [0.01, 0.10])]
fn level_one_pose_robust_without_refine(bencher: divan::Bencher, noise: f64) {
    bench_level(
        bencher,
        noise,
        LevelParams {
            refine_passes: 0,
            ..LevelParams::default()
        },
    );
}

/// The robust estimator without floor and ceiling lines: the cost of `level_lines`.
#[divan::bench(args = [0.01, 0.10])]
fn level_one_pose_robust_without_floor_lines(bencher: divan::Bencher, noise: f64) {
    bench_level(
        bencher,
        noise,
        LevelParams {
            level_lines: false,
            ..LevelParams::default()
        },
    );
}

/// The robust estimator without its maximum-likelihood last stage: the cost of that stage
/// (which runs at 1 cm, not at 10 cm, whose range noise is above `ml.max_range_sigma`).
#[divan::bench(args = [0.01, 0.10])]
fn level_one_pose_robust_without_ml(bencher: divan::Bencher, noise: f64) {
    let mut params = LevelParams::default();
    params.ml.enabled = false;
    bench_level(bencher, noise, params);
}

#[divan::bench(args = [0.01, 0.10])]
fn level_one_pose_paper(bencher: divan::Bencher, noise: f64) {
    bench_level(
        bencher,
        noise,
        LevelParams {
            estimator: Estimator::Paper,
            ..LevelParams::default()
        },
    );
}

#[divan::bench]
fn level_and_pseudo_level_one_pose(bencher: divan::Bencher) {
    let scans = pose_scans(0.01);
    let params = LevelParams::default();
    let pseudo = PseudoLevelParams::default();
    bencher.bench(|| {
        let est = level_pose(divan::black_box(&scans), &params);
        pseudo_level_scan(&scans, &est, &pseudo)
    });
}
