//! How well could any scan matcher do? The Cramér-Rao bound on the motion between two scans.
//!
//! A range is a function of where the scanner stood and of where the wall it met lies: a ray
//! at bearing `phi` from a scanner at `(t, theta)` along `u = (cos(theta + phi), sin(theta +
//! phi))` meets the line `n . x = d`, `n = (cos psi, sin psi)`, at `r = (d - n . t) / (n . u)`.
//! Both scans' ranges carry Gaussian noise `sigma` along their rays; the walls are unknown
//! lines (a plan's segments on one line are one wall, as [`WallPlanes`] groups them), so they
//! are estimated from the same ranges. Fixing the first scan's pose (the gauge), the Fisher
//! information of the second scan's pose with every wall marginalised out (its Schur
//! complement) bounds the covariance of any unbiased estimate of the motion from below (Kay
//! 1993, ch. 3; for ICP's covariance, Censi 2007). It is given which wall every ray met, which
//! no matcher knows, so it cannot be beaten.
//!
//! [`median_error`] turns the bounds of many pairs into the median translation error an
//! efficient matcher would show over them: the yardstick for a run's RPE median.
//!
//! Pure: rays in, covariances out; [`scan_rays`] builds the rays from the simulator's world.

use super::bound::WallPlanes;
use crate::geometry::{Pose2, pseudo_inverse_2x2};
use crate::simulate::World;
use nalgebra::{Matrix2, Matrix3, Matrix3x2, Point2, Point3, Vector2, Vector3};
use rayon::prelude::*;
use serde::Serialize;
use std::collections::BTreeMap;

/// The bound over a run's consecutive pairs of scans.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct RunBound {
    /// The share of the run's readings within five range sigmas (and 5 cm) of the plan's
    /// range from the scan's pose: near 1 for a run simulated in that plan.
    pub agreeing: f64,
    /// Consecutive pairs whose motion the rays make observable.
    pub pairs: usize,
    /// Pairs whose rays leave the motion unobservable (no bound).
    pub unobservable: usize,
    /// The RPE median an efficient matcher tends to over the pairs ([`median_error`]) \[m\].
    pub median_translation: f64,
    /// The root of the mean translation variance \[m\].
    pub rms_translation: f64,
    /// The root of the mean heading variance \[rad\].
    pub rms_rotation: f64,
}

/// Readings farther than this many range sigmas (and 5 cm) from the plan's range say the run
/// was not simulated in that plan.
const AGREE_SIGMAS: f64 = 5.0;

/// [`RunBound`] of a run whose scans stood at `poses` (world frame, exact) and read `points`
/// (each scan's valid readings in its own frame), with range noise `sigma` \[m\] in `world`.
/// `None` when no pair has a bound.
pub fn run_bound(
    world: &World,
    planes: &WallPlanes,
    poses: &[Pose2],
    points: &[Vec<Point2<f64>>],
    sigma: f64,
) -> Option<RunBound> {
    let tolerance = (AGREE_SIGMAS * sigma).max(0.05);
    // Every valid reading met something within the scanner's range: cast far.
    let (rays, agreeing): (Vec<Vec<PairRay>>, Vec<usize>) = poses
        .par_iter()
        .zip(points)
        .map(|(pose, pts)| {
            let mut agree = 0;
            let rays = pts
                .iter()
                .filter_map(|p| {
                    let ray = cast_ray(world, planes, pose, p.y.atan2(p.x), FAR)?;
                    if (ray.range - p.coords.norm()).abs() <= tolerance {
                        agree += 1;
                    }
                    Some(ray)
                })
                .collect();
            (rays, agree)
        })
        .unzip();
    let readings: usize = points.iter().map(Vec::len).sum();
    let agreeing: usize = agreeing.iter().sum();
    let covs: Vec<Option<Matrix3<f64>>> = (1..poses.len())
        .into_par_iter()
        .map(|i| {
            pair_bound(
                planes,
                (&poses[i - 1], &rays[i - 1]),
                (&poses[i], &rays[i]),
                sigma,
            )
        })
        .collect();
    let bounded: Vec<Matrix3<f64>> = covs.iter().flatten().copied().collect();
    let n = bounded.len();
    let translation: Vec<Matrix2<f64>> = bounded
        .iter()
        .map(|c| c.fixed_view::<2, 2>(0, 0).into_owned())
        .collect();
    Some(RunBound {
        agreeing: agreeing as f64 / readings.max(1) as f64,
        pairs: n,
        unobservable: covs.len() - n,
        median_translation: median_error(&translation)?,
        rms_translation: (translation.iter().map(|c| c.trace()).sum::<f64>() / n as f64).sqrt(),
        rms_rotation: (bounded.iter().map(|c| c[(2, 2)]).sum::<f64>() / n as f64).sqrt(),
    })
}

