//! The second pass over a bag: its LaserScans as levelscan scans, in header-stamp order,
//! grouped into poses (CONTRACT.md, "ROS bags").
//!
//! A ray's bearing is `angle_min + i * angle_increment`; a range that is NaN, infinite or
//! outside `[range_min, range_max]` is no return. The hinge elevation is the joint's position
//! interpolated at the header stamp; when the scan has a `time_increment` and the hinge moves
//! during it (a nodding laser), each ray also gets the elevation at its own time
//! (`ray_elevation`). A pose is a run of scans taken while the robot stands still (odometry
//! within [`STILL_DISTANCE`] and [`STILL_ANGLE`] of the run's first scan); without odometry, one
//! monotone sweep of the hinge.

use super::msgs::LaserScan;
use super::series::Series;
use super::source::{Bag, at_message};
use super::survey::{BagOptions, Survey, decode, stamp_nanos, stamp_seconds, survey};
use crate::formats::InputError;
use crate::geometry::Pose;
use crate::scan::{Scan, Timestamp};
use serde_json::{Value, json};
use std::collections::BinaryHeap;
use std::ops::ControlFlow;

/// A scan with no joint sample this close \[s\] has no known elevation (the contract's 0.1 s).
pub const JOINT_TOLERANCE: f64 = 0.1;
/// Ground truth further than this from a scan \[s\] is not used for it.
const TRUTH_TOLERANCE: f64 = 0.1;
/// A robot that moved less than this since a run's first scan \[m\] still stands (the
/// contract's 1 cm: well above odometry's rounding, well below a step of a stop-and-go robot).
pub const STILL_DISTANCE: f64 = 0.01;
/// ... and turned less than this \[rad\] (0.5 degree).
pub const STILL_ANGLE: f64 = 0.5 * std::f64::consts::PI / 180.0;
/// Scans held back to put them in header-stamp order: bags are written in arrival order,
/// which can differ from stamp order by a few messages, never by hundreds.
const REORDER_WINDOW: usize = 64;
/// A hinge that moves less than this over a scan \[rad\] counts as standing still for it.
const STILL_HINGE: f64 = 1e-9;

/// One decoded LaserScan waiting for its turn in stamp order.
struct Pending {
    stamp_ns: u64,
    arrival: u64,
    scan: Scan,
}

impl PartialEq for Pending {
    fn eq(&self, other: &Self) -> bool {
        (self.stamp_ns, self.arrival) == (other.stamp_ns, other.arrival)
    }
}
impl Eq for Pending {}
impl PartialOrd for Pending {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Pending {
    /// Reversed, so that the max-heap pops the earliest stamp first.
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        (other.stamp_ns, other.arrival).cmp(&(self.stamp_ns, self.arrival))
    }
}

/// Assigns poses: a new one when the robot moved (with odometry) or the hinge turned back
/// (without).
#[derive(Default)]
struct PoseGrouper {
    sequence: Option<u64>,
    first_odometry: Option<Pose>,
    last_elevation: Option<f64>,
    /// +1 rising, -1 falling, 0 not yet known in this pose.
    direction: i8,
}

impl PoseGrouper {
    fn assign(&mut self, scan: &mut Scan, with_odometry: bool) {
        let new_pose = match self.sequence {
            None => true,
            Some(_) if with_odometry => match (self.first_odometry, scan.odometry) {
                (Some(a), Some(b)) => {
                    let moved = (a.x - b.x).hypot(a.y - b.y) > STILL_DISTANCE;
                    let turned = super::series::angle_diff(a.rz, b.rz).abs() > STILL_ANGLE;
                    moved || turned
                }
                _ => true,
            },
            Some(_) => match (self.last_elevation, scan.elevation) {
                (Some(prev), Some(e)) => {
                    let step = if e > prev {
                        1
                    } else if e < prev {
                        -1
                    } else {
                        0
                    };
                    let breaks = step == 0 || (self.direction != 0 && step != self.direction);
                    if !breaks {
                        self.direction = step;
                    }
                    breaks
                }
                _ => true,
            },
        };
        if new_pose {
            self.sequence = Some(self.sequence.map_or(0, |s| s + 1));
            self.first_odometry = scan.odometry;
            self.direction = 0;
        }
        self.last_elevation = scan.elevation;
        scan.sequence = self.sequence;
    }
}

