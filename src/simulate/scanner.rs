//! The tilting laser scanner: one scan per hinge elevation at a pose (paper sect. 5.1, 7.2.1).

use super::SimulateError;
use super::noise_model::NoiseModel;
use super::raycast::World;
use super::sweep;
use crate::geometry::{Pose, beam_direction, beam_origin};
use crate::scan::{Hit, Scan, even_bearings};
use nalgebra::Vector3;
use rand::Rng;

/// The scanner's parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct ScannerParams {
    /// Rays per scan, spread evenly over the field of view, both ends included. Default 181.
    pub rays: usize,
    /// Field of view, centred on the robot's forward axis \[rad\]. Default pi (180 deg).
    pub fov: f64,
    /// Longest range that still returns \[m\]; farther surfaces give no reading. Default 30.
    pub max_range: f64,
    /// Range noise \[m\]: the standard deviation of Gaussian noise, or the full width of
    /// uniform noise (`noise_model`). Default 0.01 (a SICK LMS 200, the paper's appendix C).
    pub noise_sigma: f64,
    /// What `noise_sigma` means. Default Gaussian.
    pub noise_model: NoiseModel,
    /// Hinge offset `o` \[m\]: the scanner's origin seen from the hinge axis point, in the
    /// scanner's tilted frame (contract). Default none (the hinge passes through the origin).
    pub hinge_offset: Option<[f64; 3]>,
    /// Write `readings_sigma` (the noise sigma for every ray) into the scans. Default false:
    /// `level` must estimate the noise itself.
    pub write_sigma: bool,
    /// Rate at which the hinge turns while a scan is taken \[rad/s\] (a nodding laser;
    /// positive tilts the beams further down as the scan goes on). Default 0: the hinge stands
    /// still during each scan (stop-and-scan, the paper's robot, sect. 7.2.1). When non-zero,
    /// each ray is cast at its own elevation ([`super::sweep::ray_elevations`]) and the scans
    /// carry `ray_elevation`.
    pub sweep_rate: f64,
    /// Scans per second \[Hz\]: one scan's rays spread over `1 / scan_rate` seconds, which
    /// with `sweep_rate` sets how far the hinge turns within a scan. Default 40 (a Hokuyo
    /// UTM-30LX, a common scanner on tilting mounts); it matters only when sweeping.
    pub scan_rate: f64,
}

impl Default for ScannerParams {
    fn default() -> Self {
        Self {
            rays: 181,
            fov: std::f64::consts::PI,
            max_range: 30.0,
            noise_sigma: 0.01,
            noise_model: NoiseModel::Gaussian,
            hinge_offset: None,
            write_sigma: false,
            sweep_rate: 0.0,
            scan_rate: 40.0,
        }
    }
}

impl ScannerParams {
    /// The bearing of every ray \[rad\], from `-fov/2` to `+fov/2`.
    pub fn bearings(&self) -> Vec<f64> {
        even_bearings(self.rays, -self.fov / 2.0, self.fov / 2.0)
    }

    /// The standard deviation of the range noise \[m\] (what `readings_sigma` holds).
    pub fn range_sigma(&self) -> f64 {
        self.noise_model.sigma(self.noise_sigma)
    }

    /// One scan's period \[s\]: `1 / scan_rate`.
    pub fn scan_time(&self) -> f64 {
        1.0 / self.scan_rate
    }

    /// The time between two successive rays \[s\] (a LaserScan's `time_increment`).
    pub fn time_increment(&self) -> f64 {
        sweep::time_increment(self.rays, self.scan_time())
    }

