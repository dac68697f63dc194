//! Benchmarks (divan): run with `cargo bench --bench matching`.
//!
//! - `plicp_match`: one point-to-line ICP of a 181-ray scan against the previous one (the
//!   reference already built), from the odometry guess; `pairwise_step` adds building the
//!   reference (line fits and search grid), i.e. the whole per-scan cost of pairwise matching.
//! - `coarse_search`: the coarse correlative search of a scan against the previous one from a
//!   guess 20 cm and 5 degrees off, in buffers kept between calls (as the matcher keeps them).
//! - `run_40_pairwise` / `run_40_metascan`: a whole 40-scan run through the `Matcher`.
//! - `deskew_scan`: moving one scan's points to the mean time of its rays (`match --deskew`),
//!   against `pairwise_step` the share deskewing adds to a scan's matching.
//!
//! The per-scan benchmarks take the scanner's ray count as their argument (181 or 361 rays
//! over the same half turn).
//! - `metascan_first_100` / `metascan_last_100`: the cost of 100 metascan steps at the start of
//!   a 5000-scan run and at its end (the map built from the 4900 before, outside the timing).
//!   The run goes 14 times around the two-room plan's closed loop, resampled to 350 poses per
//!   lap (4900 = 14 x 350), so the last 100 scans are taken where the first 100 were: any
//!   difference in cost comes from the length of the run, not from the place.

use levelscan::formats::read_plan;
use levelscan::geometry::{Pose, Pose2};
use levelscan::matching::{
    CorrelativeParams, CorrelativeScratch, IcpParams, Matcher, MatcherParams, Mode, NormalParams,
    RangeParams, ScanReference, SweepMotion, correlative_search_with, deskew, icp, odometry_step,
    scan_points,
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

/// `n` level scans of `rays` rays around the two-room loop (`LAP` poses per lap, interpolated
/// between the plan's poses), with drifting odometry.
fn simulated_run(n: usize, rays: usize) -> Run {
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
        &ScannerParams {
            rays,
            ..ScannerParams::default()
        },
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

static SHORT: LazyLock<Run> = LazyLock::new(|| simulated_run(40, 181));
static SHORT_361: LazyLock<Run> = LazyLock::new(|| simulated_run(40, 361));
static LONG: LazyLock<Run> = LazyLock::new(|| simulated_run(5000, 181));

/// The 40-scan run with `rays` rays per scan.
fn short(rays: usize) -> &'static Run {
    match rays {
        181 => &SHORT,
        361 => &SHORT_361,
        _ => unreachable!("benchmarked at 181 and 361 rays"),
    }
}

#[divan::bench(args = [181, 361])]
fn plicp_match(bencher: divan::Bencher, rays: usize) {
    let run = short(rays);
    let (a, b) = (&run[10], &run[11]);
    let reference = ScanReference::new(a.0.clone(), &Point2::origin(), &NormalParams::default());
    let guess = odometry_step(a.1, b.1);
    let params = IcpParams::default();
    bencher.bench(|| icp(divan::black_box(&b.0), &reference, guess, &params));
}

#[divan::bench(args = [181, 361])]
fn pairwise_step(bencher: divan::Bencher, rays: usize) {
    let run = short(rays);
    let (a, b) = (&run[10], &run[11]);
    let guess = odometry_step(a.1, b.1);
    let params = IcpParams::default();
    bencher.bench(|| {
        let reference =
            ScanReference::new(a.0.clone(), &Point2::origin(), &NormalParams::default());
        icp(divan::black_box(&b.0), &reference, guess, &params)
    });
}

#[divan::bench(args = [181, 361])]
fn coarse_search(bencher: divan::Bencher, rays: usize) {
    let run = short(rays);
    let (a, b) = (&run[10], &run[11]);
    let step = odometry_step(a.1, b.1);
    let guess = step.compose(&Pose2::new(0.2, -0.2, 5f64.to_radians()));
    let params = CorrelativeParams::default();
    let mut scratch = CorrelativeScratch::default();
    bencher.bench_local(|| {
        correlative_search_with(
            &mut scratch,
            divan::black_box(&b.0),
            &a.0,
            &Point2::origin(),
            guess,
            &params,
        )
    });
}

#[divan::bench(args = [181, 361])]
fn deskew_scan(bencher: divan::Bencher, rays: usize) {
    let run = short(rays);
    let points = &run[11].0;
    // A 25 ms sweep, centred on the mean time, at 0.5 m/s and 30 degrees a second.
    let times: Vec<f64> = (0..points.len())
        .map(|i| 0.025 * (i as f64 / (points.len() - 1) as f64 - 0.5))
        .collect();
    let motion = SweepMotion {
        vx: 0.5,
        vy: 0.0,
        yaw_rate: 30f64.to_radians(),
    };
    bencher.bench(|| {
        let mut p = points.clone();
        deskew(divan::black_box(&mut p), &times, &motion);
        p
    });
}

/// A whole 40-scan run through the matcher in `mode`.
fn run_40(bencher: divan::Bencher, mode: Mode, rays: usize) {
    let run = short(rays);
    let params = MatcherParams {
        mode,
        ..MatcherParams::default()
    };
    bencher.bench_local(|| {
        let mut m = Matcher::new(params);
        for (points, odo) in run {
            divan::black_box(m.push(points, *odo));
        }
    });
}

#[divan::bench(args = [181, 361])]
fn run_40_pairwise(bencher: divan::Bencher, rays: usize) {
    run_40(bencher, Mode::Pairwise, rays);
}

#[divan::bench(args = [181, 361])]
fn run_40_metascan(bencher: divan::Bencher, rays: usize) {
    run_40(bencher, Mode::Metascan, rays);
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
