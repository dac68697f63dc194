//! Scans written as JSON Lines, fields in a stable order.

use super::record::KNOWN_FIELDS;
use crate::geometry::Pose;
use crate::scan::{Hit, Scan};
use serde::Serialize;
use serde::ser::{SerializeMap, SerializeSeq, Serializer};
use std::io::{self, Write};

/// Writes one scan as one compact JSON line and a newline. Fields come in a stable order
/// (`sequence`, `nrays`, `elevation`, `ray_elevation`, `theta`, `readings`, `valid`, `min_theta`, `max_theta`,
/// `odometry`, `estimate`, `true_pose`, `timestamp`, `readings_sigma`, `hinge_offset`, `hit`,
/// then the unknown fields in their order); absent optional fields are left out. Poses are
/// written `[x, y, rz]` when planar, else all 6. Numbers round-trip exactly; a non-finite number
/// is written `null` (JSON has no NaN). An unknown field named like a known one is skipped.
pub fn write_scan(w: &mut impl Write, scan: &Scan) -> io::Result<()> {
    serde_json::to_writer(&mut *w, &ScanOut(scan))?;
    w.write_all(b"\n")
}

struct ScanOut<'a>(&'a Scan);

struct PoseOut<'a>(&'a Pose);

impl Serialize for PoseOut<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let p = self.0;
        if p.is_planar() {
            [p.x, p.y, p.rz].serialize(s)
        } else {
            p.to_array().serialize(s)
        }
    }
}

struct Flags<'a>(&'a [bool]);

impl Serialize for Flags<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut seq = s.serialize_seq(Some(self.0.len()))?;
        for &v in self.0 {
            seq.serialize_element(&u8::from(v))?;
        }
        seq.end()
    }
}

struct Hits<'a>(&'a [Hit]);

impl Serialize for Hits<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_seq(self.0.iter().map(|&h| h as u8))
    }
}

impl Serialize for ScanOut<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let scan = self.0;
        let mut m = s.serialize_map(None)?;
        if let Some(v) = scan.sequence {
            m.serialize_entry("sequence", &v)?;
        }
        m.serialize_entry("nrays", &scan.nrays())?;
        if let Some(v) = scan.elevation {
            m.serialize_entry("elevation", &v)?;
        }
        if let Some(v) = &scan.ray_elevation {
            m.serialize_entry("ray_elevation", v)?;
        }
        m.serialize_entry("theta", &scan.theta)?;
        m.serialize_entry("readings", &scan.readings)?;
        m.serialize_entry("valid", &Flags(&scan.valid))?;
        if let (Some(min), Some(max)) = (scan.min_theta(), scan.max_theta()) {
            m.serialize_entry("min_theta", &min)?;
            m.serialize_entry("max_theta", &max)?;
        }
        for (name, pose) in [
            ("odometry", &scan.odometry),
            ("estimate", &scan.estimate),
            ("true_pose", &scan.true_pose),
        ] {
            if let Some(p) = pose {
                m.serialize_entry(name, &PoseOut(p))?;
            }
        }
        if let Some(t) = scan.timestamp {
            m.serialize_entry("timestamp", &[t.sec, t.usec])?;
        }
        if let Some(v) = &scan.readings_sigma {
            m.serialize_entry("readings_sigma", v)?;
        }
        if let Some(v) = &scan.hinge_offset {
            m.serialize_entry("hinge_offset", v)?;
        }
        if let Some(v) = &scan.hit {
            m.serialize_entry("hit", &Hits(v))?;
        }
        for (k, v) in &scan.extra {
            if !KNOWN_FIELDS.contains(&k.as_str()) {
                m.serialize_entry(k, v)?;
            }
        }
        m.end()
    }
}
