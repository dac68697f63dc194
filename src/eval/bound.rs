//! How well could any leveler do? The Cramér-Rao bound on a pose's attitude.
//!
//! A range is a function of the attitude and of where the surface it met lies: for a ray from
//! `o` along `u` (robot frame) meeting the plane `n . x = d` of the yaw-free level frame
//! (`level_from_robot = Ry(theta_y) Rx(theta_x)`, `L` below), `r = (d - n . L o) / (n . L u)`.
//! The floor and ceiling are level planes at unknown heights `d`; a wall is a vertical plane at
//! an unknown azimuth and offset. With Gaussian range noise `sigma`, the Fisher information of
//! the attitude, once every surface's placement is marginalised out, bounds the covariance of
//! any unbiased attitude estimate from below (Kay 1993, *Fundamentals of Statistical Signal
//! Processing: Estimation Theory*, ch. 3).
//!
//! The bound is given which surface every ray met, which no leveler knows, so it cannot be
//! beaten. A leveler's honest sigma over this bound says how much of the data's information it
//! uses; the share of poses whose bound stays inside the leveling gate is the most that any
//! leveler with that gate and honest sigmas could level.
//!
//! [`segmented_solution`] is the robust estimator told that segmentation: how far it stays
//! from the bound is what a leveler loses by using the surfaces' points through plane fits;
//! how far a leveler stays from it, what it loses to finding the surfaces.
//!
//! Pure: rays in, sigmas out; [`pose_rays`] builds the rays from the simulator's world.

use crate::geometry::{Pose, beam_direction, beam_origin};
use crate::level::LevelParams;
use crate::level::grid::{GridPoint, PlaneAccumulator, PlaneFit};
use crate::level::ml::model::Rotations;
use crate::level::up::{self, PlaneObs, UpSolution};
use crate::plan::Segment;
use crate::scan::{Hit, Scan};
use crate::simulate::World;
use nalgebra::{Matrix2, Matrix3, Point2, Point3, Vector2, Vector3};
use std::collections::BTreeMap;

/// The surface a ray met: the floor, the ceiling, or a wall plane (an index into
/// [`WallPlanes`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Surface {
    Floor,
    Ceiling,
    Wall(usize),
}

/// One noise-free ray of a pose: robot-frame origin and unit direction, its range, and the
/// surface it met with that surface's unit normal in the world frame; also the range the
/// scanner reported and the index of its scan among the pose's scans.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoundRay {
    pub origin: Point3<f64>,
    pub dir: Vector3<f64>,
    pub range: f64,
    pub surface: Surface,
    pub normal_world: Vector3<f64>,
    pub measured: f64,
    pub scan: usize,
    /// The ray's index in its scan.
    pub col: usize,
}

/// A plan's walls as planes: segments on one line are one plane (a wall interrupted by a door
/// is still one plane to estimate).
#[derive(Clone, Debug)]
pub struct WallPlanes {
    /// Unit normal and offset of each plane's line (`normal . p = offset`).
    lines: Vec<(Vector2<f64>, f64)>,
    /// Each segment with its plane.
    segments: Vec<(Segment, usize)>,
}

/// Two segments share a line when their lines agree this closely [m, and rad].
const SAME_LINE: f64 = 1e-9;
/// A wall hit lies this close to its segment \[m\] (the ray caster's rounding is far smaller).
const ON_SEGMENT: f64 = 1e-6;

