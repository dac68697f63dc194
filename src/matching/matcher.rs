//! Matching a run of scans, one at a time: pairwise (each scan against the previous one) or
//! metascan (each scan against the map of all earlier matched scans), paper sect. 2.2.
//!
//! A pure state machine: `Matcher::push` takes one scan's points and odometry and returns
//! that scan's estimate and match report. Every scan gets a report; when a match is not
//! trustworthy the step falls back to the odometry and the report says why (CSM issue #17).

use super::correlative::{CorrelativeParams, correlative_search};
use super::icp::{IcpParams, IcpResult, PosePrior, icp, icp_with_prior};
use super::map::{MapParams, VoxelMap};
use super::reference::{Line, NormalParams, ScanReference, Target, estimate_lines};
use crate::geometry::Pose2;
use crate::scan::Scan;
use nalgebra::{Point2, Vector2};

/// Pairwise or metascan.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Mode {
    /// Each scan against the previous one.
    #[default]
    Pairwise,
    /// Each scan against a map of all earlier matched scans.
    Metascan,
}

/// When to run the coarse correlative search before ICP.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Coarse {
    /// Never; ICP starts from the odometry guess.
    Never,
    /// Only when ICP from the odometry guess looks bad (fails a check, or too few source
    /// points find a partner); then the better of the two results is kept.
    #[default]
    Auto,
    /// Before every match.
    Always,
}

/// Why a step fell back to odometry.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FallbackReason {
    /// The scan has no usable ray.
    NoValidRays,
    /// Nothing to match against yet (no earlier scan with usable rays).
    NoReference,
    /// Fewer kept pairs than `min_correspondences`.
    TooFewCorrespondences,
    /// RMS residual above `max_residual`.
    HighResidual,
    /// The geometry does not pin the motion (a corridor: all normals nearly parallel).
    Degenerate,
    /// The match moved the pose farther from the odometry guess than the search ever looks:
    /// a match to the wrong place.
    LargeCorrection,
}

impl FallbackReason {
    pub fn as_str(&self) -> &'static str {
        match self {
            FallbackReason::NoValidRays => "no_valid_rays",
            FallbackReason::NoReference => "no_reference",
            FallbackReason::TooFewCorrespondences => "too_few_correspondences",
            FallbackReason::HighResidual => "high_residual",
            FallbackReason::Degenerate => "degenerate",
            FallbackReason::LargeCorrection => "large_correction",
        }
    }
}

/// The outcome of one scan.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MatchStatus {
    /// The first scan: its pose is its odometry (or the origin).
    First,
    /// The estimate came from a match.
    Ok,
    /// The estimate came from odometry.
    Fallback(FallbackReason),
}

/// What `Matcher::push` reports for one scan (the contract's `match` object).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MatchReport {
    /// `world_from_robot`, planar.
    pub estimate: Pose2,
    pub status: MatchStatus,
    pub iterations: usize,
    pub correspondences: usize,
    /// RMS residual of the kept pairs \[m\]; `None` when no match ran.
    pub residual: Option<f64>,
    /// Whether the coarse correlative search ran for this scan.
    pub coarse: bool,
}

/// Everything the matcher needs. Units in brackets; defaults in `Default`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MatcherParams {
    pub mode: Mode,
    pub icp: IcpParams,
    pub normals: NormalParams,
    pub coarse: Coarse,
    pub correlative: CorrelativeParams,
    pub map: MapParams,
    pub checks: CheckParams,
    pub ranges: RangeParams,
    /// Pairwise: also match the previous scan against this one and take the midpoint of the
    /// two motions. Default true.
    pub symmetric: bool,
    /// Weigh the odometry as a prior in every ICP solve; `None` (the default) trusts the scans
    /// alone and uses the odometry only as the first guess.
    pub odometry_prior: Option<OdometryPrior>,
}

