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
//! - [`first_pass`]: up from the first segmentation, with failure detection (5.5) in
//!   [`failure`];
//! - [`refine`] and [`resegment`]: re-segmentation in the provisional level frame (after
//!   sect. 9), its engine and its driver.

pub mod eigen3;
mod failure;
mod first_pass;
pub mod grid;
pub(crate) mod ml;
pub mod noise;
pub mod patches;
pub mod polygons;
pub mod refine;
mod resegment;
pub mod up;

pub use first_pass::level_fits;
pub use resegment::{Resegmented, refine_estimate};

use crate::geometry::Attitude;
use crate::scan::Scan;
pub use grid::BearingTrigCache;
use grid::{GridError, PoseGrid};
use nalgebra::Vector3;
use patches::{Patch, UNLABELLED};
use polygons::Polygon;
use std::fmt;

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
    /// Range noise sigma \[m\]. `None` (default): the scans' `readings_sigma`, else estimated
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
    /// Floor on the noise sigma used for tolerances \[m\], so noise-free data still has one.
    /// Default 0.001.
    pub min_sigma: f64,
    /// A plane is a wall when its normal is more than this from the robot's up \[deg\].
    /// Default 45 (the paper's bound on floor slopes).
    pub wall_min_angle_deg: f64,
    /// A quad whose opposite sides differ by more than this ratio is near a triangle and
    /// dropped \[1\]. Default 0.3.
    pub min_edge_ratio: f64,
    /// Region growing admits points within this many sigmas of a patch's plane. Default 3.
    pub grow_k: f64,
    /// Those sigmas are each point's own range noise along the plane's normal,
    /// `sigma |d . n|`, rather than `sigma`: a floor seen at a grazing angle lies within
    /// centimetres of its plane even at 10 cm noise, and an isotropic tolerance lets floor
    /// patches run up the walls' feet. Default true. Walls grown this tightly keep the floor
    /// line at their foot only as a bend across rows, which `max_row_bend_sigmas` rejects;
    /// neither helps without the other.
    pub ray_tolerance: bool,
    /// Smallest share of sigma used for that tolerance, `|d . n|` floor \[1\]. Default 0.1.
    pub min_ray_share: f64,
    /// Fit each patch's plane with its points weighted by their noise along the normal,
    /// `1 / (d . n)^2`. Default true: oblique points (on a floor, the grazing ones) are the
    /// precise ones.
    pub ray_weights: bool,
    /// Floor on `|d . n|` in those weights \[1\]. Default 0.2.
    pub ray_weight_floor: f64,
    /// Region-growing seeds span about this many range-noise sigmas sideways \[1\]. Default 6.
    pub seed_span_sigmas: f64,
    /// Widest seed \[columns\]. Default 25.
    pub max_seed_cols: usize,
    /// Floors and ceilings also seed from the paper's narrow quads when the seeds are wider.
    /// Default true: along a level surface's normal the grazing rays carry little noise.
    pub narrow_level_seeds: bool,
    /// Patches whose residuals exceed this multiple of what the noise explains are tested for
    /// being two planes \[1\]. Default 1.1.
    pub split_misfit: f64,
    /// F statistic above which two planes replace one \[1\]. Default 20.
    pub split_f: f64,
    /// Nested splits allowed per patch. Default 3.
    pub split_depth: usize,
    /// Robust reweighting passes of each patch's plane. Default 1.
    pub plane_iterations: usize,
    /// Cauchy scale of those passes, in sigmas of each point's noise along the normal \[1\].
    /// Default 2.5.
    pub plane_cauchy: f64,
    /// Height band around the floor and ceiling left out of walls in that pass, on top of
    /// three sigmas of the range noise along the vertical \[m\]. Default 0.02.
    pub flat_margin: f64,
    /// Smallest patch kept \[points\]. Default 20.
    pub min_patch_points: usize,
    /// A patch too small to split is dropped when its residual variance exceeds the noise's by
    /// more than this many standard deviations of a true plane's ratio \[1\]. Default 4; 0 keeps
    /// every patch.
    pub max_misfit_sigmas: f64,
    /// A patch needs at least this share of its points in columns where it holds two rows or
    /// more \[1\]. Default 0.75; 0 accepts any patch over two rows.
    pub min_stacked_share: f64,
    /// A patch over three or more rows is dropped when its rows' mean residuals bend away from
    /// its plane by more than this many standard deviations of a true plane's chi-square per
    /// degree of freedom \[1\] (a wall line and a floor line at its foot). Default 4; 0 keeps
    /// every patch.
    pub max_row_bend_sigmas: f64,
    /// An edge row of a patch over four rows or more goes when its mean residual from the
    /// plane of the patch's other rows exceeds this many sigmas (its points' noise and that
    /// plane's uncertainty), as the floor line at a wall's foot does; 0 keeps every row.
    /// Default 5 (on three-row patches, which it would cut to two, it left wrong planes to
    /// decide a few poses at 10 cm noise).
    pub trim_sigmas: f64,
    /// A run of points at either end of a patch's row goes when it stands in front of the
    /// patch's plane (towards the scanner): the sum of its residuals beyond this many standard
    /// deviations of that sum, as the floor just in front of a wall's foot does; 0 keeps them.
    /// Default 3.
    pub front_end_sigmas: f64,
    /// Fewer wall quads than this fails the pose (too_few_polygons / facing_floor /
    /// facing_ceiling). Default 3.
    pub min_polygons: usize,
    /// The pose fails as parallel_walls when the smaller eigenvalue of up's information
    /// matrix is below this fraction of the larger \[1\]. Default 0.01.
    pub parallel_ratio: f64,
    /// The pose fails as parallel_walls when either attitude sigma exceeds this \[deg\]: the
    /// walls seen do not pin the attitude down. Default 1.5, so that an accepted attitude is
    /// within 4.5 degrees at three sigmas (measured: no accepted pose off by more than 5).
    pub max_sigma_deg: f64,
    /// Factor on the propagated attitude sigmas \[1\]: the noise model does not see
    /// segmentation errors (a few floor points in a wall, a corner split a little off), which
    /// simulations show add about a fifth. Default 1.2.
    pub sigma_inflation: f64,
    /// Reweighting iterations of the robust estimator. Default 10.
    pub iterations: usize,
    /// Take the floor and ceiling planes seen as level, as extra evidence of up beside the
    /// walls (robust estimator). Default true: the contract's world has a level floor (z = 0)
    /// and ceiling, and the robot is tilted by what it stands on, not by the floor it sees
    /// metres away. The floor's grazing rays put their range noise almost along it, so it
    /// pins up down well even at 10 cm noise, and it still levels a robot that faces the floor
    /// or sees only parallel walls. Walls outvote a floor that disagrees (robust weights).
    /// Turn off where the visible floor itself slopes (long ramps, rubble).
    pub level_surfaces: bool,
    /// A floor or ceiling patch is used as level only with at least this many points.
    /// Default 30.
    pub min_level_points: usize,
    /// ... and only when its points fit one plane within this multiple of the residual the
    /// noise explains \[1\]. Default 3. A patch that is no plane (a wall's strip seen through
    /// heavy noise, a wall foot) can fit a normal near the robot's own z axis; along that
    /// normal the grazing rays carry little noise, so its variance would claim a confidence
    /// it has not earned.
    pub max_level_misfit: f64,
    /// Factor on a level plane's normal variance \[1\]. The noise model does not see what
    /// cleaning leaves of a wall's foot in a floor patch; simulations at 1-10 cm noise show its
    /// sigmas about this much too small. Default 2 (measured with `ray_tolerance`, which keeps
    /// the wall's foot out of floor patches; 4 without it).
    pub level_inflation: f64,
    /// Passes of re-segmentation in the provisional level frame ([`refine`], robust
    /// estimator): points re-assigned to the floor and ceiling by height and to walls as
    /// vertical planes, then up re-estimated from the refitted planes; the refined solution
    /// replaces the first when it passes the gate. 0 turns it off. Default 1 (measured on
    /// the example plans, seeds 1-3: more leveled and lower means in every cell at 1, 5 and
    /// 10 cm; a second pass changed nothing measurable).
    pub refine_passes: usize,
    /// Re-segment only poses whose first solution failed or has an attitude sigma above this
    /// \[deg\]; 0 re-segments every pose. Default 0.6: re-segmenting a pose the first solution
    /// already pins down to a few tenths of a degree changes its error by hundredths, and
    /// skipping it makes `level` a third faster at 1 cm (example plans, seeds 1-3 and five
    /// unseen plans: the same poses leveled and none ok off by more than 5 degrees; at 1.0,
    /// one was).
    pub refine_above_sigma_deg: f64,
    /// Re-segmentation admits a point within this many sigmas of a model \[1\]. Default 3.
    pub refine_k: f64,
    /// A re-segmented wall is used only when at least this many scans hold 15% of its points
    /// each. Default 2 (the floor's points are kept out of walls, so two scan lines on a wall
    /// are a wall).
    pub refine_min_rows: usize,
    /// Walls whose level-frame normals are within this angle \[deg\] and whose lines coincide
    /// within the tolerance are one wall. Default 10.
    pub refine_merge_deg: f64,
    /// Factor on a re-segmented floor's or ceiling's normal variance \[1\]. Default 4 (with 2,
    /// 3-sigma coverage fell to 96.8% at 3 scans and 10 cm, from 99.4%).
    pub refine_level_inflation: f64,
    /// Smallest up uncertainty assumed while assigning points \[deg\]. Default 0.2.
    pub refine_min_sigma_deg: f64,
    /// A re-segmented floor or ceiling must be within this angle of up \[deg\]. Default 10.
    pub refine_level_max_deg: f64,
    /// A point whose range steps to its neighbours in the adjacent scans like a level
    /// surface's (by more than `r de`, plus this many sigmas of the step's noise) joins no
    /// re-segmented wall \[1\]. Default 1.
    pub refine_step_k: f64,
    /// A re-segmented floor or ceiling is used only when its points fit one plane within this
    /// multiple of the residual the noise explains \[1\]. Default 1.5 (2 or 3 leveled a few more
    /// poses at 10 cm, but 3-sigma coverage fell to 92-94%: the extra floors were biased).
    pub refine_level_misfit: f64,
    /// Also look for walls the region growing missed, as lines in each leveled scan.
    /// Default true (a small gain: 3 scans at 1 cm mean 0.180 vs 0.185 degrees).
    pub refine_discover: bool,
    /// Where re-segmentation finds no floor (or ceiling) plane, use each scan's floor points
    /// as a line that must be level ([`refine`], [`up::LevelLine`]): a scan's plane meets the
    /// floor in a line, and its grazing rays pin that line's slope down even at 10 cm noise.
    /// Default true: it levels poses that see the floor in one scan only (on the example
    /// plans, seeds 1-3, 1-3% more poses at 5 and 10 cm).
    pub level_lines: bool,
    /// Fit the floor lines of two or more scans as one plane when their points fit one
    /// (lever arm: the distance between the lines). Default true.
    pub level_line_plane: bool,
    /// Fewest points of a scan's floor or ceiling line. Default 10.
    pub level_line_min_points: usize,
    /// A floor or ceiling line's points must fit it within this multiple of the residual the
    /// noise explains \[1\]. Default 1.5.
    pub level_line_misfit: f64,
    /// Factor on a floor or ceiling line's slope variance \[1\]. Default 4 (as
    /// `refine_level_inflation`).
    pub level_line_inflation: f64,
    /// A refined solution that uses floor or ceiling lines passes the gate only with both
    /// attitude sigmas below this \[deg\] (and `max_sigma_deg`). Default 1.0.
    pub level_line_max_sigma_deg: f64,
    /// A floor or ceiling patch is not used as level when it only spans two scans thanks to
    /// points whose range hardly changes to a neighbouring scan's point (member of the patch
    /// or not), i.e. points on a wall, and those are more than a fifth of it: a floor line and
    /// a wall's line at its foot, coplanar within high noise, gave planes 10 degrees off with
    /// sigmas under 1 degree (a box room and an angled room at 10 cm). Default true.
    pub level_steep_veto: bool,
    /// ... for every patch from range noise of this sigma \[m\], and below it for a patch on
    /// fewer than `LEVEL_MIN_ROWS_NOISY` scan lines. Default 0.03: at 1 cm noise the misfit
    /// test refuses most such planes, and the veto on every patch cost a thousandth of a
    /// degree in the 1 cm means (floor points just in front of a wall's foot). On two scan
    /// lines it does not: a wall's line parallel to the floor line below it always fits a
    /// plane, and one such "floor", 15 degrees off with a misfit of 0.9, leveled a 1 cm pose
    /// (an L-shaped room, facing a corner) 13 degrees off with a sigma of 0.5.
    pub level_steep_min_sigma: f64,
}