impl WallPlanes {
    pub fn new(segments: &[Segment]) -> Self {
        let mut lines: Vec<(Vector2<f64>, f64)> = Vec::new();
        let mut out = Vec::new();
        for seg in segments {
            let Some(dir) = (seg.b - seg.a).try_normalize(0.0) else {
                continue;
            };
            // One orientation per line, so that a line's two walks give one normal.
            let mut normal = Vector2::new(-dir.y, dir.x);
            if normal.x < 0.0 || (normal.x == 0.0 && normal.y < 0.0) {
                normal = -normal;
            }
            let offset = normal.dot(&seg.a.coords);
            let plane = lines
                .iter()
                .position(|(n, d)| {
                    (n - normal).norm() < SAME_LINE && (d - offset).abs() < SAME_LINE
                })
                .unwrap_or_else(|| {
                    lines.push((normal, offset));
                    lines.len() - 1
                });
            out.push((*seg, plane));
        }
        WallPlanes {
            lines,
            segments: out,
        }
    }

    /// Number of distinct wall planes.
    pub fn len(&self) -> usize {
        self.lines.len()
    }

    pub fn is_empty(&self) -> bool {
        self.lines.is_empty()
    }

    /// The plane of the wall through the world point `p`, if one passes there.
    pub fn locate(&self, p: &Point2<f64>) -> Option<usize> {
        self.segments
            .iter()
            .find(|(seg, _)| seg.distance_to(p) < ON_SEGMENT)
            .map(|&(_, plane)| plane)
    }

    /// A plane's line in the world's plan: unit normal and offset (`normal . p = offset`).
    pub fn line(&self, plane: usize) -> (Vector2<f64>, f64) {
        self.lines[plane]
    }

    /// Unit normal of a plane in the world frame.
    pub fn normal(&self, plane: usize) -> Vector3<f64> {
        let n = self.lines[plane].0;
        Vector3::new(n.x, n.y, 0.0)
    }
}

/// The noise-free rays of a pose's scans that met a surface within `max_range`: those whose
/// reading is valid, as the simulator cast them from the true pose.
pub fn pose_rays(
    world: &World,
    planes: &WallPlanes,
    scans: &[Scan],
    truth: &Pose,
    max_range: f64,
) -> Vec<BoundRay> {
    let world_from_robot = truth.world_from_robot();
    let mut rays = Vec::new();
    for (k, scan) in scans.iter().enumerate() {
        if scan.elevation.is_none() {
            continue;
        }
        let offset = scan
            .hinge_offset
            .map_or_else(Vector3::zeros, |o| Vector3::new(o[0], o[1], o[2]));
        for (i, &bearing) in scan.theta.iter().enumerate() {
            let Some(measured) = scan.range(i) else {
                continue;
            };
            // Each ray at its own hinge elevation when the hinge moved while it scanned.
            let elevation = scan.elevation_of_ray(i);
            let origin = beam_origin(elevation, &offset);
            let origin_world = world_from_robot * origin;
            let dir = beam_direction(elevation, bearing);
            let dir_world = world_from_robot * dir;
            let Some(hit) = world.cast(&origin_world, &dir_world, max_range) else {
                continue;
            };
            let (surface, normal_world) = match hit.hit {
                Hit::Floor => (Surface::Floor, Vector3::z()),
                Hit::Ceiling => (Surface::Ceiling, Vector3::z()),
                Hit::Wall => {
                    let p = origin_world + dir_world * hit.range;
                    let Some(plane) = planes.locate(&Point2::new(p.x, p.y)) else {
                        continue;
                    };
                    (Surface::Wall(plane), planes.normal(plane))
                }
                Hit::Nothing => continue,
            };
            rays.push(BoundRay {
                origin,
                dir,
                range: hit.range,
                surface,
                normal_world,
                measured,
                scan: k,
                col: i,
            });
        }
    }
    rays
}

/// The true attitude's rotations and their derivatives, shared by a pose's rays.
struct Linearization {
    level_from_robot: Matrix3<f64>,
    /// `d level_from_robot / d theta_x` and `/ d theta_y`.
    by_theta: [Matrix3<f64>; 2],
    /// Sine and cosine of minus the yaw: world normals into the yaw-free level frame (the
    /// floor's and ceiling's stay up).
    unyaw: (f64, f64),
}

