//! PLY point clouds (Turk 1994; the format PCL, CloudCompare, MeshLab and Open3D read): one
//! vertex per valid ray, `x y z` as float, the scan's index within its pose and the range, and
//! a colour per scan so that the scans tell apart in any viewer.

use crate::scan::Scan;
use std::io::{self, Write};

/// One point of a cloud.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CloudPoint {
    /// Position \[m\].
    pub p: [f32; 3],
    /// Index of the scan within its pose (0 for the first).
    pub scan: u8,
    /// Measured range \[m\].
    pub range: f32,
}

/// The points of one pose's scans in the robot frame: each valid ray at its hinge elevation and
/// offset ([`Scan::point_in_robot`]), tagged with its scan's index in `scans`.
pub fn pose_cloud(scans: &[Scan]) -> Vec<CloudPoint> {
    let mut points = Vec::new();
    for (k, s) in scans.iter().enumerate() {
        points.extend((0..s.nrays()).filter_map(|i| {
            let (p, r) = (s.point_in_robot(i)?, s.range(i)?);
            Some(CloudPoint {
                p: [p.x as f32, p.y as f32, p.z as f32],
                scan: k.min(255) as u8,
                range: r as f32,
            })
        }));
    }
    points
}

/// Colours of scans 0, 1, 2, ... (cycled).
const PALETTE: [[u8; 3]; 6] = [
    [228, 26, 28],
    [55, 126, 184],
    [77, 175, 74],
    [152, 78, 163],
    [255, 127, 0],
    [166, 86, 40],
];

/// Writes `points` as PLY, binary little-endian or ASCII, with `comments` in the header (one
/// line each; line breaks in them become spaces).
pub fn write_ply(
    w: &mut dyn Write,
    points: &[CloudPoint],
    comments: &[String],
    ascii: bool,
) -> io::Result<()> {
    let format = if ascii {
        "ascii"
    } else {
        "binary_little_endian"
    };
    writeln!(w, "ply\nformat {format} 1.0")?;
    for c in comments {
        writeln!(w, "comment {}", c.replace(['\n', '\r'], " "))?;
    }
    writeln!(
        w,
        "element vertex {}\nproperty float x\nproperty float y\nproperty float z\n\
         property uchar scan\nproperty float range\n\
         property uchar red\nproperty uchar green\nproperty uchar blue\nend_header",
        points.len()
    )?;
    for q in points {
        let [r, g, b] = PALETTE[q.scan as usize % PALETTE.len()];
        if ascii {
            writeln!(
                w,
                "{} {} {} {} {} {r} {g} {b}",
                q.p[0], q.p[1], q.p[2], q.scan, q.range
            )?;
        } else {
            let mut rec = [0u8; 20];
            for (k, v) in q.p.iter().enumerate() {
                rec[4 * k..4 * k + 4].copy_from_slice(&v.to_le_bytes());
            }
            rec[12] = q.scan;
            rec[13..17].copy_from_slice(&q.range.to_le_bytes());
            rec[17..20].copy_from_slice(&[r, g, b]);
            w.write_all(&rec)?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ascii_and_binary_carry_the_same_vertices() {
        let pts = [
            CloudPoint {
                p: [1.0, -2.5, 0.25],
                scan: 0,
                range: 2.7,
            },
            CloudPoint {
                p: [0.5, 0.0, -0.125],
                scan: 7,
                range: 0.5,
            },
        ];
        let mut a = Vec::new();
        write_ply(&mut a, &pts, &["pose 3".into()], true).unwrap();
        let text = String::from_utf8(a).unwrap();
        assert!(text.starts_with("ply\nformat ascii 1.0\ncomment pose 3\nelement vertex 2\n"));
        assert!(
            text.ends_with(
                "end_header\n1 -2.5 0.25 0 2.7 228 26 28\n0.5 0 -0.125 7 0.5 55 126 184\n"
            )
        );
        let mut b = Vec::new();
        write_ply(&mut b, &pts, &[], false).unwrap();
        let body = &b[b.windows(11).position(|w| w == b"end_header\n").unwrap() + 11..];
        assert_eq!(body.len(), 2 * 20);
        assert_eq!(f32::from_le_bytes(body[4..8].try_into().unwrap()), -2.5);
        assert_eq!((body[32], &body[37..40]), (7, &[55u8, 126, 184][..]));
    }
}
