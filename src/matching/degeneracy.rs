//! The matcher's side of degeneracy-aware matching (the solve is `solve.rs`'s
//! `solve_remapped`): where the odometry anchors a solve, and whether a match that slid along
//! an axis slid where the scan itself lets it.

use super::icp::IcpResult;
use super::params::{MatcherParams, OdometryPrior};
use super::reference::Line;
use super::report::FallbackReason;
use super::solve::{Remap, symmetric_eigenvalues_2x2};
use crate::geometry::Pose2;
use nalgebra::{Matrix2, Vector2};

/// The anchor of a degeneracy-aware solve: the odometry's answer `at` for the odometry step
/// `step`, with the odometry model's information. `None` when switched off
/// (`CheckParams::min_information_ratio`), or when the odometry prior takes part in the solve
/// (the MAP estimate already leans on the odometry where the scan is weak).
pub(crate) fn remap_around(
    params: &MatcherParams,
    odometry: &OdometryPrior,
    has_odometry: bool,
    at: Pose2,
    step: &Pose2,
) -> Option<Remap> {
    if params.odometry_prior && has_odometry {
        return None;
    }
    Some(Remap {
        anchor: odometry.around(at, step),
        min_ratio: params.checks.min_information_ratio?,
        min_constraint_ratio: params.checks.min_constraint_ratio,
    })
}

/// A match may slide only where the scan's own geometry lets it. From a poor start, trimming
/// can keep just the pairs on one family of walls, and the solve then takes the rest from a
/// wrong odometry guess and settles there; a corridor's own lines are all parallel. So the
/// pairs' sliding axis must be the scan's own weak axis: its lines' normal scatter along it
/// at most `CheckParams::max_free_scatter` of the largest (in the scan's frame;
/// `r.pose = target_from_scan` turns it). Otherwise the step is `degenerate`. (Directions
/// freed by the information test alone are ones the odometry knows better.) `lines`: the
/// scan's local lines (`estimate_lines` of its points, seen from the origin).
pub(crate) fn slides_as_the_scan_does(
    params: &MatcherParams,
    lines: &[Option<Line>],
    r: IcpResult,
) -> Result<IcpResult, FallbackReason> {
    let Some(m) = r.remapped.filter(|m| m.sliding) else {
        return Ok(r);
    };
    let mut scatter = Matrix2::zeros();
    for line in lines.iter().flatten() {
        scatter += line.normal * line.normal.transpose();
    }
    let (_, largest) = symmetric_eigenvalues_2x2(&scatter);
    let (s, c) = r.pose.theta.sin_cos();
    let axis = m.basis.column(0);
    let t = Vector2::new(c * axis.x + s * axis.y, -s * axis.x + c * axis.y);
    let along = (t.transpose() * scatter * t)[0];
    if largest > 0.0 && along <= params.checks.max_free_scatter * largest {
        Ok(r)
    } else {
        Err(FallbackReason::Degenerate)
    }
}
