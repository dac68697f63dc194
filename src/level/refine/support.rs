//! How many scan lines a set of points spans with a fair share of its points. Two scan lines
//! always lie in one plane, whatever they hit, so a plane over two scans is weaker evidence
//! than one over three: one place for the rules that follow from that.

use super::*;
use crate::level::params::first_pass::LEVEL_ROW_SHARE;

/// A level surface's members without an edge row (the lowest or highest scan among them) that
/// stands off the plane of the other rows by more than `refine_k` sigmas ([`line_offset_sigmas`]).
/// The scan above a floor meets the walls just above their feet: that line lies centimetres
/// over the floor, passes for floor within a provisional frame's tolerance, and tilts the plane
/// (one such row, 6 cm up, set a start 2.8 degrees off with a sigma of 0.11). Only with three
/// rows or more, so that the others still make a plane.
pub(crate) fn without_standing_rows(
    grid: &PoseGrid,
    members: Vec<usize>,
    s: f64,
    params: &LevelParams,
) -> Vec<usize> {
    let mut rows: Vec<usize> = members.iter().map(|&i| grid.row(i)).collect();
    rows.sort_unstable();
    rows.dedup();
    if rows.len() < 3 {
        return members;
    }
    let mut drop = Vec::new();
    for edge in [rows[0], rows[rows.len() - 1]] {
        // The others must still span two rows to make a plane.
        if rows.len() - drop.len() < 3 {
            break;
        }
        let (line, others): (Vec<usize>, Vec<usize>) = members
            .iter()
            .copied()
            .filter(|&i| !drop.contains(&grid.row(i)))
            .partition(|&i| grid.row(i) == edge);
        let off = |fit: PlaneFit| {
            line_offset_sigmas(grid, &line, &fit, s, params.min_sigma) > params.refine_k
        };
        if grid.accumulate(&others).fit(s).is_some_and(off) {
            drop.push(edge);
        }
    }
    members
        .into_iter()
        .filter(|&i| !drop.contains(&grid.row(i)))
        .collect()
}

/// Rows holding at least `share` of the members each.
pub(crate) fn rows_supported(grid: &PoseGrid, members: &[usize], share: f64) -> usize {
    let mut per_row = vec![0usize; grid.rows()];
    for &i in members {
        per_row[grid.row(i)] += 1;
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

/// Whether a re-segmented floor's or ceiling's `members` can make a level plane
/// ([`Check::LevelMinPoints`](crate::level::checks::Check::LevelMinPoints)): at least
/// `min_level_points` of them, over two rows that each hold a fifth of them (a level plane from
/// one scan line is that scan's own plane: a line on the floor leaves it free to turn about
/// the line).
pub(crate) fn level_support(grid: &PoseGrid, members: &[usize], params: &LevelParams) -> bool {
    members.len() >= params.min_level_points && rows_supported(grid, members, LEVEL_ROW_SHARE) >= 2
}

/// The plane (at range noise `sigma`) of a floor's or ceiling's `members` that can make one
/// ([`level_support`]).
pub(crate) fn supported_level_fit(
    grid: &PoseGrid,
    members: &[usize],
    params: &LevelParams,
    sigma: f64,
) -> Option<PlaneFit> {
    let supported = level_support(grid, members, params);
    supported
        .then(|| grid.accumulate(members).fit(sigma))
        .flatten()
}

/// Whether a level plane spans three scans. Two scan lines that meet are coplanar whatever
/// they lie on (a floor line and a wall's foot line), so a plane over two scans fits well and
/// can still lean by degrees: it is no evidence of its own that its points are one surface.
pub(crate) fn three_rows_support(grid: &PoseGrid, members: &[usize]) -> bool {
    rows_supported(grid, members, WALL_ROW_SHARE) >= 3
}
