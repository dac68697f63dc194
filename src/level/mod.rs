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

pub mod eigen3;
pub mod grid;
pub(crate) mod ml;
pub mod noise;
pub mod patches;
pub mod polygons;
pub mod refine;
pub mod up;

use crate::geometry::Attitude;
use crate::scan::Scan;
pub use grid::BearingTrigCache;
use grid::{GridError, PlaneFit, PoseGrid};
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
    /// Also seed patches from two-row quads, for walls that only two scans reach (used only
    /// when the other patches cannot fix up, and only if they rise steeply like a wall, see
    /// `steep`). Default false: a wall line and the floor line just in front of its foot, in
    /// adjacent scans, are coplanar within the noise, and the plane through them is neither
    /// (it gave confident 20-degree errors); failing is better.
    pub two_row_seeds: bool,
    /// Patches spanning only two scans are used only when the others cannot fix up, and only
    /// when their normal is at least this far from the robot's up \[deg\]. Default 60.
    pub two_row_min_angle_deg: f64,
    /// Robust reweighting passes of each patch's plane. Default 1.
    pub plane_iterations: usize,
    /// Cauchy scale of those passes, in sigmas of each point's noise along the normal \[1\].
    /// Default 2.5.
    pub plane_cauchy: f64,
    /// Grow the patches a second time without the points at the floor's or ceiling's height
    /// (robust estimator). Default false: it did not measurably help and costs a growth.
    pub flat_pass: bool,
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
            two_row_seeds: false,
            two_row_min_angle_deg: 60.0,
            plane_iterations: 1,
            flat_pass: false,
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
/// (identical results).
pub fn level_pose_with(
    scans: &[Scan],
    params: &LevelParams,
    cache: &mut BearingTrigCache,
) -> LevelEstimate {
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
    let quads = polygons::extract_quads(&grid, params, sigma);
    let (patches, labels) = match params.estimator {
        Estimator::Robust => patches::grow_patches(&grid, &quads, params, sigma, None),
        Estimator::Paper => (Vec::new(), vec![UNLABELLED; grid.points.len()]),
    };
    let mut est = LevelEstimate {
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
    };
    let mut levels = level_fits(&est, params);
    let mut result = solve(&est, &levels, params, sigma);
    // Second pass: with up known, points at the floor's or ceiling's height are not wall
    // points. Walls grown a first time can have swallowed the floor at their foot (within the
    // noise of the wall's plane, and all on one side of it); growing again without those
    // points removes that tilt.
    if params.estimator == Estimator::Robust && params.flat_pass {
        if let (Ok(sol), Some(grid)) = (&result, &est.grid) {
            if let Some(blocked) = flat_points(grid, &est.patches, &sol.attitude(), sigma, params) {
                let (patches, labels) =
                    patches::grow_patches(grid, &est.quads, params, sigma, Some(&blocked));
                let first = (
                    std::mem::replace(&mut est.patches, patches),
                    std::mem::replace(&mut est.labels, labels),
                );
                let levels2 = level_fits(&est, params);
                match solve(&est, &levels2, params, sigma) {
                    Ok(sol2) => {
                        result = Ok(sol2);
                        levels = levels2;
                    }
                    Err(_) => (est.patches, est.labels) = first,
                }
            }
        }
    }
    let needs_refine = match &result {
        Ok(sol) => attitude_sigmas(sol, params)
            .iter()
            .any(|s| s.to_degrees() > params.refine_above_sigma_deg),
        Err(_) => true,
    };
    if params.estimator == Estimator::Robust && params.refine_passes > 0 && needs_refine {
        let Refinement {
            accepted,
            raw,
            start,
        } = refined_solution(&est, &levels, &result, params);
        let confirmed = accepted.is_some();
        // The solution kept and the other one of the two: the first when the refined one is
        // kept, else the refined one, gated or not; none when the first failed.
        let other = match accepted {
            Some(refined) => std::mem::replace(&mut result, Ok(refined)).ok(),
            None => raw,
        };
        let widened = match (&result, other) {
            (Ok(kept), Some(first)) if confirmed => widened_against_first(kept, &first),
            (Ok(kept), Some(other)) => widened_unconfirmed(kept, &other),
            // The refined solution stands alone: checked against where it started.
            (Ok(kept), None) => start.and_then(|s| widened_from_start(kept, &s)),
            (Err(_), _) => None,
        };
        if let Some(widened) = widened {
            // Only its sigma changed: the walls' spread was judged already.
            result = acceptable(&widened, params, true).map(|()| widened);
        }
    }
    let Some(grid) = &est.grid else {
        return est;
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
    est.base_scan = Some(grid.scan_index[base_row]);
    est.wall_mask = wall_mask;
    match result {
        Ok(sol) => {
            est.attitude = Some(sol.attitude());
            est.sigmas = Some(attitude_sigmas(&sol, params));
            est.up = Some(sol.up);
        }
        Err(reason) => est.failure = Some(reason),
    }
    est
}

/// Largest attitude sigma of any start of re-segmentation \[rad\] (11.5 degrees): at 0.2 it
/// leveled 0.3 points fewer poses at 10 cm (3 scans), at 0.1 up to 0.7 points fewer.
const START_MAX_SIGMA: f64 = 0.2;

/// Re-segmentation in the provisional level frame ([`refine`]): its start, its refined model
/// (not yet gated), and the other starts' refined solutions that pass the gate.
pub struct Resegmented {
    pub start: UpSolution,
    pub refined: refine::Refined,
    pub rivals: Vec<UpSolution>,
}

/// Re-segmentation in the provisional level frame ([`refine`]), started from the solution
/// found (`first`), or, when the gate refused it, from every start found without a level frame
/// (`blind_starts`): of their refined models, the one that pins up down best is kept, and
/// the others that pass the gate are its rivals. `None` when there is nothing to start from or
/// no refined model fixes up.
///
/// One start can settle on a wrong but self-consistent set of planes that another start does
/// not: traced, 12 scans of a cleverRobot pose, where the ungated solution (25 degrees off)
/// refined to one 15 degrees off with sigmas under one degree, and the walls with the floor's
/// lines (1 degree off) refined to one 1.2 degrees off, as tight.
pub fn refine_estimate(
    est: &LevelEstimate,
    levels: &[PlaneFit],
    first: &Result<UpSolution, FailReason>,
    params: &LevelParams,
) -> Option<Resegmented> {
    let grid = est.grid.as_ref()?;
    let sigma = est.range_sigma;
    let steps = refine::level_steps(grid, params, sigma);
    let starts = match first {
        Ok(sol) => vec![*sol],
        Err(_) => blind_starts(est, grid, levels, &steps, params),
    };
    let walls: Vec<&Patch> = est
        .patches
        .iter()
        .filter(|p| p.kind == SurfaceKind::Wall)
        .collect();
    let mut refined: Vec<(UpSolution, refine::Refined)> = starts
        .into_iter()
        // From a start this loose, re-segmentation can settle on a wrong but self-consistent
        // set of planes (a pose 16 degrees off at the start, 23 degrees of sigma, ended 7
        // degrees off with sigmas near one degree); it rescues almost nothing from there.
        .filter(|start| start.max_attitude_sigma() <= START_MAX_SIGMA)
        .filter_map(|start| {
            let r = refine::refine(grid, &start, &walls, &steps, params, sigma)?;
            Some((start, r))
        })
        .collect();
    let (best, _) = refined
        .iter()
        .map(|(_, r)| r.solution.max_attitude_sigma())
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(&b.1))?;
    let (start, kept) = refined.swap_remove(best);
    let rivals = refined
        .into_iter()
        .map(|(_, r)| r.solution)
        .filter(|r| acceptable(r, params, true).is_ok())
        .collect();
    Some(Resegmented {
        start,
        refined: kept,
        rivals,
    })
}

