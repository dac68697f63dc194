//! Data collection (paper sect. 5.1): the scans of one pose as a grid of robot-frame points,
//! rows sorted by elevation (the paper's "scans as rows, equal bearings as columns").

use super::FailCause;
use super::eigen3::{UPPER_I, UPPER_J};
use crate::geometry::{beam_origin, rot_y};
use crate::scan::Scan;
use nalgebra::{Point3, Vector3};
use std::borrow::Cow;
use std::sync::Arc;

/// One valid reading placed in the robot frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GridPoint {
    /// The point in the robot frame \[m\].
    pub p: Point3<f64>,
    /// Unit direction of the ray that measured it, robot frame (range noise acts along it).
    pub dir: Vector3<f64>,
    /// The measured range \[m\].
    pub range: f64,
}

/// The pose's scans as rows of points, sorted by ascending elevation.
#[derive(Clone, Debug)]
pub struct PoseGrid {
    /// Index into the pose's scan slice of each row.
    pub scan_index: Vec<usize>,
    /// Elevation of each row \[rad\].
    pub elevation: Vec<f64>,
    /// Rays per row.
    pub cols: usize,
    /// Row-major points; `None` where the ray had no valid return.
    pub points: Vec<Option<GridPoint>>,
}

/// `(sin, cos)` of the bearings when every scan of a pose has the same bearings, to the bit
/// (nearly always): computed once for the noise estimate, the grid and the pseudo-level scan.
/// The last answer is kept for as long as the bearings stay the same: a scanner's bearings
/// rarely change from pose to pose, and their sines and cosines cost as much as a pass over
/// the grid. One per thread of a run.
#[derive(Clone, Debug, Default)]
pub struct BearingTrigCache {
    theta: Vec<f64>,
    trig: Option<Arc<[(f64, f64)]>>,
}

impl BearingTrigCache {
    /// The shared `(sin, cos)`, `None` when the scans' bearings differ (or there are none).
    pub(crate) fn shared(&mut self, scans: &[Scan]) -> Option<Arc<[(f64, f64)]>> {
        let first = &scans.first()?.theta;
        if !scans.iter().all(|s| same_bits(&s.theta, first)) {
            return None;
        }
        if self.trig.is_none() || !same_bits(&self.theta, first) {
            self.theta.clone_from(first);
            self.trig = Some(first.iter().map(|t| t.sin_cos()).collect());
        }
        self.trig.clone()
    }
}

/// Equal lengths and bits. A fold without an early exit, which the compiler vectorizes: they
/// nearly always match.
fn same_bits(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len()
        && a.iter()
            .zip(b)
            .fold(true, |same, (x, y)| same & (x.to_bits() == y.to_bits()))
}

/// Appends scan `s`'s rays as one row of points. Same geometry as `Scan::point_in_robot`
/// (contract: `Ry(e) (o + r (cos phi, sin phi, 0))`): at the scan's elevation `e`, with the
/// rotation built once per scan rather than once per ray; or, for a hinge that moved while it
/// scanned, each ray at its own `ray_elevation` (the row's `e` stays the nominal one).
fn push_row(
    points: &mut Vec<Option<GridPoint>>,
    s: &Scan,
    e: f64,
    trig: &[(f64, f64)],
    cols: usize,
) {
    let offset = s.hinge_offset_vector();
    let fixed = (rot_y(e), beam_origin(e, &offset));
    let rays = trig.iter().zip(s.ranges()).take(cols).enumerate();
    points.extend(rays.map(|(i, (&(sp, cp), r))| {
        r.map(|range| {
            let (robot_from_scanner, origin) = match &s.ray_elevation {
                Some(per_ray) => (rot_y(per_ray[i]), beam_origin(per_ray[i], &offset)),
                None => fixed,
            };
            let dir = robot_from_scanner * Vector3::new(cp, sp, 0.0);
            GridPoint {
                p: origin + dir * range,
                dir,
                range,
            }
        })
    }));
}

impl PoseGrid {
    /// Builds the grid. Scans without an elevation are skipped (the reader rejects them for
    /// `level`); of several scans at the same elevation only the first is used, since two rows in
    /// one plane add nothing to a plane's tilt and would make quads degenerate. Fails with
    /// [`FailCause::TooFewScans`] below three distinct elevations, and with
    /// [`FailCause::InconsistentScans`] when the scans differ in their numbers of rays.
    pub fn from_scans(scans: &[Scan]) -> Result<PoseGrid, FailCause> {
        Self::from_scans_with(scans, None)
    }

