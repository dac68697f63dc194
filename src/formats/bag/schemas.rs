//! The `ros2msg` schemas levelscan writes (MCAP registry, "ros2msg": the type's own `.msg`
//! definition first, then each type it depends on, once, after a line of 80 `=` and a line
//! `MSG: pkg/msg/Type`, the layout rosbag2 writes), and the channel metadata of the ROS 2
//! profile (`offered_qos_profiles`).
//!
//! The definitions are the field lines of the ROS 2 interfaces (common_interfaces,
//! rcl_interfaces) without their comments: comments carry no type information (ROS 2's type
//! hash, RIHS01, ignores them too) and every `.msg` parser skips them. Constants with
//! defaults (`geometry_msgs/msg/Quaternion`'s `w 1`) are kept as ROS 2 declares them.

/// One `.msg` definition: its full name and field lines.
struct Definition {
    name: &'static str,
    text: &'static str,
    /// The full names of the types its fields use, in field order.
    deps: &'static [&'static str],
}

const TIME: Definition = Definition {
    name: "builtin_interfaces/msg/Time",
    text: "int32 sec\nuint32 nanosec\n",
    deps: &[],
};

const HEADER: Definition = Definition {
    name: "std_msgs/msg/Header",
    text: "builtin_interfaces/Time stamp\nstring frame_id\n",
    deps: &["builtin_interfaces/msg/Time"],
};

const STRING: Definition = Definition {
    name: "std_msgs/msg/String",
    text: "string data\n",
    deps: &[],
};

const POINT: Definition = Definition {
    name: "geometry_msgs/msg/Point",
    text: "float64 x\nfloat64 y\nfloat64 z\n",
    deps: &[],
};

const QUATERNION: Definition = Definition {
    name: "geometry_msgs/msg/Quaternion",
    text: "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
    deps: &[],
};

const VECTOR3: Definition = Definition {
    name: "geometry_msgs/msg/Vector3",
    text: "float64 x\nfloat64 y\nfloat64 z\n",
    deps: &[],
};

const POSE: Definition = Definition {
    name: "geometry_msgs/msg/Pose",
    text: "Point position\nQuaternion orientation\n",
    deps: &["geometry_msgs/msg/Point", "geometry_msgs/msg/Quaternion"],
};

const POSE_STAMPED: Definition = Definition {
    name: "geometry_msgs/msg/PoseStamped",
    text: "std_msgs/Header header\nPose pose\n",
    deps: &["std_msgs/msg/Header", "geometry_msgs/msg/Pose"],
};

const POSE_WITH_COVARIANCE: Definition = Definition {
    name: "geometry_msgs/msg/PoseWithCovariance",
    text: "Pose pose\nfloat64[36] covariance\n",
    deps: &["geometry_msgs/msg/Pose"],
};

const TWIST: Definition = Definition {
    name: "geometry_msgs/msg/Twist",
    text: "Vector3 linear\nVector3 angular\n",
    deps: &["geometry_msgs/msg/Vector3"],
};

const TWIST_WITH_COVARIANCE: Definition = Definition {
    name: "geometry_msgs/msg/TwistWithCovariance",
    text: "Twist twist\nfloat64[36] covariance\n",
    deps: &["geometry_msgs/msg/Twist"],
};

const ODOMETRY: Definition = Definition {
    name: "nav_msgs/msg/Odometry",
    text: "std_msgs/Header header\nstring child_frame_id\n\
           geometry_msgs/PoseWithCovariance pose\ngeometry_msgs/TwistWithCovariance twist\n",
    deps: &[
        "std_msgs/msg/Header",
        "geometry_msgs/msg/PoseWithCovariance",
        "geometry_msgs/msg/TwistWithCovariance",
    ],
};

const LASER_SCAN: Definition = Definition {
    name: "sensor_msgs/msg/LaserScan",
    text: "std_msgs/Header header\n\
           float32 angle_min\nfloat32 angle_max\nfloat32 angle_increment\n\
           float32 time_increment\nfloat32 scan_time\n\
           float32 range_min\nfloat32 range_max\n\
           float32[] ranges\nfloat32[] intensities\n",
    deps: &["std_msgs/msg/Header"],
};

const JOINT_STATE: Definition = Definition {
    name: "sensor_msgs/msg/JointState",
    text: "std_msgs/Header header\n\
           string[] name\nfloat64[] position\nfloat64[] velocity\nfloat64[] effort\n",
    deps: &["std_msgs/msg/Header"],
};

