//! Levenberg-Marquardt on the attitude and every surface's placement, the placements
//! eliminated per step by the Schur complement.
//!
//! Each point meets one surface, so the Gauss-Newton matrix is an arrow: the attitude's 2x2
//! block, one 2x2 block per surface, and the attitude's coupling to each. Eliminating the
//! surfaces leaves a 2x2 system, `S = H_aa - sum_s H_as H_ss^-1 H_sa` (Triggs et al. 2000,
//! *Bundle adjustment: a modern synthesis*, sect. 6.1), whose inverse at the optimum is the
//! attitude's covariance with the placements marginalised: the Cramér-Rao bound's
//! construction (Kay 1993, ch. 3), evaluated at the estimate. Points are weighted by the
//! Huber kernel (iteratively reweighted least squares); the floor's and ceiling's unused
//! azimuth slot gets a unit diagonal so every block stays 2x2 and invertible.

use super::model::{
    Linearized, Placement, Plane, Rotations, incidence_on, initial_placement, linearize_on,
    linearize_plane, linearize_predicted, plane_rho, predict, range_rho,
};
use super::{LabelledPoint, MlError, MlParams, MlSolution, Surface, SurfaceFit, WallLine};
use crate::geometry::Attitude;
use nalgebra::{Matrix2, Vector2};

/// The arrow-shaped normal equations at one state.
struct Arrow {
    h_aa: Matrix2<f64>,
    g_a: Vector2<f64>,
    /// Per surface: `H_as`, `H_ss`, `g_s`.
    blocks: Vec<(Matrix2<f64>, Matrix2<f64>, Vector2<f64>)>,
}

/// The points' grouping by surface and the state being refined.
struct State<'a> {
    points: &'a [LabelledPoint],
    /// Per point: its surface's index in `surfaces`, `None` when left out.
    slot: Vec<Option<usize>>,
    surfaces: Vec<Surface>,
    theta: Vector2<f64>,
    placements: Vec<Placement>,
    /// While approaching from far: each point's incidence, frozen for one iteration (the
    /// plane residual, [`linearize_plane`]); `None` for the range residual.
    frozen: Option<Vec<f64>>,
    /// Per point: used in the fit (on a kept surface, and not grazing it).
    active: Vec<bool>,
    /// Per point, for the range residual at the current state: [`predict`]'s `(r^, b)` as
    /// the cost of that state computed them (NaN for a point not used), so the normal
    /// equations there need not predict again; empty when not known.
    predictions: Vec<(f64, f64)>,
}

/// Refines up from `up0` (robot frame, any length) and the labelled points: the maximum
/// likelihood under Gaussian range noise, made robust by the Huber kernel.
pub(crate) fn refine(
    points: &[LabelledPoint],
    up0: &nalgebra::Vector3<f64>,
    params: &MlParams,
) -> Result<MlSolution, MlError> {
    let good = |p: &LabelledPoint| {
        let finite = p
            .origin
            .coords
            .iter()
            .chain(p.dir.iter())
            .all(|v| v.is_finite());
        finite && p.range.is_finite() && p.range > 0.0 && p.sigma.is_finite() && p.sigma > 0.0
    };
    if !points.iter().all(good) {
        return Err(MlError::BadPoint);
    }
    let start = Attitude::from_up(up0);
    let mut state = State::new(points, Vector2::new(start.theta_x, start.theta_y), params);
    let parameters = 2 + 2 * state.surfaces.len();
    if state.active.iter().filter(|&&a| a).count() <= parameters {
        return Err(MlError::TooFewPoints);
    }
    // From far: least squares on the plane residuals, into the basin; then the likelihood
    // itself, robustly.
    state.frozen = Some(Vec::new());
    state.freeze(params.min_incidence);
    if observable_schur(&state.arrow(f64::INFINITY)).is_none() {
        return Err(MlError::Unobservable);
    }
    let approach = if params.approach {
        state.minimise(params, f64::INFINITY, APPROACH_TOLERANCE).0
    } else {
        0
    };
    state.frozen = None;
    if approach > 0 {
        // The approach moved the state: which points graze their plane moved with it.
        state.activate(params.min_incidence);
    }
    let (iterations, converged) = state.minimise(params, params.huber_k, params.step_tolerance);
    let up = Attitude::new(state.theta.x, state.theta.y).up_in_robot();
    if up.z < params.max_tilt_deg.to_radians().cos() {
        return Err(MlError::Diverged);
    }
    let at_scanner = [Surface::Floor, Surface::Ceiling]
        .iter()
        .filter_map(|&s| state.height(s))
        .any(|d| d.abs() < params.min_level_clearance);
    if at_scanner {
        return Err(MlError::ScanPlane);
    }
    state.solution(params, approach + iterations, converged)
}

