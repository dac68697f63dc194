//! ROS bag support (CONTRACT.md, "ROS bags"): the message types levelscan reads and writes
//! ([`msgs`]) and their serialization ([`cdr`]: ROS 2 CDR, and ROS 1's packed layout for the
//! same types); the messages of MCAP files, rosbag2 directories and ROS 1 bags ([`source`]);
//! a first pass for topics and the hinge, odometry and truth signals ([`survey`]), and a second
//! that yields scans grouped into poses ([`scans`]). Writing ROS 2 bags as MCAP ([`write`],
//! with the `ros2msg` schemas of [`schemas`]), the messages `level` and `match` add to them
//! ([`convert`]) and those of a simulated run ([`simulated`]).

pub mod cdr;
pub mod convert;
pub mod msgs;
pub mod scans;
pub mod schemas;
pub mod series;
pub mod simulated;
pub mod source;
pub mod survey;
pub mod write;

pub use cdr::{CdrError, CdrMessage, CdrReader, CdrWriter, StringMsg};
pub use msgs::{Header, Imu, JointState, LaserScan, Odometry, Pose, PoseStamped, Time};
pub use scans::{BagScans, read_scans};
pub use source::{Bag, BagKind, BagMessage, Channel};
pub use survey::{BagOptions, Survey, TopicSummary, survey};
pub use write::{BagWriteError, BagWriter, RawMessage};
