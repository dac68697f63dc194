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

use super::grid::{GridPoint, PlaneFit, PoseGrid};
use super::patches::Patch;
use super::up::{self, LevelLine, PlaneObs, UpSolution};
use super::{LevelParams, SurfaceKind};
use crate::geometry::Attitude;
use nalgebra::{Matrix2, Point3, Rotation3, Vector2, Vector3};

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
    pub lines: Vec<LevelLine>,
}

impl Refined {
    /// Up from the models alone, without the lines (`None` when they do not fix it), for
    /// range noise `sigma` as given to [`refine`].
    pub fn without_lines(&self, params: &LevelParams, sigma: f64) -> Option<UpSolution> {
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
struct Leveled {
    q: Vec<Option<(Vector3<f64>, Vector3<f64>)>>,
}

impl Leveled {
    fn new(grid: &PoseGrid, level_from_robot: &Rotation3<f64>) -> Self {
        Leveled {
            q: grid
                .points
                .iter()
                .map(|g| {
                    g.as_ref()
                        .map(|g| (level_from_robot * g.p.coords, level_from_robot * g.dir))
                })
                .collect(),
        }
    }
}

/// Squared distance of a leveled point `q` (ray direction `d`) from a wall's vertical plane,
/// in variances: its range noise along the wall's normal, and the error in up
/// (`sigma_up` \[rad\]) at its height above the wall's pivot; `None` when it exceeds `k2`.
fn line_z2(
    l: &Line,
    q: &Vector3<f64>,
    d: &Vector3<f64>,
    s: f64,
    min_sigma: f64,
    sigma_up: f64,
    k2: f64,
) -> Option<f64> {
    let dist = l.normal.x * q.x + l.normal.y * q.y - l.offset;
    let along = l.normal.x * d.x + l.normal.y * d.y;
    let lever = (q.z - l.z) * sigma_up;
    let (num, den) = (
        dist * dist,
        s * s * along * along + min_sigma * min_sigma + lever * lever,
    );
    // Most lines are far from a point: tell so without the division when the margin is clear
    // (a relative 1e-12 dwarfs the division's rounding, so the answer is the division's).
    if num > k2 * den * (1.0 + 1e-12) {
        return None;
    }
    let z = num / den;
    (z.is_nan() || z <= k2).then_some(z)
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
/// `walls` are the wall patches of region growing (the first walls to assign points to); the
/// floor and ceiling are found afresh. `None` when the refined model does not fix up.
pub fn refine(
    grid: &PoseGrid,
    start: &UpSolution,
    walls: &[&Patch],
    steps: &LevelSteps,
    params: &LevelParams,
    sigma: f64,
) -> Option<Refined> {
    let s = sigma.max(params.min_sigma);
    let k = params.refine_k;
    let mut up = start.up;
    let mut sigma_up = start_sigma(start, params);
    // Wall planes to assign from, robot frame.
    let mut wall_fits: Vec<PlaneFit> = walls.iter().map(|p| p.fit).collect();
    let mut level_fits: Vec<PlaneFit> = Vec::new();
    let levelish = &steps.levelish;
    let mut result: Option<Refined> = None;
    let seed_width = if params.refine_discover {
        super::patches::seed_cols(grid, params, s).max(3)
    } else {
        0
    };
    for pass in 0..params.refine_passes {
        let level_from_robot = Attitude::from_up(&up).level_from_robot();
        let lv = Leveled::new(grid, &level_from_robot);
        let level_ok = flat_points(grid, &lv, s, params.min_sigma, sigma_up, k);
        if params.level_surfaces {
            // The first pass looks for the floor and ceiling in its level frame (the region-grown
            // ones can have run up a wall's foot); later passes start from what it found.
            let fresh = pass == 0;
            level_fits = find_levels(
                grid,
                &lv,
                &level_ok,
                levelish,
                &level_fits,
                fresh,
                &up,
                params,
                s,
                sigma_up,
            );
        }
        // Floor and ceiling members, and the band around them that walls may not take.
        let mut level_members: Vec<Vec<usize>> = vec![Vec::new(); level_fits.len()];
        let mut near_level = vec![false; grid.points.len()];
        let level_models: Vec<LevelModel> =
            level_fits.iter().map(|f| LevelModel::new(f, s)).collect();
        for (i, g) in grid.points.iter().enumerate() {
            let Some(g) = g else { continue };
            let mut reach = 0;
            let mut which = 0;
            for (m, f) in level_models.iter().enumerate() {
                let (d, sd) = f.distance_sd(g, s, params.min_sigma);
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
        // points.
        if !level_fits.iter().any(|f| f.centroid.coords.dot(&up) < 0.0) {
            if let Some(low) = extreme_height(&lv, true) {
                for i in level_band(&lv, low, true, sigma_up, k, s, params) {
                    near_level[i] = true;
                }
            }
        }
        // Likewise the highest points stand for a ceiling without a model, when a few of them
        // step from scan to scan as a ceiling does: the band below them holds a wall's top and
        // the ceiling just beyond it (traced at 1 cm: a wall's plane through that corner, 7
        // degrees off vertical, leveled a pose 7 degrees off with a sigma of 1.4). Without such
        // steps the highest points are the tops of walls, which keep them.
        if !level_fits.iter().any(|f| f.centroid.coords.dot(&up) > 0.0) {
            if let Some(high) = extreme_height(&lv, false) {
                let band: Vec<usize> =
                    level_band(&lv, high, false, sigma_up, k, s, params).collect();
                if band.iter().filter(|&&i| steps.ceiling[i]).count() >= CEILING_BAND_MIN_STEPS {
                    for i in band {
                        near_level[i] = true;
                    }
                }
            }
        }
        // Walls: merge those that are one wall, then assign by horizontal distance.
        let mut lines: Vec<Line> = wall_fits
            .iter()
            .filter_map(|f| line_of(f, &level_from_robot))
            .collect();
        let candidate: Vec<bool> = (0..grid.points.len())
            .map(|i| lv.q[i].is_some() && !near_level[i] && !levelish[i])
            .collect();
        // New walls are looked for once; later passes carry them as models.
        if params.refine_discover && pass == 0 {
            lines.extend(discover_lines(grid, &lv, &candidate, seed_width, params, s));
        }
        merge_lines(&mut lines, params, s);
        let cos_similar = SIMILAR_LINES_DEG.to_radians().cos();
        let mut wall_members: Vec<Vec<usize>> = vec![Vec::new(); lines.len()];
        // Candidates within reach of a line (the floor and ceiling lines below keep off them).
        let mut in_reach = vec![false; grid.points.len()];
        for (i, q) in lv.q.iter().enumerate() {
            let Some((q, d)) = q else { continue };
            if !candidate[i] {
                continue;
            }
            // The nearest line in sigmas, and the runner-up within reach.
            let mut best: Option<(f64, usize)> = None;
            let mut second: Option<(f64, usize)> = None;
            for (m, l) in lines.iter().enumerate() {
                let Some(z) = line_z2(l, q, d, s, params.min_sigma, sigma_up, k * k) else {
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
            if second
                .is_some_and(|(_, o)| lines[m].normal.dot(&lines[o].normal).abs() < cos_similar)
            {
                continue;
            }
            wall_members[m].push(i);
        }
        let min_rows = params.refine_min_rows.max(2);
        let mut models: Vec<Model> = Vec::new();
        for members in wall_members {
            if members.len() < params.min_patch_points
                || rows_supported(grid, &members, WALL_ROW_SHARE) < min_rows
            {
                continue;
            }
            let Some(fit) = fit_members(grid, &members, sigma) else {
                continue;
            };
            // A wall must stay a wall; what turned towards up was floor after all.
            if fit.normal.dot(&up).abs() > params.wall_cos() {
                continue;
            }
            models.push(Model {
                kind: SurfaceKind::Wall,
                fit,
                members,
            });
        }
        let walls_found = models.len();
        for (f, members) in level_fits.iter().zip(level_members) {
            let members = without_standing_rows(grid, members, s, params);
            if members.len() < params.min_level_points || !two_rows_support(grid, &members) {
                continue;
            }
            let Some(fit) = fit_members(grid, &members, sigma) else {
                continue;
            };
            let kind = if f.centroid.coords.dot(&up) < 0.0 {
                SurfaceKind::Floor
            } else {
                SurfaceKind::Ceiling
            };
            if fit.misfit_ratio(s) > params.refine_level_misfit
                || fit.normal.dot(&up).abs() < params.refine_level_cos()
                || !clear_of_scanner(&fit.normal, &fit.centroid)
                // Over two scans it must agree with up (one leveled a pose 7 degrees off
                // with a sigma of 0.1); over three, it may overrule a wrong start.
                || (!three_rows_support(grid, &members) && level_z2(&fit, &up, s, sigma_up) > k * k)
                || !opaque(grid, &fit, s, params)
            {
                continue;
            }
            models.push(Model { kind, fit, members });
        }
        let mut flat_lines: Vec<LevelLine> = Vec::new();
        if params.level_surfaces && params.level_lines {
            // Points of a model, or within reach of a wall's vertical plane (a wall line near
            // its foot lies at the floor's height within the provisional frame's tolerance).
            let mut taken = vec![false; grid.points.len()];
            for m in &models {
                for &i in &m.members {
                    taken[i] = true;
                }
            }
            for (i, q) in lv.q.iter().enumerate() {
                let Some((q, d)) = q else { continue };
                if taken[i] {
                    continue;
                }
                // Candidates were tried against every line above.
                taken[i] = if candidate[i] {
                    in_reach[i]
                } else {
                    lines
                        .iter()
                        .any(|l| line_z2(l, q, d, s, params.min_sigma, sigma_up, k * k).is_some())
                };
            }
            for kind in [SurfaceKind::Floor, SurfaceKind::Ceiling] {
                if models.iter().any(|m| m.kind == kind) {
                    continue;
                }
                let ctx = LineContext {
                    grid,
                    lv: &lv,
                    levelish: if kind == SurfaceKind::Floor {
                        &steps.floor_line
                    } else {
                        &steps.ceiling
                    },
                    taken: &taken,
                    up: &up,
                    s,
                    sigma_up,
                };
                match level_lines(&ctx, kind, params) {
                    LevelEvidence::None => {}
                    LevelEvidence::Lines(found) => flat_lines.extend(found),
                    LevelEvidence::Plane(fit, members) => models.push(Model { kind, fit, members }),
                }
            }
        }
        let obs: Vec<PlaneObs> = models
            .iter()
            .map(|m| m.obs(s, params))
            .chain(
                flat_lines
                    .iter()
                    .map(|l| PlaneObs::level_line(l, params.level_line_inflation)),
            )
            .collect();
        let sol = match up::up_robust(&obs, s, params.iterations) {
            Some(sol) => sol,
            // Lines that leave no up within reach were wrong: the models stand alone.
            None if !flat_lines.is_empty() => {
                let sol = up::up_robust(&obs[..models.len()], s, params.iterations)?;
                flat_lines.clear();
                sol
            }
            None => return None,
        };
        let change = sol.up.angle(&up);
        up = sol.up;
        sigma_up = sol
            .max_attitude_sigma()
            .clamp(params.refine_min_sigma_deg.to_radians(), MAX_SIGMA_UP);
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

/// Whether (almost) no point lies beyond a floor's or ceiling's plane: the scanner sees
/// nothing through a floor or a ceiling, so points more than `refine_k` sigmas beyond the
/// plane on the side away from the scanner (below a floor, above a ceiling), counting its tilt
/// uncertainty over their distance, mean a wrong plane. A wall's line and the floor's line of
/// the next scan, both across the view, are parallel and so always coplanar: one such "floor",
/// tilted 13 degrees from the true one, had 13 of the pose's 543 points beyond it.
pub(crate) fn opaque(grid: &PoseGrid, fit: &PlaneFit, s: f64, params: &LevelParams) -> bool {
    let model = LevelModel::new(fit, s);
    // Away from the scanner, which sits at the robot frame's origin.
    let normal = if fit.normal.dot(&fit.centroid.coords) < 0.0 {
        -fit.normal
    } else {
        fit.normal
    };
    let beyond = grid
        .points
        .iter()
        .flatten()
        .filter(|g| {
            // Most points lie on the scanner's side: no need for their sigma.
            let d = normal.dot(&(g.p - fit.centroid));
            d > 0.0 && d > params.refine_k * model.distance_sd(g, s, params.min_sigma).1
        })
        .count();
    beyond <= MAX_BEYOND
}

/// Points beyond a level plane that [`opaque`] lets pass: true planes have a few (allowing
/// none leveled 7 points fewer poses at 5-10 cm noise, allowing two 0.4 points fewer).
const MAX_BEYOND: usize = 5;

/// Squared angle between a level model's normal and up, in variances: the model's normal
/// noise, inflated by its misfit, and up's own (`sigma_up` \[rad\]).
fn level_z2(fit: &PlaneFit, up: &Vector3<f64>, s: f64, sigma_up: f64) -> f64 {
    let n = fit.normal * fit.normal.dot(up).signum();
    let off = up - n * n.dot(up);
    let Some(u) = off.try_normalize(1e-12) else {
        return 0.0;
    };
    let var = fit.normal_variance_along(&u, s) * fit.misfit_ratio(s).max(1.0) + sigma_up * sigma_up;
    off.norm_squared() / var
}

/// What [`level_lines`] works on: the grid in the provisional level frame.
struct LineContext<'a> {
    grid: &'a PoseGrid,
    lv: &'a Leveled,
    levelish: &'a [bool],
    /// Points already in a wall or level model.
    taken: &'a [bool],
    up: &'a Vector3<f64>,
    s: f64,
    sigma_up: f64,
}

/// Floor or ceiling evidence found by [`level_lines`].
enum LevelEvidence {
    None,
    /// One line per scan that sees the surface.
    Lines(Vec<LevelLine>),
    /// One plane through the lines of several scans, with its points.
    Plane(PlaneFit, Vec<usize>),
}

/// The floor (or ceiling) as lines, one per scan, where the level frame's plane search found
/// none: a floor seen by one scan only, or by scans that do not overlap in bearing (the
/// floor ahead in one, to the side in another), has no point with a flat neighbour in the
/// next scan, which that search needs.
///
/// Candidates are the points whose range steps to the adjacent scans like a level surface's
/// ([`LevelSteps::floor_line`], [`LevelSteps::ceiling`]: a wall's foot does not). The floor is
/// the LOWEST level surface (a box top is not the floor) and lies at one height for all scans:
/// the lowest height window that holds a third as many candidates as the densest one gives
/// that height, and each candidate within its own vertical tolerance of it (range noise along
/// the vertical, and an error of up `sigma_up` at its horizontal distance) joins its scan's
/// line. Each scan's line is fitted with outliers removed and must fit within
/// `level_line_misfit` of its noise. With `level_line_plane` and two or more scans, the lines
/// are one plane (its lever arm is the distance between the lines) when their points fit one
/// within `refine_level_misfit`; in a plane with a full line, a line of as few as
/// [`PLANE_LINE_MIN_POINTS`] counts.
fn level_lines(ctx: &LineContext, kind: SurfaceKind, params: &LevelParams) -> LevelEvidence {
    let (grid, lv, s) = (ctx.grid, ctx.lv, ctx.s);
    let floor = kind == SurfaceKind::Floor;
    // Height key growing away from the surface's side: the outermost level surface first.
    let key = |z: f64| if floor { z } else { -z };
    let mut zs: Vec<(f64, usize)> =
        lv.q.iter()
            .enumerate()
            .filter_map(|(i, q)| {
                let (q, _) = q.as_ref()?;
                (ctx.levelish[i] && !ctx.taken[i] && key(q.z) < -MIN_LEVEL_DISTANCE)
                    .then_some((key(q.z), i))
            })
            .collect();
    let min_points = params.level_line_min_points.max(3);
    if zs.len() < min_points {
        return LevelEvidence::None;
    }
    zs.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    let half = params.refine_k * (0.3 * s + 2.0 * ctx.sigma_up) + params.flat_margin;
    // Window counts, from each start.
    let mut counts = Vec::with_capacity(zs.len());
    let mut hi = 0;
    for lo in 0..zs.len() {
        while hi < zs.len() && zs[hi].0 - zs[lo].0 <= 2.0 * half {
            hi += 1;
        }
        counts.push((lo, hi));
    }
    let densest = counts.iter().map(|(lo, hi)| hi - lo).max().unwrap_or(0);
    let Some(&(lo, hi)) = counts
        .iter()
        .find(|(lo, hi)| hi - lo >= min_points && 3 * (hi - lo) >= densest)
    else {
        return LevelEvidence::None;
    };
    let height = zs[(lo + hi) / 2].0;
    let k = params.refine_k;
    let mut rows: Vec<Vec<usize>> = vec![Vec::new(); grid.rows()];
    let rc = grid.row_col();
    for &(z, i) in &zs {
        let Some((q, d)) = lv.q[i].as_ref() else {
            continue;
        };
        let lever = q.xy().norm() * ctx.sigma_up;
        let sd = (s * s * d.z * d.z + params.min_sigma * params.min_sigma + lever * lever).sqrt();
        if (z - height).abs() <= k * sd + params.flat_margin {
            rows[rc.row(i)].push(i);
        }
    }
    let short = PLANE_LINE_MIN_POINTS.min(min_points);
    let found: Vec<(LevelLine, Vec<usize>)> = rows
        .into_iter()
        .filter_map(|row| fit_line(grid, row, ctx.up, Some(ctx.sigma_up), s, params, short))
        .collect();
    let full = |(l, _): &(LevelLine, Vec<usize>)| l.n >= min_points;
    // Short lines count only in a plane with a full one; without short lines, the full lines
    // alone are tried below.
    let full_lines = found.iter().filter(|l| full(l)).count();
    if full_lines > 0 && full_lines < found.len() && one_plane(grid, &found, s, params) {
        if let Some(plane) = lines_plane(grid, &found, s)
            .and_then(|(fit, members)| level_plane(ctx, fit, members, params))
        {
            return plane;
        }
    }
    // Alone, a line needs `level_line_min_points`.
    let found: Vec<(LevelLine, Vec<usize>)> = found.into_iter().filter(full).collect();
    // When the lines cannot be one floor, which is wrong is not clear (a wall line near its
    // foot sits at the floor's height within the provisional frame's tolerance): none is used.
    if found.is_empty() || !one_plane(grid, &found, s, params) {
        return LevelEvidence::None;
    }
    if found.len() >= 2 {
        // One floor's lines always fit one plane; a wall's line just above its foot and a
        // floor line at another bearing are skew (traced: a zigzag wall's foot 10 cm up,
        // taken with a floor line, pulled a pose 8 degrees off with a sigma of 0.4).
        let Some((fit, members)) = lines_plane(grid, &found, s) else {
            return LevelEvidence::None;
        };
        let misfit = fit.misfit_ratio(s);
        if let Some(plane) = level_plane(ctx, fit, members, params) {
            return plane;
        }
        if misfit > LINES_PLANE_MISFIT {
            return LevelEvidence::None;
        }
    }
    LevelEvidence::Lines(found.into_iter().map(|(l, _)| l).collect())
}

/// Fewest points of a scan's floor line that joins a plane through another scan's line of
/// `level_line_min_points` or more ([`level_lines`]): in the plane it adds its distance from
/// the other line, a lever arm, not a direction of its own. Traced, floor points of 7 and 11
/// in two scans beside a third scan's line of 15-18 were left out, and the poses (Cramér-Rao
/// bounds under 0.1 degree) failed. Over 432,000 protocol poses at 5-10 cm (nine plans, seeds
/// 101-180), leveled 74.36 -> 74.71% with 40 -> 41 poses ok and more than 5 degrees off and
/// 752 -> 744 more than 3 degrees off (at 5 points: 74.62%, 41 and 745); over 129,600 more
/// (seeds 1-8, 11-14, 21-32), 74.32 -> 74.64% with 4 and 4; at 1 cm, 99.09 -> 99.12%.
const PLANE_LINE_MIN_POINTS: usize = 3;

/// The plane through level lines' points, with those points (ascending).
fn lines_plane(
    grid: &PoseGrid,
    lines: &[(LevelLine, Vec<usize>)],
    s: f64,
) -> Option<(PlaneFit, Vec<usize>)> {
    let mut members: Vec<usize> = lines.iter().flat_map(|(_, m)| m.iter().copied()).collect();
    members.sort_unstable();
    Some((fit_members(grid, &members, s)?, members))
}

/// The plane `fit` through level lines' points `members` ([`lines_plane`]) as the floor or
/// ceiling, when it fits them (`level_line_plane`): within `refine_level_misfit` of the noise,
/// near up, clear of the scanner, and with nothing seen through it.
fn level_plane(
    ctx: &LineContext,
    fit: PlaneFit,
    members: Vec<usize>,
    params: &LevelParams,
) -> Option<LevelEvidence> {
    let s = ctx.s;
    (params.level_line_plane
        && fit.misfit_ratio(s) <= params.refine_level_misfit
        && fit.normal.dot(ctx.up).abs() >= params.refine_level_cos()
        && clear_of_scanner(&fit.normal, &fit.centroid)
        && opaque(ctx.grid, &fit, s, params))
    .then_some(LevelEvidence::Plane(fit, members))
}

/// Largest misfit ratio of the plane through two or more level lines' points for the lines to
/// stand as one floor or ceiling ([`level_lines`]).
const LINES_PLANE_MISFIT: f64 = 3.0;

/// Whether level lines (each with its points) can all lie in one plane: with three or more,
/// each must lie in the plane of the others' points. Any two lines pass, as do lines of one
/// floor seen by parallel scans (they leave the plane of any two free to tilt about them).
fn one_plane(
    grid: &PoseGrid,
    lines: &[(LevelLine, Vec<usize>)],
    s: f64,
    params: &LevelParams,
) -> bool {
    if lines.len() < 3 {
        return true;
    }
    (0..lines.len()).all(|i| {
        let others: Vec<usize> = lines
            .iter()
            .enumerate()
            .filter(|&(j, _)| j != i)
            .flat_map(|(_, (_, m))| m.iter().copied())
            .collect();
        fit_members(grid, &others, s).is_some_and(|fit| {
            line_offset_sigmas(grid, &lines[i].1, &fit, s, params.min_sigma) <= params.refine_k
        })
    })
}

/// A level surface's members without an edge row (the lowest or highest scan among them) that
/// stands off the plane of the other rows by more than `refine_k` sigmas ([`line_offset_sigmas`]).
/// The scan above a floor meets the walls just above their feet: that line lies centimetres
/// over the floor, passes for floor within a provisional frame's tolerance, and tilts the plane
/// (one such row, 6 cm up, set a start 2.8 degrees off with a sigma of 0.11). Only with three
/// rows or more, so that the others still make a plane.
fn without_standing_rows(
    grid: &PoseGrid,
    members: Vec<usize>,
    s: f64,
    params: &LevelParams,
) -> Vec<usize> {
    let rc = grid.row_col();
    let mut rows: Vec<usize> = members.iter().map(|&i| rc.row(i)).collect();
    rows.sort_unstable();
    rows.dedup();
    if rows.len() < 3 {
        return members;
    }
    let (first, last) = (rows[0], rows[rows.len() - 1]);
    let mut drop = Vec::new();
    for edge in [first, last] {
        // The others must still span two rows to make a plane.
        if rows.len() - drop.len() < 3 {
            break;
        }
        let (line, others): (Vec<usize>, Vec<usize>) = members
            .iter()
            .copied()
            .filter(|&i| !drop.contains(&rc.row(i)))
            .partition(|&i| rc.row(i) == edge);
        let Some(fit) = fit_members(grid, &others, s) else {
            continue;
        };
        if line_offset_sigmas(grid, &line, &fit, s, params.min_sigma) > params.refine_k {
            drop.push(edge);
        }
    }
    if drop.is_empty() {
        return members;
    }
    members
        .into_iter()
        .filter(|&i| !drop.contains(&rc.row(i)))
        .collect()
}

/// How far, in standard deviations, a line's points lie from a plane on average: the mean
/// signed distance against its noise (the points' range noise along the normal, averaged,
/// and the plane's tilt uncertainty at the line's distance from the plane's centroid).
fn line_offset_sigmas(
    grid: &PoseGrid,
    members: &[usize],
    fit: &PlaneFit,
    s: f64,
    min_sigma: f64,
) -> f64 {
    let model = LevelModel::new(fit, s);
    let mut sum = 0.0;
    let mut var = 0.0;
    let mut centre = Vector3::zeros();
    let mut n = 0.0;
    for g in members.iter().filter_map(|&i| grid.points[i].as_ref()) {
        sum += fit.normal.dot(&(g.p - fit.centroid));
        var += s * s * g.dir.dot(&fit.normal).powi(2) + min_sigma * min_sigma;
        centre += g.p.coords;
        n += 1.0;
    }
    if n == 0.0 {
        return 0.0;
    }
    let v = centre / n - fit.centroid.coords;
    let lever2 = (v.norm_squared() - fit.normal.dot(&v).powi(2)).max(0.0);
    let sd = (var / (n * n) + lever2 * model.tilt * model.tilt).sqrt();
    (sum / n).abs() / sd.max(1e-12)
}

/// Rounds of outlier removal of a level line.
const LINE_ROUNDS: usize = 3;

/// One scan's points on a level surface as a [`LevelLine`], refitted without the points
/// farther than `refine_k` sigmas from it (vertically and horizontally, each with its range
/// noise along that direction); `None` when fewer than `min_points` (at least 3) remain or the
/// rest do not fit one line within `level_line_misfit` of their noise.
fn fit_line(
    grid: &PoseGrid,
    mut idx: Vec<usize>,
    up: &Vector3<f64>,
    sigma_up: Option<f64>,
    s: f64,
    params: &LevelParams,
    min_points: usize,
) -> Option<(LevelLine, Vec<usize>)> {
    let min_points = min_points.max(3);
    let ms2 = params.min_sigma * params.min_sigma;
    for round in 0..LINE_ROUNDS {
        if idx.len() < min_points {
            return None;
        }
        let pts: Vec<(nalgebra::Point3<f64>, Vector3<f64>)> = idx
            .iter()
            .filter_map(|&i| grid.points[i].as_ref().map(|g| (g.p, g.dir)))
            .collect();
        let line = LevelLine::fit(&pts, s, params.min_sigma)?;
        // Across the line: vertical-ish and horizontal-ish unit directions.
        let v1 = (up - line.dir * line.dir.dot(up)).try_normalize(1e-12)?;
        let v2 = line.dir.cross(&v1);
        let z2 = |p: &nalgebra::Point3<f64>, d: &Vector3<f64>| {
            let r = p - line.centroid;
            let r = r - line.dir * line.dir.dot(&r);
            let a = r.dot(&v1).powi(2) / (s * s * d.dot(&v1).powi(2) + ms2);
            let b = r.dot(&v2).powi(2) / (s * s * d.dot(&v2).powi(2) + ms2);
            (a, b)
        };
        let k2 = params.refine_k * params.refine_k;
        let kept: Vec<usize> = idx
            .iter()
            .copied()
            .filter(|&i| {
                grid.points[i].as_ref().is_some_and(|g| {
                    let (a, b) = z2(&g.p, &g.dir);
                    a <= k2 && b <= k2
                })
            })
            .collect();
        if kept.len() == idx.len() || round + 1 == LINE_ROUNDS {
            if kept.len() < min_points {
                return None;
            }
            let chi2: f64 = pts
                .iter()
                .map(|(p, d)| {
                    let (a, b) = z2(p, d);
                    a + b
                })
                .sum();
            let dof = (2 * pts.len()).saturating_sub(4).max(1) as f64;
            if kept.len() < idx.len() || chi2 / dof > params.level_line_misfit {
                return None;
            }
            // A floor line is level in the provisional frame, within that frame's
            // uncertainty and its own: a wall's line that passes near the floor's height
            // (a scan meeting a far wall near its foot) slopes, and taken as level it pulled
            // poses 6-7 degrees off with sigmas under one degree.
            if let Some(sigma_up) = sigma_up {
                let slope = line.dir.dot(up);
                if slope * slope > k2 * (line.variance_along(&v1, s) + sigma_up * sigma_up) {
                    return None;
                }
            }
            return Some((line, idx));
        }
        idx = kept;
    }
    None
}

/// A level plane with what assigning points to it needs.
struct LevelModel<'a> {
    fit: &'a PlaneFit,
    /// The plane's own tilt uncertainty \[rad\].
    tilt: f64,
}

impl<'a> LevelModel<'a> {
    fn new(fit: &'a PlaneFit, s: f64) -> Self {
        let tilt = fit
            .in_plane
            .iter()
            .map(|(_, e)| fit.normal_variance_along(e, s))
            .fold(0f64, f64::max)
            .sqrt()
            .min(MAX_SIGMA_UP);
        LevelModel { fit, tilt }
    }

    /// A point's distance from the plane and its standard deviation: the range noise along
    /// the normal, and the plane's tilt uncertainty at the point's distance from its centroid.
    fn distance_sd(&self, g: &GridPoint, s: f64, min_sigma: f64) -> (f64, f64) {
        let f = self.fit;
        let v = g.p - f.centroid;
        let d = f.normal.dot(&v);
        let lever2 = (v.norm_squared() - d * d).max(0.0) * self.tilt * self.tilt;
        let sd = (s * s * g.dir.dot(&f.normal).powi(2) + min_sigma * min_sigma + lever2).sqrt();
        (d.abs(), sd)
    }
}

/// A start for poses where no first solution exists (the walls and region-grown floor could not
/// fix up): the plane through most of the points whose range steps like a level surface's
/// ([`LevelSteps::levelish`], which needs no up), found by a deterministic sample of point triples
/// (RANSAC, Fischler and Bolles 1981), taken as level. `None` when no such plane holds
/// `min_level_points` points in at least two scans with a normal within 50 degrees of the
/// robot's own up.
pub fn level_start(
    grid: &PoseGrid,
    steps: &LevelSteps,
    params: &LevelParams,
    sigma: f64,
) -> Option<UpSolution> {
    let s = sigma.max(params.min_sigma);
    let levelish = &steps.levelish;
    let idx: Vec<usize> = (0..grid.points.len())
        .filter(|&i| levelish[i] && grid.points[i].is_some())
        .collect();
    if idx.len() < params.min_level_points {
        return None;
    }
    let min_z = START_MAX_TILT_DEG.to_radians().cos();
    let members = sampled_plane(grid, &idx, &idx, |n| n.z.abs() >= min_z, s, params)?;
    let members = without_standing_rows(grid, members, s, params);
    if members.len() < params.min_level_points || !two_rows_support(grid, &members) {
        return None;
    }
    let fit = fit_members(grid, &members, sigma)?;
    if fit.normal.z.abs() < min_z {
        return None;
    }
    let sol = up::up_robust(&[PlaneObs::level(&fit, 1.0)], s, params.iterations)?;
    if !three_rows_support(grid, &members) {
        let loose = Matrix2::identity() * (MAX_SIGMA_UP * MAX_SIGMA_UP);
        return Some(UpSolution {
            cov: sol.cov + loose,
            ..sol
        });
    }
    Some(sol)
}

/// The points of `idx` on the plane through most of them, found by a deterministic sample of
/// triples of the points `sample` (RANSAC, Fischler and Bolles 1981) among planes whose normal
/// `accept`s and that pass clear of the scanner ([`clear_of_scanner`]; else one scan's own
/// points, all in its plane, win): a point is on a plane within `refine_k` sigmas of its range
/// noise along the normal, plus `flat_margin`. `None` when no triple gives such a plane.
fn sampled_plane(
    grid: &PoseGrid,
    idx: &[usize],
    sample: &[usize],
    accept: impl Fn(&Vector3<f64>) -> bool,
    s: f64,
    params: &LevelParams,
) -> Option<Vec<usize>> {
    let n = sample.len();
    if n < 3 {
        return None;
    }
    // `|r| <= k sd + margin` with `sd^2 = s^2 (d . n)^2 + min_sigma^2`, squared: no root per
    // point.
    let k2 = params.refine_k * params.refine_k;
    let floor2 = params.min_sigma * params.min_sigma;
    let on_plane = |g: &GridPoint, p0: &Point3<f64>, normal: &Vector3<f64>| {
        let beyond = normal.dot(&(g.p - p0)).abs() - params.flat_margin;
        beyond <= 0.0 || beyond * beyond <= k2 * (s * s * g.dir.dot(normal).powi(2) + floor2)
    };
    let inliers = |p0: Point3<f64>, normal: Vector3<f64>| {
        idx.iter().copied().filter(move |&i| {
            grid.points[i]
                .as_ref()
                .is_some_and(|g| on_plane(g, &p0, &normal))
        })
    };
    // Counted per hypothesis (most lose by far, and are given up early); only the best one's
    // points are gathered.
    let mut best: Option<(usize, Point3<f64>, Vector3<f64>)> = None;
    for h in 0..START_HYPOTHESES {
        // Three points spread over the candidates: a fixed stride walk, no random state.
        let pick = |k: usize| sample[(h * (2 * k + 1) * 7 + k * n / 3) % n];
        let (Some(pa), Some(pb), Some(pc)) = (
            grid.points[pick(0)].as_ref(),
            grid.points[pick(1)].as_ref(),
            grid.points[pick(2)].as_ref(),
        ) else {
            continue;
        };
        let (u, v) = (pb.p - pa.p, pc.p - pa.p);
        let cross = u.cross(&v);
        // Nearly collinear triples (one scan line) leave the plane free to turn.
        if cross.norm() < 0.1 * u.norm() * v.norm() {
            continue;
        }
        let normal = cross.normalize();
        if !accept(&normal) || !clear_of_scanner(&normal, &pa.p) {
            continue;
        }
        let on = |i: usize| {
            grid.points[i]
                .as_ref()
                .is_some_and(|g| on_plane(g, &pa.p, &normal))
        };
        if let Some(count) = count_beating(idx, on, best.map(|b| b.0)) {
            best = Some((count, pa.p, normal));
        }
    }
    let (_, p0, normal) = best?;
    Some(inliers(p0, normal).collect())
}

/// How many of `idx` satisfy `on`, when that beats `best` (more than it; anything beats
/// `None`); `None` as soon as the points left cannot beat it.
fn count_beating(idx: &[usize], on: impl Fn(usize) -> bool, best: Option<usize>) -> Option<usize> {
    let mut count = 0;
    for (j, &i) in idx.iter().enumerate() {
        if on(i) {
            count += 1;
        } else if best.is_some_and(|b| count + (idx.len() - j - 1) <= b) {
            return None;
        }
    }
    best.is_none_or(|b| count > b).then_some(count)
}

/// Floor and ceiling lines found without a level frame, for a start where neither the walls
/// nor a level plane fix up ([`level_start`]): in each scan, the points whose range steps to
/// the adjacent scans like the floor's ([`LevelSteps::floor`]) as one line, and likewise the
/// ceiling's. Their height is not checked (no frame to check it in); the lines only start
/// re-segmentation, which finds them again in its provisional level frame.
pub fn start_lines(
    grid: &PoseGrid,
    steps: &LevelSteps,
    params: &LevelParams,
    sigma: f64,
) -> Vec<LevelLine> {
    let s = sigma.max(params.min_sigma);
    let cols = grid.cols;
    let mut out = Vec::new();
    for mask in [&steps.floor, &steps.ceiling] {
        let lines: Vec<(LevelLine, Vec<usize>)> = (0..grid.rows())
            .filter_map(|r| {
                let idx: Vec<usize> = (r * cols..(r + 1) * cols).filter(|&i| mask[i]).collect();
                fit_line(
                    grid,
                    idx,
                    &Vector3::z(),
                    None,
                    s,
                    params,
                    params.level_line_min_points,
                )
            })
            .collect();
        // One floor is one plane: lines that cannot lie in one plane are not all on it, and
        // which one is not is unknown here. (A far wall met by the level scan steps to the
        // floor in the next scan as the floor does; taken as a floor line it set a start 8
        // degrees off, and re-segmentation kept it. A wall's line 14 cm above its foot,
        // coplanar with each of two floor lines but not with both, set one 3 degrees off with
        // a sigma of 0.17.)
        let coplanar = (0..lines.len())
            .all(|i| (i + 1..lines.len()).all(|j| coplanar(&lines[i].0, &lines[j].0, s, params)));
        if coplanar && one_plane(grid, &lines, s, params) {
            out.extend(lines.into_iter().map(|(line, _)| line));
        }
    }
    out
}

/// Whether two lines can lie in one plane: the offset between them across the plane their
/// directions span, within `refine_k` sigmas of their centroids' noise and their directions'
/// uncertainty over the distance between them. Nearly parallel lines always can.
fn coplanar(a: &LevelLine, b: &LevelLine, s: f64, params: &LevelParams) -> bool {
    let Some(n) = a.dir.cross(&b.dir).try_normalize(0.05) else {
        return true;
    };
    let gap = b.centroid - a.centroid;
    let offset = n.dot(&gap);
    let point = s * s + params.min_sigma * params.min_sigma;
    let var = point / a.n as f64
        + point / b.n as f64
        + gap.norm_squared() * (a.variance_along(&n, s) + b.variance_along(&n, s));
    offset * offset <= params.refine_k * params.refine_k * var
}

/// Point triples tried by [`level_start`].
const START_HYPOTHESES: usize = 48;

/// Largest tilt of a [`level_start`] plane from the robot's own up \[deg\].
const START_MAX_TILT_DEG: f64 = 50.0;

/// Passes stop when up moves by less than this fraction of its uncertainty.
const CONVERGED: f64 = 0.05;

/// Largest up uncertainty used for assignment tolerances \[rad\].
const MAX_SIGMA_UP: f64 = 0.06;

fn start_sigma(start: &UpSolution, params: &LevelParams) -> f64 {
    let s = start.max_attitude_sigma();
    if s.is_finite() {
        s.clamp(params.refine_min_sigma_deg.to_radians(), MAX_SIGMA_UP)
    } else {
        MAX_SIGMA_UP
    }
}

/// The floor and ceiling planes to assign from: the ones given, else the densest height below
/// (floor) and above (ceiling) the scanner in the level frame, where at least
/// `min_level_points` points lie within the tolerance of one height.
#[allow(clippy::too_many_arguments)]
fn find_levels(
    grid: &PoseGrid,
    lv: &Leveled,
    ok: &[bool],
    levelish: &[bool],
    given: &[PlaneFit],
    fresh: bool,
    up: &Vector3<f64>,
    params: &LevelParams,
    s: f64,
    sigma_up: f64,
) -> Vec<PlaneFit> {
    let below = |f: &PlaneFit| f.centroid.coords.dot(up) < 0.0;
    let mut out: Vec<PlaneFit> = Vec::new();
    for floor in [true, false] {
        if !fresh {
            // Later passes carry what the first found, and look for nothing new.
            if let Some(f) = given.iter().find(|f| below(f) == floor) {
                out.push(*f);
            }
            continue;
        }
        // Heights of the candidates, with the tolerance of each: the noise along the vertical
        // plus what an error in up does at the point's horizontal distance.
        let mut zs: Vec<(f64, usize)> = lv
            .q
            .iter()
            .enumerate()
            .filter_map(|(i, q)| {
                let (q, _) = q.as_ref()?;
                (ok[i] && (q.z < -MIN_LEVEL_DISTANCE) == floor && q.z.abs() > MIN_LEVEL_DISTANCE)
                    .then_some((q.z, i))
            })
            .collect();
        if zs.len() < params.min_level_points {
            continue;
        }
        zs.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
        // A window as wide as the vertical tolerance of a typical grazing floor hit.
        let half = params.refine_k * (0.3 * s + 2.0 * sigma_up) + params.flat_margin;
        let mut best = (0usize, 0usize);
        let mut lo = 0;
        for hi in 0..zs.len() {
            while zs[hi].0 - zs[lo].0 > 2.0 * half {
                lo += 1;
            }
            if hi + 1 - lo > best.1 - best.0 {
                best = (lo, hi + 1);
            }
        }
        if best.1 - best.0 < params.min_level_points {
            continue;
        }
        // The window holds wall points too (a wall's foot, or a band of wall at one height
        // in a frame degrees off): the plane through most of its points, rather than through
        // all of them, starts the rounds.
        let window: Vec<usize> = zs[best.0..best.1].iter().map(|&(_, i)| i).collect();
        let stepping: Vec<usize> = window.iter().copied().filter(|&i| levelish[i]).collect();
        let cos = params.refine_level_cos();
        let mut members = sampled_plane(
            grid,
            &window,
            &stepping,
            |n| n.dot(up).abs() >= cos,
            s,
            params,
        )
        .unwrap_or(window);
        // A few rounds of refit and reassignment: the window's plane is only as level as the
        // provisional up, so far points fall outside it at first.
        let mut fit = None;
        for round in 0..LEVEL_ROUNDS {
            if members.len() < params.min_level_points || !two_rows_support(grid, &members) {
                fit = None;
                break;
            }
            let Some(f) = fit_members(grid, &members, s) else {
                fit = None;
                break;
            };
            fit = Some(f);
            if round + 1 == LEVEL_ROUNDS {
                break;
            }
            let model = LevelModel::new(&f, s);
            members = zs
                .iter()
                .map(|&(_, i)| i)
                .filter(|&i| {
                    grid.points[i].as_ref().is_some_and(|g| {
                        let (d, sd) = model.distance_sd(g, s, params.min_sigma);
                        d <= params.refine_k * sd
                    })
                })
                .collect();
        }
        if let Some(f) = fit {
            if f.normal.dot(up).abs() >= params.refine_level_cos()
                && f.misfit_ratio(s) <= params.refine_level_misfit
                && clear_of_scanner(&f.normal, &f.centroid)
            {
                out.push(f);
            }
        }
    }
    out
}

/// Points whose range changes from scan to scan like a level surface's: in their column, the
/// range to a neighbouring row's point differs by more than `r de` for the elevation step `de`
/// (`r cot(a) de` on a surface seen `a` < 45 degrees off the beams' plane, `r tan(b) de` on a
/// wall met at vertical incidence `b`, see [`super::steep`]), plus a margin for the noise of
/// two ranges. A floor or ceiling takes no other point: at high noise a wall's foot lies within
/// a floor's tolerance, and a band of wall points at one height could pass for a floor.
///
/// Split by side too. On a floor, a scan tilted further down (the next row, larger elevation)
/// meets the surface closer for rays ahead of the hinge axis (`dir.x > 0`) and farther for
/// rays behind it; on a ceiling the other way round. A point past an occluding edge steps far
/// too, but its sign needs no luck to contradict a ceiling.
pub struct LevelSteps {
    /// Every neighbouring row's step is a level surface's.
    pub levelish: Vec<bool>,
    /// Every neighbouring row's step has the floor's sign and size.
    pub floor: Vec<bool>,
    /// Every neighbouring row's step has the ceiling's sign and size.
    pub ceiling: Vec<bool>,
    /// Every neighbouring row's step has the floor's sign, and the floor's size or a size beyond
    /// `LINE_STEP_SIGMAS` of the noise of two ranges: looser than `floor`, for floor lines
    /// (`level_lines`), which must also lie at the floor's height and run level. The floor
    /// just in front of a wall's foot steps less than `r de` to the wall above it, since the
    /// wall stops the scan above short of where it would meet the floor; traced, a scan's 19
    /// floor points 0.1-0.6 m in front of a wall were no candidates, and the pose, whose
    /// Cramér-Rao bound was 0.03 degrees, failed with walls alone (1.7 degrees of sigma).
    /// Ceiling lines keep `ceiling`: the same for them changed nothing measurable (74.38
    /// against 74.36% leveled over the poses of `LINE_STEP_SIGMAS`) and leveled a traced
    /// ceiling-room pose (`tests/level_refine.rs`, seed 6) 4 degrees off at 3.4 of its sigmas.
    pub floor_line: Vec<bool>,
}

/// Steps beyond this many standard deviations of the difference of two ranges count for
/// [`LevelSteps::floor_line`] by their sign alone. Over 432,000 protocol poses at 5-10 cm
/// (nine plans, seeds 101-180), leveled 74.16 -> 74.36% with 41 -> 40 poses ok and more than 5
/// degrees off, and 764 -> 752 more than 3 degrees off (with floor and ceiling lines: at 1,
/// 74.57% but 62 poses; at 3, 74.17% and 41); over 129,600 more (seeds 1-8, 11-14, 21-32),
/// 74.15 -> 74.32% with 4 and 4; at 1 cm (seeds 1-8), 99.01 -> 99.09%.
const LINE_STEP_SIGMAS: f64 = 2.0;

/// [`LevelSteps`] of a grid at range noise `sigma`, each adjacent-row step judged once.
pub fn level_steps(grid: &PoseGrid, params: &LevelParams, sigma: f64) -> LevelSteps {
    let two_ranges = std::f64::consts::SQRT_2 * sigma.max(params.min_sigma);
    let margin = params.refine_step_k * two_ranges;
    let rc = grid.row_col();
    // +1 a floor's step, -1 a ceiling's, 0 neither; beside it the same by sign alone.
    let pairs = row_pairs(grid, |a, b, i, j| {
        let de = grid.elevation[rc.row(j)] - grid.elevation[rc.row(i)];
        let change = (b.range - a.range) * de.signum() * a.dir.x.signum();
        let bound = 0.5 * (a.range + b.range) * de.abs() + margin;
        let side = |bound: f64| {
            if change < -bound {
                1i8
            } else if change > bound {
                -1
            } else {
                0
            }
        };
        (side(bound), side(bound.min(LINE_STEP_SIGMAS * two_ranges)))
    });
    // A wall point above or below a floor point steps far to it, but not to its other
    // neighbour on the wall: every neighbour must agree. (Each test is its own closure, so
    // that it is inlined rather than called through a pointer per point.)
    LevelSteps {
        levelish: every_row_neighbour(grid, &pairs, |(x, _)| x != 0),
        floor: every_row_neighbour(grid, &pairs, |(x, _)| x == 1),
        ceiling: every_row_neighbour(grid, &pairs, |(x, _)| x == -1),
        floor_line: every_row_neighbour(grid, &pairs, |(_, x)| x == 1),
    }
}

/// `step(a, b, i, j)` for each point `a` (index `i`) and the point `b` (index `j`) above it in
/// the next row, `None` where either is missing: each column pair of adjacent rows once,
/// pair `i` joining point `i` to the one above.
fn row_pairs<T>(
    grid: &PoseGrid,
    step: impl Fn(&GridPoint, &GridPoint, usize, usize) -> T,
) -> Vec<Option<T>> {
    let cols = grid.cols;
    (0..cols * grid.rows().saturating_sub(1))
        .map(|i| {
            let j = i + cols;
            Some(step(
                grid.points[i].as_ref()?,
                grid.points[j].as_ref()?,
                i,
                j,
            ))
        })
        .collect()
}

/// Per point, whether it has a neighbour in an adjacent row and `accept` holds for the step to
/// every such neighbour ([`row_pairs`]).
fn every_row_neighbour<T: Copy>(
    grid: &PoseGrid,
    pairs: &[Option<T>],
    accept: impl Fn(T) -> bool,
) -> Vec<bool> {
    let (cols, rows, rc) = (grid.cols, grid.rows(), grid.row_col());
    (0..grid.points.len())
        .map(|i| {
            let r = rc.row(i);
            let below = if r > 0 { pairs[i - cols] } else { None };
            let above = if r + 1 < rows { pairs[i] } else { None };
            match (below, above) {
                (None, None) => false,
                (a, b) => a.is_none_or(&accept) && b.is_none_or(&accept),
            }
        })
        .collect()
}

/// Points that can belong to a floor or ceiling, judged against their neighbours in the same
/// column (adjacent scans) in the provisional level frame: at least one neighbour lies at the
/// same height (within the vertical noise of both and what an error in up does across their
/// horizontal separation), and none rises steeply from it (a height step larger than the
/// noise and larger than the horizontal step, as up a wall). A wall's foot lies within a
/// floor plane's tolerance, but the wall point above it rises steeply; on a floor the scans
/// step far outwards at one height. The vertical noise of grazing floor hits is small, so
/// the test stays sharp at high range noise, unlike steps in range.
fn flat_points(
    grid: &PoseGrid,
    lv: &Leveled,
    s: f64,
    min_sigma: f64,
    sigma_up: f64,
    k: f64,
) -> Vec<bool> {
    let cols = grid.cols;
    let rows = grid.rows();
    // Some(true) flat, Some(false) steep, None neither or no neighbour.
    let pair = |i: usize, j: usize| -> Option<bool> {
        let ((a, da), (b, db)) = (lv.q[i].as_ref()?, lv.q[j].as_ref()?);
        let dz2 = (a.z - b.z).powi(2);
        let dxy2 = (a.xy() - b.xy()).norm_squared();
        let var = s * s * (da.z * da.z + db.z * db.z)
            + min_sigma * min_sigma
            + dxy2 * sigma_up * sigma_up;
        if dz2 <= k * k * var {
            Some(true)
        } else if dz2 > dxy2 {
            Some(false)
        } else {
            None
        }
    };
    let pairs: Vec<Option<bool>> = (0..cols * rows.saturating_sub(1))
        .map(|i| pair(i, i + cols))
        .collect();
    let rc = grid.row_col();
    (0..grid.points.len())
        .map(|i| {
            let r = rc.row(i);
            let below = if r > 0 { pairs[i - cols] } else { None };
            let above = if r + 1 < rows { pairs[i] } else { None };
            below != Some(false)
                && above != Some(false)
                && (below == Some(true) || above == Some(true))
        })
        .collect()
}

/// The height in the level frame that a fiftieth of the points lie below (`lowest`) or
/// above, when it lies beyond `MIN_LEVEL_DISTANCE` from the scanner on that side.
fn extreme_height(lv: &Leveled, lowest: bool) -> Option<f64> {
    let sign = if lowest { 1.0 } else { -1.0 };
    let mut z: Vec<f64> = lv.q.iter().flatten().map(|(q, _)| sign * q.z).collect();
    if z.len() < 50 {
        return None;
    }
    let k = z.len() / 50;
    let (_, m, _) = z.select_nth_unstable_by(k, f64::total_cmp);
    (*m < -MIN_LEVEL_DISTANCE).then_some(sign * *m)
}

/// The points within `refine_k` of their vertical tolerance (range noise along the vertical,
/// and an error of up `sigma_up` at their horizontal distance) above `height` (`above`) or
/// below it.
fn level_band<'a>(
    lv: &'a Leveled,
    height: f64,
    above: bool,
    sigma_up: f64,
    k: f64,
    s: f64,
    params: &'a LevelParams,
) -> impl Iterator<Item = usize> + 'a {
    lv.q.iter().enumerate().filter_map(move |(i, q)| {
        let (q, d) = q.as_ref()?;
        let lever = q.xy().norm() * sigma_up;
        let band = k * (s * s * d.z * d.z + lever * lever).sqrt() + params.flat_margin;
        let into = if above { q.z - height } else { height - q.z };
        (into < band).then_some(i)
    })
}

/// Fewest points stepping as a ceiling does ([`LevelSteps::ceiling`]) among the highest
/// points for these to stand for a ceiling in [`refine`]. Over 405,000 protocol poses at
/// 1-10 cm (seeds 101-150, nine plans): poses more than 3 degrees off 498 -> 477, beyond 3
/// sigmas 409 -> 395, ok and more than 5 degrees off 28 -> 27, for 0.02 points fewer leveled
/// (at 15 the same within a few poses; with no such condition, a point fewer leveled).
const CEILING_BAND_MIN_STEPS: usize = 5;

/// Lines closer in direction than this \[deg\] are pieces of one wall when both reach a point.
const SIMILAR_LINES_DEG: f64 = 20.0;

/// New walls in the level frame, found scan by scan: a run of consecutive rays whose points
/// lie on one 2D line within their noise (along-beam noise projected on the line's normal)
/// seeds a line, which grows ray by ray while the next point stays within `refine_k` sigmas.
/// This is the classic line extraction of a planar scan (e.g. Nguyen et al. 2005, "A
/// comparison of line extraction algorithms using 2D laser rangefinder"), applied to each
/// leveled scan; lines of different scans on one wall are merged afterwards.
fn discover_lines(
    grid: &PoseGrid,
    lv: &Leveled,
    candidate: &[bool],
    width: usize,
    params: &LevelParams,
    s: f64,
) -> Vec<Line> {
    let cols = grid.cols;
    let min_points = params.min_patch_points.max(width);
    let k = params.refine_k;
    let point = |i: usize| -> Option<(Vector2<f64>, Vector2<f64>, f64)> {
        if !candidate[i] {
            return None;
        }
        let (q, d) = lv.q[i].as_ref()?;
        Some((Vector2::new(q.x, q.y), Vector2::new(d.x, d.y), q.z))
    };
    let mut out = Vec::new();
    for r in 0..grid.rows() {
        let row = r * cols;
        let mut c = 0;
        while c + width <= cols {
            let mut acc = Line2::default();
            let mut unusable = None;
            for j in c..c + width {
                match point(row + j) {
                    Some((p, d, z)) => acc.add(&p, &d, z),
                    None => {
                        unusable = Some(j);
                        break;
                    }
                }
            }
            // Every seed over an unusable ray fails: the next one starts past it.
            if let Some(j) = unusable {
                c = j + 1;
                continue;
            }
            let Some(mut line) = acc
                .line()
                .filter(|l| acc.misfit(l, s, params.min_sigma) <= SEED_MISFIT)
            else {
                c += 1;
                continue;
            };
            let mut end = c + width;
            let mut gap = 0;
            let mut refit_at = acc.n * 5 / 4 + 1;
            while end < cols && gap <= MAX_GAP {
                let Some((p, d, z)) = point(row + end) else {
                    gap += 1;
                    end += 1;
                    continue;
                };
                let along = line.normal.dot(&d);
                let sd = (s * s * along * along + params.min_sigma.powi(2)).sqrt();
                if (line.normal.dot(&p) - line.offset).abs() > k * sd {
                    break;
                }
                gap = 0;
                acc.add(&p, &d, z);
                end += 1;
                if acc.n >= refit_at {
                    if let Some(l) = acc.line() {
                        line = l;
                    }
                    refit_at = acc.n * 5 / 4 + 1;
                }
            }
            if acc.n >= min_points {
                if let Some(l) = acc.line() {
                    out.push(l);
                }
            }
            c = end;
        }
    }
    out
}

/// A seed's points must fit its line within this multiple of the residual their noise
/// explains \[1\].
const SEED_MISFIT: f64 = 2.0;

/// Rays without a usable point that a growing line may step over.
const MAX_GAP: usize = 2;

/// Sums for a 2D total-least-squares line.
#[derive(Clone, Copy, Debug, Default)]
struct Line2 {
    n: usize,
    sum: Vector2<f64>,
    sxx: f64,
    sxy: f64,
    syy: f64,
    z: f64,
    /// Sum of the squared ray directions (for the noise along the normal).
    dxx: f64,
    dxy: f64,
    dyy: f64,
}

impl Line2 {
    fn add(&mut self, p: &Vector2<f64>, d: &Vector2<f64>, z: f64) {
        self.n += 1;
        self.sum += p;
        self.sxx += p.x * p.x;
        self.sxy += p.x * p.y;
        self.syy += p.y * p.y;
        self.z += z;
        self.dxx += d.x * d.x;
        self.dxy += d.x * d.y;
        self.dyy += d.y * d.y;
    }

    fn line(&self) -> Option<Line> {
        if self.n < 3 {
            return None;
        }
        let n = self.n as f64;
        let c = self.sum / n;
        let (a, b, d) = (
            self.sxx / n - c.x * c.x,
            self.sxy / n - c.x * c.y,
            self.syy / n - c.y * c.y,
        );
        // Minor axis of the 2x2 scatter [[a, b], [b, d]].
        let half = 0.5 * (a - d);
        let root = (half * half + b * b).sqrt();
        let minor = 0.5 * (a + d) - root;
        let normal = if b.abs() > 1e-15 {
            Vector2::new(b, minor - a)
        } else if a < d {
            Vector2::new(1.0, 0.0)
        } else {
            Vector2::new(0.0, 1.0)
        }
        .try_normalize(1e-300)?;
        Some(Line {
            normal,
            offset: normal.dot(&c),
            z: self.z / n,
            weight: n,
        })
    }

    /// Residual variance about `l` over what the noise explains.
    fn misfit(&self, l: &Line, s: f64, min_sigma: f64) -> f64 {
        let n = self.n as f64;
        let c = self.sum / n;
        let (u, v) = (l.normal.x, l.normal.y);
        let scatter = (self.sxx / n - c.x * c.x) * u * u
            + 2.0 * (self.sxy / n - c.x * c.y) * u * v
            + (self.syy / n - c.y * c.y) * v * v;
        let dn2 = (self.dxx * u * u + 2.0 * self.dxy * u * v + self.dyy * v * v) / n;
        let expected = s * s * dn2 + min_sigma * min_sigma;
        scatter * n / (n - 2.0).max(1.0) / expected
    }
}

/// Refit-and-reassign rounds when a floor or ceiling is first found.
const LEVEL_ROUNDS: usize = 3;

/// Floor or ceiling candidates must be this far from the scanner's height \[m\]: a level plane
/// through the scanner is seen edge-on.
const MIN_LEVEL_DISTANCE: f64 = 0.1;

/// Whether the plane through `point` with unit `normal` passes clear of the scanner, as a
/// floor's or ceiling's must, not only its points: each scan's points lie in that scan's own
/// plane through the scanner whatever they hit, so a band of wall points from one or two scans
/// (near the hinge axis the scans nearly coincide) fits a plane through the scanner that can
/// pass for level. One such "ceiling", 7 cm above the scanner over wall points alone, leveled
/// a pose 6 degrees off with a sigma of 0.7.
fn clear_of_scanner(normal: &Vector3<f64>, point: &nalgebra::Point3<f64>) -> bool {
    normal.dot(&point.coords).abs() >= MIN_LEVEL_DISTANCE
}

fn fit_members(grid: &PoseGrid, members: &[usize], sigma: f64) -> Option<PlaneFit> {
    grid.accumulate(members).fit(sigma)
}

/// Rows holding at least `share` of the members each.
fn rows_supported(grid: &PoseGrid, members: &[usize], share: f64) -> usize {
    let mut per_row = vec![0usize; grid.rows()];
    let rc = grid.row_col();
    for &i in members {
        per_row[rc.row(i)] += 1;
    }
    supported_rows(&per_row, share)
}

/// Rows holding a fair share of `per_row`'s points: `share` of them, or half of an even
/// split among the rows that hold any when that is less. Five scans on one floor hold about a
/// fifth each, so a fixed fifth failed such floors half the time.
pub(crate) fn supported_rows(per_row: &[usize], share: f64) -> usize {
    let total: usize = per_row.iter().sum();
    let present = per_row.iter().filter(|&&n| n > 0).count().max(1);
    let least = (share.min(0.5 / present as f64) * total as f64).max(1.0);
    per_row.iter().filter(|&&n| n as f64 >= least).count()
}

/// A wall's rows count towards `refine_min_rows` only with this share of its points each: a
/// scan line plus a few stray points of another scan leaves the plane free to turn about the
/// line.
const WALL_ROW_SHARE: f64 = 0.15;

/// A level plane from one scan line is that scan's own plane (a line on the floor leaves the
/// plane free to turn about it): at least two rows must each hold a fifth of the points.
fn two_rows_support(grid: &PoseGrid, members: &[usize]) -> bool {
    rows_supported(grid, members, 0.2) >= 2
}

/// Whether a level plane spans three scans. Two scan lines that meet are coplanar whatever
/// they lie on (a floor line and a wall's foot line), so a plane over two scans fits well and
/// can still lean by degrees: it is no evidence of its own that its points are one surface.
fn three_rows_support(grid: &PoseGrid, members: &[usize]) -> bool {
    rows_supported(grid, members, WALL_ROW_SHARE) >= 3
}

/// Merges lines that are one wall: normals within `refine_merge_deg` and each one's pivot
/// within the tolerance of the other (region growing splits one noisy wall into several
/// patches; left apart they would claim the same points, which would then be dropped as
/// ambiguous).
fn merge_lines(lines: &mut Vec<Line>, params: &LevelParams, s: f64) {
    let cos_max = params.refine_merge_deg.to_radians().cos();
    let tol = params.refine_k * s + params.flat_margin;
    let mut i = 0;
    while i < lines.len() {
        let mut j = i + 1;
        while j < lines.len() {
            let (a, b) = (lines[i], lines[j]);
            let c = a.normal.dot(&b.normal);
            let (bn, bo) = if c < 0.0 {
                (-b.normal, -b.offset)
            } else {
                (b.normal, b.offset)
            };
            if c.abs() >= cos_max && (a.offset - bo).abs() <= tol {
                let w = a.weight + b.weight;
                let normal = (a.normal * a.weight + bn * b.weight).normalize();
                lines[i] = Line {
                    normal,
                    offset: (a.offset * a.weight + bo * b.weight) / w,
                    z: (a.z * a.weight + b.z * b.weight) / w,
                    weight: w,
                };
                lines.swap_remove(j);
            } else {
                j += 1;
            }
        }
        i += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::level::grid::GridPoint;

    /// A level robot's grid of three rows with the given noise-free points per row.
    fn grid_of(rows: [Vec<Vector3<f64>>; 3]) -> PoseGrid {
        let cols = rows.iter().map(Vec::len).max().unwrap_or(0);
        let mut points = Vec::new();
        for row in &rows {
            for c in 0..cols {
                points.push(row.get(c).map(|p| GridPoint {
                    p: nalgebra::Point3::from(*p),
                    dir: p.normalize(),
                    range: p.norm(),
                }));
            }
        }
        PoseGrid {
            scan_index: vec![0, 1, 2],
            elevation: vec![-0.087, 0.0, 0.087],
            cols,
            points,
        }
    }

    /// `n` points from `a` to `b`.
    fn run(a: Vector3<f64>, b: Vector3<f64>, n: usize) -> Vec<Vector3<f64>> {
        (0..n)
            .map(|k| a + (b - a) * (k as f64 / (n - 1) as f64))
            .collect()
    }

    /// `n` points across the robot's path, `x` ahead, from 1 m right to 1 m left, at
    /// height `z`.
    fn across(x: f64, z: f64, n: usize) -> Vec<Vector3<f64>> {
        run(Vector3::new(x, -1.0, z), Vector3::new(x, 1.0, z), n)
    }

    fn floor_evidence(grid: &PoseGrid) -> LevelEvidence {
        floor_evidence_within(grid, 0.2f64.to_radians())
    }

    /// [`level_lines`]' floor in the robot frame taken as level, up known within `sigma_up`.
    fn floor_evidence_within(grid: &PoseGrid, sigma_up: f64) -> LevelEvidence {
        let lv = Leveled::new(grid, &Rotation3::identity());
        let all = vec![true; grid.points.len()];
        let none = vec![false; grid.points.len()];
        let ctx = LineContext {
            grid,
            lv: &lv,
            levelish: &all,
            taken: &none,
            up: &Vector3::z(),
            s: 0.01,
            sigma_up,
        };
        level_lines(&ctx, SurfaceKind::Floor, &LevelParams::default())
    }

    /// Two scans' floor lines stand only when their points fit one plane. From a loose start
    /// (up known within `MAX_SIGMA_UP`) a wall's foot 10 cm up at another bearing passes for
    /// floor by its height, but is skew to the floor line ahead (traced on a zigzag wall,
    /// where such a pair leveled a pose 8 degrees off with a sigma of 0.4); one floor's two
    /// lines make a plane.
    #[test]
    fn two_floor_lines_must_fit_one_plane() {
        let evidence = |side_z: f64| {
            let side = run(
                Vector3::new(0.5, -2.5, side_z),
                Vector3::new(2.5, -1.5, side_z),
                20,
            );
            let grid = grid_of([Vec::new(), across(2.0, -0.45, 20), side]);
            floor_evidence_within(&grid, MAX_SIGMA_UP)
        };
        assert!(matches!(evidence(-0.35), LevelEvidence::None));
        assert!(matches!(evidence(-0.45), LevelEvidence::Plane(..)));
    }

    /// A level plane's lean from up counts against the plane's own noise and up's: many
    /// sigmas when up is known to 0.2 degrees, about one when up is as uncertain as the lean.
    #[test]
    fn level_z2_weighs_a_lean_against_both_uncertainties() {
        let grid = grid_of([across(2.0, -0.45, 21), across(3.0, -0.45, 21), vec![]]);
        let members: Vec<usize> = (0..42).collect();
        let fit = grid.accumulate(&members).fit(0.0).unwrap();
        let lean = 3f64.to_radians();
        let up = Vector3::new(lean.sin(), 0.0, lean.cos());
        let level = level_z2(&fit, &Vector3::z(), 0.01, 0.2f64.to_radians());
        assert!(level < 1e-12, "{level}");
        let tight = level_z2(&fit, &up, 0.01, 0.2f64.to_radians());
        let loose = level_z2(&fit, &up, 0.01, lean);
        assert!(tight > 200.0, "{tight}");
        assert!((0.9..1.0).contains(&loose), "{loose}");
    }

    /// A level start from floor points in two scans only is loose (any two scan lines that
    /// meet are coplanar); from three it is as tight as its fit.
    #[test]
    fn a_level_start_over_two_scans_is_loose() {
        let params = LevelParams::default();
        let floor = |x: f64| across(x, -0.45, 41);
        let two = grid_of([floor(2.0), floor(3.0), vec![]]);
        let three = grid_of([floor(2.0), floor(3.0), floor(4.5)]);
        let sigma_of = |grid: &PoseGrid| {
            let steps = level_steps(grid, &params, 0.01);
            level_start(grid, &steps, &params, 0.01)
                .expect("a level start")
                .max_attitude_sigma()
        };
        let (two, three) = (sigma_of(&two), sigma_of(&three));
        assert!(two >= MAX_SIGMA_UP, "{two}");
        assert!(three < 0.1f64.to_radians(), "{three}");
    }

    /// The floor just in front of a wall's foot steps less than `r de` to the wall above it:
    /// no `floor` point, but a `floor_line` candidate by its step's sign; the wall is neither.
    #[test]
    fn the_floor_in_front_of_a_wall_foot_is_a_floor_line_candidate() {
        let wall = across(3.0, 0.0, 21);
        let grid = grid_of([wall.clone(), wall, across(2.8, -0.45, 21)]);
        let steps = level_steps(&grid, &LevelParams::default(), 0.01);
        let row = |mask: &[bool], r: usize| mask[r * 21..(r + 1) * 21].to_vec();
        let (all, none) = (vec![true; 21], vec![false; 21]);
        assert_eq!(row(&steps.floor, 2), none);
        assert_eq!(row(&steps.floor_line, 2), all);
        assert_eq!(row(&steps.ceiling, 2), none);
        assert_eq!(row(&steps.floor_line, 0), none);
        assert_eq!(row(&steps.floor_line, 1), none);
        // Within the noise of two ranges the sign says nothing.
        let grid = grid_of([
            across(3.0, 0.0, 21),
            across(3.0, 0.0, 21),
            across(2.99, -0.2, 21),
        ]);
        let steps = level_steps(&grid, &LevelParams::default(), 0.01);
        assert_eq!(row(&steps.floor_line, 2), none);
    }

    /// A scan's few floor points join the plane through another scan's floor line (their lever
    /// arm pins its tilt); alone, so few points are no line.
    #[test]
    fn a_short_floor_line_joins_a_full_one_in_a_plane() {
        let short = || {
            run(
                Vector3::new(3.5, -0.2, -0.45),
                Vector3::new(3.5, 0.2, -0.45),
                5,
            )
        };
        let grid = grid_of([Vec::new(), across(2.0, -0.45, 20), short()]);
        let LevelEvidence::Plane(fit, members) = floor_evidence(&grid) else {
            panic!("expected a floor plane");
        };
        assert_eq!(members.len(), 25);
        // Within a hundredth of a degree of level (the fit takes the noise's bias out of
        // noise-free points).
        assert!(
            fit.normal.z.abs() > 0.01f64.to_radians().cos(),
            "{:?}",
            fit.normal
        );
        let grid = grid_of([Vec::new(), Vec::new(), short()]);
        assert!(matches!(floor_evidence(&grid), LevelEvidence::None));
    }

    #[test]
    fn level_lines_take_the_floor_not_a_raised_box_top() {
        // A box top 25 cm above the floor holds twice the floor's points; the floor is the
        // lowest level surface.
        let box_top = run(
            Vector3::new(1.5, -0.4, -0.2),
            Vector3::new(1.5, 0.4, -0.2),
            40,
        );
        let floor = across(1.2, -0.45, 20);
        let grid = grid_of([Vec::new(), box_top, floor]);
        let LevelEvidence::Lines(lines) = floor_evidence(&grid) else {
            panic!("expected one floor line");
        };
        assert_eq!(lines.len(), 1);
        assert_eq!(lines[0].n, 20);
        assert!((lines[0].centroid.z + 0.45).abs() < 1e-9);
        assert!(lines[0].dir.z.abs() < 1e-9);
    }

    /// Two floor lines at different azimuths lie in one plane; a far wall's line at the
    /// scanner's height with a floor line does not (the pose that set a start 8 degrees off:
    /// 14 cm out of one plane over 4 m).
    #[test]
    fn floor_lines_are_coplanar_and_a_far_wall_line_is_not() {
        let line = |a: Vector3<f64>, b: Vector3<f64>| {
            let pts: Vec<_> = run(a, b, 30)
                .into_iter()
                .map(|p| (nalgebra::Point3::from(p), p.normalize()))
                .collect();
            LevelLine::fit(&pts, 0.05, 0.001).unwrap()
        };
        let floor_ahead = line(
            Vector3::new(2.0, -1.0, -0.45),
            Vector3::new(2.0, 1.0, -0.45),
        );
        let floor_side = line(
            Vector3::new(0.5, -2.5, -0.45),
            Vector3::new(2.5, -1.5, -0.45),
        );
        let far_wall = line(Vector3::new(2.0, 5.0, 0.0), Vector3::new(4.0, 6.0, 0.0));
        let params = LevelParams::default();
        assert!(coplanar(&floor_ahead, &floor_side, 0.05, &params));
        assert!(!coplanar(&floor_ahead, &far_wall, 0.05, &params));
        // Parallel lines always lie in one plane.
        let floor_far = line(
            Vector3::new(3.0, -1.0, -0.45),
            Vector3::new(3.0, 1.0, -0.45),
        );
        assert!(coplanar(&floor_ahead, &floor_far, 0.05, &params));
    }

    /// A line on its own that slopes in the provisional frame beyond that frame's uncertainty
    /// is no floor line, whatever its height: a far wall met near its foot by the level scan
    /// (a 4.6 degree slope against a frame good to 0.86 degrees) once set a pose 6 degrees off.
    #[test]
    fn a_sloping_line_is_no_floor_line() {
        let line = |slope_deg: f64| {
            let rise = 2.0 * slope_deg.to_radians().tan();
            grid_of([
                Vec::new(),
                Vec::new(),
                run(
                    Vector3::new(2.0, -1.0, -0.45 - rise / 2.0),
                    Vector3::new(2.0, 1.0, -0.45 + rise / 2.0),
                    30,
                ),
            ])
        };
        let frame = 0.86f64.to_radians();
        let fitted = |grid: &PoseGrid| {
            let idx: Vec<usize> = (0..grid.points.len())
                .filter(|&i| grid.points[i].is_some())
                .collect();
            fit_line(
                grid,
                idx,
                &Vector3::z(),
                Some(frame),
                0.01,
                &LevelParams::default(),
                10,
            )
        };
        assert!(fitted(&line(0.0)).is_some());
        assert!(fitted(&line(1.0)).is_some());
        assert!(fitted(&line(4.6)).is_none());
    }

    /// Floor lines 2 and 3 m ahead, 0.45 m down, 30 points each, over `third` as the last row.
    fn two_floor_rows_and(third: Vec<Vector3<f64>>) -> PoseGrid {
        grid_of([across(2.0, -0.45, 30), across(3.0, -0.45, 30), third])
    }

    /// Two lines of points in one level plane, `x` and `x + 1.5` m ahead at height `z`, as one
    /// row of a grid (a band of wall points at one height looks like this).
    fn band(x: f64, z: f64) -> Vec<Vector3<f64>> {
        let mut pts = across(x, z, 30);
        pts.extend(across(x + 1.5, z, 30));
        pts
    }

    /// A plane through the scanner is a scan's own plane, no floor, however level; one at the
    /// scanner's height below it is.
    #[test]
    fn a_level_plane_must_pass_clear_of_the_scanner() {
        let fit_of = |grid: &PoseGrid| {
            let all: Vec<usize> = (0..grid.points.len()).collect();
            grid.accumulate(&all).fit(0.0).unwrap()
        };
        let floor = grid_of([across(2.0, -0.45, 21), across(3.0, -0.45, 21), vec![]]);
        let through = grid_of([band(2.0, 0.0), vec![], vec![]]);
        let clear = |f: PlaneFit| clear_of_scanner(&f.normal, &f.centroid);
        assert!(clear(fit_of(&floor)));
        assert!(!clear(fit_of(&through)));
    }

    proptest::proptest! {
        /// The early exit changes nothing: a count beats `best` exactly when the full count
        /// does, and is then the full count.
        #[test]
        fn counting_with_an_early_exit_agrees_with_a_full_count(
            on in proptest::collection::vec(proptest::bool::ANY, 0..80),
            best in proptest::option::of(0usize..90),
        ) {
            let idx: Vec<usize> = (0..on.len()).collect();
            let full = on.iter().filter(|&&b| b).count();
            let expected = best.is_none_or(|b| full > b).then_some(full);
            proptest::prop_assert_eq!(count_beating(&idx, |i| on[i], best), expected);
        }
    }

    /// The sample finds the plane of most points among those it samples from, passing clear
    /// of the scanner: a band of 60 wall points 15 cm below the scanner beats 40 floor points
    /// when sampled, not when only the floor's points (those stepping like a floor) are; a
    /// band through the scanner never wins.
    #[test]
    fn sampled_planes_come_from_the_sample_and_pass_clear_of_the_scanner() {
        let params = LevelParams::default();
        let level = |n: &Vector3<f64>| n.z.abs() > 5f64.to_radians().cos();
        let floor_rows = || [across(2.0, -0.45, 20), across(3.0, -0.45, 20)];
        let [f1, f2] = floor_rows();
        let grid = grid_of([band(3.0, -0.15), f1, f2]);
        let all: Vec<usize> = (0..grid.points.len())
            .filter(|&i| grid.points[i].is_some())
            .collect();
        let floor: Vec<usize> = all.iter().copied().filter(|&i| i >= grid.cols).collect();
        let from_all = sampled_plane(&grid, &all, &all, level, 0.01, &params).unwrap();
        assert_eq!(from_all.len(), 60);
        let from_floor = sampled_plane(&grid, &all, &floor, level, 0.01, &params).unwrap();
        assert_eq!(from_floor, floor);
        let [f1, f2] = floor_rows();
        let grid = grid_of([band(3.0, 0.0), f1, f2]);
        let got = sampled_plane(&grid, &all, &all, level, 0.01, &params).unwrap();
        assert_eq!(got, floor);
    }

    /// Three floor lines in one plane are one floor; a wall's line 14 cm above its foot with
    /// two floor lines is not, though it is parallel to (so coplanar with) each of them.
    #[test]
    fn three_lines_must_share_one_plane() {
        let params = LevelParams::default();
        let lines_of = |third: f64| {
            let grid = two_floor_rows_and(across(4.5, third, 30));
            let lines: Vec<(LevelLine, Vec<usize>)> = (0..3)
                .map(|r| {
                    let idx: Vec<usize> = (r * grid.cols..(r + 1) * grid.cols).collect();
                    fit_line(&grid, idx, &Vector3::z(), None, 0.01, &params, 10).unwrap()
                })
                .collect();
            (grid, lines)
        };
        let (grid, lines) = lines_of(-0.45);
        assert!(one_plane(&grid, &lines, 0.01, &params));
        let (grid, lines) = lines_of(-0.31);
        assert!(coplanar(&lines[0].0, &lines[2].0, 0.01, &params));
        assert!(!one_plane(&grid, &lines, 0.01, &params));
        assert!(one_plane(&grid, &lines[..2], 0.01, &params));
    }

    /// A floor's edge row 6 cm above the plane of its other rows (the walls' feet seen by the
    /// scan above the floor) is trimmed; a floor's own rows, or two rows alone, are kept.
    #[test]
    fn an_edge_row_above_the_floor_is_trimmed() {
        let params = LevelParams::default();
        let trimmed = |rows: [Vec<Vector3<f64>>; 3]| {
            let grid = grid_of(rows);
            let all: Vec<usize> = (0..grid.points.len())
                .filter(|&i| grid.points[i].is_some())
                .collect();
            let kept = without_standing_rows(&grid, all.clone(), 0.01, &params);
            (all.len(), kept.len())
        };
        let floor = |x: f64| across(x, -0.45, 30);
        assert_eq!(trimmed([floor(2.0), floor(3.0), floor(4.5)]), (90, 90));
        assert_eq!(
            trimmed([across(4.5, -0.39, 30), floor(3.0), floor(2.0)]),
            (90, 60)
        );
        assert_eq!(
            trimmed([floor(2.0), floor(3.0), across(4.5, -0.39, 30)]),
            (90, 60)
        );
        assert_eq!(
            trimmed([floor(2.0), across(4.5, -0.39, 30), vec![]]),
            (60, 60)
        );
    }

    /// Five rows of one floor, a fifth each give or take, all count; so do three rows of
    /// seven; a line of a tenth of the points beside another line does not.
    #[test]
    fn rows_with_a_fair_share_support_a_plane() {
        assert_eq!(supported_rows(&[72, 72, 73, 88, 69], 0.2), 5);
        assert_eq!(supported_rows(&[10, 10, 10, 10, 10, 10, 10], 0.15), 7);
        assert_eq!(supported_rows(&[0, 90, 10], 0.2), 1);
        assert_eq!(supported_rows(&[0, 0, 0], 0.2), 0);
    }

    /// Nothing is seen through a floor: a plane with ten points 20 cm beneath it is no floor;
    /// the same plane with the points above it (a box on the floor) is.
    #[test]
    fn a_floor_with_points_beneath_it_is_no_floor() {
        let params = LevelParams::default();
        let fit_and_grid = |third: f64| {
            let grid = two_floor_rows_and(across(2.5, third, 10));
            let floor: Vec<usize> = (0..2 * grid.cols).collect();
            let fit = grid.accumulate(&floor).fit(0.01).unwrap();
            (grid, fit)
        };
        let (grid, fit) = fit_and_grid(-0.65);
        assert!(!opaque(&grid, &fit, 0.01, &params));
        let (grid, fit) = fit_and_grid(-0.25);
        assert!(opaque(&grid, &fit, 0.01, &params));
    }

    #[test]
    fn level_lines_refuse_a_wall_line_near_its_foot() {
        // Two floor lines 0.8 m apart, and a wall's line 3 m ahead, 3 cm above the floor: at
        // the floor's height within the tolerance and level, but not in the plane of the other
        // two. Which line is wrong is not known, so none is used.
        let wall = across(3.0, -0.42, 30);
        let near = across(1.2, -0.45, 30);
        let far = across(2.0, -0.45, 30);
        let grid = grid_of([wall, far.clone(), near.clone()]);
        assert!(matches!(floor_evidence(&grid), LevelEvidence::None));
        // A wall's line that rises along the wall (from 1.5 to 4.5 cm above the floor) is no
        // level line at all: the floor lines alone are the floor.
        let rising = run(
            Vector3::new(3.0, -1.0, -0.435),
            Vector3::new(3.0, 1.0, -0.405),
            30,
        );
        let floor_plane = |grid: &PoseGrid| {
            let LevelEvidence::Plane(fit, members) = floor_evidence(grid) else {
                panic!("expected the floor plane");
            };
            assert_eq!(members.len(), 60);
            // (The fit removes range noise that these exact points do not have.)
            assert!(fit.normal.z.abs() > 1.0 - 1e-6);
            assert!((fit.centroid.z + 0.45).abs() < 1e-9);
        };
        floor_plane(&grid_of([rising, far.clone(), near.clone()]));
        // Without the wall's line, the two floor lines are one level plane.
        floor_plane(&grid_of([Vec::new(), far, near]));
    }

    #[test]
    fn line2_fits_points_on_a_line_exactly() {
        // The line x cos(a) + y sin(a) = 2.
        let a: f64 = 0.7;
        let n = Vector2::new(a.cos(), a.sin());
        let t = Vector2::new(-a.sin(), a.cos());
        let mut acc = Line2::default();
        for k in 0..10 {
            let p = n * 2.0 + t * (k as f64 * 0.3 - 1.0);
            acc.add(&p, &p.normalize(), 0.1 * k as f64);
        }
        let l = acc.line().unwrap();
        let sign = l.normal.dot(&n).signum();
        assert!((l.normal * sign - n).norm() < 1e-12);
        assert!((l.offset * sign - 2.0).abs() < 1e-12);
        assert!((l.z - 0.45).abs() < 1e-12);
        assert!(acc.misfit(&l, 0.01, 0.001) < 1e-12);
    }

    #[test]
    fn merge_lines_joins_pieces_of_one_wall_but_not_a_corner() {
        let line = |deg: f64, offset: f64, weight: f64| {
            let a = deg.to_radians();
            Line {
                normal: Vector2::new(a.cos(), a.sin()),
                offset,
                z: 0.0,
                weight,
            }
        };
        let params = LevelParams::default();
        // Two pieces of the wall x = 3 (one with the opposite normal), and the wall y = 3.
        let mut lines = vec![
            line(0.0, 3.0, 100.0),
            line(182.0, -3.02, 50.0),
            line(90.0, 3.0, 80.0),
        ];
        merge_lines(&mut lines, &params, 0.01);
        assert_eq!(lines.len(), 2);
        let x_wall = lines.iter().find(|l| l.normal.x.abs() > 0.9).unwrap();
        assert_eq!(x_wall.weight, 150.0);
        assert!((x_wall.offset.abs() - 3.0).abs() < 0.02);
    }
}