/// The approach ends when its attitude step is below this \[rad\] (0.06 millidegrees): well
/// inside the likelihood's basin.
const APPROACH_TOLERANCE: f64 = 1e-6;

/// The points' indices grouped by surface, the surfaces in their order (a few surfaces, so a
/// short list searched from the last one found: the points of a surface come in runs).
fn group_by_surface(points: &[LabelledPoint]) -> Vec<(Surface, Vec<usize>)> {
    let mut groups: Vec<(Surface, Vec<usize>)> = Vec::new();
    let mut last = 0;
    for (i, p) in points.iter().enumerate() {
        if groups.get(last).is_none_or(|g| g.0 != p.surface) {
            last = match groups.iter().position(|g| g.0 == p.surface) {
                Some(j) => j,
                None => {
                    groups.push((p.surface, Vec::new()));
                    groups.len() - 1
                }
            };
        }
        groups[last].1.push(i);
    }
    groups.sort_by_key(|g| g.0);
    groups
}

fn huber_cost(rho: f64, k: f64) -> f64 {
    let a = rho.abs();
    if a <= k {
        0.5 * rho * rho
    } else {
        k * a - 0.5 * k * k
    }
}

fn huber_weight(rho: f64, k: f64) -> f64 {
    let a = rho.abs();
    if a <= k { 1.0 } else { k / a }
}

impl<'a> State<'a> {
    /// Groups the points by surface (keeping surfaces with enough points whose placement can
    /// be fitted at the starting attitude) and places each surface.
    fn new(points: &'a [LabelledPoint], theta: Vector2<f64>, params: &MlParams) -> Self {
        let rot = Rotations::at(&theta);
        let groups = group_by_surface(points);
        let mut slot = vec![None; points.len()];
        let mut surfaces = Vec::new();
        let mut placements = Vec::new();
        for (surface, members) in groups {
            if members.len() < params.min_surface_points {
                continue;
            }
            let pts: Vec<&LabelledPoint> = members.iter().map(|&i| &points[i]).collect();
            let Some(placement) = initial_placement(&pts, surface, &rot) else {
                continue;
            };
            for &i in &members {
                slot[i] = Some(surfaces.len());
            }
            surfaces.push(surface);
            placements.push(placement);
        }
        State {
            points,
            surfaces,
            theta,
            placements,
            frozen: None,
            predictions: Vec::new(),
            active: slot.iter().map(Option::is_some).collect(),
            slot,
        }
    }

    /// Uses the points on a kept surface whose ray meets it at an incidence `|n . L u|` of
    /// at least `min_incidence` at the current state.
    fn activate(&mut self, min_incidence: f64) {
        self.predictions.clear();
        let rot = Rotations::at(&self.theta);
        let planes = self.planes(&self.placements);
        self.active = self
            .points
            .iter()
            .zip(&self.slot)
            .map(|(p, s)| {
                s.is_some_and(|s| incidence_on(p, &planes[s].normal, &rot) >= min_incidence)
            })
            .collect();
    }

    /// Every surface's plane at `placements`.
    fn planes(&self, placements: &[Placement]) -> Vec<Plane> {
        self.surfaces
            .iter()
            .zip(placements)
            .map(|(&s, p)| Plane::at(p, s))
            .collect()
    }

    /// Point `i`'s residual at a trial state, by the current mode.
    fn residual(&self, i: usize, plane: &Plane, rot: &Rotations) -> Linearized {
        let p = &self.points[i];
        match &self.frozen {
            Some(b) => linearize_plane(p, plane, rot, b[i]),
            None => linearize_on(p, plane, rot),
        }
    }

    /// [`Self::residual`]'s value alone.
    fn rho(&self, i: usize, plane: &Plane, rot: &Rotations) -> f64 {
        let p = &self.points[i];
        match &self.frozen {
            Some(b) => plane_rho(p, plane, rot, b[i]),
            None => range_rho(p, plane, rot),
        }
    }

    /// Freezes every point's incidence at the current state, and uses only those not grazing
    /// their plane (plane mode only).
    fn freeze(&mut self, min_incidence: f64) {
        if self.frozen.is_none() {
            return;
        }
        self.predictions.clear();
        let rot = Rotations::at(&self.theta);
        let planes = self.planes(&self.placements);
        let b: Vec<f64> = self
            .points
            .iter()
            .zip(&self.slot)
            .map(|(p, s)| s.map_or(1.0, |s| incidence_on(p, &planes[s].normal, &rot)))
            .collect();
        self.active = self
            .slot
            .iter()
            .zip(&b)
            .map(|(s, &b)| s.is_some() && b >= min_incidence)
            .collect();
        self.frozen = Some(b);
    }

