//! Iterative closest point: point-to-point (Besl & McKay 1992) and point-to-line (Censi 2008),
//! with trimmed correspondences (Chetverikov et al. 2002) and a robust kernel.
//!
//! Each iteration: data association through the target's grid (`associate`), trimming to
//! the overlap that minimises the FTrICP objective (`trim`), robust weights, and the exact
//! closed-form solve of `solve.rs` from the original source points (so no error accumulates
//! over iterations). It stops when the pose changes by less than the thresholds.

use super::covariance::Sandwich;
use super::reference::{Certificate, Target};
use super::solve::{PosePrior, Remap, Remapped, RigidSolver, symmetric_eigenvalues_2x2};
use crate::geometry::minor_axis_2x2;
use crate::geometry::{Pose2, wrap_angle};
use nalgebra::{Matrix2, Matrix3, Point2, Vector2, Vector3};

/// Which ICP metric.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Metric {
    /// Point-to-point, Besl & McKay 1992 (the paper's baseline).
    PointToPoint,
    /// Point-to-line, Censi 2008; points without a reference normal fall back to point-to-point.
    #[default]
    PointToLine,
}

/// Robust kernel applied to residuals (iteratively reweighted least squares).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Kernel {
    /// Plain least squares.
    None,
    /// Huber: quadratic below the scale, linear above.
    #[default]
    Huber,
    /// Cauchy: weight `1 / (1 + (r/k)²)`.
    Cauchy,
}

/// Settings of one ICP run. Units in brackets; defaults in the `Default` impl and below.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IcpParams {
    /// Point-to-point or point-to-line. Default point-to-line.
    pub metric: Metric,
    /// Iteration limit. Default 50.
    pub max_iterations: usize,
    /// Converged when the translation changes by less than this \[m\]. Default 1e-5.
    pub epsilon_xy: f64,
    /// Converged when the heading changes by less than this \[rad\]. Default 1e-5.
    pub epsilon_theta: f64,
    /// Pairs farther apart than this are never associated \[m\]. Default 0.5.
    pub max_correspondence_distance: f64,
    /// Smallest fraction of associated pairs kept by trimming (FTrICP's lower bound on the
    /// overlap) [-]. Default 0.6. Set to 1 to switch trimming off.
    pub min_overlap: f64,
    /// FTrICP's exponent λ in `e(ξ) / ξ^λ` [-]. Default 6. Chetverikov et al. 2002 use 2,
    /// which with Gaussian range noise always picks the smallest overlap and so discards
    /// good pairs; 6 keeps about 95% of pairs whose residuals are pure noise and still cuts
    /// off a tail of gross outliers (on the two-room log: RPE median 2.8 mm with 2, 2.1 with 6).
    pub overlap_lambda: f64,
    /// Robust kernel. Default Huber.
    pub kernel: Kernel,
    /// Kernel scale \[m\]. Default 0.03.
    pub kernel_scale: f64,
    /// Point-to-line pairs are weighted by `1 / (cos² α + floor)`, α the angle between the
    /// source ray and the reference normal; `None` weighs all pairs alike [-]. Default 0.2.
    pub incidence_floor: Option<f64>,
    /// The covariance's spread of each kept pair also holds its surface's error between
    /// samples: this angle times the pair's range is added in quadrature to its residual in
    /// the sandwich \[rad\]. Lines fitted through samples a beam spacing apart, and around
    /// corners, do not lie where the surface is; that error grows with the range (the samples'
    /// spacing) and biases the pairs rather than scattering them, so the residuals never show
    /// it. Default 0 (the residuals alone);
    /// the matcher sets it from the scan's beam spacing (`CovarianceParams::sampling_fraction`).
    pub sampling_error: f64,
}

impl Default for IcpParams {
    fn default() -> Self {
        Self {
            metric: Metric::PointToLine,
            max_iterations: 50,
            epsilon_xy: 1e-5,
            epsilon_theta: 1e-5,
            max_correspondence_distance: 0.5,
            min_overlap: 0.6,
            overlap_lambda: 6.0,
            kernel: Kernel::Huber,
            kernel_scale: 0.03,
            incidence_floor: Some(0.2),
            sampling_error: 0.0,
        }
    }
}

