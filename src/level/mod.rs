//! Level estimation (paper sect. 5): wall polygons, the up vector, attitude and failure detection.
//!
//! [`level_pose`] is the whole stage as one pure function: the scans of one pose in, a
//! [`LevelEstimate`] out. Its steps follow the paper's subsections:
//! - [`grid`]: data collection (5.1), plus bias-corrected plane fits;
//! - [`noise`]: the range noise, estimated from the data when not given;
//! - [`polygons`]: the paper's quads (5.2);
//! - [`patches`]: quads merged into whole-wall patches by region growing (after sect. 9);
//! - [`up`]: the up vector (5.3), the paper's estimator and a robust least-squares one;
//! - [`attitude`]: roll and pitch from up, with their uncertainty (5.4);
//! - [`first_pass`]: up from the first segmentation, with failure detection (5.5) in
//!   [`failure`];
//! - [`refine`] and [`resegment`]: re-segmentation in the provisional level frame (after
//!   sect. 9), its engine and its driver.
//!
//! Every parameter and fixed constant sits in `params` (per stage, with unit, default and why),
//! and every accept/reject rule in one table, [`checks`].

mod adopt;
mod attitude;
#[cfg(test)]
mod check_tests;
pub mod checks;
pub(crate) mod eigen3;
mod failure;
mod first_pass;
pub mod grid;
pub(crate) mod ml;
pub(crate) mod noise;
mod params;
pub mod patches;
pub(crate) mod polygons;
pub mod refine;
mod resegment;
pub(crate) mod up;

pub use failure::FailCause;
pub use first_pass::level_fits;
pub use ml::MlParams;
pub use noise::believed_range_sigma;
pub use params::LevelParams;
pub use resegment::{Resegmented, refine_estimate};

use crate::geometry::Attitude;
use crate::scan::Scan;
pub use grid::BearingTrigCache;
use grid::PoseGrid;
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

/// Its command-line spelling (`paper`, `robust`).
impl fmt::Display for Estimator {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let value = clap::ValueEnum::to_possible_value(self).expect("no variant is skipped");
        f.write_str(value.get_name())
    }
}

/// What a plane is, judged by its normal against the robot's up (sect. 5.2).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SurfaceKind {
    Wall,
    Floor,
    Ceiling,
}

/// Why a pose could not be leveled (the contract's reasons; [`FailCause`] tells the causes
/// apart).
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

/// Where a pose's range noise came from ([`LevelEstimate::range_sigma`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum NoiseSource {
    /// Estimated from the ranges: the scans state none.
    #[default]
    Estimated,
    /// `LevelParams::sigma` (`--sigma`).
    Given,
    /// The scans' `readings_sigma`, borne out by their ranges.
    Stated,
    /// Estimated from the ranges, which contradict the `readings_sigma` the scans state (more
    /// than a factor of 3 off their scatter: a converter's placeholder).
    SetAside,
}

/// The result of leveling one pose.
#[derive(Clone, Debug, Default)]
pub struct LevelEstimate {
    /// `None` when leveled, else why not (the contract's reason, `cause`'s).
    pub failure: Option<FailReason>,
    /// `None` when leveled, else the cause within the reason ([`FailCause::reason`]).
    pub cause: Option<FailCause>,
    /// The attitude (theta_x, theta_y) \[rad\]; `None` on failure.
    pub attitude: Option<Attitude>,
    /// 1-sigma of theta_x and theta_y \[rad\]; `None` on failure.
    pub sigmas: Option<[f64; 2]>,
    /// The up vector in the robot frame; `None` on failure.
    pub up: Option<Vector3<f64>>,
    /// The range noise used \[m\].
    pub range_sigma: f64,
    /// Where `range_sigma` came from. With [`NoiseSource::Stated`] the last stage weighs each
    /// ray by its own `readings_sigma`.
    pub noise_source: NoiseSource,
    /// The grid of robot-frame points (absent when the scans could not form one).
    pub grid: Option<PoseGrid>,
    /// All coplanar quads, walls, floors and ceilings (see `kind`).
    pub quads: Vec<Polygon>,
    /// Grown patches (all kinds); the refined segmentation's models instead when the attitude
    /// comes from re-segmentation.
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
        let walls = self.wall_polygons();
        let (floors, ceilings) = (count(SurfaceKind::Floor), count(SurfaceKind::Ceiling));
        if floors > walls && floors >= ceilings {
            Some(FailReason::FacingFloor)
        } else if ceilings > walls {
            Some(FailReason::FacingCeiling)
        } else {
            None
        }
    }

    /// An estimate of no grid and no solution yet, at range noise `range_sigma`.
    fn empty(range_sigma: f64) -> Self {
        LevelEstimate {
            range_sigma,
            ..LevelEstimate::default()
        }
    }

    fn failed(cause: FailCause, range_sigma: f64) -> Self {
        let mut est = Self::empty(range_sigma);
        est.fail(cause);
        est
    }

    /// Marks the estimate failed by `cause`, with its contract reason.
    fn fail(&mut self, cause: FailCause) {
        self.cause = Some(cause);
        self.failure = Some(cause.reason());
    }
}

