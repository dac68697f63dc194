//! The floor and the ceiling in the provisional level frame: found by height (the densest
//! band below and above the scanner, then refit-and-reassign rounds), and the checks a level
//! plane must pass (clear of the scanner, nothing seen through it, agreeing with up).

use super::*;

/// Whether (almost) no point lies beyond a floor's or ceiling's plane: the scanner sees
/// nothing through a floor or a ceiling, so points more than `refine_k` sigmas beyond the
/// plane on the side away from the scanner (below a floor, above a ceiling), counting its tilt
/// uncertainty over their distance, mean a wrong plane. A wall's line and the floor's line of
/// the next scan, both across the view, are parallel and so always coplanar: one such "floor",
/// tilted 13 degrees from the true one, had 13 of the pose's 543 points beyond it.
pub(crate) fn opaque(grid: &PoseGrid, fit: &PlaneFit, s: f64, params: &LevelParams) -> bool {
    let model = LevelModel::new(fit, s);
    // Away from the scanner, which sits at the robot frame's origin.
    let normal = fit.normal * fit.normal.dot(&fit.centroid.coords).signum();
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

/// Squared angle between a level model's normal and up, in variances: the model's normal
/// noise, inflated by its misfit, and up's own (`sigma_up` \[rad\]).
pub(crate) fn level_z2(fit: &PlaneFit, up: &Vector3<f64>, s: f64, sigma_up: f64) -> f64 {
    let n = fit.normal * fit.normal.dot(up).signum();
    let off = up - n * n.dot(up);
    let Some(u) = off.try_normalize(1e-12) else {
        return 0.0;
    };
    let var = fit.normal_variance_along(&u, s) * fit.misfit_ratio(s).max(1.0) + sigma_up * sigma_up;
    off.norm_squared() / var
}

/// A level plane with what assigning points to it needs.
pub(crate) struct LevelModel<'a> {
    pub(crate) fit: &'a PlaneFit,
    /// The plane's own tilt uncertainty \[rad\].
    pub(crate) tilt: f64,
}

