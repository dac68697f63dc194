//! CARMEN logs (the text format of the CARMEN robot toolkit, used by the Radish datasets):
//! `FLASER` and `ROBOTLASER1` lines become [`Scan`]s; every other line (`ODOM`, `PARAM`,
//! `NEFF`, `RLASER`, `#` comments, ...) is skipped. A log that gives no scans but skipped laser
//! lines of other kinds (`RAWLASER1`, `ROBOTLASER2`, ...) ends with an error saying so.
//!
//! - `FLASER n r1 .. rn x y theta odom_x odom_y odom_theta timestamp [host logger_timestamp]`:
//!   the beams spread evenly over 180 degrees from -90 degrees, one degree apart for 180 or 181
//!   beams, half a degree for 360 or 361 (the step is `pi / (n - 1)` for odd `n`, `pi / n` for
//!   even `n`, as CARMEN's own tools and GMapping read them). `odometry` is the odom fields.
//!   The first pose (`x y theta`) is the laser's pose as the log has it; in the corrected logs
//!   of the Radish datasets that is the SLAM-corrected trajectory, so it is kept as
//!   `true_pose`: a reference trajectory, good to centimetres, not exact ground truth.
//! - `ROBOTLASER1 laser_type start_angle fov angular_res max_range accuracy remission_mode
//!   n r1 .. rn m e1 .. em laser_x laser_y laser_theta robot_x robot_y robot_theta tv rv
//!   forward_safety side_safety turn_axis timestamp [host logger_timestamp]`: bearings from
//!   `start_angle` in steps of `angular_res`; `odometry` is the laser's pose (the scan's own
//!   origin, which is what a matcher aligns); the robot's pose is kept as the extra field
//!   `robot_pose`.
//!
//! A range is invalid (no return) when it is <= 0 or >= the maximum range: the message's own
//! for `ROBOTLASER1`; for `FLASER` the reader's [`CarmenParams::max_range`], else the log's
//! `PARAM robot_front_laser_max`, else [`DEFAULT_FLASER_MAX_RANGE`].

use super::{InputError, limits};
use crate::geometry::Pose;
use crate::scan::{Scan, Timestamp};
use std::f64::consts::PI;
use std::io::BufRead;

/// Maximum range of `FLASER` scans when neither the caller nor the log says \[m\]. SICK scanners
/// of that era report no return as 50 m or as error codes at 81.83-81.91 m, and real logs
/// (e.g. ACES) have no `PARAM` saying so: 50 m treats all of those as invalid.
pub const DEFAULT_FLASER_MAX_RANGE: f64 = 50.0;

/// Options of the CARMEN reader.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CarmenParams {
    /// Maximum range of `FLASER` scans \[m\]; readings at or beyond it are invalid. Default: the
    /// log's `PARAM robot_front_laser_max`, else [`DEFAULT_FLASER_MAX_RANGE`] (50 m).
    pub max_range: Option<f64>,
}

/// Bearings of an `n`-beam `FLASER` scan \[rad\], from -90 degrees.
pub fn flaser_bearings(n: usize) -> Vec<f64> {
    let step = if n % 2 == 1 {
        PI / (n.max(2) - 1) as f64
    } else {
        PI / n as f64
    };
    (0..n).map(|i| -PI / 2.0 + step * i as f64).collect()
}

/// Fields of one line, with the helpers that read them and say what is wrong.
struct Fields<'a> {
    kind: &'a str,
    items: Vec<&'a str>,
    /// Each item read as a number, once (`None`: not one).
    values: Vec<Option<f64>>,
}

impl<'a> Fields<'a> {
    fn new(kind: &'a str, items: Vec<&'a str>) -> Self {
        let values = items.iter().map(|t| t.parse::<f64>().ok()).collect();
        Fields {
            kind,
            items,
            values,
        }
    }

    fn number(&self, i: usize, what: &str) -> Result<f64, String> {
        self.number_with(i, || what.to_string())
    }

