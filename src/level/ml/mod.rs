//! Maximum-likelihood refinement of up, once a segmentation is chosen (issue 26, items 1-2).
//!
//! Given which surface every point belongs to (a wall `k`, the floor, the ceiling), the
//! attitude and every surface's placement are estimated jointly from the ranges, with the
//! range noise along each ray: a wall is a vertical plane of the level frame (a 2D line), the
//! floor and ceiling level planes at unknown heights (the world the paper assumes, sect. 3:
//! vertical walls on a level floor). This is the model of the Cramér-Rao bound
//! ([`crate::eval::bound`]), so on the true segmentation the estimate is efficient to first
//! order and its covariance from the information matrix is the bound at the estimate.
//!
//! - [`model`]: the predicted range of a ray and its derivatives;
//! - [`evaluate`]: one pass over the points at a state (cost, normal equations, predictions),
//!   each surface's plane carried into the robot frame once so a point costs a few dot
//!   products;
//! - [`solve`]: Levenberg-Marquardt with a Huber kernel, the walls and heights eliminated per
//!   step by the Schur complement (each point meets one surface, so the system is an arrow),
//!   the attitude covariance with every placement marginalised, and the residuals' chi-square
//!   test that decides any inflation.
//!
//! Up lives on the sphere; it is charted by `(theta_x, theta_y)` (`up = L^T z`,
//! [`crate::geometry::Attitude::up_in_robot`]), a chart of the whole sphere less the two points
//! `up = +-x` (pitch of 90 degrees), so the step is taken in the attitude the bound and the
//! leveler report. Pure: plain points in, an estimate out.

pub(crate) mod cluster;
pub(crate) mod discover;
pub(crate) mod evaluate;
#[cfg(test)]
mod evaluate_tests;
pub(crate) mod from_segmentation;
pub(crate) mod model;
#[cfg(test)]
mod pipeline_tests;
pub(crate) mod relabel;
pub(crate) mod solve;
#[cfg(test)]
mod tests;

use nalgebra::{Point3, Vector3};
pub(crate) use solve::refine;

/// The surface a point belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub(crate) enum Surface {
    /// A vertical wall plane, by the caller's index (points of one index share one plane).
    Wall(usize),
    Floor,
    Ceiling,
}

/// One labelled range reading.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct LabelledPoint {
    /// The ray's origin in the robot frame \[m\] (the hinge offset applied).
    pub origin: Point3<f64>,
    /// The ray's unit direction in the robot frame.
    pub dir: Vector3<f64>,
    /// The measured range \[m\].
    pub range: f64,
    /// The range noise's standard deviation \[m\].
    pub sigma: f64,
    pub surface: Surface,
}

