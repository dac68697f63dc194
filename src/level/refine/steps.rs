//! Range-step classification: how a point's range changes to its neighbours in the adjacent
//! scans tells a level surface from a wall (no up needed), and, once leveled, how its height
//! does ([`flat_points`]).

use super::*;

/// Points whose range changes from scan to scan like a level surface's: in their column, the
/// range to a neighbouring row's point differs by more than `r de` for the elevation step `de`
/// (`r cot(a) de` on a surface seen `a` < 45 degrees off the beams' plane, `r tan(b) de` on a
/// wall met at vertical incidence `b`), plus a margin for the noise of
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

/// [`LevelSteps`] of a grid at range noise `sigma`, each adjacent-row step judged once.
pub fn level_steps(grid: &PoseGrid, params: &LevelParams, sigma: f64) -> LevelSteps {
    let two_ranges = std::f64::consts::SQRT_2 * sigma.max(params.min_sigma);
    let margin = params.refine_step_k * two_ranges;
    // +1 a floor's step, -1 a ceiling's, 0 neither; beside it the same by sign alone.
    let pairs = row_pairs(grid, |i, j| {
        let (a, b) = (grid.points[i].as_ref()?, grid.points[j].as_ref()?);
        let de = grid.elevation[grid.row(j)] - grid.elevation[grid.row(i)];
        let change = (b.range - a.range) * de.signum() * a.dir.x.signum();
        let bound = 0.5 * (a.range + b.range) * de.abs() + margin;
        let side = |bound: f64| (change < -bound) as i8 - (change > bound) as i8;
        Some((side(bound), side(bound.min(LINE_STEP_SIGMAS * two_ranges))))
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

/// `step(i, j)` for each grid index `i` and the index `j` above it in the next row (`None`
/// where there is no step, as where either point is missing): each column pair of adjacent
/// rows once, pair `i` joining point `i` to the one above.
pub(crate) fn row_pairs<T>(
    grid: &PoseGrid,
    step: impl Fn(usize, usize) -> Option<T>,
) -> Vec<Option<T>> {
    let cols = grid.cols;
    (0..cols * grid.rows().saturating_sub(1))
        .map(|i| step(i, i + cols))
        .collect()
}

/// Per point, whether it has a neighbour in an adjacent row and `accept` holds for the step to
/// every such neighbour ([`row_pairs`]).
pub(crate) fn every_row_neighbour<T: Copy>(
    grid: &PoseGrid,
    pairs: &[Option<T>],
    accept: impl Fn(T) -> bool,
) -> Vec<bool> {
    (0..grid.points.len())
        .map(|i| match row_steps(grid, pairs, i) {
            (None, None) => false,
            (a, b) => a.is_none_or(&accept) && b.is_none_or(&accept),
        })
        .collect()
}

/// Point `i`'s steps ([`row_pairs`]) to the rows below and above it, `None` past the grid.
pub(crate) fn row_steps<T: Copy>(
    grid: &PoseGrid,
    pairs: &[Option<T>],
    i: usize,
) -> (Option<T>, Option<T>) {
    let r = grid.row(i);
    let below = if r > 0 { pairs[i - grid.cols] } else { None };
    let above = if r + 1 < grid.rows() { pairs[i] } else { None };
    (below, above)
}

/// Points that can belong to a floor or ceiling, judged against their neighbours in the same
/// column (adjacent scans) in the provisional level frame: at least one neighbour lies at the
/// same height (within the vertical noise of both and what an error in up does across their
/// horizontal separation), and none rises steeply from it (a height step larger than the
/// noise and larger than the horizontal step, as up a wall). A wall's foot lies within a
/// floor plane's tolerance, but the wall point above it rises steeply; on a floor the scans
/// step far outwards at one height. The vertical noise of grazing floor hits is small, so
/// the test stays sharp at high range noise, unlike steps in range.
pub(crate) fn flat_points(f: &Frame) -> Vec<bool> {
    let (grid, lv, s, min_sigma, sigma_up, k) =
        (f.grid, &f.lv, f.s, f.params.min_sigma, f.sigma_up, f.k);
    // Some(true) flat, Some(false) steep, None neither or no neighbour.
    let pair = |i: usize, j: usize| -> Option<bool> {
        let ((a, da), (b, db)) = (lv[i].as_ref()?, lv[j].as_ref()?);
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
    let pairs = row_pairs(grid, pair);
    // Flat to a neighbour, and steep to none.
    let flat = |i| {
        let steps = row_steps(grid, &pairs, i);
        matches!(steps, (Some(true), None | Some(true)) | (None, Some(true)))
    };
    (0..grid.points.len()).map(flat).collect()
}