impl Linearization {
    fn at(truth: &Pose) -> Self {
        let rot = Rotations::at(&Vector2::new(truth.rx, truth.ry));
        Linearization {
            level_from_robot: rot.level_from_robot,
            by_theta: rot.by_theta,
            unyaw: (-truth.rz).sin_cos(),
        }
    }

    /// The derivatives of one ray's range: by `(theta_x, theta_y)`, and by its surface's
    /// placement `(offset, azimuth)`. The azimuth's tangent vanishes for the floor and
    /// ceiling, whose normal is up whatever the attitude.
    fn gradient(&self, ray: &BoundRay) -> ([f64; 2], [f64; 2]) {
        let (s, c) = self.unyaw;
        let n = ray.normal_world;
        let normal = Vector3::new(c * n.x - s * n.y, s * n.x + c * n.y, n.z);
        let q = ray.origin.coords + ray.dir * ray.range;
        let b = normal.dot(&(self.level_from_robot * ray.dir));
        let attitude = self.by_theta.map(|d| -normal.dot(&(d * q)) / b);
        let tangent = Vector3::new(-normal.y, normal.x, 0.0);
        let azimuth = -tangent.dot(&(self.level_from_robot * q)) / b;
        (attitude, [1.0 / b, azimuth])
    }
}

/// 1-sigma bounds on `theta_x` and `theta_y` \[rad\] for range noise `sigma` \[m\]; `None` when
/// the rays cannot fix the attitude (a corridor's parallel walls alone) or `sigma` is not
/// positive.
pub fn attitude_bound(rays: &[BoundRay], truth: &Pose, sigma: f64) -> Option<[f64; 2]> {
    let cov = attitude_bound_cov(rays, truth, sigma)?;
    Some([cov[(0, 0)].sqrt(), cov[(1, 1)].sqrt()])
}

/// The bound's whole 2x2 covariance of `(theta_x, theta_y)` \[rad^2\] (the axes are
/// correlated); `None` as for [`attitude_bound`].
pub fn attitude_bound_cov(rays: &[BoundRay], truth: &Pose, sigma: f64) -> Option<Matrix2<f64>> {
    if sigma.is_nan() || sigma <= 0.0 {
        return None;
    }
    // Each ray meets one surface, so the placements' information is block-diagonal and each
    // surface is marginalised on its own: S = F_aa - sum_k F_ak F_kk^+ F_ka.
    // Per surface: its cross information with the attitude, and its own.
    let mut blocks: Vec<(Surface, Matrix2<f64>, Matrix2<f64>)> = Vec::new();
    let mut info = Matrix2::zeros();
    let linear = Linearization::at(truth);
    for ray in rays {
        let (a, n) = linear.gradient(ray);
        let (a, n) = (Vector2::from(a), Vector2::from(n));
        if !a.iter().chain(&n).all(|v| v.is_finite()) {
            continue;
        }
        let k = match blocks.iter().position(|b| b.0 == ray.surface) {
            Some(k) => k,
            None => {
                blocks.push((ray.surface, Matrix2::zeros(), Matrix2::zeros()));
                blocks.len() - 1
            }
        };
        info += a * a.transpose();
        blocks[k].1 += a * n.transpose();
        blocks[k].2 += n * n.transpose();
    }
    let scale = info.trace();
    if scale.is_nan() || scale <= 0.0 {
        return None;
    }
    for (_, cross, own) in &blocks {
        let eps = own.norm() * 1e-12;
        let own_inv = own.pseudo_inverse(eps).ok()?;
        info -= cross * own_inv * cross.transpose();
    }
    let info = (info + info.transpose()) * 0.5;
    let eig = info.symmetric_eigenvalues();
    if eig.min() <= scale * 1e-10 {
        return None;
    }
    Some(info.try_inverse()? * (sigma * sigma))
}