/// Starts of re-segmentation found without a level frame, for a pose whose first solution
/// failed the gate: the ungated robust solution; the walls with the floor's or ceiling's
/// lines (walls that cannot fix up alone, as one wall split into patches, leave up free to
/// turn about their normal); and a floor or ceiling found by its range steps alone.
fn blind_starts(
    est: &LevelEstimate,
    grid: &PoseGrid,
    levels: &[PlaneFit],
    steps: &refine::LevelSteps,
    params: &LevelParams,
) -> Vec<UpSolution> {
    let sigma = est.range_sigma;
    let sigma_eff = sigma.max(params.min_sigma);
    let obs = robust_obs(est, levels, params, sigma, false);
    let walls = up::up_robust(&obs, sigma_eff, params.iterations);
    let with_lines = (params.level_lines && params.level_surfaces)
        .then(|| refine::start_lines(grid, steps, params, sigma))
        .filter(|lines| !lines.is_empty())
        .and_then(|lines| {
            let mut obs = obs.clone();
            obs.extend(
                lines
                    .iter()
                    .map(|l| up::PlaneObs::level_line(l, params.level_line_inflation)),
            );
            up::up_robust(&obs, sigma_eff, params.iterations)
        });
    let level = refine::level_start(grid, steps, params, sigma);
    [walls, with_lines, level].into_iter().flatten().collect()
}

