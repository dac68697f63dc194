//! How well could any estimator place a whole run? The Cramér-Rao bound on a path's poses.
//!
//! [`pair_bound`](super::pair_bound) bounds one step from two scans. A run's ATE also depends
//! on what ties steps together: the odometry between them, and walls seen from many poses.
//! Here every pose of the run after the first (the gauge: the run starts where its odometry
//! does) and every wall seen are unknowns; each ray's range is a measurement of the scanner's
//! pose and the wall it met (Gaussian noise `sigma` along the ray), and each odometry step a
//! measurement of the motion between two poses (Gaussian, the simulator's noise model). The
//! walls are unknown lines, marginalised out, as in the pair bound; grouping a plan's
//! segments on one line into one wall ([`WallPlanes`]) is knowledge no matcher has, so the
//! bound stays a lower bound (Kay 1993, ch. 3).
//!
//! Two figures come out:
//! - [`PathBound::ate`]: the ATE an efficient estimator that saw the whole run at once (a
//!   smoother) would show, in expectation: errors drawn from the bound's joint covariance of
//!   all poses, scored like a run ([`ate`]). No unbiased estimator, causal or not, has a
//!   smaller error covariance.
//! - [`PathBound::causal_rms`]: the root mean square over poses of the position sigma an
//!   efficient estimator has when it places each pose from the scans and odometry up to it
//!   (a filter, as `match` is), without the ATE's alignment.
//!
//! Pure: poses, rays and noise in, figures out.

use super::bound::WallPlanes;
use super::metrics::ate;
use super::pair_bound::{PairRay, range_derivatives};
use crate::geometry::Pose2;
use crate::simulate::OdometryParams;
use nalgebra::{DMatrix, DVector, Matrix3};
use rand::SeedableRng;
use rand::rngs::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use std::collections::BTreeMap;

/// The bound on a whole run (see the module's notes).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct PathBound {
    /// The expected ATE RMSE of an efficient smoother \[m\].
    pub ate: f64,
    /// The RMS over poses of a causal efficient estimator's position sigma, from a known start
    /// \[m\].
    pub causal_rms: f64,
}

/// Draws of the smoother's errors averaged for [`PathBound::ate`].
const DRAWS: usize = 400;

/// A wall seen by a single ray leaves one of its two parameters free: a prior this weak (in
/// units of the rays' information) pins it without touching anything the rays pin.
const WALL_PRIOR: f64 = 1e-9;

/// The bound on the run at `poses` (world frame, exact) whose scans met the walls as `rays`
/// (one list per pose), with range noise `sigma` \[m\] and odometry noise `odometry` between
/// consecutive poses; `seed` seeds the smoother's draws. `None` for fewer than two poses, for
/// odometry without noise in translation or heading (it alone would place the run exactly), or
/// for a run the measurements cannot place.
pub fn path_bound(
    planes: &WallPlanes,
    poses: &[Pose2],
    rays: &[Vec<PairRay>],
    sigma: f64,
    odometry: &OdometryParams,
    seed: u64,
) -> Option<PathBound> {
    let n = poses.len();
    if n < 2 || rays.len() != n || sigma.is_nan() || sigma <= 0.0 {
        return None;
    }
    let mut path = Information::new(poses, rays);
    // Poses 1.. come first, three unknowns each; the walls' follow.
    let first_wall = 3 * (n - 1);
    // Per pose, the unknowns measured so far (a filter at that pose knows nothing later).
    let mut active: Vec<usize> = Vec::new();
    let mut seen = vec![false; path.info.nrows()];
    let mut causal = 0.0;
    for (k, scan) in rays.iter().enumerate() {
        if k > 0 {
            path.add_odometry(poses, k, odometry)?;
            activate(&mut active, &mut seen, 3 * (k - 1)..3 * k);
        }
        for ray in scan {
            let w = path.walls[&ray.wall];
            activate(&mut active, &mut seen, w..w + 2);
            path.add_ray(planes, poses, k, ray, sigma);
        }
        if k > 0 {
            let cov = covariance_of(&path.info, &active, first_wall, 3 * (k - 1))?;
            causal += cov[(0, 0)] + cov[(1, 1)];
        }
    }
    let pose_cov = pose_covariance(&path.info, first_wall)?;
    Some(PathBound {
        ate: expected_ate(poses, &pose_cov, seed)?,
        causal_rms: (causal / (n - 1) as f64).sqrt(),
    })
}