impl LevelParams {
    /// Cosine of `wall_min_angle_deg`: a plane whose normal's cosine to up is below it is a wall.
    pub fn wall_cos(&self) -> f64 {
        self.wall_min_angle_deg.to_radians().cos()
    }

    /// Cosine of `refine_level_max_deg`.
    pub fn refine_level_cos(&self) -> f64 {
        self.refine_level_max_deg.to_radians().cos()
    }
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
            ray_tolerance: true,
            min_ray_share: 0.1,
            ray_weights: true,
            ray_weight_floor: 0.2,
            seed_span_sigmas: 6.0,
            split_misfit: 1.1,
            plane_iterations: 1,
            flat_margin: 0.02,
            plane_cauchy: 2.5,
            split_f: 20.0,
            split_depth: 3,
            max_seed_cols: 25,
            narrow_level_seeds: true,
            min_patch_points: 20,
            max_misfit_sigmas: 4.0,
            min_stacked_share: 0.75,
            max_row_bend_sigmas: 4.0,
            trim_sigmas: 5.0,
            front_end_sigmas: 3.0,
            min_polygons: 3,
            parallel_ratio: 0.01,
            max_sigma_deg: 1.5,
            sigma_inflation: 1.2,
            iterations: 10,
            level_surfaces: true,
            min_level_points: 30,
            max_level_misfit: 3.0,
            level_inflation: 2.0,
            refine_passes: 1,
            refine_above_sigma_deg: 0.6,
            refine_k: 3.0,
            refine_min_rows: 2,
            refine_merge_deg: 10.0,
            refine_level_inflation: 4.0,
            refine_min_sigma_deg: 0.2,
            refine_level_max_deg: 10.0,
            refine_step_k: 1.0,
            refine_level_misfit: 1.5,
            refine_discover: true,
            level_lines: true,
            level_line_plane: true,
            level_line_min_points: 10,
            level_line_misfit: 1.5,
            level_line_inflation: 4.0,
            level_line_max_sigma_deg: 1.0,
            level_steep_veto: true,
            level_steep_min_sigma: 0.03,
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
    /// The attitude (theta_x, theta_y) \[rad\]; `None` on failure.
    pub attitude: Option<Attitude>,
    /// 1-sigma of theta_x and theta_y \[rad\]; `None` on failure.
    pub sigmas: Option<[f64; 2]>,
    /// The up vector in the robot frame; `None` on failure.
    pub up: Option<Vector3<f64>>,
    /// The range noise used \[m\].
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
    /// `(sin, cos)` of the bearings, when every scan of the pose has the same bearings to the
    /// bit ([`BearingTrigCache`]): the pseudo-level scan's rays need them again.
    pub bearing_trig: Option<std::sync::Arc<[(f64, f64)]>>,
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