/// One noise-free ray of a scan that met a wall: its bearing in the scanner frame, its range,
/// and the wall (an index into [`WallPlanes`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PairRay {
    pub bearing: f64,
    pub range: f64,
    pub wall: usize,
}

/// The rays of a planar scan at `scanner` (world frame) along `bearings` that meet a wall of
/// `world` within `max_range`, cast at mid wall height (a flat scan sees neither floor nor
/// ceiling).
pub fn scan_rays(
    world: &World,
    planes: &WallPlanes,
    scanner: &Pose2,
    bearings: impl IntoIterator<Item = f64>,
    max_range: f64,
) -> Vec<PairRay> {
    bearings
        .into_iter()
        .filter_map(|bearing| cast_ray(world, planes, scanner, bearing, max_range))
        .collect()
}

/// The ray of [`scan_rays`] at one `bearing`, if it meets a wall.
fn cast_ray(
    world: &World,
    planes: &WallPlanes,
    scanner: &Pose2,
    bearing: f64,
    max_range: f64,
) -> Option<PairRay> {
    let origin = Point3::new(scanner.x, scanner.y, 0.5 * world.wall_height());
    let (s, c) = (scanner.theta + bearing).sin_cos();
    let hit = world.cast(&origin, &Vector3::new(c, s, 0.0), max_range)?;
    let p = Point2::new(scanner.x + hit.range * c, scanner.y + hit.range * s);
    Some(PairRay {
        bearing,
        range: hit.range,
        wall: planes.locate(&p)?,
    })
}

/// The bound on the covariance of `pose_a.between(pose_b)` (x, y in the first scan's frame
/// \[m\], heading \[rad\]) from the rays `a` of the scan at `pose_a` and `b` of the scan at
/// `pose_b` (world frame), with range noise `sigma` \[m\] and the walls' lines `planes`
/// unknown. `None` when the rays leave the motion unobservable (a corridor, one wall).
pub fn pair_bound(
    planes: &WallPlanes,
    (pose_a, a): (&Pose2, &[PairRay]),
    (pose_b, b): (&Pose2, &[PairRay]),
    sigma: f64,
) -> Option<Matrix3<f64>> {
    // Everything in the first scan's frame: its pose is the identity, the second's the motion.
    let a_from_world = pose_a.inverse();
    let motion = pose_a.between(pose_b);
    let wall_in_a = |wall: usize| -> Vector3<f64> {
        // (normal, offset) of the wall's line seen from the first scan.
        let (n, d) = planes.line(wall);
        let (s, c) = a_from_world.theta.sin_cos();
        let n_a = Vector2::new(c * n.x - s * n.y, s * n.x + c * n.y);
        let d_a = d + n_a.dot(&Vector2::new(a_from_world.x, a_from_world.y));
        Vector3::new(n_a.x, n_a.y, d_a)
    };
    let w = 1.0 / (sigma * sigma);
    // The motion's block, and per wall its 2x2 block (psi, d) and its coupling to the motion.
    let mut h_mm = Matrix3::<f64>::zeros();
    let mut walls: BTreeMap<usize, (Matrix3x2<f64>, Matrix2<f64>)> = BTreeMap::new();
    for (pose, rays, moves) in [(&Pose2::identity(), a, false), (&motion, b, true)] {
        for ray in rays {
            let line = wall_in_a(ray.wall);
            let n = Vector2::new(line.x, line.y);
            let Some((by_motion, by_wall)) = range_derivatives(&n, line.z, pose, ray.bearing)
            else {
                continue;
            };
            let entry = walls
                .entry(ray.wall)
                .or_insert((Matrix3x2::zeros(), Matrix2::zeros()));
            entry.1 += w * by_wall * by_wall.transpose();
            if moves {
                h_mm += w * by_motion * by_motion.transpose();
                entry.0 += w * by_motion * by_wall.transpose();
            }
        }
    }
    let mut schur = h_mm;
    for (h_mw, h_ww) in walls.values() {
        // A wall seen by one ray fixes one of its two parameters; its other direction couples
        // to nothing.
        schur -= h_mw * pseudo_inverse_2x2(h_ww)? * h_mw.transpose();
    }
    let schur = 0.5 * (schur + schur.transpose());
    let eig = schur.symmetric_eigen();
    let (lo, hi) = (eig.eigenvalues.min(), eig.eigenvalues.max());
    if !(lo > hi * 1e-12 && lo > 0.0) {
        return None;
    }
    schur.try_inverse()
}