/// Parameters of the refinement, and of the leveler's last stage that runs it
/// ([`from_segmentation`]).
#[derive(Clone, Debug, PartialEq)]
pub struct MlParams {
    /// Refine the leveler's answer by maximum likelihood on its segmentation. Default true
    /// (docs/ESTIMATOR.md, section 5: at 1 cm noise errors 1.03-1.04 of the Cramér-Rao bound
    /// where the leveler's are 1.34-1.51, sigmas 1.07-1.08 of it where the leveler's are
    /// 2.5-2.9).
    pub enabled: bool,
    /// The answer is refused when it lies farther than this from the leveler's start, in the
    /// start's own sigmas \[1\]. Default 2 (section 5).
    pub max_shift_sigmas: f64,
    /// Most passes of relabelling every point by the fitted model and refitting
    /// ([`relabel`]); 0 keeps the leveler's labels. Default 3: at 5 cm noise (`$E --seed 1`)
    /// none gives error / bound 1.16-1.23 and 96.6-97.5% within three sigmas, one 1.02-1.12
    /// and 99.3-99.8% (docs/ESTIMATOR.md, section 6); with the rival on the points relabelling
    /// left (section 12) passes until the labels settle give error / bound 0.93-1.28 and sigma /
    /// bound 1.27-1.48 at 10 cm over the seven accuracy sets, where one pass gave 0.98-1.29
    /// and 1.28-1.47 with 11 of 126 cell axes below 99% within three sigmas (three passes:
    /// 3); five passes give the same as three.
    pub relabel_passes: usize,
    /// Relabelling stops once a refit moves the attitude by less than this many of its sigmas
    /// (Mahalanobis) \[1\]: a further pass would move it by less still. Default 0.3: the
    /// same answers as running every pass (within 0.01 of error and sigma over bound, as
    /// many cells within three sigmas) for 40% less of the extra passes' cost; 1.0 let 6 cell
    /// axes fall below 99% within three sigmas (section 12).
    pub relabel_settle_sigmas: f64,
    /// A wall takes points this far beyond the stretch its points cover \[m\]. Default 0.3
    /// (section 5).
    pub relabel_margin: f64,
    /// On poses whose range sigma (given or estimated) exceeds this, the covariance also
    /// takes in the fit without the floor's and ceiling's edges ([`relabel::without_level_edges`])
    /// as a rival segmentation, by `d d^T / 2` as the relabelled fit's \[m\]. Default 0.08.
    /// Below it the edges' pull lies within the sigmas (at 5 cm 99.2-100% of errors within three
    /// sigmas per axis without it; with it sigma / bound rises by 0.06-0.1 for nothing); at
    /// 10 cm the model's own sigmas held only 97.7-99.85%, from the feet of walls that no scan
    /// sees standing over the floor, and with the rival 99.1-99.8% at sigma / bound 1.39-1.65,
    /// where the leveler's padded sigmas reported before were 3.0-3.35 (docs/ESTIMATOR.md,
    /// section 7).
    pub level_edges_above: f64,
    /// A floor or ceiling point with a point of another label (or none) in its own scan
    /// within this many bearings is an edge ([`relabel::without_level_edges`]) \[rays\]. Default
    /// 2: windows 1 and 3 held 98.45% and 98.71% within three sigmas in the worst cell at
    /// 10 cm, 2 held 99.08% (a few poses apart; section 7).
    pub level_edge_window: usize,
    /// A floor (ceiling) point is left out when a point of its own or an adjacent scan within
    /// this many bearings stands over (under) it as on a wall ([`relabel`]) \[rays\]. Default
    /// 1: at 10 cm noise (stage forced on) the floor's and ceiling's points that were wall
    /// hits fell from 4066 to 2228 of 475,000 (window 0 with the pair test before); a window
    /// of 3 left out more good floor points than wall hits (sigma / bound 1.45-1.60 against
    /// 1.32-1.51) and no fewer poses beyond three sigmas.
    pub relabel_window: usize,
    /// Once the first fit has leveled the points, look among those no surface explains for
    /// the walls the segmentation lacks ([`discover`]) and fit them too. Default true: at 10 cm
    /// noise the segmentation lacked a wall of the truth at 84% of leveled poses and left 9% of
    /// the points out; with the search, error / bound 1.06 -> 1.02 and sigma / bound 1.34 ->
    /// 1.32 (means over the 9 cells of 10 cm), less at 1 and 5 cm, as many poses within three
    /// sigmas (docs/ESTIMATOR.md, section 18).
    pub missing_walls: bool,
    /// Fewest points of one scan's straight run that may lie on a missing wall \[points\].
    /// Default 4: three points of a run around a corner still look straight at 10 cm noise.
    /// 3 (with `missing_wall_min_points` 6) gave the same answers within 0.005 of the bound.
    pub missing_wall_min_run: usize,
    /// Fewest points of a missing wall over all its scans \[points\]. Default 8.
    pub missing_wall_min_points: usize,
    /// Largest gap in bearings between neighbouring points of one run \[rays\]. Default 2: a
    /// ray or two lost to noise or dropouts does not cut a wall in two.
    pub missing_wall_max_gap: usize,
    /// A run joins a missing wall when it reaches the wall's stretch along its line within
    /// this \[m\]. Default 0.5: farther along the same line is another wall (a door apart)
    /// or the same one behind an occluder, which a separate wall fits as well.
    pub missing_wall_along_gap: f64,
    /// Approach from far first (the plane residuals at a frozen incidence, below). Default
    /// true; the leveler's last stage starts within its gate of the answer and goes straight
    /// to the range likelihood (section 5: the same answers, a third of the time).
    pub approach: bool,
    /// Most Levenberg-Marquardt iterations. Default 50 (from 20 degrees off, with the true
    /// segmentation, 5-8 suffice).
    pub max_iterations: usize,
    /// Converged when the attitude step is below this \[rad\]. Default 1e-10.
    pub step_tolerance: f64,
    /// Converged, without taking the step, when the range residual's next step moves the
    /// attitude by less than this many of its own sigmas (in every direction, by its
    /// information with the placements marginalised) \[1\]. Default 0.01: the answer then lies
    /// within a hundredth of a sigma of the optimum, which moves no cell's median error or
    /// sigma over the bound by more than 0.01 (docs/ESTIMATOR.md, section 24); the tighter
    /// `step_tolerance` alone took 3-4 steps and two refused trials per refinement where 1-2
    /// steps reach this (at 1 cm noise, docs/RESULTS.md).
    pub step_sigmas: f64,
    /// Huber kernel threshold, in sigmas of the point's range noise \[1\]. Default 3: a
    /// Gaussian point passes it 99.7% of the time, so the estimate keeps 99.9% of the
    /// efficiency of least squares, and a point that does not belong (a floor hit taken for a
    /// wall) pulls with a bounded force.
    pub huber_k: f64,
    /// A surface with fewer points is left out \[points\]. Default 3 (a wall's line needs two).
    pub min_surface_points: usize,
    /// A point whose ray meets its plane at an incidence `|n . L u|` below this is left out
    /// \[1\]. Default 0.02 (within 1.1 degrees of grazing): such a range moves by metres for a
    /// tenth of a degree of attitude, so it is not linear over the attitude's uncertainty and
    /// its information is not there to be had; and while approaching from a wrong attitude a
    /// floor seen by one scan lies in that scan's plane, which would make the plane through it
    /// the scan's own.
    pub min_incidence: f64,
    /// The covariance is inflated by the residuals' chi-square per degree of freedom when that
    /// exceeds its expectation by more than this many of its standard deviations \[1\].
    /// Default 3 (a right model is inflated 0.13% of the time).
    pub inflation_z: f64,
    /// The reported covariance covers the cluster-robust (sandwich) covariance of the
    /// points' scores summed over runs of this many consecutive points of one surface
    /// ([`cluster`]); 0 turns it off \[points\]. Default 8: points a segmentation gives to the
    /// wrong surface come in runs (a wall's foot, a ledge), and their shared error is then
    /// counted once per run; 4, 8 and 16 measured alike (docs/ESTIMATOR.md, section 6).
    pub cluster_rays: usize,
    /// An estimate tilted further than this from the robot's up is refused \[deg\]. Default
    /// 60: the paper's robot never tilts beyond 45 degrees (sect. 5.2), and the chart of up
    /// by `(theta_x, theta_y)` degenerates at 90 (a refinement that ran there left its basin).
    pub max_tilt_deg: f64,
    /// A floor or ceiling fitted closer than this to the scanner's height is refused \[m\].
    /// Default 0.1. Seen by one scan, a floor or ceiling is a line in that scan's plane, and
    /// an attitude that levels the scan's plane puts the line at the scanner's height, where
    /// its rays graze it and fit any range: a false optimum (traced: a ceiling pose at 10 cm
    /// noise refined to the upper scan's elevation with a sigma of 0.15 degrees).
    pub min_level_clearance: f64,
}

