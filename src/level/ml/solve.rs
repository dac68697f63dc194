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
//! azimuth slot gets a unit diagonal so every block stays 2x2 and invertible. The passes over
//! the points are [`super::evaluate`]'s.

use super::cluster::{clustered_meat, widened};
use super::evaluate::{Arrow, Evaluation, Frame, Ray, Residual, evaluate};
use super::model::{Placement, Plane, Rotations, initial_placement};
use super::{LabelledPoint, MlError, MlParams, MlSolution, Surface, SurfaceFit, WallLine};
use crate::geometry::Attitude;
use crate::geometry::pseudo_inverse_2x2;
use nalgebra::{Matrix2, Vector2};

/// The points' grouping by surface and the state being refined.
struct State<'a> {
    points: &'a [LabelledPoint],
    /// Per kept surface (as `surfaces`), its points' indices, ascending.
    members: Vec<Vec<usize>>,
    surfaces: Vec<Surface>,
    theta: Vector2<f64>,
    placements: Vec<Placement>,
    /// The residual being minimised: the plane residual while approaching from far (at the
    /// incidences frozen in `rays`), then the range residual.
    residual: Residual,
    /// The points used (on a kept surface, and not grazing it), in surface order.
    rays: Vec<Ray>,
    /// The range residual's pass at the current state with the kernel's threshold, when
    /// known (the last accepted step's).
    last: Option<Evaluation>,
}

/// Refines up from `up0` (robot frame, any length) and the labelled points: the maximum
/// likelihood under Gaussian range noise, made robust by the Huber kernel.
pub(crate) fn refine(
    points: &[LabelledPoint],
    up0: &nalgebra::Vector3<f64>,
    params: &MlParams,
) -> Result<MlSolution, MlError> {
    let labels: Vec<Option<Surface>> = points.iter().map(|p| Some(p.surface)).collect();
    refine_labelled(points, &labels, up0, params)
}

/// [`refine`] on the points that `labels` gives a surface (their own `surface` ignored), so
/// that a caller trying several segmentations of the same points need not copy them; the
/// solution's residuals are indexed by `points`.
pub(crate) fn refine_labelled(
    points: &[LabelledPoint],
    labels: &[Option<Surface>],
    up0: &nalgebra::Vector3<f64>,
    params: &MlParams,
) -> Result<MlSolution, MlError> {
    refine_labelled_from(points, labels, up0, None, params)
}

