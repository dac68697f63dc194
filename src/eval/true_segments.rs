//! The maximum-likelihood core ([`crate::level::ml`]) fed the true segmentation: the simulator's
//! `hit` labels, with each wall hit's plane from the nearest plan wall ([`super::bound`]'s
//! rays). How close it comes to the Cramér-Rao bound, in error and in sigma, is what the core
//! is worth before any segmentation is searched for; the leveler's own gap to it is what
//! finding the surfaces costs. The leveler's last stage fed the same segmentation
//! ([`last_stage_true_segments`]) shows what that stage's own rules cost when the segmentation
//! is right.

use super::bound::{BoundRay, Surface as BoundSurface};
use crate::level::LevelParams;
use crate::level::grid::PoseGrid;
use crate::level::ml::from_segmentation::last_stage;
use crate::level::ml::relabel::Neighbours;
use crate::level::ml::{self, LabelledPoint, MlParams, MlSolution, Surface};
use crate::scan::Scan;
use nalgebra::Vector3;

/// What the core found at one pose: the attitude and its 1-sigmas \[rad\], the inflation
/// its chi-square test applied, and whether it converged.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrueSegmentsFit {
    pub attitude: [f64; 2],
    pub sigmas: [f64; 2],
    pub inflation: f64,
    pub converged: bool,
}

/// The rays as labelled points with range noise `sigma` \[m\] (their measured ranges).
pub(crate) fn labelled_points(rays: &[BoundRay], sigma: f64) -> Vec<LabelledPoint> {
    rays.iter()
        .map(|r| LabelledPoint {
            origin: r.origin,
            dir: r.dir,
            range: r.measured,
            sigma,
            surface: match r.surface {
                BoundSurface::Wall(k) => Surface::Wall(k),
                BoundSurface::Floor => Surface::Floor,
                BoundSurface::Ceiling => Surface::Ceiling,
            },
        })
        .collect()
}

/// Refines up from `start` (robot frame) on the true segmentation; `None` when the surfaces
/// cannot fix the attitude.
pub fn fit_true_segments(
    rays: &[BoundRay],
    sigma: f64,
    start: &Vector3<f64>,
) -> Option<TrueSegmentsFit> {
    let points = labelled_points(rays, sigma);
    let sol = ml::refine(&points, start, &MlParams::default()).ok()?;
    Some(TrueSegmentsFit::of(&sol))
}

impl TrueSegmentsFit {
    fn of(sol: &MlSolution) -> Self {
        TrueSegmentsFit {
            attitude: sol.attitude,
            sigmas: sol.sigmas(),
            inflation: sol.inflation,
            converged: sol.converged,
        }
    }
}

/// The leveler's last stage (`ml::from_segmentation::last_stage`: the core's fit, relabelled
/// and refitted, widened by its rival segmentations) on the true segmentation from `start`,
/// before the leveler's gate; `None` when the core refuses or the scans make no grid.
pub fn last_stage_true_segments(
    rays: &[BoundRay],
    scans: &[Scan],
    sigma: f64,
    start: &Vector3<f64>,
    params: &LevelParams,
) -> Option<TrueSegmentsFit> {
    let (points, neighbours) = in_grid(rays, scans, sigma, params.ml.relabel_window)?;
    let labels: Vec<Option<Surface>> = points.iter().map(|p| Some(p.surface)).collect();
    let sol = last_stage(&points, &neighbours, &labels, start, sigma, params)?;
    Some(TrueSegmentsFit::of(&sol))
}

