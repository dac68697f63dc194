//! `levelscan info [SCANS]`: parses every record and prints one JSON object that summarises
//! the file: poses, scans, rays, elevations, valid fraction, which optional fields are present.

use super::scan_input::BagArgs;
use super::{open_input, open_output};
use levelscan::formats::bag::{Bag, BagScans, Survey, survey};
use levelscan::formats::{CarmenParams, ScanSource, read_any};
use levelscan::scan::Scan;
use serde_json::{Value, json};
use std::collections::{BTreeMap, BTreeSet, HashSet};
use std::io::Write;
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scan file: JSON Lines or a CARMEN log, optionally gzipped; standard input when absent
    /// or `-`.
    pub scans: Option<PathBuf>,
    /// Scanner's maximum range (m): a reading at or beyond it is no return. For CARMEN
    /// `FLASER` lines, which do not record it (other formats mark no return themselves)
    /// [default: the log's `PARAM robot_front_laser_max`, else 50].
    #[arg(long)]
    pub max_range: Option<f64>,
    /// Output file; standard output when absent or `-`.
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    #[command(flatten)]
    pub bag: BagArgs,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let carmen = CarmenParams {
        max_range: args.max_range,
    };
    let mut report = serde_json::Map::new();
    let path = args
        .scans
        .as_deref()
        .filter(|p| *p != std::path::Path::new("-"));
    let source = match path.map(Bag::detect).transpose()?.flatten() {
        Some(bag) => {
            report.insert("file".into(), json!(bag.name));
            report.insert("format".into(), json!(bag.kind.name()));
            let kind = bag.kind;
            let surveyed = survey(&bag, &args.bag.options(false, None))?;
            report.extend(bag_report(&surveyed));
            // A bag whose scan topic cannot be chosen (several LaserScan topics, none, a
            // named one missing) fails as level and view do: a summary of no scans with exit 0
            // read as an empty bag. The message lists the LaserScan topics and --scan-topic.
            ScanSource::Bag(Box::new(BagScans::start(bag, surveyed)?), kind)
        }
        None => {
            let input = open_input(args.scans.as_deref())?;
            let source = read_any(input.reader, &input.name, carmen)?;
            report.insert("file".into(), json!(input.name));
            report.insert("format".into(), json!(source.format()));
            source
        }
    };
    let mut summary = Summary::default();
    for item in source {
        let (_, scan) = item?;
        summary.add(&scan);
    }
    if let Value::Object(m) = summary.into_json() {
        report.extend(m);
    }
    let mut out = open_output(args.output.as_deref(), &[args.scans.as_deref()])?;
    out.write_all((Value::Object(report).to_string() + "\n").as_bytes())?;
    out.finish()?;
    Ok(())
}

/// A bag's topics (name, type, count, first and last log time in seconds), its time span,
/// and which topic and joint the scans come from.
fn bag_report(s: &Survey) -> serde_json::Map<String, Value> {
    // Whole seconds and the fraction apart, so that 1000 s prints as 1000.0, not 1000.0000000000001.
    let secs = |ns: u64| (ns / 1_000_000_000) as f64 + (ns % 1_000_000_000) as f64 / 1e9;
    let topics: Vec<Value> = s
        .topics
        .iter()
        .map(|t| {
            json!({
                "topic": t.topic,
                "type": t.message_type,
                "count": t.count,
                "first": secs(t.first),
                "last": secs(t.last),
            })
        })
        .collect();
    let first = s.topics.iter().map(|t| t.first).min();
    let last = s.topics.iter().map(|t| t.last).max();
    let mut m = serde_json::Map::new();
    m.insert("topics".into(), Value::Array(topics));
    m.insert(
        "time_span".into(),
        match (first, last) {
            (Some(a), Some(b)) => json!([secs(a), secs(b)]),
            _ => Value::Null,
        },
    );
    m.insert("scan_topic".into(), json!(s.scan_topic));
    m.insert("hinge_joint".into(), json!(s.hinge.as_ref().map(|h| &h.0)));
    m.insert(
        "odometry_topic".into(),
        json!(s.odometry.as_ref().map(|o| &o.0)),
    );
    m.insert("truth_topic".into(), json!(s.truth.as_ref().map(|t| &t.0)));
    m
}