    /// [`Fields::number`] naming the field only when it is wrong.
    fn number_with(&self, i: usize, what: impl Fn() -> String) -> Result<f64, String> {
        match self.values.get(i) {
            Some(Some(v)) if v.is_finite() => Ok(*v),
            Some(_) => Err(format!(
                "{}: {} (field {}) is not a number: `{}`",
                self.kind,
                what(),
                i + 1,
                self.items[i]
            )),
            None => Err(format!(
                "{}: the line ends before {} (field {})",
                self.kind,
                what(),
                i + 1
            )),
        }
    }

    fn count(&self, i: usize, what: &str) -> Result<usize, String> {
        let v = self.number(i, what)?;
        if v >= 0.0 && v.fract() == 0.0 && v < 1e7 {
            Ok(v as usize)
        } else {
            Err(format!(
                "{}: {what} (field {}) must be a whole number >= 0, not {v}",
                self.kind,
                i + 1
            ))
        }
    }

    /// The numbers `names` name, from field `at` on.
    fn numbers(&self, at: usize, names: &[&str]) -> Result<Vec<f64>, String> {
        (0..names.len())
            .map(|k| self.number(at + k, names[k]))
            .collect()
    }

    /// The count of rays at field `i`: at least one, at most [`limits::MAX_RAYS`].
    fn rays(&self, i: usize, what: &str) -> Result<usize, String> {
        let n = self.count(i, what)?;
        limits::check_rays(what, n).map_err(|m| format!("{}: {m}", self.kind))?;
        Ok(n)
    }

    /// How many numbers the line has, when they would disagree with `expected`, the count
    /// its counts of readings give: a wrong count would take range values for the pose. Only
    /// for lines shaped right (numbers, then nothing or `host logger_timestamp`); a line of
    /// too few numbers and no host may be cut short instead, and the field it ends before is
    /// the better message.
    fn miscounted(&self, expected: usize) -> Option<usize> {
        let k = self.values.iter().take_while(|v| v.is_some()).count();
        let host = self.items.len() == k + 2 && self.values[k + 1].is_some();
        let tail = &self.items[k..];
        ((host && k != expected) || (tail.is_empty() && k > expected)).then_some(k)
    }

    /// After the last field (index `end`), only `host logger_timestamp` may follow.
    fn check_end(&self, end: usize) -> Result<(), String> {
        let values = &self.values[end.min(self.values.len())..];
        match &self.items[end.min(self.items.len())..] {
            [] => Ok(()),
            [_, _] if values[0].is_none() && values[1].is_some_and(f64::is_finite) => Ok(()),
            rest => Err(format!(
                "{}: {} more field(s) after the timestamp (field {end}), from `{}`; the line \
                 must end with the timestamp, or with `host logger_timestamp`",
                self.kind,
                rest.len(),
                rest[0].chars().take(20).collect::<String>()
            )),
        }
    }
}

fn set_ranges(scan: &mut Scan, ranges: &[f64], max_range: f64) {
    for (i, &r) in ranges.iter().enumerate() {
        if r > 0.0 && r < max_range {
            scan.readings[i] = Some(r);
            scan.valid[i] = true;
        }
    }
}

/// A CARMEN message name: capitals, digits and underscores, starting with a capital
/// (`ODOM`, `PARAM`, `ROBOTLASER1`, `NEFF`, ...).
fn is_message_name(w: &str) -> bool {
    w.starts_with(|c: char| c.is_ascii_uppercase())
        && w.chars()
            .all(|c| c.is_ascii_uppercase() || c.is_ascii_digit() || c == '_')
}

/// Parses one line. `Ok(None)` for lines that are not scans. `flaser_max_range` is the
/// maximum range for `FLASER` lines \[m\].
pub fn parse_carmen_line(line: &str, flaser_max_range: f64) -> Result<Option<Scan>, String> {
    let mut items = line.split_ascii_whitespace();
    let kind = match items.next() {
        Some(k @ ("FLASER" | "ROBOTLASER1")) => k,
        None => return Ok(None),
        Some(w) if w.starts_with('#') || is_message_name(w) => return Ok(None),
        // Anything else is not a CARMEN log at all; saying so beats reading zero scans.
        Some(w) => {
            return Err(format!(
                "not a CARMEN log line (starts with {:?}; expected a message name such as \
                 FLASER, or a JSON object for scan JSON Lines)",
                w.chars().take(20).collect::<String>()
            ));
        }
    };
    let f = Fields::new(kind, items.collect());
    let scan = if kind == "FLASER" {
        flaser(&f, flaser_max_range)?
    } else {
        robotlaser1(&f)?
    };
    limits::check_scan(&scan).map_err(|m| format!("{kind}: {m}"))?;
    Ok(Some(scan))
}