impl Default for MatcherParams {
    fn default() -> Self {
        Self {
            mode: Mode::default(),
            icp: IcpParams::default(),
            normals: NormalParams::default(),
            coarse: Coarse::default(),
            correlative: CorrelativeParams::default(),
            map: MapParams::default(),
            checks: CheckParams::default(),
            ranges: RangeParams::default(),
            symmetric: true,
            odometry_prior: None,
        }
    }
}

/// The odometry's noise per step, for the odometry prior: sigma = per-unit part x the step +
/// constant part, the model `simulate::odometry` and `eval real` use.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OdometryPrior {
    /// Translation sigma per metre of the step, x and y each [m/m].
    pub trans_per_m: f64,
    /// Translation sigma added to every step \[m\].
    pub trans_const: f64,
    /// Heading sigma per radian of the step [rad/rad].
    pub rot_per_rad: f64,
    /// Heading sigma added to every step \[rad\].
    pub rot_const: f64,
    /// Sigma of one weighted ICP residual, which sets the scale between the two \[m\].
    pub residual_sigma: f64,
}

impl Default for OdometryPrior {
    /// Issue 4's perturbation: 2% + 5 mm, 2% + 0.5 degree; residuals of 1 cm.
    fn default() -> Self {
        Self {
            trans_per_m: 0.02,
            trans_const: 0.005,
            rot_per_rad: 0.02,
            rot_const: 0.5f64.to_radians(),
            residual_sigma: 0.01,
        }
    }
}

impl OdometryPrior {
    /// The prior centred on `at` for an odometry step `step`.
    pub fn around(&self, at: Pose2, step: &Pose2) -> PosePrior {
        let s_xy = self.trans_per_m * step.translation().norm() + self.trans_const;
        let s_th = self.rot_per_rad * step.theta.abs() + self.rot_const;
        PosePrior {
            pose: at,
            weight_xy: (self.residual_sigma / s_xy.max(1e-9)).powi(2),
            weight_theta: (self.residual_sigma / s_th.max(1e-9)).powi(2),
        }
    }
}

/// Which readings are used. Units in brackets.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RangeParams {
    /// Shorter readings are ignored (the robot's own body) \[m\]. Default 0.05.
    pub min_range: f64,
    /// Readings at or beyond this are ignored (CARMEN writes the maximum range for "no
    /// return") \[m\]. Default 40.
    pub max_range: f64,
}

impl Default for RangeParams {
    fn default() -> Self {
        Self {
            min_range: 0.05,
            max_range: 40.0,
        }
    }
}

/// When a match is rejected. Units in brackets.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CheckParams {
    /// Fewest kept pairs for a trusted match [-]. Default 20.
    pub min_correspondences: usize,
    /// Largest RMS residual of the kept pairs \[m\]. Default 0.08.
    pub max_residual: f64,
    /// Smallest λ_min/λ_max of the kept pairs' normal scatter; below it the geometry is a
    /// corridor [-]. Default 0.02.
    pub min_constraint_ratio: f64,
    /// With `Coarse::Auto`, the coarse search runs when fewer than this fraction of the
    /// source points are inliers (residual within the kernel scale) [-]. Default 0.8.
    pub coarse_trigger_fraction: f64,
    /// Largest accepted distance between the match and the odometry guess \[m\]. Default 0.6
    /// (the coarse search's 0.4 m window and ICP's reach beyond it).
    pub max_correction_xy: f64,
    /// Largest accepted heading change from the odometry guess \[rad\]. Default 30 deg.
    pub max_correction_theta: f64,
    /// Metascan: the largest move the map may make to the pairwise stage's answer \[m\].
    /// Default 0.1.
    pub max_map_correction_xy: f64,
}

impl Default for CheckParams {
    fn default() -> Self {
        Self {
            min_correspondences: 20,
            max_residual: 0.08,
            min_constraint_ratio: 0.02,
            coarse_trigger_fraction: 0.8,
            max_correction_xy: 0.6,
            max_correction_theta: 30f64.to_radians(),
            max_map_correction_xy: 0.1,
        }
    }
}