/// What `info` counts, one scan at a time (memory grows only with the number of distinct
/// elevations, sequences and field names, not with the rays).
#[derive(Default, Debug)]
struct Summary {
    scans: u64,
    poses: u64,
    /// The sequence of the previous scan: a new pose starts when it changes.
    last_sequence: Option<Option<u64>>,
    sequences_seen: HashSet<u64>,
    /// Poses whose `sequence` had already been used by an earlier pose (an input error for
    /// `level`, which groups consecutive scans).
    returning_sequences: u64,
    scans_in_pose: u64,
    scans_per_pose: Option<(u64, u64)>,
    /// Distinct elevations and ray counts of the pose being read.
    pose_elevations: BTreeSet<OrdF64>,
    pose_nrays: BTreeSet<usize>,
    elevations_per_pose: Option<(usize, usize)>,
    /// Poses that `level` cannot level: fewer than three distinct elevations (the paper's
    /// quads span three scans, sect. 5.2), or scans of different `nrays`.
    poses_with_too_few_elevations: u64,
    poses_with_mixed_nrays: u64,
    rays_total: u64,
    rays_per_scan: Option<(usize, usize)>,
    valid_rays: u64,
    range: Option<(f64, f64)>,
    /// Distinct elevations by their bits, so that equal values collapse exactly.
    elevations: BTreeSet<OrdF64>,
    without_elevation: u64,
    fields: BTreeMap<&'static str, u64>,
    extra_fields: BTreeSet<String>,
}

#[derive(Clone, Copy, Debug, PartialEq)]
struct OrdF64(f64);

impl Eq for OrdF64 {}

impl PartialOrd for OrdF64 {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for OrdF64 {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.0.total_cmp(&other.0)
    }
}

fn min_max<T: PartialOrd + Copy>(acc: Option<(T, T)>, v: T) -> Option<(T, T)> {
    Some(match acc {
        None => (v, v),
        Some((lo, hi)) => (if v < lo { v } else { lo }, if v > hi { v } else { hi }),
    })
}

impl Summary {
    fn add(&mut self, scan: &Scan) {
        self.scans += 1;
        // Scans without `sequence` are numbered in input order (contract), one pose each.
        let new_pose = scan.sequence.is_none() || self.last_sequence != Some(scan.sequence);
        if new_pose {
            self.close_pose();
            self.poses += 1;
            if scan
                .sequence
                .is_some_and(|seq| !self.sequences_seen.insert(seq))
            {
                self.returning_sequences += 1;
            }
        }
        self.scans_in_pose += 1;
        self.last_sequence = Some(scan.sequence);
        if let Some(e) = scan.elevation {
            self.pose_elevations.insert(OrdF64(e));
        }
        self.pose_nrays.insert(scan.nrays());

        let n = scan.nrays();
        self.rays_total += n as u64;
        self.rays_per_scan = min_max(self.rays_per_scan, n);
        for i in 0..n {
            if let Some(r) = scan.range(i) {
                self.valid_rays += 1;
                self.range = min_max(self.range, r);
            }
        }
        match scan.elevation {
            Some(e) => {
                self.elevations.insert(OrdF64(e));
            }
            None => self.without_elevation += 1,
        }
        let present = [
            ("odometry", scan.odometry.is_some()),
            ("estimate", scan.estimate.is_some()),
            ("true_pose", scan.true_pose.is_some()),
            ("timestamp", scan.timestamp.is_some()),
            ("readings_sigma", scan.readings_sigma.is_some()),
            ("hinge_offset", scan.hinge_offset.is_some()),
            ("hit", scan.hit.is_some()),
        ];
        for (name, here) in present {
            *self.fields.entry(name).or_default() += u64::from(here);
        }
        for k in scan.extra.keys() {
            if !self.extra_fields.contains(k) {
                self.extra_fields.insert(k.clone());
            }
        }
    }

    fn close_pose(&mut self) {
        if self.scans_in_pose > 0 {
            self.scans_per_pose = min_max(self.scans_per_pose, self.scans_in_pose);
            let distinct = self.pose_elevations.len();
            self.elevations_per_pose = min_max(self.elevations_per_pose, distinct);
            self.poses_with_too_few_elevations += u64::from(distinct < 3);
            self.poses_with_mixed_nrays += u64::from(self.pose_nrays.len() > 1);
        }
        self.scans_in_pose = 0;
        self.pose_elevations.clear();
        self.pose_nrays.clear();
    }

