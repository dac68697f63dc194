//! One match's alignment for [`Matcher`]: ICP from the odometry guess, the coarse search
//! first or as a second try (per `Coarse`), the odometry as a prior or as the anchor of the
//! directions the scan leaves free, and the checks that decide whether a result is trusted.

use super::{Coarse, FallbackReason, Matcher};
use crate::geometry::Pose2;
use crate::matching::correlative::{correlative_search_with, on_window_edge};
use crate::matching::degeneracy::{remap_around, slides_as_the_scan_does};
use crate::matching::icp::{IcpParams, IcpResult, icp_remapped, icp_with_prior};
use crate::matching::reference::{ScanReference, Target};
use nalgebra::Point2;

impl Matcher {
    /// ICP against one scan from `guess`, with the coarse search (over that scan's points)
    /// first or as a second try, per `Coarse`.
    pub(super) fn align(
        &self,
        points: &[Point2<f64>],
        reference: &ScanReference,
        guess: Pose2,
        icp: &IcpParams,
    ) -> (Result<IcpResult, FallbackReason>, bool) {
        let coarse_search = |g| {
            correlative_search_with(
                &mut self.correlative.borrow_mut(),
                points,
                reference.points(),
                &Point2::origin(),
                g,
                &self.params.correlative,
            )
            .map(|c| c.0)
            // A best on the window's edge is no found maximum: no start.
            .filter(|start| !on_window_edge(start, &g, &self.params.correlative))
        };
        let (result, coarse) = self.align_unchecked(points, reference, guess, icp, coarse_search);
        (result.and_then(|r| self.gate(r, &guess)), coarse)
    }

