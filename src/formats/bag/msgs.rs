//! Plain ROS message structs for the types levelscan reads and writes (ROS 2 names:
//! `builtin_interfaces/msg/Time`, `std_msgs/msg/Header`, `sensor_msgs/msg/LaserScan`,
//! `sensor_msgs/msg/JointState`, `nav_msgs/msg/Odometry`, `geometry_msgs/msg/PoseStamped`,
//! `sensor_msgs/msg/Imu`, `std_msgs/msg/String`). Only the fields the ROS definitions have,
//! in their order; no I/O (see [`super::cdr`]).

/// `builtin_interfaces/msg/Time`: seconds and nanoseconds since the epoch.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Default, Hash)]
pub struct Time {
    pub sec: i32,
    pub nanosec: u32,
}

impl Time {
    /// Seconds as a float (for interpolation).
    pub fn seconds(&self) -> f64 {
        self.sec as f64 + self.nanosec as f64 * 1e-9
    }

    /// Nanoseconds since the epoch (MCAP log times); negative stamps clamp to 0.
    pub fn nanos(&self) -> u64 {
        (self.sec.max(0) as u64) * 1_000_000_000 + self.nanosec as u64
    }

    pub fn from_nanos(ns: u64) -> Time {
        Time {
            sec: (ns / 1_000_000_000).min(i32::MAX as u64) as i32,
            nanosec: (ns % 1_000_000_000) as u32,
        }
    }

    /// The nearest representable time to `t` seconds.
    pub fn from_seconds(t: f64) -> Time {
        Time::from_nanos((t.max(0.0) * 1e9).round() as u64)
    }
}

/// `std_msgs/msg/Header`.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Header {
    pub stamp: Time,
    pub frame_id: String,
}

/// `sensor_msgs/msg/LaserScan`.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct LaserScan {
    pub header: Header,
    pub angle_min: f32,
    pub angle_max: f32,
    pub angle_increment: f32,
    pub time_increment: f32,
    pub scan_time: f32,
    pub range_min: f32,
    pub range_max: f32,
    pub ranges: Vec<f32>,
    pub intensities: Vec<f32>,
}

/// `sensor_msgs/msg/JointState`.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct JointState {
    pub header: Header,
    pub name: Vec<String>,
    pub position: Vec<f64>,
    pub velocity: Vec<f64>,
    pub effort: Vec<f64>,
}

/// `geometry_msgs/msg/Pose`: position and orientation quaternion (x, y, z, w).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    pub position: [f64; 3],
    pub orientation: [f64; 4],
}

impl Default for Pose {
    fn default() -> Self {
        Pose {
            position: [0.0; 3],
            orientation: [0.0, 0.0, 0.0, 1.0],
        }
    }
}

/// `nav_msgs/msg/Odometry`; `pose_covariance` and `twist_covariance` are row-major 6x6
/// over (x, y, z, roll, pitch, yaw).
#[derive(Clone, Debug, PartialEq)]
pub struct Odometry {
    pub header: Header,
    pub child_frame_id: String,
    pub pose: Pose,
    pub pose_covariance: [f64; 36],
    /// Twist: linear then angular (m/s, rad/s).
    pub twist: [f64; 6],
    pub twist_covariance: [f64; 36],
}

impl Default for Odometry {
    fn default() -> Self {
        Odometry {
            header: Header::default(),
            child_frame_id: String::new(),
            pose: Pose::default(),
            pose_covariance: [0.0; 36],
            twist: [0.0; 6],
            twist_covariance: [0.0; 36],
        }
    }
}

/// `geometry_msgs/msg/PoseStamped`.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct PoseStamped {
    pub header: Header,
    pub pose: Pose,
}

/// `sensor_msgs/msg/Imu`; covariances row-major 3x3, element 0 = -1 means "unknown" (REP 145).
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Imu {
    pub header: Header,
    /// x, y, z, w.
    pub orientation: [f64; 4],
    pub orientation_covariance: [f64; 9],
    pub angular_velocity: [f64; 3],
    pub angular_velocity_covariance: [f64; 9],
    pub linear_acceleration: [f64; 3],
    pub linear_acceleration_covariance: [f64; 9],
}

/// Quaternion (x, y, z, w) of `Rz(yaw) * Ry(pitch) * Rx(roll)` (REP-103 fixed-axis roll,
/// pitch, yaw; the contract's pose rotation).
pub fn quaternion_from_rpy(roll: f64, pitch: f64, yaw: f64) -> [f64; 4] {
    let (sr, cr) = (roll * 0.5).sin_cos();
    let (sp, cp) = (pitch * 0.5).sin_cos();
    let (sy, cy) = (yaw * 0.5).sin_cos();
    [
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
        cr * cp * cy + sr * sp * sy,
    ]
}

/// Roll, pitch, yaw of a quaternion (x, y, z, w), the inverse of [`quaternion_from_rpy`]; the
/// quaternion need not be normalised.
pub fn rpy_from_quaternion(q: [f64; 4]) -> (f64, f64, f64) {
    let [x, y, z, w] = q;
    let n = (x * x + y * y + z * z + w * w).sqrt();
    let (x, y, z, w) = if n > 0.0 {
        (x / n, y / n, z / n, w / n)
    } else {
        (0.0, 0.0, 0.0, 1.0)
    };
    let roll = (2.0 * (w * x + y * z)).atan2(1.0 - 2.0 * (x * x + y * y));
    let pitch = (2.0 * (w * y - z * x)).clamp(-1.0, 1.0).asin();
    let yaw = (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z));
    (roll, pitch, yaw)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rpy_round_trips_through_the_quaternion() {
        for &(r, p, y) in &[(0.1, -0.2, 0.3), (0.0, 0.0, 3.0), (-0.5, 0.4, -2.0)] {
            let (r2, p2, y2) = rpy_from_quaternion(quaternion_from_rpy(r, p, y));
            assert!((r - r2).abs() < 1e-12 && (p - p2).abs() < 1e-12 && (y - y2).abs() < 1e-12);
        }
        // A pure yaw of 90 degrees is (0, 0, sin 45, cos 45).
        let q = quaternion_from_rpy(0.0, 0.0, std::f64::consts::FRAC_PI_2);
        assert!((q[2] - 0.5f64.sqrt()).abs() < 1e-15 && (q[3] - 0.5f64.sqrt()).abs() < 1e-15);
    }

    #[test]
    fn time_converts_between_nanos_and_seconds() {
        let t = Time::from_nanos(1_000_100_000_001);
        assert_eq!(
            t,
            Time {
                sec: 1000,
                nanosec: 100_000_001
            }
        );
        assert_eq!(t.nanos(), 1_000_100_000_001);
        assert_eq!(
            Time::from_seconds(1000.1),
            Time {
                sec: 1000,
                nanosec: 100_000_000
            }
        );
    }
}
