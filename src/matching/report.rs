//! What the matcher reports for each scan: the contract's `match` object.

use super::solve::Remapped;
use crate::geometry::Pose2;
use nalgebra::Matrix3;

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
    /// Covariance over (x, y, yaw) of the estimate relative to the reference scan (the scan
    /// this one was first matched against: the previous one), x and y in that scan's frame:
    /// from the match (`covariance.rs`, inflated by `CovarianceParams`), from the odometry
    /// model for a fallback, zero for the first scan.
    pub covariance: Matrix3<f64>,
    /// A degeneracy-aware match: which directions came from the odometry (the free ones) and
    /// which from the scan, in the covariance's frame; `None` when no such match ran.
    pub remapped: Option<Remapped>,
}

impl MatchReport {
    /// The covariance as 9 numbers, row-major (the contract's `match.covariance`).
    pub fn covariance_row_major(&self) -> [f64; 9] {
        let c = &self.covariance;
        std::array::from_fn(|k| c[(k / 3, k % 3)])
    }

    /// The directions of (x, y, yaw) whose estimate came from the odometry, as unit vectors in
    /// the covariance's frame (the contract's `match.degenerate_directions`): none for a
    /// first scan or a match that pinned all three, all three axes for a fallback.
    pub fn degenerate_directions(&self) -> Vec<[f64; 3]> {
        match self.status {
            MatchStatus::First => Vec::new(),
            MatchStatus::Fallback(_) => vec![[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            MatchStatus::Ok => self
                .remapped
                .iter()
                .flat_map(|r| r.free_directions())
                .map(|v| [v.x, v.y, v.z])
                .collect(),
        }
    }
}