/// `FLASER n r1 .. rn x y theta odom_x odom_y odom_theta timestamp [host logger_timestamp]`.
fn flaser(f: &Fields, max_range: f64) -> Result<Scan, String> {
    let n = f.rays(0, "the number of readings")?;
    // The count, n readings, and 7 numbers.
    if let Some(k) = f.miscounted(n + 8).filter(|&k| k >= 8) {
        return Err(format!(
            "FLASER: the count says {n} readings but the line has {} (before x y theta odom_x \
             odom_y odom_theta timestamp [host logger_timestamp])",
            k - 8
        ));
    }
    let ranges = (0..n)
        .map(|i| f.number_with(1 + i, || format!("reading {}", i + 1)))
        .collect::<Result<Vec<_>, _>>()?;
    let at = 1 + n;
    let v = f.numbers(
        at,
        &[
            "x",
            "y",
            "theta",
            "odom_x",
            "odom_y",
            "odom_theta",
            "timestamp",
        ],
    )?;
    f.check_end(at + 7)?;
    let mut scan = Scan {
        readings: vec![None; n],
        valid: vec![false; n],
        theta: flaser_bearings(n),
        true_pose: Some(Pose::planar(v[0], v[1], v[2])),
        odometry: Some(Pose::planar(v[3], v[4], v[5])),
        timestamp: Some(timestamp("FLASER", v[6])?),
        ..Scan::default()
    };
    set_ranges(&mut scan, &ranges, max_range);
    Ok(scan)
}

/// `ROBOTLASER1 laser_type start_angle fov angular_res max_range accuracy remission_mode n
/// r1 .. rn m e1 .. em laser_x laser_y laser_theta robot_x robot_y robot_theta tv rv
/// forward_safety side_safety turn_axis timestamp [host logger_timestamp]`.
fn robotlaser1(f: &Fields) -> Result<Scan, String> {
    let start = f.number(1, "start_angle")?;
    let res = f.number(3, "angular_resolution")?;
    let max_range = f.number(4, "maximum_range")?;
    let n = f.rays(7, "num_readings")?;
    // 8 fields to num_readings, n readings, num_remissions, m remissions, 12 numbers.
    if let Ok(m) = f.count(8 + n, "num_remissions")
        && let Some(k) = f.miscounted(n + m + 21)
    {
        return Err(format!(
            "ROBOTLASER1: the counts say {n} readings and {m} remissions, so {} numbers are \
             expected before the host name, but the line has {k}",
            n + m + 21
        ));
    }
    let last = start + res * (n - 1) as f64;
    limits::check_angle("start_angle", start)
        .and_then(|()| limits::check_angle("the last bearing (from angular_resolution)", last))
        .map_err(|m| format!("ROBOTLASER1: {m}"))?;
    let ranges = (0..n)
        .map(|i| f.number_with(8 + i, || format!("reading {}", i + 1)))
        .collect::<Result<Vec<_>, _>>()?;
    let m = f.count(8 + n, "num_remissions")?;
    let at = 9 + n + m;
    let names = [
        "laser_x",
        "laser_y",
        "laser_theta",
        "robot_x",
        "robot_y",
        "robot_theta",
        "tv",
        "rv",
        "forward_safety",
        "side_safety",
        "turn_axis",
        "timestamp",
    ];
    let v = f.numbers(at, &names)?;
    f.check_end(at + names.len())?;
    // A max range of 0 means "not given" in some loggers: then only <= 0 is invalid.
    let max_range = if max_range > 0.0 {
        max_range
    } else {
        f64::INFINITY
    };
    let mut scan = Scan {
        readings: vec![None; n],
        valid: vec![false; n],
        theta: (0..n).map(|i| start + res * i as f64).collect(),
        odometry: Some(Pose::planar(v[0], v[1], v[2])),
        timestamp: Some(timestamp("ROBOTLASER1", v[11])?),
        ..Scan::default()
    };
    limits::check_pose("robot_pose", &Pose::planar(v[3], v[4], v[5]))
        .map_err(|m| format!("ROBOTLASER1: {m}"))?;
    scan.extra
        .insert("robot_pose".into(), serde_json::json!([v[3], v[4], v[5]]));
    set_ranges(&mut scan, &ranges, max_range);
    Ok(scan)
}

