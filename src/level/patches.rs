//! Wall patches: the paper's quads merged with their coplanar neighbours by region growing over
//! the scan grid, so that a whole wall votes with all its points (the paper's sect. 9 suggests
//! EM plane fitting after Thrun et al. 2004; region growing from good seeds reaches the same
//! planes far more cheaply for a handful of scans).

use super::grid::{GridPoint, PlaneAccumulator, PlaneFit, PoseGrid};
use super::polygons::{Polygon, classify, extract_quads_sized};
use super::{LevelParams, SurfaceKind, total_order_key};
use nalgebra::{Matrix3, Point3, Vector3};

/// One grown planar patch.
#[derive(Clone, Debug)]
pub struct Patch {
    pub fit: PlaneFit,
    pub kind: SurfaceKind,
    /// Grid indices (row * cols + col) of its points, ascending.
    pub members: Vec<usize>,
    /// Lowest and highest row it reaches.
    pub row_range: (usize, usize),
}

/// The height in the level frame (`level_from_robot` applied) of the patches of `kind`: the
/// median over all their points, or `None` with fewer than `min_points` of them.
pub fn level_height(
    grid: &PoseGrid,
    patches: &[Patch],
    kind: SurfaceKind,
    level_from_robot: &Matrix3<f64>,
    min_points: usize,
) -> Option<f64> {
    let mut z: Vec<f64> = patches
        .iter()
        .filter(|p| p.kind == kind)
        .flat_map(|p| p.members.iter())
        .filter_map(|&i| grid.points[i].as_ref())
        .map(|g| (level_from_robot * g.p.coords).z)
        .collect();
    if z.len() < min_points.max(1) {
        return None;
    }
    let mid = z.len() / 2;
    let (_, m, _) = z.select_nth_unstable_by(mid, f64::total_cmp);
    Some(*m)
}

/// Seed width \[columns\]: the paper's quad width, or wider where the range noise would leave a
/// quad's plane undetermined. A seed should span about `seed_span_sigmas` noise sigmas sideways
/// at the grid's median range, so its normal is good to a few degrees and growth follows the
/// true surface instead of wandering across a corner.
pub fn seed_cols(grid: &PoseGrid, params: &LevelParams, sigma: f64) -> usize {
    if grid.cols < 2 || grid.points.iter().all(Option::is_none) {
        return params.quad_cols;
    }
    // Angular step from the directions of the first row's consecutive valid rays.
    let step = (0..grid.cols - 1)
        .find_map(|c| {
            let (a, b) = (grid.at(0, c)?, grid.at(0, c + 1)?);
            Some(a.dir.angle(&b.dir))
        })
        .unwrap_or(1f64.to_radians());
    let want =
        |r: f64| (params.seed_span_sigmas * sigma / (r * step).max(1e-9)).ceil() as usize + 1;
    let clamp = |w: usize| w.clamp(params.quad_cols, params.max_seed_cols.max(params.quad_cols));
    // `want` falls as the range grows: when the median range is at least a range `t` that
    // asks for no more than the quad width (low noise), so does the median, which then need
    // not be found. The median (element `mid` of the sorted ranges) is at least `t` when at
    // most `mid` ranges lie below `t`.
    let valid = grid.points.iter().flatten().count();
    let mid = valid / 2;
    let slack = params.quad_cols.saturating_sub(2).max(1) as f64;
    let t = params.seed_span_sigmas * sigma / (slack * step).max(1e-300) * (1.0 + 1e-9);
    if t.is_finite() && want(t) <= params.quad_cols {
        let below = grid.points.iter().flatten().filter(|g| g.range < t).count();
        if below <= mid {
            return params.quad_cols;
        }
    }
    let mut ranges: Vec<f64> = grid.points.iter().flatten().map(|g| g.range).collect();
    let (_, r, _) = ranges.select_nth_unstable_by(mid, f64::total_cmp);
    clamp(want(*r))
}

/// No patch.
pub const UNLABELLED: u32 = u32::MAX;

