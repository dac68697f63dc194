//! What the scan readers accept beyond well-formed syntax: caps on absurd sizes, and the
//! ranges that angles, noise and positions must lie in, so that every scan read is one that
//! the rest of the crate can work with (no bearing of 1e308 turning into `null` in `level`
//! output, no line of hundreds of megabytes read into memory).
//!
//! The caps are far beyond real scanners: a SICK LMS1xx has 541 or 1081 rays, a Hokuyo
//! UTM-30LX 1081, a SICK TiM/LMS4000 or an RPLidar S2 2000-3200, a 0.01-degree 360-degree
//! scan 36,000.

use crate::geometry::Pose;
use crate::scan::Scan;
use std::f64::consts::TAU;
use std::io::{self, BufRead, Read};

/// Most rays one scan may have: 100,000.
pub const MAX_RAYS: usize = 100_000;

/// Longest line a scan file may have \[bytes\]: 32 MiB. A scan of [`MAX_RAYS`] rays with every
/// field (`theta`, `readings`, `valid`, `readings_sigma`, `hit`, CSM's extra per-ray arrays)
/// takes about 10 MB.
pub const MAX_LINE_BYTES: usize = 32 << 20;

/// Largest bearing or elevation, either way \[rad\]: one turn (2 pi), plus room for rounding.
/// Scanners give bearings within [-pi, pi] or [0, 2 pi]; a hinge that turns all the way
/// round gives elevations within one turn too.
pub const MAX_ANGLE: f64 = TAU + 1e-6;

/// Largest coordinate of a pose or hinge offset \[m\]: the floor plans' limit,
/// [`crate::plan::MAX_COORDINATE`] (10,000 km).
pub const MAX_POSITION: f64 = crate::plan::MAX_COORDINATE;

/// Largest time \[s\] (about 285 million years): beyond it, seconds no longer fit the
/// microseconds of a `[sec, usec]` timestamp exactly.
pub const MAX_SECONDS: f64 = 9e15;

/// `n` rays: at least one and at most [`MAX_RAYS`].
pub(crate) fn check_rays(what: &str, n: usize) -> Result<(), String> {
    if n == 0 {
        Err(format!("{what} must be a positive integer, not 0"))
    } else if n > MAX_RAYS {
        Err(format!(
            "{what} is {n}, more than the limit of {MAX_RAYS} rays per scan"
        ))
    } else {
        Ok(())
    }
}

/// One angle \[rad\]: finite and within [`MAX_ANGLE`] either way. `what` names it.
pub(crate) fn check_angle(what: &str, v: f64) -> Result<(), String> {
    if v.is_finite() && v.abs() <= MAX_ANGLE {
        Ok(())
    } else {
        Err(format!(
            "{what} is {}, not an angle within one turn (+-2 pi rad); angles are in radians",
            show(v)
        ))
    }
}

/// Every bearing of a scan (see [`check_angle`]); the error names the first bad one.
pub(crate) fn check_bearings(field: &str, theta: &[f64]) -> Result<(), String> {
    match theta
        .iter()
        .position(|t| !(t.is_finite() && t.abs() <= MAX_ANGLE))
    {
        None => Ok(()),
        Some(i) => check_angle(&format!("{field}[{i}]"), theta[i]),
    }
}

/// Range noise sigmas: each >= 0 (and finite), or `null`.
pub(crate) fn check_sigmas(field: &str, sigma: &[Option<f64>]) -> Result<(), String> {
    match sigma
        .iter()
        .position(|s| s.is_some_and(|s| !(s >= 0.0 && s.is_finite())))
    {
        None => Ok(()),
        Some(i) => Err(format!(
            "{field}[{i}] is {}: a noise sigma must be >= 0 metres (or null)",
            show(sigma[i].unwrap_or(f64::NAN))
        )),
    }
}

/// A pose's position within [`MAX_POSITION`] (its angles may be any finite number of
/// radians: headings are often left unwrapped).
pub(crate) fn check_pose(field: &str, pose: &Pose) -> Result<(), String> {
    for (name, v) in [("x", pose.x), ("y", pose.y), ("z", pose.z)] {
        check_position(&format!("{field}: {name}"), v)?;
    }
    Ok(())
}

/// A length \[m\] within [`MAX_POSITION`].
pub(crate) fn check_position(what: &str, v: f64) -> Result<(), String> {
    if v.is_finite() && v.abs() <= MAX_POSITION {
        Ok(())
    } else {
        Err(format!(
            "{what} is {} m, beyond the limit of +-{MAX_POSITION:e} m",
            show(v)
        ))
    }
}

/// A time in seconds within [`MAX_SECONDS`].
pub(crate) fn check_seconds(what: &str, t: f64) -> Result<(), String> {
    if t.is_finite() && t.abs() < MAX_SECONDS {
        Ok(())
    } else {
        Err(format!(
            "{what} is {} s, beyond the limit of +-{MAX_SECONDS:e} s",
            show(t)
        ))
    }
}

