//! ROS bag support: the message types levelscan reads and writes ([`msgs`]) and their
//! serialization ([`cdr`]: ROS 2 CDR, and ROS 1's packed layout for the same types).

pub mod cdr;
pub mod msgs;

pub use cdr::{CdrError, CdrMessage, CdrReader, CdrWriter, StringMsg};
pub use msgs::{Header, Imu, JointState, LaserScan, Odometry, Pose, PoseStamped, Time};
