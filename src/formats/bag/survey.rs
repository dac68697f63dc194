//! The first pass over a bag: what topics it has, and the signals scans are interpolated in
//! (the hinge joint, odometry, ground truth), chosen as CONTRACT.md's "ROS bags" table says.
//! Scans themselves are read in the second pass ([`super::scans`]), so memory holds only these
//! small series, not the scans.

use super::cdr::CdrMessage;
use super::msgs::{JointState, LaserScan, Odometry, PoseStamped, rpy_from_quaternion};
use super::series::Series;
use super::source::{Bag, BagMessage, at_message};
use crate::formats::InputError;
use crate::geometry::Pose;
use std::collections::BTreeMap;
use std::ops::ControlFlow;

/// Which topics and joint to read; the defaults are the contract's.
#[derive(Clone, Debug)]
pub struct BagOptions {
    /// The scans' topic; default: the bag's only LaserScan topic (or `preferred_scan_topic`).
    pub scan_topic: Option<String>,
    /// Taken when the bag has it and no topic is named (`match` prefers `/scan_level`).
    pub preferred_scan_topic: Option<String>,
    pub joint_topic: String,
    /// The hinge's joint name; default: the only joint the joint topic names.
    pub hinge_joint: Option<String>,
    /// Default: the only Odometry topic (`/odom` when there are several).
    pub odom_topic: Option<String>,
    /// Default: `/ground_truth` when present.
    pub truth_topic: Option<String>,
    /// `level` needs every scan's elevation: a bag without the hinge joint is then an error.
    pub need_elevation: bool,
}

impl Default for BagOptions {
    fn default() -> Self {
        BagOptions {
            scan_topic: None,
            preferred_scan_topic: None,
            joint_topic: "/joint_states".to_string(),
            hinge_joint: None,
            odom_topic: None,
            truth_topic: None,
            need_elevation: false,
        }
    }
}

// The message types by their ROS 2 names, as the decoders know them.
const LASER_SCAN: &str = LaserScan::TYPE;
const JOINT_STATE: &str = JointState::TYPE;
const ODOMETRY: &str = Odometry::TYPE;
const POSE_STAMPED: &str = PoseStamped::TYPE;

/// One topic of the bag, for `info`.
#[derive(Clone, Debug, PartialEq)]
pub struct TopicSummary {
    pub topic: String,
    pub message_type: String,
    pub count: u64,
    /// First and last log time \[ns\].
    pub first: u64,
    pub last: u64,
}

/// What the first pass found.
#[derive(Clone, Debug)]
pub struct Survey {
    /// Every topic, by name.
    pub topics: Vec<TopicSummary>,
    /// The scans' topic, when there is one to take.
    pub scan_topic: Option<String>,
    /// Why there is none (several LaserScan topics, none, a wrong type): the error to give
    /// when scans are wanted.
    pub scan_topic_error: Option<InputError>,
    /// The hinge joint's position \[rad\] by header stamp \[s\].
    pub hinge: Option<(String, Series<f64>)>,
    pub odometry: Option<(String, Series<Pose>)>,
    pub truth: Option<(String, Series<Pose>)>,
}

/// Decodes a message by its encoding (`cdr` or `ros1`); errors name topic and log time.
pub fn decode<M: CdrMessage>(bag: &str, m: &BagMessage) -> Result<M, InputError> {
    let result = match m.channel.message_encoding.as_str() {
        "cdr" => M::from_cdr(m.data),
        "ros1" => M::from_ros1(m.data),
        other => {
            return Err(InputError::new(
                bag,
                at_message(&m.channel.topic, m.log_time),
                format!("message encoding {other:?} (levelscan reads cdr and ros1)"),
            ));
        }
    };
    result.map_err(|e| {
        InputError::new(
            bag,
            at_message(&m.channel.topic, m.log_time),
            format!("a {} that does not decode: {e}", M::TYPE),
        )
    })
}

/// Collects joint positions: the named joint's, or while there is only one, the only one's.
#[derive(Default)]
struct HingeCollector {
    named: Option<String>,
    seen: Vec<String>,
    series: Series<f64>,
}

impl HingeCollector {
    fn push(&mut self, t: f64, js: &JointState) {
        for (name, &pos) in js.name.iter().zip(&js.position) {
            if !self.seen.contains(name) && self.seen.len() < 64 {
                self.seen.push(name.clone());
            }
            let wanted = match &self.named {
                Some(n) => n == name,
                None => self.seen.len() == 1,
            };
            if wanted && pos.is_finite() {
                self.series.push(t, pos);
            }
        }
    }
}

