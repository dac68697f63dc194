//! Scan JSON Lines: one scan per line in CSM's laser_data layout (the paper's Fig. 13, the
//! contract's table).
//!
//! The parser is a hand-written serde visitor rather than a derive with `#[serde(flatten)]`:
//! flatten buffers every field into an intermediate map, which is several times slower, and the
//! visitor lets each error name its field and index (`readings[3]: ...`). Unknown fields are
//! kept, in order, in [`Scan::extra`], so CSM's own logs (`true_alpha`, `cov_alpha`, `cluster`,
//! ...) pass through untouched.

use super::{InputError, json_error_message, limits};
use crate::geometry::Pose;
use crate::scan::{Hit, Scan, Timestamp, even_bearings};
use rayon::prelude::*;
use serde::de::{self, Deserializer, MapAccess, SeqAccess, Visitor};
use serde::ser::{SerializeMap, SerializeSeq, Serializer};
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;
use std::fmt;
use std::io::{self, BufRead, Write};

/// Parses one line of scan JSON Lines into a [`Scan`]. The error is the message alone; the
/// readers add the file name and line number.
pub fn parse_scan_line(text: &str) -> Result<Scan, String> {
    parse_scan_line_with(text, false)
}

/// [`parse_scan_line`], skipping over the simulator's `hit` labels when `skip_hit` (they are
/// left out of the scan, unchecked): `level` never reads them (contract), and they are a
/// tenth of what a simulated line holds to parse.
fn parse_scan_line_with(text: &str, skip_hit: bool) -> Result<Scan, String> {
    let mut de = serde_json::Deserializer::from_str(text);
    let raw = de::DeserializeSeed::deserialize(RawScanVisitor { skip_hit }, &mut de)
        .and_then(|raw| de.end().map(|()| raw))
        .map_err(|e| json_error_message(&e))?;
    raw.into_scan()
}

fn is_blank(line: &str) -> bool {
    line.bytes().all(|b| b.is_ascii_whitespace())
}

/// Reads scan JSON Lines one line at a time: memory stays at one line whatever the file's
/// length. Yields `(line number, scan)` with 1-based line numbers; blank lines are skipped. After
/// the first error it yields nothing more, since the contract stops at the first bad line.
pub struct ScanReader<R> {
    reader: R,
    name: String,
    line: usize,
    buf: String,
    done: bool,
}

impl<R: BufRead> ScanReader<R> {
    /// `name` is the file's name as the user gave it (or `<stdin>`), for error messages.
    pub fn new(reader: R, name: impl Into<String>) -> Self {
        Self {
            reader,
            name: name.into(),
            line: 0,
            buf: String::new(),
            done: false,
        }
    }
}

impl<R: BufRead> Iterator for ScanReader<R> {
    type Item = Result<(usize, Scan), InputError>;

    fn next(&mut self) -> Option<Self::Item> {
        while !self.done {
            self.buf.clear();
            match limits::read_line_capped(&mut self.reader, &mut self.buf) {
                Ok(0) => self.done = true,
                Ok(_) => {
                    self.line += 1;
                    if is_blank(&self.buf) {
                        continue;
                    }
                    let parsed = parse_scan_line(&self.buf)
                        .map(|scan| (self.line, scan))
                        .map_err(|m| InputError::at_line(&self.name, self.line, m));
                    self.done = parsed.is_err();
                    return Some(parsed);
                }
                Err(e) => {
                    self.done = true;
                    return Some(Err(read_error(&self.name, self.line + 1, &e)));
                }
            }
        }
        None
    }
}

pub(crate) fn read_error(name: &str, line: usize, e: &io::Error) -> InputError {
    let what = if limits::is_line_too_long(e) {
        e.to_string()
    } else if e.kind() == io::ErrorKind::InvalidData {
        "is not valid UTF-8 text".to_string()
    } else {
        format!("cannot read: {e}")
    };
    InputError::at_line(name, line, what)
}

/// Lines per batch of [`ParallelScanReader`]; enough to keep every core busy.
const BATCH_LINES: usize = 1024;
/// Bytes per batch of [`ParallelScanReader`], so that memory stays bounded for long lines.
const BATCH_BYTES: usize = 8 << 20;

/// Like [`ScanReader`], but parses batches of lines in parallel (rayon) and yields them in input
/// order: for big files. While one batch is parsed the next is read, so decompression and I/O
/// overlap the parsing. Memory is bounded by two batches (each at most 1024 lines or about
/// 8 MB).
pub struct ParallelScanReader<R> {
    source: LineSource<R>,
    /// Read ahead, not parsed yet.
    next: Batch,
    /// The batch being parsed; its line buffers are reused.
    current: Batch,
    ready: VecDeque<Result<(usize, Scan), InputError>>,
    started: bool,
    done: bool,
    skip_hit: bool,
}

struct LineSource<R> {
    reader: R,
    name: String,
    line: usize,
}

/// Lines read in one go: (line number, text), of which the first `used` are this batch's.
#[derive(Default)]
struct Batch {
    lines: Vec<(usize, String)>,
    used: usize,
    /// The batch ended because the input did (end of file or a read error).
    last: bool,
    read_err: Option<InputError>,
}