    pub fn validate(&self) -> Result<(), SimulateError> {
        let bad = |what: &str| Err(SimulateError::InvalidParameter(what.to_string()));
        if self.rays == 0 {
            return bad("rays must be at least 1");
        }
        if !(self.fov >= 0.0 && self.fov <= 2.0 * std::f64::consts::PI) {
            return bad("the field of view must be between 0 and 360 degrees");
        }
        if !(self.max_range > 0.0 && self.max_range.is_finite()) {
            return bad("the maximum range must be a positive number of metres");
        }
        if !(self.noise_sigma >= 0.0 && self.noise_sigma.is_finite()) {
            return bad("the range noise must be zero or a positive number of metres");
        }
        if self
            .hinge_offset
            .is_some_and(|o| o.iter().any(|v| !v.is_finite()))
        {
            return bad("the hinge offset must be three finite numbers");
        }
        if !(self.scan_rate > 0.0 && self.scan_rate.is_finite()) {
            return bad("the scan rate must be a positive number of scans per second");
        }
        if !self.sweep_rate.is_finite() {
            return bad("the sweep rate must be a finite number of degrees per second");
        }
        // Past a full turn within one scan the per-ray elevations are no longer angles the
        // scan readers take (`formats::limits::MAX_ANGLE`).
        if sweep::half_travel(self.rays, self.sweep_rate, self.scan_time()) > std::f64::consts::PI {
            return bad("the hinge may turn at most 360 degrees within one scan");
        }
        Ok(())
    }
}

/// `n` hinge elevations `step` apart, centred on level \[rad\], in increasing order: 3 scans
/// 5 degrees apart give -5, 0, +5 degrees (positive tilts the beams down).
pub fn elevations_centred(n: usize, step: f64) -> Vec<f64> {
    let mid = (n as f64 - 1.0) / 2.0;
    (0..n).map(|i| (i as f64 - mid) * step).collect()
}