/// Grows patches from seed quads: walls first, best-fitting first, then floors and ceilings;
/// three-row seeds before two-row ones (a wall that only two scans reach, e.g. ahead of a robot
/// pitched towards the floor). Seeds are as wide as the paper's quads at low noise and wider at
/// high noise ([`seed_cols`]), since a seed's plane must be good enough to grow from.
/// A neighbouring grid point (same column in the next row, or next column in the same row)
/// joins when it lies within `grow_k * sigma` of the patch's current plane; the plane is
/// refitted as the patch grows. Finally members farther than that from the final plane are
/// released and the plane refitted once more.
/// Returns the patches and, per grid point, the index of its patch or [`UNLABELLED`].
pub fn grow_patches(
    grid: &PoseGrid,
    quads: &[Polygon],
    params: &LevelParams,
    sigma: f64,
) -> (Vec<Patch>, Vec<u32>) {
    let n = grid.points.len();
    let cols = grid.cols;
    let mut labels = vec![UNLABELLED; n];
    let mut patches = Vec::new();
    let tol = params.grow_k * sigma.max(params.min_sigma);
    let width = seed_cols(grid, params, sigma);
    let wide: Vec<Polygon>;
    let three_row: &[Polygon] = if width == params.quad_cols {
        quads
    } else {
        wide = extract_quads_sized(grid, params, sigma, params.quad_rows, width);
        &wide
    };
    // Floors and ceilings also seed from the paper's narrow quads when the seeds are wide:
    // along a level surface's normal the grazing rays carry little noise, so a narrow quad
    // pins its plane well, and a wide quad rarely fits where the floor is seen only near an
    // edge of the scans (its far and near sides too unequal, or a wall inside it).
    let narrow_level: Vec<&Polygon> = if params.narrow_level_seeds && width != params.quad_cols {
        quads
            .iter()
            .filter(|q| q.kind != SurfaceKind::Wall)
            .collect()
    } else {
        Vec::new()
    };
    let candidates: Vec<(u8, &Polygon)> = three_row
        .iter()
        .map(|q| (0u8, q))
        .chain(narrow_level.iter().map(|q| (2u8, *q)))
        .collect();
    // Ordered by rank, then mean squared residual, then position, packed in one integer key
    // (unique, so an unstable sort gives the stable order).
    let mut keys: Vec<u128> = candidates
        .iter()
        .enumerate()
        .map(|(i, &(band, q))| {
            let rank = band + if q.kind == SurfaceKind::Wall { 0 } else { 2 };
            // As unsigned, in the same order.
            let residual = total_order_key(q.fit.residual_ss / q.fit.n as f64) as u64 ^ 1 << 63;
            (u128::from(rank) << 96) | (u128::from(residual) << 32) | i as u128
        })
        .collect();
    keys.sort_unstable();
    let seeds = keys.iter().map(|&k| candidates[(k as u32) as usize].1);
    let mut members = Vec::new();
    // Columns without a division per visit.
    let rc = grid.row_col();
    for q in seeds {
        if q.span(cols).any(|i| labels[i] != UNLABELLED) {
            continue;
        }
        let id = patches.len() as u32;
        let mut acc = PlaneAccumulator::default();
        members.clear();
        for i in q.span(cols) {
            labels[i] = id;
            members.push(i);
            if let Some(g) = &grid.points[i] {
                acc.add(g);
            }
        }
        let Some(mut fit) = acc.fit(sigma) else {
            continue;
        };
        let s_eff = sigma.max(params.min_sigma);
        let tol_at = |fit: &PlaneFit, g: &GridPoint| ray_tolerance(fit, g, tol, s_eff, params);
        let mut refit_at = acc.n + acc.n / 3 + 1;
        // Breadth first: the members not yet visited are the queue.
        let mut next = 0;
        while let Some(&i) = members.get(next) {
            next += 1;
            let c = rc.col(i);
            let mut neighbours = [usize::MAX; 4];
            if c > 0 {
                neighbours[0] = i - 1;
            }
            if c + 1 < cols {
                neighbours[1] = i + 1;
            }
            if i >= cols {
                neighbours[2] = i - cols;
            }
            if i + cols < n {
                neighbours[3] = i + cols;
            }
            for j in neighbours {
                if j == usize::MAX || labels[j] != UNLABELLED {
                    continue;
                }
                let Some(g) = &grid.points[j] else { continue };
                if fit.distance(&g.p).abs() <= tol_at(&fit, g) {
                    labels[j] = id;
                    members.push(j);
                    acc.add(g);
                    if acc.n >= refit_at {
                        if let Some(f) = acc.fit(sigma) {
                            fit = f;
                        }
                        refit_at = acc.n + acc.n / 3 + 1;
                    }
                }
            }
        }
        // Release members that the final plane does not explain, then refit.
        if let Some(f) = acc.fit(sigma) {
            fit = f;
        }
        // Few are released: their sums come off the accumulator, rather than the kept ones'
        // being summed again.
        let mut released = PlaneAccumulator::default();
        members.retain(|&i| {
            let Some(g) = grid.points[i].as_ref() else {
                return false;
            };
            if fit.distance(&g.p).abs() <= tol_at(&fit, g) {
                true
            } else {
                released.add(g);
                labels[i] = UNLABELLED;
                false
            }
        });
        let made = make_patch(grid, &members, acc.minus(&released), params, sigma);
        match made {
            Some(p) => patches.push(p),
            None => {
                for &i in &members {
                    labels[i] = UNLABELLED;
                }
            }
        }
    }
    // Split patches that are really two planes (grown across a corner or a wall's foot),
    // then label the points afresh.
    let mut split = Vec::with_capacity(patches.len());
    for p in patches {
        if p.fit.misfit_ratio(sigma.max(params.min_sigma)) <= params.split_misfit {
            split.push(p);
            continue;
        }
        for part in split_members(grid, &p.members, params, sigma, params.split_depth) {
            split.extend(release_and_make(grid, &part, params, sigma, tol));
        }
    }
    labels.fill(UNLABELLED);
    for (id, p) in split.iter().enumerate() {
        for &i in &p.members {
            labels[i] = id as u32;
        }
    }
    (split, labels)
}

/// [`rows_span`] of members in ascending order: their first and last.
fn rows_span_sorted(members: &[usize], cols: usize) -> (usize, usize) {
    match (members.first(), members.last()) {
        (Some(&lo), Some(&hi)) => (lo / cols, hi / cols),
        _ => (usize::MAX, 0),
    }
}

fn rows_span(members: &[usize], cols: usize) -> (usize, usize) {
    // Rows grow with the grid index: the lowest and highest rows are those of the lowest and
    // highest index.
    let lo = members.iter().min().map_or(usize::MAX, |&i| i / cols);
    let hi = members.iter().max().map_or(0, |&i| i / cols);
    (lo, hi)
}

/// A patch from members when it is big enough and spans at least two rows (one row is a
/// line, which leaves its plane free to turn about it). `acc` holds the sums of the members'
/// points (the callers have just visited them).
fn make_patch(
    grid: &PoseGrid,
    members: &[usize],
    acc: PlaneAccumulator,
    params: &LevelParams,
    sigma: f64,
) -> Option<Patch> {
    // In grid order from here: the passes below then walk the grid forwards.
    let sorted = ascending(members);
    let members = &sorted[..];
    // The rows spanned, unless too small or one row: nothing to fit (trimming only takes
    // points away).
    let span = |members: &[usize]| {
        let (lo, hi) = rows_span_sorted(members, grid.cols);
        (members.len() >= params.min_patch_points && hi > lo).then_some((lo, hi))
    };
    // Still a patch once points went: big enough, over two rows, and stacked.
    let still_a_patch =
        |members: &[usize]| span(members).is_some() && stacked(members, grid, params);
    span(members)?;
    let first = acc.fit(sigma)?;
    let trimmed = trim_edge_rows(grid, members, &acc, &first, sigma, params);
    let (members, first) = match &trimmed {
        // A three-row patch that lost a row is no wall.
        Some(kept) if kept.is_empty() => return None,
        Some(kept) => (&kept[..], grid.accumulate(kept).fit(sigma)?),
        None => (members, first),
    };
    if !still_a_patch(members) {
        return None;
    }
    let fit = robust_fit(grid, members, first, params, sigma)?;
    let fronted = without_front_row_ends(grid, members, &fit, params, sigma);
    let (members, fit) = match &fronted {
        Some(kept) => {
            if !still_a_patch(kept) {
                return None;
            }
            let first = grid.accumulate(kept).fit(sigma)?;
            (&kept[..], robust_fit(grid, kept, first, params, sigma)?)
        }
        None => (members, fit),
    };
    let (lo, hi) = span(members)?;
    if too_bent_to_split(&fit, members.len(), params, sigma)
        || bent_across_rows(grid, members, &fit, params, sigma)
    {
        return None;
    }
    Some(Patch {
        kind: classify(&fit.normal, &fit.centroid, params),
        fit,
        members: members.to_vec(),
        row_range: (lo, hi),
    })
}