impl Default for MlParams {
    fn default() -> Self {
        Self {
            enabled: true,
            max_shift_sigmas: 2.0,
            relabel_passes: 3,
            relabel_settle_sigmas: 0.3,
            relabel_margin: 0.3,
            level_edges_above: 0.08,
            level_edge_window: 2,
            relabel_window: 1,
            missing_walls: true,
            missing_wall_min_run: 4,
            missing_wall_min_points: 8,
            missing_wall_max_gap: 2,
            missing_wall_along_gap: 0.5,
            approach: true,
            max_iterations: 50,
            step_tolerance: 1e-10,
            step_sigmas: 1e-2,
            huber_k: 3.0,
            min_surface_points: 3,
            min_incidence: 0.02,
            inflation_z: 3.0,
            cluster_rays: 8,
            max_tilt_deg: 60.0,
            min_level_clearance: 0.1,
        }
    }
}

/// A wall's line in the level frame: `(cos a, sin a) . (x, y) = offset`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct WallLine {
    pub surface: Surface,
    pub azimuth: f64,
    pub offset: f64,
}

impl WallLine {
    /// Its line as the fit's placement.
    pub(crate) fn placement(&self) -> model::Placement {
        model::Placement {
            offset: self.offset,
            azimuth: self.azimuth,
        }
    }
}

