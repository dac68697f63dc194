//! The messages of a simulated run as a ROS 2 bag (CONTRACT.md, "ROS bags", `simulate`):
//! `/scan`, `/joint_states` just before and just after each scan, `/odom` and
//! `/ground_truth`, with pose k starting at 1000 + 2k s and its scans 0.1 s apart. Pure: the
//! caller writes the messages ([`super::write::BagWriter`]).

use super::msgs::{
    Header, JointState, LaserScan, Odometry, Pose, PoseStamped, Time, quaternion_from_rpy,
};
use crate::geometry::Pose as Pose6;
use crate::scan::Scan;
use crate::simulate::ScannerParams;

pub const SCAN_TOPIC: &str = "/scan";
pub const JOINT_TOPIC: &str = "/joint_states";
pub const ODOM_TOPIC: &str = "/odom";
pub const TRUTH_TOPIC: &str = "/ground_truth";
/// The hinge's joint name in `/joint_states`.
pub const HINGE_JOINT: &str = "hinge";

/// The time of pose 0's first scan \[s\]: a round number well after the epoch, so that no
/// "1 ms before" underflows and stamps read easily.
pub const FIRST_POSE_TIME: f64 = 1000.0;
/// Time between the starts of consecutive poses \[s\] (contract).
pub const POSE_PERIOD: f64 = 2.0;
/// Time between the scans of one pose \[s\] (contract): the hinge moves to the next elevation.
pub const SCAN_SPACING: f64 = 0.1;
/// The time one scan takes \[s\], written as `scan_time`: 25 ms, a 40 Hz scanner (Hokuyo
/// UTM-30LX, SICK TiM5xx). It must leave room for the joint messages 1 ms either side
/// within [`SCAN_SPACING`].
pub const SCAN_TIME: f64 = 0.025;
/// The joint messages' distance before the scan's first ray and after its last \[s\]: close
/// enough that interpolating between them gives the hinge angle of every ray exactly (the
/// hinge stands still, or moves at a constant rate, across the scan).
pub const JOINT_MARGIN: f64 = 0.001;
/// Most scans one pose may have: the last one's joint message must come before the next
/// pose's first one.
pub const MAX_SCANS_PER_POSE: usize =
    ((POSE_PERIOD - SCAN_TIME - 2.0 * JOINT_MARGIN) / SCAN_SPACING) as usize + 1;

/// One message of a simulated bag.
#[derive(Clone, Debug, PartialEq)]
pub enum SimMessage {
    Scan(LaserScan),
    Joint(JointState),
    /// Boxed: its two 6x6 covariances make it five times the size of the others.
    Odom(Box<Odometry>),
    Truth(PoseStamped),
}

impl SimMessage {
    pub fn topic(&self) -> &'static str {
        match self {
            SimMessage::Scan(_) => SCAN_TOPIC,
            SimMessage::Joint(_) => JOINT_TOPIC,
            SimMessage::Odom(_) => ODOM_TOPIC,
            SimMessage::Truth(_) => TRUTH_TOPIC,
        }
    }
}

/// The stamp of scan `j` of pose `k` \[ns\].
pub fn scan_stamp_ns(k: u64, j: usize) -> u64 {
    let secs = FIRST_POSE_TIME + POSE_PERIOD * k as f64 + SCAN_SPACING * j as f64;
    (secs * 1e9).round() as u64
}

/// The messages of pose `k` (its scans in the order taken), each with its log time \[ns\]
/// (= its header stamp), in log-time order. Errors when the pose has more scans than fit in
/// its 2 s ([`MAX_SCANS_PER_POSE`]).
pub fn pose_messages(
    k: u64,
    scans: &[Scan],
    scanner: &ScannerParams,
) -> Result<Vec<(u64, SimMessage)>, String> {
    if scans.len() > MAX_SCANS_PER_POSE {
        return Err(format!(
            "pose {k} has {} scans; a bag holds at most {MAX_SCANS_PER_POSE} per pose ({} s \
             apart within the pose's {} s)",
            scans.len(),
            SCAN_SPACING,
            POSE_PERIOD
        ));
    }
    let margin_ns = (JOINT_MARGIN * 1e9) as u64;
    let scan_ns = (SCAN_TIME * 1e9) as u64;
    let mut out = Vec::with_capacity(scans.len() * 5);
    for (j, scan) in scans.iter().enumerate() {
        let t = scan_stamp_ns(k, j);
        let msg = laser_scan(scan, scanner, Time::from_nanos(t));
        // The hinge angle at time `dt` after the first ray: constant for a hinge that
        // stands still, else the straight line through the first and last rays' angles.
        let (e0, rate) = hinge_motion(scan, f64::from(msg.time_increment));
        let before = t - margin_ns;
        let after = t + scan_ns + margin_ns;
        out.push((before, joint(before, e0 - rate * JOINT_MARGIN)));
        out.push((t, SimMessage::Scan(msg)));
        if let Some(o) = scan.odometry {
            out.push((t, SimMessage::Odom(Box::new(odometry(&o, t)))));
        }
        if let Some(p) = scan.true_pose {
            out.push((t, SimMessage::Truth(ground_truth(&p, t))));
        }
        out.push((after, joint(after, e0 + rate * (SCAN_TIME + JOINT_MARGIN))));
    }
    out.sort_by_key(|(t, _)| *t);
    Ok(out)
}

