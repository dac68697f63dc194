//! The matcher's settings: one struct per stage, each field with its unit, default and why.

use super::correlative::CorrelativeParams;
use super::covariance::CovarianceParams;
use super::icp::IcpParams;
use super::map::MapParams;
use super::reference::NormalParams;
use super::solve::PosePrior;
use crate::geometry::Pose2;
use nalgebra::{Matrix3, Vector3};

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
    /// Metascan: the first stage (the scan against the last one that went into the map) only
    /// finds the basin that the map stage then refines, so its ICP stops at this many times
    /// the ICP's convergence thresholds [-]. Default 100 (1 mm and 0.06 degrees at the ICP's
    /// defaults): on the CARMEN logs 9% (Intel), 15% (ACES), 21% (CSAIL) and 20% (Freiburg
    /// 079) fewer instructions than 1, drift at 10 m over seeds 1-10 within the seeds' spread
    /// (docs/RESULTS.md). 1 converges both stages alike.
    pub local_tolerance_factor: f64,
    /// The odometry's noise per step: how far the degeneracy-aware solve trusts the odometry
    /// for the directions a scan leaves unpinned (`CheckParams::min_information_ratio`), what
    /// a step that falls back to odometry is worth, and the prior with `odometry_prior`.
    pub odometry: OdometryPrior,
    /// Weigh the odometry as a prior in every ICP solve; false (the default) trusts the scans
    /// alone and uses the odometry as the first guess and for what the scans leave unpinned.
    pub odometry_prior: bool,
    /// How the match's covariance is widened for errors the residuals do not show.
    pub covariance: CovarianceParams,
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
            local_tolerance_factor: 100.0,
            odometry: OdometryPrior::default(),
            odometry_prior: false,
            covariance: CovarianceParams::default(),
        }
    }
}

/// The odometry's noise per step: sigma = per-unit part x the step + constant part, the model
/// `simulate::odometry` and `eval real` use to perturb it.
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

    /// The covariance of an odometry step `step` under this noise model, over (x, y, yaw) in
    /// the frame the step starts from: what a step that falls back to odometry is worth.
    pub fn step_covariance(&self, step: &Pose2) -> Matrix3<f64> {
        let s_xy = self.trans_per_m * step.translation().norm() + self.trans_const;
        let s_th = self.rot_per_rad * step.theta.abs() + self.rot_const;
        Matrix3::from_diagonal(&Vector3::new(s_xy * s_xy, s_xy * s_xy, s_th * s_th))
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
    /// corridor [-]. Default 0.02. Only for all-or-nothing matching
    /// (`min_information_ratio: None`): degeneracy-aware matching tests each direction instead.
    pub min_constraint_ratio: f64,
    /// Degeneracy-aware matching: along each eigenvector of the scan's information whitened
    /// by the odometry's (the scan's information over the odometry's, per direction; Zhang,
    /// Kaess and Singh 2016), the pose comes from the scan when the ratio is at least this
    /// and from the odometry otherwise, so that a corridor still pins its width and heading
    /// [-]. Default 10: the information is in units of `OdometryPrior::residual_sigma`
    /// (1 cm) while the match's real variance is `CovarianceParams`' 3.5 or more times the
    /// sandwich's, so 10 asks for a scan a few times surer than the odometry; a pillar's
    /// face of four rays passes it. `None`: a match that does not pin all three falls back
    /// to odometry whole.
    pub min_information_ratio: Option<f64>,
    /// Degeneracy-aware matching: the pairs' sliding axis (see `min_constraint_ratio`) may
    /// come from the odometry only where the scan's own lines leave it weak, their normal
    /// scatter along it at most this fraction of the largest [-]. Default 0.3: a corridor's
    /// is about 0.001; up to 0.4 it refuses the wrong slide of a match started 25 cm off in
    /// a room (tests/matching_icp.rs, the correction gate); 0.1 also refuses partial
    /// matches that help on the CARMEN Intel log (drift at 10 m 1.06% against 0.96%).
    pub max_free_scatter: f64,
    /// With `Coarse::Auto`, the coarse search runs when the share of source points that are
    /// inliers (residual within the kernel scale) falls below this fraction of the median
    /// share of the run's last 16 accepted matches (of 1 before there are 16) [-]. Default
    /// 0.8. Relative, because the share depends on the sensor and the place more than on the
    /// basin ICP found (`matcher/trigger.rs`).
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
            min_information_ratio: Some(10.0),
            max_free_scatter: 0.3,
            coarse_trigger_fraction: 0.8,
            max_correction_xy: 0.6,
            max_correction_theta: 30f64.to_radians(),
            max_map_correction_xy: 0.1,
        }
    }
}