/// The Fisher information of a run's unknowns: poses 1.. (x, y, heading), then each wall seen
/// (angle of its normal, offset), built up measurement by measurement.
pub(crate) struct Information {
    pub(crate) info: DMatrix<f64>,
    /// Each wall seen: where its two unknowns start.
    pub(crate) walls: BTreeMap<usize, usize>,
}

impl Information {
    /// No information yet about the run at `poses` whose scans met the walls as `rays`.
    pub(crate) fn new(poses: &[Pose2], rays: &[Vec<PairRay>]) -> Self {
        let n = poses.len();
        let mut walls: BTreeMap<usize, usize> = BTreeMap::new();
        for ray in rays.iter().flatten() {
            let next = 3 * (n - 1) + 2 * walls.len();
            walls.entry(ray.wall).or_insert(next);
        }
        let dim = 3 * (n - 1) + 2 * walls.len();
        Information {
            info: DMatrix::zeros(dim, dim),
            walls,
        }
    }

    /// The information of one ray of scan `k` (noise `sigma` \[m\]).
    pub(crate) fn add_ray(
        &mut self,
        planes: &WallPlanes,
        poses: &[Pose2],
        k: usize,
        ray: &PairRay,
        sigma: f64,
    ) {
        let w = self.walls[&ray.wall];
        let info = &mut self.info;
        let (normal, d) = planes.line(ray.wall);
        // The range's derivatives by the pose and the wall, as in the pair bound.
        let Some((by_pose, by_wall)) = range_derivatives(&normal, d, &poses[k], ray.bearing) else {
            return;
        };
        let mut entries: Vec<(usize, f64)> = vec![(w, by_wall.x), (w + 1, by_wall.y)];
        if k > 0 {
            let p = 3 * (k - 1);
            entries.extend([(p, by_pose.x), (p + 1, by_pose.y), (p + 2, by_pose.z)]);
        }
        let weight = 1.0 / (sigma * sigma);
        for &(i, a) in &entries {
            for &(j, b) in &entries {
                info[(i, j)] += weight * a * b;
            }
        }
    }

    /// The information of the odometry step from pose `k - 1` to pose `k`: the motion in the
    /// first pose's frame, with the simulator's sigmas for the true step
    /// ([`crate::simulate::odometry`]). `None` for a step without noise in translation or
    /// heading: it alone would fix what it measures, which no finite weight says.
    pub(crate) fn add_odometry(
        &mut self,
        poses: &[Pose2],
        k: usize,
        odometry: &OdometryParams,
    ) -> Option<()> {
        let info = &mut self.info;
        let (a, b) = (&poses[k - 1], &poses[k]);
        let step = a.between(b);
        let s_t = odometry.trans_per_m * step.x.hypot(step.y) + odometry.trans_const;
        let s_r = odometry.rot_per_rad * step.theta.abs() + odometry.rot_const;
        if s_t <= 0.0 || s_r <= 0.0 || s_t.is_nan() || s_r.is_nan() {
            return None;
        }
        let (s, c) = a.theta.sin_cos();
        let (dx, dy) = (b.x - a.x, b.y - a.y);
        // Rows: the step's x, y (in pose a's frame) and heading; columns: a's then b's unknowns.
        let by_a = Matrix3::new(
            -c,
            -s,
            -s * dx + c * dy,
            s,
            -c,
            -c * dx - s * dy,
            0.0,
            0.0,
            -1.0,
        );
        let by_b = Matrix3::new(c, s, 0.0, -s, c, 0.0, 0.0, 0.0, 1.0);
        let weights = [1.0 / (s_t * s_t), 1.0 / (s_t * s_t), 1.0 / (s_r * s_r)];
        let blocks: Vec<(usize, Matrix3<f64>)> = if k > 1 {
            vec![(3 * (k - 2), by_a), (3 * (k - 1), by_b)]
        } else {
            vec![(0, by_b)]
        };
        for (i0, ja) in &blocks {
            for (j0, jb) in &blocks {
                let block = ja.transpose() * Matrix3::from_diagonal(&weights.into()) * jb;
                for r in 0..3 {
                    for q in 0..3 {
                        info[(i0 + r, j0 + q)] += block[(r, q)];
                    }
                }
            }
        }
        Some(())
    }
}

