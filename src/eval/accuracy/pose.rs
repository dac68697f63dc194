//! One pose leveled and scored against the truth: its error, its sigmas, and its pseudo-level
//! scan's points judged by distance to the plan's walls and by the simulator's hit labels.

use super::AccuracyParams;
use crate::eval::true_segments::TrueSegmentsFit;
use crate::geometry::Pose;
use crate::level::{FailCause, FailReason, LevelParams, level_pose};
use crate::plan::Segment;
use crate::pseudo_level::pseudo_level_scan_and_base;
use crate::scan::{Hit, Scan};
use nalgebra::Point2;
use std::borrow::Cow;

/// What happened at one pose in one cell with one estimator.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct PoseOutcome {
    /// Index of the pose's plan and of the pose in that plan's draw.
    pub plan: usize,
    pub pose: usize,
    /// True theta_x and theta_y \[deg\].
    pub truth_deg: [f64; 2],
    /// Estimated theta_x and theta_y \[deg\], when leveled.
    pub estimate_deg: Option<[f64; 2]>,
    pub failure: Option<FailReason>,
    /// The cause within `failure`'s reason ([`FailCause`]), for finding the poses behind it.
    pub cause: Option<FailCause>,
    /// The paper's error `max(|dtheta_x|, |dtheta_y|)` \[deg\], when leveled.
    pub error_deg: Option<f64>,
    /// True when leveled and both angle errors lie within 3 reported sigmas.
    pub within_3_sigma: bool,
    /// Valid pseudo-level points.
    pub pseudo_valid: usize,
    /// Valid pseudo-level points farther than `phantom_distance` from every true wall.
    pub phantoms: usize,
    /// Valid pseudo-level points whose ray met the floor or the ceiling (the simulator's hit
    /// labels): the phantoms a scan matcher suffers from, whatever the range noise did.
    pub floor_kept: usize,
    /// Valid pseudo-level points whose ray met a wall.
    pub walls_kept: usize,
    /// Wall hits of the pose's best single scan (most wall hits).
    pub best_wall_hits: usize,
    /// Wall hits of the scan the pseudo-level scan was made from (the base scan).
    pub base_wall_hits: usize,
    /// The base scan's wall hits left out of the pseudo-level scan that lie within
    /// `LOW_BAND` of the floor (or ceiling) by the truth: a wall's foot, which the
    /// pseudo-level scan's floor band refuses by design.
    pub walls_dropped_low: usize,
    /// The reported attitude sigmas of theta_x and theta_y \[deg\], when leveled.
    pub sigmas_deg: Option<[f64; 2]>,
    /// The larger reported attitude sigma \[deg\], when leveled.
    pub sigma_deg: Option<f64>,
    /// The larger of the pose's Cramér-Rao bounds on theta_x and theta_y \[deg\]
    /// ([`crate::eval::bound`]); infinite when its rays cannot fix the attitude, `None` when
    /// not computed (no noise).
    pub bound_deg: Option<f64>,
    /// An efficient estimator's error on this pose over `bound_deg`: an error drawn from the
    /// bound's 2x2 covariance, `max(|ex|, |ey|)` over the larger bound; `None` without a
    /// finite bound.
    pub efficient_over_bound: Option<f64>,
    /// The larger sigma \[deg\] of up found from the true segmentation
    /// ([`crate::eval::bound::segmented_solution`]); infinite when that cannot fix up, `None`
    /// when not computed (no noise).
    pub segmented_deg: Option<f64>,
    /// The maximum-likelihood core on the true segmentation ([`crate::eval::true_segments`]),
    /// when computed and it could fix up.
    pub true_segments: Option<TrueSegmentsFit>,
    /// The leveler's last stage on the true segmentation
    /// ([`crate::eval::true_segments::last_stage_true_segments`]), when computed and the core
    /// could fix up.
    pub true_segments_last_stage: Option<TrueSegmentsFit>,
}

impl PoseOutcome {
    /// The error over the pose's own bound, when leveled with a finite bound.
    pub fn error_over_bound(&self) -> Option<f64> {
        Some(self.error_deg? / self.bound_deg.filter(|b| b.is_finite())?)
    }

    /// The larger reported sigma over the bound, when leveled with a finite bound.
    pub fn sigma_over_bound(&self) -> Option<f64> {
        Some(self.sigma_deg? / self.bound_deg.filter(|b| b.is_finite())?)
    }