/// The members without the rows at either edge of the patch that the plane of its other rows
/// does not explain; `None` when no row goes, and none at all (an empty list) when the patch
/// spans three rows and one of its edge rows goes. At the foot of a wall the scan below the wall
/// meets the floor within centimetres of the wall's plane, and the wall's patch takes that
/// floor line in and tilts towards it: in a ceiling room, with a hinge offset and 2 cm noise,
/// such patches leveled poses 7-15 degrees off with sigmas near 1 degree. Fitted with the
/// line, the plane absorbs most of its offset (what [`bent_across_rows`] sees); left out, the
/// offset is plain: the edge row's mean residual from the other rows' plane, over its noise
/// (each point's range noise along the normal, `sigma |d . n|`) and that plane's own
/// uncertainty at the row (offset, and tilt over the lever arm), scaled by the plane's misfit.
fn trim_edge_rows(
    grid: &PoseGrid,
    members: &[usize],
    all: &PlaneAccumulator,
    all_fit: &PlaneFit,
    sigma: f64,
    params: &LevelParams,
) -> Option<Vec<usize>> {
    if params.trim_sigmas <= 0.0 {
        return None;
    }
    // Over four rows or more the rest is still a three-row wall. Over three, an edge row
    // standing off leaves no wall to keep: trimmed to two rows, such patches let other,
    // wrong planes decide some poses at 10 cm; the patch goes (an empty list).
    let (lo, hi) = rows_span_sorted(members, grid.cols);
    let three = hi == lo + 2;
    if hi < lo + 2 {
        return None;
    }
    let s = sigma.max(params.min_sigma);
    // A plane the noise explains has no row standing off it worth the test: a floor line
    // taken in at a wall's foot leaves the whole patch's fit about half as scattered again.
    if all_fit.misfit_ratio(s) <= params.split_misfit {
        return None;
    }
    let rc = grid.row_col();
    // Each row's own sums, so that the other rows' plane is a subtraction away.
    let mut per_row = vec![PlaneAccumulator::default(); hi + 1];
    for &i in members {
        if let Some(g) = &grid.points[i] {
            per_row[rc.row(i)].add(g);
        }
    }
    // Whether `row` stands off the plane of the rows `first..=last` other than it.
    let stands_off = |row: usize, first: usize, last: usize| -> bool {
        let others = (lo..=hi)
            .filter(|&r| r == row || !(first..=last).contains(&r))
            .fold(*all, |acc, r| acc.minus(&per_row[r]));
        if others.n < params.min_patch_points {
            return false;
        }
        let Some(fit) = others.fit(sigma) else {
            return false;
        };
        let (mut sum, mut var, mut at, mut n) = (0.0, 0.0, Vector3::zeros(), 0.0);
        for g in members
            .iter()
            .filter(|&&i| rc.row(i) == row)
            .filter_map(|&i| grid.points[i].as_ref())
        {
            sum += fit.distance(&g.p);
            var += (s * g.dir.dot(&fit.normal).abs().max(params.min_ray_share)).powi(2);
            at += g.p.coords;
            n += 1.0;
        }
        if n == 0.0 {
            return false;
        }
        // The mean residual's noise, plus the other rows' plane's own uncertainty where the
        // row lies: its offset at the centroid and its tilt over the lever arm to the row.
        let arm = at / n - fit.centroid.coords;
        let arm = arm - fit.normal * fit.normal.dot(&arm);
        let tilt = arm.try_normalize(1e-12).map_or(0.0, |u| {
            arm.norm_squared() * fit.normal_variance_along(&u, s)
        });
        let offset = s * s * fit.dn2 / fit.weight;
        let spread = (var / (n * n) + offset + tilt) * fit.misfit_ratio(s).max(1.0);
        (sum / n).abs() > params.trim_sigmas * spread.sqrt()
    };
    let (mut first, mut last) = (lo, hi);
    if three {
        // A wall line and the floor line at its foot, 2-15 cm out, with a few points of the
        // third scan near the hinge axis: a "wall" 11.6 degrees off at 1 cm noise.
        return (stands_off(lo, lo, hi) || stands_off(hi, lo, hi)).then(Vec::new);
    }
    if stands_off(first, first, last) {
        first += 1;
    }
    if last >= first + 3 && stands_off(last, first, last) {
        last -= 1;
    }
    if (first, last) == (lo, hi) {
        return None;
    }
    // What stays must still be a wall over three rows, each holding a fair share of its
    // points. Else the row that stood off may be the true wall and the rest a wall line and
    // the floor line at its foot, coplanar, with a few stray points in other rows: trimmed,
    // such a patch leveled a pose 28 degrees off at 1 cm noise.
    let held: Vec<usize> = (first..=last)
        .filter(|&r| per_row[r].n as f64 >= MIN_TRIMMED_ROW_SHARE * all.n as f64)
        .collect();
    if held.len() < 3 || held.windows(2).any(|w| w[1] != w[0] + 1) {
        return None;
    }
    Some(
        members
            .iter()
            .copied()
            .filter(|&i| (first..=last).contains(&rc.row(i)))
            .collect(),
    )
}

/// Fewest points, as a share of the patch's, in each of three adjacent rows that a trimmed
/// patch keeps.
const MIN_TRIMMED_ROW_SHARE: f64 = 0.15;