    /// Whether the scanner looks mostly at the floor or the ceiling (sect. 5.5): more floor
    /// (or ceiling) quads than wall quads. A pose can level from the floor and still be facing
    /// it, with few wall points for its pseudo-level scan; cleverRobot retakes such scans.
    pub fn facing(&self) -> Option<FailReason> {
        let count = |k: SurfaceKind| self.quads.iter().filter(|q| q.kind == k).count();
        let (walls, floors, ceilings) = (
            count(SurfaceKind::Wall),
            count(SurfaceKind::Floor),
            count(SurfaceKind::Ceiling),
        );
        if floors > walls && floors >= ceilings {
            Some(FailReason::FacingFloor)
        } else if ceilings > walls {
            Some(FailReason::FacingCeiling)
        } else {
            None
        }
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
            bearing_trig: None,
        }
    }
}

/// The range noise for a pose: `params.sigma`, else the median of the scans' `readings_sigma`,
/// else estimated from the data ([`noise::estimate_range_sigma`]), else `params.min_sigma`.
pub fn range_sigma_for(scans: &[Scan], params: &LevelParams) -> f64 {
    range_sigma_with(scans, params, None)
}

/// [`range_sigma_for`], given the `(sin, cos)` of the bearings when every scan shares them.
fn range_sigma_with(scans: &[Scan], params: &LevelParams, trig: Option<&[(f64, f64)]>) -> f64 {
    if let Some(s) = params.sigma {
        return s;
    }
    // The given sigmas' median; when they grow with range, the farther half's
    // (`noise::far_if_noisier`).
    let (mut given, mut ranged, mut ranges) = (Vec::new(), Vec::new(), Vec::new());
    for s in scans {
        let Some(sigmas) = s.readings_sigma.as_ref() else {
            continue;
        };
        for (i, v) in sigmas.iter().enumerate() {
            let Some(x) = v.filter(|x| x.is_finite() && *x >= 0.0) else {
                continue;
            };
            given.push(x);
            if let Some(r) = s.range(i) {
                ranged.push(x);
                ranges.push(r);
            }
        }
    }
    if !given.is_empty() {
        let median = |v: &mut [f64]| {
            let mid = v.len() / 2;
            *v.select_nth_unstable_by(mid, f64::total_cmp).1
        };
        let halves = noise::split_at_median_range(&ranged, &ranges)
            .map(|(mut near, mut far)| (median(&mut near), median(&mut far)));
        return noise::far_if_noisier(median(&mut given), halves);
    }
    noise::estimate_range_sigma_with(scans, trig).unwrap_or(params.min_sigma)
}