/// The refined solution when it passes the gate. When it does not, the first stands: the
/// refined model sometimes keeps fewer points (ambiguous ones are left out), and letting its
/// verdict overrule a first solution that passed failed 4-8% more poses at 10 cm for a
/// small gain in the mean error (0.43 to 0.36 degrees at 5 scans).
fn refined_solution(
    est: &LevelEstimate,
    levels: &[PlaneFit],
    first: &Result<UpSolution, FailReason>,
    params: &LevelParams,
) -> Refinement {
    let Some(Resegmented {
        start,
        refined,
        rivals,
    }) = refine_estimate(est, levels, first, params)
    else {
        return Refinement::default();
    };
    let raw = Some(refined.solution);
    let start = Some(start);
    let level_models = refined.models.iter().any(|m| m.kind != SurfaceKind::Wall);
    // Lines alone leave each direction of up to single lines, with nothing to check them
    // against: traced on a zigzag wall at 10 cm, three floor lines (no wall kept) leveled a
    // pose 9.5 degrees off with a sigma of 0.3, one of them 5 degrees off level, running onto
    // a wall's foot. Over 405,000 protocol poses at 1-10 cm (seeds 101-150, nine plans), no
    // other pose was leveled that way.
    let accepted = if refined.models.is_empty() {
        None
    } else if refined.lines.is_empty() {
        acceptable(&refined.solution, params, level_models)
            .is_ok()
            .then_some(refined.solution)
    } else {
        // A line pins up down across it only: the other direction rests on the walls that
        // alone could not pass the gate, so it is held to a stricter one; failing that, the
        // models without the lines are gated as usual.
        let strict = params.max_sigma_deg.min(params.level_line_max_sigma_deg);
        if acceptable_within(&refined.solution, params, true, strict).is_ok() {
            Some(refined.solution)
        } else {
            refined
                .without_lines(params, est.range_sigma)
                .filter(|w| acceptable(w, params, level_models).is_ok())
        }
    };
    // Another start's re-segmentation that passes the gate as well but lies far from this
    // one: two self-consistent readings of the pose, and which one is right is not known.
    let accepted = accepted.and_then(|a| {
        let widened = rivals.iter().fold(a, |kept, rival| {
            widened_by_disagreement(&kept, rival).unwrap_or(kept)
        });
        acceptable(&widened, params, true)
            .is_ok()
            .then_some(widened)
    });
    Refinement {
        accepted,
        raw,
        start,
    }
}

/// What re-segmentation gave: the refined solution when it passed the gate, the refined
/// solution gated or not, and the solution it started from.
#[derive(Default)]
struct Refinement {
    accepted: Option<UpSolution>,
    raw: Option<UpSolution>,
    start: Option<UpSolution>,
}

/// The re-segmented solution `kept`, widened by its disagreement with the first solution
/// ([`widened_by_disagreement`]) unless it is [`TIGHTER_THAN_FIRST`] times tighter: then the
/// re-segmentation found evidence that the first did not use (traced: a floor plane), and their
/// distance is the first's error, not doubt about which reading is right.
fn widened_against_first(kept: &UpSolution, first: &UpSolution) -> Option<UpSolution> {
    if kept.max_attitude_sigma() * TIGHTER_THAN_FIRST <= first.max_attitude_sigma() {
        return None;
    }
    widened_by_disagreement(kept, first)
}