/// A CARMEN time in seconds, within [`limits::MAX_SECONDS`].
fn timestamp(kind: &str, t: f64) -> Result<Timestamp, String> {
    limits::check_seconds("timestamp", t).map_err(|m| format!("{kind}: {m}"))?;
    Ok(Timestamp::from_seconds(t))
}

/// Reads the scans of a CARMEN log, one line at a time. Yields `(line number, scan)`; stops
/// after the first error.
pub struct CarmenReader<R> {
    reader: R,
    name: String,
    line: usize,
    buf: String,
    params: CarmenParams,
    /// From `PARAM robot_front_laser_max`, when the log has it.
    logged_max_range: Option<f64>,
    done: bool,
    /// Scans yielded so far.
    scans: usize,
    /// Laser messages of kinds this reader does not read (`RAWLASER1`, `ROBOTLASER2`, ...):
    /// each kind with its count, in order of first appearance, and the first one's line. A
    /// log of nothing else would otherwise read as empty without a word.
    skipped: Vec<(String, usize)>,
    first_skipped_line: usize,
}

impl<R: BufRead> CarmenReader<R> {
    /// `name` is the file's name as the user gave it (or `<stdin>`), for error messages.
    pub fn new(reader: R, name: impl Into<String>, params: CarmenParams) -> Self {
        Self {
            reader,
            name: name.into(),
            line: 0,
            buf: String::new(),
            params,
            logged_max_range: None,
            done: false,
            scans: 0,
            skipped: Vec::new(),
            first_skipped_line: 0,
        }
    }

    /// Counts the current line when it is a laser message of a kind not read.
    fn note_skipped(&mut self) {
        let Some(kind) = self.buf.split_ascii_whitespace().next() else {
            return;
        };
        if !is_message_name(kind) || !kind.contains("LASER") {
            return;
        }
        match self.skipped.iter_mut().find(|(k, _)| k == kind) {
            Some((_, n)) => *n += 1,
            None => {
                if self.skipped.is_empty() {
                    self.first_skipped_line = self.line;
                }
                self.skipped.push((kind.to_string(), 1));
            }
        }
    }

    /// At the end of a log that gave no scans: the laser lines it skipped, as an error.
    fn unread_lasers(&self) -> Option<InputError> {
        if self.scans > 0 || self.skipped.is_empty() {
            return None;
        }
        let kinds: Vec<String> = self
            .skipped
            .iter()
            .map(|(kind, n)| format!("{n} {kind} line{}", if *n == 1 { "" } else { "s" }))
            .collect();
        Some(InputError::at_line(
            &self.name,
            self.first_skipped_line,
            format!(
                "no scans: {} skipped (the first here); levelscan reads FLASER and ROBOTLASER1 \
                 laser lines",
                kinds.join(", ")
            ),
        ))
    }

    fn flaser_max_range(&self) -> f64 {
        self.params
            .max_range
            .or(self.logged_max_range)
            .unwrap_or(DEFAULT_FLASER_MAX_RANGE)
    }
}

impl<R: BufRead> Iterator for CarmenReader<R> {
    type Item = Result<(usize, Scan), InputError>;