    /// The estimate's error per axis \[deg\], when leveled.
    pub fn axis_errors_deg(&self) -> Option<[f64; 2]> {
        let e = self.estimate_deg?;
        Some([e[0] - self.truth_deg[0], e[1] - self.truth_deg[1]])
    }
}

/// Height band above the floor and below the ceiling \[m\] in which a dropped wall hit
/// counts as a wall's foot (or head): the pseudo-level scan's own band is 5 cm plus three
/// sigmas of the range noise along the vertical, 0.1-0.3 of the range noise for rays at 5-20
/// degrees; 15 cm spans it at 10 cm noise.
pub const LOW_BAND: f64 = 0.15;

/// Wall hits of a scan by the simulator's labels.
fn wall_hits(scan: &Scan) -> usize {
    scan.hit
        .as_ref()
        .map_or(0, |h| h.iter().filter(|&&x| x == Hit::Wall).count())
}

/// The scans as the leveler is given them: as cast, or with `drop_ray_elevation` each ray at
/// its scan's nominal elevation (the truth and the hit labels stay with `scans`).
fn leveler_view<'a>(scans: &'a [Scan], params: &AccuracyParams) -> Cow<'a, [Scan]> {
    if params.drop_ray_elevation {
        let nominal = scans.iter().map(|s| Scan {
            ray_elevation: None,
            ..s.clone()
        });
        Cow::Owned(nominal.collect())
    } else {
        Cow::Borrowed(scans)
    }
}

/// Levels one pose's scans and scores the result against the truth: the plan's `walls` and
/// its ceiling's height when it has one (its `plan` and `pose` indices, bound and
/// true-segment fields are the caller's to set).
pub fn evaluate_pose(
    scans: &[Scan],
    truth: &Pose,
    (walls, ceiling): (&[Segment], Option<f64>),
    level: &LevelParams,
    params: &AccuracyParams,
) -> PoseOutcome {
    let seen = leveler_view(scans, params);
    let est = level_pose(&seen, level);
    let t = truth.attitude();
    let truth_deg = [t.theta_x.to_degrees(), t.theta_y.to_degrees()];
    let best_wall_hits = scans.iter().map(wall_hits).max().unwrap_or(0);
    let (Some(att), Some(sig)) = (est.attitude, est.sigmas) else {
        return PoseOutcome {
            truth_deg,
            failure: est.failure,
            cause: est.cause,
            best_wall_hits,
            ..PoseOutcome::default()
        };
    };
    let (dx, dy) = (
        (att.theta_x - t.theta_x).abs(),
        (att.theta_y - t.theta_y).abs(),
    );
    let (pseudo, base) = pseudo_level_scan_and_base(&seen, &est, &params.pseudo);
    let base = &scans[base];
    let planar = truth.to_pose2();
    let world_from_robot = truth.world_from_robot();
    let top = ceiling;
    let mut out = PoseOutcome {
        truth_deg,
        estimate_deg: Some([att.theta_x.to_degrees(), att.theta_y.to_degrees()]),
        error_deg: Some(dx.max(dy).to_degrees()),
        within_3_sigma: dx <= 3.0 * sig[0] && dy <= 3.0 * sig[1],
        best_wall_hits,
        base_wall_hits: wall_hits(base),
        sigmas_deg: Some([sig[0].to_degrees(), sig[1].to_degrees()]),
        sigma_deg: Some(sig[0].max(sig[1]).to_degrees()),
        ..PoseOutcome::default()
    };
    for i in 0..pseudo.nrays() {
        let hit = base.hit.as_ref().and_then(|h| h.get(i));
        let Some(r) = pseudo.range(i) else {
            if hit == Some(&Hit::Wall) {
                let z = base.point_in_robot(i).map(|p| (world_from_robot * p).z);
                if z.is_some_and(|z| z < LOW_BAND || top.is_some_and(|t| z > t - LOW_BAND)) {
                    out.walls_dropped_low += 1;
                }
            }
            continue;
        };
        out.pseudo_valid += 1;
        match hit {
            Some(Hit::Floor | Hit::Ceiling) => out.floor_kept += 1,
            Some(Hit::Wall) => out.walls_kept += 1,
            _ => {}
        }
        let (s, c) = pseudo.theta[i].sin_cos();
        let w = planar.transform_point(&Point2::new(r * c, r * s));
        let d = walls
            .iter()
            .map(|seg| seg.distance_to(&w))
            .fold(f64::INFINITY, f64::min);
        if d > params.phantom_distance {
            out.phantoms += 1;
        }
    }
    out
}