/// How many times tighter than the first solution a re-segmented one must be to stand without
/// widening by their disagreement. Traced, 6 of 16 protocol poses that failed while their
/// Cramér-Rao bounds were under 0.12 degree had a first solution 2-3 of its sigmas off and a
/// re-segmented one 5-30 times tighter and within 0.1 degree of the truth. Over 432,000
/// protocol poses at 5-10 cm (nine plans, seeds 101-180), leveled 74.71 -> 74.80% with the same
/// 41 poses ok and more than 5 degrees off and 744 more than 3 (at 1.5, the more cautious 2's
/// equal: 74.84%, the same counts, 3 more poses beyond 3 sigmas; never widening: 11 more poses
/// more than 5 degrees off);
/// over 129,600 more (seeds 1-8, 11-14, 21-32), 74.64 -> 74.76% with 4 and 4; at 1 cm, 99.12 ->
/// 99.17%.
const TIGHTER_THAN_FIRST: f64 = 2.0;

/// `kept` with its covariance widened by its distance from `other` when the two disagree
/// beyond [`DISAGREEMENT_SIGMAS`] of their joint uncertainty; `None` when they agree. The
/// first solution and the re-segmented one rest on nearly the same ranges, so they can only
/// disagree that much when one of them rests on a wrong segmentation, and which one is not
/// known: traced poses ended 5-7 degrees off either way, with sigmas near one degree.
fn widened_by_disagreement(kept: &UpSolution, other: &UpSolution) -> Option<UpSolution> {
    widened_beyond(
        kept,
        other,
        kept.cov + other.cov_in(&kept.basis),
        DISAGREEMENT_SIGMAS,
    )
}

/// `kept`, the first solution, with its covariance widened by its distance from `other`, a
/// re-segmentation that could not pass the gate, when that distance exceeds
/// [`UNCONFIRMED_SIGMAS`] of the first solution's own uncertainty; `None` otherwise. Such a
/// re-segmentation is too loose to test the first solution against their joint uncertainty,
/// yet landing that far off means the first solution's planes were not the ones seen in its
/// own level frame. Traced, 13 of 17 poses reported ok and 5-7 degrees off (75,600 protocol
/// poses at 5-10 cm) were first solutions whose re-segmentation failed the gate; 11 of those
/// lay 2-18 degrees away, most of them nearer the truth, with sigmas of 1-1.5 degrees.
fn widened_unconfirmed(kept: &UpSolution, other: &UpSolution) -> Option<UpSolution> {
    widened_beyond(kept, other, kept.cov, UNCONFIRMED_SIGMAS)
}

/// `kept`, a refined solution that passed the gate where the first solution had failed, with
/// its covariance widened by its distance from the solution re-segmentation started from when
/// that exceeds [`FROM_START_SIGMAS`] of the start's own uncertainty. The start (one of
/// [`blind_starts`]) seeded the re-segmentation; landing that far
/// from it means its planes were wrong, and a segmentation grown from them is in doubt too.
/// Traced: a start 11 degrees off with sigmas of 1.6-1.8 degrees led to a refined solution 6
/// degrees off with sigmas under one degree.
fn widened_from_start(kept: &UpSolution, start: &UpSolution) -> Option<UpSolution> {
    widened_beyond(kept, start, start.cov_in(&kept.basis), FROM_START_SIGMAS)
}

/// `kept` with `d d^T` added to its covariance, for `d` its distance from `other` in its tangent
/// plane, when `d` lies beyond `sigmas` of `spread` (a covariance in `kept`'s basis).
fn widened_beyond(
    kept: &UpSolution,
    other: &UpSolution,
    spread: nalgebra::Matrix2<f64>,
    sigmas: f64,
) -> Option<UpSolution> {
    let d = nalgebra::Vector2::new(other.up.dot(&kept.basis[0]), other.up.dot(&kept.basis[1]));
    let z2 = (d.transpose() * spread.try_inverse()? * d)[(0, 0)];
    (z2 > sigmas * sigmas).then(|| UpSolution {
        cov: kept.cov + d * d.transpose(),
        ..*kept
    })
}

/// How far apart, in joint sigmas, the first and the re-segmented solutions may lie before
/// the kept one's covariance takes in their distance. The sum of the two covariances
/// overstates their difference's (they share most of their data), so 2.5 of it is a stricter
/// test than it looks. Over 145,800 poses of nine plans, it cut the poses reported ok and more
/// than 5 degrees off from 22 to 17 for 0.25 points fewer leveled at 5-10 cm (3: 20 and 0.1;
/// 2: 13 and 0.65).
const DISAGREEMENT_SIGMAS: f64 = 2.5;