impl<'a> LevelModel<'a> {
    pub(crate) fn new(fit: &'a PlaneFit, s: f64) -> Self {
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
    pub(crate) fn distance_sd(&self, g: &GridPoint, s: f64, min_sigma: f64) -> (f64, f64) {
        let f = self.fit;
        let v = g.p - f.centroid;
        let d = f.normal.dot(&v);
        let lever2 = (v.norm_squared() - d * d).max(0.0) * self.tilt * self.tilt;
        let sd = (s * s * g.dir.dot(&f.normal).powi(2) + min_sigma * min_sigma + lever2).sqrt();
        (d.abs(), sd)
    }
}

/// The floor and ceiling planes to assign from in frame `f`: the densest height among the
/// usable (`ok`) points below (floor) and above (ceiling) the scanner in the level frame, where
/// at least
/// `min_level_points` points lie within the tolerance of one height ([`height_window`]),
/// refitted in rounds ([`refit_rounds`]) and kept when level within `refine_max_tilt_deg` of
/// up, explaining its points and clear of the scanner (sect. 5.3 takes floors and ceilings as
/// the level constraints).
pub(crate) fn find_levels(f: &Frame, ok: &[bool]) -> Vec<PlaneFit> {
    let (grid, params, up, s) = (f.grid, f.params, &f.up, f.s);
    let mut out: Vec<PlaneFit> = Vec::new();
    for floor in [true, false] {
        let mut zs = height_candidates(&f.lv, floor, |i| ok[i]);
        if !floor {
            // By height, ascending, as for the floor.
            zs = zs.into_iter().rev().map(|(z, i)| (-z, i)).collect();
        }
        // The most populous window (the lowest such), when it holds `min_level_points`.
        let min_points = params.min_level_points;
        let Some((lo, hi)) = height_window(f, &zs, |n, most| n == most && n >= min_points) else {
            continue;
        };
        let window: Vec<usize> = zs[lo..hi].iter().map(|&(_, i)| i).collect();
        // The window holds wall points too (a wall's foot, or a band of wall at one height
        // in a frame degrees off): the plane through most of its points, rather than through
        // all of them, starts the rounds.
        let levelish = |i: &usize| f.steps.levelish[*i];
        let stepping: Vec<usize> = window.iter().copied().filter(levelish).collect();
        let cos = params.refine_level_cos();
        let level = |n: &Vector3<f64>| n.dot(up).abs() >= cos;
        let members = sampled_plane(grid, &window, &stepping, level, s, params).unwrap_or(window);
        let fit = refit_rounds(grid, &zs, members, params, s);
        out.extend(fit.filter(|fit| checks::refined_level(fit, up, s, params)));
    }
    out
}

/// The candidates for the floor (`floor`) or the ceiling: the points that `keep` accepts more
/// than `MIN_LEVEL_DISTANCE` below or above the scanner in the level frame, as (height key
/// growing away from the surface's side, grid index), ascending: the outermost first.
pub(crate) fn height_candidates(
    lv: &Leveled,
    floor: bool,
    keep: impl Fn(usize) -> bool,
) -> Vec<(f64, usize)> {
    let key = |z: f64| if floor { z } else { -z };
    let mut zs: Vec<(f64, usize)> = lv
        .iter()
        .enumerate()
        .filter_map(|(i, q)| {
            let (q, _) = q.as_ref()?;
            (keep(i) && key(q.z) < -MIN_LEVEL_DISTANCE).then_some((key(q.z), i))
        })
        .collect();
    zs.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    zs
}

/// The first height window over the ascending heights `zs` whose count `accept(count,
/// densest)` takes, as `lo..hi`: per start `lo`, the heights within `2 half` of `zs[lo]`, where
/// `half` is `refine_k` times the vertical tolerance of a typical grazing floor hit
/// (`GRAZING_RAY_DZ` of the noise and up's error over `GRAZING_LEVER`), plus `flat_margin`. The
/// one height-window scan behind the floor and ceiling searches (by height in [`find_levels`],
/// by lines in `level_lines`).
pub(crate) fn height_window(
    f: &Frame,
    zs: &[(f64, usize)],
    accept: impl Fn(usize, usize) -> bool,
) -> Option<(usize, usize)> {
    let params = f.params;
    let half =
        params.refine_k * (GRAZING_RAY_DZ * f.s + GRAZING_LEVER * f.sigma_up) + params.flat_margin;
    let mut windows = Vec::with_capacity(zs.len());
    let mut hi = 0;
    for lo in 0..zs.len() {
        while hi < zs.len() && zs[hi].0 - zs[lo].0 <= 2.0 * half {
            hi += 1;
        }
        windows.push((lo, hi));
    }
    let densest = windows.iter().map(|(lo, hi)| hi - lo).max().unwrap_or(0);
    windows
        .into_iter()
        .find(|&(lo, hi)| accept(hi - lo, densest))
}

/// `LEVEL_ROUNDS` rounds of refit and reassignment from `members`: the window's plane is only
/// as level as the provisional up, so far points fall outside it at first. Each round takes
/// the candidates `zs` within `refine_k` of their distance's standard deviation
/// ([`LevelModel`]); `None` once too few points or scan lines remain.
fn refit_rounds(
    grid: &PoseGrid,
    zs: &[(f64, usize)],
    mut members: Vec<usize>,
    params: &LevelParams,
    s: f64,
) -> Option<PlaneFit> {
    for round in 0..LEVEL_ROUNDS {
        let f = supported_level_fit(grid, &members, params, s)?;
        if round + 1 == LEVEL_ROUNDS {
            return Some(f);
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
    None
}

/// The height in the level frame that a fiftieth of the points lie below (`lowest`) or
/// above, when it lies beyond `MIN_LEVEL_DISTANCE` from the scanner on that side.
pub(crate) fn extreme_height(lv: &Leveled, lowest: bool) -> Option<f64> {
    let sign = if lowest { 1.0 } else { -1.0 };
    let mut z: Vec<f64> = lv.iter().flatten().map(|(q, _)| sign * q.z).collect();
    if z.len() < 50 {
        return None;
    }
    let k = z.len() / 50;
    let (_, m, _) = z.select_nth_unstable_by(k, f64::total_cmp);
    (*m < -MIN_LEVEL_DISTANCE).then_some(sign * *m)
}

/// The points of frame `f` within `refine_k` of their vertical tolerance (range noise along the
/// vertical, and an error of up `sigma_up` at their horizontal distance) above `height`
/// (`above`) or below it.
pub(crate) fn level_band<'a>(
    f: &'a Frame,
    height: f64,
    above: bool,
) -> impl Iterator<Item = usize> + Clone + 'a {
    let (s, k) = (f.s, f.k);
    f.lv.iter().enumerate().filter_map(move |(i, q)| {
        let (q, d) = q.as_ref()?;
        let lever = q.xy().norm() * f.sigma_up;
        let band = k * (s * s * d.z * d.z + lever * lever).sqrt() + f.params.flat_margin;
        let into = if above { q.z - height } else { height - q.z };
        (into < band).then_some(i)
    })
}
