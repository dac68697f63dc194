//! Matching a run of scans, one at a time: pairwise (each scan against the previous one) or
//! metascan (each scan against the map of all earlier matched scans), paper sect. 2.2.
//!
//! A pure state machine: `Matcher::push` takes one scan's points and odometry and returns
//! that scan's estimate and match report. Every scan gets a report; when a match is not
//! trustworthy the step falls back to the odometry and the report says why (CSM issue #17).

mod align;
mod odometry_check;
mod trigger;

use super::correlative::CorrelativeScratch;
pub use super::covariance::CovarianceParams;
use super::covariance::{fuse, inflation, rays_per_degree, rotate_into};
use super::dense::LineRuns;
use super::deskew::RayTiming;
use super::icp::{IcpResult, icp};
use super::map::VoxelMap;
pub use super::params::{CheckParams, Coarse, MatcherParams, Mode, OdometryPrior, RangeParams};
use super::reference::{Line, NormalParams, ScanReference, lines_in_runs};
pub use super::report::{FallbackReason, MatchReport, MatchStatus};
use crate::geometry::Pose2;
use crate::scan::Scan;
use align::Untrimmed;
use nalgebra::{Matrix3, Point2, Vector2};
use std::cell::RefCell;

/// A scan's usable rays as robot-frame 2D points, in ray order.
pub fn scan_points(scan: &Scan, ranges: &RangeParams) -> Vec<Point2<f64>> {
    usable_rays(scan, ranges).map(|(_, p)| p).collect()
}

/// [`scan_points`] with each point's time after the mean time of the scan's rays \[s\]
/// ([`RayTiming::mean`]), for [`deskew`](super::deskew).
pub fn timed_scan_points(
    scan: &Scan,
    ranges: &RangeParams,
    timing: &RayTiming,
) -> (Vec<Point2<f64>>, Vec<f64>) {
    let mean = timing.mean(scan.nrays());
    usable_rays(scan, ranges)
        .map(|(i, p)| (p, timing.of_ray(i) - mean))
        .unzip()
}

/// The index and robot-frame point of each ray with a reading within `ranges`.
fn usable_rays<'a>(
    scan: &'a Scan,
    ranges: &'a RangeParams,
) -> impl Iterator<Item = (usize, Point2<f64>)> + 'a {
    (0..scan.nrays()).filter_map(|i| {
        let r = scan.range(i)?;
        if r < ranges.min_range || r >= ranges.max_range || !scan.theta[i].is_finite() {
            return None;
        }
        let (s, c) = scan.theta[i].sin_cos();
        Some((i, Point2::new(r * c, r * s)))
    })
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
    /// Metascan: the covariance of the keyframe's estimate relative to the map, world frame.
    /// A step between two scans matched to the map carries both scans' errors.
    keyframe_covariance: Matrix3<f64>,
    /// The current scan's rays per degree, which widens its covariance.
    rays_per_degree: f64,
    /// The coarse search's buffers, reused from scan to scan.
    correlative: RefCell<CorrelativeScratch>,
    /// The run's recent inlier shares, which decide when `Coarse::Auto` searches.
    trigger: RefCell<trigger::CoarseTrigger>,
    /// The run's recent odometry errors against its matches, which judge the odometry model.
    odometry_check: odometry_check::OdometryCheck,
    /// Pairwise: the current scan as a reference, when the match the other way built it; it
    /// becomes the next keyframe instead of being built again.
    built: Option<ScanReference>,
    /// The current scan's local lines (`estimate_lines` from its own frame's origin), fitted
    /// once per scan for every use: the sliding test, the map, the keyframe, the way back.
    lines: Vec<Option<Line>>,
    /// How those lines were fitted (runs of rays for a dense or noisy scan).
    line_runs: LineRuns,
}

impl Matcher {
    pub fn new(params: MatcherParams) -> Self {
        Self {
            params,
            previous: None,
            keyframe: None,
            map: VoxelMap::new(params.map),
            has_odometry: false,
            keyframe_covariance: Matrix3::zeros(),
            rays_per_degree: 0.0,
            correlative: RefCell::new(CorrelativeScratch::default()),
            trigger: RefCell::default(),
            odometry_check: odometry_check::OdometryCheck::default(),
            built: None,
            lines: Vec::new(),
            line_runs: LineRuns {
                length: 1,
                for_noise: false,
            },
        }
    }

