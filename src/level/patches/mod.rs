//! Wall patches: the paper's quads merged with their coplanar neighbours by region growing over
//! the scan grid, so that a whole wall votes with all its points (the paper's sect. 9 suggests
//! EM plane fitting after Thrun et al. 2004; region growing from good seeds reaches the same
//! planes far more cheaply for a handful of scans).

use super::grid::{GridPoint, PlaneAccumulator, PlaneFit, PoseGrid};
use super::polygons::{Polygon, classify, extract_quads};
use super::{LevelParams, SurfaceKind, median_of, total_order_key};
use nalgebra::{Point3, Vector3};

mod fit;
mod split;
mod trim;

use crate::level::params::patches::*;
use fit::*;
pub use split::split_members;
use split::*;
use trim::*;

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
    let mid = grid.points.iter().flatten().count() / 2;
    let slack = params.quad_cols.saturating_sub(2).max(1) as f64;
    let t = params.seed_span_sigmas * sigma / (slack * step).max(1e-300) * (1.0 + 1e-9);
    if t.is_finite() && want(t) <= params.quad_cols {
        let below = grid.points.iter().flatten().filter(|g| g.range < t).count();
        if below <= mid {
            return params.quad_cols;
        }
    }
    let mut ranges: Vec<f64> = grid.points.iter().flatten().map(|g| g.range).collect();
    clamp(want(median_of(&mut ranges)))
}

/// No patch.
pub(crate) const UNLABELLED: u32 = u32::MAX;

/// Grows patches from seed quads: walls first, best-fitting first, then floors and ceilings;
/// three-row seeds before two-row ones (a wall that only two scans reach, e.g. ahead of a robot
/// pitched towards the floor). Seeds are as wide as the paper's quads at low noise and wider at
/// high noise ([`seed_cols`]), since a seed's plane must be good enough to grow from.
/// A neighbouring grid point (same column in the next row, or next column in the same row)
/// joins when it lies within `grow_k * sigma` of the patch's current plane; the plane is
/// refitted as the patch grows. Finally members farther than that from the final plane are
/// released and the plane refitted once more.
/// Returns the patches and, per grid point, the index of its patch or [`UNLABELLED`].
pub(crate) fn grow_patches(
    grid: &PoseGrid,
    quads: &[Polygon],
    params: &LevelParams,
    sigma: f64,
) -> (Vec<Patch>, Vec<u32>) {
    let mut labels = vec![UNLABELLED; grid.points.len()];
    let mut patches = Vec::new();
    let growth = Growth {
        grid,
        params,
        sigma,
    };
    let width = seed_cols(grid, params, sigma);
    let wide: Vec<Polygon>;
    let three_row: &[Polygon] = if width == params.quad_cols {
        quads
    } else {
        wide = extract_quads(grid, params, sigma, width);
        &wide
    };
    let mut members = Vec::new();
    for q in ordered_seeds(three_row, quads, width != params.quad_cols) {
        let id = patches.len() as u32;
        patches.extend(growth.grow_seed(q, id, &mut labels, &mut members));
    }
    let split = growth.split_two_plane_patches(patches);
    let labels = labels_of(grid.points.len(), &split);
    (split, labels)
}

/// Per grid point (of `n`), the index of the patch among `patches` that holds it, or
/// [`UNLABELLED`].
pub(crate) fn labels_of(n: usize, patches: &[Patch]) -> Vec<u32> {
    let mut labels = vec![UNLABELLED; n];
    for (id, p) in patches.iter().enumerate() {
        for &i in &p.members {
            labels[i] = id as u32;
        }
    }
    labels
}

/// The seeds of [`grow_patches`] in the order they are tried (sect. 5.2's quads as seeds):
/// walls before floors and ceilings, then by mean squared residual, then by position, packed
/// in one integer key (unique, so an unstable sort gives the stable order). With
/// `narrow_level`, floors and ceilings also seed from the paper's narrow `quads` after the
/// wide ones: along a level surface's normal the grazing rays carry little noise, so a narrow
/// quad pins its plane well, and a wide quad rarely fits where the floor is seen only near an
/// edge of the scans (its far and near sides too unequal, or a wall inside it).
fn ordered_seeds<'a>(
    three_row: &'a [Polygon],
    quads: &'a [Polygon],
    narrow_level: bool,
) -> Vec<&'a Polygon> {
    let narrow = quads
        .iter()
        .filter(|q| narrow_level && q.kind != SurfaceKind::Wall);
    let candidates: Vec<(u8, &Polygon)> = three_row
        .iter()
        .map(|q| (0u8, q))
        .chain(narrow.map(|q| (2u8, q)))
        .collect();
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
    keys.iter()
        .map(|&k| candidates[(k as u32) as usize].1)
        .collect()
}