/// Levels one pose: its scans (any order, at least three distinct elevations) in, attitude,
/// uncertainty, wall geometry and failure reason out (paper sect. 5).
pub fn level_pose(scans: &[Scan], params: &LevelParams) -> LevelEstimate {
    level_pose_with(scans, params, &mut BearingTrigCache::default())
}

/// [`level_pose`] with the bearings' sines and cosines kept from the last pose in `cache`
/// (identical results). The pipeline, stage by stage (paper sect. 5 and 6).
pub fn level_pose_with(
    scans: &[Scan],
    params: &LevelParams,
    cache: &mut BearingTrigCache,
) -> LevelEstimate {
    // The range noise, then the grid of robot-frame points (sect. 5.1).
    let trig = cache.shared(scans);
    let sigma = range_sigma_with(scans, params, trig.as_deref());
    let grid = match PoseGrid::from_scans_with(scans, trig.as_deref()) {
        Ok(g) => g,
        Err(GridError::TooFewScans) => {
            return LevelEstimate::failed(FailReason::TooFewScans, sigma);
        }
        Err(GridError::InconsistentScans) => {
            return LevelEstimate::failed(FailReason::InconsistentScans, sigma);
        }
    };
    // The paper's quads (sect. 5.2), grown into whole-wall patches (robust estimator).
    let mut est = segmented(grid, params, sigma, trig);
    // Up from walls and level surfaces, and failure detection (sect. 5.3-5.5).
    let levels = first_pass::level_fits(&est, params);
    let first = first_pass::solve(&est, &levels, params, sigma);
    // Re-segmentation in the provisional level frame (after sect. 9), gated again.
    let result = resegment::resegmented(&est, &levels, first, params);
    // The wall points and base scan of the pseudo-level scan (sect. 6), then the attitude.
    est.wall_mask = wall_mask(&est);
    est.base_scan = est.grid.as_ref().map(|g| base_scan(g, &est.wall_mask));
    match result {
        Ok(sol) => {
            est.attitude = Some(sol.attitude());
            est.sigmas = Some(failure::attitude_sigmas(&sol, params));
            est.up = Some(sol.up);
        }
        Err(reason) => est.failure = Some(reason),
    }
    est
}