    /// [`PoseGrid::from_scans`], given the `(sin, cos)` of the bearings when every scan shares
    /// them ([`BearingTrigCache`]).
    pub(crate) fn from_scans_with(
        scans: &[Scan],
        shared_trig: Option<&[(f64, f64)]>,
    ) -> Result<PoseGrid, FailCause> {
        let mut order: Vec<(usize, f64)> = scans
            .iter()
            .enumerate()
            .filter_map(|(i, s)| s.elevation.filter(|e| e.is_finite()).map(|e| (i, e)))
            .collect();
        order.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
        order.dedup_by(|b, a| (b.1 - a.1).abs() < 1e-9);
        if order.len() < 3 {
            return Err(FailCause::TooFewScans);
        }
        let cols = scans[order[0].0].nrays();
        if scans.iter().any(|s| s.nrays() != cols) {
            return Err(FailCause::InconsistentScans);
        }
        let mut points = Vec::with_capacity(order.len() * cols);
        for &(i, e) in &order {
            // Scans of one pose nearly always share their bearings (`shared_trig`); else each
            // scan's own.
            let own = || Cow::Owned(scans[i].theta.iter().map(|t| t.sin_cos()).collect());
            let trig = shared_trig.map_or_else(own, Cow::Borrowed);
            push_row(&mut points, &scans[i], e, &trig, cols);
        }
        Ok(PoseGrid {
            scan_index: order.iter().map(|o| o.0).collect(),
            elevation: order.iter().map(|o| o.1).collect(),
            cols,
            points,
        })
    }

    pub(crate) fn rows(&self) -> usize {
        self.scan_index.len()
    }

    /// The plane sums of the valid points among `members` (grid indices), in their order.
    pub(crate) fn accumulate(&self, members: &[usize]) -> PlaneAccumulator {
        let mut acc = PlaneAccumulator::default();
        let points = members.iter().filter_map(|&i| self.points[i].as_ref());
        points.for_each(|g| acc.add(g));
        acc
    }

    pub fn at(&self, row: usize, col: usize) -> Option<&GridPoint> {
        self.points[row * self.cols + col].as_ref()
    }

    /// The row of grid index `i`.
    pub(crate) fn row(&self, i: usize) -> usize {
        i / self.cols
    }
}

/// A total-least-squares plane through points whose range noise acts along their rays.
///
/// The raw scatter of noisy points is biased: its expectation is the true scatter plus
/// `sigma^2 * sum d d^T` over the ray directions `d`, which is not isotropic, so the smallest
/// eigenvector of the raw scatter tilts towards the rays. Subtracting that expected noise term
/// (a consistent, bias-corrected TLS, cf. Kanatani's renormalisation) removes the tilt: at 10 cm
/// noise and 20 degrees of pitch it is worth several degrees on a wall 3 m away.
#[derive(Clone, Copy, Debug, Default)]
pub struct PlaneAccumulator {
    /// Points added.
    pub(crate) n: usize,
    /// Sum of their weights (= n when unweighted).
    pub(crate) weight: f64,
    /// Weighted sums in the layout of [`Moments`]: p, p p^T and d d^T over the ray directions.
    sums: Moments,
}

/// What one point adds to a plane's sums: `p` (3), `p p^T` (6, upper triangle xx, xy, xz, yy,
/// yz, zz), then `d d^T` over its ray direction (6, same layout).
type Moments = [f64; 15];

const SUM: usize = 0;
const PP: usize = 3;
const DD: usize = 9;

/// A point's [`Moments`], computed when it is added: stored with every point they would triple
/// the grid's size, and the passes over it would cost more in memory traffic than they save.
fn moments(p: &Vector3<f64>, d: &Vector3<f64>) -> Moments {
    let ([p0, p1, p2, p3, p4, p5], [d0, d1, d2, d3, d4, d5]) = (outer_upper(p), outer_upper(d));
    [
        p.x, p.y, p.z, p0, p1, p2, p3, p4, p5, d0, d1, d2, d3, d4, d5,
    ]
}

/// `v v^T`'s upper triangle, laid out as in [`Moments`].
fn outer_upper(v: &Vector3<f64>) -> [f64; 6] {
    std::array::from_fn(|t| v[UPPER_I[t]] * v[UPPER_J[t]])
}