/// How far, in the first solution's own sigmas, a re-segmentation that failed the gate may lie
/// from it before its covariance takes in their distance ([`widened_unconfirmed`]). Over
/// 75,600 protocol poses at 5-10 cm (nine plans, seeds 1-8 and 11-16), poses reported ok and
/// more than 5 degrees off fell from 17 to 9 and those beyond 3 sigmas from 96 to 79, for 0.76
/// points fewer leveled; over 97,200 more at 1-10 cm (seeds 21-28), from 16 to 10, for 0.77
/// points. At 2.5: 8 and 7 such poses, for 1.1 points.
const UNCONFIRMED_SIGMAS: f64 = 3.0;

/// How far, in the start's sigmas, a refined solution that stands alone may lie from the
/// solution its re-segmentation started from ([`widened_from_start`]). Over the same two sets
/// (172,800 poses) poses reported ok and more than 5 degrees off fell from 19 to 16, and those
/// more than 4 sigmas off from 23 to 20 (seeds 21-28), for 0.09 points fewer leveled; at 3
/// sigmas the same, for 0.2 points.
const FROM_START_SIGMAS: f64 = 4.0;

/// Points at the height of the floor or ceiling patches once leveled with `att` (within
/// `flat_margin` plus three sigmas of their range noise along the vertical); `None` when
/// neither height is known.
fn flat_points(
    grid: &PoseGrid,
    patches: &[Patch],
    att: &Attitude,
    sigma: f64,
    params: &LevelParams,
) -> Option<Vec<bool>> {
    let level_from_robot = att.level_from_robot();
    let matrix = *level_from_robot.matrix();
    let height = |kind: SurfaceKind| {
        patches::level_height(grid, patches, kind, &matrix, params.min_patch_points)
    };
    // Without a floor patch (the walls may have swallowed it), the floor is the lowest
    // points seen: the 2nd percentile of the leveled heights. If no floor is in view, this
    // only trims the lowest band of wall points.
    let floor = height(SurfaceKind::Floor).or_else(|| {
        let mut z: Vec<f64> = grid
            .points
            .iter()
            .flatten()
            .map(|g| (level_from_robot * g.p).z)
            .collect();
        if z.len() < 50 {
            return None;
        }
        let k = z.len() / 50;
        let (_, m, _) = z.select_nth_unstable_by(k, f64::total_cmp);
        (*m < 0.0).then_some(*m)
    });
    let ceiling = height(SurfaceKind::Ceiling);
    if floor.is_none() && ceiling.is_none() {
        return None;
    }
    let s = sigma.max(params.min_sigma);
    Some(
        grid.points
            .iter()
            .map(|g| {
                g.as_ref().is_some_and(|g| {
                    let z = (level_from_robot * g.p).z;
                    let margin = params.flat_margin + 3.0 * s * (level_from_robot * g.dir).z.abs();
                    [floor, ceiling]
                        .iter()
                        .flatten()
                        .any(|h| (z - h).abs() < margin)
                })
            })
            .collect(),
    )
}

/// Failure detection (sect. 5.5) and the up vector. When the walls seen cannot fix up (too
/// few, or all parallel) while floor or ceiling quads outnumber wall quads, the reason is
/// facing_floor / facing_ceiling: the scanner looks at the wrong surface, and a robot can
/// retake its scans tilted the other way (sect. 5.5, 7.2.2).
fn solve(
    est: &LevelEstimate,
    levels: &[PlaneFit],
    params: &LevelParams,
    sigma: f64,
) -> Result<UpSolution, FailReason> {
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
    if walls < params.min_polygons && levels.is_empty() {
        return Err(facing(FailReason::TooFewPolygons));
    }
    solve_up(est, levels, params, sigma).map_err(facing)
}