    fn into_json(mut self) -> Value {
        self.close_pose();
        let elevations: Vec<f64> = self.elevations.iter().map(|e| e.0).collect();
        let degrees: Vec<f64> = elevations.iter().map(|e| e.to_degrees()).collect();
        let pair = |p: Option<(u64, u64)>| p.map(|(lo, hi)| json!({"min": lo, "max": hi}));
        json!({
            "poses": self.poses,
            "scans": self.scans,
            "scans_per_pose": pair(self.scans_per_pose),
            "elevations_per_pose": self
                .elevations_per_pose
                .map(|(lo, hi)| json!({"min": lo, "max": hi})),
            "poses_with_too_few_elevations": self.poses_with_too_few_elevations,
            "poses_with_mixed_nrays": self.poses_with_mixed_nrays,
            "returning_sequences": self.returning_sequences,
            "rays": {
                "total": self.rays_total,
                "per_scan": self.rays_per_scan.map(|(lo, hi)| json!({"min": lo, "max": hi})),
            },
            "valid_rays": self.valid_rays,
            "valid_fraction": if self.rays_total > 0 {
                json!(self.valid_rays as f64 / self.rays_total as f64)
            } else {
                Value::Null
            },
            "range_m": self.range.map(|(lo, hi)| json!({"min": lo, "max": hi})),
            "elevations": {
                "distinct": elevations.len(),
                "rad": elevations,
                "deg": degrees,
                "scans_without": self.without_elevation,
            },
            "fields": self.fields,
            "extra_fields": self.extra_fields,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use levelscan::geometry::Pose;

    fn scan(seq: Option<u64>, elevation: Option<f64>, readings: &[Option<f64>]) -> Scan {
        let mut s = Scan::with_even_bearings(readings.len(), -1.0, 1.0);
        s.sequence = seq;
        s.elevation = elevation;
        s.readings = readings.to_vec();
        s.valid = readings.iter().map(Option::is_some).collect();
        s
    }

    #[test]
    fn summary_counts_poses_scans_rays_and_elevations() {
        let mut sum = Summary::default();
        let r = [Some(1.0), None, Some(3.0), Some(2.0)];
        for seq in 0..3 {
            for e in [-0.1, 0.0, 0.1] {
                sum.add(&scan(Some(seq), Some(e), &r));
            }
        }
        let mut last = scan(Some(1), Some(0.0), &[Some(0.5), None]); // 1 comes back
        last.true_pose = Some(Pose::planar(1.0, 2.0, 0.0));
        sum.add(&last);
        let j = sum.into_json();
        assert_eq!(j["poses"], 4);
        assert_eq!(j["scans"], 10);
        assert_eq!(j["returning_sequences"], 1);
        assert_eq!(j["scans_per_pose"], json!({"min": 1, "max": 3}));
        assert_eq!(j["elevations_per_pose"], json!({"min": 1, "max": 3}));
        assert_eq!(j["poses_with_too_few_elevations"], 1);
        assert_eq!(j["poses_with_mixed_nrays"], 0);
        assert_eq!(j["rays"]["total"], 9 * 4 + 2);
        assert_eq!(j["rays"]["per_scan"], json!({"min": 2, "max": 4}));
        assert_eq!(j["valid_rays"], 9 * 3 + 1);
        assert_eq!(j["valid_fraction"], json!(28.0 / 38.0));
        assert_eq!(j["range_m"], json!({"min": 0.5, "max": 3.0}));
        assert_eq!(j["elevations"]["rad"], json!([-0.1, 0.0, 0.1]));
        assert_eq!(j["elevations"]["distinct"], 3);
        assert_eq!(j["fields"]["true_pose"], 1);
        assert_eq!(j["fields"]["odometry"], 0);
    }

    #[test]
    fn scans_without_sequence_are_one_pose_each() {
        let mut sum = Summary::default();
        for _ in 0..4 {
            sum.add(&scan(None, None, &[Some(1.0)]));
        }
        let j = sum.into_json();
        assert_eq!(j["poses"], 4);
        assert_eq!(j["elevations"]["scans_without"], 4);
        assert_eq!(j["elevations"]["distinct"], 0);
        assert_eq!(j["poses_with_too_few_elevations"], 4);
    }

    #[test]
    fn pose_with_mixed_ray_counts_is_counted() {
        let mut sum = Summary::default();
        for (e, n) in [(-0.1, 3), (0.0, 3), (0.1, 4)] {
            sum.add(&scan(Some(0), Some(e), &vec![Some(1.0); n]));
        }
        let j = sum.into_json();
        assert_eq!(j["poses_with_mixed_nrays"], 1);
        assert_eq!(j["poses_with_too_few_elevations"], 0);
    }
}
