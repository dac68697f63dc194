//! Wall patches: the paper's quads merged with their coplanar neighbours by region growing over
//! the scan grid, so that a whole wall votes with all its points (the paper's sect. 9 suggests
//! EM plane fitting after Thrun et al. 2004; region growing from good seeds reaches the same
//! planes far more cheaply for a handful of scans).

use super::grid::{PlaneAccumulator, PlaneFit, PoseGrid};
use super::polygons::{Polygon, classify, extract_quads_sized};
use super::{LevelParams, SurfaceKind};
use std::collections::VecDeque;

/// One grown planar patch.
#[derive(Clone, Debug)]
pub struct Patch {
    pub fit: PlaneFit,
    pub kind: SurfaceKind,
    /// Grid indices (row * cols + col) of its points.
    pub members: Vec<usize>,
    /// Lowest and highest row it reaches.
    pub row_range: (usize, usize),
}

/// No patch.
pub const UNLABELLED: u32 = u32::MAX;

/// Grows patches from the quads (best-fitting first), then from two-row quads over what is left
/// (a wall that only two scans reach, e.g. ahead of a robot pitched towards the floor). A neighbouring grid point (same column in
/// the next row, or next column in the same row) joins when it lies within `grow_k * sigma` of
/// the patch's current plane; the plane is refitted as the patch grows. Finally members farther
/// than that from the final plane are released and the plane refitted once more.
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
    let by_fit = |qs: &[Polygon]| {
        let mut order: Vec<usize> = (0..qs.len()).collect();
        order.sort_by(|&a, &b| {
            let qa = qs[a].fit.residual_ss / qs[a].fit.n as f64;
            let qb = qs[b].fit.residual_ss / qs[b].fit.n as f64;
            qa.total_cmp(&qb).then(a.cmp(&b))
        });
        order
    };
    let two_row: Vec<Polygon> = if params.quad_rows > 2 {
        extract_quads_sized(grid, params, sigma, 2, params.quad_cols)
    } else {
        Vec::new()
    };
    let seeds: Vec<&Polygon> = by_fit(quads)
        .into_iter()
        .map(|i| &quads[i])
        .chain(by_fit(&two_row).into_iter().map(|i| &two_row[i]))
        .collect();
    let mut queue = VecDeque::new();
    let mut members = Vec::new();
    for q in seeds {
        if q.span(cols).any(|i| labels[i] != UNLABELLED) {
            continue;
        }
        let id = patches.len() as u32;
        let mut acc = PlaneAccumulator::default();
        members.clear();
        queue.clear();
        for i in q.span(cols) {
            labels[i] = id;
            members.push(i);
            queue.push_back(i);
            if let Some(g) = &grid.points[i] {
                acc.add(g);
            }
        }
        let Some(mut fit) = acc.fit(sigma) else {
            continue;
        };
        let mut refit_at = acc.n + acc.n / 3 + 1;
        while let Some(i) = queue.pop_front() {
            let (r, c) = (i / cols, i % cols);
            let mut neighbours = [usize::MAX; 4];
            if c > 0 {
                neighbours[0] = i - 1;
            }
            if c + 1 < cols {
                neighbours[1] = i + 1;
            }
            if r > 0 {
                neighbours[2] = i - cols;
            }
            if r + 1 < grid.rows() {
                neighbours[3] = i + cols;
            }
            for j in neighbours {
                if j == usize::MAX || labels[j] != UNLABELLED {
                    continue;
                }
                let Some(g) = &grid.points[j] else { continue };
                if fit.distance(&g.p).abs() <= tol {
                    labels[j] = id;
                    members.push(j);
                    queue.push_back(j);
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
        let mut kept = PlaneAccumulator::default();
        members.retain(|&i| {
            let Some(g) = grid.points[i].as_ref() else {
                return false;
            };
            if fit.distance(&g.p).abs() <= tol {
                kept.add(g);
                true
            } else {
                labels[i] = UNLABELLED;
                false
            }
        });
        let (lo, hi) = members.iter().fold((usize::MAX, 0), |(lo, hi), &i| {
            (lo.min(i / cols), hi.max(i / cols))
        });
        let fit = kept.fit(sigma);
        match fit {
            Some(fit) if members.len() >= params.min_patch_points && hi > lo => {
                patches.push(Patch {
                    kind: classify(&fit.normal, &fit.centroid, params),
                    fit,
                    members: members.clone(),
                    row_range: (lo, hi),
                });
            }
            _ => {
                for &i in &members {
                    labels[i] = UNLABELLED;
                }
            }
        }
    }
    (patches, labels)
}