fn solve_up(
    est: &LevelEstimate,
    levels: &[PlaneFit],
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
                .map(|q| PlaneObs::wall(&q.fit, misfit(&q.fit)))
                .collect();
            up::solution_at(up, &obs, sigma_eff, false)
        }
        Estimator::Robust => {
            // Patches over three or more scans first. A plane through just two scan lines can
            // be a wall line and a floor line that happen to be coplanar, so two-row patches
            // only help when the others cannot fix up, and then only clearly vertical ones.
            let obs_with = |two_rows: bool| robust_obs(est, levels, params, sigma, two_rows);
            let first = obs_with(false);
            let attempt = up::up_robust(&first, sigma_eff, params.iterations)
                .filter(|sol| acceptable(sol, params, !levels.is_empty()).is_ok());
            match attempt {
                Some(sol) => sol,
                None if !params.two_row_seeds => {
                    if first.is_empty() {
                        return Err(FailReason::TooFewPolygons);
                    }
                    up::up_robust(&first, sigma_eff, params.iterations)
                        .ok_or(FailReason::ParallelWalls)?
                }
                None => {
                    let obs = obs_with(true);
                    if obs.is_empty() {
                        return Err(FailReason::TooFewPolygons);
                    }
                    up::up_robust(&obs, sigma_eff, params.iterations)
                        .ok_or(FailReason::ParallelWalls)?
                }
            }
        }
    };
    acceptable(&sol, params, !levels.is_empty())?;
    Ok(sol)
}

/// The robust estimator's observations: wall patches over three or more scans (with
/// `two_rows`, also steep two-row ones) and the level planes.
fn robust_obs<'a>(
    est: &'a LevelEstimate,
    levels: &'a [PlaneFit],
    params: &LevelParams,
    sigma: f64,
    two_rows: bool,
) -> Vec<PlaneObs<'a>> {
    let misfit = |f: &grid::PlaneFit| f.misfit_ratio(sigma.max(params.min_sigma)).max(1.0);
    let full_rows = params.quad_rows.min(grid_rows(est)).saturating_sub(1);
    let strict = (params.two_row_min_angle_deg.to_radians()).cos();
    est.patches
        .iter()
        .filter(|p| p.kind == SurfaceKind::Wall)
        .filter(|p| {
            p.row_range.1 - p.row_range.0 >= full_rows
                || (two_rows
                    && p.fit.normal.z.abs() < strict
                    && est.grid.as_ref().is_some_and(|g| steep(g, p)))
        })
        .map(|p| PlaneObs::wall(&p.fit, misfit(&p.fit)))
        .chain(
            levels
                .iter()
                .map(|f| PlaneObs::level(f, misfit(f) * params.level_inflation)),
        )
        .collect()
}

/// Fewest scan lines, each with a fair share of its points, that a floor or ceiling patch
/// needs to be a level plane of the first solution from `level_steep_min_sigma` (3 cm) of noise
/// up. Two lines always lie in one plane, and a wall's line with the next scan's floor line made
/// a "floor" 8 degrees off, which with one wall leveled a pose 7 degrees off with a sigma of
/// 0.4 degrees. Re-segmentation still takes such floors, checked against the provisional up.
/// Over 172,800 protocol poses (two seed sets, nine plans) poses reported ok and more than 5
/// degrees off fell from 16 to 13 and those beyond 3 sigmas from 78 to 64 (seeds 1-16), for
/// 0.4 points fewer leveled at 5-10 cm; 1 cm is unchanged.
const LEVEL_MIN_ROWS_NOISY: usize = 3;

/// Floor and ceiling planes usable as level (when `level_surfaces` is on): each floor or
/// ceiling patch cleaned of the points that do not behave like a level surface, and refitted.
///
/// At high noise a patch grown on the floor can run up the foot of a wall (the two meet within
/// the growing tolerance), and the mixture's plane is tilted by degrees. A level surface is
/// told from a wall by how its range changes from scan to scan in one column: by more than
/// `r de` per elevation step `de` (`r cot(a) de` for a surface seen `a` < 45 degrees off the
/// beams' plane, against `r tan(b) de` on a wall). Only points with such a step to a
/// neighbouring scan, in the patch's prevailing direction, are kept. A patch mostly in one scan
/// line is dropped: it fits that scan's own plane, whose normal is near the robot's z axis
/// whatever the surface. From `level_steep_min_sigma` of noise up, so is a patch on two scan
/// lines only (`LEVEL_MIN_ROWS_NOISY`).
pub fn level_fits(est: &LevelEstimate, params: &LevelParams) -> Vec<PlaneFit> {
    let (Some(grid), true) = (
        est.grid.as_ref(),
        params.level_surfaces && params.estimator == Estimator::Robust,
    ) else {
        return Vec::new();
    };
    let sigma = est.range_sigma.max(params.min_sigma);
    est.patches
        .iter()
        .filter(|p| p.kind != SurfaceKind::Wall && p.fit.n >= params.min_level_points)
        .filter_map(|p| clean_level_fit(grid, p, sigma, params))
        .collect()
}

