//! Re-segmentation in the provisional level frame: EM-style plane fitting (the paper's sect. 9
//! points to Thrun et al. 2004, "Learning compact 3D models of indoor and outdoor environments
//! with a mobile robot", which alternates assigning points to planes and refitting them).
//!
//! Region growing over the scan grid (`patches`) works in the robot frame at a tolerance that
//! follows the range noise: at 10 cm noise that is 30 cm, and patches run across a wall's foot or
//! a corner. Once a first up exists (even one the sigma gate rejects), segmenting is easier in the
//! provisional level frame: the floor lies at one height, the ceiling at another, and every wall
//! is a vertical plane, a 2D line onto which the points of all scans pile. Each pass
//! 1. levels every point with the current up;
//! 2. assigns points to the floor and the ceiling by their distance from those planes, and the
//!    others to walls by their horizontal distance from each wall's vertical plane; a point in
//!    reach of two models (a corner, a wall's foot or top) is left out;
//! 3. refits each model's plane from its points (bias-corrected TLS,
//!    [`PlaneAccumulator`](super::grid::PlaneAccumulator)) and re-estimates up from them with the
//!    robust estimator ([`up::up_robust`]), whose information matrix gives the sigmas;
//!
//! until up moves by a small fraction of its uncertainty (one pass by default: more did not
//! measurably help). The walls' planes are refitted free (not forced vertical): their tilt
//! is the evidence of up; verticality only steers which points they get.

use super::checks::{self, clear_of_scanner};
use super::grid::{GridPoint, PlaneFit, PoseGrid};
use super::up::{self, LevelLine, PlaneObs, UpSolution};
use super::{LevelParams, SurfaceKind};
use crate::geometry::Attitude;
use nalgebra::{Matrix2, Point3, Rotation3, Vector2, Vector3};

mod floor;
pub(crate) mod lines;
mod ransac;
mod steps;
mod support;
mod sweep;
#[cfg(test)]
mod tests;
mod walls;

use crate::level::params::refine::*;
pub(crate) use floor::opaque;
use floor::*;
pub(crate) use lines::start_lines;
use lines::*;
pub use ransac::level_start;
use ransac::*;
use steps::*;
pub use steps::{LevelSteps, level_steps};
pub(crate) use steps::{row_pairs, row_steps};
pub(crate) use support::supported_rows;
use support::*;
pub(crate) use sweep::swept_start;
use walls::*;

/// One model of the refined segmentation: a plane and the grid points assigned to it.
#[derive(Clone, Debug)]
pub struct Model {
    pub kind: SurfaceKind,
    /// The plane in the robot frame, fitted free from `members`.
    pub fit: PlaneFit,
    /// Grid indices of its points, ascending.
    pub members: Vec<usize>,
}

impl Model {
    /// The model as evidence on up, its noise inflated by its misfit (floors and ceilings
    /// by `refine_level_inflation` more), for effective range noise `s`.
    fn obs(&self, s: f64, params: &LevelParams) -> PlaneObs<'_> {
        let misfit = self.fit.misfit_ratio(s).max(1.0);
        if self.kind == SurfaceKind::Wall {
            PlaneObs::wall(&self.fit, misfit)
        } else {
            PlaneObs::level(&self.fit, misfit * params.refine_level_inflation)
        }
    }
}

/// The refined segmentation and the up vector it gives.
#[derive(Clone, Debug)]
pub struct Refined {
    pub solution: UpSolution,
    /// Walls, then the floor and the ceiling when seen.
    pub models: Vec<Model>,
    /// Lines on the floor or ceiling used where no level plane was found
    /// (`level_lines`).
    pub lines: Vec<FlatLine>,
}

/// A scan's run of floor or ceiling points used as a level line.
#[derive(Clone, Copy, Debug)]
pub struct FlatLine {
    pub line: LevelLine,
    /// The surface it lies on: the floor or the ceiling.
    pub kind: SurfaceKind,
}

impl Refined {
    /// Up from the models alone, without the lines (`None` when they do not fix it), for
    /// range noise `sigma` as given to [`refine`].
    pub(crate) fn without_lines(&self, params: &LevelParams, sigma: f64) -> Option<UpSolution> {
        let s = sigma.max(params.min_sigma);
        let obs: Vec<PlaneObs> = self.models.iter().map(|m| m.obs(s, params)).collect();
        up::up_robust(&obs, s, params.iterations)
    }
}