/// The LaserScan of one simulated scan (frame `laser`): the scanner's bearings and limits,
/// NaN where there was no return. `range_max` is the scanner's plus six sigmas of the range
/// noise, so that a noisy return near the limit, which the JSON Lines output keeps, is not
/// dropped by a reader that clips at `range_max`. `time_increment` is 0 for a hinge that
/// stands still during the scan, else `scan_time / nrays` (rays spread over the scan).
pub fn laser_scan(scan: &Scan, scanner: &ScannerParams, stamp: Time) -> LaserScan {
    let n = scan.nrays();
    let angle_min = -scanner.fov / 2.0;
    let increment = if n > 1 {
        scanner.fov / (n - 1) as f64
    } else {
        0.0
    };
    let ranges = scan
        .ranges()
        .map(|r| r.map_or(f32::NAN, |r| r as f32))
        .collect();
    let time_increment = match &scan.ray_elevation {
        Some(_) if n > 0 => SCAN_TIME / n as f64,
        _ => 0.0,
    };
    LaserScan {
        header: Header {
            stamp,
            frame_id: "laser".into(),
        },
        angle_min: angle_min as f32,
        angle_max: (angle_min + increment * n.saturating_sub(1) as f64) as f32,
        angle_increment: increment as f32,
        time_increment: time_increment as f32,
        scan_time: SCAN_TIME as f32,
        range_min: 0.0,
        range_max: (scanner.max_range + 6.0 * scanner.range_sigma()) as f32,
        ranges,
        intensities: Vec::new(),
    }
}

/// The hinge angle at the first ray \[rad\] and its rate \[rad/s\]: from `ray_elevation`
/// (first and last rays, `dt` apart per ray) when the hinge moves, else `elevation` and 0.
fn hinge_motion(scan: &Scan, dt: f64) -> (f64, f64) {
    match scan.ray_elevation.as_deref() {
        Some([first, .., last]) if dt > 0.0 => {
            let span = dt * (scan.nrays() - 1) as f64;
            (*first, (last - first) / span)
        }
        Some([only, ..]) => (*only, 0.0),
        _ => (scan.elevation.unwrap_or(0.0), 0.0),
    }
}

fn joint(t: u64, position: f64) -> SimMessage {
    SimMessage::Joint(JointState {
        header: Header {
            stamp: Time::from_nanos(t),
            frame_id: String::new(),
        },
        name: vec![HINGE_JOINT.to_string()],
        position: vec![position],
        velocity: Vec::new(),
        effort: Vec::new(),
    })
}

fn ros_pose(p: &Pose6, z: f64) -> Pose {
    Pose {
        position: [p.x, p.y, z],
        orientation: quaternion_from_rpy(p.rx, p.ry, p.rz),
    }
}

/// `/odom` (frame `odom`, child `base_link`): the drifting planar dead reckoning. Its
/// covariance is not modelled (zero), as many simulated drivers publish it.
fn odometry(o: &Pose6, t: u64) -> Odometry {
    Odometry {
        header: Header {
            stamp: Time::from_nanos(t),
            frame_id: "odom".into(),
        },
        child_frame_id: "base_link".into(),
        pose: ros_pose(o, o.z),
        ..Odometry::default()
    }
}

