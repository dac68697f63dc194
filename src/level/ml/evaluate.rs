//! One pass over the used points at a state of the refinement: the robust cost, the
//! arrow-shaped normal equations ([`Arrow`]) and every point's predicted range, together.
//!
//! The model is [`super::model`]'s, rearranged so that a point costs a handful of dot
//! products: `n . (L x) = (L^T n) . x`, so each surface's normal (and a wall's tangent) is
//! rotated back into the robot frame once per state, with the attitude's derivatives, rather
//! than every point being rotated into the level frame ([`Frame`]). The points of one surface
//! are stored together ([`Ray`], in surface order), so each surface's block of the normal
//! equations is summed in one run. A trial state's pass gives the normal equations there too:
//! a step of Levenberg-Marquardt is nearly always accepted (its damping starts at 1e-6), and
//! then the next step, and the covariance at the end, need no pass of their own.

use super::LabelledPoint;
use super::model::{MIN_INCIDENCE, Plane, Rotations, off_grazing};
use nalgebra::{Matrix2, Vector2, Vector3};

/// The arrow-shaped normal equations at one state.
#[derive(Clone, Debug, Default)]
pub(crate) struct Arrow {
    pub h_aa: Matrix2<f64>,
    pub g_a: Vector2<f64>,
    /// Per surface: `H_as`, `H_ss`, `g_s`.
    pub blocks: Vec<(Matrix2<f64>, Matrix2<f64>, Vector2<f64>)>,
}

/// A point the fit uses, as the passes read it.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Ray {
    /// Its index in the refinement's input.
    pub index: usize,
    /// Its surface's index.
    pub slot: usize,
    pub origin: Vector3<f64>,
    pub dir: Vector3<f64>,
    pub range: f64,
    pub sigma: f64,
    /// The measured point `o + u r` (robot frame), which the plane residual places.
    pub point: Vector3<f64>,
    /// The plane residual's scale `1 / (sigma max(b, MIN_INCIDENCE))`, for `b` the incidence
    /// frozen when the ray was taken in ([`super::model::linearize_plane`]).
    pub plane_scale: f64,
}

impl Ray {
    /// Point `index` of the input, on surface `slot`, met at `incidence` (`|n . L u|`, frozen
    /// for the plane residual).
    pub fn new(index: usize, slot: usize, p: &LabelledPoint, incidence: f64) -> Self {
        Ray {
            index,
            slot,
            origin: p.origin.coords,
            dir: p.dir,
            range: p.range,
            sigma: p.sigma,
            point: p.origin.coords + p.dir * p.range,
            plane_scale: 1.0 / (p.sigma * incidence.max(MIN_INCIDENCE)),
        }
    }
}

/// Which residual the pass takes (the module [`super::solve`] explains both).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Residual {
    /// The range residual `(r - r^) / sigma`: the likelihood's.
    Range,
    /// The measured point's distance from its plane at a frozen incidence: the approach's.
    Plane,
}

/// A surface's plane at one state, carried back into the robot frame: `L^T n` (so that
/// `n . L x = normal . x`), the attitude's derivatives `(dL/d theta_k)^T n`, and a wall's
/// tangent `L^T t` (zero for the floor and ceiling, whose azimuth is not a parameter).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Frame {
    normal: Vector3<f64>,
    by_theta: [Vector3<f64>; 2],
    tangent: Vector3<f64>,
    offset: f64,
    /// The floor or ceiling (no azimuth).
    level: bool,
}

impl Frame {
    pub fn at(plane: &Plane, rot: &Rotations) -> Self {
        let n = &plane.normal;
        Frame {
            normal: rot.level_from_robot.tr_mul(n),
            by_theta: [rot.by_theta[0].tr_mul(n), rot.by_theta[1].tr_mul(n)],
            tangent: plane
                .tangent
                .map_or(Vector3::zeros(), |t| rot.level_from_robot.tr_mul(&t)),
            offset: plane.offset,
            level: plane.tangent.is_none(),
        }
    }

    /// `|n . L u|` of a ray along `dir`: the share of its range noise along the normal.
    pub fn incidence(&self, dir: &Vector3<f64>) -> f64 {
        self.normal.dot(dir).abs()
    }

    /// The range the model predicts for `ray`, and the divisor `b = n . L u` it took (kept
    /// from zero by [`MIN_INCIDENCE`]), as [`super::model::predict`].
    fn predict(&self, ray: &Ray) -> (f64, f64) {
        let b = off_grazing(self.normal.dot(&ray.dir));
        ((self.offset - self.normal.dot(&ray.origin)) / b, b)
    }

