//! Level estimation (paper sect. 5): wall polygons, the up vector, attitude and failure detection.
//!
//! [`level_pose`] is the whole stage as one pure function: the scans of one pose in, a
//! [`LevelEstimate`] out. Its steps follow the paper's subsections:
//! - [`grid`]: data collection (5.1), plus bias-corrected plane fits;
//! - [`noise`]: the range noise, estimated from the data when not given;
//! - [`polygons`]: the paper's quads (5.2);
//! - [`patches`]: quads merged into whole-wall patches by region growing (after sect. 9);
//! - [`up`]: the up vector (5.3), the paper's estimator and a robust least-squares one, and the
//!   attitude with its uncertainty (5.4);
//! - failure detection (5.5) here in [`level_pose`].

pub mod grid;
pub mod noise;
pub mod patches;
pub mod polygons;
pub mod up;

use crate::geometry::Attitude;
use crate::scan::Scan;
use grid::{GridError, PoseGrid};
use nalgebra::Vector3;
use patches::{Patch, UNLABELLED};
use polygons::Polygon;
use std::fmt;
use up::{PlaneObs, UpSolution};

/// Which up-vector estimator to use.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum Estimator {
    /// The paper's weighted sum of cross products over its small quads (sect. 5.3).
    Paper,
    /// Least squares over whole-wall patches with per-patch normal variances and robust
    /// reweighting (sect. 9's suggestion, in closed form).
    #[default]
    Robust,
}

impl fmt::Display for Estimator {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Estimator::Paper => "paper",
            Estimator::Robust => "robust",
        })
    }
}

/// What a plane is, judged by its normal against the robot's up (sect. 5.2).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SurfaceKind {
    Wall,
    Floor,
    Ceiling,
}

/// Parameters of level estimation.
#[derive(Clone, Debug, PartialEq)]
pub struct LevelParams {
    /// Range noise sigma [m]. `None` (default): the scans' `readings_sigma`, else estimated
    /// from the data.
    pub sigma: Option<f64>,
    /// Up-vector estimator. Default: robust.
    pub estimator: Estimator,
    /// Quad height in scans (rows). Default 3 (the paper's).
    pub quad_rows: usize,
    /// Quad width in rays (columns). Default 5 (the paper's).
    pub quad_cols: usize,
    /// Coplanarity tolerance of a quad, in range-noise sigmas. Default 3.5.
    pub coplanar_k: f64,
    /// Floor on the noise sigma used for tolerances [m], so noise-free data still has one.
    /// Default 0.001.
    pub min_sigma: f64,
    /// A plane is a wall when its normal is more than this from the robot's up [deg].
    /// Default 45 (the paper's bound on floor slopes).
    pub wall_min_angle_deg: f64,
    /// A quad whose opposite sides differ by more than this ratio is near a triangle and
    /// dropped [1]. Default 0.3.
    pub min_edge_ratio: f64,
    /// Region growing admits points within this many sigmas of a patch's plane. Default 3.
    pub grow_k: f64,
    /// Smallest patch kept [points]. Default 20.
    pub min_patch_points: usize,
    /// Fewer wall quads than this fails the pose (too_few_polygons / facing_floor /
    /// facing_ceiling). Default 3.
    pub min_polygons: usize,
    /// The pose fails as parallel_walls when the smaller eigenvalue of up's information
    /// matrix is below this fraction of the larger [1]. Default 0.01.
    pub parallel_ratio: f64,
    /// The pose fails as parallel_walls when either attitude sigma exceeds this [deg].
    /// Default 3.
    pub max_sigma_deg: f64,
    /// Reweighting iterations of the robust estimator. Default 10.
    pub iterations: usize,
}

impl Default for LevelParams {
    fn default() -> Self {
        Self {
            sigma: None,
            estimator: Estimator::Robust,
            quad_rows: 3,
            quad_cols: 5,
            coplanar_k: 3.5,
            min_sigma: 0.001,
            wall_min_angle_deg: 45.0,
            min_edge_ratio: 0.3,
            grow_k: 3.0,
            min_patch_points: 20,
            min_polygons: 3,
            parallel_ratio: 0.01,
            max_sigma_deg: 3.0,
            iterations: 10,
        }
    }
}

/// Why a pose could not be leveled (the contract's reasons).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FailReason {
    TooFewScans,
    InconsistentScans,
    TooFewPolygons,
    FacingFloor,
    FacingCeiling,
    ParallelWalls,
}