/// The members (ascending) without the runs of points at either end of their rows that stand
/// in front of the plane `fit`; `None` when no run does.
///
/// Where a wall meets the floor, the floor just in front of its foot lies within the growing
/// tolerance of the wall's plane at high noise, and the scans that reach below the foot meet it
/// at one end of their run over the wall, where the floor takes over along the scan line. Those
/// points all lie on the scanner's side of the wall and tilt it: at 10 cm noise with 361 rays,
/// one pose leveled 2.4 degrees off on average over 300 noise draws (the true segmentation: 0.0).
/// The ceiling over a wall's top, a wall's foot in a floor patch and the other wall of a
/// concave corner join the same way. A true plane's residuals take no side, so the test is the
/// sum of the residuals towards the scanner over the first `m` points of the run (`m` from
/// [`MIN_FRONT_RUN`] to half the run), over that sum's standard deviation (each point's
/// `sigma |d . n|` in quadrature), above `front_end_sigmas`. [`make_patch`] applies it to the
/// plane it has fitted and fits again without the runs that go. Over 129,600 protocol poses at
/// 5-10 cm (two seed sets, nine plans), poses reported ok and more than 5 degrees off fell from
/// 14 to 4 and those beyond 3 sigmas from 157 to 110, with 0.24 points more leveled; at 1 cm,
/// 0.04 points more.
fn without_front_row_ends(
    grid: &PoseGrid,
    members: &[usize],
    fit: &PlaneFit,
    params: &LevelParams,
    sigma: f64,
) -> Option<Vec<usize>> {
    if params.front_end_sigmas <= 0.0 {
        return None;
    }
    let s = sigma.max(params.min_sigma);
    // The scanner sits at the robot frame's origin. Residuals towards it are in units of `s`,
    // their variances in units of `s^2`.
    let towards = fit.distance(&Point3::origin()).signum();
    let along = fit.normal * (towards / s);
    let at = along.dot(&fit.centroid.coords);
    let in_front = |i: usize| {
        grid.points[i].as_ref().map_or((0.0, 0.0), |g| {
            let share = g.dir.dot(&fit.normal).abs().max(params.min_ray_share);
            (along.dot(&g.p.coords) - at, share * share)
        })
    };
    let rc = grid.row_col();
    let k = params.front_end_sigmas;
    let mut keep = vec![true; members.len()];
    let mut dropped = false;
    // Members ascend: each row's are one slice, in column order.
    let mut start = 0;
    while start < members.len() {
        let next_row = (rc.row(members[start]) + 1) * grid.cols;
        let len = members[start..].partition_point(|&i| i < next_row);
        let run = &members[start..start + len];
        let half = len / 2;
        let left = front_run(run[..half].iter().map(|&i| in_front(i)), k);
        let right = front_run(run[len - half..].iter().rev().map(|&i| in_front(i)), k);
        keep[start..start + left].fill(false);
        keep[start + len - right..start + len].fill(false);
        dropped |= left + right > 0;
        start += len;
    }
    if !dropped {
        return None;
    }
    Some(
        members
            .iter()
            .zip(&keep)
            .filter_map(|(&i, &k)| k.then_some(i))
            .collect(),
    )
}

/// Shortest run at a row's end that [`without_front_row_ends`] tests: shorter ones are single
/// noisy points rather than another surface.
const MIN_FRONT_RUN: usize = 3;

/// Length of the leading run of `residuals` whose sum (with their variances) stands out most in
/// standard deviations of that sum, when by more than `k` and the run is at least
/// [`MIN_FRONT_RUN`] long; 0 otherwise.
fn front_run(residuals: impl Iterator<Item = (f64, f64)>, k: f64) -> usize {
    let (mut sum, mut var) = (0.0, 0.0);
    // Compared squared and cross-multiplied, `sum^2 / var > best`, with no root or division
    // per point.
    let (mut best_sum2, mut best_var, mut best) = (k * k, 1.0, 0);
    for (m, (r, v)) in residuals.enumerate() {
        sum += r;
        var += v;
        if m + 1 >= MIN_FRONT_RUN && sum > 0.0 && sum * sum * best_var > best_sum2 * var {
            (best_sum2, best_var, best) = (sum * sum, var, m + 1);
        }
    }
    best
}

/// Whether the members are stacked: at least `min_stacked_share` of them have a member in an
/// adjacent row of their column (the scan next in elevation). On a wall the scans meet the
/// same stretch one above the other. A floor line with a few wall points at one end of it (the
/// floor at a wall's foot, at nearly the wall's range) is mostly single points in their
/// columns, and those few points decide its tilt: a steep "wall" off by degrees. Rows that
/// are not adjacent do not count: two wall lines over a floor line (the middle scan's beam
/// meets the floor, or another surface, between them) once passed as stacked and tilted a
/// pose's attitude by 20 degrees with a small sigma. `members` are in ascending order.
fn stacked(members: &[usize], grid: &PoseGrid, params: &LevelParams) -> bool {
    // Members ascend: the neighbours one row down and one row up are found by two cursors
    // that only move forwards, rather than in a mask over the whole grid.
    let cols = grid.cols;
    let (mut down, mut up) = (0, 0);
    let has = |cursor: &mut usize, target: usize| {
        while *cursor < members.len() && members[*cursor] < target {
            *cursor += 1;
        }
        *cursor < members.len() && members[*cursor] == target
    };
    let stacked = members
        .iter()
        .filter(|&&i| (i >= cols && has(&mut down, i - cols)) || has(&mut up, i + cols))
        .count();
    stacked as f64 >= params.min_stacked_share * members.len() as f64
}

/// A patch too small for [`split_members`] whose points fit their plane far worse than the
/// noise explains is no plane: typically two scan lines on a wall and one on the floor at its
/// foot, at nearly the same range, which a quad's tolerance let through. Its normal is tilted
/// by degrees, and where no other wall pins the same direction it would decide the attitude.
/// The test: residual variance over the noise's above `1 + k sqrt(2 / dof)` (k =
/// `max_misfit_sigmas`), k standard deviations of a true plane's ratio.
fn too_bent_to_split(fit: &PlaneFit, members: usize, params: &LevelParams, sigma: f64) -> bool {
    if params.max_misfit_sigmas <= 0.0 || members >= 2 * params.min_patch_points {
        return false;
    }
    let dof = (fit.weight - 3.0).max(1.0);
    fit.misfit_ratio(sigma.max(params.min_sigma))
        > 1.0 + params.max_misfit_sigmas * (2.0 / dof).sqrt()
}

/// Whether the patch's scan lines do not lie on one plane: a wall line and the floor line at
/// its foot (or a wall's lines with a floor line in front of them), in adjacent scans, make
/// a plane that tilts to pass near all of them, and the split test cannot cut them apart when
/// one part is a single row. A plane fitted through `R` rows absorbs their offsets along the
/// normal up to a linear trend with height; the rest, the rows' bend, is `R - 2` degrees of
/// freedom: `chi2 = sum_k m_k^2 / Var(m_k)` over the rows' mean residuals `m_k`, with
/// `Var(m_k) = sigma^2 sum (d . n)^2 / n_k^2` from each point's noise along the normal. The
/// patch is dropped when `chi2 / dof` exceeds one by `max_row_bend_sigmas` standard deviations
/// of a true plane's (`sqrt(2 / dof)`).
fn bent_across_rows(
    grid: &PoseGrid,
    members: &[usize],
    fit: &PlaneFit,
    params: &LevelParams,
    sigma: f64,
) -> bool {
    if params.max_row_bend_sigmas <= 0.0 {
        return false;
    }
    let s2 = sigma.max(params.min_sigma).powi(2);
    // Per row: sum of residuals, sum of (d . n)^2, count.
    let mut rows = vec![(0.0, 0.0, 0usize); grid.rows()];
    let rc = grid.row_col();
    for &i in members {
        if let Some(g) = &grid.points[i] {
            let r = &mut rows[rc.row(i)];
            r.0 += fit.distance(&g.p);
            r.1 += g.dir.dot(&fit.normal).powi(2).max(1e-4);
            r.2 += 1;
        }
    }
    let used: Vec<&(f64, f64, usize)> = rows.iter().filter(|r| r.2 > 0).collect();
    if used.len() < 3 {
        return false;
    }
    let chi2: f64 = used
        .iter()
        .map(|(sum, dn2, _)| sum * sum / (s2 * dn2))
        .sum();
    let dof = (used.len() - 2) as f64;
    chi2 / dof > 1.0 + params.max_row_bend_sigmas * (2.0 / dof).sqrt()
}