/// A LaserScan as a levelscan scan, without `sequence` (the grouper's). Errors name the
/// topic and log time.
fn convert(
    bag: &str,
    topic: &str,
    log_time: u64,
    msg: &LaserScan,
    survey: &Survey,
) -> Result<Scan, InputError> {
    let at = || at_message(topic, log_time);
    let n = msg.ranges.len();
    if n == 0 {
        return Err(InputError::new(bag, at(), "a LaserScan without ranges"));
    }
    crate::formats::limits::check_rays("ranges", n).map_err(|e| InputError::new(bag, at(), e))?;
    if !(msg.angle_min.is_finite() && msg.angle_increment.is_finite()) {
        return Err(InputError::new(
            bag,
            at(),
            "angle_min or angle_increment is not a finite number",
        ));
    }
    let t = stamp_seconds(msg.header.stamp, log_time);
    let (lo, hi) = (msg.range_min as f64, msg.range_max as f64);
    let readings: Vec<Option<f64>> = msg
        .ranges
        .iter()
        .map(|&r| {
            let r = r as f64;
            (r.is_finite() && r >= lo && r <= hi && r > 0.0).then_some(r)
        })
        .collect();
    let valid = readings.iter().map(Option::is_some).collect();
    let theta = (0..n)
        .map(|i| msg.angle_min as f64 + i as f64 * msg.angle_increment as f64)
        .collect();
    let mut scan = Scan {
        theta,
        readings,
        valid,
        ..Default::default()
    };
    if let Some((joint, series)) = &survey.hinge {
        hinge_elevations(&mut scan, joint, series, t, msg.time_increment as f64)
            .map_err(|e| InputError::new(bag, at(), e))?;
    }
    if let Some((_, odom)) = &survey.odometry {
        scan.odometry = odom
            .at(t, f64::INFINITY)
            .map(|p| Pose::planar(p.x, p.y, p.rz));
    }
    if let Some((_, truth)) = &survey.truth {
        scan.true_pose = truth.at(t, TRUTH_TOLERANCE);
    }
    let stamp = msg.header.stamp;
    scan.timestamp = Some(Timestamp {
        sec: stamp.sec as i64,
        usec: (stamp.nanosec / 1000) as i64,
    });
    // The same limits as every reader's (formats::limits): what a bag gives must be a scan
    // the rest of levelscan accepts, read back from its own output too.
    crate::formats::limits::check_scan(&scan).map_err(|e| InputError::new(bag, at(), e))?;
    scan.extra
        .insert("ros".to_string(), ros_extra(topic, log_time, msg));
    Ok(scan)
}

/// The scan's hinge elevation from the joint's positions at its stamp `t` [s]; with rays
/// `dt` [s] apart on a moving hinge (a nodding laser), each ray's own as well. The error says
/// when no joint position is near enough.
fn hinge_elevations(
    scan: &mut Scan,
    joint: &str,
    series: &Series<f64>,
    t: f64,
    dt: f64,
) -> Result<(), String> {
    let Some(e) = series.at(t, JOINT_TOLERANCE) else {
        let nearest = series
            .nearest_time(t)
            .map(|s| format!("; the nearest is {:.3} s away", (s - t).abs()))
            .unwrap_or_default();
        return Err(format!(
            "no position of joint {joint} within {JOINT_TOLERANCE} s of the scan's stamp \
             {t:.9}{nearest}"
        ));
    };
    scan.elevation = Some(e);
    let n = scan.theta.len();
    if dt > 0.0 && dt.is_finite() && n > 1 {
        // Each ray at the hinge angle of its own time (nodding lasers); the elevation at
        // a ray's time exists whenever the scan's does, as the series holds its ends.
        let per_ray: Vec<f64> = (0..n)
            .map(|i| series.at(t + i as f64 * dt, f64::INFINITY).unwrap_or(e))
            .collect();
        let (min, max) = per_ray
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                (a.min(v), b.max(v))
            });
        if max - min > STILL_HINGE {
            // The scan's own elevation is its nominal, mid-scan one (Scan::elevation).
            scan.elevation = series.at(t + 0.5 * (n - 1) as f64 * dt, f64::INFINITY);
            scan.ray_elevation = Some(per_ray);
        }
    }
    Ok(())
}