    /// How the last scan's local lines were fitted: through runs of how many rays, and whether
    /// its range noise made them longer than its density did.
    pub fn line_runs(&self) -> LineRuns {
        self.line_runs
    }

    /// The metascan map so far (empty in pairwise mode).
    pub fn map(&self) -> &VoxelMap {
        &self.map
    }

    /// Matches the next scan: `points` in its robot frame (ray order), `odometry` its dead
    /// reckoning pose if known.
    pub fn push(&mut self, points: &[Point2<f64>], odometry: Option<Pose2>) -> MatchReport {
        self.push_with_sigma(points, odometry, None)
    }

    /// [`push`](Self::push) for a scan whose range noise is known \[m\] (its `readings_sigma`):
    /// a noisy scan fits its local lines over runs of rays ([`NormalParams::range_sigma`]).
    /// `None` takes `params.normals.range_sigma`.
    pub fn push_with_sigma(
        &mut self,
        points: &[Point2<f64>],
        odometry: Option<Pose2>,
        range_sigma: Option<f64>,
    ) -> MatchReport {
        self.has_odometry =
            odometry.is_some() && self.previous.is_some_and(|(_, prev)| prev.is_some());
        self.rays_per_degree = rays_per_degree(points);
        self.built = None;
        let normals = NormalParams {
            range_sigma: range_sigma.unwrap_or(self.params.normals.range_sigma),
            ..self.params.normals
        };
        self.line_runs = LineRuns::of(self.rays_per_degree, &normals);
        let k = self.line_runs.length;
        self.lines = lines_in_runs(points, &Point2::origin(), k, &normals);
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
            self.keyframe_covariance = Matrix3::zeros();
            MatchStatus::First
        };
        MatchReport {
            estimate,
            status,
            iterations: 0,
            correspondences: 0,
            residual: None,
            coarse: false,
            covariance: Matrix3::zeros(),
            remapped: None,
        }
    }

    /// Makes `points` (at `estimate`) the scan the next one is first matched against.
    fn set_keyframe(&mut self, points: &[Point2<f64>], estimate: Pose2, odometry: Option<Pose2>) {
        let reference = self
            .built
            .take()
            .unwrap_or_else(|| ScanReference::with_lines(points.to_vec(), self.lines.clone()));
        self.keyframe = Some(Keyframe {
            reference,
            estimate,
            odometry,
        });
    }

    /// Makes `points` (at `estimate`) the next pairwise reference, or adds them to the map.
    fn remember(&mut self, points: &[Point2<f64>], estimate: Pose2, odometry: Option<Pose2>) {
        match self.params.mode {
            Mode::Pairwise => self.set_keyframe(points, estimate, odometry),
            Mode::Metascan => {
                let lines = &self.lines;
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
                    reference: ScanReference::with_lines(points.to_vec(), self.lines.clone()),
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
            let step = odometry_step(prev_odometry, odometry);
            let estimate = prev_estimate.compose(&step);
            let reason = if points.is_empty() {
                FallbackReason::NoValidRays
            } else {
                FallbackReason::NoReference
            };
            return self.fallback(points, odometry, estimate, reason, &step);
        };
        let guess = odometry_step(keyframe.odometry, odometry);
        let odometry_estimate = keyframe.estimate.compose(&guess);
        if points.is_empty() {
            return self.fallback(
                points,
                odometry,
                odometry_estimate,
                FallbackReason::NoValidRays,
                &guess,
            );
        }
        let (result, coarse) = self.align(points, &keyframe.reference, guess, &self.scan_icp());
        let (result, current) = match result {
            Ok(r) => {
                let (r, current) = self.symmetrize(points, &keyframe.reference, r);
                (Ok(r), current)
            }
            Err(e) => (Err(e), None),
        };
        let keyframe_estimate = keyframe.estimate;
        self.built = current;
        // The ICP pose is already keyframe_from_scan, so its covariance is relative to it.
        let reference = Reference {
            base: keyframe_estimate,
            theta: 0.0,
            odometry_estimate,
            step: guess,
        };
        self.finish(points, odometry, result, coarse, reference)
    }

    /// Matches the other way too (the reference's points against this scan's lines) and takes
    /// the midpoint of the two motions when they agree: each direction fits lines to a
    /// different scan's noise, so their errors partly cancel. Also returns the current scan as
    /// a reference when it was built for the way back.
    fn symmetrize(
        &self,
        points: &[Point2<f64>],
        reference: &ScanReference,
        r: IcpResult,
    ) -> (IcpResult, Option<ScanReference>) {
        // A match that took directions from the odometry keeps them exactly: the way back
        // would move them by half its own (unpinned) answer.
        if !self.params.symmetric || r.remapped.is_some_and(|m| m.free > 0) {
            return (r, None);
        }
        let current = ScanReference::with_lines(points.to_vec(), self.lines.clone());
        let back = icp(
            reference.points(),
            &current,
            r.pose.inverse(),
            &self.scan_icp(),
        );
        let Some(back) = back.filter(|b| self.check(*b).is_ok()) else {
            return (r, Some(current));
        };
        let d = r.pose.between(&back.pose.inverse());
        if d.translation().norm() > 0.02 || d.theta.abs() > 1f64.to_radians() {
            return (r, Some(current));
        }
        let pose = r
            .pose
            .compose(&Pose2::new(0.5 * d.x, 0.5 * d.y, 0.5 * d.theta));
        (IcpResult { pose, ..r }, Some(current))
    }

    fn metascan(
        &mut self,
        points: &[Point2<f64>],
        odometry: Option<Pose2>,
        prev_estimate: Pose2,
        prev_odometry: Option<Pose2>,
    ) -> MatchReport {
        let step = odometry_step(prev_odometry, odometry);
        let guess = prev_estimate.compose(&step);
        if points.is_empty() {
            return self.fallback(points, odometry, guess, FallbackReason::NoValidRays, &step);
        }
        if self.map.is_empty() {
            // Nothing to match against yet (e.g. the first pose failed to level and had no
            // valid ray): this scan starts the map at its odometry guess, as a first scan does;
            // otherwise the map would stay empty for the whole run.
            self.remember(points, guess, odometry);
            return self.fallback(points, odometry, guess, FallbackReason::NoReference, &step);
        }
        // First against the last scan that went into the map (as pairwise, with the coarse
        // search when needed): one scan has one clear basin, the map may have several near a
        // poor guess. Then refine against the whole map, which ties the run to earlier visits.
        let mut start = guess;
        let mut coarse = false;
        let mut local_ok: Option<IcpResult> = None;
        if let Some(kf) = self.keyframe.as_ref() {
            let local_guess = kf.estimate.between(&guess);
            let (local, used_coarse) =
                self.align(points, &kf.reference, local_guess, &self.local_params());
            coarse = used_coarse;
            if let Ok(r) = local {
                start = kf.estimate.compose(&r.pose);
                // In the world frame, as the map's result is.
                let covariance = r.covariance.map(|c| rotate_into(&c, -kf.estimate.theta));
                let remapped = r.remapped.map(|m| m.rotated_into(-kf.estimate.theta));
                local_ok = Some(IcpResult {
                    pose: start,
                    covariance,
                    remapped,
                    ..r
                });
            }
        }
        let result = self
            .icp_anchored(
                points,
                &self.map,
                start,
                (guess, &step),
                &self.refine_params(),
                Untrimmed::WhenFree,
            )
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
        // The reference scan is the last one that went into the map (the keyframe): the
        // world-frame covariance is turned into its frame.
        let theta = self.keyframe.as_ref().map_or(0.0, |kf| kf.estimate.theta);
        let reference = Reference {
            base: Pose2::identity(),
            theta,
            odometry_estimate: guess,
            step,
        };
        self.finish(points, odometry, result, coarse, reference)
    }

    fn finish(
        &mut self,
        points: &[Point2<f64>],
        odometry: Option<Pose2>,
        result: Result<IcpResult, FallbackReason>,
        coarse: bool,
        reference: Reference,
    ) -> MatchReport {
        match result {
            Ok(r) => {
                let estimate = reference.base.compose(&r.pose);
                let (covariance, own) = self.match_covariance(&r, &reference);
                // A step the scans pinned whole measures the odometry's error on it.
                if self.has_odometry && r.remapped.is_none_or(|m| m.free == 0) {
                    let previous = reference
                        .odometry_estimate
                        .compose(&reference.step.inverse());
                    self.odometry_check.record(
                        &self.params.odometry,
                        &reference.step,
                        &previous.between(&estimate),
                    );
                }
                self.remember(points, estimate, odometry);
                self.keyframe_covariance = own;
                MatchReport {
                    estimate,
                    status: MatchStatus::Ok,
                    iterations: r.iterations,
                    correspondences: r.correspondences,
                    residual: Some(r.residual),
                    coarse,
                    covariance,
                    remapped: r.remapped.map(|m| m.rotated_into(reference.theta)),
                }
            }
            Err(reason) => {
                let mut report = self.fallback(
                    points,
                    odometry,
                    reference.odometry_estimate,
                    reason,
                    &reference.step,
                );
                report.coarse = coarse;
                report
            }
        }
    }

    /// The reported covariance of an accepted match: the sandwich turned into the reference
    /// scan's frame, widened by `CovarianceParams`, fused with the odometry's when the odometry
    /// prior took part in the solve (the estimate is then the MAP of both). A match whose pairs
    /// left no covariance (cannot pass the checks, but to be safe) reports the odometry's.
    /// Metascan matches against the map, so the step from the keyframe also carries the
    /// keyframe's own error against the map (their sum: the errors are not anticorrelated).
    /// Returns the reported covariance and, in the ICP target's frame, this scan's own.
    fn match_covariance(
        &self,
        r: &IcpResult,
        reference: &Reference,
    ) -> (Matrix3<f64>, Matrix3<f64>) {
        let odometry = self.odometry_model().step_covariance(&reference.step);
        // Directions taken from the odometry carry its error along them (independent of the
        // scan's part, which lies in the other directions of the whitened information).
        let from_odometry = r
            .remapped
            .filter(|m| m.free > 0)
            .map_or(Matrix3::zeros(), |m| {
                m.free_covariance(&odometry.diagonal().map(f64::sqrt))
            });
        let own = match r.covariance {
            Some(scan) => {
                let k = inflation(&self.params.covariance, r.residual, self.rays_per_degree);
                let scan = scan * k + from_odometry;
                if self.params.odometry_prior && self.has_odometry {
                    // The odometry's is isotropic in x, y: the same in every frame.
                    fuse(&scan, &odometry).unwrap_or(scan)
                } else {
                    scan
                }
            }
            None => rotate_into(&odometry, -reference.theta),
        };
        let relative = match self.params.mode {
            Mode::Pairwise => own,
            Mode::Metascan => own + self.keyframe_covariance,
        };
        (rotate_into(&relative, reference.theta), own)
    }

    /// The odometry's noise model (`MatcherParams::odometry`), scaled up where the run's
    /// matches show the odometry far noisier ([`odometry_check`]).
    fn odometry_model(&self) -> OdometryPrior {
        self.odometry_check.judged(&self.params.odometry)
    }

    fn fallback(
        &mut self,
        points: &[Point2<f64>],
        odometry: Option<Pose2>,
        estimate: Pose2,
        reason: FallbackReason,
        step: &Pose2,
    ) -> MatchReport {
        // The next scan is first matched against this one (placed by odometry), so one bad step
        // does not poison the next. Metascan keeps it out of the map, which stays clean, but its
        // first (pairwise) stage starts from this scan, the nearest in space and time.
        let covariance = self.odometry_model().step_covariance(step);
        if !points.is_empty() {
            self.set_keyframe(points, estimate, odometry);
            // Placed by odometry from the previous scan (isotropic in x, y: any frame).
            self.keyframe_covariance += covariance;
        }
        MatchReport {
            estimate,
            status: MatchStatus::Fallback(reason),
            iterations: 0,
            correspondences: 0,
            residual: None,
            coarse: false,
            covariance,
            remapped: None,
        }
    }
}

/// Where a match's result goes: the estimate is `base ⊕` the ICP pose; `theta` is the heading
/// of the reference scan's frame in the ICP target's frame (for the covariance); the odometry's
/// answer and step serve a fallback.
struct Reference {
    base: Pose2,
    theta: f64,
    odometry_estimate: Pose2,
    step: Pose2,
}

/// Matches a whole run (convenience over `Matcher` for tests, benchmarks and experiments).
pub fn match_run(
    runs: &[(Vec<Point2<f64>>, Option<Pose2>)],
    params: &MatcherParams,
) -> Vec<MatchReport> {
    let mut m = Matcher::new(*params);
    runs.iter().map(|(p, o)| m.push(p, *o)).collect()
}