/// The pose's quads (sect. 5.2) and, with the robust estimator, its patches, as an estimate
/// without a solution yet.
fn segmented(
    grid: PoseGrid,
    params: &LevelParams,
    sigma: f64,
    trig: Option<std::sync::Arc<[(f64, f64)]>>,
) -> LevelEstimate {
    let quads = polygons::extract_quads(&grid, params, sigma);
    let (patches, labels) = match params.estimator {
        Estimator::Robust => patches::grow_patches(&grid, &quads, params, sigma),
        Estimator::Paper => (Vec::new(), vec![UNLABELLED; grid.points.len()]),
    };
    LevelEstimate {
        failure: None,
        attitude: None,
        sigmas: None,
        up: None,
        range_sigma: sigma,
        base_scan: None,
        quads,
        patches,
        labels,
        wall_mask: Vec::new(),
        grid: Some(grid),
        bearing_trig: trig,
    }
}

/// Per grid point, whether it lies on a wall: inside a wall quad's span or a wall patch (the
/// first segmentation's, sect. 6).
fn wall_mask(est: &LevelEstimate) -> Vec<bool> {
    let Some(grid) = &est.grid else {
        return Vec::new();
    };
    let mut wall_mask = vec![false; grid.points.len()];
    // A quad's span row by row (`Polygon::span`'s indices): overlapping quads mark most
    // points several times, cheaply as slices.
    for q in est.quads.iter().filter(|q| q.kind == SurfaceKind::Wall) {
        for r in q.row..q.row + q.rows {
            let start = r * grid.cols + q.col;
            wall_mask[start..start + q.cols].fill(true);
        }
    }
    let wall_patch: Vec<bool> = est
        .patches
        .iter()
        .map(|p| p.kind == SurfaceKind::Wall)
        .collect();
    for (mask, &l) in wall_mask.iter_mut().zip(&est.labels) {
        *mask |= l != UNLABELLED && wall_patch[l as usize];
    }
    wall_mask
}