/// A scan's usable rays as robot-frame 2D points, in ray order.
pub fn scan_points(scan: &Scan, ranges: &RangeParams) -> Vec<Point2<f64>> {
    (0..scan.nrays())
        .filter_map(|i| {
            let r = scan.range(i)?;
            if r < ranges.min_range || r >= ranges.max_range || !scan.theta[i].is_finite() {
                return None;
            }
            let (s, c) = scan.theta[i].sin_cos();
            Some(Point2::new(r * c, r * s))
        })
        .collect()
}

/// The odometry step from one scan to the next (`prev⁻¹ ⊕ cur`), identity when either is
/// unknown.
pub fn odometry_step(prev: Option<Pose2>, cur: Option<Pose2>) -> Pose2 {
    match (prev, cur) {
        (Some(a), Some(b)) => a.between(&b),
        _ => Pose2::identity(),
    }
}

/// The last scan matched against (pairwise) and where it is.
struct Keyframe {
    reference: ScanReference,
    estimate: Pose2,
    odometry: Option<Pose2>,
}

/// Pairwise or metascan matching of a run, one scan at a time.
pub struct Matcher {
    params: MatcherParams,
    /// Estimate and odometry of the previous scan.
    previous: Option<(Pose2, Option<Pose2>)>,
    keyframe: Option<Keyframe>,
    map: VoxelMap,
    /// Whether the current and previous scans both have odometry (for the prior).
    has_odometry: bool,
}

impl Matcher {
    pub fn new(params: MatcherParams) -> Self {
        Self {
            params,
            previous: None,
            keyframe: None,
            map: VoxelMap::new(params.map),
            has_odometry: false,
        }
    }

    /// The metascan map so far (empty in pairwise mode).
    pub fn map(&self) -> &VoxelMap {
        &self.map
    }

    /// Matches the next scan: `points` in its robot frame (ray order), `odometry` its dead
    /// reckoning pose if known.
    pub fn push(&mut self, points: &[Point2<f64>], odometry: Option<Pose2>) -> MatchReport {
        self.has_odometry =
            odometry.is_some() && self.previous.is_some_and(|(_, prev)| prev.is_some());
        let report = match self.previous {
            None => self.first(points, odometry),
            Some((prev_estimate, prev_odometry)) => match self.params.mode {
                Mode::Pairwise => self.pairwise(points, odometry, prev_estimate, prev_odometry),
                Mode::Metascan => self.metascan(points, odometry, prev_estimate, prev_odometry),
            },
        };
        self.previous = Some((report.estimate, odometry));
        report
    }

    fn first(&mut self, points: &[Point2<f64>], odometry: Option<Pose2>) -> MatchReport {
        let estimate = odometry.unwrap_or_else(Pose2::identity);
        let status = if points.is_empty() {
            MatchStatus::Fallback(FallbackReason::NoValidRays)
        } else {
            self.remember(points, estimate, odometry);
            MatchStatus::First
        };
        MatchReport {
            estimate,
            status,
            iterations: 0,
            correspondences: 0,
            residual: None,
            coarse: false,
        }
    }

    /// Makes `points` (at `estimate`) the scan the next one is first matched against.
    fn set_keyframe(&mut self, points: &[Point2<f64>], estimate: Pose2, odometry: Option<Pose2>) {
        self.keyframe = Some(Keyframe {
            reference: ScanReference::new(points.to_vec(), &Point2::origin(), &self.params.normals),
            estimate,
            odometry,
        });
    }