    /// Rejects a match that moved too far from the odometry guess. Without odometry the guess
    /// is the identity, which says nothing about the step, so nothing is rejected.
    pub(super) fn gate(&self, r: IcpResult, guess: &Pose2) -> Result<IcpResult, FallbackReason> {
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

    fn align_unchecked<T: Target + ?Sized>(
        &self,
        points: &[Point2<f64>],
        target: &T,
        guess: Pose2,
        icp: &IcpParams,
        coarse_search: impl Fn(Pose2) -> Option<Pose2>,
    ) -> (Result<IcpResult, FallbackReason>, bool) {
        let p = &self.params;
        let run = |g: Pose2| {
            self.icp_anchored(
                points,
                target,
                g,
                (guess, &guess),
                icp,
                Untrimmed::WhenRefused,
            )
        };
        match p.coarse {
            Coarse::Never => (run(guess).and_then(|r| self.check(r)), false),
            Coarse::Always => {
                let start = coarse_search(guess).unwrap_or(guess);
                (run(start).and_then(|r| self.check(r)), true)
            }
            Coarse::Auto => {
                let share = |r: &IcpResult| r.inliers as f64 / points.len().max(1) as f64;
                // Every accepted match's share joins the run's recent level.
                let accepted = |result: Result<IcpResult, FallbackReason>| {
                    let result = result.and_then(|r| self.check(r));
                    if let Ok(r) = &result {
                        self.trigger.borrow_mut().record(share(r));
                    }
                    result
                };
                let first = run(guess);
                let threshold = self
                    .trigger
                    .borrow()
                    .threshold(p.checks.coarse_trigger_fraction);
                let looks_good =
                    matches!(&first, Ok(r) if self.check(*r).is_ok() && share(r) >= threshold);
                if looks_good {
                    return (accepted(first), false);
                }
                let Some(start) = coarse_search(guess) else {
                    return (accepted(first), false);
                };
                // The search kept the guess itself: ICP from there is the first run again.
                if same_pose(&start, &guess) {
                    return (accepted(first), true);
                }
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
                (accepted(better), true)
            }
        }
    }

    /// The map stage's ICP settings. Its start is already within millimetres; in a map whose
    /// walls are a few voxels thick, associations keep flipping between neighbouring voxels
    /// below 0.1 mm, and chasing that costs iterations that grow with the map's age
    /// (measured: 6.9 -> 11.0 iterations from the first to the last 100 scans of a 5000-scan
    /// run; 5.0 -> 4.8 with the looser threshold, same accuracy).
    pub(super) fn refine_params(&self) -> IcpParams {
        self.loosened(10.0)
    }

    /// Metascan's local stage's ICP settings (`MatcherParams::local_tolerance_factor`).
    pub(super) fn local_params(&self) -> IcpParams {
        self.loosened(self.params.local_tolerance_factor)
    }

    /// The ICP settings for the current scan: the configured ones, with the sampling error of
    /// its beam spacing (`CovarianceParams::sampling_fraction`) in the covariance.
    pub(super) fn scan_icp(&self) -> IcpParams {
        let spacing = if self.rays_per_degree > 0.0 {
            (1.0 / self.rays_per_degree).to_radians()
        } else {
            0.0
        };
        IcpParams {
            sampling_error: self.params.covariance.sampling_fraction * spacing,
            ..self.params.icp
        }
    }

    /// The ICP settings with both convergence thresholds `factor` times the configured ones.
    fn loosened(&self, factor: f64) -> IcpParams {
        let icp = self.scan_icp();
        IcpParams {
            epsilon_xy: icp.epsilon_xy * factor,
            epsilon_theta: icp.epsilon_theta * factor,
            ..icp
        }
    }

    /// ICP from `start` with the odometry's answer `odometry = (guess, step)` as a prior
    /// (`odometry_prior`; only a real odometry step makes one: identity means "no odometry")
    /// or as the anchor of the directions the scan leaves free.
    ///
    /// Trimming keeps the pairs that fit best, and where the odometry errs along a hall by
    /// more than the kernel scale, the few pairs on an end wall or a pillar that pin its
    /// length fit worst: trimmed, they leave the length free, the solve takes it from the
    /// odometry, and the pairs stay misfit from every start. So a solve that left a direction
    /// free runs once more with every associated pair kept (`min_overlap` 1; the robust kernel
    /// still bounds an outlier's pull), and that answer is taken when it pins more directions
    /// and more pairs fit it (`quality`); it faces the same tests. `when` says which slides:
    /// against one scan only those the scan's own lines refuse, since a point the other scan
    /// did not see still finds a partner on another surface, and such pairs, trimmed for
    /// their misfit, pull all along the free direction (13-18 cm on the one-side hall's
    /// leveled scans); against the map of all earlier scans any, since a point's partner lies
    /// where its surface is (docs/RESULTS.md, tenth session).
    pub(super) fn icp_anchored<T: Target + ?Sized>(
        &self,
        points: &[Point2<f64>],
        target: &T,
        start: Pose2,
        (guess, step): (Pose2, &Pose2),
        icp_params: &IcpParams,
        when: Untrimmed,
    ) -> Result<IcpResult, FallbackReason> {
        let odometry = self.odometry_model();
        let remap = remap_around(&self.params, &odometry, self.has_odometry, guess, step);
        let solve = |icp_params: &IcpParams| {
            match remap {
                Some(remap) => icp_remapped(points, target, start, remap, icp_params),
                None => {
                    let prior = (self.params.odometry_prior && self.has_odometry)
                        .then(|| odometry.around(guess, step));
                    icp_with_prior(points, target, start, prior, icp_params)
                }
            }
            .ok_or(FallbackReason::TooFewCorrespondences)
            .and_then(|r| slides_as_the_scan_does(&self.params, &self.lines, r))
        };
        let trimmed = solve(icp_params);
        let retry = match &trimmed {
            Ok(r) => when == Untrimmed::WhenFree && free_directions(r) > 0,
            // The slide test refused the direction the kept pairs left free.
            Err(reason) => *reason == FallbackReason::Degenerate,
        };
        if !retry || icp_params.min_overlap >= 1.0 {
            return trimmed;
        }
        let untrimmed = solve(&IcpParams {
            min_overlap: 1.0,
            ..*icp_params
        });
        match (trimmed, untrimmed) {
            (Ok(t), Ok(u))
                if free_directions(&u) < free_directions(&t) && quality(&u) > quality(&t) =>
            {
                Ok(u)
            }
            (Ok(t), _) => Ok(t),
            (Err(_), untrimmed) => untrimmed,
        }
    }

    pub(super) fn check(&self, r: IcpResult) -> Result<IcpResult, FallbackReason> {
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
        // A remapped solve has tested each direction itself (and taken the weak ones from the
        // odometry); the ratio is the all-or-nothing test.
        if r.remapped.is_none()
            && r.constraint_ratio
                .is_some_and(|ratio| ratio < c.min_constraint_ratio)
        {
            return Err(FallbackReason::Degenerate);
        }
        Ok(r)
    }
}

/// Whether two poses are the same to the bit (so ICP from either gives the same result).
fn same_pose(a: &Pose2, b: &Pose2) -> bool {
    a.x.to_bits() == b.x.to_bits()
        && a.y.to_bits() == b.y.to_bits()
        && a.theta.to_bits() == b.theta.to_bits()
}

/// When [`Matcher::icp_anchored`] solves once more with every associated pair kept.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Untrimmed {
    /// When the slide test refused the direction the kept pairs left free (against one scan).
    WhenRefused,
    /// When the kept pairs left any direction free (against the map).
    WhenFree,
}

/// How many directions a solve took from the odometry.
fn free_directions(r: &IcpResult) -> usize {
    r.remapped.map_or(0, |m| m.free)
}

/// Which of two ICP results to trust: more inliers, then the smaller residual.
fn quality(r: &IcpResult) -> (usize, std::cmp::Reverse<u64>) {
    (r.inliers, std::cmp::Reverse(r.residual.to_bits()))
}