/// Each scan's `rays` on walls it meets with at least `m` rays (the others dropped).
pub fn seen_by_at_least(rays: &[Vec<PairRay>], m: usize) -> Vec<Vec<PairRay>> {
    rays.iter()
        .map(|scan| {
            let mut count: BTreeMap<usize, usize> = BTreeMap::new();
            for ray in scan {
                *count.entry(ray.wall).or_default() += 1;
            }
            scan.iter()
                .filter(|r| count[&r.wall] >= m)
                .copied()
                .collect()
        })
        .collect()
}

/// Appends the unknowns `new` to `active` (in order) unless already there.
fn activate(active: &mut Vec<usize>, seen: &mut [bool], new: std::ops::Range<usize>) {
    for i in new {
        if !seen[i] {
            seen[i] = true;
            active.push(i);
        }
    }
}

/// The information restricted to the unknowns `active`, factored; the walls' (indices from
/// `first_wall` on) given the weak prior.
fn factored(
    info: &DMatrix<f64>,
    active: &[usize],
    first_wall: usize,
) -> Option<nalgebra::Cholesky<f64, nalgebra::Dyn>> {
    let m = active.len();
    let scale = (0..m)
        .map(|i| info[(active[i], active[i])])
        .fold(0.0, f64::max)
        .max(1e-300);
    let sub = DMatrix::from_fn(m, m, |i, j| {
        let prior = if i == j && active[i] >= first_wall {
            WALL_PRIOR * scale
        } else {
            0.0
        };
        info[(active[i], active[j])] + prior
    });
    sub.cholesky()
}

/// The 3x3 covariance of the pose whose unknowns start at `pose` (among `active`).
fn covariance_of(
    info: &DMatrix<f64>,
    active: &[usize],
    first_wall: usize,
    pose: usize,
) -> Option<Matrix3<f64>> {
    let chol = factored(info, active, first_wall)?;
    let at = active.iter().position(|&i| i == pose)?;
    let mut rhs = DMatrix::zeros(active.len(), 3);
    for q in 0..3 {
        rhs[(at + q, q)] = 1.0;
    }
    let x = chol.solve(&rhs);
    Some(Matrix3::from_fn(|r, q| x[(at + r, q)]))
}

/// The joint covariance of poses 1.. (the unknowns before `first_wall`, in their order) from
/// all the information.
fn pose_covariance(info: &DMatrix<f64>, first_wall: usize) -> Option<DMatrix<f64>> {
    let all: Vec<usize> = (0..info.nrows()).collect();
    let chol = factored(info, &all, first_wall)?;
    let rhs = DMatrix::from_fn(all.len(), first_wall, |i, j| if i == j { 1.0 } else { 0.0 });
    let x = chol.solve(&rhs);
    Some(x.rows(0, first_wall).into_owned())
}