/// How one surface fits: its points (those used), their clipped chi-square and its degrees of
/// freedom.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct SurfaceFit {
    pub surface: Surface,
    pub points: usize,
    pub chi2: f64,
    pub dof: f64,
}

/// The refined estimate.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct MlSolution {
    /// `(theta_x, theta_y)` \[rad\].
    pub attitude: [f64; 2],
    /// Up in the robot frame (unit).
    pub up: Vector3<f64>,
    /// Covariance of `(theta_x, theta_y)` \[rad^2\] from the information matrix with every
    /// placement marginalised, times `inflation`, widened to cover the cluster-robust
    /// covariance ([`cluster`]).
    pub covariance: [[f64; 2]; 2],
    /// 1 unless the chi-square test failed; then the chi-square per degree of freedom.
    pub inflation: f64,
    pub walls: Vec<WallLine>,
    /// Heights of the floor and ceiling planes in the level frame (scanner at 0) \[m\].
    pub floor: Option<f64>,
    pub ceiling: Option<f64>,
    /// Per input point: its normalised residual `(r - r^) / sigma` at the estimate, `None` for
    /// a point left out (on a surface with too few points, or grazing its plane).
    pub residuals: Vec<Option<f64>>,
    /// Sum over used points of `min(rho^2, huber_k^2)` and its degrees of freedom (points less
    /// parameters).
    pub chi2: f64,
    pub dof: f64,
    /// The chi-square a right model gives on average and its standard deviation.
    pub chi2_expected: f64,
    pub chi2_spread: f64,
    pub surfaces: Vec<SurfaceFit>,
    pub iterations: usize,
    pub converged: bool,
}

impl MlSolution {
    /// The 1-sigma of `theta_x` and `theta_y` \[rad\].
    pub fn sigmas(&self) -> [f64; 2] {
        [self.covariance[0][0].sqrt(), self.covariance[1][1].sqrt()]
    }

    /// Where this solution placed `surface`, if it kept it.
    pub(crate) fn placement_of(&self, surface: Surface) -> Option<model::Placement> {
        match surface {
            Surface::Floor => self.floor.map(model::Placement::level),
            Surface::Ceiling => self.ceiling.map(model::Placement::level),
            Surface::Wall(_) => self
                .walls
                .iter()
                .find(|w| w.surface == surface)
                .map(WallLine::placement),
        }
    }

    /// The covariance of `(theta_x, theta_y)` as a matrix.
    pub(crate) fn covariance_matrix(&self) -> nalgebra::Matrix2<f64> {
        nalgebra::Matrix2::from_fn(|i, j| self.covariance[i][j])
    }
}

/// Why no estimate.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub(crate) enum MlError {
    #[error("fewer points than parameters")]
    TooFewPoints,
    #[error("the surfaces do not fix the attitude (parallel walls alone)")]
    Unobservable,
    #[error("a point has a non-finite or non-positive range or sigma")]
    BadPoint,
    #[error("the refinement left the tilts a robot can have (beyond max_tilt_deg)")]
    Diverged,
    #[error("the floor or ceiling came out at the scanner's height (a scan's own plane)")]
    ScanPlane,
}