fn clean_level_fit(
    grid: &PoseGrid,
    p: &Patch,
    sigma: f64,
    params: &LevelParams,
) -> Option<PlaneFit> {
    let cols = grid.cols;
    // A mask rather than a binary search: `step` asks several times per member.
    let mut in_patch = vec![false; grid.points.len()];
    for &i in &p.members {
        in_patch[i] = true;
    }
    let member = |i: usize| in_patch[i];
    let rc = grid.row_col();
    // Signed scan-to-scan range steps in units of `r de`, keyed by the lower point.
    let step = |i: usize| -> Option<f64> {
        let j = i + cols;
        if j >= grid.points.len() || !member(j) {
            return None;
        }
        let (a, b) = (grid.points[i].as_ref()?, grid.points[j].as_ref()?);
        let de = grid.elevation[rc.row(j)] - grid.elevation[rc.row(i)];
        let scale = 0.5 * (a.range + b.range) * de;
        (scale.abs() > 1e-9).then(|| (b.range - a.range) / scale)
    };
    // Each member's step once: `kept` below asks for it up to three times per member (and
    // only for members).
    let mut step_at = vec![None; grid.points.len()];
    for &i in &p.members {
        step_at[i] = step(i);
    }
    let mut steps: Vec<f64> = p.members.iter().filter_map(|&i| step_at[i]).collect();
    if steps.len() < 10 {
        return None;
    }
    let mid = steps.len() / 2;
    let sign = steps.select_nth_unstable_by(mid, f64::total_cmp).1.signum();
    let levelish = |i: usize| step_at[i].is_some_and(|x| x * sign > 1.0);
    // A point whose range hardly changes to a neighbouring scan's, member or not, lies on a
    // steep surface with it: a wall line at the foot of a wall joins a floor patch through the
    // floor line below it (their step is a floor's), but the wall above it gives it away.
    let on_steep = |i: usize| -> bool {
        let Some(a) = grid.points[i].as_ref() else {
            return false;
        };
        let r = rc.row(i);
        [
            (r > 0).then(|| i - cols),
            (i + cols < grid.points.len()).then_some(i + cols),
        ]
        .into_iter()
        .flatten()
        .any(|j| {
            grid.points[j].as_ref().is_some_and(|b| {
                let de = grid.elevation[rc.row(j)] - grid.elevation[r];
                (b.range - a.range).abs() <= 0.5 * (a.range + b.range) * de.abs()
            })
        })
    };
    let kept = |i: usize| {
        let from_below = i >= cols && member(i - cols) && levelish(i - cols);
        levelish(i) || from_below
    };
    let noisy = sigma >= params.level_steep_min_sigma;
    let kept_points = || {
        p.members
            .iter()
            .filter(|&&i| kept(i))
            .filter_map(|&i| Some((i, grid.points[i].as_ref()?)))
    };
    let mut rows_all = vec![0usize; grid.rows()];
    for (i, _) in kept_points() {
        rows_all[rc.row(i)] += 1;
    }
    // From `level_steep_min_sigma` of noise a wall's line and a floor line can pass for one
    // plane; below it, on two scan lines only they still can, when they are parallel.
    let veto = params.level_steep_veto
        && (noisy || refine::supported_rows(&rows_all, 0.2) < LEVEL_MIN_ROWS_NOISY);
    // The fit with every kept point, and (for the veto) without those on a steep surface.
    let mut all = grid::PlaneAccumulator::default();
    let mut flat = grid::PlaneAccumulator::default();
    let mut rows_flat = vec![0usize; grid.rows()];
    for (i, g) in kept_points() {
        all.add(g);
        if veto && !on_steep(i) {
            flat.add(g);
            rows_flat[rc.row(i)] += 1;
        }
    }
    let min_rows = if noisy { LEVEL_MIN_ROWS_NOISY } else { 2 };
    let usable = |acc: &grid::PlaneAccumulator, per_row: &[usize]| -> Option<PlaneFit> {
        let supported = refine::supported_rows(per_row, 0.2);
        if acc.n < params.min_level_points || supported < min_rows {
            return None;
        }
        acc.fit(sigma)
    };
    let fit_all = usable(&all, &rows_all);
    let steep = if veto { all.n - flat.n } else { 0 };
    // A plane that only the steep points make (a floor line and a wall's line at its foot,
    // coplanar within the noise) is no floor.
    let fit = fit_all?;
    if steep > 0 && usable(&flat, &rows_flat).is_none() && 5 * steep > all.n {
        return None;
    }
    let floorlike = fit.normal.z.abs() > params.wall_cos();
    (floorlike
        && fit.misfit_ratio(sigma) <= params.max_level_misfit
        && refine::opaque(grid, &fit, sigma, params))
    .then_some(fit)
}