/// The mean ATE RMSE of runs whose poses 1.. err by draws from `cov` (pose 0 exact).
fn expected_ate(poses: &[Pose2], cov: &DMatrix<f64>, seed: u64) -> Option<f64> {
    let sym = (cov + cov.transpose()) * 0.5;
    let l = sym.cholesky()?.l();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let m = cov.nrows();
    let mut sum = 0.0;
    for _ in 0..DRAWS {
        let z = DVector::from_fn(m, |_, _| StandardNormal.sample(&mut rng));
        let e = &l * z;
        let estimate: Vec<Pose2> = poses
            .iter()
            .enumerate()
            .map(|(k, p)| match k {
                0 => *p,
                _ => {
                    let i = 3 * (k - 1);
                    Pose2::new(p.x + e[i], p.y + e[i + 1], p.theta + e[i + 2])
                }
            })
            .collect();
        sum += ate(&estimate, poses)?.rmse;
    }
    Some(sum / DRAWS as f64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::test_scenes::{rays_at, segment};
    use nalgebra::Vector2;

    const SIGMA: f64 = 0.01;

    fn odometry() -> OdometryParams {
        OdometryParams::default()
    }

    /// The whitened measurements (ranges over `SIGMA`, odometry steps over their sigmas) as a
    /// function of the unknowns, for the finite-difference twin.
    fn measurements(
        x: &DVector<f64>,
        poses: &[Pose2],
        rays: &[Vec<PairRay>],
        walls: &BTreeMap<usize, usize>,
        odo: &OdometryParams,
    ) -> Vec<f64> {
        let pose = |k: usize| match k {
            0 => poses[0],
            _ => Pose2::new(x[3 * (k - 1)], x[3 * k - 2], x[3 * k - 1]),
        };
        let mut out = Vec::new();
        for (k, scan) in rays.iter().enumerate() {
            let p = pose(k);
            for ray in scan {
                let w = walls[&ray.wall];
                let (psi, d) = (x[w], x[w + 1]);
                let n = Vector2::new(psi.cos(), psi.sin());
                let u = Vector2::new((p.theta + ray.bearing).cos(), (p.theta + ray.bearing).sin());
                out.push((d - n.dot(&Vector2::new(p.x, p.y))) / n.dot(&u) / SIGMA);
            }
        }
        for k in 1..poses.len() {
            let truth = poses[k - 1].between(&poses[k]);
            let s_t = odo.trans_per_m * truth.x.hypot(truth.y) + odo.trans_const;
            let s_r = odo.rot_per_rad * truth.theta.abs() + odo.rot_const;
            let step = pose(k - 1).between(&pose(k));
            out.extend([step.x / s_t, step.y / s_t, step.theta / s_r]);
        }
        out
    }

    /// The information built measurement by measurement equals `J^T J` of the whitened
    /// measurements, `J` by central differences (a brute-force twin).
    #[test]
    fn the_information_is_that_of_the_measurements_by_finite_differences() {
        let room = [
            segment((0.0, 0.0), (6.0, 0.0)),
            segment((6.0, 0.0), (6.0, 4.0)),
            segment((6.0, 4.0), (0.0, 4.0)),
            segment((0.0, 4.0), (0.0, 0.0)),
            segment((3.0, 1.5), (3.4, 1.5)),
            segment((3.4, 1.5), (3.4, 1.9)),
        ];
        let poses = [
            Pose2::new(1.0, 1.0, 0.2),
            Pose2::new(1.6, 1.2, 0.5),
            Pose2::new(2.0, 2.6, -0.4),
        ];
        let (planes, rays) = rays_at(&room, &poses);
        let odo = odometry();
        let mut path = Information::new(&poses, &rays);
        for (k, scan) in rays.iter().enumerate() {
            if k > 0 {
                path.add_odometry(&poses, k, &odo).unwrap();
            }
            for ray in scan {
                path.add_ray(&planes, &poses, k, ray, SIGMA);
            }
        }
        let dim = path.info.nrows();
        let mut x0 = DVector::zeros(dim);
        for (k, p) in poses.iter().enumerate().skip(1) {
            (x0[3 * (k - 1)], x0[3 * k - 2], x0[3 * k - 1]) = (p.x, p.y, p.theta);
        }
        for (&wall, &w) in &path.walls {
            let (n, d) = planes.line(wall);
            (x0[w], x0[w + 1]) = (n.y.atan2(n.x), d);
        }
        let m0 = measurements(&x0, &poses, &rays, &path.walls, &odo);
        let h = 1e-6;
        let mut jac = DMatrix::zeros(m0.len(), dim);
        for j in 0..dim {
            let (mut up, mut down) = (x0.clone(), x0.clone());
            up[j] += h;
            down[j] -= h;
            let (mu, md) = (
                measurements(&up, &poses, &rays, &path.walls, &odo),
                measurements(&down, &poses, &rays, &path.walls, &odo),
            );
            for i in 0..m0.len() {
                jac[(i, j)] = (mu[i] - md[i]) / (2.0 * h);
            }
        }
        let twin = jac.transpose() * &jac;
        let scale = twin.amax();
        let worst = (&path.info - &twin).amax();
        assert!(worst < 1e-6 * scale, "{worst} of {scale}");
    }

    /// In a corridor without ends the walls pin the width and the heading but not the length:
    /// pose k's sigma along it is the odometry's over k steps, `sqrt(k) s_t`, so the causal
    /// RMS over poses 1..n-1 is `s_t sqrt(n / 2)`; seeing both ends at every pose (a short
    /// room) pins it to well under one step's odometry.
    #[test]
    fn a_corridor_leaves_its_length_to_the_odometry_and_a_room_pins_it() {
        let corridor = [
            segment((-1000.0, 0.0), (1000.0, 0.0)),
            segment((-1000.0, 2.0), (1000.0, 2.0)),
        ];
        let n = 9;
        let poses: Vec<Pose2> = (0..n).map(|k| Pose2::new(k as f64, 1.0, 0.0)).collect();
        let odo = odometry();
        let s_t = odo.trans_per_m + odo.trans_const;
        let (planes, rays) = rays_at(&corridor, &poses);
        let bound = path_bound(&planes, &poses, &rays, SIGMA, &odo, 1).expect("bound");
        let along = s_t * (n as f64 / 2.0).sqrt();
        // y and the heading add a little: the walls pin them to millimetres.
        assert!(
            bound.causal_rms >= along && bound.causal_rms < along * 1.01,
            "{} against {along}",
            bound.causal_rms
        );
        let room = [
            segment((-1.0, 0.0), (10.0, 0.0)),
            segment((10.0, 0.0), (10.0, 2.0)),
            segment((10.0, 2.0), (-1.0, 2.0)),
            segment((-1.0, 2.0), (-1.0, 0.0)),
        ];
        let (planes, rays) = rays_at(&room, &poses);
        let bound = path_bound(&planes, &poses, &rays, SIGMA, &odo, 1).expect("bound");
        assert!(bound.causal_rms < 0.2 * s_t, "{}", bound.causal_rms);
        assert!(bound.ate < bound.causal_rms, "{bound:?}");
        // The room's end walls are 2 m wide: from the middle of the room the far one is met by
        // fewer rays than the near one. Asking for more rays per wall than the end walls get
        // drops them, and the length is the odometry's again.
        let few = seen_by_at_least(&rays, 60);
        assert!(
            few.iter()
                .flatten()
                .all(|r| planes.line(r.wall).0.x.abs() < 1e-9)
        );
        let bound = path_bound(&planes, &poses, &few, SIGMA, &odo, 1).expect("bound");
        assert!(bound.causal_rms >= along, "{}", bound.causal_rms);
    }

    /// Dropping rays only drops information: the bound never tightens as `m` grows.
    #[test]
    fn fewer_rays_never_tighten_the_bound() {
        let room = [
            segment((0.0, 0.0), (12.0, 0.0)),
            segment((12.0, 0.0), (12.0, 3.0)),
            segment((12.0, 3.0), (0.0, 3.0)),
            segment((0.0, 3.0), (0.0, 0.0)),
            segment((5.0, 0.0), (5.0, 0.2)),
            segment((5.0, 0.2), (5.3, 0.2)),
            segment((5.3, 0.2), (5.3, 0.0)),
        ];
        let poses: Vec<Pose2> = (0..6)
            .map(|k| Pose2::new(1.0 + 0.8 * k as f64, 1.5, 0.05 * k as f64))
            .collect();
        let (planes, rays) = rays_at(&room, &poses);
        let odo = odometry();
        let mut last = 0.0;
        for m in [0, 2, 3, 5, 10] {
            let kept = seen_by_at_least(&rays, m);
            let b = path_bound(&planes, &poses, &kept, SIGMA, &odo, 1).expect("bound");
            assert!(
                b.causal_rms >= last * (1.0 - 1e-9),
                "m {m}: {} < {last}",
                b.causal_rms
            );
            last = b.causal_rms;
        }
    }
}
