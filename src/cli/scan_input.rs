//! Opening a scan input as every scan-reading command does: a ROS bag by its content (with
//! the topic flags of CONTRACT.md, "ROS bags"), else JSON Lines or a CARMEN log.

use super::open_input;
use levelscan::formats::bag::{Bag, BagOptions, BagScans, Survey};
use levelscan::formats::{CarmenParams, ScanSource, read_any};
use levelscan::scan::Scan;
use std::io::BufRead;
use std::path::Path;

/// Which topics of a ROS bag to read (ignored for other inputs).
#[derive(clap::Args, Debug, Clone, Default)]
pub struct BagArgs {
    /// Bag input: the LaserScan topic (default: the bag's only one).
    #[arg(long, value_name = "TOPIC")]
    pub scan_topic: Option<String>,
    /// Bag input: the sensor_msgs/JointState topic with the hinge joint.
    #[arg(long, value_name = "TOPIC", default_value = "/joint_states")]
    pub joint_topic: String,
    /// Bag input: the hinge's joint name (default: the only joint on the joint topic).
    #[arg(long, value_name = "NAME")]
    pub hinge_joint: Option<String>,
    /// Bag input: the nav_msgs/Odometry topic (default: the only one, if any).
    #[arg(long, value_name = "TOPIC")]
    pub odom_topic: Option<String>,
    /// Bag input: the geometry_msgs/PoseStamped ground truth (default: /ground_truth).
    #[arg(long, value_name = "TOPIC")]
    pub truth_topic: Option<String>,
}

impl BagArgs {
    /// The reader's options; `need_elevation` for `level`, `preferred` the scan topic taken
    /// when present and none is named (`/scan_level` for `match`).
    pub fn options(&self, need_elevation: bool, preferred: Option<&str>) -> BagOptions {
        BagOptions {
            scan_topic: self.scan_topic.clone(),
            preferred_scan_topic: preferred.map(str::to_string),
            joint_topic: self.joint_topic.clone(),
            hinge_joint: self.hinge_joint.clone(),
            odom_topic: self.odom_topic.clone(),
            truth_topic: self.truth_topic.clone(),
            need_elevation,
        }
    }
}

/// An opened scan input.
pub struct ScanInput {
    pub name: String,
    pub source: ScanSource<Box<dyn BufRead + Send>>,
    /// A bag's first pass (topics, signals); `None` for text inputs.
    pub survey: Option<Survey>,
    /// The bag itself, to copy through into a bag output.
    pub bag: Option<Bag>,
}

/// Opens `path` as a bag when it is one (by content); `None` for anything else (text, or
/// standard input for `None` or `-`).
pub fn open_bag(path: Option<&Path>, bag: &BagOptions) -> anyhow::Result<Option<ScanInput>> {
    let Some(p) = path.filter(|p| *p != Path::new("-")) else {
        return Ok(None);
    };
    let Some(found) = Bag::detect(p)? else {
        return Ok(None);
    };
    let kind = found.kind;
    let name = found.name.clone();
    let (scans, survey) = BagScans::open(found.clone(), bag)?;
    Ok(Some(ScanInput {
        name,
        source: ScanSource::Bag(Box::new(scans), kind),
        survey: Some(survey),
        bag: Some(found),
    }))
}

/// Opens `path` (standard input for `None` or `-`) as scans: a bag by its content, else text.
pub fn open_scans(
    path: Option<&Path>,
    carmen: CarmenParams,
    bag: &BagOptions,
) -> anyhow::Result<ScanInput> {
    if let Some(bag) = open_bag(path, bag)? {
        return Ok(bag);
    }
    let input = open_input(path)?;
    let source = read_any(input.reader, &input.name, carmen)?;
    Ok(ScanInput {
        name: input.name,
        source,
        survey: None,
        bag: None,
    })
}

/// Refuses a raw scan of a tilting scanner (a hinge elevation other than 0, and no `level`
/// object) where 2D scans are wanted: matched or mapped as they are, scans of one pose at
/// several elevations see the walls at different ranges and give a wrong path without a word.
/// Level output (pseudo-level scans keep their base scan's elevation), CSM and CARMEN logs (no
/// elevation) and scans taken level (elevation 0) pass. `command` names the command in the
/// message, `next` what to run first.
pub fn refuse_raw_scan(
    name: &str,
    line: usize,
    scan: &Scan,
    command: &str,
    next: &str,
) -> anyhow::Result<()> {
    if let Some(e) = scan.elevation.filter(|&e| e != 0.0)
        && !scan.extra.contains_key("level")
    {
        anyhow::bail!(
            "{name}:{line}: a raw scan at hinge elevation {:.1} deg; {command} takes 2D scans \
             ({next})",
            e.to_degrees()
        );
    }
    Ok(())
}