/// What an ICP run found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IcpResult {
    /// `target_from_source`: maps source points onto the target.
    pub pose: Pose2,
    pub iterations: usize,
    /// Whether the convergence thresholds were met before the iteration limit.
    pub converged: bool,
    /// Pairs kept after trimming in the last iteration.
    pub correspondences: usize,
    /// Source points that found a target point within the association distance.
    pub associated: usize,
    /// Associated pairs with a residual within the kernel scale: the support of the result.
    pub inliers: usize,
    /// RMS of the kept residuals in the last iteration \[m\].
    pub residual: f64,
    /// How well the kept pairs pin the translation: λ_min / λ_max of `Σ n nᵀ` over their
    /// reference normals (0 in a corridor, 0.5 at best) [-]; `None` when no pair had a normal.
    pub constraint_ratio: Option<f64>,
    /// The solver found no unique motion (a degenerate system).
    pub degenerate: bool,
    /// Covariance of `pose` over (x, y, θ) in the target's frame from the kept pairs alone
    /// (no prior, not inflated): the sandwich `H⁻¹ B H⁻¹` of `covariance.rs`; `None` when the
    /// pairs leave a direction free. After a remapped solve with free directions, the
    /// scan's part only: the sandwich over the observed directions (rank 3 - free).
    pub covariance: Option<Matrix3<f64>>,
    /// With [`icp_remapped`]: which directions the last solve took from the anchor.
    pub remapped: Option<Remapped>,
}

impl IcpResult {
    fn before_any_iteration(pose: Pose2) -> Self {
        Self {
            pose,
            iterations: 0,
            converged: false,
            correspondences: 0,
            associated: 0,
            inliers: 0,
            residual: f64::INFINITY,
            constraint_ratio: None,
            degenerate: false,
            covariance: None,
            remapped: None,
        }
    }
}

#[derive(Clone, Copy)]
struct Pair {
    p: Point2<f64>,
    q: Point2<f64>,
    /// Reference line for point-to-line pairs: (normal, anchor).
    line: Option<(Vector2<f64>, Point2<f64>)>,
    residual: f64,
}

/// Aligns `source` (points in the source scanner's frame, the scanner at the origin) to
/// `target`, starting from `guess` (`target_from_source`). Returns `None` when the target is
/// empty or no point associates.
pub fn icp<T: Target + ?Sized>(
    source: &[Point2<f64>],
    target: &T,
    guess: Pose2,
    params: &IcpParams,
) -> Option<IcpResult> {
    icp_with_prior(source, target, guess, None, params)
}

/// [`icp`] with a Gaussian prior on the pose added to every solve (maximum a posteriori
/// rather than maximum likelihood), as real-time correlative matchers weigh the odometry
/// (Olson 2009, eq. 2; Cartographer's translation and rotation weights).
pub fn icp_with_prior<T: Target + ?Sized>(
    source: &[Point2<f64>],
    target: &T,
    guess: Pose2,
    prior: Option<PosePrior>,
    params: &IcpParams,
) -> Option<IcpResult> {
    icp_solving(source, target, guess, prior, None, params, true)
}

/// [`icp`] whose every solve keeps the directions the pairs observe and takes the others
/// from `remap`'s anchor (solution remapping, `solve.rs`), instead of failing as degenerate.
pub fn icp_remapped<T: Target + ?Sized>(
    source: &[Point2<f64>],
    target: &T,
    guess: Pose2,
    remap: Remap,
    params: &IcpParams,
) -> Option<IcpResult> {
    icp_solving(source, target, guess, None, Some(remap), params, true)
}