impl FailReason {
    /// The contract's spelling.
    pub fn as_str(&self) -> &'static str {
        match self {
            FailReason::TooFewScans => "too_few_scans",
            FailReason::InconsistentScans => "inconsistent_scans",
            FailReason::TooFewPolygons => "too_few_polygons",
            FailReason::FacingFloor => "facing_floor",
            FailReason::FacingCeiling => "facing_ceiling",
            FailReason::ParallelWalls => "parallel_walls",
        }
    }
}

impl fmt::Display for FailReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// The result of leveling one pose.
#[derive(Clone, Debug)]
pub struct LevelEstimate {
    /// `None` when leveled, else why not.
    pub failure: Option<FailReason>,
    /// The attitude (theta_x, theta_y) [rad]; `None` on failure.
    pub attitude: Option<Attitude>,
    /// 1-sigma of theta_x and theta_y [rad]; `None` on failure.
    pub sigmas: Option<[f64; 2]>,
    /// The up vector in the robot frame; `None` on failure.
    pub up: Option<Vector3<f64>>,
    /// The range noise used [m].
    pub range_sigma: f64,
    /// The grid of robot-frame points (absent when the scans could not form one).
    pub grid: Option<PoseGrid>,
    /// All coplanar quads, walls, floors and ceilings (see `kind`).
    pub quads: Vec<Polygon>,
    /// Grown patches (all kinds).
    pub patches: Vec<Patch>,
    /// Per grid point: patch index or [`UNLABELLED`].
    pub labels: Vec<u32>,
    /// Per grid point: inside a wall quad's span or a wall patch.
    pub wall_mask: Vec<bool>,
    /// Index into the pose's scans of the base scan for the pseudo-level scan (sect. 6).
    pub base_scan: Option<usize>,
}

impl LevelEstimate {
    /// Number of wall quads (the contract's `polygons`).
    pub fn wall_polygons(&self) -> usize {
        self.quads
            .iter()
            .filter(|q| q.kind == SurfaceKind::Wall)
            .count()
    }

    pub fn is_ok(&self) -> bool {
        self.failure.is_none()
    }

    fn failed(reason: FailReason, range_sigma: f64) -> Self {
        LevelEstimate {
            failure: Some(reason),
            attitude: None,
            sigmas: None,
            up: None,
            range_sigma,
            grid: None,
            quads: Vec::new(),
            patches: Vec::new(),
            labels: Vec::new(),
            wall_mask: Vec::new(),
            base_scan: None,
        }
    }
}

/// The range noise for a pose: `params.sigma`, else the median of the scans' `readings_sigma`,
/// else estimated from the data ([`noise::estimate_range_sigma`]), else `params.min_sigma`.
pub fn range_sigma_for(scans: &[Scan], params: &LevelParams) -> f64 {
    if let Some(s) = params.sigma {
        return s;
    }
    let mut given: Vec<f64> = scans
        .iter()
        .filter_map(|s| s.readings_sigma.as_ref())
        .flatten()
        .filter_map(|v| v.filter(|x| x.is_finite() && *x >= 0.0))
        .collect();
    if !given.is_empty() {
        let mid = given.len() / 2;
        let (_, m, _) = given.select_nth_unstable_by(mid, f64::total_cmp);
        return *m;
    }
    noise::estimate_range_sigma(scans).unwrap_or(params.min_sigma)
}