/// Before [`segmented_solution`] fits a surface, the scan with its second most points must
/// hold at least this share of the points of the scan with the most. A surface met by one
/// scan is a line, which leaves its plane free to turn about it, and a few points off the
/// line pin it down too loosely for a linearized sigma to be trusted (traced: a floor of 66
/// points in one scan and 5 in the next reported sigmas about a quarter of the bound).
const SEGMENTED_MIN_SHARE: f64 = 0.2;

/// Up as the robust estimator finds it when told which surface every point met: each surface
/// met by at least two scans in comparable numbers (`SEGMENTED_MIN_SHARE`) fitted as a plane
/// from the measured points, walls taken as vertical and the floor and ceiling as level, with
/// no inflation ([`up::up_robust`]). Between the bound and a leveler's own sigma, its sigma tells
/// how much is lost to finding the surfaces rather than to using them; `None` when those
/// planes cannot fix up.
pub fn segmented_solution(rays: &[BoundRay], sigma: f64) -> Option<UpSolution> {
    let mut surfaces: Vec<(Surface, PlaneAccumulator, BTreeMap<usize, usize>)> = Vec::new();
    for ray in rays {
        let k = match surfaces.iter().position(|s| s.0 == ray.surface) {
            Some(k) => k,
            None => {
                surfaces.push((ray.surface, PlaneAccumulator::default(), BTreeMap::new()));
                surfaces.len() - 1
            }
        };
        let point = GridPoint {
            p: ray.origin + ray.dir * ray.measured,
            dir: ray.dir,
            range: ray.measured,
        };
        surfaces[k].1.add(&point);
        *surfaces[k].2.entry(ray.scan).or_default() += 1;
    }
    let fits: Vec<(Surface, PlaneFit)> = surfaces
        .iter()
        .filter(|(_, _, per_scan)| {
            let mut counts: Vec<usize> = per_scan.values().copied().collect();
            counts.sort_unstable_by(|a, b| b.cmp(a));
            counts.len() >= 2 && counts[1] as f64 >= SEGMENTED_MIN_SHARE * counts[0] as f64
        })
        .filter_map(|(surface, acc, _)| Some((*surface, acc.fit(sigma)?)))
        .collect();
    let obs: Vec<PlaneObs> = fits
        .iter()
        .map(|(surface, fit)| match surface {
            Surface::Wall(_) => PlaneObs::wall(fit, 1.0),
            Surface::Floor | Surface::Ceiling => PlaneObs::level(fit, 1.0),
        })
        .collect();
    up::up_robust(&obs, sigma, LevelParams::default().iterations)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::{Plan, box_plan};
    use crate::simulate::{ScannerParams, elevations_centred, simulate_pose};
    use proptest::prelude::*;
    use rand::SeedableRng;
    use rand::rngs::ChaCha8Rng;

    const DEG: f64 = std::f64::consts::PI / 180.0;

    fn rays_at(plan: &Plan, pose: &Pose, elevations: &[f64]) -> Vec<BoundRay> {
        noisy_rays_at(plan, pose, elevations, 0.0, 1)
    }

    fn noisy_rays_at(
        plan: &Plan,
        pose: &Pose,
        elevations: &[f64],
        noise: f64,
        seed: u64,
    ) -> Vec<BoundRay> {
        let world = World::from_plan(plan);
        let scanner = ScannerParams {
            noise_sigma: noise,
            ..ScannerParams::default()
        };
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let scans = simulate_pose(&world, 0, pose, elevations, &scanner, &mut rng);
        let planes = WallPlanes::new(&plan.segments());
        pose_rays(&world, &planes, &scans, pose, scanner.max_range)
    }

    fn pose(x: f64, y: f64, rz: f64, ry: f64, rx: f64) -> Pose {
        Pose {
            x,
            y,
            z: 0.45,
            rz,
            ry,
            rx,
        }
    }

    /// The analytic derivatives by the attitude agree with ranges cast again from a slightly
    /// turned robot (the walls, floor and ceiling staying where they are).
    #[test]
    fn gradient_matches_recast_ranges() {
        let plan = box_plan(6.0, 4.0, 3.0, true);
        let world = World::from_plan(&plan);
        let truth = pose(2.0, 1.5, 0.4, 7.0 * DEG, -11.0 * DEG);
        let rays = rays_at(&plan, &truth, &elevations_centred(3, 5.0 * DEG));
        assert!(rays.len() > 400);
        let h = 1e-7;
        let recast = |ray: &BoundRay, p: &Pose| {
            let iso = p.world_from_robot();
            world
                .cast(&(iso * ray.origin), &(iso * ray.dir), 30.0)
                .map(|hit| hit.range)
        };
        let linear = Linearization::at(&truth);
        let mut checked = 0;
        for ray in &rays {
            let (g, _) = linear.gradient(ray);
            let bumped = [
                Pose {
                    rx: truth.rx + h,
                    ..truth
                },
                Pose {
                    ry: truth.ry + h,
                    ..truth
                },
            ];
            for (k, p) in bumped.iter().enumerate() {
                // A ray at an edge may meet another surface once turned (a jump in range).
                let Some(r) = recast(ray, p).filter(|r| (r - ray.range).abs() < 1e-3) else {
                    continue;
                };
                let numeric = (r - ray.range) / h;
                assert!(
                    (numeric - g[k]).abs() < 1e-4 * (1.0 + g[k].abs()),
                    "ray {ray:?} k {k}: numeric {numeric}, analytic {}",
                    g[k]
                );
                checked += 1;
            }
        }
        assert!(checked > 800, "only {checked} derivatives checked");
    }

    /// Floor alone, robot level: the bound is the covariance of the weighted plane fit
    /// `b r = d - y theta_x + x theta_y` (b the ray's vertical direction), in closed form.
    #[test]
    fn floor_only_bound_is_the_weighted_plane_fit() {
        let truth = pose(0.0, 0.0, 0.0, 0.0, 0.0);
        let rays: Vec<BoundRay> = (0..40)
            .map(|i| {
                let bearing = -1.2 + 0.06 * i as f64;
                let elevation = if i % 2 == 0 { 10.0 * DEG } else { 20.0 * DEG };
                let dir = beam_direction(elevation, bearing);
                BoundRay {
                    origin: Point3::origin(),
                    dir,
                    range: 0.45 / -dir.z,
                    surface: Surface::Floor,
                    normal_world: Vector3::z(),
                    measured: 0.45 / -dir.z,
                    scan: i % 2,
                    col: i,
                }
            })
            .collect();
        let sigma = 0.03;
        let mut xtx = nalgebra::Matrix3::zeros();
        for r in &rays {
            let q = r.dir * r.range;
            let row = Vector3::new(1.0, -q.y, q.x) / r.dir.z;
            xtx += row * row.transpose();
        }
        let cov = xtx.try_inverse().unwrap() * sigma * sigma;
        let bound = attitude_bound(&rays, &truth, sigma).unwrap();
        assert!((bound[0] - cov[(1, 1)].sqrt()).abs() < 1e-9 * bound[0].max(1e-12));
        assert!((bound[1] - cov[(2, 2)].sqrt()).abs() < 1e-9 * bound[1].max(1e-12));
    }

    /// Two parallel walls and nothing else leave the tilt about their normal free.
    #[test]
    fn a_corridor_seen_level_has_no_bound() {
        let corridor = Plan {
            wall_height: 3.0,
            walls: vec![
                vec![Point2::new(-50.0, 0.0), Point2::new(50.0, 0.0)],
                vec![Point2::new(-50.0, 2.0), Point2::new(50.0, 2.0)],
            ],
            ceiling: false,
            poses: vec![],
        };
        // Level and looking up: no ray reaches the floor.
        let truth = pose(0.0, 1.0, 0.0, 0.0, 0.0);
        let rays = rays_at(&corridor, &truth, &[-10.0 * DEG, -5.0 * DEG, 0.0]);
        assert!(rays.iter().all(|r| matches!(r.surface, Surface::Wall(_))));
        assert!(rays.len() > 300);
        assert_eq!(attitude_bound(&rays, &truth, 0.01), None);
    }

    /// Told which surface every point met, the robust estimator is honest (the true attitude
    /// within 3 of its sigmas) and, to first order, no better than the bound.
    #[test]
    fn segmented_solution_is_honest_and_no_better_than_the_bound() {
        let plan = box_plan(6.0, 4.0, 2.5, true);
        let noise = 0.05;
        let mut within = 0;
        let poses = 40;
        for k in 0..poses {
            let f = k as f64;
            let truth = pose(
                1.0 + (f * 0.37) % 4.0,
                1.0 + (f * 0.53) % 2.0,
                f * 0.7,
                ((f * 7.3) % 40.0 - 20.0) * DEG,
                ((f * 3.1) % 40.0 - 20.0) * DEG,
            );
            let rays = noisy_rays_at(&plan, &truth, &elevations_centred(3, 5.0 * DEG), noise, k);
            let bound = attitude_bound(&rays, &truth, noise).unwrap();
            let sol = segmented_solution(&rays, noise).unwrap();
            let sigma = sol.attitude_sigmas();
            let (est, t) = (sol.attitude(), truth.attitude());
            let err = [est.theta_x - t.theta_x, est.theta_y - t.theta_y];
            for a in 0..2 {
                assert!(
                    sigma[a] >= 0.8 * bound[a],
                    "pose {k}: {sigma:?} vs {bound:?}"
                );
            }
            if (0..2).all(|a| err[a].abs() <= 3.0 * sigma[a]) {
                within += 1;
            }
        }
        assert!(within >= poses - 2, "{within} of {poses} within 3 sigma");
    }

    #[test]
    fn collinear_segments_are_one_plane() {
        let segs = [
            Segment {
                a: Point2::new(8.0, 0.0),
                b: Point2::new(8.0, 2.0),
            },
            Segment {
                a: Point2::new(8.0, 6.0),
                b: Point2::new(8.0, 3.4),
            },
            Segment {
                a: Point2::new(0.0, 0.0),
                b: Point2::new(8.0, 0.0),
            },
        ];
        let planes = WallPlanes::new(&segs);
        assert_eq!(planes.len(), 2);
        assert_eq!(
            planes.locate(&Point2::new(8.0, 1.0)),
            planes.locate(&Point2::new(8.0, 5.0))
        );
        assert_eq!(planes.locate(&Point2::new(8.0, 2.7)), None);
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(24))]

        /// The bound scales with the noise, and more scans (a superset of the rays) never
        /// loosen it.
        #[test]
        fn bound_scales_with_noise_and_tightens_with_scans(
            x in 1.0f64..5.0, y in 1.0f64..3.0, rz in -3.0f64..3.0,
            ry in -20.0f64..20.0, rx in -20.0f64..20.0,
        ) {
            let plan = box_plan(6.0, 4.0, 3.0, false);
            let truth = pose(x, y, rz, ry * DEG, rx * DEG);
            let three = rays_at(&plan, &truth, &elevations_centred(3, 5.0 * DEG));
            let five = rays_at(&plan, &truth, &elevations_centred(5, 5.0 * DEG));
            let b1 = attitude_bound(&three, &truth, 0.01).unwrap();
            let b2 = attitude_bound(&three, &truth, 0.02).unwrap();
            let b5 = attitude_bound(&five, &truth, 0.01).unwrap();
            for k in 0..2 {
                prop_assert!((b2[k] - 2.0 * b1[k]).abs() < 1e-9 * b2[k]);
                prop_assert!(b5[k] <= b1[k] * (1.0 + 1e-9));
            }
        }
    }
}