impl PlaneAccumulator {
    pub fn add(&mut self, gp: &GridPoint) {
        // `add_weighted(gp, 1.0)` without its 15 multiplications: the hottest loop of leveling
        // (3% more instructions through the weighted one).
        self.n += 1;
        self.weight += 1.0;
        for (s, m) in self.sums.iter_mut().zip(&moments(&gp.p.coords, &gp.dir)) {
            *s += m;
        }
    }

    /// Adds a point with weight `w` in [0, 1] (robust refits).
    pub(crate) fn add_weighted(&mut self, gp: &GridPoint, w: f64) {
        self.n += 1;
        self.weight += w;
        for (s, m) in self.sums.iter_mut().zip(&moments(&gp.p.coords, &gp.dir)) {
            *s += w * m;
        }
    }

    /// Scales every weight by `k` (the point count stays).
    pub(crate) fn scale(&mut self, k: f64) {
        self.weight *= k;
        for s in &mut self.sums {
            *s *= k;
        }
    }

    /// The accumulator of the points in `self` but not in `part` (a subset of them).
    pub fn minus(&self, part: &PlaneAccumulator) -> PlaneAccumulator {
        let mut out = *self;
        out.n -= part.n;
        out.weight -= part.weight;
        for (s, m) in out.sums.iter_mut().zip(&part.sums) {
            *s -= m;
        }
        out
    }

    /// Fits the plane; `sigma` is the range noise \[m\] used for the bias correction (0 for none).
    pub fn fit(&self, sigma: f64) -> Option<PlaneFit> {
        if self.n < 3 || self.weight < 3.0 {
            return None;
        }
        let nf = self.weight;
        // Upper triangles (layout of [`Moments`]): the raw scatter about the weighted centroid
        // `c`, and that minus the expected noise along the rays.
        let c = Vector3::new(self.sums[SUM], self.sums[SUM + 1], self.sums[SUM + 2]) / nf;
        let cv = [c.x, c.y, c.z];
        let raw: [f64; 6] =
            std::array::from_fn(|t| self.sums[PP + t] - nf * cv[UPPER_I[t]] * cv[UPPER_J[t]]);
        let dd = &self.sums[DD..DD + 6];
        let k = sigma * sigma * (nf - 1.0) / nf;
        let corrected: [f64; 6] = std::array::from_fn(|t| raw[t] - dd[t] * k);
        let eig = super::eigen3::sym_eigen3_upper(&corrected);
        let normal = eig.vectors[0].try_normalize(1e-300)?;
        // Noise along the normal: sigma^2 * mean (d . n)^2.
        let dn2 = quadratic_form(dd, &normal) / nf;
        let residual_ss = quadratic_form(&raw, &normal).max(0.0);
        Some(PlaneFit {
            centroid: Point3::from(c),
            normal,
            in_plane: [
                (eig.values[1], eig.vectors[1]),
                (eig.values[2], eig.vectors[2]),
            ],
            n: self.n,
            weight: nf,
            dn2,
            residual_ss,
        })
    }
}

/// `v^T A v` for the symmetric `A` of upper triangle `a` (layout of [`Moments`]).
fn quadratic_form(a: &[f64], v: &Vector3<f64>) -> f64 {
    a[0] * v.x * v.x
        + a[3] * v.y * v.y
        + a[5] * v.z * v.z
        + 2.0 * (a[1] * v.x * v.y + a[2] * v.x * v.z + a[4] * v.y * v.z)
}

/// A fitted plane with what its normal's uncertainty needs.
#[derive(Clone, Copy, Debug)]
pub struct PlaneFit {
    pub centroid: Point3<f64>,
    /// Unit normal (sign arbitrary).
    pub normal: Vector3<f64>,
    /// The two in-plane eigenpairs of the corrected scatter (eigenvalue [m^2], unit vector).
    pub in_plane: [(f64, Vector3<f64>); 2],
    pub n: usize,
    /// Sum of the points' weights (= n when unweighted).
    pub weight: f64,
    /// Mean of (d . n)^2 over the rays: the share of range noise that acts along the normal.
    pub dn2: f64,
    /// Sum of squared distances of the points to the plane [m^2].
    pub residual_ss: f64,
}

impl PlaneFit {
    pub(crate) fn distance(&self, p: &Point3<f64>) -> f64 {
        self.normal.dot(&(p - self.centroid))
    }

