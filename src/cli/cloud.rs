//! `levelscan cloud [SCANS] --sequence N -o pose.ply`: one pose's raw scans as a PLY point
//! cloud in the robot frame (x forward, y left, z up; each ray at its hinge elevation and
//! offset), for PCL, CloudCompare, MeshLab or Open3D.

use super::{open_input, open_output};
use anyhow::{Context, bail};
use levelscan::formats::carmen::CarmenParams;
use levelscan::formats::ply::{pose_cloud, write_ply};
use levelscan::formats::read_any;
use levelscan::scan::Scan;
use std::path::{Path, PathBuf};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Raw scans (simulate output, or a robot's scans as JSON Lines); none or `-` reads
    /// standard input.
    pub input: Option<PathBuf>,
    /// The pose to write (its `sequence`); may be left out when the file holds one pose.
    #[arg(long)]
    pub sequence: Option<u64>,
    /// Output file; standard output when absent or `-`: the PLY cloud. (Binary PLY on a
    /// terminal is refused: give `-o cloud.ply`, --ascii, or redirect it.)
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// ASCII PLY instead of binary little-endian.
    #[arg(long)]
    pub ascii: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    if !args.ascii {
        super::view::refuse_terminal(args.output.as_deref(), "a binary PLY cloud", "cloud.ply")?;
    }
    let (name, sequence, scans) = read_pose(args.input.as_deref(), args.sequence)?;
    let points = pose_cloud(&scans);
    let elevations: Vec<String> = scans
        .iter()
        .map(|s| format!("{:.2}", s.elevation.unwrap_or(0.0).to_degrees()))
        .collect();
    let comments = [
        format!("levelscan cloud of {name}, sequence {sequence}"),
        "frame robot (REP-103: x forward, y left, z up), metres".to_string(),
        format!(
            "scans {} at hinge elevations {} deg",
            scans.len(),
            elevations.join(" ")
        ),
    ];
    let mut out = open_output(args.output.as_deref(), &[args.input.as_deref()])?;
    let shown = match args.output.as_deref().filter(|p| p.as_os_str() != "-") {
        Some(p) => p.display().to_string(),
        None => super::output::STDOUT.to_string(),
    };
    write_ply(&mut out, &points, &comments, args.ascii)
        .with_context(|| format!("{shown}: cannot write"))?;
    out.finish()?;
    eprintln!(
        "levelscan cloud: sequence {sequence}: {} points from {} scans; wrote {shown}",
        points.len(),
        scans.len(),
    );
    Ok(())
}

/// The scans of the pose asked for (or of the file's only pose): `(file name, sequence, scans)`.
fn read_pose(path: Option<&Path>, wanted: Option<u64>) -> anyhow::Result<(String, u64, Vec<Scan>)> {
    let input = open_input(path)?;
    let name = input.name.clone();
    let mut scans = Vec::new();
    let mut seen: Vec<u64> = Vec::new();
    for item in read_any(input.reader, name.clone(), CarmenParams::default())? {
        let (line, scan) = item?;
        if scan.extra.contains_key("level") {
            bail!(
                "{name}:{line}: level output (a 2D pseudo-level scan); cloud takes the raw \
                 scans of a pose"
            );
        }
        let Some(seq) = scan.sequence else {
            bail!("{name}:{line}: no sequence: cloud needs the scans grouped into poses");
        };
        if seen.last() != Some(&seq) {
            seen.push(seq);
        }
        if wanted.unwrap_or(seq) == seq && (wanted.is_some() || seen.len() == 1) {
            scans.push(scan);
        }
    }
    let sequence = match (wanted, seen.as_slice()) {
        (Some(s), _) if !scans.is_empty() => s,
        (Some(s), _) => bail!("{name}: no pose with sequence {s}"),
        (None, []) => bail!("{name}: no scans in it"),
        (None, [only]) => *only,
        (None, many) => bail!(
            "{name}: {} poses in it (sequence {} to {}); choose one with --sequence",
            many.len(),
            many[0],
            many[many.len() - 1]
        ),
    };
    Ok((name, sequence, scans))
}