const IMU: Definition = Definition {
    name: "sensor_msgs/msg/Imu",
    text: "std_msgs/Header header\n\
           geometry_msgs/Quaternion orientation\nfloat64[9] orientation_covariance\n\
           geometry_msgs/Vector3 angular_velocity\nfloat64[9] angular_velocity_covariance\n\
           geometry_msgs/Vector3 linear_acceleration\nfloat64[9] linear_acceleration_covariance\n",
    deps: &[
        "std_msgs/msg/Header",
        "geometry_msgs/msg/Quaternion",
        "geometry_msgs/msg/Vector3",
    ],
};

const ALL: &[Definition] = &[
    TIME,
    HEADER,
    STRING,
    POINT,
    QUATERNION,
    VECTOR3,
    POSE,
    POSE_STAMPED,
    POSE_WITH_COVARIANCE,
    TWIST,
    TWIST_WITH_COVARIANCE,
    ODOMETRY,
    LASER_SCAN,
    JOINT_STATE,
    IMU,
];

fn definition(name: &str) -> Option<&'static Definition> {
    ALL.iter().find(|d| d.name == name)
}

/// The line that separates concatenated definitions: 80 `=`.
const SEPARATOR: &str =
    "================================================================================";

/// The concatenated `ros2msg` schema of `type_name` (e.g. `sensor_msgs/msg/LaserScan`), or
/// `None` for a type levelscan does not write. Dependencies follow depth first, in the order
/// their fields appear, each once.
pub fn ros2msg_schema(type_name: &str) -> Option<String> {
    let top = definition(type_name)?;
    let mut order: Vec<&'static str> = Vec::new();
    collect_deps(top, &mut order);
    let mut text = top.text.to_string();
    for name in order {
        let d = definition(name).expect("every dependency is defined");
        text.push_str(SEPARATOR);
        text.push_str("\nMSG: ");
        text.push_str(d.name);
        text.push('\n');
        text.push_str(d.text);
    }
    Some(text)
}

fn collect_deps(d: &Definition, order: &mut Vec<&'static str>) {
    for &name in d.deps {
        if !order.contains(&name) {
            order.push(name);
            collect_deps(
                definition(name).expect("every dependency is defined"),
                order,
            );
        }
    }
}

/// `offered_qos_profiles` of a channel levelscan creates (MCAP registry, ROS 2 profile: a
/// required YAML sequence of QoS policies). One publisher offering reliable, volatile,
/// keep-last 10 with no deadline, lifespan or lease: a reliable offer matches both reliable
/// and best-effort subscribers (slam_toolbox, AMCL subscribe best effort to scans), and
/// volatile is what a live sensor offers. The numbers are the rmw enum values (history 1 =
/// keep last, reliability 1 = reliable, durability 2 = volatile, liveliness 1 = automatic) and
/// the infinite duration (2^63 - 1 ns), the form rosbag2 writes since Foxy and still reads.
pub const DEFAULT_QOS: &str = "- history: 1
  depth: 10
  reliability: 1
  durability: 2
  deadline:
    sec: 9223372036
    nsec: 854775807
  lifespan:
    sec: 9223372036
    nsec: 854775807
  liveliness: 1
  liveliness_lease_duration:
    sec: 9223372036
    nsec: 854775807
  avoid_ros_namespace_conventions: false";

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn laser_scan_schema_is_its_fields_then_header_then_time() {
        let s = ros2msg_schema("sensor_msgs/msg/LaserScan").unwrap();
        let sep = "=".repeat(80);
        let parts: Vec<&str> = s.split(&format!("{sep}\n")).collect();
        assert_eq!(parts.len(), 3, "{s}");
        assert!(parts[0].starts_with("std_msgs/Header header\nfloat32 angle_min\n"));
        assert_eq!(
            parts[1],
            "MSG: std_msgs/msg/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n"
        );
        assert_eq!(
            parts[2],
            "MSG: builtin_interfaces/msg/Time\nint32 sec\nuint32 nanosec\n"
        );
    }

    #[test]
    fn odometry_lists_every_nested_type_once() {
        let s = ros2msg_schema("nav_msgs/msg/Odometry").unwrap();
        let msgs: Vec<&str> = s.lines().filter_map(|l| l.strip_prefix("MSG: ")).collect();
        assert_eq!(
            msgs,
            [
                "std_msgs/msg/Header",
                "builtin_interfaces/msg/Time",
                "geometry_msgs/msg/PoseWithCovariance",
                "geometry_msgs/msg/Pose",
                "geometry_msgs/msg/Point",
                "geometry_msgs/msg/Quaternion",
                "geometry_msgs/msg/TwistWithCovariance",
                "geometry_msgs/msg/Twist",
                "geometry_msgs/msg/Vector3",
            ]
        );
        // Every field's type is either primitive or defined in the schema.
        for d in ALL {
            for dep in d.deps {
                assert!(definition(dep).is_some(), "{dep}");
            }
        }
        assert!(ros2msg_schema("sensor_msgs/msg/PointCloud2").is_none());
    }
}