fn icp_solving<T: Target + ?Sized>(
    source: &[Point2<f64>],
    target: &T,
    guess: Pose2,
    prior: Option<PosePrior>,
    remap: Option<Remap>,
    params: &IcpParams,
    reuse: bool,
) -> Option<IcpResult> {
    if target.is_empty() || source.is_empty() {
        return None;
    }
    // Each source point's last certified association (see `associate`), with `reuse`.
    let mut certificates: Vec<Option<Certificate>> =
        vec![None; if reuse { source.len() } else { 0 }];
    let mut pose = guess;
    let mut pairs: Vec<Pair> = Vec::with_capacity(source.len());
    let mut trimming = Trimming::default();
    let mut result = IcpResult::before_any_iteration(pose);
    // The pose the last kept pairs were associated at: their residuals and Jacobians are there.
    let mut associated_at = pose;
    let mut cycle = CycleWatch::default();
    for iteration in 1..=params.max_iterations {
        associate(
            source,
            target,
            &pose,
            params,
            reuse.then_some(&mut certificates[..]),
            &mut pairs,
        );
        if pairs.is_empty() {
            return None;
        }
        associated_at = pose;
        result.associated = pairs.len();
        result.inliers = pairs
            .iter()
            .filter(|p| p.residual <= params.kernel_scale)
            .count();
        let kept = trimming.trim(&mut pairs, params);
        let kept_pairs = &pairs[..kept];
        let solver = weighted_solver(kept_pairs, &pose, prior, params);
        result.iterations = iteration;
        result.correspondences = kept;
        result.residual =
            (kept_pairs.iter().map(|p| p.residual.powi(2)).sum::<f64>() / kept as f64).sqrt();
        let scatter = normal_scatter(kept_pairs);
        result.constraint_ratio = scatter.map(|(ratio, _)| ratio);
        let solved = solve(&solver, remap.as_ref(), scatter, &pose).map(|(next, how)| {
            result.remapped = how.or(result.remapped);
            next
        });
        let next = match solved {
            Ok(next) => next,
            Err(_) => {
                result.degenerate = true;
                break;
            }
        };
        let step_xy = (next.translation() - pose.translation()).norm();
        let step_theta = wrap_angle(next.theta - pose.theta).abs();
        pose = next;
        result.pose = pose;
        if step_xy < params.epsilon_xy && step_theta < params.epsilon_theta {
            result.converged = true;
            break;
        }
        if cycle.ends(associated_at, result.residual, &pose, params) {
            break;
        }
    }
    let observed = result.remapped.filter(|r| r.free > 0);
    result.covariance = sandwich(
        &pairs[..result.correspondences],
        &associated_at,
        params,
        observed,
    );
    Some(result)
}

/// The solver over the kept pairs associated at `pose`, each with its robust and incidence
/// weight, and the prior if any.
fn weighted_solver(
    kept: &[Pair],
    pose: &Pose2,
    prior: Option<PosePrior>,
    params: &IcpParams,
) -> RigidSolver {
    let mut solver = RigidSolver::new();
    let rotation = pose.theta.sin_cos();
    for pair in kept {
        let w = weight(pair.residual, params) * incidence_weight(pair, rotation, params);
        match (params.metric, pair.line) {
            (Metric::PointToLine, Some((n, anchor))) => solver.add_line(n, &pair.p, &anchor, w),
            _ => solver.add_point(&pair.p, &pair.q, w),
        }
    }
    if let Some(prior) = prior {
        solver.add_prior(&prior.pose, prior.weight_xy, prior.weight_theta);
    }
    solver
}

/// One solve: exact, or remapped (with the pairs' normal scatter's minor axis as the sliding
/// axis when their scatter ratio is below the remap's `min_constraint_ratio`).
fn solve(
    solver: &RigidSolver,
    remap: Option<&Remap>,
    scatter: Option<(f64, Matrix2<f64>)>,
    pose: &Pose2,
) -> Result<(Pose2, Option<Remapped>), super::solve::SolveError> {
    let Some(remap) = remap else {
        return solver.solve_near(pose.theta).map(|next| (next, None));
    };
    let sliding = scatter
        .filter(|(ratio, _)| *ratio < remap.min_constraint_ratio)
        .map(|(_, scatter)| minor_axis_2x2(&scatter));
    let (next, how) = solver.solve_remapped(remap, pose, sliding)?;
    Ok((next, Some(how)))
}