    /// Variance of `n . u` for a unit vector `u` (nearly) in the plane, from first-order TLS
    /// perturbation: `sigma_n^2 * sum_k (u . e_k)^2 / lambda_k` over the in-plane eigenpairs,
    /// with `sigma_n^2 = sigma^2 * mean (d . n)^2` the noise along the normal.
    pub(crate) fn normal_variance_along(&self, u: &Vector3<f64>, sigma: f64) -> f64 {
        let sn2 = (sigma * sigma * self.dn2).max(1e-12);
        let share = |(l, e): &(f64, Vector3<f64>)| u.dot(e).powi(2) / l.max(1e-12);
        self.in_plane.iter().map(share).sum::<f64>() * sn2
    }

    /// Observed over expected residual variance (1 for a clean planar patch); more than 1
    /// means the points are not one plane with this noise (a corner, clutter, floor points).
    pub(crate) fn misfit_ratio(&self, sigma: f64) -> f64 {
        let dof = (self.weight - 3.0).max(1.0);
        let expected = (sigma * sigma * self.dn2).max(1e-12) * dof;
        self.residual_ss / expected
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The cache answers as a fresh computation would, whether the bearings repeat, change,
    /// or differ between the scans of a pose.
    #[test]
    fn bearing_trig_cache_follows_the_bearings() {
        let pose = |n: usize, lo: f64| vec![Scan::with_even_bearings(n, lo, 1.0); 3];
        let mut cache = BearingTrigCache::default();
        let mixed = vec![
            Scan::with_even_bearings(9, -1.0, 1.0),
            Scan::with_even_bearings(9, -0.5, 1.0),
        ];
        for scans in [
            pose(9, -1.0),
            pose(9, -1.0),
            pose(9, -0.5),
            mixed,
            pose(11, -0.5),
            pose(9, -1.0),
        ] {
            let fresh = BearingTrigCache::default().shared(&scans);
            assert_eq!(cache.shared(&scans).as_deref(), fresh.as_deref());
            if let Some(t) = fresh {
                assert_eq!(t[0], scans[0].theta[0].sin_cos());
            }
        }
        assert!(cache.shared(&[]).is_none());
    }

    /// The shared sines and cosines are taken only when every scan has the same bearings to the
    /// bit, and give the grid that computing them per scan gives.
    #[test]
    fn shared_bearing_trig_gives_the_same_grid() {
        let scan = |e: f64, flip_zero: bool| {
            let mut s = Scan::with_even_bearings(9, -1.0, 1.0);
            if flip_zero {
                s.theta[4] = -0.0;
            }
            s.elevation = Some(e);
            s.hinge_offset = Some([0.05, 0.0, 0.02]);
            for i in 0..9 {
                s.readings[i] = Some(1.0 + 0.1 * i as f64 + e);
                s.valid[i] = i != 3;
            }
            s
        };
        let same: Vec<Scan> = [0.1, -0.2, 0.0, 0.3].map(|e| scan(e, false)).to_vec();
        let shared_bearing_trig = |s: &[Scan]| BearingTrigCache::default().shared(s);
        let trig = shared_bearing_trig(&same).expect("same bearings");
        let shared = PoseGrid::from_scans_with(&same, Some(&trig)).unwrap();
        let own = PoseGrid::from_scans(&same).unwrap();
        assert_eq!(shared.points, own.points);
        assert_eq!(shared.scan_index, own.scan_index);
        // +0 and -0 compare equal but are different bearings.
        let mixed = vec![scan(0.1, false), scan(-0.2, true), scan(0.0, false)];
        assert!(shared_bearing_trig(&mixed).is_none());
        assert!(shared_bearing_trig(&[]).is_none());
    }

    fn gp(x: f64, y: f64, z: f64) -> GridPoint {
        let p = Point3::new(x, y, z);
        GridPoint {
            p,
            dir: p.coords.normalize(),
            range: p.coords.norm(),
        }
    }

    #[test]
    fn plane_fit_recovers_exact_wall_normal() {
        let mut acc = PlaneAccumulator::default();
        for i in 0..5 {
            for j in 0..4 {
                acc.add(&gp(3.0, i as f64 * 0.3 - 0.6, j as f64 * 0.2 - 0.3));
            }
        }
        let f = acc.fit(0.0).unwrap();
        assert!((f.normal.x.abs() - 1.0).abs() < 1e-12);
        assert!(f.residual_ss < 1e-20);
        assert!((f.centroid.x - 3.0).abs() < 1e-12);
    }
}