/// A wall as a vertical plane in the level frame: `normal . (x, y) = offset`, with the height
/// of its points' centroid (the pivot of an error in up).
#[derive(Clone, Copy, Debug)]
struct Line {
    normal: Vector2<f64>,
    offset: f64,
    z: f64,
    /// Points behind it (merged lines average by it).
    weight: f64,
}

/// Every valid grid point in the provisional level frame: position and ray direction.
pub(crate) type Leveled = Vec<Option<(Vector3<f64>, Vector3<f64>)>>;

fn leveled(grid: &PoseGrid, level_from_robot: &Rotation3<f64>) -> Leveled {
    let level = |g: &GridPoint| (level_from_robot * g.p.coords, level_from_robot * g.dir);
    grid.points.iter().map(|g| g.as_ref().map(level)).collect()
}

fn line_of(fit: &PlaneFit, level_from_robot: &Rotation3<f64>) -> Option<Line> {
    let n = level_from_robot * fit.normal;
    let normal = Vector2::new(n.x, n.y).try_normalize(1e-9)?;
    let c = level_from_robot * fit.centroid.coords;
    Some(Line {
        normal,
        offset: normal.dot(&Vector2::new(c.x, c.y)),
        z: c.z,
        weight: fit.weight,
    })
}

/// Refines up from a provisional solution by re-segmenting the grid in its level frame.
/// `walls` are the planes of region growing's wall patches (the first walls to assign points
/// to); the floor and ceiling are found afresh. `None` when the refined model does not fix up.
pub(crate) fn refine(
    grid: &PoseGrid,
    start: &UpSolution,
    walls: &[PlaneFit],
    steps: &LevelSteps,
    params: &LevelParams,
    sigma: f64,
) -> Option<Refined> {
    let s = sigma.max(params.min_sigma);
    let mut up = start.up;
    let mut sigma_up = sigma_up_of(start, params);
    // Wall planes to assign from, robot frame.
    let mut wall_fits = walls.to_vec();
    let mut level_fits: Vec<PlaneFit> = Vec::new();
    let mut result: Option<Refined> = None;
    // Walls the region growing missed are looked for as lines in each leveled scan (a small
    // gain: 3 scans at 1 cm mean 0.180 vs 0.185 degrees).
    let seed_width = super::patches::seed_cols(grid, params, s).max(3);
    for pass in 0..params.refine_passes {
        // 1. Every point leveled with the current up.
        let level_from_robot = Attitude::from_up(&up).level_from_robot();
        let f = Frame {
            grid,
            params,
            steps,
            lv: leveled(grid, &level_from_robot),
            level_from_robot,
            up,
            s,
            sigma,
            k: params.refine_k,
            sigma_up,
        };
        let level_ok = flat_points(&f);
        if params.level_surfaces && pass == 0 {
            // The first pass looks for the floor and ceiling afresh in its level frame (the
            // region-grown ones can have run up a wall's foot); later passes carry them and
            // look for nothing new.
            level_fits = find_levels(&f, &level_ok);
        }
        // 2. Points assigned to the floor and ceiling, then to walls; 3. the models refitted.
        let (level_members, near_level) = assign_levels(&f, &level_fits, &level_ok);
        // New walls are looked for once; later passes carry them as models.
        let (walls, wall_members) =
            assign_walls(&f, &wall_fits, &near_level, pass == 0, seed_width);
        let (mut models, walls_found) = models_of(&f, wall_members, &level_fits, level_members);
        let flat_lines = level_line_evidence(&f, &walls, &mut models);
        let (sol, flat_lines) = solve_models(&f, &models, flat_lines)?;
        let change = sol.up.angle(&up);
        up = sol.up;
        sigma_up = sigma_up_of(&sol, params);
        wall_fits = models[..walls_found].iter().map(|m| m.fit).collect();
        level_fits = models[walls_found..].iter().map(|m| m.fit).collect();
        result = Some(Refined {
            solution: sol,
            models,
            lines: flat_lines,
        });
        // Converged when up moved by a small fraction of its own uncertainty.
        if change < CONVERGED * sigma_up {
            break;
        }
    }
    result
}