/// The sandwich covariance over the kept pairs, each residual (with the sampling error of
/// its range in quadrature) with the weight it had in the last solve and its Jacobian w.r.t.
/// (t_x, t_y, θ) at `pose`: for `r = n · (R p + t - q)`,
/// `∂r/∂t = n` and `∂r/∂θ = n · R' p`, `R' p = (-sin θ p_x - cos θ p_y, cos θ p_x - sin θ p_y)`.
/// With free directions, over the observed ones only.
fn sandwich(
    kept: &[Pair],
    pose: &Pose2,
    params: &IcpParams,
    remapped: Option<Remapped>,
) -> Option<Matrix3<f64>> {
    let (s, c) = pose.theta.sin_cos();
    let mut acc = Sandwich::default();
    for pair in kept {
        let w = weight(pair.residual, params) * incidence_weight(pair, (s, c), params);
        let moved = moved_by(pose, (s, c), &pair.p);
        let lever = Vector2::new(-s * pair.p.x - c * pair.p.y, c * pair.p.x - s * pair.p.y);
        let sampling2 = (params.sampling_error * pair.p.coords.norm()).powi(2);
        let mut row = |n: Vector2<f64>, r: f64| {
            acc.add(
                Vector3::new(n.x, n.y, n.dot(&lever)),
                (r * r + sampling2).sqrt(),
                w,
            )
        };
        match (params.metric, pair.line) {
            (Metric::PointToLine, Some((n, anchor))) => row(n, n.dot(&(moved - anchor))),
            _ => {
                let d = moved - pair.q;
                row(Vector2::x(), d.x);
                row(Vector2::y(), d.y);
            }
        }
    }
    match remapped {
        Some(r) => acc.covariance_along(&r.observed_basis().collect::<Vec<_>>()),
        None => acc.covariance(),
    }
}

/// `pose.transform_point(p)` with the pose's `sin_cos` computed once by the caller for all
/// its points (the same arithmetic, so the same result to the bit).
#[inline]
fn moved_by(pose: &Pose2, (s, c): (f64, f64), p: &Point2<f64>) -> Point2<f64> {
    Point2::new(pose.x + c * p.x - s * p.y, pose.y + s * p.x + c * p.y)
}

/// Nearest target point for every source point under `pose`, within the association distance.
///
/// With `certificates` (one per source point), a point still within the margin of the query
/// that certified its neighbour (the nearest grid point then, with every other one at least
/// twice the margin farther) has that neighbour still as its nearest, to the bit the same
/// answer as a new search (ties never get a margin); only its distance is computed anew.
/// Other points are searched with a certificate. After the first solve the pose moves by
/// millimetres, so most points keep their neighbour for several iterations; the first
/// iteration's queries are certified too (on the intel log that costs less than plain first
/// queries: 2,241M against 2,266M instructions of `levelscan match`).
fn associate<T: Target + ?Sized>(
    source: &[Point2<f64>],
    target: &T,
    pose: &Pose2,
    params: &IcpParams,
    mut certificates: Option<&mut [Option<Certificate>]>,
    pairs: &mut Vec<Pair>,
) {
    pairs.clear();
    let max_d2 = params.max_correspondence_distance.powi(2);
    let rotation = pose.theta.sin_cos();
    for (i, p) in source.iter().enumerate() {
        let moved = moved_by(pose, rotation, p);
        let nb = match certificates.as_deref_mut() {
            None => target.nearest_within(&moved, max_d2),
            Some(certificates) => match &certificates[i] {
                Some(c) if (moved - c.at).norm_squared() < c.margin * c.margin => {
                    target.nearest_reusing(&moved, max_d2, c)
                }
                _ => {
                    let (nb, certificate) = target.nearest_certified(&moved, max_d2);
                    certificates[i] = certificate;
                    nb
                }
            },
        };
        let Some(nb) = nb else {
            continue;
        };
        let line = nb.line.map(|l| (l.normal, l.anchor));
        let residual = match (params.metric, line) {
            (Metric::PointToLine, Some((n, anchor))) => n.dot(&(moved - anchor)).abs(),
            _ => nb.dist2.sqrt(),
        };
        pairs.push(Pair {
            p: *p,
            q: nb.point,
            line,
            residual,
        });
    }
}

/// ICP maps the pose it associated at to the pose the solve gives; with discrete
/// associations and trimming that map can fall into a limit cycle instead of a fixed point
/// (on the CARMEN Intel log 29 of 909 scans ran to the iteration limit between two or four
/// poses that repeated exactly, their kept pairs' count alternating by a few). Once the solve
/// returns to within the convergence thresholds of a pose already associated at, the cycle
/// is known: the run goes on until it is at the cycle's pose whose kept pairs have the least
/// RMS residual and stops there, so the answer does not depend on where in the cycle the
/// iteration limit would have fallen, and the rest of the limit's iterations are not spent.
#[derive(Default)]
struct CycleWatch {
    /// The last poses associated at, with their kept pairs' RMS residual, oldest first.
    recent: Vec<(Pose2, f64)>,
    /// Once a cycle is seen: the member to stop at.
    stop_at: Option<Pose2>,
}