/// The base scan of the pseudo-level scan (sect. 6): the one with most wall points, ties to
/// the one nearest level elevation; its index among the pose's scans.
fn base_scan(grid: &PoseGrid, wall_mask: &[bool]) -> usize {
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
    grid.scan_index[base_row]
}

/// The key `f64::total_cmp` orders by: the bits as a signed integer, with the magnitude bits
/// of negative numbers flipped.
pub(crate) fn total_order_key(z: f64) -> i64 {
    let bits = z.to_bits() as i64;
    bits ^ (((bits >> 63) as u64) >> 1) as i64
}

/// The inverse of [`total_order_key`] (which is its own inverse: the flip keeps the sign).
pub(crate) fn from_total_order_key(key: i64) -> f64 {
    f64::from_bits((key ^ (((key >> 63) as u64) >> 1) as i64) as u64)
}

#[cfg(test)]
mod tests {
    use super::failure::acceptable;
    use super::resegment::*;
    use super::up::UpSolution;
    use super::*;

    /// Up tilted by `deg` about the robot's x axis, with a 1-sigma of `sigma_deg` both ways.
    fn solution(deg: f64, sigma_deg: f64) -> UpSolution {
        let a = deg.to_radians();
        let up = Vector3::new(0.0, -a.sin(), a.cos());
        let basis = [Vector3::x(), up.cross(&Vector3::x())];
        UpSolution {
            up,
            basis,
            cov: nalgebra::Matrix2::identity() * sigma_deg.to_radians().powi(2),
            info_eigenvalues: (1.0, 1.0),
        }
    }

    /// How far `widened`'s covariance reaches beyond `kept`'s \[deg\], for a widening by a
    /// distance along one direction.
    fn added_deg(widened: &UpSolution, kept: &UpSolution) -> f64 {
        (widened.cov - kept.cov).norm().sqrt().to_degrees()
    }

    /// An up tilted beyond the wall angle (45 degrees) is refused however small its sigma; one
    /// just inside it passes.
    #[test]
    fn an_up_beyond_the_wall_angle_is_refused() {
        let params = LevelParams::default();
        assert_eq!(
            acceptable(&solution(46.0, 0.1), &params, true),
            Err(FailReason::ParallelWalls)
        );
        assert_eq!(acceptable(&solution(44.0, 0.1), &params, true), Ok(()));
    }