/// [`refine_labelled`] with each surface that `warm` has placed starting at its placement
/// there: `warm` is the fit of nearly the same labels (before a relabelling, or of a rival
/// segmentation that differs from it in a few points), whose optimum is a step or two from
/// this one. The optimum is the same as from the fresh start within the step test's
/// tolerance; the passes to reach it are fewer.
pub(crate) fn refine_labelled_from(
    points: &[LabelledPoint],
    labels: &[Option<Surface>],
    up0: &nalgebra::Vector3<f64>,
    warm: Option<&MlSolution>,
    params: &MlParams,
) -> Result<MlSolution, MlError> {
    assert_eq!(points.len(), labels.len(), "one label per point");
    let good = |p: &LabelledPoint| {
        let finite = p
            .origin
            .coords
            .iter()
            .chain(p.dir.iter())
            .all(|v| v.is_finite());
        finite && p.range.is_finite() && p.range > 0.0 && p.sigma.is_finite() && p.sigma > 0.0
    };
    let labelled = || points.iter().zip(labels).filter(|(_, l)| l.is_some());
    if !labelled().all(|(p, _)| good(p)) {
        return Err(MlError::BadPoint);
    }
    let start = Attitude::from_up(up0);
    let theta = Vector2::new(start.theta_x, start.theta_y);
    let mut state = State::new(points, labels, theta, warm, params);
    let parameters = 2 + 2 * state.surfaces.len();
    if state.members.iter().map(Vec::len).sum::<usize>() <= parameters {
        return Err(MlError::TooFewPoints);
    }
    // From far: least squares on the plane residuals, into the basin; then the likelihood
    // itself, robustly. Without the approach the first pass is the likelihood's own, which
    // its first step then takes as it is.
    let (residual, k) = if params.approach {
        (Residual::Plane, f64::INFINITY)
    } else {
        (Residual::Range, params.huber_k)
    };
    state.residual = residual;
    state.take_rays(params.min_incidence);
    let mut first = Evaluation::default();
    state.evaluate_at(&state.theta, &state.placements, k, true, &mut first);
    if observable_schur(&first.arrow).is_none() {
        return Err(MlError::Unobservable);
    }
    let approach = if params.approach {
        let approach = state.minimise(params, f64::INFINITY, APPROACH_TOLERANCE).0;
        state.residual = Residual::Range;
        if approach > 0 {
            // The approach moved the state: which points graze their plane moved with it.
            state.take_rays(params.min_incidence);
        }
        approach
    } else {
        state.last = Some(first);
        0
    };
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

/// The labelled points' indices grouped by surface, the surfaces in their order (a few
/// surfaces, so a short list searched from the last one found: the points of a surface come
/// in runs).
fn group_by_surface(labels: &[Option<Surface>]) -> Vec<(Surface, Vec<usize>)> {
    let mut groups: Vec<(Surface, Vec<usize>)> = Vec::new();
    let mut last = 0;
    for (i, surface) in labels.iter().enumerate() {
        let Some(surface) = *surface else {
            continue;
        };
        if groups.get(last).is_none_or(|g| g.0 != surface) {
            last = match groups.iter().position(|g| g.0 == surface) {
                Some(j) => j,
                None => {
                    groups.push((surface, Vec::new()));
                    groups.len() - 1
                }
            };
        }
        groups[last].1.push(i);
    }
    groups.sort_by_key(|g| g.0);
    groups
}

/// The attitude a fit of `labels` reaches, from `warm` (a fit of nearly the same labels) by
/// one Gauss-Newton step at `warm`'s attitude and placements: to first order in the labels'
/// difference, the same as the whole fit (a one-step estimator from a consistent start,
/// Lehmann and Casella 1998, *Theory of point estimation*, sect. 6.4), for one pass over the
/// rays instead of the fit's three or four. `None` when the labels do not fix the attitude.
pub(crate) fn one_step(
    points: &[LabelledPoint],
    labels: &[Option<Surface>],
    warm: &MlSolution,
    params: &MlParams,
) -> Option<[f64; 2]> {
    let theta = Vector2::new(warm.attitude[0], warm.attitude[1]);
    let mut state = State::new(points, labels, theta, Some(warm), params);
    state.residual = Residual::Range;
    state.take_rays(params.min_incidence);
    let mut at = Evaluation::default();
    state.evaluate_at(&theta, &state.placements, params.huber_k, true, &mut at);
    observable_schur(&at.arrow)?;
    let (d_theta, _) = damped_step(&at.arrow, 0.0)?;
    let next = theta + d_theta;
    Some([next.x, next.y])
}

impl<'a> State<'a> {
    /// Groups the points by surface (keeping surfaces with enough points whose placement can
    /// be fitted at the starting attitude) and places each surface: where `warm` placed it,
    /// else by its points' own fit.
    fn new(
        points: &'a [LabelledPoint],
        labels: &[Option<Surface>],
        theta: Vector2<f64>,
        warm: Option<&MlSolution>,
        params: &MlParams,
    ) -> Self {
        let rot = Rotations::at(&theta);
        let groups = group_by_surface(labels);
        let mut kept = Vec::new();
        let mut surfaces = Vec::new();
        let mut placements = Vec::new();
        for (surface, members) in groups {
            if members.len() < params.min_surface_points {
                continue;
            }
            let pts: Vec<&LabelledPoint> = members.iter().map(|&i| &points[i]).collect();
            let Some(fresh) = initial_placement(&pts, surface, &rot) else {
                continue;
            };
            let placement = warm.and_then(|w| w.placement_of(surface)).unwrap_or(fresh);
            kept.push(members);
            surfaces.push(surface);
            placements.push(placement);
        }
        State {
            points,
            surfaces,
            theta,
            placements,
            residual: Residual::Range,
            rays: Vec::new(),
            last: None,
            members: kept,
        }
    }

    /// Every surface's plane at `theta` and `placements`, carried into the robot frame.
    fn frames(&self, theta: &Vector2<f64>, placements: &[Placement]) -> Vec<Frame> {
        let rot = Rotations::at(theta);
        self.surfaces
            .iter()
            .zip(placements)
            .map(|(&s, p)| Frame::at(&Plane::at(p, s), &rot))
            .collect()
    }

    /// Takes in the points on a kept surface whose ray meets it at an incidence `|n . L u|`
    /// of at least `min_incidence` at the current state, in surface order, with that
    /// incidence frozen for the plane residual.
    fn take_rays(&mut self, min_incidence: f64) {
        self.last = None;
        let frames = self.frames(&self.theta, &self.placements);
        self.rays.clear();
        // Every member at most: one allocation, where growing by doubling copied the rays
        // (128 bytes each) about once more.
        self.rays.reserve(self.members.iter().map(Vec::len).sum());
        for (slot, members) in self.members.iter().enumerate() {
            for &index in members {
                let p = &self.points[index];
                let incidence = frames[slot].incidence(&p.dir);
                if incidence >= min_incidence {
                    self.rays.push(Ray::new(index, slot, p, incidence));
                }
            }
        }
    }

    /// The pass at a trial state with threshold `k` into `out`.
    fn evaluate_at(
        &self,
        theta: &Vector2<f64>,
        placements: &[Placement],
        k: f64,
        with_arrow: bool,
        out: &mut Evaluation,
    ) {
        let frames = self.frames(theta, placements);
        evaluate(&self.rays, &frames, self.residual, k, with_arrow, out);
    }

    /// Runs Levenberg-Marquardt with Huber threshold `k` until the attitude step is below
    /// `tolerance`: `(iterations, converged)`. With the range residual, each trial's pass
    /// gives its normal equations, which serve the next step when it is accepted; the plane
    /// residual's change with every freeze of the incidences, so it passes again.
    fn minimise(&mut self, params: &MlParams, k: f64, tolerance: f64) -> (usize, bool) {
        let mut lambda = 1e-6;
        let plane = self.residual == Residual::Plane;
        let step_sigmas2 = params.step_sigmas * params.step_sigmas;
        // The range residual's pass at the current state, when the caller has it.
        let mut known = !plane && self.last.is_some();
        let mut current = self.last.take().unwrap_or_default();
        let mut trial = Evaluation::default();
        let mut placements = Vec::with_capacity(self.placements.len());
        let mut outcome = (params.max_iterations, false);
        for iteration in 1..=params.max_iterations {
            if plane {
                self.take_rays(params.min_incidence);
            }
            if plane || !known {
                self.evaluate_at(&self.theta, &self.placements, k, true, &mut current);
                known = true;
            }
            // The attitude's information with every placement marginalised, when it fixes
            // both tilts: the steps below are judged in its sigmas (it does not change with
            // the damping).
            let attitude_info = if plane {
                None
            } else {
                observable_schur(&current.arrow)
            };
            let mut accepted = false;
            let mut step_norm = f64::INFINITY;
            // Damp until the cost falls (Marquardt's scaling by the diagonal).
            for _ in 0..12 {
                let Some((d_theta, d_place)) = damped_step(&current.arrow, lambda) else {
                    lambda *= 10.0;
                    continue;
                };
                // The step's squared length in sigmas (the range residual's only): the
                // attitude's, or where the attitude is not yet fixed, every parameter's (the
                // Newton decrement).
                let step_z2 = || match &attitude_info {
                    Some(s) => d_theta.dot(&(s * d_theta)),
                    None => decrement(&current.arrow, &d_theta, &d_place),
                };
                if !plane && step_z2() < step_sigmas2 {
                    // The step moves the attitude by less than `step_sigmas` of its own sigma
                    // (in every direction): the state is the optimum for every purpose, and
                    // taking the step would cost a pass for nothing (near the optimum the
                    // cost's change is rounding, and trials get refused). The placements are
                    // not waited for: a surface whose points lie mostly beyond the kernel
                    // walks towards them by centimetres a step for tens of steps while the
                    // attitude moves by thousandths of its sigma (docs/ESTIMATOR.md,
                    // section 24).
                    return self.keep(iteration, true, current);
                }
                let theta = self.theta + d_theta;
                placements.clear();
                placements.extend(
                    self.placements
                        .iter()
                        .zip(&d_place)
                        .map(|(p, d)| Placement {
                            offset: p.offset + d.x,
                            azimuth: p.azimuth + d.y,
                        }),
                );
                self.evaluate_at(&theta, &placements, k, !plane, &mut trial);
                step_norm = d_theta.norm();
                if trial.cost <= current.cost {
                    self.theta = theta;
                    std::mem::swap(&mut self.placements, &mut placements);
                    let settled = current.cost - trial.cost <= 1e-14 * current.cost.max(1e-300);
                    std::mem::swap(&mut current, &mut trial);
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
                outcome = (iteration, accepted || step_norm < tolerance);
                break;
            }
        }
        self.keep(outcome.0, outcome.1, current)
    }

    /// Ends [`Self::minimise`]: keeps the range residual's pass at the final state for the
    /// solution, and returns `(iterations, converged)`.
    fn keep(&mut self, iterations: usize, converged: bool, current: Evaluation) -> (usize, bool) {
        if self.residual == Residual::Range {
            self.last = Some(current);
        }
        (iterations, converged)
    }

    /// The estimate at the current state: covariance, residuals and the chi-square test.
    fn solution(
        &self,
        params: &MlParams,
        iterations: usize,
        converged: bool,
    ) -> Result<MlSolution, MlError> {
        let k = params.huber_k;
        let mut at_state = Evaluation::default();
        let eval = match &self.last {
            Some(e) => e,
            None => {
                self.evaluate_at(&self.theta, &self.placements, k, true, &mut at_state);
                &at_state
            }
        };
        let schur = observable_schur(&eval.arrow).ok_or(MlError::Unobservable)?;
        let cov = schur.try_inverse().ok_or(MlError::Unobservable)?;
        let mut residuals: Vec<Option<f64>> = vec![None; self.points.len()];
        for (ray, predicted) in self.rays.iter().zip(&eval.predicted) {
            residuals[ray.index] = Some((ray.range - predicted) / ray.sigma);
        }
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
        // Over the rays, whose residuals these are (each surface's in ascending order).
        for ray in &self.rays {
            let (r, fit) = (residuals[ray.index], &mut surfaces[ray.slot]);
            fit.points += 1;
            fit.chi2 += r.map_or(0.0, clipped);
            fit.dof += 1.0;
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
        let cov = self
            .cluster_covariance(eval, &cov, params)
            .map_or(cov * inflation, |robust| {
                widened(&(cov * inflation), &robust)
            });
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

    /// The cluster-robust covariance at the current state ([`super::cluster`]), from the
    /// range residual's pass `eval` and the information's inverse `cov`; `None` when turned
    /// off (`cluster_rays` 0) or when a surface's block is singular.
    fn cluster_covariance(
        &self,
        eval: &Evaluation,
        cov: &Matrix2<f64>,
        params: &MlParams,
    ) -> Option<Matrix2<f64>> {
        if params.cluster_rays == 0 {
            return None;
        }
        let meat = clustered_meat(&self.rays, &eval.scores, &eval.arrow, params.cluster_rays)?;
        Some(cov * meat * cov)
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
        let inv = pseudo_inverse_2x2(h_ss)?;
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
            Some(-(pseudo_inverse_2x2(h_ss)? * (g_s + h_as.transpose() * d_theta)))
        })
        .collect::<Option<Vec<_>>>()?;
    d_theta
        .iter()
        .chain(d_place.iter().flat_map(|d| d.iter()))
        .all(|v| v.is_finite())
        .then_some((d_theta, d_place))
}

/// The Newton decrement of the step `(d_theta, d_place)`: `-g . d = d^T (H + lambda D) d`,
/// the step's squared length in the parameters' own sigmas (at least, in every direction).
fn decrement(arrow: &Arrow, d_theta: &Vector2<f64>, d_place: &[Vector2<f64>]) -> f64 {
    let surfaces: f64 = arrow
        .blocks
        .iter()
        .zip(d_place)
        .map(|((_, _, g_s), d)| g_s.dot(d))
        .sum();
    -(arrow.g_a.dot(d_theta) + surfaces)
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