    /// `ray`'s normalised residual `rho`, the point `q` and scale its derivatives take, and
    /// (for the range residual) its predicted range.
    pub fn residual(&self, ray: &Ray, residual: Residual) -> (f64, Vector3<f64>, f64, Option<f64>) {
        match residual {
            Residual::Range => {
                let (predicted, b) = self.predict(ray);
                let q = ray.origin + ray.dir * predicted;
                let scale = 1.0 / (b * ray.sigma);
                (
                    (ray.range - predicted) / ray.sigma,
                    q,
                    scale,
                    Some(predicted),
                )
            }
            Residual::Plane => {
                let rho = (self.normal.dot(&ray.point) - self.offset) * ray.plane_scale;
                (rho, ray.point, ray.plane_scale, None)
            }
        }
    }

    /// The residual's derivatives by the attitude and by the surface's `(offset, azimuth)`
    /// at the point `q` and `scale` of [`Self::residual`]: `d r^/d theta = -n . L' q / b`,
    /// `d r^/d d = 1 / b`, `d r^/d a = -t . L q / b` (the plane residual's are the same at
    /// its frozen incidence), negated and over `sigma` for `rho = (r - r^) / sigma`.
    pub fn jacobians(&self, q: &Vector3<f64>, scale: f64) -> ([f64; 2], [f64; 2]) {
        let ja = [
            self.by_theta[0].dot(q) * scale,
            self.by_theta[1].dot(q) * scale,
        ];
        (ja, [-scale, self.tangent.dot(q) * scale])
    }
}

/// What a pass gives: the robust cost, the normal equations (when asked for) and, for the
/// range residual, each ray's predicted range and (with the normal equations) its [`Score`]
/// (in `rays`' order).
#[derive(Clone, Debug, Default)]
pub(crate) struct Evaluation {
    pub cost: f64,
    pub arrow: Arrow,
    pub predicted: Vec<f64>,
    pub scores: Vec<Score>,
}

/// A ray's share of the score at one state: its residual's Jacobians by the attitude and by
/// its surface's placement, and its Huber-weighted residual `w rho`. Kept by the range
/// residual's passes for the cluster-robust covariance at the final state
/// ([`super::cluster::clustered_meat`]), which would otherwise pass over the rays once more
/// to compute them again (3% of leveling's instructions).
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Score {
    pub by_attitude: [f64; 2],
    pub by_placement: [f64; 2],
    pub weighted: f64,
}

pub(crate) fn huber_cost(rho: f64, k: f64) -> f64 {
    let a = rho.abs();
    if a <= k {
        0.5 * rho * rho
    } else {
        k * a - 0.5 * k * k
    }
}

pub(crate) fn huber_weight(rho: f64, k: f64) -> f64 {
    let a = rho.abs();
    if a <= k { 1.0 } else { k / a }
}

/// The pass over `rays` (in surface order) at the state whose surfaces are `frames`, with
/// Huber threshold `k`, into `out`; the normal equations only `with_arrow`. The floor's and
/// ceiling's unused azimuth gets a unit diagonal, so that every block stays invertible.
pub(crate) fn evaluate(
    rays: &[Ray],
    frames: &[Frame],
    residual: Residual,
    k: f64,
    with_arrow: bool,
    out: &mut Evaluation,
) {
    let arrow = &mut out.arrow;
    arrow.h_aa = Matrix2::zeros();
    arrow.g_a = Vector2::zeros();
    arrow.blocks.clear();
    arrow.blocks.resize(
        frames.len(),
        (Matrix2::zeros(), Matrix2::zeros(), Vector2::zeros()),
    );
    // The residual and whether the normal equations are wanted are fixed for the pass: one
    // loop for each, without their tests per ray (the passes are a sixth of leveling).
    out.cost = match (residual, with_arrow) {
        (Residual::Range, true) => pass::<true, true>(rays, frames, k, out),
        (Residual::Range, false) => pass::<true, false>(rays, frames, k, out),
        (Residual::Plane, true) => pass::<false, true>(rays, frames, k, out),
        (Residual::Plane, false) => pass::<false, false>(rays, frames, k, out),
    };
    for (block, frame) in out.arrow.blocks.iter_mut().zip(frames) {
        if frame.level {
            block.1[(1, 1)] = 1.0;
        }
    }
}

