//! Surface polygon extraction (paper sect. 5.2): quadrilaterals `rows` scans high and `cols`
//! rays wide, placed greedily left to right over every band of adjacent rows.

use super::grid::{PlaneAccumulator, PlaneFit, PoseGrid};
use super::{LevelParams, SurfaceKind};
use crate::level::params::quads::*;
use nalgebra::{Point3, Vector3};

/// One extracted quadrilateral.
#[derive(Clone, Debug)]
pub struct Polygon {
    /// First (lowest-elevation) row and first column of its span.
    pub row: usize,
    pub col: usize,
    /// Rows and columns spanned.
    pub rows: usize,
    pub cols: usize,
    /// Corners in order around the quad, robot frame \[m\].
    pub corners: [Point3<f64>; 4],
    /// Area [m^2] (half the cross product of the diagonals).
    pub area: f64,
    pub fit: PlaneFit,
    pub kind: SurfaceKind,
}

impl Polygon {
    /// Grid indices of the points in its span.
    pub(crate) fn span(&self, cols_total: usize) -> impl Iterator<Item = usize> + '_ {
        (self.row..self.row + self.rows)
            .flat_map(move |r| (self.col..self.col + self.cols).map(move |c| r * cols_total + c))
    }
}

/// Classifies a plane by the angle of its normal to the robot's up (0, 0, 1): more than
/// `wall_min_angle` away (`wall_cos`, [`LevelParams::wall_cos`], computed once for many quads)
/// is a wall (the paper assumes tilts below 45 degrees), otherwise floor when the plane passes
/// below the scanner (along its up-pointing normal) and ceiling when above. (A point's
/// robot-frame z would not do: a beam tilted up in the robot frame still meets the floor when
/// the robot pitches down.)
pub(crate) fn classify(
    normal: &Vector3<f64>,
    centroid: &Point3<f64>,
    wall_cos: f64,
) -> SurfaceKind {
    if normal.z.abs() < wall_cos {
        SurfaceKind::Wall
    } else if normal.dot(&centroid.coords) * normal.z.signum() < 0.0 {
        SurfaceKind::Floor
    } else {
        SurfaceKind::Ceiling
    }
}

/// Extracts the paper's quads: a quad is kept when all its points are valid, lie within
/// `coplanar_k * sigma` of its plane, and it is not close to a triangle. Walls, floors and
/// ceilings are all returned (with their kind), so that failure detection can tell a robot
/// facing the floor from one that sees nothing. Greedy per band: after a kept quad the next one
/// starts on its right edge; after a rejected one, one column further right. The quads are
/// `quad_rows` high and `cols` wide (the paper's `quad_cols`, or a region-growing seed's width).
pub(crate) fn extract_quads(
    grid: &PoseGrid,
    params: &LevelParams,
    sigma: f64,
    cols: usize,
) -> Vec<Polygon> {
    let (qr, qc) = (params.quad_rows.max(2), cols.max(2));
    if grid.rows() < qr || grid.cols < qc {
        return Vec::new();
    }
    // As many as fit edge to edge in every band: no reallocation, which copied the quads
    // (300 bytes each) about once more.
    let bands = grid.rows() - qr + 1;
    let mut out = Vec::with_capacity(bands * (grid.cols / (qc - 1)));
    let tol = params.coplanar_k * sigma.max(params.min_sigma);
    let wall_cos = params.wall_cos();
    for r in 0..=grid.rows() - qr {
        let mut c = 0;
        while c + qc <= grid.cols {
            match quad_at(grid, r, c, qr, qc, tol, sigma, wall_cos, params) {
                Some(q) => {
                    out.push(q);
                    c += qc - 1;
                }
                None => c += 1,
            }
        }
    }
    out
}