/// What the bag writer needs to write a `/scan_level` beside this scan (see [`Scan::extra`]).
fn ros_extra(topic: &str, log_time: u64, msg: &LaserScan) -> Value {
    json!({
        "topic": topic,
        "frame_id": msg.header.frame_id,
        "stamp": [msg.header.stamp.sec, msg.header.stamp.nanosec],
        "log_time": log_time,
        "angle_min": msg.angle_min,
        "angle_increment": msg.angle_increment,
        "range_min": msg.range_min,
        "range_max": msg.range_max,
        "time_increment": msg.time_increment,
        "scan_time": msg.scan_time,
    })
}

/// The second pass: calls `f` with each scan in stamp order, `sequence` assigned, and its
/// 1-based number on the topic. `survey` is the first pass's (see [`survey`]).
pub fn read_scans(
    bag: &Bag,
    survey: &Survey,
    f: &mut dyn FnMut(usize, Scan) -> Result<ControlFlow<()>, InputError>,
) -> Result<(), InputError> {
    let Some(topic) = survey.scan_topic.clone() else {
        return Err(survey
            .scan_topic_error
            .clone()
            .unwrap_or_else(|| InputError::new(&bag.name, "", "no scan topic")));
    };
    let with_odometry = survey.odometry.is_some();
    let mut heap: BinaryHeap<Pending> = BinaryHeap::with_capacity(REORDER_WINDOW + 1);
    let mut grouper = PoseGrouper::default();
    let mut emitted = 0usize;
    let mut emit =
        |p: Pending, f: &mut dyn FnMut(usize, Scan) -> Result<ControlFlow<()>, InputError>| {
            let mut scan = p.scan;
            grouper.assign(&mut scan, with_odometry);
            emitted += 1;
            f(emitted, scan)
        };
    let mut arrival = 0u64;
    let mut stopped = false;
    bag.for_each_message(&mut |m| {
        if m.channel.topic != topic {
            return Ok(ControlFlow::Continue(()));
        }
        let msg: LaserScan = decode(&bag.name, m)?;
        let scan = convert(&bag.name, &topic, m.log_time, &msg, survey)?;
        let stamp = msg.header.stamp;
        let stamp_ns = stamp_nanos(stamp, m.log_time);
        arrival += 1;
        heap.push(Pending {
            stamp_ns,
            arrival,
            scan,
        });
        if heap.len() > REORDER_WINDOW {
            let next = heap.pop().expect("non-empty");
            if emit(next, f)?.is_break() {
                stopped = true;
                return Ok(ControlFlow::Break(()));
            }
        }
        Ok(ControlFlow::Continue(()))
    })?;
    while !stopped && let Some(next) = heap.pop() {
        if emit(next, f)?.is_break() {
            break;
        }
    }
    Ok(())
}

/// Scans of a bag as an iterator, read on a thread of its own (both passes), a bounded
/// number of scans ahead. Yields `(scan number, scan)` and stops after the first error, like
/// the text readers.
pub struct BagScans {
    rx: std::sync::mpsc::Receiver<Batch>,
    /// The batch being handed out, in reverse order (popped from the back).
    current: Vec<(usize, Scan)>,
    /// The error that ended the current batch, handed out after its scans.
    error: Option<InputError>,
    done: bool,
}

/// Scans sent between the reading thread and the consumer in one message: one channel
/// operation per scan cost more than converting a 1081-ray scan (docs/BAGS.md, Speed).
struct Batch {
    scans: Vec<(usize, Scan)>,
    /// Set on the last batch when the reading stopped on an error.
    error: Option<InputError>,
}

