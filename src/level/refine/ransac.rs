//! A level plane found without any frame (RANSAC, Fischler and Bolles 1981, over a
//! deterministic sample of point triples): the start of re-segmentation when no first solution
//! exists.

use super::*;
use crate::level::params::up::*;

/// A start for poses where no first solution exists (the walls and region-grown floor could not
/// fix up): the plane through most of the points whose range steps like a level surface's
/// ([`LevelSteps::levelish`], which needs no up), found by a deterministic sample of point triples
/// (RANSAC, Fischler and Bolles 1981), taken as level. `None` when no such plane holds
/// `min_level_points` points in at least two scans with a normal within `MAX_TILT_DEG` (50 degrees) of the
/// robot's own up.
pub fn level_start(
    grid: &PoseGrid,
    steps: &LevelSteps,
    params: &LevelParams,
    sigma: f64,
) -> Option<UpSolution> {
    let s = sigma.max(params.min_sigma);
    let idx: Vec<usize> = (0..grid.points.len())
        .filter(|&i| steps.levelish[i] && grid.points[i].is_some())
        .collect();
    if idx.len() < params.min_level_points {
        return None;
    }
    let min_z = MAX_TILT_DEG.to_radians().cos();
    let members = sampled_plane(grid, &idx, &idx, |n| n.z.abs() >= min_z, s, params)?;
    let members = without_standing_rows(grid, members, s, params);
    let fit =
        supported_level_fit(grid, &members, params, sigma).filter(|f| f.normal.z.abs() >= min_z)?;
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
pub(crate) fn sampled_plane(
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
    let on = |i: usize, p0: &Point3<f64>, normal: &Vector3<f64>| {
        grid.points[i].as_ref().is_some_and(|g| {
            let beyond = normal.dot(&(g.p - p0)).abs() - params.flat_margin;
            beyond <= 0.0 || beyond * beyond <= k2 * (s * s * g.dir.dot(normal).powi(2) + floor2)
        })
    };
    // Counted per hypothesis (most lose by far, and are given up early); only the best one's
    // points are gathered.
    let mut best: Option<(usize, Point3<f64>, Vector3<f64>)> = None;
    for h in 0..START_HYPOTHESES {
        // Three points spread over the candidates: a fixed stride walk, no random state.
        let pick = |k: usize| sample[(h * (2 * k + 1) * 7 + k * n / 3) % n];
        let point = |k: usize| grid.points[pick(k)].as_ref();
        let (Some(pa), Some(pb), Some(pc)) = (point(0), point(1), point(2)) else {
            continue;
        };
        let (u, v) = (pb.p - pa.p, pc.p - pa.p);
        // Nearly collinear triples (one scan line) leave the plane free to turn.
        let normal = u
            .cross(&v)
            .try_normalize(COLLINEAR_SIN * u.norm() * v.norm());
        let Some(normal) = normal.filter(|n| accept(n) && clear_of_scanner(n, &pa.p)) else {
            continue;
        };
        if let Some(count) = count_beating(idx, |i| on(i, &pa.p, &normal), best.map(|b| b.0)) {
            best = Some((count, pa.p, normal));
        }
    }
    let (_, p0, normal) = best?;
    let on_best = |i: &usize| on(*i, &p0, &normal);
    Some(idx.iter().copied().filter(on_best).collect())
}

/// How many of `idx` satisfy `on`, when that beats `best` (more than it; anything beats
/// `None`); `None` as soon as the points left cannot beat it.
pub(crate) fn count_beating(
    idx: &[usize],
    on: impl Fn(usize) -> bool,
    best: Option<usize>,
) -> Option<usize> {
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