    /// The robust cost at a trial state; for the range residual, each point's prediction
    /// there into `predictions` (else it is left empty).
    fn cost(
        &self,
        theta: &Vector2<f64>,
        placements: &[Placement],
        k: f64,
        predictions: &mut Vec<(f64, f64)>,
    ) -> f64 {
        let rot = Rotations::at(theta);
        let planes = self.planes(placements);
        predictions.clear();
        if self.frozen.is_some() {
            return (0..self.points.len())
                .filter_map(|i| {
                    let s = self.slot[i].filter(|_| self.active[i])?;
                    Some(huber_cost(self.rho(i, &planes[s], &rot), k))
                })
                .sum();
        }
        predictions.resize(self.points.len(), (f64::NAN, f64::NAN));
        (0..self.points.len())
            .filter_map(|i| {
                let s = self.slot[i].filter(|_| self.active[i])?;
                let p = &self.points[i];
                let pred = predict(p, &planes[s], &rot);
                predictions[i] = pred;
                Some(huber_cost((p.range - pred.0) / p.sigma, k))
            })
            .sum()
    }

    /// The weighted normal equations at the current state.
    fn arrow(&self, k: f64) -> Arrow {
        let rot = Rotations::at(&self.theta);
        let planes = self.planes(&self.placements);
        let cached = self.frozen.is_none() && self.predictions.len() == self.points.len();
        let mut arrow = Arrow {
            h_aa: Matrix2::zeros(),
            g_a: Vector2::zeros(),
            blocks: vec![
                (Matrix2::zeros(), Matrix2::zeros(), Vector2::zeros());
                self.surfaces.len()
            ],
        };
        for i in 0..self.points.len() {
            let Some(s) = self.slot[i].filter(|_| self.active[i]) else {
                continue;
            };
            let lin = match self.predictions.get(i).filter(|_| cached) {
                Some(&pred) => linearize_predicted(&self.points[i], &planes[s], &rot, pred),
                None => self.residual(i, &planes[s], &rot),
            };
            let w = huber_weight(lin.rho, k);
            let (ja, js) = (lin.by_attitude, lin.by_placement);
            arrow.h_aa += ja * ja.transpose() * w;
            arrow.g_a += ja * (lin.rho * w);
            let block = &mut arrow.blocks[s];
            block.0 += ja * js.transpose() * w;
            block.1 += js * js.transpose() * w;
            block.2 += js * (lin.rho * w);
        }
        for (surface, block) in self.surfaces.iter().zip(&mut arrow.blocks) {
            if !matches!(surface, Surface::Wall(_)) {
                block.1[(1, 1)] = 1.0;
            }
        }
        arrow
    }

    /// Runs Levenberg-Marquardt with Huber threshold `k` until the attitude step is below
    /// `tolerance`: `(iterations, converged)`.
    fn minimise(&mut self, params: &MlParams, k: f64, tolerance: f64) -> (usize, bool) {
        let mut lambda = 1e-6;
        // The range residual's cost carries over from the step accepted; the plane
        // residual's changes with every freeze.
        let mut kept_cost: Option<f64> = None;
        let mut trial_predictions = Vec::new();
        for iteration in 1..=params.max_iterations {
            self.freeze(params.min_incidence);
            let mut cost = match kept_cost.filter(|_| self.frozen.is_none()) {
                Some(c) => c,
                None => {
                    let mut predictions = std::mem::take(&mut self.predictions);
                    let c = self.cost(&self.theta, &self.placements, k, &mut predictions);
                    self.predictions = predictions;
                    c
                }
            };
            let arrow = self.arrow(k);
            let mut accepted = false;
            let mut step_norm = f64::INFINITY;
            // Damp until the cost falls (Marquardt's scaling by the diagonal).
            for _ in 0..12 {
                let Some((d_theta, d_place)) = damped_step(&arrow, lambda) else {
                    lambda *= 10.0;
                    continue;
                };
                let theta = self.theta + d_theta;
                let placements: Vec<Placement> = self
                    .placements
                    .iter()
                    .zip(&d_place)
                    .map(|(p, d)| Placement {
                        offset: p.offset + d.x,
                        azimuth: p.azimuth + d.y,
                    })
                    .collect();
                let trial = self.cost(&theta, &placements, k, &mut trial_predictions);
                step_norm = d_theta.norm();
                if trial <= cost {
                    self.theta = theta;
                    self.placements = placements;
                    std::mem::swap(&mut self.predictions, &mut trial_predictions);
                    let settled = cost - trial <= 1e-14 * cost.max(1e-300);
                    cost = trial;
                    kept_cost = Some(cost);
                    lambda = (lambda / 10.0).max(1e-12);
                    accepted = true;
                    if settled {
                        step_norm = 0.0;
                    }
                    break;
                }
                lambda *= 10.0;
            }
            if !accepted || step_norm < tolerance {
                return (iteration, accepted || step_norm < tolerance);
            }
        }
        (params.max_iterations, false)
    }