/// Levels one pose: its scans (any order, at least three distinct elevations) in, attitude,
/// uncertainty, wall geometry and failure reason out (paper sect. 5).
pub fn level_pose(scans: &[Scan], params: &LevelParams) -> LevelEstimate {
    let sigma = range_sigma_for(scans, params);
    let grid = match PoseGrid::from_scans(scans) {
        Ok(g) => g,
        Err(GridError::TooFewScans) => {
            return LevelEstimate::failed(FailReason::TooFewScans, sigma);
        }
        Err(GridError::InconsistentScans) => {
            return LevelEstimate::failed(FailReason::InconsistentScans, sigma);
        }
    };
    let quads = polygons::extract_quads(&grid, params, sigma);
    let (patches, labels) = match params.estimator {
        Estimator::Robust => patches::grow_patches(&grid, &quads, params, sigma),
        Estimator::Paper => (Vec::new(), vec![UNLABELLED; grid.points.len()]),
    };
    let mut wall_mask = vec![false; grid.points.len()];
    for q in quads.iter().filter(|q| q.kind == SurfaceKind::Wall) {
        for i in q.span(grid.cols) {
            wall_mask[i] = true;
        }
    }
    for (i, &l) in labels.iter().enumerate() {
        if l != UNLABELLED && patches[l as usize].kind == SurfaceKind::Wall {
            wall_mask[i] = true;
        }
    }
    let base_row = (0..grid.rows())
        .max_by_key(|&r| {
            let n = wall_mask[r * grid.cols..(r + 1) * grid.cols]
                .iter()
                .filter(|&&w| w)
                .count();
            // Ties go to the row nearest level elevation.
            (n, std::cmp::Reverse((grid.elevation[r].abs() * 1e6) as i64))
        })
        .unwrap_or(0);
    let mut est = LevelEstimate {
        failure: None,
        attitude: None,
        sigmas: None,
        up: None,
        range_sigma: sigma,
        base_scan: Some(grid.scan_index[base_row]),
        quads,
        patches,
        labels,
        wall_mask,
        grid: None,
    };
    match solve(&est, params, sigma) {
        Ok(sol) => {
            est.attitude = Some(sol.attitude());
            est.sigmas = Some(sol.attitude_sigmas());
            est.up = Some(sol.up);
        }
        Err(reason) => est.failure = Some(reason),
    }
    est.grid = Some(grid);
    est
}

/// Failure detection (sect. 5.5) and the up vector. When the walls seen cannot fix up (too
/// few, or all parallel) while floor or ceiling quads outnumber wall quads, the reason is
/// facing_floor / facing_ceiling: the scanner looks at the wrong surface, and a robot can
/// retake its scans tilted the other way (sect. 5.5, 7.2.2).
fn solve(est: &LevelEstimate, params: &LevelParams, sigma: f64) -> Result<UpSolution, FailReason> {
    let count = |k: SurfaceKind| est.quads.iter().filter(|q| q.kind == k).count();
    let (walls, floors, ceilings) = (
        count(SurfaceKind::Wall),
        count(SurfaceKind::Floor),
        count(SurfaceKind::Ceiling),
    );
    let facing = |otherwise: FailReason| {
        if floors > walls && floors >= ceilings {
            FailReason::FacingFloor
        } else if ceilings > walls {
            FailReason::FacingCeiling
        } else {
            otherwise
        }
    };
    if walls < params.min_polygons {
        return Err(facing(FailReason::TooFewPolygons));
    }
    solve_up(est, params, sigma).map_err(facing)
}

fn solve_up(
    est: &LevelEstimate,
    params: &LevelParams,
    sigma: f64,
) -> Result<UpSolution, FailReason> {
    let misfit = |f: &grid::PlaneFit| f.misfit_ratio(sigma.max(params.min_sigma)).max(1.0);
    let sigma_eff = sigma.max(params.min_sigma);
    let sol = match params.estimator {
        Estimator::Paper => {
            let wall_quads: Vec<&Polygon> = est
                .quads
                .iter()
                .filter(|q| q.kind == SurfaceKind::Wall)
                .collect();
            let normals: Vec<(Vector3<f64>, f64)> =
                wall_quads.iter().map(|q| (q.fit.normal, q.area)).collect();
            let up = up::up_paper(&normals).ok_or(FailReason::ParallelWalls)?;
            let obs: Vec<PlaneObs> = wall_quads
                .iter()
                .map(|q| PlaneObs {
                    fit: &q.fit,
                    inflate: misfit(&q.fit),
                })
                .collect();
            up::solution_at(up, &obs, sigma_eff, false)
        }
        Estimator::Robust => {
            let obs: Vec<PlaneObs> = est
                .patches
                .iter()
                .filter(|p| p.kind == SurfaceKind::Wall)
                .map(|p| PlaneObs {
                    fit: &p.fit,
                    inflate: misfit(&p.fit),
                })
                .collect();
            if obs.is_empty() {
                return Err(FailReason::TooFewPolygons);
            }
            up::up_robust(&obs, sigma_eff, params.iterations).ok_or(FailReason::ParallelWalls)?
        }
    };
    let (lo, hi) = sol.info_eigenvalues;
    if hi.is_nan() || hi <= 0.0 || lo < params.parallel_ratio * hi {
        return Err(FailReason::ParallelWalls);
    }
    let s = sol.attitude_sigmas();
    let max_sigma = params.max_sigma_deg.to_radians();
    if !(s[0] <= max_sigma && s[1] <= max_sigma) {
        return Err(FailReason::ParallelWalls);
    }
    Ok(sol)
}
