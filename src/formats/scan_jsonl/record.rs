//! One line's record: its fields as they are in the file ([`RawScan`], read by a hand-written
//! visitor that names the field of every error), then the cross-field checks that make it a
//! [`Scan`].

use super::fields::{
    Array, Count, Flag, HitCode, HitLen, Num, Offset, Opt, PoseField, RayCount, Stamp, in_field,
};
use crate::formats::limits;
use crate::geometry::Pose;
use crate::scan::{Hit, Scan, Timestamp, even_bearings};
use serde::Deserialize;
use serde::de::{self, Deserializer, MapAccess, Visitor};
use std::fmt;

/// The fields as they were in the line, before the cross-field checks.
#[derive(Default)]
pub(super) struct RawScan {
    sequence: Option<u64>,
    nrays: Option<u64>,
    elevation: Option<f64>,
    ray_elevation: Option<Vec<f64>>,
    theta: Option<Vec<f64>>,
    readings: Option<Vec<Option<f64>>>,
    valid: Option<Vec<bool>>,
    min_theta: Option<f64>,
    max_theta: Option<f64>,
    odometry: Option<Pose>,
    estimate: Option<Pose>,
    true_pose: Option<Pose>,
    timestamp: Option<Timestamp>,
    readings_sigma: Option<Vec<Option<f64>>>,
    hinge_offset: Option<[f64; 3]>,
    hit: Option<Vec<Hit>>,
    /// Entries of a `hit` that was checked but not kept.
    hit_len: Option<usize>,
    extra: serde_json::Map<String, serde_json::Value>,
}

impl RawScan {
    pub(super) fn into_scan(self) -> Result<Scan, String> {
        let readings = self
            .readings
            .ok_or_else(|| "missing field `readings`".to_string())?;
        let nrays = match self.nrays {
            Some(n) => usize::try_from(n).map_err(|_| format!("nrays {n} is too large"))?,
            // Tolerate hand-written scans without `nrays`: the readings say how many rays.
            None => readings.len(),
        };
        limits::check_rays("nrays", nrays)?;
        let check_len = |field: &str, len: usize| {
            if len == nrays {
                Ok(())
            } else {
                Err(format!("{field} has {len} entries but nrays is {nrays}"))
            }
        };
        check_len("readings", readings.len())?;
        for (field, v) in [("min_theta", self.min_theta), ("max_theta", self.max_theta)] {
            v.map_or(Ok(()), |v| limits::check_angle(field, v))?;
        }
        let theta = match (self.theta, self.min_theta, self.max_theta) {
            (Some(t), _, _) => {
                check_len("theta", t.len())?;
                t
            }
            (None, Some(min), Some(max)) => even_bearings(nrays, min, max),
            (None, _, _) => {
                return Err("theta is missing, and so are min_theta and max_theta".to_string());
            }
        };
        let valid = match self.valid {
            Some(v) => {
                check_len("valid", v.len())?;
                v
            }
            None => readings.iter().map(Option::is_some).collect(),
        };
        if let Some(s) = &self.readings_sigma {
            check_len("readings_sigma", s.len())?;
        }
        if let Some(e) = &self.ray_elevation {
            check_len("ray_elevation", e.len())?;
        }
        if let Some(n) = self.hit.as_ref().map(Vec::len).or(self.hit_len) {
            check_len("hit", n)?;
        }
        let scan = Scan {
            sequence: self.sequence,
            elevation: self.elevation,
            ray_elevation: self.ray_elevation,
            theta,
            readings,
            valid,
            odometry: self.odometry,
            estimate: self.estimate,
            true_pose: self.true_pose,
            timestamp: self.timestamp,
            readings_sigma: self.readings_sigma,
            hinge_offset: self.hinge_offset,
            hit: self.hit,
            extra: self.extra,
        };
        limits::check_scan(&scan)?;
        Ok(scan)
    }
}

/// The fields this crate knows, in the order [`write_scan`] writes them.
pub(super) const KNOWN_FIELDS: [&str; 16] = [
    "sequence",
    "nrays",
    "elevation",
    "ray_elevation",
    "theta",
    "readings",
    "valid",
    "min_theta",
    "max_theta",
    "odometry",
    "estimate",
    "true_pose",
    "timestamp",
    "readings_sigma",
    "hinge_offset",
    "hit",
];