fn pose_of(p: &super::msgs::Pose) -> Pose {
    let (roll, pitch, yaw) = rpy_from_quaternion(p.orientation);
    Pose::new(
        p.position[0],
        p.position[1],
        p.position[2],
        yaw,
        pitch,
        roll,
    )
}

/// A message's pose, within the limits every reader enforces (formats::limits): the error
/// names the topic and log time.
fn checked_pose(
    bag: &str,
    m: &BagMessage,
    field: &str,
    p: &super::msgs::Pose,
) -> Result<Pose, InputError> {
    let pose = pose_of(p);
    crate::formats::limits::check_pose(field, &pose)
        .map_err(|e| InputError::new(bag, at_message(&m.channel.topic, m.log_time), e))?;
    Ok(pose)
}

/// The first pass: topics, and the hinge, odometry and truth series.
pub fn survey(bag: &Bag, opts: &BagOptions) -> Result<Survey, InputError> {
    let mut topics: BTreeMap<String, TopicSummary> = BTreeMap::new();
    let mut hinge = HingeCollector {
        named: opts.hinge_joint.clone(),
        ..Default::default()
    };
    let mut odometry: BTreeMap<String, Series<Pose>> = BTreeMap::new();
    let truth_topic = opts.truth_topic.as_deref().unwrap_or("/ground_truth");
    let mut truth = Series::default();
    bag.for_each_message(&mut |m| {
        let ty = &m.channel.message_type;
        let entry = topics
            .entry(m.channel.topic.clone())
            .or_insert_with(|| TopicSummary {
                topic: m.channel.topic.clone(),
                message_type: ty.clone(),
                count: 0,
                first: m.log_time,
                last: m.log_time,
            });
        entry.count += 1;
        entry.first = entry.first.min(m.log_time);
        entry.last = entry.last.max(m.log_time);
        let topic = m.channel.topic.as_str();
        if topic == opts.joint_topic && ty == JOINT_STATE {
            let js: JointState = decode(&bag.name, m)?;
            hinge.push(stamp_seconds(js.header.stamp, m.log_time), &js);
        } else if ty == ODOMETRY && opts.odom_topic.as_deref().is_none_or(|t| t == topic) {
            let o: Odometry = decode(&bag.name, m)?;
            let t = stamp_seconds(o.header.stamp, m.log_time);
            let pose = checked_pose(&bag.name, m, "odometry", &o.pose)?;
            odometry.entry(topic.to_string()).or_default().push(t, pose);
        } else if topic == truth_topic && ty == POSE_STAMPED {
            let p: PoseStamped = decode(&bag.name, m)?;
            let pose = checked_pose(&bag.name, m, "pose", &p.pose)?;
            truth.push(stamp_seconds(p.header.stamp, m.log_time), pose);
        }
        Ok(ControlFlow::Continue(()))
    })?;
    let topics: Vec<TopicSummary> = topics.into_values().collect();
    let (scan_topic, scan_topic_error) = match choose_scan_topic(&bag.name, &topics, opts) {
        Ok(t) => (Some(t), None),
        Err(e) => (None, Some(e)),
    };
    let hinge = choose_hinge(&bag.name, &topics, opts, hinge)?;
    let odometry = choose_odometry(&bag.name, opts, odometry)?;
    let truth = (!truth.is_empty()).then(|| {
        truth.finish();
        (truth_topic.to_string(), truth)
    });
    Ok(Survey {
        topics,
        scan_topic,
        scan_topic_error,
        hinge,
        odometry,
        truth,
    })
}

/// A header stamp in seconds; a zero stamp (some drivers leave it unset) falls back to the
/// message's log time.
pub fn stamp_seconds(stamp: super::msgs::Time, log_time: u64) -> f64 {
    stamp_nanos(stamp, log_time) as f64 * 1e-9
}

/// [`stamp_seconds`] in nanoseconds (the order scans are read in).
pub fn stamp_nanos(stamp: super::msgs::Time, log_time: u64) -> u64 {
    if stamp.sec == 0 && stamp.nanosec == 0 {
        log_time
    } else {
        stamp.nanos()
    }
}