/// The checks on a scan read from a file, after the lengths of its arrays: bearings,
/// elevation (the scan's and each ray's), noise sigmas, poses, hinge offset and timestamp (see the checks above).
pub(crate) fn check_scan(scan: &Scan) -> Result<(), String> {
    check_bearings("theta", &scan.theta)?;
    if let Some(e) = scan.elevation {
        check_angle("elevation", e)?;
    }
    if let Some(e) = &scan.ray_elevation {
        check_bearings("ray_elevation", e)?;
    }
    if let Some(s) = &scan.readings_sigma {
        check_sigmas("readings_sigma", s)?;
    }
    for (field, pose) in [
        ("odometry", &scan.odometry),
        ("estimate", &scan.estimate),
        ("true_pose", &scan.true_pose),
    ] {
        if let Some(p) = pose {
            check_pose(field, p)?;
        }
    }
    if let Some(o) = &scan.hinge_offset {
        for (k, v) in o.iter().enumerate() {
            check_position(&format!("hinge_offset[{k}]"), *v)?;
        }
    }
    if let Some(t) = &scan.timestamp {
        check_seconds("timestamp", t.seconds())?;
    }
    Ok(())
}

/// A number for a message: huge ones in exponent form (Rust prints every digit otherwise).
fn show(v: f64) -> String {
    if v.is_finite() && (v.abs() >= 1e7 || (v != 0.0 && v.abs() < 1e-6)) {
        format!("{v:e}")
    } else {
        v.to_string()
    }
}

/// The error of a line longer than [`MAX_LINE_BYTES`], told apart by [`is_line_too_long`].
#[derive(Debug)]
struct LineTooLong;

impl std::fmt::Display for LineTooLong {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "the line is longer than {} MiB, the limit for one scan (a scan of {MAX_RAYS} rays \
             with every field takes about 10 MB); is this a scan file?",
            MAX_LINE_BYTES >> 20
        )
    }
}

impl std::error::Error for LineTooLong {}

/// Whether `e` is the error of [`read_line_capped`] for a line that is too long.
pub(crate) fn is_line_too_long(e: &io::Error) -> bool {
    e.get_ref().is_some_and(|inner| inner.is::<LineTooLong>())
}

/// `BufRead::read_line` that reads at most [`MAX_LINE_BYTES`] (plus the newline) into
/// memory: a longer line is an error (see [`is_line_too_long`]), and so is one that is not
/// UTF-8 (`InvalidData`, as `read_line` gives).
pub(crate) fn read_line_capped<R: BufRead>(reader: &mut R, buf: &mut String) -> io::Result<usize> {
    read_line_within(reader, buf, MAX_LINE_BYTES)
}