enum Key {
    Known(usize),
    Other(String),
}

impl<'de> Deserialize<'de> for Key {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct KeyVisitor;
        impl Visitor<'_> for KeyVisitor {
            type Value = Key;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a field name")
            }
            fn visit_str<E: de::Error>(self, v: &str) -> Result<Key, E> {
                Ok(match KNOWN_FIELDS.iter().position(|k| *k == v) {
                    Some(i) => Key::Known(i),
                    None => Key::Other(v.to_string()),
                })
            }
        }
        d.deserialize_identifier(KeyVisitor)
    }
}

impl<'de> Deserialize<'de> for RawScan {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_map(RawScanVisitor { skip_hit: false })
    }
}

pub(super) struct RawScanVisitor {
    /// Skip over `hit` instead of reading it.
    pub(super) skip_hit: bool,
}

impl<'de> de::DeserializeSeed<'de> for RawScanVisitor {
    type Value = RawScan;

    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<RawScan, D::Error> {
        d.deserialize_map(self)
    }
}

impl<'de> Visitor<'de> for RawScanVisitor {
    type Value = RawScan;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a scan object")
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<RawScan, A::Error> {
        let mut raw = RawScan::default();
        let mut seen = [false; KNOWN_FIELDS.len()];
        while let Some(key) = map.next_key::<Key>()? {
            let i = match key {
                Key::Known(i) => i,
                Key::Other(name) => {
                    let value: serde_json::Value = map.next_value()?;
                    if raw.extra.insert(name.clone(), value).is_some() {
                        return Err(de::Error::custom(format!("duplicate field `{name}`")));
                    }
                    continue;
                }
            };
            let field = KNOWN_FIELDS[i];
            if std::mem::replace(&mut seen[i], true) {
                return Err(de::Error::custom(format!("duplicate field `{field}`")));
            }
            let wrap = |e| in_field(field, e);
            match field {
                "sequence" => raw.sequence = map.next_value::<Opt<Count>>().map_err(wrap)?.get(),
                "nrays" => raw.nrays = map.next_value::<Opt<RayCount>>().map_err(wrap)?.get(),
                "elevation" => raw.elevation = map.next_value::<Opt<Num>>().map_err(wrap)?.get(),
                "ray_elevation" => {
                    raw.ray_elevation = map.next_value::<Opt<Array<Num>>>().map_err(wrap)?.get()
                }
                "min_theta" => raw.min_theta = map.next_value::<Opt<Num>>().map_err(wrap)?.get(),
                "max_theta" => raw.max_theta = map.next_value::<Opt<Num>>().map_err(wrap)?.get(),
                "theta" => raw.theta = map.next_value::<Opt<Array<Num>>>().map_err(wrap)?.get(),
                "readings" => {
                    raw.readings = map
                        .next_value::<Opt<Array<Opt<Num>>>>()
                        .map_err(wrap)?
                        .get()
                }
                "readings_sigma" => {
                    raw.readings_sigma = map
                        .next_value::<Opt<Array<Opt<Num>>>>()
                        .map_err(wrap)?
                        .get()
                }
                "valid" => raw.valid = map.next_value::<Opt<Array<Flag>>>().map_err(wrap)?.get(),
                "hit" if self.skip_hit => raw.hit_len = map.next_value::<HitLen>().map_err(wrap)?.0,
                "hit" => raw.hit = map.next_value::<Opt<Array<HitCode>>>().map_err(wrap)?.get(),
                "odometry" => raw.odometry = map.next_value::<PoseField>().map_err(wrap)?.0,
                "estimate" => raw.estimate = map.next_value::<PoseField>().map_err(wrap)?.0,
                "true_pose" => raw.true_pose = map.next_value::<PoseField>().map_err(wrap)?.0,
                "timestamp" => raw.timestamp = map.next_value::<Opt<Stamp>>().map_err(wrap)?.get(),
                "hinge_offset" => {
                    raw.hinge_offset = map.next_value::<Opt<Offset>>().map_err(wrap)?.get()
                }
                _ => unreachable!("every known field has an arm"),
            }
        }
        Ok(raw)
    }
}
