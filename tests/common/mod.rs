//! A tiny analytic ray caster for level tests: vertical walls over 2D segments, the floor z = 0
//! and an optional ceiling. Independent of `levelscan::simulate` on purpose (a twin to check
//! the leveler against, not the code under test).
#![allow(dead_code, clippy::needless_range_loop)]

use levelscan::geometry::{Pose, beam_direction};
use levelscan::scan::{Hit, Scan};
use nalgebra::{Point3, Vector2, Vector3};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

pub struct Room {
    pub segments: Vec<([f64; 2], [f64; 2])>,
    pub height: f64,
    pub ceiling: bool,
}

impl Room {
    /// A closed polygon of walls.
    pub fn polygon(corners: &[[f64; 2]], height: f64, ceiling: bool) -> Room {
        let segments = (0..corners.len())
            .map(|i| (corners[i], corners[(i + 1) % corners.len()]))
            .collect();
        Room {
            segments,
            height,
            ceiling,
        }
    }

    /// The room with an axis-aligned box (a pillar) from corner `lo` to corner `hi`.
    pub fn with_box(mut self, lo: [f64; 2], hi: [f64; 2]) -> Room {
        let c = [lo, [hi[0], lo[1]], hi, [lo[0], hi[1]]];
        self.segments.extend((0..4).map(|i| (c[i], c[(i + 1) % 4])));
        self
    }

    pub fn box_room(w: f64, d: f64) -> Room {
        Room::polygon(&[[0.0, 0.0], [w, 0.0], [w, d], [0.0, d]], 3.0, false)
    }

    /// Two long parallel walls 2 m apart, open ends far beyond range.
    pub fn corridor() -> Room {
        Room {
            segments: vec![([-200.0, 0.0], [200.0, 0.0]), ([-200.0, 2.0], [200.0, 2.0])],
            height: 3.0,
            ceiling: false,
        }
    }

    /// Distance along the ray to the first surface and what it is.
    pub fn cast(&self, o: &Point3<f64>, d: &Vector3<f64>, max_range: f64) -> Option<(f64, Hit)> {
        let mut best: Option<(f64, Hit)> = None;
        let mut consider = |t: f64, h: Hit| {
            if t > 1e-9 && t <= max_range && best.is_none_or(|(bt, _)| t < bt) {
                best = Some((t, h));
            }
        };
        if d.z < 0.0 {
            consider(-o.z / d.z, Hit::Floor);
        }
        if self.ceiling && d.z > 0.0 {
            consider((self.height - o.z) / d.z, Hit::Ceiling);
        }
        let dxy = Vector2::new(d.x, d.y);
        for (a, b) in &self.segments {
            let a = Vector2::new(a[0], a[1]);
            let e = Vector2::new(b[0], b[1]) - a;
            let den = dxy.x * e.y - dxy.y * e.x;
            if den.abs() < 1e-15 {
                continue;
            }
            let w = a - Vector2::new(o.x, o.y);
            let t = (w.x * e.y - w.y * e.x) / den;
            let s = (w.x * dxy.y - w.y * dxy.x) / den;
            let z = o.z + t * d.z;
            if (0.0..=1.0).contains(&s) && (0.0..=self.height).contains(&z) {
                consider(t, Hit::Wall);
            }
        }
        best
    }
}

/// Scans of one pose: `nrays` over 180 degrees, 30 m range, Gaussian range noise.
pub fn scans_at(
    room: &Room,
    pose: &Pose,
    elevations: &[f64],
    noise: f64,
    seed: u64,
    sequence: u64,
) -> Vec<Scan> {
    let nrays = 181;
    let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(seed);
    let normal = Normal::new(0.0, noise.max(1e-300)).unwrap();
    let world_from_robot = pose.world_from_robot();
    let origin = Point3::new(pose.x, pose.y, pose.z);
    elevations
        .iter()
        .map(|&e| {
            let mut s = Scan::with_even_bearings(
                nrays,
                -std::f64::consts::FRAC_PI_2,
                std::f64::consts::FRAC_PI_2,
            );
            s.sequence = Some(sequence);
            s.elevation = Some(e);
            s.true_pose = Some(*pose);
            let mut hits = vec![Hit::Nothing; nrays];
            for i in 0..nrays {
                let d = world_from_robot.rotation * beam_direction(e, s.theta[i]);
                if let Some((t, h)) = room.cast(&origin, &d, 30.0) {
                    let r = t + if noise > 0.0 {
                        normal.sample(&mut rng)
                    } else {
                        0.0
                    };
                    if r > 0.0 {
                        s.readings[i] = Some(r);
                        s.valid[i] = true;
                        hits[i] = h;
                    }
                }
            }
            s.hit = Some(hits);
            s
        })
        .collect()
}

/// Elevations `n` scans `step_deg` apart, centred on level [rad].
pub fn elevations(n: usize, step_deg: f64) -> Vec<f64> {
    (0..n)
        .map(|k| (k as f64 - (n as f64 - 1.0) / 2.0) * step_deg.to_radians())
        .collect()
}

/// A plan under examples/plans, e.g. "office" or "halls/pilaster_hall" (for the tests that
/// run the library's own simulator in the example rooms).
pub fn example_plan(name: &str) -> levelscan::plan::Plan {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("examples/plans")
        .join(format!("{name}.wall"));
    levelscan::formats::read_plan(&path).unwrap()
}