    /// Two solutions 4 degrees apart with 1-degree sigmas (2.8 joint sigmas) widen the kept
    /// one by their distance; 2 degrees apart, or against a 10-degree sigma, they agree.
    #[test]
    fn disagreeing_solutions_widen_the_kept_one() {
        let kept = solution(0.0, 1.0);
        let widened = widened_by_disagreement(&kept, &solution(4.0, 1.0)).expect("widened");
        let extra = added_deg(&widened, &kept);
        assert!((extra - 4.0).abs() < 0.01, "{extra}");
        assert_eq!(widened.up, kept.up);
        assert!(widened_by_disagreement(&kept, &solution(2.0, 1.0)).is_none());
        assert!(widened_by_disagreement(&kept, &solution(4.0, 10.0)).is_none());
    }

    /// A re-segmented solution three times tighter than the first, 3.5 degrees from it (3.7
    /// joint sigmas), stands as it is; one only half again as tight is widened by the distance.
    #[test]
    fn a_much_tighter_resegmentation_stands_against_the_first() {
        let first = solution(3.5, 0.9);
        let tight = solution(0.0, 0.3);
        assert!(widened_against_first(&tight, &first).is_none());
        assert!(widened_by_disagreement(&tight, &first).is_some());
        let loose = solution(0.0, 0.6);
        let widened = widened_against_first(&loose, &first).expect("widened");
        assert!((added_deg(&widened, &loose) - 3.5).abs() < 0.01);
    }

    /// A re-segmentation that failed the gate, 4 degrees from a first solution of 1-degree
    /// sigmas, widens it even with its own 10-degree sigma; 2 degrees away it does not.
    #[test]
    fn an_unconfirmed_first_solution_widens_beyond_its_own_sigmas() {
        let kept = solution(0.0, 1.0);
        let loose = solution(4.0, 10.0);
        assert!(widened_by_disagreement(&kept, &loose).is_none());
        let widened = widened_unconfirmed(&kept, &loose).expect("widened");
        let extra = added_deg(&widened, &kept);
        assert!((extra - 4.0).abs() < 0.01, "{extra}");
        assert_eq!(widened.up, kept.up);
        assert!(widened_unconfirmed(&kept, &solution(2.0, 10.0)).is_none());
    }

    /// A refined solution 5 degrees from a start of 1-degree sigmas widens by that distance;
    /// 3 degrees away it does not.
    #[test]
    fn a_refined_solution_far_from_its_start_widens() {
        let refined = solution(0.0, 0.5);
        let widened = widened_from_start(&refined, &solution(5.0, 1.0)).expect("widened");
        let extra = added_deg(&widened, &refined);
        assert!((extra - 5.0).abs() < 0.01, "{extra}");
        assert!(widened_from_start(&refined, &solution(3.0, 1.0)).is_none());
    }

    /// The integer keys order as `total_cmp` does and give back the same bits.
    #[test]
    fn total_order_keys_sort_as_total_cmp() {
        let mut z = vec![
            1.5,
            -0.0,
            0.0,
            -2.25,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
            -f64::NAN,
            1e-310,
            -1e-310,
            f64::MAX,
            -0.5,
        ];
        for &x in &z {
            assert_eq!(
                from_total_order_key(total_order_key(x)).to_bits(),
                x.to_bits()
            );
        }
        let mut keys: Vec<i64> = z.iter().map(|&x| total_order_key(x)).collect();
        keys.sort_unstable();
        z.sort_by(f64::total_cmp);
        let back: Vec<u64> = keys
            .iter()
            .map(|&k| from_total_order_key(k).to_bits())
            .collect();
        assert_eq!(back, z.iter().map(|x| x.to_bits()).collect::<Vec<_>>());
        // As unsigned with the sign bit flipped (the seeds' packed keys), in the same order.
        assert!(
            keys.windows(2)
                .all(|w| (w[0] as u64 ^ 1 << 63) <= (w[1] as u64 ^ 1 << 63))
        );
    }
}