/// A ray's noise-free range `r = (d - n . t) / (n . u)`, from `pose` along `bearing` to the
/// wall line `n . p = d`, differentiated by the pose `(x, y, theta)` and by the wall's (normal
/// angle, offset); `None` where the ray runs along the wall.
pub(crate) fn range_derivatives(
    n: &Vector2<f64>,
    d: f64,
    pose: &Pose2,
    bearing: f64,
) -> Option<(Vector3<f64>, Vector2<f64>)> {
    let (s, c) = (pose.theta + bearing).sin_cos();
    let u = Vector2::new(c, s);
    let t = Vector2::new(pose.x, pose.y);
    let nu = n.dot(&u);
    if nu.abs() < 1e-12 {
        return None;
    }
    let r = (d - n.dot(&t)) / nu;
    let hit = t + u * r;
    let (n_perp, u_perp) = (Vector2::new(-n.y, n.x), Vector2::new(-u.y, u.x));
    let by_pose = Vector3::new(-n.x / nu, -n.y / nu, -r * n.dot(&u_perp) / nu);
    let by_wall = Vector2::new(-n_perp.dot(&hit) / nu, 1.0 / nu);
    Some((by_pose, by_wall))
}

/// Far enough for any reading \[m\].
const FAR: f64 = 1.0e6;

/// The median translation error over pairs whose errors are Gaussian with the translation
/// covariances `covs` \[m\]: the `m` at which the pairs' mean chance of `|e| <= m` is one
/// half. What an efficient matcher's RPE median tends to over a run with these pairs (one
/// run's own median scatters about it by a few per cent). `None` when `covs` is empty.
pub fn median_error(covs: &[Matrix2<f64>]) -> Option<f64> {
    if covs.is_empty() {
        return None;
    }
    let share_within = |m: f64| -> f64 {
        covs.iter().map(|c| chance_within(c, m)).sum::<f64>() / covs.len() as f64
    };
    let (mut lo, mut hi) = (
        0.0,
        covs.iter().map(|c| c.trace().sqrt()).fold(0.0, f64::max),
    );
    while share_within(hi) < 0.5 {
        hi *= 2.0;
    }
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if share_within(mid) < 0.5 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Some(0.5 * (lo + hi))
}

/// Angle steps of the polar integral in [`chance_within`]; the integrand is smooth and
/// periodic, so the trapezoid rule converges geometrically.
const ANGLE_STEPS: usize = 256;