/// Drops members farther than `tol` from the members' plane, then makes the patch.
fn release_and_make(
    grid: &PoseGrid,
    members: &[usize],
    params: &LevelParams,
    sigma: f64,
    tol: f64,
) -> Option<Patch> {
    let fit = grid.accumulate(members).fit(sigma)?;
    let mut acc = PlaneAccumulator::default();
    let kept: Vec<usize> = members
        .iter()
        .copied()
        .filter(|&i| {
            grid.points[i].as_ref().is_some_and(|g| {
                let near = fit.distance(&g.p).abs() <= tol;
                if near {
                    acc.add(g);
                }
                near
            })
        })
        .collect();
    make_patch(grid, &kept, acc, params, sigma)
}

/// The patch's plane refitted with Cauchy weights on each point's residual over its own noise
/// along the normal (`sigma |d . n|`), so that the few floor points caught at a wall's foot,
/// all on one side of it, stop tilting the wall.
fn robust_fit(
    grid: &PoseGrid,
    members: &[usize],
    mut fit: PlaneFit,
    params: &LevelParams,
    sigma: f64,
) -> Option<PlaneFit> {
    let points = || members.iter().filter_map(|&i| grid.points[i].as_ref());
    let s = sigma.max(params.min_sigma);
    if params.ray_weights {
        fit = ray_weighted_fit(points(), params, sigma, fit)?;
    } else if fit.misfit_ratio(s) > params.split_misfit {
        // A plane its noise already explains has no outliers worth reweighting.
        for _ in 0..params.plane_iterations {
            let mut acc = PlaneAccumulator::default();
            for g in points() {
                acc.add_weighted(g, cauchy_weight(&fit, g, s, params));
            }
            fit = acc.fit(sigma)?;
        }
    }
    Some(fit)
}

/// Cauchy weight of a point's residual over its own noise along the normal.
fn cauchy_weight(fit: &PlaneFit, g: &GridPoint, s: f64, params: &LevelParams) -> f64 {
    let sd = s * g.dir.dot(&fit.normal).abs().max(0.3);
    let z = fit.distance(&g.p) / (params.plane_cauchy * sd);
    1.0 / (1.0 + z * z)
}

/// How far from a patch's plane a point may lie and still join it: `grow_k` sigmas of the
/// point's own range noise along the plane's normal, `sigma |d . n|` (at least
/// `min_ray_share` of sigma), when `ray_tolerance` is on; else `tol` for every point.
///
/// A floor seen at a grazing angle carries its range noise almost along itself, so its points
/// lie within centimetres of its plane even at 10 cm noise, while the foot of a wall rises
/// out of it at once; an isotropic `grow_k sigma` (30 cm at 10 cm noise) let floor patches run
/// up the walls and tilted them by degrees.
fn ray_tolerance(fit: &PlaneFit, g: &GridPoint, tol: f64, sigma: f64, params: &LevelParams) -> f64 {
    if params.ray_tolerance {
        params.grow_k * sigma * g.dir.dot(&fit.normal).abs().max(params.min_ray_share)
    } else {
        tol
    }
}

/// A plane refitted with each point weighted by the inverse variance of its range noise
/// along the normal, `1 / (d . n)^2` (with `|d . n|` at least `ray_weight_floor`), normalised
/// to a mean of one so that [`PlaneFit::normal_variance_along`] stays the weighted fit's
/// variance; plus the Cauchy weights of [`robust_fit`] when the plane misfits. Points met at
/// an oblique incidence are the precise ones along the normal; an unweighted fit lets the
/// head-on points' noise dominate. One pass, with the weights from the unweighted fit's normal:
/// a second pass, with weights from the weighted normal, moved no statistic beyond its noise
/// (75,600 protocol poses at 5-10 cm: leveled 73.94 vs 73.92%, ok and > 5 degrees off 16 vs
/// 17; the 1 cm cells of Table I unchanged) and cost 4% of `level`'s time.
fn ray_weighted_fit<'a>(
    points: impl Iterator<Item = &'a GridPoint>,
    params: &LevelParams,
    sigma: f64,
    fit: PlaneFit,
) -> Option<PlaneFit> {
    let s = sigma.max(params.min_sigma);
    let robust = fit.misfit_ratio(s) > params.split_misfit;
    let (mut acc, mut ray_weights, mut n) = (PlaneAccumulator::default(), 0.0, 0.0);
    for g in points {
        let w = 1.0
            / g.dir
                .dot(&fit.normal)
                .abs()
                .max(params.ray_weight_floor)
                .powi(2);
        let cauchy = if robust {
            cauchy_weight(&fit, g, s, params)
        } else {
            1.0
        };
        acc.add_weighted(g, w * cauchy);
        ray_weights += w;
        n += 1.0;
    }
    // The ray weights' mean scaled to one, after the sums (they are linear in the weights).
    acc.scale(n / ray_weights.max(1e-300));
    acc.fit(sigma)
}

/// Members in row-major order (`by_row`) or column-major order, ties by grid index, as a
/// sort by `(row or column, index)` would give: ascending grid index is row-major, and a
/// stable counting sort of that by column is column-major (members are distinct).
fn in_order(grid: &PoseGrid, members: &[usize], by_row: bool) -> Vec<usize> {
    let ascending = ascending(members);
    if by_row {
        return ascending;
    }
    let cols = grid.cols.max(1);
    let rc = grid.row_col();
    let mut start = vec![0usize; cols + 1];
    for &i in &ascending {
        start[rc.col(i) + 1] += 1;
    }
    for c in 0..cols {
        start[c + 1] += start[c];
    }
    let mut out = vec![0usize; ascending.len()];
    for &i in &ascending {
        let slot = &mut start[rc.col(i)];
        out[*slot] = i;
        *slot += 1;
    }
    out
}

