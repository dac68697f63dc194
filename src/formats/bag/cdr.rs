//! OMG CDR (XCDR1, the `cdr` message encoding of ROS 2, MCAP's ROS 2 appendix) for the fixed
//! layouts of [`super::msgs`]. Hand-written rather than serde-based: the seven layouts are
//! fixed, and decoding a LaserScan's `float32[]` as one slice conversion instead of a
//! per-element visitor is what keeps bag reading above 300 MB/s.
//!
//! Layout: a 4-byte encapsulation header (`00 01` little endian, `00 00` big endian, then two
//! option bytes), then the fields in order, each primitive aligned to its size counted from
//! the end of the header; strings are a `uint32` length including the terminating NUL, the
//! bytes and the NUL; sequences a `uint32` count then the elements.

use super::msgs::*;

/// A message that does not decode: what was being read and why.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct CdrError(pub String);

type Result<T> = std::result::Result<T, CdrError>;

/// Cap on sequence lengths, so a corrupt count cannot ask for gigabytes.
const MAX_SEQUENCE: usize = 1 << 24;

/// Reads CDR fields in order from one message.
pub struct CdrReader<'a> {
    data: &'a [u8],
    pos: usize,
    little: bool,
    /// ROS 1 serialization instead: no alignment, no NUL in strings, `uint32 seq` in headers.
    ros1: bool,
}

impl<'a> CdrReader<'a> {
    /// Starts after the encapsulation header; refuses other encapsulations (e.g. XCDR2).
    pub fn new(data: &'a [u8]) -> Result<Self> {
        if data.len() < 4 {
            return Err(CdrError(
                "message shorter than its 4-byte CDR header".into(),
            ));
        }
        let little = match (data[0], data[1]) {
            (0, 1) => true,
            (0, 0) => false,
            (a, b) => {
                return Err(CdrError(format!(
                    "unsupported CDR encapsulation {a:#04x} {b:#04x} (expected plain CDR)"
                )));
            }
        };
        Ok(Self {
            data: &data[4..],
            pos: 0,
            little,
            ros1: false,
        })
    }

    /// A reader of ROS 1 serialization (little endian, packed, no encapsulation header): the
    /// same field order as ROS 2 for these types, plus `seq` in `std_msgs/Header`.
    pub fn ros1(data: &'a [u8]) -> Self {
        Self {
            data,
            pos: 0,
            little: true,
            ros1: true,
        }
    }

    fn take(&mut self, n: usize, align: usize, what: &str) -> Result<&'a [u8]> {
        let start = if self.ros1 {
            self.pos
        } else {
            self.pos.div_ceil(align) * align
        };
        let end = start.checked_add(n).filter(|&e| e <= self.data.len());
        let Some(end) = end else {
            return Err(CdrError(format!("message ends inside {what}")));
        };
        self.pos = end;
        Ok(&self.data[start..end])
    }

    pub fn u32(&mut self, what: &str) -> Result<u32> {
        let b: [u8; 4] = self.take(4, 4, what)?.try_into().expect("4 bytes");
        Ok(if self.little {
            u32::from_le_bytes(b)
        } else {
            u32::from_be_bytes(b)
        })
    }

    pub fn i32(&mut self, what: &str) -> Result<i32> {
        self.u32(what).map(|v| v as i32)
    }

    pub fn f32(&mut self, what: &str) -> Result<f32> {
        self.u32(what).map(f32::from_bits)
    }

    pub fn f64(&mut self, what: &str) -> Result<f64> {
        let b: [u8; 8] = self.take(8, 8, what)?.try_into().expect("8 bytes");
        Ok(f64::from_bits(if self.little {
            u64::from_le_bytes(b)
        } else {
            u64::from_be_bytes(b)
        }))
    }

    fn count(&mut self, what: &str, elem: usize) -> Result<usize> {
        let n = self.u32(what)? as usize;
        let left = self.data.len().saturating_sub(self.pos);
        if n > MAX_SEQUENCE || n.saturating_mul(elem) > left {
            return Err(CdrError(format!(
                "{what} claims {n} elements, more than the message holds"
            )));
        }
        Ok(n)
    }

    pub fn string(&mut self, what: &str) -> Result<String> {
        let n = self.count(what, 1)?;
        let bytes = self.take(n, 1, what)?;
        // The length counts the NUL in CDR (not in ROS 1); some tools write "" as length 0.
        let text = bytes.strip_suffix(&[0]).unwrap_or(bytes);
        String::from_utf8(text.to_vec()).map_err(|_| CdrError(format!("{what} is not UTF-8")))
    }

    pub fn f32_seq(&mut self, what: &str) -> Result<Vec<f32>> {
        let n = self.count(what, 4)?;
        let bytes = self.take(n * 4, 4, what)?;
        // One loop per byte order (not a function pointer), so that the conversion inlines:
        // ranges are most of a bag's bytes.
        let words = bytes
            .chunks_exact(4)
            .map(|c| <[u8; 4]>::try_from(c).expect("4 bytes"));
        Ok(if self.little {
            words.map(f32::from_le_bytes).collect()
        } else {
            words.map(f32::from_be_bytes).collect()
        })
    }

    pub fn f64_seq(&mut self, what: &str) -> Result<Vec<f64>> {
        let n = self.count(what, 8)?;
        // Sequence elements align like the element (the count may end on a 4-byte boundary).
        let bytes = if n == 0 {
            &[][..]
        } else {
            self.take(n * 8, 8, what)?
        };
        let conv = if self.little {
            f64::from_le_bytes
        } else {
            f64::from_be_bytes
        };
        Ok(bytes
            .chunks_exact(8)
            .map(|c| conv(c.try_into().expect("8 bytes")))
            .collect())
    }

    pub fn f64_array<const N: usize>(&mut self, what: &str) -> Result<[f64; N]> {
        let mut out = [0.0; N];
        for v in &mut out {
            *v = self.f64(what)?;
        }
        Ok(out)
    }

    pub fn string_seq(&mut self, what: &str) -> Result<Vec<String>> {
        let n = self.count(what, 4)?;
        (0..n).map(|_| self.string(what)).collect()
    }

    pub fn time(&mut self) -> Result<Time> {
        Ok(Time {
            sec: self.i32("header.stamp.sec")?,
            nanosec: self.u32("header.stamp.nanosec")?,
        })
    }

    pub fn header(&mut self) -> Result<Header> {
        if self.ros1 {
            self.u32("header.seq")?;
        }
        Ok(Header {
            stamp: self.time()?,
            frame_id: self.string("header.frame_id")?,
        })
    }

    pub fn pose(&mut self) -> Result<Pose> {
        Ok(Pose {
            position: self.f64_array("pose.position")?,
            orientation: self.f64_array("pose.orientation")?,
        })
    }
}