    /// The estimate at the current state: covariance, residuals and the chi-square test.
    fn solution(
        &self,
        params: &MlParams,
        iterations: usize,
        converged: bool,
    ) -> Result<MlSolution, MlError> {
        let k = params.huber_k;
        let schur = observable_schur(&self.arrow(k)).ok_or(MlError::Unobservable)?;
        let cov = schur.try_inverse().ok_or(MlError::Unobservable)?;
        let rot = Rotations::at(&self.theta);
        let planes = self.planes(&self.placements);
        // The range residuals at the state, from the predictions its cost made when known.
        let cached = self.predictions.len() == self.points.len();
        let residuals: Vec<Option<f64>> = (0..self.points.len())
            .map(|i| {
                let s = self.slot[i].filter(|_| self.active[i])?;
                let p = &self.points[i];
                Some(match cached {
                    true => (p.range - self.predictions[i].0) / p.sigma,
                    false => range_rho(p, &planes[s], &rot),
                })
            })
            .collect();
        let clipped = |r: f64| (r * r).min(k * k);
        let mut surfaces: Vec<SurfaceFit> = self
            .surfaces
            .iter()
            .map(|&surface| SurfaceFit {
                surface,
                points: 0,
                chi2: 0.0,
                dof: if matches!(surface, Surface::Wall(_)) {
                    -2.0
                } else {
                    -1.0
                },
            })
            .collect();
        for (r, s) in residuals.iter().zip(&self.slot) {
            if let (Some(r), Some(s)) = (r, s) {
                surfaces[*s].points += 1;
                surfaces[*s].chi2 += clipped(*r);
                surfaces[*s].dof += 1.0;
            }
        }
        let chi2: f64 = surfaces.iter().map(|s| s.chi2).sum();
        let dof = surfaces.iter().map(|s| s.dof).sum::<f64>() - 2.0;
        let (mean, var) = clipped_chi2_moments(k);
        let chi2_expected = mean * dof;
        let chi2_spread = (var * dof).sqrt();
        let inflation = if chi2 > chi2_expected + params.inflation_z * chi2_spread {
            chi2 / chi2_expected
        } else {
            1.0
        };
        let cov = cov * inflation;
        let attitude = Attitude::new(self.theta.x, self.theta.y);
        Ok(MlSolution {
            attitude: [self.theta.x, self.theta.y],
            up: attitude.up_in_robot(),
            covariance: [[cov[(0, 0)], cov[(0, 1)]], [cov[(1, 0)], cov[(1, 1)]]],
            inflation,
            walls: self.lines(),
            floor: self.height(Surface::Floor),
            ceiling: self.height(Surface::Ceiling),
            residuals,
            chi2,
            dof,
            chi2_expected,
            chi2_spread,
            surfaces,
            iterations,
            converged,
        })
    }

    fn lines(&self) -> Vec<WallLine> {
        self.surfaces
            .iter()
            .zip(&self.placements)
            .filter(|(s, _)| matches!(s, Surface::Wall(_)))
            .map(|(&surface, p)| WallLine {
                surface,
                azimuth: p.azimuth,
                offset: p.offset,
            })
            .collect()
    }

    fn height(&self, which: Surface) -> Option<f64> {
        let i = self.surfaces.iter().position(|&s| s == which)?;
        Some(self.placements[i].offset)
    }
}

/// The pseudo-inverse of a surface's own information: a placement the points leave free (a
/// wall seen as one vertical line of points has no azimuth) carries no information, and
/// marginalising it removes none from the attitude, as in the bound (nor does a surface all
/// of whose points are left out).
fn pseudo_inverse(m: &Matrix2<f64>) -> Option<Matrix2<f64>> {
    let eig = m.symmetric_eigen();
    let top = eig.eigenvalues.amax();
    if !top.is_finite() {
        return None;
    }
    let mut inv = Matrix2::zeros();
    for k in 0..2 {
        let l = eig.eigenvalues[k];
        if l > top * 1e-12 && l > 0.0 {
            let v = eig.eigenvectors.column(k);
            inv += v * v.transpose() / l;
        }
    }
    Some(inv)
}