#[allow(clippy::too_many_arguments)]
fn quad_at(
    grid: &PoseGrid,
    r: usize,
    c: usize,
    qr: usize,
    qc: usize,
    tol: f64,
    sigma: f64,
    wall_cos: f64,
    params: &LevelParams,
) -> Option<Polygon> {
    // Every point valid, and their plain sum: the same sum and division as
    // `PlaneAccumulator::centroid` (weights of one), for the cheap test below, before the
    // scatter sums that only quads passing it need.
    let row = |rr: usize| &grid.points[rr * grid.cols + c..rr * grid.cols + c + qc];
    let mut sum = Vector3::zeros();
    for rr in r..r + qr {
        for g in row(rr) {
            sum += g.as_ref()?.p.coords;
        }
    }
    // Every point is valid from here: whether any lies beyond `limit` from a plane.
    let beyond = |n: &Vector3<f64>, origin: &Point3<f64>, limit: f64| {
        (r..r + qr).any(|rr| any_beyond(n, origin, row(rr).iter().flatten().map(|g| g.p), limit))
    };
    let corner = |rr: usize, cc: usize| grid.at(rr, cc).map(|g| g.p);
    let corners = [
        corner(r, c)?,
        corner(r, c + qc - 1)?,
        corner(r + qr - 1, c + qc - 1)?,
        corner(r + qr - 1, c)?,
    ];
    if near_triangle(&corners, params.min_edge_ratio) {
        return None;
    }
    // Cheap rejection before the eigen decomposition: the plane through the centroid normal to
    // the diagonals' cross product is close to the fit for any quad that can pass, so a point
    // beyond `DIAGONAL_PLANE_TOLERANCES` tolerances from it means a corner or an edge.
    let diag = (corners[2] - corners[0]).cross(&(corners[3] - corners[1]));
    if let Some(n) = diag.try_normalize(1e-12) {
        let centroid = Point3::from(sum / (qr * qc) as f64);
        if beyond(&n, &centroid, DIAGONAL_PLANE_TOLERANCES * tol) {
            return None;
        }
    }
    let mut acc = PlaneAccumulator::default();
    for rr in r..r + qr {
        row(rr).iter().flatten().for_each(|g| acc.add(g));
    }
    let fit = acc.fit(sigma)?;
    // No point is farther than `sqrt(residual_ss)` from the plane: when that is clearly within
    // the tolerance, every point is, and the points need no visit.
    if fit.residual_ss > 0.99 * tol * tol && beyond(&fit.normal, &fit.centroid, tol) {
        return None;
    }
    Some(Polygon {
        row: r,
        col: c,
        rows: qr,
        cols: qc,
        corners,
        area: 0.5 * diag.norm(),
        kind: classify(&fit.normal, &fit.centroid, wall_cos),
        fit,
    })
}

/// [`Check::QuadNearTriangle`](super::checks::Check::QuadNearTriangle): whether a quad with
/// `corners` in order around it is close to a triangle, the shorter of two opposite sides below
/// `min_edge_ratio` of the longer (sect. 5.2).
pub(crate) fn near_triangle(corners: &[Point3<f64>; 4], min_edge_ratio: f64) -> bool {
    let side = |a: usize, b: usize| (corners[a] - corners[b]).norm();
    let ratio = |a: f64, b: f64| a.min(b) / a.max(b).max(1e-300);
    ratio(side(0, 1), side(2, 3)) < min_edge_ratio || ratio(side(3, 0), side(1, 2)) < min_edge_ratio
}

/// [`Check::QuadDiagonal`](super::checks::Check::QuadDiagonal) and
/// [`Check::QuadCoplanar`](super::checks::Check::QuadCoplanar): whether any of `points` lies
/// farther than `limit` from the plane through `origin` with unit normal `n`.
pub(crate) fn any_beyond(
    n: &Vector3<f64>,
    origin: &Point3<f64>,
    mut points: impl Iterator<Item = Point3<f64>>,
    limit: f64,
) -> bool {
    points.any(|p| n.dot(&(p - origin)).abs() > limit)
}
