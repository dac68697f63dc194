//! The tests' own ROS 2 CDR encoder and ros2msg schema texts (see the module above).
#![allow(dead_code)]

// ---- ROS 2 CDR, little endian (the test's own encoder) ------------------------------------

/// A CDR buffer: the 4-byte encapsulation header (CDR_LE), then fields aligned to their size
/// counted from the end of that header (the OMG CDR rule ROS 2 uses).
pub struct Cdr(pub Vec<u8>);

impl Cdr {
    pub fn new() -> Cdr {
        Cdr(vec![0, 1, 0, 0])
    }
    fn align(&mut self, n: usize) {
        while (self.0.len() - 4) % n != 0 {
            self.0.push(0);
        }
    }
    pub fn u32(&mut self, v: u32) -> &mut Self {
        self.align(4);
        self.0.extend_from_slice(&v.to_le_bytes());
        self
    }
    pub fn i32(&mut self, v: i32) -> &mut Self {
        self.u32(v as u32)
    }
    pub fn f32(&mut self, v: f32) -> &mut Self {
        self.u32(v.to_bits())
    }
    pub fn f64(&mut self, v: f64) -> &mut Self {
        self.align(8);
        self.0.extend_from_slice(&v.to_le_bytes());
        self
    }
    pub fn string(&mut self, s: &str) -> &mut Self {
        self.u32(s.len() as u32 + 1);
        self.0.extend_from_slice(s.as_bytes());
        self.0.push(0);
        self
    }
    pub fn header(&mut self, ns: u64, frame: &str) -> &mut Self {
        self.i32((ns / 1_000_000_000) as i32)
            .u32((ns % 1_000_000_000) as u32)
            .string(frame)
    }
    pub fn f64s(&mut self, v: &[f64]) -> &mut Self {
        self.u32(v.len() as u32);
        for x in v {
            self.f64(*x);
        }
        self
    }
    /// A pose: position, then the quaternion (x, y, z, w) of yaw about z, roll/pitch given.
    pub fn pose(&mut self, p: [f64; 3], q: [f64; 4]) -> &mut Self {
        for x in p.iter().chain(q.iter()) {
            self.f64(*x);
        }
        self
    }
    pub fn done(&mut self) -> Vec<u8> {
        std::mem::take(&mut self.0)
    }
}

/// Quaternion (x, y, z, w) of Rz(yaw) Ry(pitch) Rx(roll).
pub fn quat(roll: f64, pitch: f64, yaw: f64) -> [f64; 4] {
    let (sr, cr) = (roll / 2.0).sin_cos();
    let (sp, cp) = (pitch / 2.0).sin_cos();
    let (sy, cy) = (yaw / 2.0).sin_cos();
    [
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
        cr * cp * cy + sr * sp * sy,
    ]
}

pub struct LaserScanMsg<'a> {
    pub stamp_ns: u64,
    pub frame: &'a str,
    pub angle_min: f32,
    pub angle_increment: f32,
    pub range_min: f32,
    pub range_max: f32,
    pub ranges: &'a [f32],
}

pub fn laser_scan_cdr(m: &LaserScanMsg) -> Vec<u8> {
    let n = m.ranges.len().max(1) as f32;
    let mut c = Cdr::new();
    c.header(m.stamp_ns, m.frame)
        .f32(m.angle_min)
        .f32(m.angle_min + m.angle_increment * (n - 1.0))
        .f32(m.angle_increment)
        .f32(0.0)
        .f32(0.1)
        .f32(m.range_min)
        .f32(m.range_max)
        .u32(m.ranges.len() as u32);
    for r in m.ranges {
        c.f32(*r);
    }
    c.u32(0).done()
}

pub fn joint_state_cdr(stamp_ns: u64, names: &[&str], positions: &[f64]) -> Vec<u8> {
    let mut c = Cdr::new();
    c.header(stamp_ns, "").u32(names.len() as u32);
    for n in names {
        c.string(n);
    }
    c.f64s(positions).f64s(&[]).f64s(&[]).done()
}

pub fn odometry_cdr(stamp_ns: u64, x: f64, y: f64, yaw: f64) -> Vec<u8> {
    let mut c = Cdr::new();
    c.header(stamp_ns, "odom")
        .string("base_link")
        .pose([x, y, 0.0], quat(0.0, 0.0, yaw));
    for _ in 0..36 + 6 + 36 {
        c.f64(0.0);
    }
    c.done()
}

pub fn pose_stamped_cdr(stamp_ns: u64, pose6: &[f64]) -> Vec<u8> {
    let mut c = Cdr::new();
    let q = quat(pose6[5], pose6[4], pose6[3]);
    c.header(stamp_ns, "world")
        .pose([pose6[0], pose6[1], pose6[2]], q)
        .done()
}

pub fn string_cdr(s: &str) -> Vec<u8> {
    Cdr::new().string(s).done()
}

// ---- ros2msg schema texts ----------------------------------------------------------------

const TIME: &str = "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n";
const HEADER: &str = "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n";
const SEP: &str =
    "================================================================================\n";

pub fn schema_text(name: &str) -> String {
    let header = format!("{SEP}{HEADER}{SEP}{TIME}");
    let geometry = format!(
        "{SEP}MSG: geometry_msgs/Pose\nPoint position\nQuaternion orientation\n{SEP}\
         MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n{SEP}\
         MSG: geometry_msgs/Quaternion\nfloat64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n"
    );
    match name {
        "sensor_msgs/msg/LaserScan" => format!(
            "std_msgs/Header header\nfloat32 angle_min\nfloat32 angle_max\n\
             float32 angle_increment\nfloat32 time_increment\nfloat32 scan_time\n\
             float32 range_min\nfloat32 range_max\nfloat32[] ranges\nfloat32[] intensities\n{header}"
        ),
        "sensor_msgs/msg/JointState" => format!(
            "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\n\
             float64[] effort\n{header}"
        ),
        "nav_msgs/msg/Odometry" => format!(
            "std_msgs/Header header\nstring child_frame_id\n\
             geometry_msgs/PoseWithCovariance pose\ngeometry_msgs/TwistWithCovariance twist\n\
             {header}{SEP}MSG: geometry_msgs/PoseWithCovariance\nPose pose\n\
             float64[36] covariance\n{SEP}MSG: geometry_msgs/TwistWithCovariance\nTwist twist\n\
             float64[36] covariance\n{SEP}MSG: geometry_msgs/Twist\nVector3 linear\n\
             Vector3 angular\n{SEP}MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\n\
             float64 z\n{geometry}"
        ),
        "geometry_msgs/msg/PoseStamped" => {
            format!("std_msgs/Header header\nPose pose\n{header}{geometry}")
        }
        _ => "string data\n".to_string(),
    }
}