    /// Makes `points` (at `estimate`) the next pairwise reference, or adds them to the map.
    fn remember(&mut self, points: &[Point2<f64>], estimate: Pose2, odometry: Option<Pose2>) {
        match self.params.mode {
            Mode::Pairwise => self.set_keyframe(points, estimate, odometry),
            Mode::Metascan => {
                let lines = estimate_lines(points, &Point2::origin(), &self.params.normals);
                let world: Vec<Point2<f64>> =
                    points.iter().map(|p| estimate.transform_point(p)).collect();
                let (s, c) = estimate.theta.sin_cos();
                let world_lines: Vec<Option<Line>> = lines
                    .iter()
                    .map(|l| {
                        l.map(|l| Line {
                            normal: Vector2::new(
                                c * l.normal.x - s * l.normal.y,
                                s * l.normal.x + c * l.normal.y,
                            ),
                            anchor: estimate.transform_point(&l.anchor),
                        })
                    })
                    .collect();
                self.map.insert(&world, &world_lines);
                // The last scan, in its own frame, seeds the coarse search.
                self.keyframe = Some(Keyframe {
                    reference: ScanReference::with_lines(points.to_vec(), lines),
                    estimate,
                    odometry,
                });
            }
        }
    }

    fn pairwise(
        &mut self,
        points: &[Point2<f64>],
        odometry: Option<Pose2>,
        prev_estimate: Pose2,
        prev_odometry: Option<Pose2>,
    ) -> MatchReport {
        let Some(keyframe) = &self.keyframe else {
            let estimate = prev_estimate.compose(&odometry_step(prev_odometry, odometry));
            let reason = if points.is_empty() {
                FallbackReason::NoValidRays
            } else {
                FallbackReason::NoReference
            };
            return self.fallback(points, odometry, estimate, reason, None);
        };
        let guess = odometry_step(keyframe.odometry, odometry);
        let odometry_estimate = keyframe.estimate.compose(&guess);
        if points.is_empty() {
            return self.fallback(
                points,
                odometry,
                odometry_estimate,
                FallbackReason::NoValidRays,
                None,
            );
        }
        let (result, coarse) = self.align(points, &keyframe.reference, guess);
        let result = result.map(|r| self.symmetrize(points, &keyframe.reference, r));
        let keyframe_estimate = keyframe.estimate;
        self.finish(
            points,
            odometry,
            result,
            coarse,
            |r| keyframe_estimate.compose(&r.pose),
            odometry_estimate,
        )
    }

    /// Matches the other way too (the reference's points against this scan's lines) and takes
    /// the midpoint of the two motions when they agree: each direction fits lines to a
    /// different scan's noise, so their errors partly cancel.
    fn symmetrize(
        &self,
        points: &[Point2<f64>],
        reference: &ScanReference,
        r: IcpResult,
    ) -> IcpResult {
        if !self.params.symmetric {
            return r;
        }
        let current = ScanReference::new(points.to_vec(), &Point2::origin(), &self.params.normals);
        let Some(back) = icp(
            reference.points(),
            &current,
            r.pose.inverse(),
            &self.params.icp,
        ) else {
            return r;
        };
        if self.check(back).is_err() {
            return r;
        }
        let d = r.pose.between(&back.pose.inverse());
        if d.translation().norm() > 0.02 || d.theta.abs() > 1f64.to_radians() {
            return r;
        }
        IcpResult {
            pose: r
                .pose
                .compose(&Pose2::new(0.5 * d.x, 0.5 * d.y, 0.5 * d.theta)),
            ..r
        }
    }