fn list(topics: &[&TopicSummary]) -> String {
    topics
        .iter()
        .map(|t| t.topic.as_str())
        .collect::<Vec<_>>()
        .join(", ")
}

fn choose_scan_topic(
    bag: &str,
    topics: &[TopicSummary],
    opts: &BagOptions,
) -> Result<String, InputError> {
    let scans: Vec<&TopicSummary> = topics
        .iter()
        .filter(|t| t.message_type == LASER_SCAN)
        .collect();
    if let Some(name) = &opts.scan_topic {
        return match topics.iter().find(|t| &t.topic == name) {
            Some(t) if t.message_type == LASER_SCAN => Ok(name.clone()),
            Some(t) => Err(InputError::new(
                bag,
                name.as_str(),
                format!("the scan topic holds {}, not {LASER_SCAN}", t.message_type),
            )),
            None => Err(InputError::new(
                bag,
                "",
                format!(
                    "no topic {name} (--scan-topic); its LaserScan topics: {}",
                    if scans.is_empty() {
                        "none".to_string()
                    } else {
                        list(&scans)
                    }
                ),
            )),
        };
    }
    if let Some(p) = &opts.preferred_scan_topic
        && scans.iter().any(|t| &t.topic == p)
    {
        return Ok(p.clone());
    }
    match scans[..] {
        [only] => Ok(only.topic.clone()),
        [] => Err(InputError::new(
            bag,
            "",
            format!("no {LASER_SCAN} topic in the bag"),
        )),
        _ => Err(InputError::new(
            bag,
            "",
            format!(
                "{} LaserScan topics ({}): name one with --scan-topic",
                scans.len(),
                list(&scans)
            ),
        )),
    }
}

type Hinge = Option<(String, Series<f64>)>;

fn choose_hinge(
    bag: &str,
    topics: &[TopicSummary],
    opts: &BagOptions,
    mut hinge: HingeCollector,
) -> Result<Hinge, InputError> {
    let topic = &opts.joint_topic;
    let need = opts.need_elevation;
    let missing = |message: String| {
        if need {
            Err(InputError::new(bag, topic.as_str(), message))
        } else {
            Ok(None)
        }
    };
    match topics.iter().find(|t| &t.topic == topic) {
        None => {
            return missing(format!(
                "no messages on {topic}: level needs the hinge elevation of every scan \
                 (--joint-topic, --hinge-joint)"
            ));
        }
        Some(t) if t.message_type != JOINT_STATE => {
            return Err(InputError::new(
                bag,
                topic.as_str(),
                format!(
                    "the joint topic holds {}, not {JOINT_STATE}",
                    t.message_type
                ),
            ));
        }
        Some(_) => {}
    }
    let names = hinge.seen.join(", ");
    let joint = match (&hinge.named, hinge.seen.len()) {
        (Some(n), _) if hinge.series.is_empty() => {
            return missing(format!(
                "no joint {n} (--hinge-joint) in {topic}; it names: {names}"
            ));
        }
        (Some(n), _) => n.clone(),
        (None, 1) => hinge.seen[0].clone(),
        (None, 0) => return missing(format!("the messages on {topic} name no joint")),
        (None, _) => {
            return missing(format!(
                "{topic} names several joints ({names}): name the hinge with --hinge-joint"
            ));
        }
    };
    hinge.series.finish();
    Ok(Some((joint, hinge.series)))
}

type Odom = Option<(String, Series<Pose>)>;

fn choose_odometry(
    bag: &str,
    opts: &BagOptions,
    mut odometry: BTreeMap<String, Series<Pose>>,
) -> Result<Odom, InputError> {
    if let Some(name) = &opts.odom_topic
        && !odometry.contains_key(name)
    {
        return Err(InputError::new(
            bag,
            "",
            format!("no {ODOMETRY} messages on {name} (--odom-topic)"),
        ));
    }
    let name = match odometry.len() {
        0 => return Ok(None),
        1 => odometry.keys().next().cloned(),
        _ if odometry.contains_key("/odom") => Some("/odom".to_string()),
        _ => {
            let names: Vec<&str> = odometry.keys().map(String::as_str).collect();
            return Err(InputError::new(
                bag,
                "",
                format!(
                    "several Odometry topics ({}): name one with --odom-topic",
                    names.join(", ")
                ),
            ));
        }
    };
    let name = name.expect("one key");
    let mut series = odometry.remove(&name).expect("present");
    series.finish();
    Ok(Some((name, series)))
}