/// The rays as labelled points (range noise `sigma`) in the leveler's own grid
/// ([`PoseGrid::from_scans`]: rows by ascending elevation, the rays' indices as columns), in
/// its row-major order, with their neighbourhoods within `window` bearings; `None` when the
/// scans make no grid.
pub(crate) fn in_grid(
    rays: &[BoundRay],
    scans: &[Scan],
    sigma: f64,
    window: usize,
) -> Option<(Vec<LabelledPoint>, Neighbours)> {
    let grid = PoseGrid::from_scans(scans).ok()?;
    let mut row_of = vec![None; scans.len()];
    for (row, &k) in grid.scan_index.iter().enumerate() {
        row_of[k] = Some(row);
    }
    // Each ray with its grid index, in the grid's order.
    let mut placed: Vec<(usize, BoundRay)> = rays
        .iter()
        .filter_map(|r| Some((row_of[r.scan]? * grid.cols + r.col, *r)))
        .collect();
    placed.sort_by_key(|&(cell, _)| cell);
    let (index, rays): (Vec<usize>, Vec<BoundRay>) = placed.into_iter().unzip();
    let neighbours = Neighbours::new(index, grid.points.len(), grid.cols, window);
    Some((labelled_points(&rays, sigma), neighbours))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::bound::{WallPlanes, pose_rays};
    use crate::eval::test_scenes::tilted_room_scans;
    use crate::geometry::Pose;
    use crate::simulate::World;

    const DEG: f64 = std::f64::consts::PI / 180.0;

    /// A tilted pose in a 6 x 4 m room with a low ceiling: its scans at `noise`, and their
    /// true rays.
    fn pose_scans(noise: f64, seed: u64) -> (Pose, Vec<Scan>, World, WallPlanes) {
        tilted_room_scans(0.8, (9.0 * DEG, -6.0 * DEG), noise, seed)
    }

    fn start_off(truth: &Pose, by: f64) -> Vector3<f64> {
        crate::geometry::Attitude::new(truth.rx + by, truth.ry - by).up_in_robot()
    }

    /// Noise-free, from 3 degrees off: the relabelled fit is the truth (within a hundredth of
    /// its sigma: the stage stops a thousandth of a sigma from its optimum), and the rival (the
    /// fit before relabelling) lies on it, so nothing widens its sigmas: they are the core's
    /// on every point, a little looser for the points relabelling leaves out (floor points a
    /// wall stands over, grazing rays), never tighter.
    #[test]
    fn last_stage_on_noise_free_truth_is_exact() {
        let (truth, scans, world, planes) = pose_scans(0.0, 1);
        let rays = pose_rays(&world, &planes, &scans, &truth, 30.0);
        let params = LevelParams::default();
        let start = start_off(&truth, 3.0 * DEG);
        let fit = last_stage_true_segments(&rays, &scans, 0.01, &start, &params).unwrap();
        assert!(
            (fit.attitude[0] - truth.rx).abs() < 0.01 * fit.sigmas[0],
            "{fit:?}"
        );
        assert!(
            (fit.attitude[1] - truth.ry).abs() < 0.01 * fit.sigmas[1],
            "{fit:?}"
        );
        let core = fit_true_segments(&rays, 0.01, &start).unwrap();
        for (a, b) in fit.sigmas.iter().zip(core.sigmas) {
            assert!(
                *a >= b * (1.0 - 1e-9) && *a < 1.1 * b,
                "{fit:?} against {core:?}"
            );
        }
    }

    /// The grid is built by elevation, whatever order the scans come in: shuffled scans (no
    /// two neighbours in elevation next to each other) give the same fit to the bit; and at
    /// 5 cm the stage lands within three sigmas of the truth.
    #[test]
    fn last_stage_grid_follows_elevation_not_scan_order() {
        let (truth, scans, world, planes) = pose_scans(0.05, 7);
        let params = LevelParams::default();
        let start = start_off(&truth, 1.0 * DEG);
        let fit_of = |scans: &[Scan]| {
            let rays = pose_rays(&world, &planes, scans, &truth, 30.0);
            last_stage_true_segments(&rays, scans, 0.05, &start, &params).unwrap()
        };
        let ascending = fit_of(&scans);
        let shuffled: Vec<Scan> = [2, 0, 3, 1].iter().map(|&k| scans[k].clone()).collect();
        assert_eq!(fit_of(&shuffled), ascending);
        let errors = [
            ascending.attitude[0] - truth.rx,
            ascending.attitude[1] - truth.ry,
        ];
        for (e, s) in errors.iter().zip(ascending.sigmas) {
            assert!(e.abs() < 3.0 * s, "{ascending:?}");
        }
    }
}