/// `P(|e| <= m)` for `e ~ N(0, cov)` in 2D: in the covariance's eigenbasis `e = (a z1, b z2)`
/// with standard normal `z`; along each direction `alpha` of `z` the radius reaches `m /
/// sqrt(a^2 cos^2 + b^2 sin^2)`, and a standard 2D normal lies within radius `rho` with chance
/// `1 - exp(-rho^2 / 2)`.
fn chance_within(cov: &Matrix2<f64>, m: f64) -> f64 {
    let eig = cov.symmetric_eigenvalues();
    let (l1, l2) = (eig[0].max(0.0), eig[1].max(0.0));
    let mut sum = 0.0;
    for k in 0..ANGLE_STEPS {
        let alpha = std::f64::consts::TAU * k as f64 / ANGLE_STEPS as f64;
        let (s, c) = alpha.sin_cos();
        let scale = l1 * c * c + l2 * s * s;
        sum += if scale > 0.0 {
            1.0 - (-0.5 * m * m / scale).exp()
        } else {
            1.0
        };
    }
    sum / ANGLE_STEPS as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::test_scenes::{rays_at, segment};
    use crate::plan::Segment;

    const SIGMA: f64 = 0.01;

    /// An L-shaped room with a pillar and a wall broken by a door (two segments, one line).
    fn room() -> Vec<Segment> {
        vec![
            segment((0.0, 0.0), (7.0, 0.0)),
            segment((7.0, 0.0), (7.0, 3.0)),
            segment((7.0, 3.0), (4.0, 3.0)),
            segment((4.0, 3.0), (4.0, 5.0)),
            segment((4.0, 5.0), (2.2, 5.0)),
            segment((1.2, 5.0), (0.0, 5.0)),
            segment((0.0, 5.0), (0.0, 0.0)),
            segment((5.0, 1.0), (5.4, 1.0)),
            segment((5.4, 1.0), (5.4, 1.4)),
            segment((5.4, 1.4), (5.0, 1.4)),
            segment((5.0, 1.4), (5.0, 1.0)),
        ]
    }

    fn bound_in(
        segments: &[Segment],
        a: &Pose2,
        b: &Pose2,
    ) -> (Option<Matrix3<f64>>, Vec<PairRay>, Vec<PairRay>, WallPlanes) {
        let (planes, mut rays) = rays_at(segments, &[*a, *b]);
        let (rb, ra) = (rays.pop().unwrap(), rays.pop().unwrap());
        let cov = pair_bound(&planes, (a, &ra), (b, &rb), SIGMA);
        (cov, ra, rb, planes)
    }

    /// The range of a ray from a scanner at `pose` (first scan's frame) at `bearing` to the
    /// line `(psi, d)`.
    fn range(pose: &Pose2, bearing: f64, psi: f64, d: f64) -> f64 {
        let n = Vector2::new(psi.cos(), psi.sin());
        let u = Vector2::new((pose.theta + bearing).cos(), (pose.theta + bearing).sin());
        (d - n.dot(&Vector2::new(pose.x, pose.y))) / n.dot(&u)
    }

    #[test]
    fn the_schur_complement_agrees_with_the_whole_information_by_finite_differences() {
        let (pa, pb) = (Pose2::new(1.5, 1.2, 0.3), Pose2::new(1.9, 1.0, 0.45));
        let (cov, ra, rb, planes) = bound_in(&room(), &pa, &pb);
        let cov = cov.expect("observable");
        // The walls seen, in the first scan's frame, as (psi, d).
        let a_from_world = pa.inverse();
        let seen: Vec<usize> = {
            let mut v: Vec<usize> = ra.iter().chain(&rb).map(|r| r.wall).collect();
            v.sort_unstable();
            v.dedup();
            v
        };
        let wall0: Vec<(f64, f64)> = seen
            .iter()
            .map(|&w| {
                let (n, d) = planes.line(w);
                let psi = n.y.atan2(n.x) + a_from_world.theta;
                let n_a = Vector2::new(psi.cos(), psi.sin());
                (
                    psi,
                    d + n_a.dot(&Vector2::new(a_from_world.x, a_from_world.y)),
                )
            })
            .collect();
        let motion = pa.between(&pb);
        let dim = 3 + 2 * seen.len();
        let ranges = |x: &nalgebra::DVector<f64>| -> Vec<f64> {
            let m = Pose2::new(x[0], x[1], x[2]);
            let wall = |w: usize| {
                let k = seen.iter().position(|&s| s == w).unwrap();
                (x[3 + 2 * k], x[4 + 2 * k])
            };
            let a = ra.iter().map(|r| {
                let (psi, d) = wall(r.wall);
                range(&Pose2::identity(), r.bearing, psi, d)
            });
            let b = rb.iter().map(|r| {
                let (psi, d) = wall(r.wall);
                range(&m, r.bearing, psi, d)
            });
            a.chain(b).collect()
        };
        let mut x0 = nalgebra::DVector::zeros(dim);
        (x0[0], x0[1], x0[2]) = (motion.x, motion.y, motion.theta);
        for (k, &(psi, d)) in wall0.iter().enumerate() {
            (x0[3 + 2 * k], x0[4 + 2 * k]) = (psi, d);
        }
        // The noise-free ranges are the model's at x0.
        let r0 = ranges(&x0);
        for (r, ray) in r0.iter().zip(ra.iter().chain(&rb)) {
            assert!((r - ray.range).abs() < 1e-9, "{r} {}", ray.range);
        }
        let h = 1e-6;
        let mut jac = nalgebra::DMatrix::zeros(r0.len(), dim);
        for j in 0..dim {
            let (mut up, mut down) = (x0.clone(), x0.clone());
            up[j] += h;
            down[j] -= h;
            let (ru, rd) = (ranges(&up), ranges(&down));
            for i in 0..r0.len() {
                jac[(i, j)] = (ru[i] - rd[i]) / (2.0 * h);
            }
        }
        let info = jac.transpose() * &jac / (SIGMA * SIGMA);
        let full = info.pseudo_inverse(1e-12).unwrap();
        for i in 0..3 {
            for j in 0..3 {
                let (got, want) = (cov[(i, j)], full[(i, j)]);
                assert!(
                    (got - want).abs() <= 1e-5 * (cov[(i, i)] * cov[(j, j)]).sqrt(),
                    "{i} {j}: {got} {want}"
                );
            }
        }
    }

    #[test]
    fn the_bound_does_not_depend_on_the_world_frame() {
        let (pa, pb) = (Pose2::new(1.5, 1.2, 0.3), Pose2::new(1.9, 1.0, 0.45));
        let moved = Pose2::new(-3.0, 12.0, 1.1);
        let segments: Vec<Segment> = room()
            .iter()
            .map(|s| Segment {
                a: moved.transform_point(&s.a),
                b: moved.transform_point(&s.b),
            })
            .collect();
        let here = bound_in(&room(), &pa, &pb).0.unwrap();
        let there = bound_in(&segments, &moved.compose(&pa), &moved.compose(&pb))
            .0
            .unwrap();
        assert!((here - there).norm() < 1e-9 * here.norm(), "{here} {there}");
    }

    #[test]
    fn one_wall_leaves_the_motion_unobservable() {
        let wall = [segment((-20.0, 3.0), (20.0, 3.0))];
        let (pa, pb) = (Pose2::new(0.0, 0.0, 0.2), Pose2::new(0.5, 0.1, 0.25));
        assert!(bound_in(&wall, &pa, &pb).0.is_none());
        // A second wall across it pins the motion.
        let two = [wall[0], segment((6.0, -20.0), (6.0, 20.0))];
        assert!(bound_in(&two, &pa, &pb).0.is_some());
    }

    #[test]
    fn a_less_noisy_scanner_tightens_the_bound_by_its_noise() {
        let (pa, pb) = (Pose2::new(1.5, 1.2, 0.3), Pose2::new(1.9, 1.0, 0.45));
        let (cov, ra, rb, planes) = bound_in(&room(), &pa, &pb);
        let half = pair_bound(&planes, (&pa, &ra), (&pb, &rb), SIGMA / 2.0).unwrap();
        assert!((cov.unwrap() / 4.0 - half).norm() < 1e-12 * half.norm());
    }

    #[test]
    fn the_median_error_is_rayleighs_and_the_half_normals() {
        let s: f64 = 0.003;
        let round = median_error(&[Matrix2::identity() * s * s]).unwrap();
        assert!(
            (round - s * (2.0 * 2f64.ln()).sqrt()).abs() < 1e-12,
            "{round}"
        );
        let flat = median_error(&[Matrix2::new(s * s, 0.0, 0.0, 0.0)]).unwrap();
        assert!((flat - s * 0.674_489_750_196_081_7).abs() < 1e-9, "{flat}");
        // Rotating a covariance does not move its median; mixing two is between them.
        let r = nalgebra::Rotation2::new(0.7).into_inner();
        let c = Matrix2::new(4.0 * s * s, 0.0, 0.0, s * s);
        let a = median_error(&[c]).unwrap();
        assert!((median_error(&[r * c * r.transpose()]).unwrap() - a).abs() < 1e-9);
        let mixed = median_error(&[c, Matrix2::identity() * s * s]).unwrap();
        assert!(mixed > round && mixed < a, "{round} {mixed} {a}");
        assert!(median_error(&[]).is_none());
    }
}