impl<R: BufRead> LineSource<R> {
    /// Fills `batch` with the next non-blank lines.
    fn read_batch(&mut self, batch: &mut Batch) {
        batch.used = 0;
        batch.last = false;
        batch.read_err = None;
        let mut bytes = 0;
        while batch.used < BATCH_LINES && bytes < BATCH_BYTES {
            if batch.used == batch.lines.len() {
                batch.lines.push((0, String::new()));
            }
            let slot = &mut batch.lines[batch.used];
            slot.1.clear();
            match limits::read_line_capped(&mut self.reader, &mut slot.1) {
                Ok(0) => {
                    batch.last = true;
                    return;
                }
                Ok(n) => {
                    self.line += 1;
                    if is_blank(&slot.1) {
                        continue;
                    }
                    slot.0 = self.line;
                    bytes += n;
                    batch.used += 1;
                }
                Err(e) => {
                    batch.last = true;
                    batch.read_err = Some(read_error(&self.name, self.line + 1, &e));
                    return;
                }
            }
        }
    }
}

impl<R: BufRead + Send> ParallelScanReader<R> {
    /// `name` is the file's name as the user gave it (or `<stdin>`), for error messages.
    pub fn new(reader: R, name: impl Into<String>) -> Self {
        Self {
            source: LineSource {
                reader,
                name: name.into(),
                line: 0,
            },
            next: Batch::default(),
            current: Batch::default(),
            ready: VecDeque::new(),
            started: false,
            done: false,
            skip_hit: false,
        }
    }

    /// Skips over `hit` labels without reading them (see [`parse_scan_line`]); for `level`,
    /// which never reads them.
    pub fn skipping_hit(mut self) -> Self {
        self.skip_hit = true;
        self
    }

    /// Parses the read-ahead batch while reading the one after it.
    fn fill(&mut self) {
        if !self.started {
            self.source.read_batch(&mut self.next);
            self.started = true;
        }
        std::mem::swap(&mut self.current, &mut self.next);
        let current = &self.current;
        let name = self.source.name.clone();
        let (source, next) = (&mut self.source, &mut self.next);
        let skip_hit = self.skip_hit;
        let (parsed, ()) = rayon::join(
            || {
                current.lines[..current.used]
                    .par_iter()
                    .map(|(line, text)| {
                        parse_scan_line_with(text, skip_hit)
                            .map(|scan| (*line, scan))
                            .map_err(|m| InputError::at_line(&name, *line, m))
                    })
                    .collect::<Vec<_>>()
            },
            || {
                if !current.last {
                    source.read_batch(next);
                }
            },
        );
        for item in parsed {
            let bad = item.is_err();
            self.ready.push_back(item);
            if bad {
                self.done = true;
                return;
            }
        }
        if let Some(e) = self.current.read_err.take() {
            self.ready.push_back(Err(e));
        }
        self.done = self.current.last;
    }
}

impl<R: BufRead + Send> Iterator for ParallelScanReader<R> {
    type Item = Result<(usize, Scan), InputError>;

    fn next(&mut self) -> Option<Self::Item> {
        while self.ready.is_empty() && !self.done {
            self.fill();
        }
        self.ready.pop_front()
    }
}

// ---------------------------------------------------------------------------------------------
// Reading: a raw record as it is in the file, then validated into a `Scan`.

/// The fields as they were in the line, before the cross-field checks.
#[derive(Default)]
struct RawScan {
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
    fn into_scan(self) -> Result<Scan, String> {
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
const KNOWN_FIELDS: [&str; 16] = [
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

/// Prefixes an error from inside a field's value with the field's name: `readings[3]: ...`
/// for element errors (which start with `[i]`), `readings: ...` otherwise.
fn in_field<E: de::Error>(field: &str, e: E) -> E {
    let text = e.to_string();
    // serde_json has already placed the inner error; its position is added again outside.
    let text = match text.rfind(" at line ") {
        Some(i) => &text[..i],
        None => &text[..],
    };
    if text.starts_with('[') {
        E::custom(format!("{field}{text}"))
    } else {
        E::custom(format!("{field}: {text}"))
    }
}

impl<'de> Deserialize<'de> for RawScan {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_map(RawScanVisitor { skip_hit: false })
    }
}

struct RawScanVisitor {
    /// Skip over `hit` instead of reading it.
    skip_hit: bool,
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
                "nrays" => raw.nrays = map.next_value::<Opt<Count>>().map_err(wrap)?.get(),
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

/// Types that are read as a value of one JSON field.
trait Value: Sized {
    type Out;
    fn into_out(self) -> Self::Out;
}

/// A field or element that may be `null`.
struct Opt<T>(Option<T>);

impl<T: Value> Opt<T> {
    fn get(self) -> Option<T::Out> {
        self.0.map(Value::into_out)
    }
}

impl<T: Value> Value for Opt<T> {
    type Out = Option<T::Out>;
    fn into_out(self) -> Self::Out {
        self.get()
    }
}

impl<'de, T: Deserialize<'de>> Deserialize<'de> for Opt<T> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        Option::<T>::deserialize(d).map(Opt)
    }
}

/// A JSON number of any kind, as f64.
struct Num(f64);

impl Value for Num {
    type Out = f64;
    fn into_out(self) -> f64 {
        self.0
    }
}

struct NumVisitor;

impl Visitor<'_> for NumVisitor {
    type Value = f64;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a number")
    }
    fn visit_f64<E: de::Error>(self, v: f64) -> Result<f64, E> {
        Ok(v)
    }
    fn visit_u64<E: de::Error>(self, v: u64) -> Result<f64, E> {
        Ok(v as f64)
    }
    fn visit_i64<E: de::Error>(self, v: i64) -> Result<f64, E> {
        Ok(v as f64)
    }
}

impl<'de> Deserialize<'de> for Num {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_f64(NumVisitor).map(Num)
    }
}

/// An integer >= 0 (a float with no fraction is accepted: some writers emit `3.0`).
struct Count(u64);

impl Value for Count {
    type Out = u64;
    fn into_out(self) -> u64 {
        self.0
    }
}