/// Simulates the scans a robot at `world_from_robot` takes, one per elevation, in the order
/// given. Each ray starts at `world_from_robot · Ry(e)·o` and runs along
/// `R · Ry(e)·(cos phi, sin phi, 0)` (contract); its reading is the true range plus Gaussian
/// noise, and a noisy reading that comes out at or below zero is no reading. The `hit` labels
/// are the truth of what each ray met, whatever the noise did to its reading.
///
/// With a hinge that moves while it scans (`params.sweep_rate`), ray `i` is cast at its own
/// elevation ([`sweep::ray_elevations`], centred on the scan's) and the scan carries it as
/// `ray_elevation`; `elevation` stays the nominal one.
///
/// Fills `sequence`, `elevation`, `ray_elevation`, `theta`, `readings`, `valid`, `hit`, `true_pose`, and
/// `hinge_offset` and `readings_sigma` when the parameters ask for them; `odometry` is left to
/// the caller (it depends on the poses before this one).
pub fn simulate_pose<R: Rng + ?Sized>(
    world: &World,
    sequence: u64,
    world_from_robot: &Pose,
    elevations: &[f64],
    params: &ScannerParams,
    rng: &mut R,
) -> Vec<Scan> {
    let bearings = params.bearings();
    let iso = world_from_robot.world_from_robot();
    let offset = params
        .hinge_offset
        .map_or_else(Vector3::zeros, |o| Vector3::new(o[0], o[1], o[2]));
    elevations
        .iter()
        .map(|&e| {
            // A still hinge casts every ray from one origin; a moving one from each ray's own.
            let ray_elevation =
                sweep::ray_elevations(e, bearings.len(), params.sweep_rate, params.scan_time());
            let origin = iso * beam_origin(e, &offset);
            let mut readings = Vec::with_capacity(bearings.len());
            let mut valid = Vec::with_capacity(bearings.len());
            let mut hits = Vec::with_capacity(bearings.len());
            for (i, &phi) in bearings.iter().enumerate() {
                let (origin, e) = match &ray_elevation {
                    Some(own) => (iso * beam_origin(own[i], &offset), own[i]),
                    None => (origin, e),
                };
                let direction = iso * beam_direction(e, phi);
                match world.cast(&origin, &direction, params.max_range) {
                    Some(h) => {
                        let r = h.range + params.noise_model.draw(params.noise_sigma, rng);
                        readings.push((r > 0.0).then_some(r));
                        valid.push(r > 0.0);
                        hits.push(h.hit);
                    }
                    None => {
                        readings.push(None);
                        valid.push(false);
                        hits.push(Hit::Nothing);
                    }
                }
            }
            Scan {
                sequence: Some(sequence),
                elevation: Some(e),
                ray_elevation,
                theta: bearings.clone(),
                readings,
                valid,
                true_pose: Some(*world_from_robot),
                readings_sigma: params
                    .write_sigma
                    .then(|| vec![Some(params.range_sigma()); bearings.len()]),
                hinge_offset: params.hinge_offset,
                hit: Some(hits),
                ..Scan::default()
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::rot_y;
    use crate::plan::{Plan, box_plan};
    use nalgebra::{Point2, Point3};
    use proptest::prelude::*;
    use rand::SeedableRng;
    use rand::rngs::ChaCha8Rng;

    const DEG: f64 = std::f64::consts::PI / 180.0;

    fn noiseless() -> ScannerParams {
        ScannerParams {
            noise_sigma: 0.0,
            ..ScannerParams::default()
        }
    }

    fn rng() -> ChaCha8Rng {
        ChaCha8Rng::seed_from_u64(7)
    }

    #[test]
    fn elevations_are_centred_on_level() {
        assert_eq!(elevations_centred(3, 5.0), vec![-5.0, 0.0, 5.0]);
        assert_eq!(elevations_centred(4, 2.0), vec![-3.0, -1.0, 1.0, 3.0]);
        assert_eq!(elevations_centred(1, 5.0), vec![0.0]);
        assert!(elevations_centred(0, 5.0).is_empty());
    }

    #[test]
    fn level_scan_in_box_room_matches_analytic_ranges() {
        // 10 x 6 m room, robot at (4, 3) facing +x: walls 6 m ahead, 3 m left and right.
        let world = World::from_plan(&box_plan(10.0, 6.0, 3.0, false));
        let pose = Pose::new(4.0, 3.0, 0.45, 0.0, 0.0, 0.0);
        let scans = simulate_pose(&world, 0, &pose, &[0.0], &noiseless(), &mut rng());
        let s = &scans[0];
        assert_eq!(s.nrays(), 181);
        // Rays at -90, 0 and +90 degrees, and at 45 degrees (the right-front corner is at
        // (10, 0): -26.6 deg, so +45 deg meets the left wall at y = 6: range 3·sqrt 2).
        for (i, want) in [(0, 3.0), (90, 6.0), (180, 3.0), (135, 3.0 * 2f64.sqrt())] {
            assert!((s.readings[i].unwrap() - want).abs() < 1e-9, "ray {i}");
            assert_eq!(s.hit.as_ref().unwrap()[i], Hit::Wall);
        }
        // Every ray of a level scan inside a closed room hits a wall.
        assert_eq!(s.valid_count(), 181);
    }

    #[test]
    fn yawed_robot_sees_the_room_rotated() {
        let world = World::from_plan(&box_plan(10.0, 6.0, 3.0, false));
        let pose = Pose::new(4.0, 3.0, 0.45, 90.0 * DEG, 0.0, 0.0);
        let s = &simulate_pose(&world, 0, &pose, &[0.0], &noiseless(), &mut rng())[0];
        // Facing +y: ahead 3 m, right (-90) is +x: 6 m, left is -x: 4 m.
        for (i, want) in [(90, 3.0), (0, 6.0), (180, 4.0)] {
            assert!((s.readings[i].unwrap() - want).abs() < 1e-9, "ray {i}");
        }
    }

    #[test]
    fn beam_tilted_down_hits_floor_at_height_over_sine() {
        // Level robot at height h, bearing 0, elevation e down: floor at h / sin e, before
        // the wall 30 m away.
        let world = World::from_plan(&box_plan(60.0, 20.0, 3.0, false));
        let h = 0.45;
        for e_deg in [2.0, 5.0, 10.0, 30.0] {
            let e = e_deg * DEG;
            let pose = Pose::new(10.0, 10.0, h, 0.0, 0.0, 0.0);
            let s = &simulate_pose(&world, 0, &pose, &[e], &noiseless(), &mut rng())[0];
            assert_eq!(s.hit.as_ref().unwrap()[90], Hit::Floor);
            assert!((s.readings[90].unwrap() - h / e.sin()).abs() < 1e-9);
        }
    }

    #[test]
    fn beam_tilted_up_hits_ceiling_at_clearance_over_sine() {
        let world = World::from_plan(&box_plan(60.0, 20.0, 2.4, true));
        let h = 0.45;
        let e = -10.0 * DEG;
        let pose = Pose::new(10.0, 10.0, h, 0.0, 0.0, 0.0);
        let s = &simulate_pose(&world, 0, &pose, &[e], &noiseless(), &mut rng())[0];
        assert_eq!(s.hit.as_ref().unwrap()[90], Hit::Ceiling);
        assert!((s.readings[90].unwrap() - (2.4 - h) / (-e).sin()).abs() < 1e-9);
        // Without a ceiling the same beam clears the 2.4 m walls 50 m away: beyond 30 m.
        let open = World::from_plan(&box_plan(60.0, 20.0, 2.4, false));
        let s = &simulate_pose(&open, 0, &pose, &[e], &noiseless(), &mut rng())[0];
        assert_eq!(s.hit.as_ref().unwrap()[90], Hit::Nothing);
        assert!(!s.valid[90] && s.readings[90].is_none());
    }

    #[test]
    fn hinge_offset_moves_points_as_the_contract_says() {
        // Scanner origin 0.1 m ahead of and 0.2 m above the hinge; beam tilted down 20 deg
        // from a robot 1 m up: the beam starts at Ry(e)·o and meets the floor there.
        let world = World::from_plan(&box_plan(60.0, 20.0, 3.0, false));
        let o = [0.1, 0.0, 0.2];
        let e = 20.0 * DEG;
        let params = ScannerParams {
            hinge_offset: Some(o),
            ..noiseless()
        };
        let pose = Pose::new(10.0, 10.0, 1.0, 0.0, 0.0, 0.0);
        let s = &simulate_pose(&world, 0, &pose, &[e], &params, &mut rng())[0];
        assert_eq!(s.hinge_offset, Some(o));
        let start = rot_y(e) * Vector3::new(0.1, 0.0, 0.2);
        let height = 1.0 + start.z;
        let want = height / e.sin();
        assert!((s.readings[90].unwrap() - want).abs() < 1e-9);
        // The reading, put back with the offset, is a floor point in the world.
        let p = pose.world_from_robot() * s.point_in_robot(90).unwrap();
        assert!(p.z.abs() < 1e-9);
        assert!((p.x - (10.0 + start.x + want * e.cos())).abs() < 1e-9);
        // Without the offset the same reading would be placed wrongly.
        let plain = Scan {
            hinge_offset: None,
            ..s.clone()
        };
        let q = pose.world_from_robot() * plain.point_in_robot(90).unwrap();
        assert!((q - p).norm() > 0.1);
    }

    #[test]
    fn rays_meeting_nothing_are_invalid() {
        // A single wall behind the robot; a level robot sees nothing ahead or sideways.
        let plan = Plan {
            wall_height: 3.0,
            walls: vec![vec![Point2::new(-1.0, -5.0), Point2::new(-1.0, 5.0)]],
            ceiling: false,
            poses: vec![],
        };
        let world = World::from_plan(&plan);
        let pose = Pose::new(0.0, 0.0, 0.45, 0.0, 0.0, 0.0);
        let s = &simulate_pose(
            &world,
            3,
            &pose,
            &[0.0],
            &ScannerParams::default(),
            &mut rng(),
        )[0];
        assert_eq!(s.sequence, Some(3));
        assert_eq!(s.valid_count(), 0);
        assert!(s.readings.iter().all(Option::is_none));
        assert!(s.hit.as_ref().unwrap().iter().all(|&h| h == Hit::Nothing));
        assert!(s.valid.iter().all(|&v| !v));
    }

    #[test]
    fn noise_has_the_requested_spread() {
        let world = World::from_plan(&box_plan(10.0, 6.0, 3.0, false));
        let pose = Pose::new(4.0, 3.0, 1.0, 0.0, 0.0, 0.0);
        let params = ScannerParams {
            noise_sigma: 0.05,
            write_sigma: true,
            ..ScannerParams::default()
        };
        let clean = &simulate_pose(&world, 0, &pose, &[0.0], &noiseless(), &mut rng())[0];
        let mut r = rng();
        let mut errs = Vec::new();
        for _ in 0..20 {
            let s = &simulate_pose(&world, 0, &pose, &[0.0], &params, &mut r)[0];
            assert_eq!(s.readings_sigma.as_ref().unwrap()[0], Some(0.05));
            for i in 0..s.nrays() {
                errs.push(s.readings[i].unwrap() - clean.readings[i].unwrap());
            }
        }
        let n = errs.len() as f64;
        let mean = errs.iter().sum::<f64>() / n;
        let sd = (errs.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / n).sqrt();
        assert!(mean.abs() < 0.005, "mean {mean}");
        assert!((sd - 0.05).abs() < 0.005, "sd {sd}");
    }

    #[test]
    fn same_rng_state_gives_same_scans() {
        let world = World::from_plan(&box_plan(10.0, 6.0, 3.0, false));
        let pose = Pose::new(4.0, 3.0, 0.45, 0.3, 0.1, -0.1);
        let e = elevations_centred(3, 5.0 * DEG);
        let p = ScannerParams::default();
        let a = simulate_pose(&world, 0, &pose, &e, &p, &mut rng());
        let b = simulate_pose(&world, 0, &pose, &e, &p, &mut rng());
        assert_eq!(a, b);
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(48))]

        /// Every valid simulated point, put back in the world with the true pose, lies on a
        /// surface of the kind its label says.
        #[test]
        fn simulated_points_lie_on_their_labelled_surface(
            x in 1.0f64..9.0, y in 1.0f64..5.0, z in 0.2f64..1.5,
            rz in -3.2f64..3.2, ry in -0.4f64..0.4, rx in -0.4f64..0.4,
            ceiling in any::<bool>(), offset in any::<bool>(), sigma in 0.0f64..0.05,
            seed in any::<u64>(),
        ) {
            let mut plan = box_plan(10.0, 6.0, 2.5, ceiling);
            // A pillar, so some rays meet walls inside the room.
            plan.walls.push(vec![
                Point2::new(6.0, 4.0), Point2::new(6.5, 4.0), Point2::new(6.5, 4.5),
                Point2::new(6.0, 4.5), Point2::new(6.0, 4.0),
            ]);
            let world = World::from_plan(&plan);
            let params = ScannerParams {
                rays: 61,
                noise_sigma: sigma,
                hinge_offset: offset.then_some([0.05, -0.02, 0.1]),
                ..ScannerParams::default()
            };
            let pose = Pose::new(x, y, z, rz, ry, rx);
            let e = elevations_centred(5, 5.0 * DEG);
            let mut r = ChaCha8Rng::seed_from_u64(seed);
            let scans = simulate_pose(&world, 0, &pose, &e, &params, &mut r);
            let iso = pose.world_from_robot();
            let tol = 6.0 * sigma + 1e-9;
            let segments = plan.segments();
            for s in &scans {
                for i in 0..s.nrays() {
                    let Some(p) = s.point_in_robot(i) else { continue };
                    let w: Point3<f64> = iso * p;
                    let label = s.hit.as_ref().unwrap()[i];
                    let on_wall = || {
                        let q = Point2::new(w.x, w.y);
                        segments.iter().any(|sg| sg.distance_to(&q) <= tol)
                            && w.z >= -tol && w.z <= plan.wall_height + tol
                    };
                    match label {
                        Hit::Floor => prop_assert!(w.z.abs() <= tol, "floor point at z {}", w.z),
                        Hit::Ceiling => prop_assert!((w.z - 2.5).abs() <= tol),
                        Hit::Wall => prop_assert!(on_wall(), "wall point {w:?}"),
                        Hit::Nothing => prop_assert!(false, "valid ray labelled nothing"),
                    }
                }
            }
        }
    }
}