/// Cycles up to this long are found \[iterations\] (those seen are two and four long).
const CYCLE_MEMORY: usize = 8;

impl CycleWatch {
    /// After an iteration that associated at `at` (kept pairs' RMS `residual`) and solved
    /// `next`: whether the run should stop here.
    fn ends(&mut self, at: Pose2, residual: f64, next: &Pose2, params: &IcpParams) -> bool {
        let same = |a: &Pose2, b: &Pose2| {
            (a.translation() - b.translation()).norm() < params.epsilon_xy
                && wrap_angle(a.theta - b.theta).abs() < params.epsilon_theta
        };
        if let Some(best) = self.stop_at {
            return same(&at, &best);
        }
        if self.recent.len() == CYCLE_MEMORY {
            self.recent.remove(0);
        }
        self.recent.push((at, residual));
        let Some(start) = self.recent.iter().position(|(p, _)| same(p, next)) else {
            return false;
        };
        let best = self.recent[start..]
            .iter()
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(p, _)| *p)
            .unwrap_or(at);
        self.stop_at = Some(best);
        same(&at, &best)
    }
}

/// Buffers of `trim`, kept over one ICP run's iterations.
#[derive(Default)]
struct Trimming {
    /// Each pair's residual as bits (residuals are never negative: their bits order as
    /// `total_cmp` orders them). Equal residuals add the same square whichever comes first,
    /// so only the cut needs their indices: the kept ones are the first in association order.
    order: Vec<u64>,
    /// `ξ^λ` for every overlap `count / n` from the first kept, for the last `n` seen (pair
    /// counts repeat from iteration to iteration near convergence; the same `powf`, so the
    /// same values).
    powers: Vec<f64>,
    powers_of: Option<(usize, usize, u64)>,
}

impl Trimming {
    /// Keeps the overlap ξ >= `min_overlap` of the pairs with the smallest residuals that
    /// minimises `e(ξ) / ξ^λ`, e being the mean squared residual of the best ξ·N pairs
    /// (Chetverikov et al. 2002, "FTrICP"), in their association order; returns how many.
    /// The smallest `min_overlap` share is always kept, so only its sum matters: it is
    /// selected (linear time), and only the rest is sorted.
    fn trim(&mut self, pairs: &mut Vec<Pair>, params: &IcpParams) -> usize {
        let n = pairs.len();
        if params.min_overlap >= 1.0 {
            return n;
        }
        self.order.clear();
        self.order
            .extend(pairs.iter().map(|p| p.residual.to_bits()));
        let first = ((params.min_overlap * n as f64).ceil() as usize).clamp(1, n);
        self.order.select_nth_unstable(first - 1);
        self.order[first..].sort_unstable();
        let lambda = params.overlap_lambda;
        let key = Some((n, first, lambda.to_bits()));
        if self.powers_of != key {
            self.powers.clear();
            self.powers.extend((1..=n).map(|count| {
                let xi = count as f64 / n as f64;
                if count < first { 0.0 } else { xi.powf(lambda) }
            }));
            self.powers_of = key;
        }
        let squared = |&bits: &u64| f64::from_bits(bits).powi(2);
        let mut sum: f64 = self.order[..first - 1].iter().map(squared).sum();
        let mut best = (f64::INFINITY, n);
        for (k, entry) in self.order.iter().enumerate().skip(first - 1) {
            sum += squared(entry);
            let count = k + 1;
            // A floor on e keeps noise-free data from preferring the smallest overlap.
            let e = (sum / count as f64).max(1e-12);
            let psi = e / self.powers[k];
            if psi < best.0 {
                best = (psi, count);
            }
        }
        let last_kept = self.order[best.1 - 1];
        // Of the pairs tied with the last kept, as many as the sorted prefix holds.
        let mut ties = self.order[..best.1]
            .iter()
            .filter(|&&bits| bits == last_kept)
            .count();
        pairs.retain(|p| {
            let bits = p.residual.to_bits();
            if bits == last_kept {
                let kept = ties > 0;
                ties = ties.saturating_sub(1);
                kept
            } else {
                bits < last_kept
            }
        });
        best.1
    }
}