fn read_line_within<R: BufRead>(reader: &mut R, buf: &mut String, cap: usize) -> io::Result<usize> {
    let mut bytes = std::mem::take(buf).into_bytes();
    bytes.clear();
    let n = reader
        .by_ref()
        .take(cap as u64 + 1)
        .read_until(b'\n', &mut bytes)?;
    if bytes.len() > cap && bytes.last() != Some(&b'\n') {
        return Err(io::Error::new(io::ErrorKind::InvalidData, LineTooLong));
    }
    match String::from_utf8(bytes) {
        Ok(text) => {
            *buf = text;
            Ok(n)
        }
        Err(e) => {
            // Keep the allocation for the next line.
            let mut bytes = e.into_bytes();
            bytes.clear();
            *buf = String::from_utf8(bytes).unwrap_or_default();
            Err(io::Error::new(
                io::ErrorKind::InvalidData,
                "stream did not contain valid UTF-8",
            ))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Cursor;

    #[test]
    fn lines_up_to_the_cap_are_read_and_longer_ones_refused() {
        let mut r = Cursor::new(b"abcd\nabcde\nabc".to_vec());
        let mut buf = String::new();
        assert_eq!(read_line_within(&mut r, &mut buf, 4).unwrap(), 5);
        assert_eq!(buf, "abcd\n");
        let e = read_line_within(&mut r, &mut buf, 4).unwrap_err();
        assert!(is_line_too_long(&e), "{e}");
        let mut r = Cursor::new(b"abc".to_vec());
        assert_eq!(read_line_within(&mut r, &mut buf, 4).unwrap(), 3);
        assert_eq!(buf, "abc");
        assert_eq!(read_line_within(&mut r, &mut buf, 4).unwrap(), 0);
        let mut r = Cursor::new(b"a\xffb\n".to_vec());
        let e = read_line_within(&mut r, &mut buf, 4).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::InvalidData);
        assert!(!is_line_too_long(&e));
    }

    #[test]
    fn real_scanners_pass_and_absurd_sizes_do_not() {
        for n in [1, 181, 361, 541, 1081, 2000, 3200, 36_000, MAX_RAYS] {
            assert_eq!(check_rays("nrays", n), Ok(()));
        }
        assert_eq!(
            check_rays("nrays", 0).unwrap_err(),
            "nrays must be a positive integer, not 0"
        );
        assert_eq!(
            check_rays("nrays", 1_000_000).unwrap_err(),
            "nrays is 1000000, more than the limit of 100000 rays per scan"
        );
    }

    #[test]
    fn angles_beyond_one_turn_are_refused() {
        assert_eq!(check_bearings("theta", &[-TAU, 0.0, TAU, 3.0]), Ok(()));
        assert_eq!(
            check_bearings("theta", &[0.0, 1e308]).unwrap_err(),
            "theta[1] is 1e308, not an angle within one turn (+-2 pi rad); angles are in radians"
        );
        assert!(check_angle("elevation", -7.0).is_err());
        assert!(check_angle("elevation", f64::NAN).is_err());
    }

    fn jsonl_err(line: &str) -> String {
        crate::formats::parse_scan_line(line).unwrap_err()
    }

    /// The checks as the JSON Lines reader applies them, with the messages a user sees.
    #[test]
    fn scan_lines_beyond_the_limits_are_refused() {
        let e =
            jsonl_err(r#"{"nrays": 2, "min_theta": 0, "max_theta": 1e308, "readings": [1, 2]}"#);
        assert_eq!(
            e,
            "max_theta is 1e308, not an angle within one turn (+-2 pi rad); angles are in radians"
        );
        let e = jsonl_err(r#"{"nrays": 2, "theta": [0, 7], "readings": [1, 2]}"#);
        assert!(e.starts_with("theta[1] is 7, not an angle"), "{e}");
        let e = jsonl_err(r#"{"theta": [0], "readings": [1], "elevation": -9}"#);
        assert!(e.starts_with("elevation is -9, not an angle"), "{e}");
        let e =
            jsonl_err(r#"{"theta": [0, 1], "readings": [1, 2], "readings_sigma": [0.01, -0.01]}"#);
        assert_eq!(
            e,
            "readings_sigma[1] is -0.01: a noise sigma must be >= 0 metres (or null)"
        );
        let e = jsonl_err(r#"{"nrays": 1000000, "theta": [0], "readings": [1]}"#);
        assert_eq!(
            e,
            "nrays is 1000000, more than the limit of 100000 rays per scan"
        );
        let e = jsonl_err(r#"{"theta": [0], "readings": [1], "odometry": [1e300, 0, 0]}"#);
        assert!(
            e.starts_with("odometry: x is 1e300 m, beyond the limit"),
            "{e}"
        );
        let e = jsonl_err(r#"{"theta": [0], "readings": [1], "hinge_offset": [0, 0, 2e7]}"#);
        assert!(e.starts_with("hinge_offset[2] is 2e7 m"), "{e}");
        let e = jsonl_err(r#"{"theta": [0], "readings": [1], "timestamp": 1e300}"#);
        assert!(
            e.starts_with("timestamp: the time is 1e300 s, beyond the limit of +-9e15 s"),
            "{e}"
        );
        // Readings may be anything finite: logs write -1 or huge values for no return.
        assert!(crate::formats::parse_scan_line(r#"{"theta": [0], "readings": [1e300]}"#).is_ok());
    }

    #[test]
    fn the_array_cap_stops_reading_at_max_rays() {
        let n = MAX_RAYS;
        let ones = vec!["1"; n].join(",");
        let line =
            format!(r#"{{"nrays": {n}, "min_theta": -3, "max_theta": 3, "readings": [{ones}]}}"#);
        assert_eq!(crate::formats::parse_scan_line(&line).unwrap().nrays(), n);
        let line = format!(r#"{{"min_theta": -3, "max_theta": 3, "readings": [{ones},1]}}"#);
        let e = jsonl_err(&line);
        assert!(
            e.starts_with("readings: more than 100000 entries, the limit of rays per scan"),
            "{e}"
        );
    }

    #[test]
    fn negative_sigmas_and_far_positions_are_refused() {
        assert_eq!(check_sigmas("s", &[Some(0.0), None, Some(0.01)]), Ok(()));
        assert_eq!(
            check_sigmas("readings_sigma", &[Some(0.01), Some(-0.5)]).unwrap_err(),
            "readings_sigma[1] is -0.5: a noise sigma must be >= 0 metres (or null)"
        );
        let far = Pose::planar(1.0, -3e7, 0.0);
        assert_eq!(
            check_pose("odometry", &far).unwrap_err(),
            "odometry: y is -3e7 m, beyond the limit of +-1e7 m"
        );
        assert_eq!(
            check_pose("odometry", &Pose::planar(5.8e6, 1.0, 99.0)),
            Ok(())
        );
        assert!(check_seconds("timestamp", 1e300).is_err());
        assert_eq!(check_seconds("timestamp", 1.7e9), Ok(()));
    }
}