/// Distinct grid indices in ascending order: marked in a bitset over their range and read
/// back word by word, cheaper than a comparison sort for a patch's members (dense in their
/// range).
fn ascending(members: &[usize]) -> Vec<usize> {
    let (Some(&lo), Some(&hi)) = (members.iter().min(), members.iter().max()) else {
        return Vec::new();
    };
    if hi - lo > 16 * members.len() {
        let mut v = members.to_vec();
        v.sort_unstable();
        return v;
    }
    let mut bits = vec![0u64; (hi - lo) / 64 + 1];
    for &i in members {
        bits[(i - lo) / 64] |= 1 << ((i - lo) % 64);
    }
    let mut out = Vec::with_capacity(members.len());
    for (k, &word) in bits.iter().enumerate() {
        let mut w = word;
        while w != 0 {
            out.push(lo + 64 * k + w.trailing_zeros() as usize);
            w &= w - 1;
        }
    }
    out
}

/// Splits a patch's members into planes while two planes explain them significantly better
/// than one: the best split by column (walls meet at corners, which are column ranges) or by
/// row (contiguous splits only: freely reassigning points would split one noisy plane into two
/// parallel ones and fool the test), accepted by an F test on the residual sums of squares,
/// `F = ((RSS1 - RSS2) / 3) / (RSS2 / (n - 6))`, which needs no noise level. Recurses into the
/// parts up to `depth` times.
pub fn split_members(
    grid: &PoseGrid,
    members: &[usize],
    params: &LevelParams,
    sigma: f64,
    depth: usize,
) -> Vec<Vec<usize>> {
    let whole = vec![members.to_vec()];
    if depth == 0 || members.len() < 2 * params.min_patch_points {
        return whole;
    }
    let cols = grid.cols;
    let rc = grid.row_col();
    let Some(fit_all) = grid.accumulate(members).fit(sigma) else {
        return whole;
    };
    let rss1 = fit_all.residual_ss;
    // Candidate cuts (where the key changes, both parts spanning two rows), as (lower bound on
    // the two planes' RSS, which ordering, boundary index). They are fitted in order of their
    // bounds, and a cut whose bound exceeds the best RSS found cannot win, so most of them
    // need no eigen decomposition. The winner is the same as fitting every cut in turn: the
    // least RSS, ties to the first ordering and boundary.
    let mut candidates: Vec<(f64, usize, usize)> = Vec::new();
    let orders: [Vec<usize>; 2] = [
        in_order(grid, members, false),
        in_order(grid, members, true),
    ];
    let mut prefixes: [Vec<PlaneAccumulator>; 2] = [Vec::new(), Vec::new()];
    for (which, sorted) in orders.iter().enumerate() {
        let by_row = which == 1;
        let key = |i: usize| if by_row { rc.row(i) } else { rc.col(i) };
        let n = sorted.len();
        // Prefix plane sums, and the rows spanned by every prefix and suffix.
        let prefix = &mut prefixes[which];
        prefix.reserve(n + 1);
        let mut acc = PlaneAccumulator::default();
        prefix.push(acc);
        let (mut pre_lo, mut pre_hi) = (vec![usize::MAX; n + 1], vec![0usize; n + 1]);
        for (k, &i) in sorted.iter().enumerate() {
            if let Some(g) = &grid.points[i] {
                acc.add(g);
            }
            prefix.push(acc);
            pre_lo[k + 1] = pre_lo[k].min(rc.row(i));
            pre_hi[k + 1] = pre_hi[k].max(rc.row(i));
        }
        let (mut suf_lo, mut suf_hi) = (vec![usize::MAX; n + 1], vec![0usize; n + 1]);
        for k in (0..n).rev() {
            suf_lo[k] = suf_lo[k + 1].min(rc.row(sorted[k]));
            suf_hi[k] = suf_hi[k + 1].max(rc.row(sorted[k]));
        }
        let total = acc;
        let half = params.min_patch_points / 2;
        for b in half.max(1)..n.saturating_sub(half).max(1) {
            // Only where the key changes (column or row boundaries).
            if key(sorted[b]) == key(sorted[b - 1]) {
                continue;
            }
            if pre_hi[b] <= pre_lo[b] || suf_hi[b] <= suf_lo[b] {
                continue;
            }
            let l = prefix[b];
            let r = total.minus(&l);
            let bound = l.residual_lower_bound() + r.residual_lower_bound();
            candidates.push((bound, which, b));
        }
    }
    candidates.sort_by(|x, y| x.0.total_cmp(&y.0));
    // Best split so far: (RSS of the two planes, which ordering, boundary index).
    let mut best: Option<(f64, usize, usize)> = None;
    for &(bound, which, b) in &candidates {
        if best.is_some_and(|(br, _, _)| bound > br) {
            break;
        }
        let prefix = &prefixes[which];
        let l = prefix[b];
        let r = prefix[prefix.len() - 1].minus(&l);
        let (Some(fl), Some(fr)) = (l.fit(sigma), r.fit(sigma)) else {
            continue;
        };
        let rss2 = fl.residual_ss + fr.residual_ss;
        let better =
            best.is_none_or(|(br, bw, bb)| rss2 < br || (rss2 == br && (which, b) < (bw, bb)));
        if better {
            best = Some((rss2, which, b));
        }
    }
    let Some((_, which, cut)) = best else {
        return whole;
    };
    let (a, b) = (orders[which][..cut].to_vec(), orders[which][cut..].to_vec());
    let ok = |m: &[usize]| {
        let (lo, hi) = rows_span(m, cols);
        m.len() >= params.min_patch_points / 2 && hi > lo
    };
    if !ok(&a) || !ok(&b) {
        return whole;
    }
    let (Some(fa), Some(fb)) = (
        grid.accumulate(&a).fit(sigma),
        grid.accumulate(&b).fit(sigma),
    ) else {
        return whole;
    };
    let rss2 = fa.residual_ss + fb.residual_ss;
    let n = members.len() as f64;
    let f = ((rss1 - rss2) / 3.0) / (rss2 / (n - 6.0)).max(1e-300);
    if f.is_nan() || f <= params.split_f {
        return whole;
    }
    let mut out = split_members(grid, &a, params, sigma, depth - 1);
    out.extend(split_members(grid, &b, params, sigma, depth - 1));
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Point3, Vector3};
    use proptest::prelude::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// Membership alone decides stacking: points with a member in the adjacent row of their
    /// column stack; two rows that are not adjacent do not, even where both hold the column.
    #[test]
    fn only_adjacent_rows_stack() {
        let (rows, cols) = (3, 20);
        let grid = PoseGrid {
            scan_index: (0..rows).collect(),
            elevation: (0..rows).map(|r| r as f64 * 0.087).collect(),
            cols,
            points: vec![None; rows * cols],
        };
        let at = |r: usize, c: usize| r * cols + c;
        let params = LevelParams::default();
        let wall: Vec<usize> = (0..rows)
            .flat_map(|r| (0..cols).map(move |c| at(r, c)))
            .collect();
        assert!(stacked(&wall, &grid, &params));
        // Row 0 on the left, row 1 on the right, row 2 under both: every column holds two
        // rows, but only the right half's rows 1 and 2 are neighbours.
        let split: Vec<usize> = (0..10)
            .map(|c| at(0, c))
            .chain((10..20).map(|c| at(1, c)))
            .chain((0..20).map(|c| at(2, c)))
            .collect();
        assert!(!stacked(&split, &grid, &params));
    }

    proptest! {
        /// The bitmap ordering gives what a sort gives, dense or sparse, sorted or not.
        #[test]
        fn ascending_is_a_sort_of_distinct_indices(
            set in proptest::collection::btree_set(0usize..5000, 0..300),
            seed in any::<u64>(),
        ) {
            let mut members: Vec<usize> = set.iter().copied().collect();
            let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(seed);
            rand::seq::SliceRandom::shuffle(&mut members[..], &mut rng);
            let sorted: Vec<usize> = set.into_iter().collect();
            prop_assert_eq!(ascending(&members), sorted);
        }
    }

    /// A wall met obliquely: the plane through (3, 0, 0) with normal `n`, seen by 3 scans of
    /// 61 rays from the origin, with Gaussian range noise `sigma`.
    fn oblique_wall_grid(n: &Vector3<f64>, sigma: f64, seed: u64) -> PoseGrid {
        let elevation: Vec<f64> = (0..3).map(|r| (r as f64 - 1.0) * 0.087).collect();
        noisy_grid(elevation, 61, sigma, seed, Point3::origin(), |_, c, e| {
            let bearing = (c as f64 - 30.0).to_radians() * 1.2;
            let dir = Vector3::new(bearing.cos() * e.cos(), bearing.sin(), -e.sin());
            // Range to the plane n . (p - (3, 0, 0)) = 0 along dir.
            (dir, 3.0 * n.x / n.dot(&dir))
        })
    }

    /// A grid of scans at `elevation`, `cols` rays each, seen from `origin`: ray (row, column)
    /// at its row's elevation goes along the direction `ray` gives and meets its surface at the
    /// range it gives, plus Gaussian range noise `sigma` (drawn in grid order).
    fn noisy_grid(
        elevation: Vec<f64>,
        cols: usize,
        sigma: f64,
        seed: u64,
        origin: Point3<f64>,
        ray: impl Fn(usize, usize, f64) -> (Vector3<f64>, f64),
    ) -> PoseGrid {
        let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(seed);
        let noise = Normal::new(0.0, sigma).unwrap();
        let rows = elevation.len();
        let mut points = Vec::with_capacity(rows * cols);
        for (r, &e) in elevation.iter().enumerate() {
            for c in 0..cols {
                let (dir, exact) = ray(r, c, e);
                let range = exact + noise.sample(&mut rng);
                points.push(Some(GridPoint {
                    p: origin + dir * range,
                    dir,
                    range,
                }));
            }
        }
        PoseGrid {
            scan_index: (0..rows).collect(),
            elevation,
            cols,
            points,
        }
    }

    /// The weighted wall fit is better than the plain one on an oblique wall, and the normal
    /// variance it reports is not smaller than the scatter over repeated noise (its sigmas are
    /// not overconfident).
    #[test]
    fn ray_weighted_wall_fit_is_tighter_and_not_overconfident() {
        let n = Vector3::new(1.0, -1.2, 0.0).normalize();
        let params = LevelParams::default();
        let sigma = 0.1;
        let up = Vector3::z();
        let (mut sq_w, mut sq_plain, mut predicted) = (0.0, 0.0, 0.0);
        let trials = 300;
        for seed in 0..trials {
            let grid = oblique_wall_grid(&n, sigma, seed);
            let members: Vec<usize> = (0..grid.points.len()).collect();
            let plain = grid.accumulate(&members).fit(sigma).unwrap();
            let weighted =
                ray_weighted_fit(grid.points.iter().flatten(), &params, sigma, plain).unwrap();
            sq_plain += plain.normal.dot(&up).powi(2);
            sq_w += weighted.normal.dot(&up).powi(2);
            predicted += weighted.normal_variance_along(&up, sigma);
        }
        let t = trials as f64;
        let (var_w, var_plain, predicted) = (sq_w / t, sq_plain / t, predicted / t);
        assert!(
            var_w < 0.5 * var_plain,
            "weighted {var_w:.3e} vs plain {var_plain:.3e}"
        );
        assert!(
            var_w < 1.1 * predicted,
            "observed {var_w:.3e} over predicted {predicted:.3e}"
        );
    }

    /// Three scans of 21 rays at elevations -5, 0, 5 degrees from 0.45 m above the floor,
    /// ahead of a wall 2.3 m away: rows 0 and 1 meet the wall, row 2 (pitched down) the floor
    /// at `foot` metres.
    fn wall_over_floor_line(foot: f64, sigma: f64, seed: u64) -> (PoseGrid, Vec<usize>) {
        let elevation: Vec<f64> = (0..3).map(|r| (r as f64 - 1.0) * 0.087).collect();
        let origin = Point3::new(0.0, 0.0, 0.45);
        let grid = noisy_grid(elevation, 21, sigma, seed, origin, |r, c, e| {
            // Pitched 7 degrees towards the floor: depressions 2, 7, 12 degrees.
            let (dep, bearing) = (e + 0.122, (c as f64 - 10.0).to_radians());
            let dir = Vector3::new(bearing.cos() * dep.cos(), bearing.sin(), -dep.sin());
            let exact = if r < 2 {
                2.3 / dir.x
            } else {
                foot / (dir.x * dir.x + dir.y * dir.y).sqrt()
            };
            (dir, exact)
        });
        let members = (0..grid.points.len()).collect();
        (grid, members)
    }

    /// A wall at x = 2.5 m seen by four scans (61 rays over 60 degrees), with 10 cm range noise;
    /// with `floor_run`, the last 12 rays of the lowest scan meet the floor just in front of
    /// the wall's foot instead, 2 to 25 cm short of it along the ray (within the growing
    /// tolerance). Returns the grid, every point as members, and the floor run's indices.
    fn wall_with_floor_run(floor_run: bool, seed: u64) -> (PoseGrid, Vec<usize>, Vec<usize>) {
        let (rows, cols, run) = (4, 61, 12);
        let elevation: Vec<f64> = (0..rows).map(|r| (r as f64 - 1.5) * 0.087).collect();
        let in_run = |r: usize, c: usize| floor_run && r == rows - 1 && c + run >= cols;
        let grid = noisy_grid(elevation, cols, 0.1, seed, Point3::origin(), |r, c, e| {
            let bearing = (c as f64 - 30.0).to_radians();
            let dir = Vector3::new(bearing.cos() * e.cos(), bearing.sin(), -e.sin());
            let short = if in_run(r, c) {
                0.02 + 0.02 * (c + run - cols) as f64
            } else {
                0.0
            };
            (dir, 2.5 / dir.x - short)
        });
        let members = (0..grid.points.len()).collect();
        let floor = (0..grid.points.len())
            .filter(|&i| in_run(i / cols, i % cols))
            .collect();
        (grid, members, floor)
    }

    /// The floor run at the end of a wall's lowest row tilts the wall's plane towards it by 1.6
    /// degrees on average over 40 noise draws; without the runs that go (more than half of its
    /// points, and at most 0.5% of the wall's) the average tilt is within 0.3 degrees of zero.
    #[test]
    fn a_floor_run_in_front_of_a_walls_foot_goes() {
        let params = LevelParams::default();
        let (mut floor_dropped, mut floor_total, mut wall_dropped, mut wall_total) = (0, 0, 0, 0);
        let (mut tilt_all, mut tilt_kept) = (0.0, 0.0);
        // Signed: positive when the plane leans away at its top.
        let tilt = |n: &Vector3<f64>| (n.z * n.x.signum()).asin().to_degrees() / 40.0;
        for seed in 0..40 {
            let (grid, members, floor) = wall_with_floor_run(true, seed);
            let fit = grid.accumulate(&members).fit(0.1).unwrap();
            let kept = without_front_row_ends(&grid, &members, &fit, &params, 0.1)
                .unwrap_or_else(|| members.clone());
            let dropped = |i: &usize| kept.binary_search(i).is_err();
            floor_dropped += floor.iter().filter(|i| dropped(i)).count();
            floor_total += floor.len();
            wall_dropped += members
                .iter()
                .filter(|i| !floor.contains(i) && dropped(i))
                .count();
            wall_total += members.len() - floor.len();
            tilt_all += tilt(&fit.normal);
            tilt_kept += tilt(&grid.accumulate(&kept).fit(0.1).unwrap().normal);
        }
        assert!(tilt_all < -1.0, "{tilt_all}");
        assert!(tilt_kept.abs() < 0.3, "{tilt_kept}");
        assert!(
            2 * floor_dropped > floor_total,
            "{floor_dropped} of {floor_total} floor points dropped"
        );
        assert!(
            wall_dropped as f64 <= 0.005 * wall_total as f64,
            "{wall_dropped} of {wall_total} wall points dropped"
        );
    }

    /// A true plane keeps every point in at least 95 of 100 noise draws: its residuals take no
    /// side.
    #[test]
    fn a_true_plane_rarely_loses_a_row_end() {
        let params = LevelParams::default();
        let trimmed = (0..100)
            .filter(|&seed| {
                let (grid, members, _) = wall_with_floor_run(false, seed);
                let fit = grid.accumulate(&members).fit(0.1).unwrap();
                without_front_row_ends(&grid, &members, &fit, &params, 0.1).is_some()
            })
            .count();
        assert!(trimmed <= 5, "{trimmed} of 100 draws trimmed");
    }

    #[test]
    fn wall_lines_with_the_floor_line_at_their_foot_are_bent_across_rows() {
        let params = LevelParams::default();
        for seed in 0..20 {
            // The floor line 10 cm in front of the wall's foot, at 1 cm noise.
            let (grid, members) = wall_over_floor_line(2.2, 0.01, seed);
            let fit = grid.accumulate(&members).fit(0.01).unwrap();
            assert!(
                bent_across_rows(&grid, &members, &fit, &params, 0.01),
                "seed {seed}"
            );
        }
    }

    /// Two wall lines and the floor line 10 cm in front of their foot, the floor line taking
    /// more of the patch (the wall's third scan sees it only near the hinge axis): the patch
    /// goes whole; a true three-row wall at 10 cm noise rarely does.
    #[test]
    fn a_three_row_patch_with_a_row_off_its_plane_goes() {
        let params = LevelParams::default();
        let dropped = |grid: &PoseGrid, members: &[usize], sigma: f64| {
            let acc = grid.accumulate(members);
            let fit = acc.fit(sigma).unwrap();
            trim_edge_rows(grid, members, &acc, &fit, sigma, &params).is_some_and(|m| m.is_empty())
        };
        for seed in 0..20 {
            let (grid, members) = wall_over_floor_line(2.2, 0.01, seed);
            // Only a few points of the top wall row, near one edge.
            let members: Vec<usize> = members
                .into_iter()
                .filter(|&i| i >= grid.cols || i % grid.cols < 5)
                .collect();
            assert!(dropped(&grid, &members, 0.01), "seed {seed}");
        }
        let n = Vector3::new(1.0, -1.2, 0.2).normalize();
        let gone = (0..200)
            .filter(|&seed| {
                let grid = oblique_wall_grid(&n, 0.1, seed);
                let members: Vec<usize> = (0..grid.points.len()).collect();
                dropped(&grid, &members, 0.1)
            })
            .count();
        assert!(gone <= 4, "{gone} of 200 true walls dropped");
    }

    #[test]
    fn a_true_plane_over_three_rows_is_rarely_bent() {
        let params = LevelParams::default();
        let n = Vector3::new(1.0, -1.2, 0.2).normalize();
        let mut bent = 0;
        for seed in 0..200 {
            let grid = oblique_wall_grid(&n, 0.1, seed);
            let members: Vec<usize> = (0..grid.points.len()).collect();
            let fit = grid.accumulate(&members).fit(0.1).unwrap();
            bent += usize::from(bent_across_rows(&grid, &members, &fit, &params, 0.1));
        }
        // A 4-sigma threshold on one degree of freedom rejects about 1% of true planes.
        assert!(bent <= 6, "{bent} of 200 true planes called bent");
    }

    #[test]
    fn ray_weighted_fit_is_exact_without_noise() {
        let n = Vector3::new(1.0, -1.2, 0.3).normalize();
        let grid = oblique_wall_grid(&n, 1e-300, 1);
        let members: Vec<usize> = (0..grid.points.len()).collect();
        let plain = grid.accumulate(&members).fit(0.0).unwrap();
        let params = LevelParams::default();
        let fit = ray_weighted_fit(grid.points.iter().flatten(), &params, 0.0, plain).unwrap();
        assert!(1.0 - fit.normal.dot(&n).abs() < 1e-12, "{:?}", fit.normal);
    }
}