/// Range noise acts along the ray, so a point-to-line residual carries only its component
/// along the normal, `σ cos α` for incidence angle α: weighting by the inverse variance
/// (Censi 2007, "An accurate closed-form estimate of ICP's covariance", sect. III) trusts
/// grazing points more. The floor keeps the weight finite and hedges against the larger
/// sampling error of the reference line along grazing rays.
fn incidence_weight(pair: &Pair, (s, c): (f64, f64), params: &IcpParams) -> f64 {
    let (Metric::PointToLine, Some((n, _)), Some(floor)) =
        (params.metric, pair.line, params.incidence_floor)
    else {
        return 1.0;
    };
    let norm = pair.p.coords.norm();
    if norm == 0.0 {
        return 1.0;
    }
    let ray = Vector2::new(c * pair.p.x - s * pair.p.y, s * pair.p.x + c * pair.p.y) / norm;
    let cos = n.dot(&ray);
    1.0 / (cos * cos + floor)
}

fn weight(residual: f64, params: &IcpParams) -> f64 {
    let k = params.kernel_scale;
    match params.kernel {
        Kernel::None => 1.0,
        Kernel::Huber => {
            if residual <= k {
                1.0
            } else {
                k / residual
            }
        }
        Kernel::Cauchy => 1.0 / (1.0 + (residual / k).powi(2)),
    }
}

