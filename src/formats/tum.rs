//! TUM trajectories (the TUM RGB-D benchmark's text format, which `evo` reads): one line
//! `timestamp x y z qx qy qz qw` per pose, seconds, metres and a unit quaternion (Hamilton,
//! scalar last). Planar poses have z = 0 and a rotation about z alone.

use crate::geometry::Pose2;
use std::io::{self, Write};

/// Writes one TUM line for a planar pose at `time` seconds.
pub fn write_tum(w: &mut impl Write, time: f64, pose: &Pose2) -> io::Result<()> {
    let (qz, qw) = (pose.theta / 2.0).sin_cos();
    // `{}` prints the shortest text that reads back to the same f64.
    writeln!(w, "{} {} {} 0 0 0 {} {}", time, pose.x, pose.y, qz, qw)
}

/// Reads one TUM line back as `(time, planar pose)`; `Ok(None)` for blank and `#` lines. The
/// heading is the quaternion's rotation about z (exact for planar poses).
pub fn parse_tum_line(line: &str) -> Result<Option<(f64, Pose2)>, String> {
    let line = line.trim();
    if line.is_empty() || line.starts_with('#') {
        return Ok(None);
    }
    let v = line
        .split_ascii_whitespace()
        .map(|t| {
            t.parse::<f64>()
                .map_err(|_| format!("`{t}` is not a number"))
        })
        .collect::<Result<Vec<f64>, _>>()?;
    let [t, x, y, _z, qx, qy, qz, qw] = v[..] else {
        return Err(format!(
            "a TUM line has 8 numbers (timestamp x y z qx qy qz qw), this has {}",
            v.len()
        ));
    };
    // Yaw of a quaternion (ZYX convention).
    let yaw = (2.0 * (qw * qz + qx * qy)).atan2(1.0 - 2.0 * (qy * qy + qz * qz));
    Ok(Some((t, Pose2::new(x, y, yaw))))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{UnitQuaternion, Vector3};
    use proptest::prelude::*;

    #[test]
    fn quarter_turn_has_known_quaternion() {
        let mut out = Vec::new();
        write_tum(
            &mut out,
            1.5,
            &Pose2::new(1.0, -2.0, std::f64::consts::FRAC_PI_2),
        )
        .unwrap();
        let text = String::from_utf8(out).unwrap();
        let v: Vec<f64> = text
            .split_whitespace()
            .map(|t| t.parse().unwrap())
            .collect();
        assert_eq!(&v[..4], &[1.5, 1.0, -2.0, 0.0]);
        let h = std::f64::consts::FRAC_1_SQRT_2;
        assert!((v[6] - h).abs() < 1e-15 && (v[7] - h).abs() < 1e-15);
        assert_eq!((v[4], v[5]), (0.0, 0.0));
    }

    proptest! {
        #[test]
        fn tum_quaternion_matches_nalgebras_and_reads_back(
            t in 0.0f64..1e9, x in -1e3f64..1e3, y in -1e3f64..1e3, yaw in -3.0f64..3.0,
        ) {
            let mut out = Vec::new();
            write_tum(&mut out, t, &Pose2::new(x, y, yaw)).unwrap();
            let text = String::from_utf8(out).unwrap();
            let v: Vec<f64> = text.split_whitespace().map(|s| s.parse().unwrap()).collect();
            let q = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw);
            prop_assert!((q.i - v[4]).abs() < 1e-15 && (q.j - v[5]).abs() < 1e-15);
            prop_assert!((q.k - v[6]).abs() < 1e-15 && (q.w - v[7]).abs() < 1e-15);
            let (tb, p) = parse_tum_line(&text).unwrap().unwrap();
            prop_assert_eq!((tb, p.x, p.y), (t, x, y));
            prop_assert!((p.theta - yaw).abs() < 1e-12);
        }
    }

    #[test]
    fn bad_tum_lines_say_why() {
        assert_eq!(parse_tum_line("# header").unwrap(), None);
        assert!(parse_tum_line("1 2 3").unwrap_err().contains("8 numbers"));
        assert!(
            parse_tum_line("1 2 3 a 0 0 0 1")
                .unwrap_err()
                .contains("`a`")
        );
    }
}