/// The range noise for a pose: `params.sigma`, else the median of the scans' `readings_sigma`
/// when the data bear it out ([`noise::stated_is_believable`]), else estimated from the data
/// ([`noise::estimate_range_sigma_with`]), else
/// `params.min_sigma`; given the `(sin, cos)` of the bearings when every scan shares them.
fn range_sigma_with(
    scans: &[Scan],
    params: &LevelParams,
    trig: Option<&[(f64, f64)]>,
) -> (f64, NoiseSource) {
    if let Some(s) = params.sigma {
        return (s, NoiseSource::Given);
    }
    // The given sigmas' median; when they grow with range, the farther half's
    // (`noise::far_if_noisier`).
    let (mut given, mut ranged, mut ranges) = (Vec::new(), Vec::new(), Vec::new());
    for s in scans {
        for (i, v) in s.readings_sigma.iter().flatten().enumerate() {
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
    let scatter = noise::estimate_range_sigma_with(scans, trig);
    if !given.is_empty() {
        let halves = noise::split_at_median_range(&ranged, &ranges)
            .map(|(mut near, mut far)| (median_of(&mut near), median_of(&mut far)));
        let stated = noise::far_if_noisier(median_of(&mut given), halves);
        // A stated noise the ranges contradict is a placeholder (a converter's 1 m): the
        // data's own estimate stands instead.
        if noise::stated_is_believable(stated, scatter) {
            return (stated, NoiseSource::Stated);
        }
        return (scatter.unwrap_or(params.min_sigma), NoiseSource::SetAside);
    }
    (scatter.unwrap_or(params.min_sigma), NoiseSource::Estimated)
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
    let (sigma, noise_source) = range_sigma_with(scans, params, trig.as_deref());
    let grid = match PoseGrid::from_scans_with(scans, trig.as_deref()) {
        Ok(g) => g,
        Err(cause) => {
            return LevelEstimate {
                noise_source,
                ..LevelEstimate::failed(cause, sigma)
            };
        }
    };
    // The paper's quads (sect. 5.2), grown into whole-wall patches (robust estimator).
    let mut est = segmented(grid, params, sigma, trig);
    est.noise_source = noise_source;
    // Up from walls and level surfaces, and failure detection (sect. 5.3-5.5).
    let levels = first_pass::level_fits(&est, params);
    let first = first_pass::solve(&est, &levels, params, sigma);
    // Re-segmentation in the provisional level frame (after sect. 9), gated again.
    let (result, refined) = resegment::resegmented(&est, &levels, first, params);
    // The stages after it take the segmentation that produced the attitude.
    if let Some(models) = refined {
        adopt::adopt_refined(&mut est, models);
    }
    // The wall points and base scan of the pseudo-level scan (sect. 6), then the attitude.
    if let Some(grid) = &est.grid {
        est.wall_mask = wall_mask_where(grid, &est, |_| true);
        est.base_scan = Some(base_scan(grid, &est.wall_mask));
    }
    // The attitude, refined by maximum likelihood on that segmentation.
    ml::from_segmentation::finish(&mut est, scans, result, params);
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
    let quads = polygons::extract_quads(&grid, params, sigma, params.quad_cols);
    let (patches, labels) = match params.estimator {
        Estimator::Robust => patches::grow_patches(&grid, &quads, params, sigma),
        Estimator::Paper => (Vec::new(), vec![UNLABELLED; grid.points.len()]),
    };
    LevelEstimate {
        quads,
        patches,
        labels,
        grid: Some(grid),
        bearing_trig: trig,
        ..LevelEstimate::empty(sigma)
    }
}

/// Per grid point, whether it lies on a wall: inside the span of a wall quad that `quad_counts`
/// accepts (the pseudo-level scan's keep test takes only those vertical once leveled) or in a
/// wall patch (of the segmentation that produced the attitude, sect. 6).
pub(crate) fn wall_mask_where(
    grid: &PoseGrid,
    est: &LevelEstimate,
    quad_counts: impl Fn(&Polygon) -> bool,
) -> Vec<bool> {
    let mut wall_mask = vec![false; grid.points.len()];
    // A quad's span row by row (`Polygon::span`'s indices): overlapping quads mark most
    // points several times, cheaply as slices.
    for q in est
        .quads
        .iter()
        .filter(|q| q.kind == SurfaceKind::Wall && quad_counts(q))
    {
        for r in q.row..q.row + q.rows {
            let start = r * grid.cols + q.col;
            wall_mask[start..start + q.cols].fill(true);
        }
    }
    for (mask, &l) in wall_mask.iter_mut().zip(&est.labels) {
        *mask |= l != UNLABELLED && est.patches[l as usize].kind == SurfaceKind::Wall;
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

/// The upper median of `v` (element `len / 2` in `f64::total_cmp` order), reordering `v`.
/// `v` must not be empty.
pub(crate) fn median_of(v: &mut [f64]) -> f64 {
    let mid = v.len() / 2;
    *v.select_nth_unstable_by(mid, f64::total_cmp).1
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

    /// The estimators print as they are spelled on the command line (the accuracy tables'
    /// `estimator` column).
    #[test]
    fn estimators_print_their_command_line_names() {
        assert_eq!(Estimator::Paper.to_string(), "paper");
        assert_eq!(Estimator::Robust.to_string(), "robust");
    }

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
            Err(FailCause::BeyondWallAngle)
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