/// `λ_min / λ_max` of the kept pairs' normal scatter `Σ n nᵀ`, and the scatter (whose minor
/// axis only a remapped solve of a weak scatter needs: it costs an `atan2` and a `sin_cos`).
fn normal_scatter(pairs: &[Pair]) -> Option<(f64, Matrix2<f64>)> {
    let mut scatter = Matrix2::zeros();
    let mut any = false;
    for (n, _) in pairs.iter().filter_map(|p| p.line) {
        scatter += n * n.transpose();
        any = true;
    }
    if !any {
        return None;
    }
    let (lo, hi) = symmetric_eigenvalues_2x2(&scatter);
    Some((if hi > 0.0 { lo.max(0.0) / hi } else { 0.0 }, scatter))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pair(r: f64) -> Pair {
        Pair {
            p: Point2::origin(),
            q: Point2::origin(),
            line: None,
            residual: r,
        }
    }

    /// Pairs on three walls of a room (x = 3, y = 2, y = -4) at several ranges, each on its
    /// own line with the residual `r`.
    fn room_pairs(r: f64) -> Vec<Pair> {
        let mut pairs = Vec::new();
        for k in 0..5 {
            let t = -1.0 + 0.5 * k as f64;
            for (p, n) in [
                (Point2::new(3.0, t), Vector2::new(-1.0, 0.0)),
                (Point2::new(t, 2.0), Vector2::new(0.0, -1.0)),
                (Point2::new(2.0 * t, -4.0), Vector2::new(0.0, 1.0)),
            ] {
                pairs.push(Pair {
                    p,
                    q: p,
                    line: Some((n, p - n * r)),
                    residual: r,
                });
            }
        }
        pairs
    }

    #[test]
    fn the_sampling_error_adds_the_pairs_range_in_quadrature_to_their_residual() {
        // A brute-force twin of the sandwich at the identity: rows J = (n, n x p), unit
        // weights (no incidence weighting, residuals inside Huber's scale), and each pair's
        // spread r^2 + (s |p|)^2.
        let twin = |pairs: &[Pair], s: f64| {
            let (mut h, mut b) = (Matrix3::zeros(), Matrix3::zeros());
            for pair in pairs {
                let (n, _) = pair.line.unwrap();
                let j = Vector3::new(n.x, n.y, n.x * -pair.p.y + n.y * pair.p.x);
                h += j * j.transpose();
                let spread = pair.residual.powi(2) + (s * pair.p.coords.norm()).powi(2);
                b += spread * j * j.transpose();
            }
            let h_inv: Matrix3<f64> = h.try_inverse().unwrap();
            h_inv * b * h_inv
        };
        for (r, s) in [(0.0, 0.01), (0.0, 0.02), (0.01, 0.0), (0.01, 0.005)] {
            let params = IcpParams {
                incidence_floor: None,
                sampling_error: s,
                ..IcpParams::default()
            };
            let pairs = room_pairs(r);
            let got = sandwich(&pairs, &Pose2::identity(), &params, None).unwrap();
            let want = twin(&pairs, s);
            assert!(
                (got - want).norm() <= 1e-12 * want.norm(),
                "{got} vs {want}"
            );
        }
        // Noise-free pairs: the covariance is the sampling term alone, four times as large when
        // the sampling error doubles, and none at all without it.
        let at = |s: f64| {
            let params = IcpParams {
                sampling_error: s,
                ..IcpParams::default()
            };
            sandwich(&room_pairs(0.0), &Pose2::identity(), &params, None).unwrap()
        };
        assert!((at(0.02) - 4.0 * at(0.01)).norm() <= 1e-12 * at(0.02).norm());
        assert_eq!(at(0.0), Matrix3::zeros());
    }

    #[test]
    fn a_limit_cycle_stops_at_its_member_of_least_residual() {
        let params = IcpParams::default();
        let (a, b, c) = (
            Pose2::new(0.0, 0.0, 0.0),
            Pose2::new(0.01, 0.0, 0.001),
            Pose2::new(0.02, 0.0, 0.0),
        );
        // A -> B -> A: B has the smaller residual and is where the run stands: stop now.
        let mut watch = CycleWatch::default();
        assert!(!watch.ends(a, 0.2, &b, &params));
        assert!(watch.ends(b, 0.1, &a, &params));
        // A -> B -> C -> A with A the best: on to A, then stop.
        let mut watch = CycleWatch::default();
        assert!(!watch.ends(a, 0.1, &b, &params));
        assert!(!watch.ends(b, 0.3, &c, &params));
        assert!(!watch.ends(c, 0.2, &a, &params));
        assert!(!watch.ends(b, 0.3, &c, &params));
        assert!(!watch.ends(c, 0.2, &a, &params));
        assert!(watch.ends(a, 0.1, &b, &params));
        // Poses that keep moving (by more than the thresholds) never stop the run.
        let mut watch = CycleWatch::default();
        for k in 0..40 {
            let at = Pose2::new(1e-4 * k as f64, 0.0, 0.0);
            let next = Pose2::new(1e-4 * (k + 1) as f64, 0.0, 0.0);
            assert!(!watch.ends(at, 0.1, &next, &params));
        }
    }

    /// FTrICP's choice the plain way: every pair sorted, every prefix's mean square.
    fn trimmed_by_sorting(residuals: &[f64], params: &IcpParams) -> Vec<usize> {
        let n = residuals.len();
        let mut order: Vec<usize> = (0..n).collect();
        order.sort_by(|&a, &b| residuals[a].total_cmp(&residuals[b]).then(a.cmp(&b)));
        let first = ((params.min_overlap * n as f64).ceil() as usize).clamp(1, n);
        let (mut sum, mut best) = (0.0, (f64::INFINITY, n));
        for (k, &i) in order.iter().enumerate() {
            sum += residuals[i] * residuals[i];
            let count = k + 1;
            let xi = count as f64 / n as f64;
            let psi = (sum / count as f64).max(1e-12) / xi.powf(params.overlap_lambda);
            if count >= first && psi < best.0 {
                best = (psi, count);
            }
        }
        let mut kept = order[..best.1].to_vec();
        kept.sort_unstable();
        kept
    }

    proptest::proptest! {
        #[test]
        fn trimming_keeps_what_sorting_every_pair_keeps_in_association_order(
            residuals in proptest::collection::vec(0.0f64..0.3, 1..400),
            outliers in proptest::collection::vec(0.3f64..2.0, 0..60),
        ) {
            let mut all = residuals.clone();
            // Outliers spread through the scan, as real ones are.
            for (k, r) in outliers.iter().enumerate() {
                let at = (k * 7919) % (all.len() + 1);
                all.insert(at, *r);
            }
            let params = IcpParams::default();
            let mut pairs: Vec<Pair> = all
                .iter()
                .enumerate()
                .map(|(i, &r)| Pair { p: Point2::new(i as f64, 0.0), ..pair(r) })
                .collect();
            let kept = Trimming::default().trim(&mut pairs, &params);
            let want = trimmed_by_sorting(&all, &params);
            proptest::prop_assert_eq!(kept, want.len());
            let got: Vec<usize> = pairs.iter().map(|p| p.p.x as usize).collect();
            proptest::prop_assert_eq!(got, want);
        }
    }

    /// Points along a room's walls (a `w` × `h` rectangle with a pillar), every `step`
    /// metres with the given jitter, in the frame of a scanner at `at`.
    fn room(w: f64, h: f64, step: f64, jitter: &[f64], at: &Pose2) -> Vec<Point2<f64>> {
        let mut walls = Vec::new();
        let n = |len: f64| (len / step) as usize;
        walls.extend((0..n(w)).map(|k| Point2::new(k as f64 * step, 0.0)));
        walls.extend((0..n(h)).map(|k| Point2::new(w, k as f64 * step)));
        walls.extend((0..n(w)).map(|k| Point2::new(w - k as f64 * step, h)));
        walls.extend((0..n(h)).map(|k| Point2::new(0.0, h - k as f64 * step)));
        for k in 0..n(0.6) {
            walls.push(Point2::new(0.4 * w + k as f64 * step, 0.5 * h));
        }
        let inverse = at.inverse();
        walls
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let e = jitter[i % jitter.len()];
                inverse.transform_point(&Point2::new(p.x + e, p.y - 0.7 * e))
            })
            .collect()
    }

    proptest::proptest! {
        /// Reusing certified associations changes nothing: the same result to the bit as
        /// searching for every point in every iteration, against a scan and against a map.
        #[test]
        fn icp_with_reused_associations_equals_icp_searching_every_point(
            w in 2.0f64..8.0,
            h in 2.0f64..8.0,
            step in 0.02f64..0.15,
            jitter in proptest::collection::vec(-0.02f64..0.02, 1..40),
            offset in (-0.3f64..0.3, -0.3f64..0.3, -0.2f64..0.2),
            guess_error in (-0.1f64..0.1, -0.1f64..0.1, -0.05f64..0.05),
            point_to_point in proptest::bool::ANY,
        ) {
            use crate::matching::map::{MapParams, VoxelMap};
            use crate::matching::reference::{NormalParams, ScanReference};
            let origin = Pose2::new(0.5 * w, 0.4 * h, 0.0);
            let target_points = room(w, h, step, &[0.0], &origin);
            let truth = Pose2::new(offset.0, offset.1, offset.2);
            let source = room(w, h, step * 1.3, &jitter, &origin.compose(&truth));
            let guess = Pose2::new(
                truth.x + guess_error.0,
                truth.y + guess_error.1,
                truth.theta + guess_error.2,
            );
            let mut params = IcpParams::default();
            if point_to_point {
                params.metric = Metric::PointToPoint;
            }
            let scan = ScanReference::new(
                target_points.clone(),
                &Point2::origin(),
                &NormalParams::default(),
            );
            let lines = scan.lines().to_vec();
            let run = |target: &dyn Target, reuse: bool| {
                icp_solving(&source, target, guess, None, None, &params, reuse)
            };
            let searched = run(&scan, false);
            proptest::prop_assert!(searched.is_some());
            proptest::prop_assert_eq!(run(&scan, true), searched);
            let mut map = VoxelMap::new(MapParams::default());
            map.insert(&target_points, &lines);
            proptest::prop_assert_eq!(run(&map, true), run(&map, false));
        }
    }

    #[test]
    fn trimming_drops_gross_outliers_only() {
        let mut pairs: Vec<Pair> = (0..90).map(|i| pair(0.01 + 1e-4 * i as f64)).collect();
        pairs.extend((0..10).map(|_| pair(0.4)));
        let kept = Trimming::default().trim(&mut pairs, &IcpParams::default());
        assert_eq!(kept, 90);
    }

    #[test]
    fn trimming_keeps_everything_when_residuals_are_even() {
        let mut pairs: Vec<Pair> = (0..100).map(|_| pair(0.01)).collect();
        assert_eq!(
            Trimming::default().trim(&mut pairs, &IcpParams::default()),
            100
        );
    }
}
