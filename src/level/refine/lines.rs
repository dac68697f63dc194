//! Floor and ceiling lines: a scan's plane meets a level surface in a straight line whose
//! direction must be level. Found per scan among the points that step like a level surface's,
//! fitted with outliers removed, and taken as one plane when several scans' lines fit one.

use super::*;

/// Floor or ceiling evidence found by [`level_lines`].
pub(crate) enum LevelEvidence {
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
/// `level_line_misfit` of its noise. With two or more scans, the lines
/// are one plane (its lever arm is the distance between the lines) when their points fit one
/// within `refine_level_misfit`; in a plane with a full line, a line of as few as
/// [`PLANE_LINE_MIN_POINTS`] counts. The `candidate`s, in frame `f`, are the points that step
/// like the surface sought and that no wall or level model has taken.
pub(crate) fn level_lines(
    f: &Frame,
    kind: SurfaceKind,
    candidate: impl Fn(usize) -> bool,
) -> LevelEvidence {
    let (grid, params, s) = (f.grid, f.params, f.s);
    let zs = height_candidates(&f.lv, kind == SurfaceKind::Floor, candidate);
    let min_points = params.level_line_min_points.max(3);
    // The outermost window that holds `min_points` and a third as many as the densest (a box
    // top is not the floor); the surface's height key is its middle.
    let Some((lo, hi)) = height_window(f, &zs, |n, most| n >= min_points && 3 * n >= most) else {
        return LevelEvidence::None;
    };
    let height = zs[(lo + hi) / 2].0;
    let short = PLANE_LINE_MIN_POINTS.min(min_points);
    let found: Vec<(LevelLine, Vec<usize>)> = rows_at_height(f, &zs, height)
        .into_iter()
        .filter_map(|row| fit_line(grid, row, &f.up, Some(f.sigma_up), s, params, short))
        .collect();
    lines_evidence(f, found, min_points)
}

/// Per scan (grid row), the candidates `zs` within their own vertical tolerance of `height`:
/// `refine_k` standard deviations of the range noise along the vertical and an error of up
/// `sigma_up` at their horizontal distance, plus `flat_margin`.
fn rows_at_height(f: &Frame, zs: &[(f64, usize)], height: f64) -> Vec<Vec<usize>> {
    let (params, s, k) = (f.params, f.s, f.params.refine_k);
    let mut rows: Vec<Vec<usize>> = vec![Vec::new(); f.grid.rows()];
    for &(z, i) in zs {
        let Some((q, d)) = f.lv[i].as_ref() else {
            continue;
        };
        let lever = q.xy().norm() * f.sigma_up;
        let sd = (s * s * d.z * d.z + params.min_sigma * params.min_sigma + lever * lever).sqrt();
        if (z - height).abs() <= k * sd + params.flat_margin {
            rows[f.grid.row(i)].push(i);
        }
    }
    rows
}

/// What the fitted per-scan lines `found` are evidence of ([`level_lines`]): one plane when a
/// full line (`min_points`) and short ones fit one, else the full lines alone, as one plane
/// when two or more fit one ([`level_plane`]), else as lines when they are not skew beyond
/// `LINES_PLANE_MISFIT`; nothing when they cannot be one floor.
fn lines_evidence(
    f: &Frame,
    found: Vec<(LevelLine, Vec<usize>)>,
    min_points: usize,
) -> LevelEvidence {
    let (grid, params, s) = (f.grid, f.params, f.s);
    let full = |(l, _): &(LevelLine, Vec<usize>)| l.n >= min_points;
    // Short lines count only in a plane with a full one; without short lines, the full lines
    // alone are tried below.
    let full_lines = found.iter().filter(|l| full(l)).count();
    if full_lines > 0 && full_lines < found.len() && one_plane(grid, &found, s, params) {
        if let Some(plane) = lines_plane(grid, &found, s).and_then(|p| level_plane(f, p)) {
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
        // No plane at all is as bad.
        let plane = lines_plane(grid, &found, s);
        let skew = plane.as_ref().is_none_or(|p| skew_lines(&p.0, s));
        if let Some(plane) = plane.and_then(|p| level_plane(f, p)) {
            return plane;
        }
        if skew {
            return LevelEvidence::None;
        }
    }
    LevelEvidence::Lines(found.into_iter().map(|(l, _)| l).collect())
}

/// [`Check::LinesPlaneMisfit`](checks::Check::LinesPlaneMisfit): whether several scans'
/// lines are skew, the plane `fit` through their points misfitting beyond `LINES_PLANE_MISFIT`
/// at noise `s`.
pub(crate) fn skew_lines(fit: &PlaneFit, s: f64) -> bool {
    fit.misfit_ratio(s) > LINES_PLANE_MISFIT
}

/// The plane through level lines' points, with those points (ascending).
pub(crate) fn lines_plane(
    grid: &PoseGrid,
    lines: &[(LevelLine, Vec<usize>)],
    s: f64,
) -> Option<(PlaneFit, Vec<usize>)> {
    let mut members: Vec<usize> = lines.iter().flat_map(|(_, m)| m.iter().copied()).collect();
    members.sort_unstable();
    Some((grid.accumulate(&members).fit(s)?, members))
}

/// The plane `fit` through level lines' points `members` ([`lines_plane`]) as the floor or
/// ceiling, when it fits them: within `refine_level_misfit` of the noise,
/// near up, clear of the scanner, and with nothing seen through it.
fn level_plane(f: &Frame, (fit, members): (PlaneFit, Vec<usize>)) -> Option<LevelEvidence> {
    let (params, s) = (f.params, f.s);
    (checks::refined_level(&fit, &f.up, s, params) && opaque(f.grid, &fit, s, params))
        .then_some(LevelEvidence::Plane(fit, members))
}

/// Whether level lines (each with its points) can all lie in one plane: with three or more,
/// each must lie in the plane of the others' points. Any two lines pass, as do lines of one
/// floor seen by parallel scans (they leave the plane of any two free to tilt about them).
pub(crate) fn one_plane(
    grid: &PoseGrid,
    lines: &[(LevelLine, Vec<usize>)],
    s: f64,
    params: &LevelParams,
) -> bool {
    lines.len() < 3
        || (0..lines.len()).all(|i| {
            let others: Vec<usize> = lines
                .iter()
                .enumerate()
                .filter(|&(j, _)| j != i)
                .flat_map(|(_, (_, m))| m.iter().copied())
                .collect();
            grid.accumulate(&others).fit(s).is_some_and(|fit| {
                line_offset_sigmas(grid, &lines[i].1, &fit, s, params.min_sigma) <= params.refine_k
            })
        })
}

/// How far, in standard deviations, a line's points lie from a plane on average: the mean
/// signed distance against its noise (the points' range noise along the normal, averaged,
/// and the plane's tilt uncertainty at the line's distance from the plane's centroid).
pub(crate) fn line_offset_sigmas(
    grid: &PoseGrid,
    members: &[usize],
    fit: &PlaneFit,
    s: f64,
    min_sigma: f64,
) -> f64 {
    let model = LevelModel::new(fit, s);
    let (mut sum, mut var, mut centre, mut n) = (0.0, 0.0, Vector3::zeros(), 0.0);
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

/// One scan's points on a level surface as a [`LevelLine`], refitted without the points
/// farther than `refine_k` sigmas from it (vertically and horizontally, each with its range
/// noise along that direction); `None` when fewer than `min_points` (at least 3) remain or the
/// rest do not fit one line within `level_line_misfit` of their noise.
pub(crate) fn fit_line(
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
    // Valid points only (all are, as the callers pick them), so that `pts` below runs with `idx`.
    idx.retain(|&i| grid.points[i].is_some());
    for round in 0..LINE_ROUNDS {
        if idx.len() < min_points {
            return None;
        }
        let pts: Vec<(Point3<f64>, Vector3<f64>)> = idx
            .iter()
            .filter_map(|&i| grid.points[i].as_ref().map(|g| (g.p, g.dir)))
            .collect();
        let line = LevelLine::fit(&pts, s, params.min_sigma)?;
        // Across the line: vertical-ish and horizontal-ish unit directions.
        let v1 = (up - line.dir * line.dir.dot(up)).try_normalize(1e-12)?;
        let v2 = line.dir.cross(&v1);
        let z2 = |p: &Point3<f64>, d: &Vector3<f64>| {
            let r = p - line.centroid;
            let r = r - line.dir * line.dir.dot(&r);
            let a = r.dot(&v1).powi(2) / (s * s * d.dot(&v1).powi(2) + ms2);
            let b = r.dot(&v2).powi(2) / (s * s * d.dot(&v2).powi(2) + ms2);
            (a, b)
        };
        let k2 = params.refine_k * params.refine_k;
        let z: Vec<(f64, f64)> = pts.iter().map(|(p, d)| z2(p, d)).collect();
        let kept: Vec<usize> = (0..idx.len())
            .filter(|&k| z[k].0 <= k2 && z[k].1 <= k2)
            .map(|k| idx[k])
            .collect();
        if kept.len() == idx.len() || round + 1 == LINE_ROUNDS {
            // Points still going after the last round: no line. (All kept, they are the
            // `min_points` or more checked above.)
            let chi2 = z.iter().map(|(a, b)| a + b).sum();
            if kept.len() < idx.len() || line_misfits(chi2, pts.len(), params) {
                return None;
            }
            // A floor line is level in the provisional frame, within that frame's
            // uncertainty and its own: a wall's line that passes near the floor's height
            // (a scan meeting a far wall near its foot) slopes, and taken as level it pulled
            // poses 6-7 degrees off with sigmas under one degree.
            let slope = line.dir.dot(up);
            let sloping = |su: f64| slope * slope > k2 * (line.variance_along(&v1, s) + su * su);
            return (!sigma_up.is_some_and(sloping)).then_some((line, idx));
        }
        idx = kept;
    }
    None
}

/// [`Check::LineMisfit`](checks::Check::LineMisfit): whether a line's `points` misfit it, their
/// chi-square about it (two residuals each, four parameters) beyond `level_line_misfit` per
/// degree of freedom.
pub(crate) fn line_misfits(chi2: f64, points: usize, params: &LevelParams) -> bool {
    let dof = (2 * points).saturating_sub(4).max(1) as f64;
    chi2 / dof > params.level_line_misfit
}

/// Floor and ceiling lines found without a level frame, for a start where neither the walls
/// nor a level plane fix up ([`level_start`]): in each scan, the points whose range steps to
/// the adjacent scans like the floor's ([`LevelSteps::floor`]) as one line, and likewise the
/// ceiling's. Their height is not checked (no frame to check it in); the lines only start
/// re-segmentation, which finds them again in its provisional level frame.
pub(crate) fn start_lines(
    grid: &PoseGrid,
    steps: &LevelSteps,
    params: &LevelParams,
    sigma: f64,
) -> Vec<LevelLine> {
    let s = sigma.max(params.min_sigma);
    let (cols, min_points) = (grid.cols, params.level_line_min_points);
    let mut out = Vec::new();
    for mask in [&steps.floor, &steps.ceiling] {
        let lines: Vec<(LevelLine, Vec<usize>)> = (0..grid.rows())
            .filter_map(|r| {
                let idx: Vec<usize> = (r * cols..(r + 1) * cols).filter(|&i| mask[i]).collect();
                fit_line(grid, idx, &Vector3::z(), None, s, params, min_points)
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
pub(crate) fn coplanar(a: &LevelLine, b: &LevelLine, s: f64, params: &LevelParams) -> bool {
    let Some(n) = a.dir.cross(&b.dir).try_normalize(PARALLEL_LINES_SIN) else {
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

/// [`Check::LinesAtOneHeight`](checks::Check::LinesAtOneHeight): whether the floor and
/// ceiling `lines` are one floor and one ceiling under the solution `sol` they gave: each
/// floor line below the scanner and each ceiling line above it, and the lines of one surface
/// at one height within `refine_k` sigmas (each line's mean height noise, `s` over the root of
/// its points and the `min_sigma` floor, and `sol`'s larger attitude sigma over the horizontal
/// distance between them). The lines were gathered at one height in the provisional frame,
/// whose tolerance spans the start's error over their distance; the solution's frame is much
/// tighter (traced at 10 cm noise: a start 10 degrees off took a tilted-up scan's run along a
/// wall, 0.4 m above the true floor line, as a second floor line, and the two leveled the
/// pose 5.3 degrees off at a sigma of 0.57).
pub(crate) fn lines_at_one_height(
    lines: &[FlatLine],
    sol: &UpSolution,
    s: f64,
    params: &LevelParams,
) -> bool {
    let k = params.refine_k;
    let tilt = sol.max_attitude_sigma();
    let height = |l: &FlatLine| sol.up.dot(&l.line.centroid.coords);
    let var = |l: &FlatLine| s * s / l.line.n as f64 + params.min_sigma * params.min_sigma;
    let on_its_side = |l: &FlatLine| {
        let side = if l.kind == SurfaceKind::Floor {
            -1.0
        } else {
            1.0
        };
        height(l) * side > -k * var(l).sqrt()
    };
    let together = |a: &FlatLine, b: &FlatLine| {
        let d = b.line.centroid - a.line.centroid;
        let across = (d.norm_squared() - sol.up.dot(&d).powi(2)).max(0.0);
        let spread = var(a) + var(b) + across * tilt * tilt;
        (height(a) - height(b)).powi(2) <= k * k * spread
    };
    lines.iter().all(on_its_side)
        && lines.iter().enumerate().all(|(i, a)| {
            lines[i + 1..]
                .iter()
                .filter(|b| b.kind == a.kind)
                .all(|b| together(a, b))
        })
}