/// [`evaluate`]'s loop for the range residual (`RANGE`) or the plane residual, with the
/// normal equations (`ARROW`) or without: fills `out`'s predicted ranges and scores (for the
/// range residual) and normal equations, and returns the cost.
fn pass<const RANGE: bool, const ARROW: bool>(
    rays: &[Ray],
    frames: &[Frame],
    k: f64,
    out: &mut Evaluation,
) -> f64 {
    let residual = if RANGE {
        Residual::Range
    } else {
        Residual::Plane
    };
    // Every ray's slot written in place, sized at once (and not cleared first: every slot is
    // written, and an evaluation reused for the next trial keeps its size): pushing tested the
    // room per ray and growing by doubling copied them.
    let (n_predicted, n_scores) = match (RANGE, ARROW) {
        (true, true) => (rays.len(), rays.len()),
        (true, false) => (rays.len(), 0),
        _ => (0, 0),
    };
    out.predicted.resize(n_predicted, 0.0);
    out.scores.resize(n_scores, Score::default());
    // Sliced to their sizes, so that the compiler sees every ray's index in range and drops
    // the bounds checks.
    let (predicted_out, scores_out) = (
        &mut out.predicted[..n_predicted],
        &mut out.scores[..n_scores],
    );
    let arrow = &mut out.arrow;
    let mut cost = 0.0;
    // The rays come in runs of one surface (surface order): each run's sums are kept apart
    // and added to the normal equations when the run ends.
    let Some(first) = rays.first() else {
        return cost;
    };
    let mut slot = first.slot;
    let mut frame = &frames[slot];
    let mut sums = Sums::default();
    for (i, ray) in rays.iter().enumerate() {
        if ray.slot != slot {
            if ARROW {
                std::mem::take(&mut sums).into_arrow(arrow, slot);
            }
            slot = ray.slot;
            frame = &frames[slot];
        }
        let (rho, q, scale, predicted) = frame.residual(ray, residual);
        if RANGE {
            predicted_out[i] = predicted.unwrap_or_default();
        }
        cost += huber_cost(rho, k);
        if ARROW {
            let (ja, js) = frame.jacobians(&q, scale);
            let w = huber_weight(rho, k);
            if RANGE {
                scores_out[i] = Score {
                    by_attitude: ja,
                    by_placement: js,
                    weighted: w * rho,
                };
            }
            sums.add(rho, ja, js, w);
        }
    }
    if ARROW {
        sums.into_arrow(arrow, slot);
    }
    cost
}

/// One surface's sums of the normal equations over its run of rays, kept in scalars.
#[derive(Default)]
struct Sums {
    aa: [f64; 3],
    ga: [f64; 2],
    as_: [f64; 4],
    ss: [f64; 3],
    gs: [f64; 2],
}

impl Sums {
    fn add(&mut self, rho: f64, ja: [f64; 2], js: [f64; 2], w: f64) {
        let wa = [ja[0] * w, ja[1] * w];
        let ws = [js[0] * w, js[1] * w];
        self.aa[0] += ja[0] * wa[0];
        self.aa[1] += ja[0] * wa[1];
        self.aa[2] += ja[1] * wa[1];
        self.ga[0] += wa[0] * rho;
        self.ga[1] += wa[1] * rho;
        self.as_[0] += wa[0] * js[0];
        self.as_[1] += wa[0] * js[1];
        self.as_[2] += wa[1] * js[0];
        self.as_[3] += wa[1] * js[1];
        self.ss[0] += js[0] * ws[0];
        self.ss[1] += js[0] * ws[1];
        self.ss[2] += js[1] * ws[1];
        self.gs[0] += ws[0] * rho;
        self.gs[1] += ws[1] * rho;
    }

    /// Adds the sums to the attitude's rows of `arrow` and to surface `slot`'s block.
    fn into_arrow(self, arrow: &mut Arrow, slot: usize) {
        arrow.h_aa += Matrix2::new(self.aa[0], self.aa[1], self.aa[1], self.aa[2]);
        arrow.g_a += Vector2::new(self.ga[0], self.ga[1]);
        let block = &mut arrow.blocks[slot];
        block.0 += Matrix2::new(self.as_[0], self.as_[1], self.as_[2], self.as_[3]);
        block.1 += Matrix2::new(self.ss[0], self.ss[1], self.ss[1], self.ss[2]);
        block.2 += Vector2::new(self.gs[0], self.gs[1]);
    }
}