    fn metascan(
        &mut self,
        points: &[Point2<f64>],
        odometry: Option<Pose2>,
        prev_estimate: Pose2,
        prev_odometry: Option<Pose2>,
    ) -> MatchReport {
        let guess = prev_estimate.compose(&odometry_step(prev_odometry, odometry));
        if points.is_empty() {
            return self.fallback(points, odometry, guess, FallbackReason::NoValidRays, None);
        }
        if self.map.is_empty() {
            // Nothing to match against yet (e.g. the first pose failed to level and had no
            // valid ray): this scan starts the map at its odometry guess, as a first scan does;
            // otherwise the map would stay empty for the whole run.
            self.remember(points, guess, odometry);
            return self.fallback(points, odometry, guess, FallbackReason::NoReference, None);
        }
        // First against the last scan that went into the map (as pairwise, with the coarse
        // search when needed): one scan has one clear basin, the map may have several near a
        // poor guess. Then refine against the whole map, which ties the run to earlier visits.
        let mut start = guess;
        let mut coarse = false;
        let mut local_ok: Option<IcpResult> = None;
        if let Some(kf) = self.keyframe.as_ref() {
            let local_guess = kf.estimate.between(&guess);
            let (local, used_coarse) = self.align(points, &kf.reference, local_guess);
            coarse = used_coarse;
            if let Ok(r) = local {
                start = kf.estimate.compose(&r.pose);
                local_ok = Some(IcpResult { pose: start, ..r });
            }
        }
        // The start is already within millimetres; in a map whose walls are a few voxels
        // thick, associations keep flipping between neighbouring voxels below 0.1 mm, and
        // chasing that costs iterations that grow with the map's age (measured: 6.9 -> 11.0
        // iterations from the first to the last 100 scans of a 5000-scan run; 5.0 -> 4.8
        // with the looser threshold, same accuracy).
        let refine = IcpParams {
            epsilon_xy: self.params.icp.epsilon_xy * 10.0,
            epsilon_theta: self.params.icp.epsilon_theta * 10.0,
            ..self.params.icp
        };
        let step = odometry_step(prev_odometry, odometry);
        let prior = self
            .params
            .odometry_prior
            .filter(|_| self.has_odometry)
            .map(|o| o.around(guess, &step));
        let result = icp_with_prior(points, &self.map, start, prior, &refine)
            .ok_or(FallbackReason::TooFewCorrespondences)
            .and_then(|r| self.check(r))
            .and_then(|r| self.gate(r, &guess));
        // The map may only fine-tune the pairwise stage's answer: a big jump means the map
        // near here is too thin or ambiguous (e.g. built from one far scan), so keep the
        // pairwise answer instead.
        let result = match (result, local_ok) {
            (Ok(r), Some(local)) => {
                let d = local.pose.between(&r.pose);
                if d.translation().norm() > self.params.checks.max_map_correction_xy {
                    Ok(local)
                } else {
                    Ok(r)
                }
            }
            (Err(_), Some(local)) => Ok(local),
            (result, None) => result,
        };
        self.finish(points, odometry, result, coarse, |r| r.pose, guess)
    }

    /// ICP against one scan from `guess`, with the coarse search (over that scan's points)
    /// first or as a second try, per `Coarse`.
    fn align(
        &self,
        points: &[Point2<f64>],
        reference: &ScanReference,
        guess: Pose2,
    ) -> (Result<IcpResult, FallbackReason>, bool) {
        let coarse_search = |g| {
            correlative_search(
                points,
                reference.points(),
                &Point2::origin(),
                g,
                &self.params.correlative,
            )
            .map(|c| c.0)
        };
        let (result, coarse) = self.align_unchecked(points, reference, guess, coarse_search);
        (result.and_then(|r| self.gate(r, &guess)), coarse)
    }

    /// Rejects a match that moved too far from the odometry guess. Without odometry the guess
    /// is the identity, which says nothing about the step, so nothing is rejected.
    fn gate(&self, r: IcpResult, guess: &Pose2) -> Result<IcpResult, FallbackReason> {
        if !self.has_odometry {
            return Ok(r);
        }
        let c = &self.params.checks;
        let d = guess.between(&r.pose);
        if d.translation().norm() > c.max_correction_xy || d.theta.abs() > c.max_correction_theta {
            return Err(FallbackReason::LargeCorrection);
        }
        Ok(r)
    }

