//! The contract's "Output of level": one pose's pseudo-level scan (sect. 6) with its `level`
//! object, and, when asked, the wall polygons for the viewer (`wall_polygons`, the quads of
//! sect. 5.2, and `wall_patches`, the merged walls), in the robot frame. Written by `level` and
//! by the demo.

use crate::level::{LevelEstimate, SurfaceKind};
use crate::pseudo_level::{PseudoLevelParams, pseudo_level_scan_and_base};
use crate::scan::Scan;
use nalgebra::Point3;
use serde_json::{Value, json};

/// The output record of one pose: its pseudo-level scan plus the `level` object (and the
/// polygons when asked).
pub fn level_record(
    scans: &[Scan],
    est: &LevelEstimate,
    pseudo: &PseudoLevelParams,
    polygons: bool,
) -> Scan {
    let (mut scan, base) = pseudo_level_scan_and_base(scans, est, pseudo);
    let base_elevation = scans.get(base).and_then(|s| s.elevation);
    let level = json!({
        "status": if est.is_ok() { "ok" } else { "failed" },
        "reason": est.failure.map(|r| r.as_str()),
        "theta_x": est.attitude.map(|a| a.theta_x),
        "theta_y": est.attitude.map(|a| a.theta_y),
        "sigma_x": est.sigmas.map(|s| s[0]),
        "sigma_y": est.sigmas.map(|s| s[1]),
        "up": est.up.map(|u| [u.x, u.y, u.z]),
        "polygons": est.wall_polygons(),
        "base_elevation": base_elevation,
    });
    scan.extra.insert("level".to_string(), level);
    if polygons {
        let quads: Vec<Value> = est
            .quads
            .iter()
            .filter(|q| q.kind == SurfaceKind::Wall)
            .map(|q| corners_json(&q.corners))
            .collect();
        scan.extra
            .insert("wall_polygons".to_string(), Value::Array(quads));
        scan.extra.insert(
            "wall_patches".to_string(),
            Value::Array(patch_outlines(est)),
        );
    }
    scan
}

fn corners_json(c: &[Point3<f64>; 4]) -> Value {
    Value::Array(c.iter().map(|p| json!([p.x, p.y, p.z])).collect())
}

/// Each wall patch as the rectangle its points span in its own plane (robot frame).
fn patch_outlines(est: &LevelEstimate) -> Vec<Value> {
    let Some(grid) = &est.grid else {
        return Vec::new();
    };
    est.patches
        .iter()
        .filter(|p| p.kind == SurfaceKind::Wall)
        .map(|p| {
            let c = p.fit.centroid;
            let (a, b) = (p.fit.in_plane[1].1, p.fit.in_plane[0].1);
            let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
            for g in p.members.iter().filter_map(|&i| grid.points[i].as_ref()) {
                let d = g.p - c;
                let uv = [d.dot(&a), d.dot(&b)];
                for k in 0..2 {
                    lo[k] = lo[k].min(uv[k]);
                    hi[k] = hi[k].max(uv[k]);
                }
            }
            let corner = |u: f64, v: f64| c + a * u + b * v;
            corners_json(&[
                corner(lo[0], lo[1]),
                corner(hi[0], lo[1]),
                corner(hi[0], hi[1]),
                corner(lo[0], hi[1]),
            ])
        })
        .collect()
}
