//! Benchmarks (divan): building the viewer's scene and page for a run of 300 poses of
//! 5 x 181 rays (about 270,000 points, decimated to the default 250,000 cap), and the
//! occupancy grid of 300 level scans (5 cm cells). Run with `cargo bench --bench viz`.

use levelscan::formats::parse_plan;
use levelscan::occupancy::{GridParams, PlacedScan, build_grid};
use levelscan::simulate::{
    RandomPoseParams, ScannerParams, World, elevations_centred, random_poses, simulate_poses,
};
use levelscan::viz::html::viewer_page;
use levelscan::viz::scene::{Source, ViewParams, build_scene};

fn main() {
    divan::main();
}

const OFFICE: &str = include_str!("../examples/plans/office.wall");

fn run() -> (levelscan::plan::Plan, Vec<Source>) {
    let plan = parse_plan(OFFICE, "office.wall").expect("the built-in plan parses");
    let world = World::from_plan(&plan);
    let poses = random_poses(&world, 300, &RandomPoseParams::default(), 1).expect("free space");
    let scans = simulate_poses(
        &world,
        &poses,
        None,
        0,
        &elevations_centred(5, 5f64.to_radians()),
        &ScannerParams::default(),
        None,
        1,
    );
    let source = Source {
        name: "run".into(),
        scans: scans.into_iter().flatten().collect(),
    };
    (plan, vec![source])
}

#[divan::bench(sample_count = 10)]
fn scene_300_poses(bencher: divan::Bencher) {
    let (plan, sources) = run();
    bencher.bench(|| build_scene(Some(&plan), &sources, &ViewParams::default()));
}

#[divan::bench(sample_count = 10)]
fn page_300_poses(bencher: divan::Bencher) {
    let (plan, sources) = run();
    let scene = build_scene(Some(&plan), &sources, &ViewParams::default());
    bencher.bench(|| viewer_page(&scene).len());
}

#[divan::bench(sample_count = 10)]
fn occupancy_grid_300_scans(bencher: divan::Bencher) {
    let plan = parse_plan(OFFICE, "office.wall").expect("the built-in plan parses");
    let world = World::from_plan(&plan);
    let poses = random_poses(&world, 300, &RandomPoseParams::default(), 1).expect("free space");
    let scans: Vec<PlacedScan> = simulate_poses(
        &world,
        &poses,
        None,
        0,
        &[0.0],
        &ScannerParams::default(),
        None,
        1,
    )
    .into_iter()
    .flatten()
    .map(|s| PlacedScan {
        pose: s.true_pose.expect("simulated").to_pose2(),
        hits: s.points_2d(),
    })
    .collect();
    bencher.bench(|| build_grid(&scans, &GridParams::default()).map(|g| g.width));
}