    fn align_unchecked(
        &self,
        points: &[Point2<f64>],
        target: &dyn Target,
        guess: Pose2,
        coarse_search: impl Fn(Pose2) -> Option<Pose2>,
    ) -> (Result<IcpResult, FallbackReason>, bool) {
        let p = &self.params;
        // Only a real odometry step makes a prior (identity means "no odometry").
        let prior = p
            .odometry_prior
            .filter(|_| self.has_odometry)
            .map(|o| o.around(guess, &guess));
        let run = |g: Pose2| {
            icp_with_prior(points, target, g, prior, &p.icp)
                .ok_or(FallbackReason::TooFewCorrespondences)
        };
        match p.coarse {
            Coarse::Never => (run(guess).and_then(|r| self.check(r)), false),
            Coarse::Always => {
                let start = coarse_search(guess).unwrap_or(guess);
                (run(start).and_then(|r| self.check(r)), true)
            }
            Coarse::Auto => {
                let first = run(guess);
                let looks_good = matches!(&first, Ok(r) if self.check(*r).is_ok()
                    && r.inliers as f64 >= p.checks.coarse_trigger_fraction * points.len() as f64);
                if looks_good {
                    return (first.and_then(|r| self.check(r)), false);
                }
                let Some(start) = coarse_search(guess) else {
                    return (first.and_then(|r| self.check(r)), false);
                };
                let second = run(start);
                let better = match (&first, &second) {
                    (Ok(a), Ok(b)) => {
                        if quality(b) > quality(a) {
                            second
                        } else {
                            first
                        }
                    }
                    (Err(_), Ok(_)) => second,
                    _ => first,
                };
                (better.and_then(|r| self.check(r)), true)
            }
        }
    }

    fn check(&self, r: IcpResult) -> Result<IcpResult, FallbackReason> {
        let c = &self.params.checks;
        if r.degenerate {
            return Err(FallbackReason::Degenerate);
        }
        if r.correspondences < c.min_correspondences {
            return Err(FallbackReason::TooFewCorrespondences);
        }
        if r.residual > c.max_residual {
            return Err(FallbackReason::HighResidual);
        }
        if r.constraint_ratio
            .is_some_and(|ratio| ratio < c.min_constraint_ratio)
        {
            return Err(FallbackReason::Degenerate);
        }
        Ok(r)
    }

    fn finish(
        &mut self,
        points: &[Point2<f64>],
        odometry: Option<Pose2>,
        result: Result<IcpResult, FallbackReason>,
        coarse: bool,
        estimate_of: impl Fn(&IcpResult) -> Pose2,
        odometry_estimate: Pose2,
    ) -> MatchReport {
        match result {
            Ok(r) => {
                let estimate = estimate_of(&r);
                self.remember(points, estimate, odometry);
                MatchReport {
                    estimate,
                    status: MatchStatus::Ok,
                    iterations: r.iterations,
                    correspondences: r.correspondences,
                    residual: Some(r.residual),
                    coarse,
                }
            }
            Err(reason) => {
                let mut report = self.fallback(points, odometry, odometry_estimate, reason, None);
                report.coarse = coarse;
                report
            }
        }
    }

    fn fallback(
        &mut self,
        points: &[Point2<f64>],
        odometry: Option<Pose2>,
        estimate: Pose2,
        reason: FallbackReason,
        residual: Option<f64>,
    ) -> MatchReport {
        // The next scan is first matched against this one (placed by odometry), so one bad step
        // does not poison the next. Metascan keeps it out of the map, which stays clean, but its
        // first (pairwise) stage starts from this scan, the nearest in space and time.
        if !points.is_empty() {
            self.set_keyframe(points, estimate, odometry);
        }
        MatchReport {
            estimate,
            status: MatchStatus::Fallback(reason),
            iterations: 0,
            correspondences: 0,
            residual,
            coarse: false,
        }
    }
}

/// Which of two ICP results to trust: more inliers, then the smaller residual.
fn quality(r: &IcpResult) -> (usize, std::cmp::Reverse<u64>) {
    (r.inliers, std::cmp::Reverse(r.residual.to_bits()))
}

/// Matches a whole run (convenience over `Matcher` for tests, benchmarks and experiments).
pub fn match_run(
    runs: &[(Vec<Point2<f64>>, Option<Pose2>)],
    params: &MatcherParams,
) -> Vec<MatchReport> {
    let mut m = Matcher::new(*params);
    runs.iter().map(|(p, o)| m.push(p, *o)).collect()
}
