//! ROS bag support: the message types levelscan reads and writes ([`msgs`]) and their
//! serialization ([`cdr`]: ROS 2 CDR, and ROS 1's packed layout for the same types); writing
//! ROS 2 bags as MCAP ([`write`], with the `ros2msg` schemas of [`schemas`]), the messages
//! `level` and `match` add to them ([`convert`]) and those of a simulated run ([`simulated`]).

pub mod cdr;
pub mod convert;
pub mod msgs;
pub mod schemas;
pub mod simulated;
pub mod write;

pub use cdr::{CdrError, CdrMessage, CdrReader, CdrWriter, StringMsg};
pub use msgs::{Header, Imu, JointState, LaserScan, Odometry, Pose, PoseStamped, Time};
pub use write::{BagWriteError, BagWriter, RawMessage};