/// Scans per batch, and batches queued ahead of the consumer (at most 256 scans in flight).
const BATCH: usize = 32;
const QUEUE: usize = 8;

impl BagScans {
    /// Runs the first pass now (so that topic and joint errors come before any output), then
    /// streams the second on a thread.
    pub fn open(bag: Bag, opts: &BagOptions) -> Result<(BagScans, Survey), InputError> {
        let survey = survey(&bag, opts)?;
        let scans = BagScans::start(bag, survey.clone())?;
        Ok((scans, survey))
    }

    /// Streams the second pass of a bag already surveyed.
    pub fn start(bag: Bag, survey: Survey) -> Result<BagScans, InputError> {
        if let Some(e) = &survey.scan_topic_error {
            return Err(e.clone());
        }
        let (tx, rx) = std::sync::mpsc::sync_channel::<Batch>(QUEUE);
        std::thread::spawn(move || {
            let mut scans = Vec::with_capacity(BATCH);
            let result = read_scans(&bag, &survey, &mut |n, scan| {
                scans.push((n, scan));
                if scans.len() < BATCH {
                    return Ok(ControlFlow::Continue(()));
                }
                let full = std::mem::replace(&mut scans, Vec::with_capacity(BATCH));
                Ok(
                    match tx.send(Batch {
                        scans: full,
                        error: None,
                    }) {
                        Ok(()) => ControlFlow::Continue(()),
                        Err(_) => ControlFlow::Break(()),
                    },
                )
            });
            let _ = tx.send(Batch {
                scans,
                error: result.err(),
            });
        });
        Ok(BagScans {
            rx,
            current: Vec::new(),
            error: None,
            done: false,
        })
    }
}

impl Iterator for BagScans {
    type Item = Result<(usize, Scan), InputError>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            if self.done {
                return None;
            }
            if let Some(scan) = self.current.pop() {
                return Some(Ok(scan));
            }
            if let Some(e) = self.error.take() {
                self.done = true;
                return Some(Err(e));
            }
            let Ok(batch) = self.rx.recv() else {
                self.done = true;
                return None;
            };
            self.current = batch.scans;
            self.current.reverse();
            self.error = batch.error;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scan_at(elevation: f64, odometry: Option<Pose>) -> Scan {
        Scan {
            elevation: Some(elevation),
            odometry,
            ..Default::default()
        }
    }

    fn sequences(scans: &mut [Scan], with_odometry: bool) -> Vec<u64> {
        let mut g = PoseGrouper::default();
        scans
            .iter_mut()
            .map(|s| {
                g.assign(s, with_odometry);
                s.sequence.unwrap()
            })
            .collect()
    }

    #[test]
    fn without_odometry_a_pose_is_one_monotone_sweep() {
        let mut scans: Vec<Scan> = [-0.2, 0.0, 0.2, 0.1, 0.0, -0.1, -0.1, 0.3]
            .iter()
            .map(|&e| scan_at(e, None))
            .collect();
        assert_eq!(sequences(&mut scans, false), vec![0, 0, 0, 1, 1, 1, 2, 2]);
    }

    #[test]
    fn with_odometry_a_pose_is_a_run_standing_still() {
        let p = |x: f64, yaw_deg: f64| Some(Pose::planar(x, 0.0, yaw_deg.to_radians()));
        let mut scans = vec![
            scan_at(0.0, p(0.0, 0.0)),
            scan_at(0.1, p(0.005, 0.3)),
            scan_at(0.2, p(0.009, -0.4)),
            scan_at(0.0, p(0.5, 0.0)),
            scan_at(0.1, p(0.5, 0.6)),
            scan_at(0.2, p(0.5, 0.6)),
        ];
        // The hinge turning back does not split a pose while the robot stands still.
        assert_eq!(sequences(&mut scans, true), vec![0, 0, 0, 1, 2, 2]);
    }
}