/// `/ground_truth` (frame `world`): the true pose in full, the scanner's height and the
/// robot's roll and pitch included (the simulator knows them; the robot frame's origin is the
/// scanner's, contract "Frames and angles").
fn ground_truth(p: &Pose6, t: u64) -> PoseStamped {
    PoseStamped {
        header: Header {
            stamp: Time::from_nanos(t),
            frame_id: "world".into(),
        },
        pose: ros_pose(p, p.z),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scan(elevation: f64, n: usize) -> Scan {
        let mut s = Scan::with_even_bearings(n, -0.5, 0.5);
        s.elevation = Some(elevation);
        s.readings[0] = Some(2.0);
        s.valid[0] = true;
        s.odometry = Some(Pose6::planar(1.0, 2.0, 0.3));
        s.true_pose = Some(Pose6::new(1.1, 2.1, 0.45, 0.3, 0.05, -0.02));
        s
    }

    fn params(n: usize) -> ScannerParams {
        ScannerParams {
            rays: n,
            fov: 1.0,
            ..ScannerParams::default()
        }
    }

    /// Pose 2 starts at 1004 s, its scans 0.1 s apart; each scan has a joint message 1 ms
    /// before and 1 ms after its 25 ms, at its elevation; odometry and truth at its stamp.
    #[test]
    fn pose_messages_follow_the_contract_timeline() {
        let scans = [scan(-0.1, 5), scan(0.0, 5), scan(0.1, 5)];
        let msgs = pose_messages(2, &scans, &params(5)).unwrap();
        assert_eq!(msgs.len(), 15);
        assert!(msgs.windows(2).all(|w| w[0].0 <= w[1].0));
        let at = |topic: &str| -> Vec<u64> {
            msgs.iter()
                .filter(|(_, m)| m.topic() == topic)
                .map(|(t, _)| *t)
                .collect()
        };
        let s = 1_000_000_000;
        assert_eq!(
            at(SCAN_TOPIC),
            [1004 * s, 1004 * s + s / 10, 1004 * s + s / 5]
        );
        assert_eq!(at(ODOM_TOPIC), at(SCAN_TOPIC));
        assert_eq!(at(TRUTH_TOPIC), at(SCAN_TOPIC));
        assert_eq!(
            at(JOINT_TOPIC)[..2],
            [1004 * s - s / 1000, 1004 * s + 26 * s / 1000]
        );
        for (t, m) in &msgs {
            match m {
                SimMessage::Joint(j) => {
                    assert_eq!(j.header.stamp.nanos(), *t);
                    assert_eq!(j.name, ["hinge"]);
                    let k = ((*t - 1004 * s + s / 50) / (s / 10)) as usize;
                    assert_eq!(j.position, [scans[k].elevation.unwrap()]);
                }
                SimMessage::Scan(l) => {
                    assert_eq!(l.header.stamp.nanos(), *t);
                    assert_eq!(l.header.frame_id, "laser");
                    assert_eq!(
                        (l.angle_min, l.angle_max, l.angle_increment),
                        (-0.5, 0.5, 0.25)
                    );
                    assert_eq!(l.ranges[0], 2.0);
                    assert!(l.ranges[1..].iter().all(|r| r.is_nan()));
                    assert_eq!(l.time_increment, 0.0);
                    assert_eq!(l.range_max, 30.06);
                }
                SimMessage::Odom(o) => {
                    assert_eq!(
                        (o.header.frame_id.as_str(), o.child_frame_id.as_str()),
                        ("odom", "base_link")
                    );
                    assert_eq!(o.pose.position, [1.0, 2.0, 0.0]);
                }
                SimMessage::Truth(p) => {
                    assert_eq!(p.header.frame_id, "world");
                    assert_eq!(p.pose.position, [1.1, 2.1, 0.45]);
                    let (r, pi, y) = super::super::msgs::rpy_from_quaternion(p.pose.orientation);
                    assert!(
                        (r + 0.02).abs() < 1e-12
                            && (pi - 0.05).abs() < 1e-12
                            && (y - 0.3).abs() < 1e-12
                    );
                }
            }
        }
        let too_many = vec![scan(0.0, 5); MAX_SCANS_PER_POSE + 1];
        assert!(pose_messages(0, &too_many, &params(5)).is_err());
        assert_eq!(MAX_SCANS_PER_POSE, 20);
    }

    /// A hinge moving during the scan: `time_increment` spreads the rays over the scan, and
    /// interpolating the two joint messages at ray i's time gives its `ray_elevation`.
    #[test]
    fn moving_hinge_joint_messages_interpolate_to_each_ray() {
        let n = 5;
        let mut s = scan(0.0, n);
        let dt = SCAN_TIME / n as f64;
        let rate = 0.5; // rad/s
        s.ray_elevation = Some((0..n).map(|i| -0.01 + rate * dt * i as f64).collect());
        let msgs = pose_messages(0, &[s.clone()], &params(n)).unwrap();
        let joints: Vec<(f64, f64)> = msgs
            .iter()
            .filter_map(|(t, m)| match m {
                SimMessage::Joint(j) => Some((*t as f64 * 1e-9, j.position[0])),
                _ => None,
            })
            .collect();
        let SimMessage::Scan(l) = &msgs[1].1 else {
            panic!("scan second")
        };
        assert_eq!(l.time_increment, (SCAN_TIME / n as f64) as f32);
        let t0 = l.header.stamp.seconds();
        let [(ta, ea), (tb, eb)] = joints[..] else {
            panic!("two joint messages")
        };
        for (i, want) in s.ray_elevation.unwrap().iter().enumerate() {
            let t = t0 + f64::from(l.time_increment) * i as f64;
            let e = ea + (eb - ea) * (t - ta) / (tb - ta);
            assert!((e - want).abs() < 1e-6, "ray {i}: {e} vs {want}");
        }
    }
}