/// One pass's provisional level frame and the tolerances of assigning points in it.
pub(crate) struct Frame<'a> {
    grid: &'a PoseGrid,
    params: &'a LevelParams,
    steps: &'a LevelSteps,
    lv: Leveled,
    level_from_robot: Rotation3<f64>,
    up: Vector3<f64>,
    /// Effective range noise (floored at `min_sigma`) \[m\].
    s: f64,
    /// The range noise as given, for the plane fits \[m\].
    sigma: f64,
    /// `refine_k`.
    k: f64,
    /// Up's uncertainty \[rad\].
    sigma_up: f64,
}

impl Frame<'_> {
    /// Squared distance of a leveled point `q` (ray direction `d`) from a wall's vertical
    /// plane, in variances: its range noise along the wall's normal, and the error in up
    /// (`sigma_up`) at its height above the wall's pivot; `None` when beyond `k` sigmas.
    fn line_z2(&self, l: &Line, q: &Vector3<f64>, d: &Vector3<f64>) -> Option<f64> {
        let (s, min_sigma, k2) = (self.s, self.params.min_sigma, self.k * self.k);
        let dist = l.normal.x * q.x + l.normal.y * q.y - l.offset;
        let along = l.normal.x * d.x + l.normal.y * d.y;
        let lever = (q.z - l.z) * self.sigma_up;
        let (num, den) = (
            dist * dist,
            s * s * along * along + min_sigma * min_sigma + lever * lever,
        );
        // Most lines are far from a point: tell so without the division when the margin is
        // clear (a relative 1e-12 dwarfs the division's rounding, so the answer is the
        // division's).
        if num > k2 * den * (1.0 + 1e-12) {
            return None;
        }
        let z = num / den;
        (z.is_nan() || z <= k2).then_some(z)
    }
}

/// The floor's and ceiling's members (points in reach of one level model only, and flat to a
/// neighbour), and the band around them that walls may not take.
fn assign_levels(
    f: &Frame,
    level_fits: &[PlaneFit],
    level_ok: &[bool],
) -> (Vec<Vec<usize>>, Vec<bool>) {
    let (grid, params, lv, up, s, k) = (f.grid, f.params, &f.lv, f.up, f.s, f.k);
    let mut level_members: Vec<Vec<usize>> = vec![Vec::new(); level_fits.len()];
    let mut near_level = vec![false; grid.points.len()];
    let level_models: Vec<LevelModel> = level_fits.iter().map(|l| LevelModel::new(l, s)).collect();
    for (i, g) in grid.points.iter().enumerate() {
        let Some(g) = g else { continue };
        let (mut reach, mut which) = (0, 0);
        for (m, model) in level_models.iter().enumerate() {
            let (d, sd) = model.distance_sd(g, s, params.min_sigma);
            if d <= k * sd {
                reach += 1;
                which = m;
            }
            if d <= k * sd + params.flat_margin {
                near_level[i] = true;
            }
        }
        if reach == 1 && level_ok[i] {
            level_members[which].push(i);
        }
    }
    // Without a floor model, the lowest points seen stand for the floor: the band above
    // them holds a wall's foot and the floor just in front of it, which no vertical plane
    // tells apart at high noise. If no floor is in view, this only trims the lowest wall
    // points. Likewise the highest points stand for a ceiling without a model, when a few of
    // them step from scan to scan as a ceiling does: the band below them holds a wall's top
    // and the ceiling just beyond it (traced at 1 cm: a wall's plane through that corner, 7
    // degrees off vertical, leveled a pose 7 degrees off with a sigma of 1.4). Without such
    // steps the highest points are the tops of walls, which keep them.
    for (lowest, side) in [(true, -1.0), (false, 1.0)] {
        let modelled = level_fits
            .iter()
            .any(|l| l.centroid.coords.dot(&up) * side > 0.0);
        let Some(height) = (!modelled).then(|| extreme_height(lv, lowest)).flatten() else {
            continue;
        };
        let band = level_band(f, height, lowest);
        if lowest || steps_as_ceiling(band.clone(), &f.steps.ceiling) {
            band.for_each(|i| near_level[i] = true);
        }
    }
    (level_members, near_level)
}

/// [`Check::CeilingBandSteps`](checks::Check::CeilingBandSteps): whether the highest points
/// `band` stand for a ceiling: `CEILING_BAND_MIN_STEPS` of them step as a ceiling does
/// (`ceiling`, per grid point).
pub(crate) fn steps_as_ceiling(band: impl Iterator<Item = usize>, ceiling: &[bool]) -> bool {
    band.filter(|&i| ceiling[i]).count() >= CEILING_BAND_MIN_STEPS
}