/// What growing patches over one grid needs: the grid, the parameters and the range noise as
/// given.
struct Growth<'a> {
    grid: &'a PoseGrid,
    params: &'a LevelParams,
    sigma: f64,
}

impl Growth<'_> {
    /// One patch grown from seed `q` as patch `id` (sect. 9's region growing from a sect. 5.2
    /// quad): nothing when the seed overlaps a patch already grown, or when the grown members
    /// make no patch ([`Growth::make_patch`]), in which case their labels are freed again.
    /// `members` is scratch space reused across seeds.
    fn grow_seed(
        &self,
        q: &Polygon,
        id: u32,
        labels: &mut [u32],
        members: &mut Vec<usize>,
    ) -> Option<Patch> {
        let (grid, sigma) = (self.grid, self.sigma);
        let cols = grid.cols;
        if q.span(cols).any(|i| labels[i] != UNLABELLED) {
            return None;
        }
        let mut acc = PlaneAccumulator::default();
        members.clear();
        for i in q.span(cols) {
            labels[i] = id;
            members.push(i);
            if let Some(g) = &grid.points[i] {
                acc.add(g);
            }
        }
        let mut fit = acc.fit(sigma)?;
        self.flood(id, labels, members, &mut acc, &mut fit);
        let made = self.release_and_make(members, &acc, |i| labels[i] = UNLABELLED);
        if made.is_none() {
            members.iter().for_each(|&i| labels[i] = UNLABELLED);
        }
        made
    }

    /// The patch of `members` (their sums `acc`) without the members their plane does not
    /// explain (beyond [`ray_tolerance`]), each of which goes to `release`
    /// ([`Growth::make_patch`]).
    fn release_and_make(
        &self,
        members: &mut Vec<usize>,
        acc: &PlaneAccumulator,
        mut release: impl FnMut(usize),
    ) -> Option<Patch> {
        let (grid, params) = (self.grid, self.params);
        let s_eff = self.sigma.max(params.min_sigma);
        let fit = acc.fit(self.sigma)?;
        // Few are released: their sums come off the accumulator, rather than the kept ones'
        // being summed again.
        let mut released = PlaneAccumulator::default();
        members.retain(|&i| {
            let Some(g) = grid.points[i].as_ref() else {
                return false;
            };
            let kept = fit.distance(&g.p).abs() <= ray_tolerance(&fit, g, s_eff, params);
            if !kept {
                released.add(g);
                release(i);
            }
            kept
        });
        self.make_patch(members, acc.minus(&released))
    }

    /// Patches that are really two planes (grown across a corner or a wall's foot) split into
    /// their planes ([`split_members`]) when their misfit ratio exceeds `split_misfit`: sect. 9's
    /// EM would give each plane its own points; here a contiguous split does.
    fn split_two_plane_patches(&self, patches: Vec<Patch>) -> Vec<Patch> {
        let (grid, params, sigma) = (self.grid, self.params, self.sigma);
        let mut split = Vec::with_capacity(patches.len());
        for p in patches {
            if plane_explained(&p.fit, sigma, params) {
                split.push(p);
                continue;
            }
            for mut part in split_members(grid, &p.members, params, sigma, params.split_depth) {
                let acc = grid.accumulate(&part);
                split.extend(self.release_and_make(&mut part, &acc, |_| {}));
            }
        }
        split
    }

    /// A patch from members when it is big enough and spans at least two rows (one row is a
    /// line, which leaves its plane free to turn about it). `acc` holds the sums of the members'
    /// points (the callers have just visited them).
    fn make_patch(&self, members: &[usize], acc: PlaneAccumulator) -> Option<Patch> {
        let (grid, params, sigma) = (self.grid, self.params, self.sigma);
        // In grid order from here: the passes below then walk the grid forwards.
        let sorted = ascending(members);
        let members = &sorted[..];
        // The rows spanned, unless too small or one row: nothing to fit (trimming only takes
        // points away).
        let span = |members: &[usize]| patch_rows(members, grid.cols, params);
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
        let fit = self.robust_fit(members, first)?;
        let fronted = without_front_row_ends(grid, members, &fit, params, sigma);
        let (members, fit) = match &fronted {
            Some(kept) if !still_a_patch(kept) => return None,
            Some(kept) => {
                let first = grid.accumulate(kept).fit(sigma)?;
                (&kept[..], self.robust_fit(kept, first)?)
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
            kind: classify(&fit.normal, &fit.centroid, params.wall_cos()),
            fit,
            members: members.to_vec(),
            row_range: (lo, hi),
        })
    }

    /// The breadth-first growth of one patch (sect. 9's region growing): an unlabelled
    /// neighbour (left, right, previous or next row) of a member joins when within
    /// [`ray_tolerance`] of the current plane `fit`, which is refitted each time the members
    /// grew by a third, so the plane follows the surface without a refit per point. The members
    /// not yet visited are the queue.
    fn flood(
        &self,
        id: u32,
        labels: &mut [u32],
        members: &mut Vec<usize>,
        acc: &mut PlaneAccumulator,
        fit: &mut PlaneFit,
    ) {
        let (grid, params, sigma) = (self.grid, self.params, self.sigma);
        let s_eff = sigma.max(params.min_sigma);
        let (n, cols) = (grid.points.len(), grid.cols);
        let mut refit_at = acc.n + acc.n / 3 + 1;
        let mut next = 0;
        while let Some(&i) = members.get(next) {
            next += 1;
            let c = i % cols;
            // Left, right, previous and next row; `usize::MAX` where the grid ends (cheaper in
            // this, the hottest loop of region growing, than Options).
            let neighbours = [
                if c > 0 { i - 1 } else { usize::MAX },
                if c + 1 < cols { i + 1 } else { usize::MAX },
                if i >= cols { i - cols } else { usize::MAX },
                if i + cols < n { i + cols } else { usize::MAX },
            ];
            for j in neighbours {
                if j == usize::MAX || labels[j] != UNLABELLED {
                    continue;
                }
                let Some(g) = &grid.points[j] else { continue };
                if fit.distance(&g.p).abs() <= ray_tolerance(fit, g, s_eff, params) {
                    labels[j] = id;
                    members.push(j);
                    acc.add(g);
                    if acc.n >= refit_at {
                        *fit = acc.fit(sigma).unwrap_or(*fit);
                        refit_at = acc.n + acc.n / 3 + 1;
                    }
                }
            }
        }
    }
}