/// True when the patch's points rise steeply from scan to scan, as on a wall: in each column
/// with points in two adjacent rows, the range changes by less than `0.7 r de` (on a wall met
/// at a vertical incidence below 35 degrees, `|dr| = r tan(incidence) de`; on a floor met at
/// less than 45 degrees down, `|dr| = r cot(angle) de > r de`); the median over columns
/// decides. It keeps a wall line plus a floor line out of the walls.
pub fn steep(grid: &PoseGrid, p: &Patch) -> bool {
    let cols = grid.cols;
    let member = |i: usize| p.members.binary_search(&i).is_ok();
    let mut ratios: Vec<f64> = p
        .members
        .iter()
        .filter_map(|&i| {
            let (r, c) = (i / cols, i % cols);
            let j = (r + 1) * cols + c;
            if r + 1 >= grid.rows() || !member(j) {
                return None;
            }
            let (a, b) = (grid.points[i].as_ref()?, grid.points[j].as_ref()?);
            let de = (grid.elevation[r + 1] - grid.elevation[r]).abs();
            Some((b.range - a.range).abs() / (0.5 * (a.range + b.range) * de).max(1e-9))
        })
        .collect();
    if ratios.len() < 5 {
        return false;
    }
    let mid = ratios.len() / 2;
    let (_, m, _) = ratios.select_nth_unstable_by(mid, f64::total_cmp);
    *m < 0.7
}

fn grid_rows(est: &LevelEstimate) -> usize {
    est.grid.as_ref().map_or_else(
        || {
            est.patches
                .iter()
                .map(|p| p.row_range.1 + 1)
                .max()
                .unwrap_or(0)
        },
        |g| g.rows(),
    )
}

/// The reported 1-sigma of theta_x and theta_y \[rad\]: the propagated covariance, scaled by
/// `sigma_inflation`.
fn attitude_sigmas(sol: &UpSolution, params: &LevelParams) -> [f64; 2] {
    sol.attitude_sigmas().map(|s| s * params.sigma_inflation)
}

/// The parallel-walls test: up must be pinned down in both tangent directions.
///
/// The eigenvalue-ratio test speaks of walls: with a level plane in the fit, up is pinned in
/// both directions however unequal they are, and only the sigma test applies.
fn acceptable(sol: &UpSolution, params: &LevelParams, with_level: bool) -> Result<(), FailReason> {
    acceptable_within(sol, params, with_level, params.max_sigma_deg)
}

/// [`acceptable`] with the sigma gate at `max_sigma_deg` instead of the parameters' own.
fn acceptable_within(
    sol: &UpSolution,
    params: &LevelParams,
    with_level: bool,
    max_sigma_deg: f64,
) -> Result<(), FailReason> {
    let (lo, hi) = sol.info_eigenvalues;
    if hi.is_nan() || hi <= 0.0 || (!with_level && lo < params.parallel_ratio * hi) {
        return Err(FailReason::ParallelWalls);
    }
    if !within_wall_angle(&sol.up, params) {
        return Err(FailReason::ParallelWalls);
    }
    let s = attitude_sigmas(sol, params);
    let max_sigma = max_sigma_deg.to_radians();
    if !(s[0] <= max_sigma && s[1] <= max_sigma) {
        return Err(FailReason::ParallelWalls);
    }
    Ok(())
}

/// Whether up lies within `wall_min_angle_deg` of the robot's z axis. Walls, floors and
/// ceilings were told apart by that angle (sect. 5.2: floors slope less than 45 degrees), so an
/// up tilted beyond it contradicts the segmentation it came from: the floor would have been
/// taken for a wall. Re-segmentation from a blind start once settled on a floor and a wall's
/// top as one "wall" and leveled a pose 55 degrees off (361 rays, 10 cm noise).
fn within_wall_angle(up: &Vector3<f64>, params: &LevelParams) -> bool {
    up.z >= params.wall_cos()
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