/// Points assigned to walls: the walls' lines (`wall_fits` in this frame, merged, and with
/// `discover` the lines found in each leveled scan), the wall candidates (not near a level
/// surface, not stepping like one); with each line's members.
struct WallAssignment {
    lines: Vec<Line>,
    candidate: Vec<bool>,
    /// Candidates within reach of a line (the floor and ceiling lines keep off them).
    in_reach: Vec<bool>,
}

fn assign_walls(
    f: &Frame,
    wall_fits: &[PlaneFit],
    near_level: &[bool],
    discover: bool,
    seed_width: usize,
) -> (WallAssignment, Vec<Vec<usize>>) {
    let (grid, lv) = (f.grid, &f.lv);
    // Walls: merge those that are one wall, then assign by horizontal distance.
    let mut lines: Vec<Line> = wall_fits
        .iter()
        .filter_map(|w| line_of(w, &f.level_from_robot))
        .collect();
    let candidate: Vec<bool> = (0..grid.points.len())
        .map(|i| lv[i].is_some() && !near_level[i] && !f.steps.levelish[i])
        .collect();
    if discover {
        lines.extend(discover_lines(f, &candidate, seed_width));
    }
    merge_lines(&mut lines, f.params, f.s);
    let cos_similar = SIMILAR_LINES_DEG.to_radians().cos();
    let mut wall_members: Vec<Vec<usize>> = vec![Vec::new(); lines.len()];
    // Candidates within reach of a line (the floor and ceiling lines below keep off them).
    let mut in_reach = vec![false; grid.points.len()];
    for (i, q) in lv.iter().enumerate() {
        let Some((q, d)) = q else { continue };
        if !candidate[i] {
            continue;
        }
        // The nearest line in sigmas, and the runner-up within reach.
        let mut best: Option<(f64, usize)> = None;
        let mut second: Option<(f64, usize)> = None;
        for (m, l) in lines.iter().enumerate() {
            let Some(z) = f.line_z2(l, q, d) else {
                continue;
            };
            if best.is_none_or(|b| z < b.0) {
                second = best;
                best = Some((z, m));
            } else if second.is_none_or(|b| z < b.0) {
                second = Some((z, m));
            }
        }
        let Some((_, m)) = best else { continue };
        in_reach[i] = true;
        // In reach of two walls that meet (a corner): no one's point. Two nearly parallel
        // lines in reach are one wall's pieces left unmerged: the nearer takes it.
        if second.is_some_and(|(_, o)| lines[m].normal.dot(&lines[o].normal).abs() < cos_similar) {
            continue;
        }
        wall_members[m].push(i);
    }
    let walls = WallAssignment {
        lines,
        candidate,
        in_reach,
    };
    (walls, wall_members)
}

/// The refitted models: walls that span `refine_min_rows` scans and stay walls, then the
/// floor and ceiling that pass the level checks; with the count of walls.
fn models_of(
    f: &Frame,
    wall_members: Vec<Vec<usize>>,
    level_fits: &[PlaneFit],
    level_members: Vec<Vec<usize>>,
) -> (Vec<Model>, usize) {
    let (grid, params, up, s, sigma, k, sigma_up) =
        (f.grid, f.params, f.up, f.s, f.sigma, f.k, f.sigma_up);
    let wall = |members: Vec<usize>| {
        let fit = spans_wall_rows(grid, &members, params)
            .then(|| grid.accumulate(&members).fit(sigma))
            .flatten()?;
        // A wall must stay a wall; what turned towards up was floor after all.
        let kind = SurfaceKind::Wall;
        (fit.normal.dot(&up).abs() <= params.wall_cos()).then_some(Model { kind, fit, members })
    };
    let mut models: Vec<Model> = wall_members.into_iter().filter_map(wall).collect();
    let walls_found = models.len();
    let level = |(f, members): (&PlaneFit, Vec<usize>)| {
        let members = without_standing_rows(grid, members, s, params);
        let fit = supported_level_fit(grid, &members, params, sigma)?;
        let kind = if f.centroid.coords.dot(&up) < 0.0 {
            SurfaceKind::Floor
        } else {
            SurfaceKind::Ceiling
        };
        let stands = checks::refined_level(&fit, &up, s, params)
            // Over two scans it must agree with up (one leveled a pose 7 degrees off
            // with a sigma of 0.1); over three, it may overrule a wrong start.
            && (three_rows_support(grid, &members) || level_z2(&fit, &up, s, sigma_up) <= k * k)
            && opaque(grid, &fit, s, params);
        stands.then_some(Model { kind, fit, members })
    };
    models.extend(level_fits.iter().zip(level_members).filter_map(level));
    (models, walls_found)
}