/// The attitude's information with every placement marginalised, when it fixes both tilts:
/// its smaller eigenvalue above 1e-10 of the unmarginalised information's trace (parallel
/// walls alone leave the tilt about their normal free).
fn observable_schur(arrow: &Arrow) -> Option<Matrix2<f64>> {
    let schur = reduced(arrow)?.0;
    let scale = arrow.h_aa.trace();
    let eig = schur.symmetric_eigenvalues();
    (scale > 0.0 && eig.min() > scale * 1e-10).then_some(schur)
}

/// The reduced attitude system `(S, g~)` with every surface eliminated.
fn reduced(arrow: &Arrow) -> Option<(Matrix2<f64>, Vector2<f64>)> {
    let mut s = arrow.h_aa;
    let mut g = arrow.g_a;
    for (h_as, h_ss, g_s) in &arrow.blocks {
        let inv = pseudo_inverse(h_ss)?;
        s -= h_as * inv * h_as.transpose();
        g -= h_as * inv * g_s;
    }
    Some(((s + s.transpose()) * 0.5, g))
}

/// The Gauss-Newton step damped by `lambda` times each diagonal: the attitude's change and
/// each surface's `(offset, azimuth)` change. The residual is `r - r^`, so the step solves
/// `H d = -g` with `g = J^T W rho` of `rho`'s Jacobian.
fn damped_step(arrow: &Arrow, lambda: f64) -> Option<(Vector2<f64>, Vec<Vector2<f64>>)> {
    let damp = |m: &Matrix2<f64>| {
        let mut d = *m;
        d[(0, 0)] *= 1.0 + lambda;
        d[(1, 1)] *= 1.0 + lambda;
        d
    };
    let damped = Arrow {
        h_aa: damp(&arrow.h_aa),
        g_a: arrow.g_a,
        blocks: arrow
            .blocks
            .iter()
            .map(|(h_as, h_ss, g_s)| (*h_as, damp(h_ss), *g_s))
            .collect(),
    };
    let (s, g) = reduced(&damped)?;
    let d_theta = -(s.try_inverse()? * g);
    let d_place = damped
        .blocks
        .iter()
        .map(|(h_as, h_ss, g_s)| {
            Some(-(pseudo_inverse(h_ss)? * (g_s + h_as.transpose() * d_theta)))
        })
        .collect::<Option<Vec<_>>>()?;
    d_theta
        .iter()
        .chain(d_place.iter().flat_map(|d| d.iter()))
        .all(|v| v.is_finite())
        .then_some((d_theta, d_place))
}

/// Mean and variance of `min(z^2, k^2)` for a standard normal `z` (Simpson's rule on
/// `[0, k]`): what one point adds to the clipped chi-square when the model is right.
pub(crate) fn clipped_chi2_moments(k: f64) -> (f64, f64) {
    // Every refinement asks for the same threshold: the last answer is kept per thread
    // (2000 exponentials each, a twentieth of a refinement's work).
    thread_local! {
        static LAST: std::cell::Cell<Option<(u64, (f64, f64))>> = const { std::cell::Cell::new(None) };
    }
    LAST.with(|last| match last.get() {
        Some((bits, moments)) if bits == k.to_bits() => moments,
        _ => {
            let moments = clipped_chi2_moments_of(k);
            last.set(Some((k.to_bits(), moments)));
            moments
        }
    })
}

/// [`clipped_chi2_moments`], computed.
fn clipped_chi2_moments_of(k: f64) -> (f64, f64) {
    let n = 2000;
    let h = k / n as f64;
    let pdf = |z: f64| (-0.5 * z * z).exp() / (2.0 * std::f64::consts::PI).sqrt();
    let (mut p, mut m2, mut m4) = (0.0, 0.0, 0.0);
    for i in 0..=n {
        let z = i as f64 * h;
        let w = if i == 0 || i == n {
            1.0
        } else if i % 2 == 1 {
            4.0
        } else {
            2.0
        };
        let f = pdf(z) * w;
        p += f;
        m2 += f * z * z;
        m4 += f * z.powi(4);
    }
    let (p, m2, m4) = (2.0 * p * h / 3.0, 2.0 * m2 * h / 3.0, 2.0 * m4 * h / 3.0);
    let tail = (1.0 - p).max(0.0);
    let mean = m2 + k * k * tail;
    let second = m4 + k.powi(4) * tail;
    (mean, second - mean * mean)
}