/// Writes CDR little endian, with the encapsulation header.
pub struct CdrWriter {
    buf: Vec<u8>,
}

impl Default for CdrWriter {
    fn default() -> Self {
        Self::new()
    }
}

impl CdrWriter {
    pub fn new() -> Self {
        Self {
            buf: vec![0, 1, 0, 0],
        }
    }

    fn align(&mut self, n: usize) {
        while (self.buf.len() - 4) % n != 0 {
            self.buf.push(0);
        }
    }

    pub fn u32(&mut self, v: u32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    pub fn f32(&mut self, v: f32) {
        self.u32(v.to_bits());
    }

    pub fn f64(&mut self, v: f64) {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    pub fn string(&mut self, s: &str) {
        self.u32(s.len() as u32 + 1);
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
    }

    pub fn f32_seq(&mut self, v: &[f32]) {
        self.u32(v.len() as u32);
        for x in v {
            self.buf.extend_from_slice(&x.to_le_bytes());
        }
    }

    pub fn f64_seq(&mut self, v: &[f64]) {
        self.u32(v.len() as u32);
        for &x in v {
            self.f64(x);
        }
    }

    pub fn f64s(&mut self, v: &[f64]) {
        for &x in v {
            self.f64(x);
        }
    }

    pub fn header(&mut self, h: &Header) {
        self.u32(h.stamp.sec as u32);
        self.u32(h.stamp.nanosec);
        self.string(&h.frame_id);
    }

    pub fn pose(&mut self, p: &Pose) {
        self.f64s(&p.position);
        self.f64s(&p.orientation);
    }

    pub fn finish(self) -> Vec<u8> {
        self.buf
    }
}

/// A message type with a fixed CDR layout and its ROS 2 type name.
pub trait CdrMessage: Sized {
    /// e.g. `sensor_msgs/msg/LaserScan`.
    const TYPE: &'static str;
    fn decode(r: &mut CdrReader<'_>) -> Result<Self>;
    fn encode(&self, w: &mut CdrWriter);

    /// Decodes one whole CDR message (with its encapsulation header).
    fn from_cdr(data: &[u8]) -> Result<Self> {
        Self::decode(&mut CdrReader::new(data)?)
    }

    /// Decodes one ROS 1 serialized message.
    fn from_ros1(data: &[u8]) -> Result<Self> {
        Self::decode(&mut CdrReader::ros1(data))
    }

    fn to_cdr(&self) -> Vec<u8> {
        let mut w = CdrWriter::new();
        self.encode(&mut w);
        w.finish()
    }
}

impl CdrMessage for LaserScan {
    const TYPE: &'static str = "sensor_msgs/msg/LaserScan";
    fn decode(r: &mut CdrReader<'_>) -> Result<Self> {
        Ok(LaserScan {
            header: r.header()?,
            angle_min: r.f32("angle_min")?,
            angle_max: r.f32("angle_max")?,
            angle_increment: r.f32("angle_increment")?,
            time_increment: r.f32("time_increment")?,
            scan_time: r.f32("scan_time")?,
            range_min: r.f32("range_min")?,
            range_max: r.f32("range_max")?,
            ranges: r.f32_seq("ranges")?,
            intensities: r.f32_seq("intensities")?,
        })
    }
    fn encode(&self, w: &mut CdrWriter) {
        w.header(&self.header);
        for v in [
            self.angle_min,
            self.angle_max,
            self.angle_increment,
            self.time_increment,
            self.scan_time,
            self.range_min,
            self.range_max,
        ] {
            w.f32(v);
        }
        w.f32_seq(&self.ranges);
        w.f32_seq(&self.intensities);
    }
}

impl CdrMessage for JointState {
    const TYPE: &'static str = "sensor_msgs/msg/JointState";
    fn decode(r: &mut CdrReader<'_>) -> Result<Self> {
        Ok(JointState {
            header: r.header()?,
            name: r.string_seq("name")?,
            position: r.f64_seq("position")?,
            velocity: r.f64_seq("velocity")?,
            effort: r.f64_seq("effort")?,
        })
    }
    fn encode(&self, w: &mut CdrWriter) {
        w.header(&self.header);
        w.u32(self.name.len() as u32);
        for n in &self.name {
            w.string(n);
        }
        w.f64_seq(&self.position);
        w.f64_seq(&self.velocity);
        w.f64_seq(&self.effort);
    }
}

impl CdrMessage for Odometry {
    const TYPE: &'static str = "nav_msgs/msg/Odometry";
    fn decode(r: &mut CdrReader<'_>) -> Result<Self> {
        Ok(Odometry {
            header: r.header()?,
            child_frame_id: r.string("child_frame_id")?,
            pose: r.pose()?,
            pose_covariance: r.f64_array("pose.covariance")?,
            twist: r.f64_array("twist.twist")?,
            twist_covariance: r.f64_array("twist.covariance")?,
        })
    }
    fn encode(&self, w: &mut CdrWriter) {
        w.header(&self.header);
        w.string(&self.child_frame_id);
        w.pose(&self.pose);
        w.f64s(&self.pose_covariance);
        w.f64s(&self.twist);
        w.f64s(&self.twist_covariance);
    }
}

impl CdrMessage for PoseStamped {
    const TYPE: &'static str = "geometry_msgs/msg/PoseStamped";
    fn decode(r: &mut CdrReader<'_>) -> Result<Self> {
        Ok(PoseStamped {
            header: r.header()?,
            pose: r.pose()?,
        })
    }
    fn encode(&self, w: &mut CdrWriter) {
        w.header(&self.header);
        w.pose(&self.pose);
    }
}

impl CdrMessage for Imu {
    const TYPE: &'static str = "sensor_msgs/msg/Imu";
    fn decode(r: &mut CdrReader<'_>) -> Result<Self> {
        Ok(Imu {
            header: r.header()?,
            orientation: r.f64_array("orientation")?,
            orientation_covariance: r.f64_array("orientation_covariance")?,
            angular_velocity: r.f64_array("angular_velocity")?,
            angular_velocity_covariance: r.f64_array("angular_velocity_covariance")?,
            linear_acceleration: r.f64_array("linear_acceleration")?,
            linear_acceleration_covariance: r.f64_array("linear_acceleration_covariance")?,
        })
    }
    fn encode(&self, w: &mut CdrWriter) {
        w.header(&self.header);
        w.f64s(&self.orientation);
        w.f64s(&self.orientation_covariance);
        w.f64s(&self.angular_velocity);
        w.f64s(&self.angular_velocity_covariance);
        w.f64s(&self.linear_acceleration);
        w.f64s(&self.linear_acceleration_covariance);
    }
}

/// `std_msgs/msg/String`'s one field.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct StringMsg {
    pub data: String,
}

impl CdrMessage for StringMsg {
    const TYPE: &'static str = "std_msgs/msg/String";
    fn decode(r: &mut CdrReader<'_>) -> Result<Self> {
        Ok(StringMsg {
            data: r.string("data")?,
        })
    }
    fn encode(&self, w: &mut CdrWriter) {
        w.string(&self.data);
    }
}

#[cfg(test)]
#[path = "cdr_tests.rs"]
mod tests;