impl<'de> Deserialize<'de> for Count {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl Visitor<'_> for V {
            type Value = u64;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("an integer >= 0")
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<u64, E> {
                Ok(v)
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> Result<u64, E> {
                u64::try_from(v).map_err(|_| E::custom(format!("must be an integer >= 0, not {v}")))
            }
            fn visit_f64<E: de::Error>(self, v: f64) -> Result<u64, E> {
                // 2^53: beyond it a float no longer says which integer it is.
                if v >= 0.0 && v.fract() == 0.0 && v <= 9_007_199_254_740_992.0 {
                    Ok(v as u64)
                } else {
                    Err(E::custom(format!("must be an integer >= 0, not {v}")))
                }
            }
        }
        d.deserialize_any(V).map(Count)
    }
}

/// A per-ray array; element errors say which index.
struct Array<T>(Vec<T>);

impl<T: Value> Value for Array<T> {
    type Out = Vec<T::Out>;
    fn into_out(self) -> Self::Out {
        self.0.into_iter().map(Value::into_out).collect()
    }
}

impl<'de, T: Deserialize<'de>> Deserialize<'de> for Array<T> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V<T>(std::marker::PhantomData<T>);
        impl<'de, T: Deserialize<'de>> Visitor<'de> for V<T> {
            type Value = Vec<T>;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("an array")
            }
            fn visit_seq<A: SeqAccess<'de>>(self, seq: A) -> Result<Vec<T>, A::Error> {
                let mut out = Vec::with_capacity(seq.size_hint().unwrap_or(256).min(1 << 16));
                each_element(seq, |v| out.push(v))?;
                Ok(out)
            }
        }
        d.deserialize_seq(V(std::marker::PhantomData)).map(Array)
    }
}

/// Reads every element of a JSON array as a `T`, handing each to `f`; an element's error
/// names its index (`[i]: ...`).
fn each_element<'de, A: SeqAccess<'de>, T: Deserialize<'de>>(
    mut seq: A,
    mut f: impl FnMut(T),
) -> Result<(), A::Error> {
    let mut i = 0;
    loop {
        match seq.next_element::<T>() {
            // Bounds the memory of one line whatever its length.
            Ok(Some(_)) if i == limits::MAX_RAYS => {
                return Err(de::Error::custom(format!(
                    "more than {} entries, the limit of rays per scan",
                    limits::MAX_RAYS
                )));
            }
            Ok(Some(v)) => f(v),
            Ok(None) => return Ok(()),
            Err(e) => return Err(in_field(&format!("[{i}]"), e)),
        }
        i += 1;
    }
}

/// A `valid` entry: 0 or 1 (booleans are accepted too).
struct Flag(bool);

impl Value for Flag {
    type Out = bool;
    fn into_out(self) -> bool {
        self.0
    }
}

impl<'de> Deserialize<'de> for Flag {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl Visitor<'_> for V {
            type Value = bool;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("0 or 1")
            }
            fn visit_bool<E: de::Error>(self, v: bool) -> Result<bool, E> {
                Ok(v)
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<bool, E> {
                match v {
                    0 => Ok(false),
                    1 => Ok(true),
                    _ => Err(E::custom(format!("must be 0 or 1, not {v}"))),
                }
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> Result<bool, E> {
                Err(E::custom(format!("must be 0 or 1, not {v}")))
            }
            fn visit_f64<E: de::Error>(self, v: f64) -> Result<bool, E> {
                match v {
                    0.0 => Ok(false),
                    1.0 => Ok(true),
                    _ => Err(E::custom(format!("must be 0 or 1, not {v}"))),
                }
            }
        }
        d.deserialize_any(V).map(Flag)
    }
}

/// A `hit` entry: 0 nothing, 1 wall, 2 floor, 3 ceiling.
struct HitCode(Hit);

impl Value for HitCode {
    type Out = Hit;
    fn into_out(self) -> Hit {
        self.0
    }
}

impl<'de> Deserialize<'de> for HitCode {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let Count(code) = Count::deserialize(d)?;
        Hit::from_code(code)
            .map(HitCode)
            .ok_or_else(|| de::Error::custom(format!("must be 0, 1, 2 or 3, not {code}")))
    }
}

/// A `hit` array checked entry by entry (as [`HitCode`]s) and counted, but not kept: `level`
/// never reads the labels, yet a bad one is still bad input.
struct HitLen(Option<usize>);

impl<'de> Deserialize<'de> for HitLen {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = HitLen;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("an array or null")
            }
            fn visit_unit<E: de::Error>(self) -> Result<HitLen, E> {
                Ok(HitLen(None))
            }
            fn visit_none<E: de::Error>(self) -> Result<HitLen, E> {
                Ok(HitLen(None))
            }
            fn visit_some<D: Deserializer<'de>>(self, d: D) -> Result<HitLen, D::Error> {
                d.deserialize_seq(V)
            }
            fn visit_seq<A: SeqAccess<'de>>(self, seq: A) -> Result<HitLen, A::Error> {
                let mut n = 0;
                each_element(seq, |_: HitCode| n += 1)?;
                Ok(HitLen(Some(n)))
            }
        }
        d.deserialize_option(V)
    }
}

/// A pose: 6 numbers `[x, y, z, rz, ry, rx]` or 3 `[x, y, rz]`; `null`, or any `null` entry,
/// means unknown (CSM writes `[null, null, null]`).
struct PoseField(Option<Pose>);

