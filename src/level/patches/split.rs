//! Splitting a patch that is bent, or stacked from two surfaces, into planar parts.

use super::*;

/// Whether the members are stacked: at least `min_stacked_share` of them have a member in an
/// adjacent row of their column (the scan next in elevation). On a wall the scans meet the
/// same stretch one above the other. A floor line with a few wall points at one end of it (the
/// floor at a wall's foot, at nearly the wall's range) is mostly single points in their
/// columns, and those few points decide its tilt: a steep "wall" off by degrees. Rows that
/// are not adjacent do not count: two wall lines over a floor line (the middle scan's beam
/// meets the floor, or another surface, between them) once passed as stacked and tilted a
/// pose's attitude by 20 degrees with a small sigma. `members` are in ascending order.
pub(super) fn stacked(members: &[usize], grid: &PoseGrid, params: &LevelParams) -> bool {
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
pub(super) fn too_bent_to_split(
    fit: &PlaneFit,
    members: usize,
    params: &LevelParams,
    sigma: f64,
) -> bool {
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
pub(super) fn bent_across_rows(
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
    for &i in members {
        if let Some(g) = &grid.points[i] {
            let r = &mut rows[grid.row(i)];
            r.0 += fit.distance(&g.p);
            r.1 += g.dir.dot(&fit.normal).powi(2).max(ROW_BEND_DN2_FLOOR);
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
    let Some(fit_all) = grid.accumulate(members).fit(sigma) else {
        return whole;
    };
    // Column-major and row-major, ties by grid index, as a sort by `(column or row, index)`
    // would give: ascending grid index is row-major, and a stable sort of that by column is
    // column-major.
    let by_row = ascending(members);
    let mut by_column = by_row.clone();
    by_column.sort_by_key(|&i| i % grid.cols);
    let orders = [by_column, by_row];
    // The least two-plane RSS over both orderings, ties to the first ordering and boundary.
    let Some((_, which, cut)) = (0..2)
        .filter_map(|w| best_cut(grid, &orders[w], w == 1, params, sigma).map(|(r, b)| (r, w, b)))
        .min_by(|x, y| x.0.total_cmp(&y.0))
    else {
        return whole;
    };
    // The cut's parts hold half a patch each over two rows ([`best_cut`]): the F test of
    // their own fits decides (the search's sums, one part a difference of two, lose the
    // digits of a noise-free plane's residuals).
    let (a, b) = orders[which].split_at(cut);
    let rss = |m: &[usize]| grid.accumulate(m).fit(sigma).map(|f| f.residual_ss);
    let (Some(ra), Some(rb)) = (rss(a), rss(b)) else {
        return whole;
    };
    if !two_planes(fit_all.residual_ss, ra + rb, members.len(), params) {
        return whole;
    }
    let mut out = split_members(grid, a, params, sigma, depth - 1);
    out.extend(split_members(grid, b, params, sigma, depth - 1));
    out
}

/// The cut of one member ordering (`by_row`, else by column) that [`split_members`] takes:
/// where the key changes and both parts hold half a patch over two rows, the one of least
/// two-plane RSS (ties to the first), as (RSS, boundary index).
fn best_cut(
    grid: &PoseGrid,
    sorted: &[usize],
    by_row: bool,
    params: &LevelParams,
    sigma: f64,
) -> Option<(f64, usize)> {
    let key = |i: usize| if by_row { grid.row(i) } else { i % grid.cols };
    let n = sorted.len();
    // Prefix plane sums.
    let mut prefix = Vec::with_capacity(n + 1);
    let mut acc = PlaneAccumulator::default();
    prefix.push(acc);
    for &i in sorted {
        if let Some(g) = &grid.points[i] {
            acc.add(g);
        }
        prefix.push(acc);
    }
    // The parts before and from `b` span two rows each when they reach past the run of the
    // first member's row and of the last one's.
    let row = |k: usize| grid.row(sorted[k]);
    let first_other = (0..n).find(|&k| row(k) != row(0)).unwrap_or(n);
    let last_other = (0..n).rev().find(|&k| row(k) != row(n - 1));
    let two_rows = |b: usize| first_other < b && last_other.is_some_and(|k| k >= b);
    let half = params.min_patch_points / 2;
    let mut best: Option<(f64, usize)> = None;
    for b in half.max(1)..n.saturating_sub(half).max(1) {
        // Only where the key changes (column or row boundaries).
        if key(sorted[b]) == key(sorted[b - 1]) || !two_rows(b) {
            continue;
        }
        let (Some(fl), Some(fr)) = (prefix[b].fit(sigma), acc.minus(&prefix[b]).fit(sigma)) else {
            continue;
        };
        let rss2 = fl.residual_ss + fr.residual_ss;
        if best.is_none_or(|(br, _)| rss2 < br) {
            best = Some((rss2, b));
        }
    }
    best
}

/// [`Check::PatchSplitF`](crate::level::checks::Check::PatchSplitF): whether two planes of
/// residual sum of squares `rss2` explain `n` points significantly better than one of `rss1`:
/// the F statistic of [`split_members`] above `split_f`.
pub(crate) fn two_planes(rss1: f64, rss2: f64, n: usize, params: &LevelParams) -> bool {
    let f = ((rss1 - rss2) / 3.0) / (rss2 / (n as f64 - 6.0)).max(1e-300);
    !(f.is_nan() || f <= params.split_f)
}