/// [`Check::PatchSplitMisfit`](super::checks::Check::PatchSplitMisfit): whether a patch's
/// plane explains its points within `split_misfit` of the noise, so that it is not tested for
/// being two planes (nor its edge rows for standing off).
pub(crate) fn plane_explained(fit: &PlaneFit, sigma: f64, params: &LevelParams) -> bool {
    fit.misfit_ratio(sigma.max(params.min_sigma)) <= params.split_misfit
}

/// The lowest and highest rows of members in ascending order (rows grow with the grid index):
/// their first's and last's; `(usize::MAX, 0)` for none.
pub(crate) fn rows_span_sorted(members: &[usize], cols: usize) -> (usize, usize) {
    match (members.first(), members.last()) {
        (Some(&lo), Some(&hi)) => (lo / cols, hi / cols),
        _ => (usize::MAX, 0),
    }
}

/// [`Check::PatchMinPoints`](super::checks::Check::PatchMinPoints): the rows that ascending
/// `members` span, when they are at least `min_patch_points` over two rows or more.
pub(crate) fn patch_rows(
    members: &[usize],
    cols: usize,
    params: &LevelParams,
) -> Option<(usize, usize)> {
    let (lo, hi) = rows_span_sorted(members, cols);
    (members.len() >= params.min_patch_points && hi > lo).then_some((lo, hi))
}

#[cfg(test)]
mod tests;
