//! `levelscan map [SCANS] -o map.yaml`: an occupancy grid for ROS `map_server` (PGM + YAML) from
//! matched 2D scans (`match` output), each placed at its `estimate` (or `--pose`).

use super::open_input;
use super::scan_input::refuse_raw_scan;
use anyhow::{Context, bail};
use levelscan::formats::carmen::CarmenParams;
use levelscan::formats::pgm_map::{Classes, pgm_bytes, yaml_text};
use levelscan::formats::read_any;
use levelscan::geometry::Pose;
use levelscan::occupancy::{GridParams, OccupancyGrid, PlacedScan, build_grid};
use levelscan::scan::Scan;
use std::path::{Path, PathBuf};

/// Which of a record's poses places its scan.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum PoseField {
    /// What `match` concluded.
    Estimate,
    /// The simulator's truth (or a log's reference).
    #[value(name = "true_pose")]
    TruePose,
    /// Dead reckoning.
    Odometry,
}

impl PoseField {
    fn name(self) -> &'static str {
        match self {
            PoseField::Estimate => "estimate",
            PoseField::TruePose => "true_pose",
            PoseField::Odometry => "odometry",
        }
    }

    fn of(self, scan: &Scan) -> Option<Pose> {
        match self {
            PoseField::Estimate => scan.estimate,
            PoseField::TruePose => scan.true_pose,
            PoseField::Odometry => scan.odometry,
        }
    }
}

#[derive(clap::Args, Debug)]
pub struct Args {
    /// 2D scans with poses: `match` output (leveled or not), or a CSM or CARMEN log; none or
    /// `-` reads standard input.
    pub input: Option<PathBuf>,
    /// Output file: the map's YAML; the PGM image is written beside it under the same name
    /// (map.pgm). Two files, so never standard output.
    #[arg(short, long, default_value = "map.yaml")]
    pub output: PathBuf,
    /// Cell size (m).
    #[arg(long, default_value_t = GridParams::default().resolution)]
    pub resolution: f64,
    /// The pose that places each scan.
    #[arg(long, value_enum, default_value_t = PoseField::Estimate)]
    pub pose: PoseField,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    if args.output.as_os_str() == "-" {
        bail!("-o -: a map is two files (YAML and PGM), not standard output: give -o map.yaml");
    }
    if args.output.extension().is_some_and(|e| e == "pgm") {
        bail!(
            "{}: -o names the YAML file (the PGM is written beside it)",
            args.output.display()
        );
    }
    let scans = read_placed(args.input.as_deref(), args.pose)?;
    let params = GridParams {
        resolution: args.resolution,
        ..GridParams::default()
    };
    let grid = build_grid(&scans, &params).context("levelscan map")?;
    let image = args.output.with_extension("pgm");
    let image_name = image
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "map.pgm".into());
    let classes = Classes::default();
    write(&image, &pgm_bytes(&grid, &classes))?;
    write(&args.output, yaml_text(&image_name, &grid).as_bytes())?;
    eprintln!(
        "levelscan map: {} scans, {}; wrote {} and {}",
        scans.len(),
        describe(&grid, &classes),
        args.output.display(),
        image.display()
    );
    Ok(())
}

/// Every record as a placed scan; raw multi-elevation scans and records without the pose are
/// input errors naming the line.
fn read_placed(path: Option<&Path>, pose: PoseField) -> anyhow::Result<Vec<PlacedScan>> {
    let input = open_input(path)?;
    let name = input.name.clone();
    let mut out = Vec::new();
    for item in read_any(input.reader, name.clone(), CarmenParams::default())? {
        let (line, scan) = item?;
        refuse_raw_scan(
            &name,
            line,
            &scan,
            "map",
            "level then match them first: levelscan level | levelscan match",
        )?;
        let Some(p) = pose.of(&scan) else {
            bail!(
                "{name}:{line}: no {} to place the scan at (run levelscan match first, or \
                 choose another --pose)",
                pose.name()
            );
        };
        out.push(PlacedScan {
            pose: p.to_pose2(),
            hits: scan.points_2d(),
        });
    }
    if out.is_empty() {
        bail!("{name}: no scans in it");
    }
    Ok(out)
}

fn describe(grid: &OccupancyGrid, classes: &Classes) -> String {
    let n = (grid.width * grid.height).max(1) as f64;
    let (mut occupied, mut free) = (0usize, 0usize);
    for r in 0..grid.height {
        for c in 0..grid.width {
            let p = grid.probability(c, r);
            occupied += usize::from(p > classes.occupied);
            free += usize::from(p < classes.free);
        }
    }
    format!(
        "{} x {} cells of {} m ({:.1} x {:.1} m), {:.1}% occupied, {:.1}% free",
        grid.width,
        grid.height,
        grid.resolution,
        grid.width as f64 * grid.resolution,
        grid.height as f64 * grid.resolution,
        100.0 * occupied as f64 / n,
        100.0 * free as f64 / n
    )
}

fn write(path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    std::fs::write(path, bytes).with_context(|| format!("{}: cannot write", path.display()))
}