impl<'de> Deserialize<'de> for PoseField {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let Some(Array(v)) = Option::<Array<Opt<Num>>>::deserialize(d)? else {
            return Ok(PoseField(None));
        };
        if v.len() != 3 && v.len() != 6 {
            return Err(de::Error::custom(format!(
                "a pose has 6 numbers [x, y, z, rz, ry, rx] or 3 [x, y, rz], not {}",
                v.len()
            )));
        }
        let nums: Option<Vec<f64>> = v.into_iter().map(|o| o.0.map(|n| n.0)).collect();
        Ok(PoseField(nums.map(|n| match n[..] {
            [x, y, rz] => Pose::planar(x, y, rz),
            _ => Pose::new(n[0], n[1], n[2], n[3], n[4], n[5]),
        })))
    }
}

/// A timestamp `[sec, usec]` (CSM), or seconds as one number.
struct Stamp(Timestamp);

impl Value for Stamp {
    type Out = Timestamp;
    fn into_out(self) -> Timestamp {
        self.0
    }
}

impl<'de> Deserialize<'de> for Stamp {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = Timestamp;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("[sec, usec]")
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Timestamp, A::Error> {
                let whole = |v: f64| -> Result<i64, A::Error> {
                    if v.fract() == 0.0 && v.abs() < 9e15 {
                        Ok(v as i64)
                    } else {
                        Err(de::Error::custom(format!(
                            "timestamp must be [sec, usec] integers, not {v}"
                        )))
                    }
                };
                let sec = seq.next_element::<Num>()?;
                let usec = seq.next_element::<Num>()?;
                match (sec, usec, seq.next_element::<serde_json::Value>()?) {
                    (Some(Num(s)), Some(Num(u)), None) => Ok(Timestamp {
                        sec: whole(s)?,
                        usec: whole(u)?,
                    }),
                    _ => Err(de::Error::custom("must be [sec, usec]")),
                }
            }
            fn visit_f64<E: de::Error>(self, v: f64) -> Result<Timestamp, E> {
                limits::check_seconds("the time", v).map_err(E::custom)?;
                Ok(Timestamp::from_seconds(v))
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<Timestamp, E> {
                self.visit_f64(v as f64)
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> Result<Timestamp, E> {
                self.visit_f64(v as f64)
            }
        }
        d.deserialize_any(V).map(Stamp)
    }
}

/// `hinge_offset`: 3 numbers.
struct Offset([f64; 3]);

impl Value for Offset {
    type Out = [f64; 3];
    fn into_out(self) -> [f64; 3] {
        self.0
    }
}

