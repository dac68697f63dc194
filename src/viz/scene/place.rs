//! Where every record goes: its kind (raw, level output, matched) and the robot's pose, read
//! from the records; and which poses are drawn when the input is too big for one page.

use super::Source;
use super::ViewParams;
use crate::geometry::{Attitude, Pose};
use crate::scan::Scan;
use std::collections::HashMap;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Kind {
    Raw,
    Leveled,
    Matched,
}

/// A record that went through `match` is shown where the matcher put it, even when it was
/// `level` output before.
pub(super) fn kind_of(scan: &Scan) -> Kind {
    if scan.extra.contains_key("match") {
        Kind::Matched
    } else if scan.extra.contains_key("level") {
        Kind::Leveled
    } else if scan.elevation.is_none() && scan.estimate.is_some() {
        Kind::Matched
    } else {
        Kind::Raw
    }
}

/// The first of a record's poses in `order`, with the field's name.
fn first_pose(scan: &Scan, order: [&'static str; 3]) -> Option<(Pose, &'static str)> {
    order.into_iter().find_map(|field| {
        let pose = match field {
            "true_pose" => scan.true_pose,
            "estimate" => scan.estimate,
            _ => scan.odometry,
        };
        pose.map(|p| (p, field))
    })
}

/// Where a raw record is: `true_pose`, else `estimate`, else `odometry`, else the origin.
fn raw_pose(scan: &Scan) -> Option<(Pose, &'static str)> {
    first_pose(scan, ["true_pose", "estimate", "odometry"])
}

/// Where a matched record is: what the matcher concluded first.
fn matched_pose(scan: &Scan) -> Option<(Pose, &'static str)> {
    first_pose(scan, ["estimate", "odometry", "true_pose"])
}

/// The estimated attitude of a `level` record, when it leveled.
fn level_attitude(scan: &Scan) -> Option<Attitude> {
    let level = scan.extra.get("level")?;
    let tx = level.get("theta_x")?.as_f64()?;
    let ty = level.get("theta_y")?.as_f64()?;
    Some(Attitude::new(tx, ty))
}

/// A pose group, placed: consecutive records of one source with the same sequence (or one
/// record when sequences are absent), the unit of decimation and of a pose cone.
pub(super) struct Placed<'a> {
    pub kind: Kind,
    /// Index of the group's source.
    pub source: usize,
    /// The record field the position comes from (`true_pose`, `estimate`, `odometry`), or
    /// `None` when none is given (drawn at the origin).
    pub pose_from: Option<&'static str>,
    pub scans: Vec<&'a Scan>,
    /// The robot's pose in the world: raw records' 6-DOF pose; for level output the raw pose
    /// of the same sequence when loaded (true attitude and height, so polygons sit on the red
    /// scans), else its planar pose with the estimated attitude at the default height; for
    /// matched records the planar estimate at z = 0.
    pub pose: Pose,
    /// Whether the group adds a pose cone (level output whose raw scans are loaded does not).
    pub cone: bool,
    /// Kept after decimation.
    pub drawn: bool,
}

pub(super) struct Placement<'a> {
    pub groups: Vec<Placed<'a>>,
    pub notes: Vec<String>,
}

/// Consecutive raw records of one source with the same sequence form one group.
fn groups(source: &Source) -> Vec<(Kind, Vec<&Scan>)> {
    let mut out: Vec<(Kind, Vec<&Scan>)> = Vec::new();
    for scan in &source.scans {
        let kind = kind_of(scan);
        if let Some((last_kind, last)) = out.last_mut()
            && kind == Kind::Raw
            && *last_kind == Kind::Raw
            && scan.sequence.is_some()
            && last[0].sequence == scan.sequence
        {
            last.push(scan);
            continue;
        }
        out.push((kind, vec![scan]));
    }
    out
}

/// Places every group of every source, keeping 1 pose in k beyond `params.max_points`.
pub(super) fn place<'a>(sources: &'a [Source], params: &ViewParams) -> Placement<'a> {
    // Raw 6-DOF poses by sequence, so level output of the same run lands where its raw scans are.
    let mut raw_by_sequence: HashMap<u64, Pose> = HashMap::new();
    for scan in sources.iter().flat_map(|s| &s.scans) {
        if kind_of(scan) == Kind::Raw
            && let (Some(seq), Some((pose, _))) = (scan.sequence, raw_pose(scan))
        {
            raw_by_sequence.entry(seq).or_insert(pose);
        }
    }
    let all: Vec<(usize, Kind, Vec<&Scan>)> = sources
        .iter()
        .enumerate()
        .flat_map(|(i, s)| groups(s).into_iter().map(move |(k, g)| (i, k, g)))
        .collect();
    let total_points: usize = all
        .iter()
        .flat_map(|(_, _, g)| g.iter())
        .map(|s| s.valid_count())
        .sum();
    let stride = total_points.div_ceil(params.max_points.max(1)).max(1);
    let mut notes = Vec::new();
    if stride > 1 {
        let kept = all.len().div_ceil(stride);
        notes.push(format!(
            "{total_points} scan points in {} poses: keeping 1 pose in {stride} ({kept} poses) to keep the page small (--max-points {}).",
            all.len(),
            params.max_points
        ));
    }
    let groups: Vec<Placed> = all
        .into_iter()
        .enumerate()
        .map(|(k, (source, kind, scans))| {
            let mut g = locate(kind, scans, &raw_by_sequence, params);
            g.source = source;
            g.drawn = k % stride == 0;
            g
        })
        .collect();
    let unplaced = groups
        .iter()
        .filter(|g| g.drawn && g.pose_from.is_none())
        .count();
    if unplaced > 0 {
        notes.push(format!(
            "{unplaced} poses had no true_pose, estimate or odometry and are drawn at the origin."
        ));
    }
    Placement { groups, notes }
}

fn locate<'a>(
    kind: Kind,
    scans: Vec<&'a Scan>,
    raw_by_sequence: &HashMap<u64, Pose>,
    params: &ViewParams,
) -> Placed<'a> {
    let first = scans[0];
    let (pose, pose_from, cone) = match kind {
        Kind::Raw => {
            let pose = raw_pose(first);
            (pose.unwrap_or_default().0, pose.map(|p| p.1), true)
        }
        Kind::Leveled => {
            let planar = raw_pose(first);
            let raw = first
                .sequence
                .and_then(|s| raw_by_sequence.get(&s).copied());
            let pose = raw.unwrap_or_else(|| {
                let p = planar.unwrap_or_default().0;
                let att = level_attitude(first).unwrap_or_default();
                Pose::new(
                    p.x,
                    p.y,
                    params.default_height,
                    p.rz,
                    att.theta_y,
                    att.theta_x,
                )
            });
            (pose, planar.map(|p| p.1), raw.is_none())
        }
        Kind::Matched => {
            let pose = matched_pose(first);
            let p = pose.unwrap_or_default().0;
            let planar = Pose::new(p.x, p.y, 0.0, p.rz, 0.0, 0.0);
            (planar, pose.map(|p| p.1), true)
        }
    };
    Placed {
        kind,
        source: 0,
        pose_from,
        scans,
        pose,
        cone,
        drawn: true,
    }
}