    fn next(&mut self) -> Option<Self::Item> {
        while !self.done {
            self.buf.clear();
            match super::limits::read_line_capped(&mut self.reader, &mut self.buf) {
                Ok(0) => {
                    self.done = true;
                    return self.unread_lasers().map(Err);
                }
                Ok(_) => {
                    self.line += 1;
                    let mut words = self.buf.split_ascii_whitespace();
                    if words.next() == Some("PARAM")
                        && words.next() == Some("robot_front_laser_max")
                    {
                        self.logged_max_range = words
                            .next()
                            .and_then(|v| v.parse::<f64>().ok())
                            .filter(|v| *v > 0.0);
                        continue;
                    }
                    match parse_carmen_line(&self.buf, self.flaser_max_range()) {
                        Ok(None) => self.note_skipped(),
                        Ok(Some(scan)) => {
                            self.scans += 1;
                            return Some(Ok((self.line, scan)));
                        }
                        Err(m) => {
                            self.done = true;
                            return Some(Err(InputError::at_line(&self.name, self.line, m)));
                        }
                    }
                }
                Err(e) => {
                    self.done = true;
                    return Some(Err(super::scan_jsonl::read_error(
                        &self.name,
                        self.line + 1,
                        &e,
                    )));
                }
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Cursor;

    #[test]
    fn flaser_bearings_follow_carmens_convention() {
        let b = flaser_bearings(181);
        assert!((b[0] + PI / 2.0).abs() < 1e-15);
        assert!((b[180] - PI / 2.0).abs() < 1e-12);
        let b = flaser_bearings(180);
        assert!((b[1] - b[0] - PI / 180.0).abs() < 1e-15);
        assert!((b[179] - (PI / 2.0 - PI / 180.0)).abs() < 1e-12);
        let b = flaser_bearings(361);
        assert!((b[1] - b[0] - PI / 360.0).abs() < 1e-15);
        let b = flaser_bearings(360);
        assert!((b[1] - b[0] - PI / 360.0).abs() < 1e-15);
    }

    #[test]
    fn flaser_line_becomes_a_scan() {
        let line = "FLASER 4 1.5 81.91 0 2.25 0.5 -1 0.25 0.6 -1.1 0.3 12.75 pippo 12.75";
        let s = parse_carmen_line(line, 50.0).unwrap().unwrap();
        assert_eq!(s.nrays(), 4);
        assert_eq!(s.readings, vec![Some(1.5), None, None, Some(2.25)]);
        assert_eq!(s.valid, vec![true, false, false, true]);
        assert_eq!(s.true_pose, Some(Pose::planar(0.5, -1.0, 0.25)));
        assert_eq!(s.odometry, Some(Pose::planar(0.6, -1.1, 0.3)));
        assert_eq!(
            s.timestamp,
            Some(Timestamp {
                sec: 12,
                usec: 750000
            })
        );
        assert!((s.theta[0] + PI / 2.0).abs() < 1e-15);
        assert!((s.theta[1] - s.theta[0] - PI / 4.0).abs() < 1e-15);
    }

    #[test]
    fn robotlaser1_line_becomes_a_scan() {
        // type start fov res max acc mode n r.. m e.. laser(3) robot(3) tv rv fs ss ta time host lt
        let line = "ROBOTLASER1 0 -1.5 3.0 1.0 20 0.01 0 4 1 2 25 0 2 7 8 \
                    1 2 0.1 0.9 2 0.1 0 0 0.5 0.3 0 100.5 host 100.5";
        let s = parse_carmen_line(line, 50.0).unwrap().unwrap();
        assert_eq!(s.theta, vec![-1.5, -0.5, 0.5, 1.5]);
        assert_eq!(s.readings, vec![Some(1.0), Some(2.0), None, None]);
        assert_eq!(s.odometry, Some(Pose::planar(1.0, 2.0, 0.1)));
        assert_eq!(s.extra["robot_pose"], serde_json::json!([0.9, 2.0, 0.1]));
        assert_eq!(s.timestamp.unwrap().seconds(), 100.5);
        assert_eq!(s.true_pose, None);
    }

    #[test]
    fn lines_that_are_no_carmen_at_all_are_errors() {
        for line in ["hello", "[1,2,3]", "42 1 2", "null"] {
            let err = parse_carmen_line(line, 50.0).unwrap_err();
            assert!(err.contains("not a CARMEN log line"), "{line}: {err}");
        }
        assert_eq!(parse_carmen_line("ODOM 1 2 3", 50.0), Ok(None));
        assert_eq!(parse_carmen_line("# comment", 50.0), Ok(None));
    }

    #[test]
    fn other_lines_are_skipped_and_bad_lines_name_the_line() {
        let log = "# comment\nPARAM robot_front_laser_max 2.0 host 0\nODOM 0 0 0 0 0 0 1 h 1\n\
                   FLASER 2 1.0 3.0 0 0 0 0 0 0 1.0 h 1\n\nFLASER 2 1.0 x 0 0 0 0 0 0 1.0 h 1\n";
        let items: Vec<_> =
            CarmenReader::new(Cursor::new(log), "intel.log", CarmenParams::default()).collect();
        assert_eq!(items.len(), 2);
        let (line, scan) = items[0].as_ref().unwrap();
        assert_eq!(*line, 4);
        // The log's PARAM says 2 m, so the 3 m reading is no return.
        assert_eq!(scan.readings, vec![Some(1.0), None]);
        assert_eq!(
            items[1].as_ref().unwrap_err().to_string(),
            "intel.log:6: FLASER: reading 2 (field 3) is not a number: `x`"
        );
    }

    #[test]
    fn a_log_of_laser_lines_of_other_kinds_says_what_it_skipped() {
        let raw = "RAWLASER1 0 -1.5708 3.1416 0.0175 81.9 0.01 0 3 2 2 2 0 5.0 host 5.0\n";
        let log = format!("# log\nODOM 0 0 0 0 0 0 1 h 1\n{raw}{raw}ROBOTLASER2 1 2 3\n");
        let items: Vec<_> =
            CarmenReader::new(Cursor::new(log), "raw.log", CarmenParams::default()).collect();
        assert_eq!(items.len(), 1);
        assert_eq!(
            items[0].as_ref().unwrap_err().to_string(),
            "raw.log:3: no scans: 2 RAWLASER1 lines, 1 ROBOTLASER2 line skipped (the first \
             here); levelscan reads FLASER and ROBOTLASER1 laser lines"
        );
        // Beside scans it reads, other lasers (a rear RLASER) are skipped without a word.
        let log = format!("{raw}FLASER 2 1.0 3.0 0 0 0 0 0 0 1.0 h 1\n");
        let items: Vec<_> =
            CarmenReader::new(Cursor::new(log), "mixed.log", CarmenParams::default()).collect();
        assert_eq!(items.len(), 1);
        assert!(items[0].is_ok());
        // A log of no laser lines at all is just empty.
        let log = "# log\nODOM 0 0 0 0 0 0 1 h 1\n";
        assert_eq!(
            CarmenReader::new(Cursor::new(log), "odom.log", CarmenParams::default()).count(),
            0
        );
    }

    #[test]
    fn truncated_flaser_is_an_error() {
        let e = parse_carmen_line("FLASER 3 1 2 3 0 0", 50.0).unwrap_err();
        assert_eq!(e, "FLASER: the line ends before theta (field 7)");
        let e = parse_carmen_line("FLASER -2 1 2", 50.0).unwrap_err();
        assert!(e.contains("must be a whole number"), "{e}");
    }

    #[test]
    fn a_flaser_count_that_disagrees_with_its_readings_names_both() {
        // Three readings given, the count says 2 or 4: the pose would be read from ranges.
        let e = parse_carmen_line("FLASER 2 1 2 3 0 0 0 0 0 0 1.5 host 1.5", 50.0).unwrap_err();
        assert_eq!(
            e,
            "FLASER: the count says 2 readings but the line has 3 (before x y theta odom_x \
             odom_y odom_theta timestamp [host logger_timestamp])"
        );
        let e = parse_carmen_line("FLASER 4 1 2 3 0 0 0 0 0 0 1.5 host 1.5", 50.0).unwrap_err();
        assert!(
            e.starts_with("FLASER: the count says 4 readings but the line has 3"),
            "{e}"
        );
        // Without host and logger time, too; but a line of too few numbers may be cut short.
        let e = parse_carmen_line("FLASER 3 1 2 0 0 0 0 0 0 1.5", 50.0).unwrap_err();
        assert_eq!(e, "FLASER: the line ends before timestamp (field 11)");
        let e = parse_carmen_line("FLASER 1 1 2 0 0 0 0 0 0 1.5", 50.0).unwrap_err();
        assert!(
            e.starts_with("FLASER: the count says 1 readings but the line has 2"),
            "{e}"
        );
        assert!(parse_carmen_line("FLASER 2 1 2 0 0 0 0 0 0 1.5", 50.0).is_ok());
    }

    #[test]
    fn trailing_tokens_say_what_is_expected() {
        let e = parse_carmen_line("FLASER 2 1 2 0 0 0 0 0 0 1.5 host 1.5 extra", 50.0).unwrap_err();
        assert_eq!(
            e,
            "FLASER: 3 more field(s) after the timestamp (field 10), from `host`; the line must \
             end with the timestamp, or with `host logger_timestamp`"
        );
        let e = parse_carmen_line("FLASER 2 1 2 0 0 0 0 0 0 1.5 host", 50.0).unwrap_err();
        assert!(
            e.starts_with("FLASER: 1 more field(s) after the timestamp"),
            "{e}"
        );
        let e = parse_carmen_line("FLASER 2 1 2 0 0 0 0 0 0 1.5 host later", 50.0).unwrap_err();
        assert!(e.contains("from `host`"), "{e}");
        let line = "ROBOTLASER1 0 -1.5 3.0 1.0 20 0.01 0 4 1 2 25 0 2 7 8 \
                    1 2 0.1 0.9 2 0.1 0 0 0.5 0.3 0 100.5 host 100.5 x";
        let e = parse_carmen_line(line, 50.0).unwrap_err();
        assert!(
            e.starts_with("ROBOTLASER1: 3 more field(s) after the timestamp"),
            "{e}"
        );
    }

    #[test]
    fn a_robotlaser1_count_that_disagrees_names_the_counts() {
        // 4 readings announced, 5 given (and 2 remissions).
        let line = "ROBOTLASER1 0 -1.5 3.0 1.0 20 0.01 0 4 1 2 25 0 9 2 7 8 \
                    1 2 0.1 0.9 2 0.1 0 0 0.5 0.3 0 100.5 host 100.5";
        let e = parse_carmen_line(line, 50.0).unwrap_err();
        assert!(
            e.starts_with("ROBOTLASER1: the counts say 4 readings and 9 remissions"),
            "{e}"
        );
    }

    #[test]
    fn absurd_sizes_and_values_are_refused() {
        let e = parse_carmen_line("FLASER 1000000 1 2", 50.0).unwrap_err();
        assert_eq!(
            e,
            "FLASER: the number of readings is 1000000, more than the limit of 100000 rays per \
             scan"
        );
        let e = parse_carmen_line("FLASER 0 0 0 0 0 0 0 1.5", 50.0).unwrap_err();
        assert_eq!(
            e,
            "FLASER: the number of readings must be a positive integer, not 0"
        );
        let e = parse_carmen_line("FLASER 1 1 0 0 0 0 0 0 1e300", 50.0).unwrap_err();
        assert!(
            e.starts_with("FLASER: timestamp is 1e300 s, beyond the limit"),
            "{e}"
        );
        let e = parse_carmen_line("FLASER 1 1 3e7 0 0 0 0 0 1.5", 50.0).unwrap_err();
        assert!(e.starts_with("FLASER: true_pose: x is 3e7 m"), "{e}");
        let line = "ROBOTLASER1 0 -1.5 3.0 1e10 20 0.01 0 4 1 2 25 0 0 \
                    1 2 0.1 0.9 2 0.1 0 0 0.5 0.3 0 100.5";
        let e = parse_carmen_line(line, 50.0).unwrap_err();
        assert!(e.starts_with("ROBOTLASER1: the last bearing"), "{e}");
    }

    #[test]
    fn callers_max_range_wins_over_the_logs() {
        let log = "PARAM robot_front_laser_max 2.0 host 0\nFLASER 2 1.0 3.0 0 0 0 0 0 0 1.0 h 1\n";
        let params = CarmenParams {
            max_range: Some(10.0),
        };
        let items: Vec<_> = CarmenReader::new(Cursor::new(log), "a", params).collect();
        assert_eq!(
            items[0].as_ref().unwrap().1.readings,
            vec![Some(1.0), Some(3.0)]
        );
    }
}