/// [`Check::RefinedWallRows`](checks::Check::RefinedWallRows): whether a re-segmented wall's
/// `members` are a wall: `min_patch_points` of them, with `WALL_ROW_SHARE` of them in each of
/// `refine_min_rows` scans (at least two).
pub(crate) fn spans_wall_rows(grid: &PoseGrid, members: &[usize], params: &LevelParams) -> bool {
    members.len() >= params.min_patch_points
        && rows_supported(grid, members, WALL_ROW_SHARE) >= params.refine_min_rows.max(2)
}

/// Floor and ceiling lines where no level model was found (`level_lines`): each added to
/// `models` when several scans' lines make one plane, else returned as lines.
fn level_line_evidence(
    f: &Frame,
    walls: &WallAssignment,
    models: &mut Vec<Model>,
) -> Vec<FlatLine> {
    let (grid, params, steps, lv) = (f.grid, f.params, f.steps, &f.lv);
    let (lines, candidate, in_reach) = (&walls.lines, &walls.candidate, &walls.in_reach);
    let mut flat_lines: Vec<FlatLine> = Vec::new();
    if params.level_surfaces && params.level_lines {
        // Points of a model, or within reach of a wall's vertical plane (a wall line near
        // its foot lies at the floor's height within the provisional frame's tolerance).
        let mut taken = vec![false; grid.points.len()];
        for &i in models.iter().flat_map(|m| &m.members) {
            taken[i] = true;
        }
        for (i, q) in lv.iter().enumerate() {
            let Some((q, d)) = q else { continue };
            if taken[i] {
                continue;
            }
            // Candidates were tried against every line above.
            taken[i] = if candidate[i] {
                in_reach[i]
            } else {
                lines.iter().any(|l| f.line_z2(l, q, d).is_some())
            };
        }
        let floor = (SurfaceKind::Floor, &steps.floor_line);
        for (kind, levelish) in [floor, (SurfaceKind::Ceiling, &steps.ceiling)] {
            if models.iter().any(|m| m.kind == kind) {
                continue;
            }
            match level_lines(f, kind, |i| levelish[i] && !taken[i]) {
                LevelEvidence::None => {}
                LevelEvidence::Lines(found) => {
                    flat_lines.extend(found.into_iter().map(|line| FlatLine { line, kind }))
                }
                LevelEvidence::Plane(fit, members) => models.push(Model { kind, fit, members }),
            }
        }
    }
    flat_lines
}

/// Up from the models and the level lines; without the lines when they leave no up.
fn solve_models(
    f: &Frame,
    models: &[Model],
    mut flat_lines: Vec<FlatLine>,
) -> Option<(UpSolution, Vec<FlatLine>)> {
    let (s, params, inflate) = (f.s, f.params, f.params.level_line_inflation);
    let obs: Vec<PlaneObs> = models
        .iter()
        .map(|m| m.obs(s, params))
        .chain(
            flat_lines
                .iter()
                .map(|l| PlaneObs::level_line(&l.line, inflate)),
        )
        .collect();
    // Lines that are no one floor and one ceiling under the up they give were wrong too
    // (`Check::LinesAtOneHeight`).
    let joint = up::up_robust(&obs, s, params.iterations)
        .filter(|sol| lines_at_one_height(&flat_lines, sol, s, params));
    let sol = match joint {
        Some(sol) => sol,
        // Lines that leave no up within reach were wrong: the models stand alone.
        None if !flat_lines.is_empty() => {
            let sol = up::up_robust(&obs[..models.len()], s, params.iterations)?;
            flat_lines.clear();
            sol
        }
        None => return None,
    };
    Some((sol, flat_lines))
}

/// Up's uncertainty for assigning points \[rad\]: `sol`'s larger attitude sigma, within
/// `refine_min_sigma_deg` and `MAX_SIGMA_UP` (an undetermined sigma is infinite, not NaN).
fn sigma_up_of(sol: &UpSolution, params: &LevelParams) -> f64 {
    sol.max_attitude_sigma()
        .clamp(params.refine_min_sigma_deg.to_radians(), MAX_SIGMA_UP)
}