impl<'de> Deserialize<'de> for Offset {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let Array(v) = Array::<Num>::deserialize(d)?;
        match v[..] {
            [Num(x), Num(y), Num(z)] => Ok(Offset([x, y, z])),
            _ => Err(de::Error::custom(format!(
                "must be 3 numbers [x, y, z], not {}",
                v.len()
            ))),
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Writing.

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

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::io::Cursor;

    /// A line as CSM's own tools write it: spaces, `null` readings and pose entries,
    /// `readings_sigma` with nulls, `true_alpha`, `cov_alpha`, `timestamp`, no `sequence`,
    /// no `elevation`.
    const CSM_LINE: &str = r#"{ "nrays": 5, "min_theta": -1.5, "max_theta": 1.5, "theta": [ -1.5, -0.75, 0, 0.75, 1.5 ], "readings": [ 2.5, null, 3.25, 4, 1e-1 ], "valid": [ 1, 0, 1, 1, 1 ], "readings_sigma": [ 0.01, null, 0.01, 0.01, 0.01 ], "true_alpha": [ null, null, null, null, null ], "cov_alpha": [ null, null, null, null, null ], "odometry": [ 1.5, -2, 0.25 ], "estimate": [ null, null, null ], "true_pose": [ 1.5, -2.0, 0.3 ], "timestamp": [ 1190823410, 123456 ] }"#;

    fn parse(text: &str) -> Scan {
        parse_scan_line(text).unwrap_or_else(|e| panic!("{e}"))
    }

    fn err(text: &str) -> String {
        parse_scan_line(text).unwrap_err()
    }

    #[test]
    fn csm_log_line_is_read_as_it_is() {
        let s = parse(CSM_LINE);
        assert_eq!(s.nrays(), 5);
        assert_eq!(s.sequence, None);
        assert_eq!(s.elevation, None);
        assert_eq!(s.theta[3], 0.75);
        assert_eq!(
            s.readings,
            vec![Some(2.5), None, Some(3.25), Some(4.0), Some(0.1)]
        );
        assert_eq!(s.valid, vec![true, false, true, true, true]);
        assert_eq!(s.odometry, Some(Pose::planar(1.5, -2.0, 0.25)));
        assert_eq!(s.estimate, None, "a pose with null entries is absent");
        assert_eq!(s.true_pose, Some(Pose::planar(1.5, -2.0, 0.3)));
        assert_eq!(
            s.timestamp,
            Some(Timestamp {
                sec: 1190823410,
                usec: 123456
            })
        );
        assert_eq!(
            s.readings_sigma,
            Some(vec![Some(0.01), None, Some(0.01), Some(0.01), Some(0.01)])
        );
        let extra: Vec<&str> = s.extra.keys().map(String::as_str).collect();
        assert_eq!(
            extra,
            ["true_alpha", "cov_alpha"],
            "unknown fields kept in order"
        );
        assert_eq!(s.extra["true_alpha"][0], serde_json::Value::Null);
    }

    #[test]
    fn csm_line_passes_through_with_unknown_fields() {
        let s = parse(CSM_LINE);
        let mut out = Vec::new();
        write_scan(&mut out, &s).unwrap();
        let text = String::from_utf8(out).unwrap();
        assert!(text.ends_with("}\n") && text.matches('\n').count() == 1);
        assert!(text.contains(r#""true_alpha":[null,null,null,null,null]"#));
        assert!(!text.contains("estimate"), "an unknown pose stays absent");
        assert_eq!(parse(&text), s);
    }

    #[test]
    fn six_number_poses_and_multi_elevation_fields() {
        let s = parse(
            r#"{"sequence": 7, "nrays": 2, "elevation": -0.0872, "theta": [0, 0.1], "readings": [1, 2],
                "true_pose": [1, 2, 0.45, 0.5, 0.1, -0.2], "hinge_offset": [0.05, 0, 0.1], "hit": [1, 2]}"#,
        );
        assert_eq!(s.sequence, Some(7));
        assert_eq!(s.elevation, Some(-0.0872));
        assert_eq!(s.true_pose, Some(Pose::new(1.0, 2.0, 0.45, 0.5, 0.1, -0.2)));
        assert_eq!(s.hinge_offset, Some([0.05, 0.0, 0.1]));
        assert_eq!(s.hit, Some(vec![Hit::Wall, Hit::Floor]));
        assert_eq!(
            s.valid,
            vec![true, true],
            "valid defaults to: reading is a number"
        );
    }

    /// `ray_elevation` (a nodding hinge's per-ray elevation) is read, written back in the
    /// same place and checked like the other per-ray fields.
    #[test]
    fn ray_elevation_round_trips_and_is_checked() {
        let line = r#"{"nrays": 3, "elevation": 0.1, "theta": [-1, 0, 1], "readings": [1, 2, 3], "ray_elevation": [0.05, 0.1, 0.15]}"#;
        let s = parse(line);
        assert_eq!(s.ray_elevation, Some(vec![0.05, 0.1, 0.15]));
        assert!(s.extra.is_empty(), "ray_elevation is a known field");
        let mut out = Vec::new();
        write_scan(&mut out, &s).unwrap();
        let text = String::from_utf8(out).unwrap();
        assert!(
            text.starts_with(
                r#"{"nrays":3,"elevation":0.1,"ray_elevation":[0.05,0.1,0.15],"theta""#
            ),
            "{text}"
        );
        assert_eq!(parse(&text), s);
        let without = parse(r#"{"nrays": 1, "theta": [0], "readings": [1]}"#);
        assert_eq!(without.ray_elevation, None);
        let mut out = Vec::new();
        write_scan(&mut out, &without).unwrap();
        assert!(!String::from_utf8(out).unwrap().contains("ray_elevation"));

        let base = r#""nrays": 2, "theta": [0, 1], "readings": [1, 2]"#;
        let bad = |field: &str| err(&format!("{{{base}, \"ray_elevation\": {field}}}"));
        assert_eq!(bad("[0.1]"), "ray_elevation has 1 entries but nrays is 2");
        assert_eq!(
            bad("[0.1, 0.2, 0.3]"),
            "ray_elevation has 3 entries but nrays is 2"
        );
        let e = bad("[0.1, 7]");
        assert!(e.starts_with("ray_elevation[1] is 7, not an angle"), "{e}");
        let e = bad("[0.1, -1e300]");
        assert!(
            e.starts_with("ray_elevation[1] is -1e300, not an angle"),
            "{e}"
        );
        let e = bad("[null, 0.2]");
        assert!(e.starts_with("ray_elevation[0]"), "{e}");
        let e = bad(r#"[0.1, "x"]"#);
        assert!(e.starts_with("ray_elevation[1]"), "{e}");
        assert_eq!(
            parse(&format!("{{{base}, \"ray_elevation\": null}}")).ray_elevation,
            None
        );
    }

    #[test]
    fn theta_absent_is_spread_from_min_to_max() {
        let s = parse(r#"{"nrays": 3, "min_theta": -1, "max_theta": 1, "readings": [1, null, 2]}"#);
        assert_eq!(s.theta, vec![-1.0, 0.0, 1.0]);
        assert_eq!(s.valid, vec![true, false, true]);
        assert_eq!(
            err(r#"{"nrays": 3, "readings": [1, null, 2]}"#),
            "theta is missing, and so are min_theta and max_theta"
        );
        assert_eq!(
            err(r#"{"nrays": 3, "min_theta": -1, "readings": [1, null, 2]}"#),
            "theta is missing, and so are min_theta and max_theta"
        );
    }

    #[test]
    fn arrays_of_the_wrong_length_name_the_field() {
        let theta: Vec<String> = (0..181).map(|i| format!("{}", i as f64 * 0.01)).collect();
        let readings: Vec<&str> = vec!["1.0"; 180];
        let line = format!(
            r#"{{"nrays": 181, "theta": [{}], "readings": [{}]}}"#,
            theta.join(","),
            readings.join(",")
        );
        assert_eq!(err(&line), "readings has 180 entries but nrays is 181");
        assert_eq!(
            err(r#"{"nrays": 2, "theta": [0, 1], "readings": [1, 2], "valid": [1]}"#),
            "valid has 1 entries but nrays is 2"
        );
        assert_eq!(
            err(r#"{"nrays": 2, "theta": [0], "readings": [1, 2]}"#),
            "theta has 1 entries but nrays is 2"
        );
        assert_eq!(
            err(r#"{"nrays": 2, "theta": [0, 1], "readings": [1, 2], "hit": [1, 1, 1]}"#),
            "hit has 3 entries but nrays is 2"
        );
        assert_eq!(
            err(r#"{"nrays": 2, "theta": [0, 1], "readings": [1, 2], "readings_sigma": []}"#),
            "readings_sigma has 0 entries but nrays is 2"
        );
    }

    #[test]
    fn non_positive_or_fractional_nrays_is_rejected() {
        assert_eq!(
            err(r#"{"nrays": 0, "theta": [], "readings": []}"#),
            "nrays must be > 0"
        );
        assert!(
            err(r#"{"nrays": -3, "theta": [], "readings": []}"#)
                .starts_with("nrays: must be an integer >= 0, not -3")
        );
        assert!(
            err(r#"{"nrays": 2.5, "theta": [0, 1], "readings": [1, 2]}"#)
                .starts_with("nrays: must be an integer >= 0, not 2.5")
        );
        assert!(
            err(r#"{"nrays": "2", "theta": [0, 1], "readings": [1, 2]}"#)
                .starts_with("nrays: invalid type: string \"2\", expected an integer >= 0")
        );
    }

    #[test]
    fn wrong_types_name_the_field_and_index() {
        let e = err(r#"{"nrays": 3, "theta": [0, 1, 2], "readings": [1, "far", 2]}"#);
        assert!(
            e.starts_with("readings[1]: invalid type: string \"far\", expected a number"),
            "{e}"
        );
        assert!(e.contains("(column "), "{e}");
        let e = err(r#"{"nrays": 3, "theta": [0, null, 2], "readings": [1, 1, 2]}"#);
        assert!(
            e.starts_with("theta[1]: invalid type: null, expected a number"),
            "{e}"
        );
        let e = err(r#"{"nrays": 2, "theta": [0, 1], "readings": [1, 2], "valid": [1, 2]}"#);
        assert!(e.starts_with("valid[1]: must be 0 or 1, not 2"), "{e}");
        let e = err(r#"{"nrays": 2, "theta": [0, 1], "readings": [1, 2], "hit": [0, 4]}"#);
        assert!(e.starts_with("hit[1]: must be 0, 1, 2 or 3, not 4"), "{e}");
        let e = err(r#"{"sequence": -1, "nrays": 1, "theta": [0], "readings": [1]}"#);
        assert!(
            e.starts_with("sequence: must be an integer >= 0, not -1"),
            "{e}"
        );
        let e = err(r#"{"nrays": 1, "theta": [0], "readings": [1], "odometry": [1, 2]}"#);
        assert!(e.starts_with("odometry: a pose has 6 numbers"), "{e}");
        let e = err(r#"{"nrays": 1, "theta": [0], "readings": [1], "elevation": "0.1"}"#);
        assert!(e.starts_with("elevation: invalid type: string"), "{e}");
        let e = err(r#"{"nrays": 1, "theta": [0], "readings": 5}"#);
        assert!(
            e.starts_with("readings: invalid type: integer `5`, expected an array"),
            "{e}"
        );
        let e = err(r#"{"nrays": 1, "theta": [0], "readings": [1], "hinge_offset": [1, 2]}"#);
        assert!(e.starts_with("hinge_offset: must be 3 numbers"), "{e}");
        let e = err(r#"{"nrays": 1, "theta": [0], "readings": [1], "timestamp": [1, 2, 3]}"#);
        assert!(e.starts_with("timestamp: must be [sec, usec]"), "{e}");
    }

    #[test]
    fn malformed_json_and_duplicates_are_errors() {
        assert!(
            err(r#"{"nrays": 1, "theta": [0], "readings": [1]"#).starts_with("EOF while parsing")
        );
        assert!(err(r#"{"nrays": 1 "theta": [0]}"#).starts_with("expected `,` or `}`"));
        assert!(err("[1, 2]").starts_with("invalid type: sequence, expected a scan object"));
        assert!(
            err(r#"{"nrays": 1, "theta": [0], "readings": [1]} {}"#)
                .starts_with("trailing characters")
        );
        assert!(
            err(r#"{"nrays": 1, "nrays": 1, "theta": [0], "readings": [1]}"#)
                .starts_with("duplicate field `nrays`")
        );
        assert!(err(r#"{"nrays": 1, "theta": [0]}"#).starts_with("missing field `readings`"));
    }

    #[test]
    fn null_optional_fields_count_as_absent() {
        let s = parse(
            r#"{"sequence": null, "nrays": 1, "elevation": null, "theta": [0], "readings": [1],
                "odometry": null, "readings_sigma": null, "timestamp": null}"#,
        );
        assert_eq!(s.sequence, None);
        assert_eq!(s.elevation, None);
        assert_eq!(s.odometry, None);
        assert_eq!(s.readings_sigma, None);
    }

    fn reader_lines(input: &str) -> Vec<Result<(usize, Scan), InputError>> {
        ScanReader::new(Cursor::new(input.as_bytes()), "scans.jsonl").collect()
    }

    #[test]
    fn reader_skips_blank_lines_and_reports_file_and_line() {
        let good = r#"{"sequence": 0, "nrays": 1, "theta": [0], "readings": [1]}"#;
        let input = format!(
            "{good}\n\n   \n{good}\r\n{{\"nrays\": 0, \"theta\": [], \"readings\": []}}\n{good}\n"
        );
        let items = reader_lines(&input);
        assert_eq!(items.len(), 3, "stops after the first error");
        assert_eq!(items[0].as_ref().unwrap().0, 1);
        assert_eq!(items[1].as_ref().unwrap().0, 4);
        assert_eq!(
            items[2].as_ref().unwrap_err().to_string(),
            "scans.jsonl:5: nrays must be > 0"
        );
    }

    #[test]
    fn reader_reports_invalid_utf8_with_its_line() {
        let good = r#"{"nrays": 1, "theta": [0], "readings": [1]}"#;
        let mut bytes = format!("{good}\n").into_bytes();
        bytes.extend_from_slice(b"{\"nrays\": \xff}\n");
        let items: Vec<_> = ScanReader::new(Cursor::new(bytes), "x.jsonl").collect();
        assert_eq!(items.len(), 2);
        assert_eq!(
            items[1].as_ref().unwrap_err().to_string(),
            "x.jsonl:2: is not valid UTF-8 text"
        );
    }

    fn scan_text(n: usize) -> String {
        let mut text = String::new();
        for k in 0..n {
            let mut s = Scan::with_even_bearings(3, -1.0, 1.0);
            s.sequence = Some(k as u64 / 3);
            s.readings = vec![Some(k as f64), None, Some(0.5)];
            s.valid = vec![true, false, true];
            let mut line = Vec::new();
            write_scan(&mut line, &s).unwrap();
            text.push_str(std::str::from_utf8(&line).unwrap());
            if k % 7 == 0 {
                text.push('\n'); // blank lines shift the numbering
            }
        }
        text
    }

    #[test]
    fn parallel_reader_matches_the_streaming_reader() {
        let text = scan_text(2500); // more than two batches
        let serial: Vec<_> = ScanReader::new(Cursor::new(text.as_bytes()), "a").collect();
        let parallel: Vec<_> = ParallelScanReader::new(Cursor::new(text.as_bytes()), "a").collect();
        assert_eq!(serial.len(), 2500);
        assert_eq!(serial, parallel);
    }

    #[test]
    fn parallel_reader_stops_at_the_first_error_in_order() {
        let mut text = scan_text(1500);
        // Corrupt the line of scan 1200 and a later one: only the first is reported.
        let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
        let serial: Vec<_> = ScanReader::new(Cursor::new(text.as_bytes()), "a").collect();
        let (bad_line, _) = *serial[1200].as_ref().unwrap();
        lines[bad_line - 1] = r#"{"nrays": 1, "theta": [0], "readings": [1, 2]}"#.into();
        let (later, _) = *serial[1400].as_ref().unwrap();
        lines[later - 1] = "garbage".into();
        text = lines.join("\n");
        let items: Vec<_> = ParallelScanReader::new(Cursor::new(text.as_bytes()), "f").collect();
        assert_eq!(items.len(), 1201);
        assert!(items[..1200].iter().all(Result::is_ok));
        assert_eq!(
            items[1200].as_ref().unwrap_err().to_string(),
            format!("f:{bad_line}: readings has 2 entries but nrays is 1")
        );
    }

    #[test]
    fn written_fields_come_in_the_stable_order() {
        let mut s = Scan::with_even_bearings(2, -0.5, 0.5);
        s.readings = vec![Some(1.0), None];
        s.valid = vec![true, false];
        s.sequence = Some(3);
        s.elevation = Some(0.1);
        s.odometry = Some(Pose::planar(1.0, 2.0, 0.5));
        s.true_pose = Some(Pose::new(1.0, 2.0, 0.45, 0.5, 0.1, 0.0));
        s.hit = Some(vec![Hit::Wall, Hit::Nothing]);
        s.extra.insert("zeta".into(), serde_json::json!(1));
        s.extra.insert("alpha".into(), serde_json::json!("a"));
        let mut out = Vec::new();
        write_scan(&mut out, &s).unwrap();
        assert_eq!(
            String::from_utf8(out).unwrap(),
            "{\"sequence\":3,\"nrays\":2,\"elevation\":0.1,\"theta\":[-0.5,0.5],\
             \"readings\":[1.0,null],\"valid\":[1,0],\"min_theta\":-0.5,\"max_theta\":0.5,\
             \"odometry\":[1.0,2.0,0.5],\"true_pose\":[1.0,2.0,0.45,0.5,0.1,0.0],\
             \"hit\":[1,0],\"zeta\":1,\"alpha\":\"a\"}\n"
        );
    }

    fn arb_f64() -> impl Strategy<Value = f64> {
        prop_oneof![
            -1e6f64..1e6,
            any::<f64>().prop_filter("finite", |v| v.is_finite()),
            Just(0.0),
            Just(-0.0),
        ]
    }

    /// Bearings and elevations: within one turn (`limits::MAX_ANGLE`).
    fn arb_angle() -> impl Strategy<Value = f64> {
        let max = limits::MAX_ANGLE;
        prop_oneof![-max..=max, Just(0.0), Just(-0.0), Just(max), Just(-max)]
    }

    /// Positions: within `limits::MAX_POSITION`.
    fn arb_position() -> impl Strategy<Value = f64> {
        let max = limits::MAX_POSITION;
        prop_oneof![-1e3f64..1e3, -max..=max, Just(0.0), Just(-0.0), Just(max)]
    }

    /// Noise sigmas: any finite number >= 0.
    fn arb_sigma() -> impl Strategy<Value = f64> {
        arb_f64().prop_map(f64::abs)
    }

    fn arb_pose() -> impl Strategy<Value = Option<Pose>> {
        let xyz = || (arb_position(), arb_position(), arb_position());
        prop_oneof![
            Just(None),
            (arb_position(), arb_position(), arb_f64())
                .prop_map(|(x, y, t)| Some(Pose::planar(x, y, t))),
            (xyz(), (arb_f64(), arb_f64(), arb_f64()))
                .prop_map(|((x, y, z), (rz, ry, rx))| Some(Pose::new(x, y, z, rz, ry, rx))),
        ]
    }

    fn arb_scan() -> impl Strategy<Value = Scan> {
        (1usize..40).prop_flat_map(|n| {
            (
                (
                    prop::option::of(any::<u64>()),
                    prop::option::of(arb_angle()),
                    prop::collection::vec(arb_angle(), n),
                    prop::collection::vec(prop::option::of(arb_f64()), n),
                    prop::collection::vec(any::<bool>(), n),
                ),
                (arb_pose(), arb_pose(), arb_pose()),
                (
                    prop::option::of((any::<i32>(), 0i64..1_000_000)),
                    prop::option::of(prop::collection::vec(prop::option::of(arb_sigma()), n)),
                    prop::option::of(prop::array::uniform3(arb_position())),
                    prop::option::of(prop::collection::vec(0u64..4, n)),
                    prop::collection::vec(("[a-z_]{1,8}", any::<i32>()), 0..3),
                ),
                prop::option::of(prop::collection::vec(arb_angle(), n)),
            )
                .prop_map(
                    |(
                        (sequence, elevation, theta, readings, valid),
                        (odometry, estimate, true_pose),
                        (stamp, sigma, hinge_offset, hit, extra),
                        ray_elevation,
                    )| Scan {
                        sequence,
                        elevation,
                        ray_elevation,
                        theta,
                        readings,
                        valid,
                        odometry,
                        estimate,
                        true_pose,
                        timestamp: stamp.map(|(s, u)| Timestamp {
                            sec: s as i64,
                            usec: u,
                        }),
                        readings_sigma: sigma,
                        hinge_offset,
                        hit: hit.map(|h| h.into_iter().filter_map(Hit::from_code).collect()),
                        extra: extra
                            .into_iter()
                            .filter(|(k, _)| !KNOWN_FIELDS.contains(&k.as_str()))
                            .map(|(k, v)| (k, serde_json::json!(v)))
                            .collect(),
                    },
                )
        })
    }

    proptest! {
        #[test]
        fn write_then_read_returns_the_same_scans(scans in prop::collection::vec(arb_scan(), 1..5)) {
            let mut out = Vec::new();
            for s in &scans {
                write_scan(&mut out, s).unwrap();
            }
            let back: Vec<Scan> = ScanReader::new(Cursor::new(&out), "rt")
                .map(|r| r.map(|(_, s)| s))
                .collect::<Result<_, _>>()
                .unwrap();
            prop_assert_eq!(back, scans);
        }

        /// CSM's tools write spaces everywhere and their own field order: the same scan laid
        /// out that way (pretty-printed onto one line, fields in reverse order) reads the same.
        #[test]
        fn spacing_and_field_order_do_not_matter(scan in arb_scan()) {
            let mut out = Vec::new();
            write_scan(&mut out, &scan).unwrap();
            let value: serde_json::Value = serde_json::from_slice(&out).unwrap();
            let serde_json::Value::Object(map) = value else { unreachable!() };
            let reversed: serde_json::Map<String, serde_json::Value> =
                map.into_iter().rev().collect();
            let text = serde_json::to_string_pretty(&reversed).unwrap().replace('\n', " ");
            let mut back = parse_scan_line(&text).unwrap();
            // Unknown fields keep the order they had in the line, now reversed.
            let extra: Vec<_> = back.extra.clone().into_iter().rev().collect();
            back.extra = extra.into_iter().collect();
            prop_assert_eq!(back, scan);
        }
    }

    /// `level`'s reader checks and counts `hit` but does not keep it (never read by `level`),
    /// and reads everything else as the plain parser does; bad labels are still errors.
    #[test]
    fn skipping_hit_leaves_the_rest_alone() {
        let line = r#"{"sequence": 4, "elevation": 0.1, "theta": [0, 1], "readings": [2, null], "hit": [1, 0], "extra": [1]}"#;
        let skipped = parse_scan_line_with(line, true).unwrap();
        let mut plain = parse(&line.replace(r#""hit": [1, 0], "#, ""));
        assert_eq!(skipped, plain);
        plain.hit = Some(vec![Hit::Wall, Hit::Nothing]);
        assert_ne!(skipped, plain);
        let bad_code = line.replace("[1, 0]", "[1, 9]");
        assert!(
            parse_scan_line_with(&bad_code, true)
                .unwrap_err()
                .contains("hit[1]")
        );
        let short = line.replace("[1, 0]", "[1]");
        assert!(
            parse_scan_line_with(&short, true)
                .unwrap_err()
                .contains("hit has 1 entries but nrays is 2")
        );
        let twice = r#"{"theta": [0], "readings": [2], "hit": [1], "hit": [1]}"#;
        assert!(
            parse_scan_line_with(twice, true)
                .unwrap_err()
                .contains("duplicate field `hit`")
        );
    }

    #[test]
    fn parallel_reader_skipping_hit_reads_the_same_scans_without_hits() {
        let lines = "{\"sequence\": 1, \"elevation\": 0, \"theta\": [0], \"readings\": [2], \"hit\": [1]}\n\n{\"sequence\": 2, \"elevation\": 0.1, \"theta\": [0], \"readings\": [3], \"hit\": [0]}\n";
        let plain: Vec<(usize, Scan)> = ParallelScanReader::new(Cursor::new(lines), "p")
            .collect::<Result<_, _>>()
            .unwrap();
        let skipped: Vec<(usize, Scan)> = ParallelScanReader::new(Cursor::new(lines), "p")
            .skipping_hit()
            .collect::<Result<_, _>>()
            .unwrap();
        assert_eq!(plain.len(), 2);
        assert_eq!(plain[1].0, 3);
        for ((la, a), (lb, b)) in plain.iter().zip(&skipped) {
            assert_eq!(la, lb);
            assert!(a.hit.is_some() && b.hit.is_none());
            assert_eq!(
                Scan {
                    hit: None,
                    ..a.clone()
                },
                *b
            );
        }
    }
}
