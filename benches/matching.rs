//! Benchmarks (divan): run with `cargo bench --bench matching`.
//!
//! - `plicp_match`: one point-to-line ICP of a 181-ray scan against the previous one (the
//!   reference already built), from the odometry guess; `pairwise_step` adds building the
//!   reference (line fits and kd-tree), i.e. the whole per-scan cost of pairwise matching.
//! - `metascan_first_100` / `metascan_last_100`: the cost of 100 metascan steps at the start of
//!   a 5000-scan run and at its end (the map built from the 4900 before, outside the timing).
//!   The run goes 14 times around the two-room plan's closed loop, resampled to 350 poses per
//!   lap (4900 = 14 x 350), so the last 100 scans are taken where the first 100 were: any
//!   difference in cost comes from the length of the run, not from the place.

use levelscan::formats::read_plan;
use levelscan::geometry::{Pose, Pose2};
use levelscan::matching::{
    IcpParams, Matcher, MatcherParams, Mode, NormalParams, RangeParams, ScanReference, icp,
    odometry_step, scan_points,
};
use levelscan::simulate::{OdometryParams, ScannerParams, World, odometry, simulate_poses};
use nalgebra::Point2;
use std::path::Path;
use std::sync::LazyLock;

fn main() {
    divan::main();
}

type Run = Vec<(Vec<Point2<f64>>, Option<Pose2>)>;

/// Poses per lap of the benchmark's loop.
const LAP: usize = 350;

/// `n` level scans around the two-room loop (`LAP` poses per lap, interpolated between the
/// plan's poses), with drifting odometry.
fn simulated_run(n: usize) -> Run {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/plans/two_rooms.wall");
    let plan = read_plan(&path).expect("the example plan is valid");
    let world = World::from_plan(&plan);
    let m = plan.poses.len();
    let poses: Vec<Pose> = (0..n)
        .map(|i| {
            let s = (i % LAP) as f64 * m as f64 / LAP as f64;
            let (k, f) = (s.floor() as usize, s.fract());
            let (a, b) = (plan.poses[k % m], plan.poses[(k + 1) % m]);
            let yaw = a.rz + f * levelscan::geometry::wrap_angle(b.rz - a.rz);
            Pose::new(
                a.x + f * (b.x - a.x),
                a.y + f * (b.y - a.y),
                a.z,
                yaw,
                0.0,
                0.0,
            )
        })
        .collect();
    let odo = odometry(&poses, &OdometryParams::default(), 7);
    simulate_poses(
        &world,
        &poses,
        Some(&odo),
        0,
        &[0.0],
        &ScannerParams::default(),
        None,
        7,
    )
    .into_iter()
    .flatten()
    .map(|s| {
        (
            scan_points(&s, &RangeParams::default()),
            s.odometry.map(|o| o.to_pose2()),
        )
    })
    .collect()
}

static SHORT: LazyLock<Run> = LazyLock::new(|| simulated_run(40));
static LONG: LazyLock<Run> = LazyLock::new(|| simulated_run(5000));

#[divan::bench]
fn plicp_match(bencher: divan::Bencher) {
    let (a, b) = (&SHORT[10], &SHORT[11]);
    let reference = ScanReference::new(a.0.clone(), &Point2::origin(), &NormalParams::default());
    let guess = odometry_step(a.1, b.1);
    let params = IcpParams::default();
    bencher.bench(|| icp(divan::black_box(&b.0), &reference, guess, &params));
}

#[divan::bench]
fn pairwise_step(bencher: divan::Bencher) {
    let (a, b) = (&SHORT[10], &SHORT[11]);
    let guess = odometry_step(a.1, b.1);
    let params = IcpParams::default();
    bencher.bench(|| {
        let reference =
            ScanReference::new(a.0.clone(), &Point2::origin(), &NormalParams::default());
        icp(divan::black_box(&b.0), &reference, guess, &params)
    });
}

fn metascan_params() -> MatcherParams {
    MatcherParams {
        mode: Mode::Metascan,
        ..MatcherParams::default()
    }
}

#[divan::bench(sample_count = 5, sample_size = 1)]
fn metascan_first_100(bencher: divan::Bencher) {
    let run = &*LONG;
    bencher
        .with_inputs(|| Matcher::new(metascan_params()))
        .bench_local_refs(|m| {
            for (points, odo) in &run[..100] {
                divan::black_box(m.push(points, *odo));
            }
        });
}

#[divan::bench(sample_count = 5, sample_size = 1)]
fn metascan_last_100(bencher: divan::Bencher) {
    let run = &*LONG;
    bencher
        .with_inputs(|| {
            let mut m = Matcher::new(metascan_params());
            for (points, odo) in &run[..run.len() - 100] {
                m.push(points, *odo);
            }
            m
        })
        .bench_local_refs(|m| {
            for (points, odo) in &run[run.len() - 100..] {
                divan::black_box(m.push(points, *odo));
            }
        });
}
