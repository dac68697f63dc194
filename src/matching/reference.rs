//! What a scan is matched against: points with line normals and a search grid over them.
//!
//! Normals come from the reference scan's own neighbours in ray order (Censi 2008 uses the
//! segment through the two nearest points; a small line fit is steadier under noise). Near a
//! corner the centred window straddles two walls, so the one-sided windows are tried as well
//! and the flattest fit wins.

use super::covariance::rays_per_degree_from;
use super::dense;
use super::grid::{Hit, PointGrid, scan_cell};
use super::solve::symmetric_eigenvalues_2x2;
use crate::geometry::minor_axis_2x2;
use nalgebra::{Matrix2, Point2, Vector2};

/// The nearest reference point to a query.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Neighbour {
    pub point: Point2<f64>,
    /// The reference surface there, when its neighbourhood is a line (not a corner, clutter
    /// or a lone point).
    pub line: Option<Line>,
    /// Squared distance from the query \[m²\].
    pub dist2: f64,
}

/// Anything a scan can be matched against: one scan (pairwise) or the map (metascan).
pub trait Target {
    /// The nearest reference point to `p` when it lies within `sqrt(max_d2)`, else `None`
    /// (the same as `nearest(p)` filtered by its distance, found without looking farther).
    fn nearest_within(&self, p: &Point2<f64>, max_d2: f64) -> Option<Neighbour>;
    fn nearest(&self, p: &Point2<f64>) -> Option<Neighbour> {
        self.nearest_within(p, f64::INFINITY)
    }
    /// [`Self::nearest_within`], and what lets a query near `p` skip the search (see
    /// [`Self::nearest_reusing`]): `None` when it proves nothing.
    fn nearest_certified(
        &self,
        p: &Point2<f64>,
        max_d2: f64,
    ) -> (Option<Neighbour>, Option<Certificate>) {
        (self.nearest_within(p, max_d2), None)
    }
    /// What `nearest_within(p, max_d2)` answers, for `p` closer (strictly) than
    /// `certificate.margin` to `certificate.at` (a query of `nearest_certified` with the
    /// same `max_d2`): the neighbour found then is still the nearest, so no search is made.
    fn nearest_reusing(
        &self,
        p: &Point2<f64>,
        max_d2: f64,
        _certificate: &Certificate,
    ) -> Option<Neighbour> {
        self.nearest_within(p, max_d2)
    }
    /// Number of points (0 means nothing to match against).
    fn len(&self) -> usize;
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// A query's nearest grid point with how far a later query may move from it and still have
/// that point as its nearest (`PointGrid::nearest_certified`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Certificate {
    /// Where the certified query was made.
    pub at: Point2<f64>,
    /// Queries closer than this to `at` (strictly) have the same nearest grid point \[m\].
    pub margin: f64,
    /// The nearest grid point's item and position; `None`: no point within the bound.
    nearest: Option<(u32, Point2<f64>)>,
}

impl Certificate {
    pub(crate) fn new(at: Point2<f64>, hit: Option<&Hit>, margin: f64) -> Option<Self> {
        (margin > 0.0).then_some(Self {
            at,
            margin,
            nearest: hit.map(|hit| (hit.item, hit.point)),
        })
    }

    /// What the grid answers a query at `p` within `max_d2`, `p` within the margin.
    #[inline]
    pub(crate) fn again(&self, p: &Point2<f64>, max_d2: f64) -> Option<Hit> {
        let (item, point) = self.nearest?;
        PointGrid::again(p, max_d2, item, point)
    }
}

/// A local line fitted through a reference point's neighbours.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Line {
    /// Unit normal, facing the scanner.
    pub normal: Vector2<f64>,
    /// The reference point moved onto the fitted line: the fit averages the range noise of
    /// its neighbours, so point-to-line residuals measure from here rather than from the raw,
    /// noisy point.
    pub anchor: Point2<f64>,
}

/// Normal estimation settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NormalParams {
    /// Neighbours on each side (in ray order) used for the line fit \[rays\]. Default 4.
    pub window: usize,
    /// A larger step between consecutive points ends the neighbourhood \[m\]. Default 0.3.
    pub max_gap: f64,
    /// Far away, the step may be up to this many times the rays' spacing at the nearer
    /// point's range instead [-]. Default 4: a surface seen at up to 75 degrees' incidence
    /// (1 / cos 75° ≈ 4). Rays 1 degree apart meet a wall 20 m away 35 cm apart head-on; with
    /// a fixed gap alone, the end walls and pillar faces that pin a hall's length would be
    /// lone points, matched point to point, and the pairs' information would see only the
    /// long walls (docs/RESULTS.md, ninth session).
    pub gap_spacings: f64,
    /// Largest accepted thickness of the fit, sqrt(λ_min / λ_max) of the scatter [-].
    /// Default 0.15.
    pub max_thickness: f64,
    /// A denser scan takes its lines from the means of runs of consecutive rays, spaced at
    /// most this density \[rays/deg\]. Default 2 (0.5 degree, the finest spacing of the SICK
    /// family and of the CARMEN logs, whose lines are fitted as they were): `window` is
    /// counted in rays, and at 0.25 degree it spans too little of a wall to beat the range
    /// noise ([`dense`](super::dense)). 0 fits the lines through the raw rays.
    pub max_rays_per_degree: f64,
    /// The scan's range noise \[m\]. Default 0.01, what `window` is made for. A noisier scan
    /// takes its lines from the means of runs of rays as a dense one does, long enough for
    /// normals as good as the window's at 1 cm (3 rays at 5 cm, 5 at 10 cm;
    /// [`dense`](super::dense)). `match` sets it from `--sigma` or the scans' `readings_sigma`.
    pub range_sigma: f64,
}

impl Default for NormalParams {
    fn default() -> Self {
        Self {
            window: 4,
            max_gap: 0.3,
            gap_spacings: 4.0,
            max_thickness: 0.15,
            max_rays_per_degree: 2.0,
            range_sigma: dense::WINDOW_SIGMA,
        }
    }
}

/// Local lines of points given in scan order, seen from `sensor` (normals face it).
pub fn estimate_lines(
    points: &[Point2<f64>],
    sensor: &Point2<f64>,
    params: &NormalParams,
) -> Vec<Option<Line>> {
    let k = dense::run_length(rays_per_degree_from(points, sensor), params);
    lines_in_runs(points, sensor, k, params)
}

/// [`estimate_lines`] with the run length `k` already chosen ([`dense::run_length`]): through
/// every ray (`k` = 1), else through the means of runs of `k` rays
/// ([`dense::lines_from_runs`]).
pub(crate) fn lines_in_runs(
    points: &[Point2<f64>],
    sensor: &Point2<f64>,
    k: usize,
    params: &NormalParams,
) -> Vec<Option<Line>> {
    match k {
        0 | 1 => lines_through(points, sensor, params),
        k => dense::lines_from_runs(points, sensor, k, params),
    }
}

/// Local lines fitted through every point's neighbours in scan order.
pub(crate) fn lines_through(
    points: &[Point2<f64>],
    sensor: &Point2<f64>,
    params: &NormalParams,
) -> Vec<Option<Line>> {
    let n = points.len();
    // Chain break before index i when the step from i-1 is too long.
    let gap_before: Vec<bool> = (0..n)
        .map(|i| i > 0 && is_gap(points[i - 1] - sensor, points[i] - sensor, params))
        .collect();
    (0..n)
        .map(|i| {
            let mut lo = i;
            while lo > 0 && i - lo < params.window && !gap_before[lo] {
                lo -= 1;
            }
            let mut hi = i;
            while hi + 1 < n && hi - i < params.window && !gap_before[hi + 1] {
                hi += 1;
            }
            let best = [(lo, hi), (lo, i), (i, hi)]
                .into_iter()
                .filter(|(a, b)| b - a >= 2)
                .filter_map(|(a, b)| line_fit(&points[a..=b]))
                .min_by(|x, y| x.1.total_cmp(&y.1))?;
            let (scatter, thickness, centroid) = best;
            if thickness > params.max_thickness {
                return None;
            }
            // Only the flattest fit's normal is needed: its axis is taken from its scatter.
            let mut normal = minor_axis_2x2(&scatter);
            if normal.dot(&(sensor - points[i])) < 0.0 {
                normal = -normal;
            }
            let anchor = points[i] - normal * normal.dot(&(points[i] - centroid));
            Some(Line { normal, anchor })
        })
        .collect()
}

/// Whether consecutive points `u`, `v` (relative to the sensor) are too far apart to lie on
/// one surface: farther than `max_gap` and than `gap_spacings` times the rays' spacing at
/// the nearer range (`|u × v| / max(|u|, |v|)` = min(|u|, |v|) sin of the angle between them:
/// the rays' spacing where no ray between them was dropped).
pub(crate) fn is_gap(u: Vector2<f64>, v: Vector2<f64>, params: &NormalParams) -> bool {
    let spacing = u.perp(&v).abs() / u.norm().max(v.norm()).max(f64::MIN_POSITIVE);
    (u - v).norm() > params.max_gap.max(params.gap_spacings * spacing)
}

/// Total-least-squares line through `pts`: (scatter, whose minor axis is the unit normal;
/// thickness sqrt(λ_min/λ_max); centroid).
fn line_fit(pts: &[Point2<f64>]) -> Option<(Matrix2<f64>, f64, Point2<f64>)> {
    let k = pts.len() as f64;
    let mean = pts.iter().fold(Vector2::zeros(), |acc, p| acc + p.coords) / k;
    let mut cov = Matrix2::zeros();
    for p in pts {
        let d = p.coords - mean;
        cov += d * d.transpose();
    }
    let (lmin, lmax) = symmetric_eigenvalues_2x2(&cov);
    if lmax <= 0.0 {
        return None;
    }
    let thickness = (lmin.max(0.0) / lmax).sqrt();
    Some((cov, thickness, Point2::from(mean)))
}

/// One scan as a match target: its points, their local lines and a grid over them.
pub struct ScanReference {
    points: Vec<Point2<f64>>,
    lines: Vec<Option<Line>>,
    grid: PointGrid,
}

impl ScanReference {
    /// Points in scan order, in the reference frame, seen from `sensor` in that frame.
    pub fn new(points: Vec<Point2<f64>>, sensor: &Point2<f64>, params: &NormalParams) -> Self {
        let lines = estimate_lines(&points, sensor, params);
        Self::with_lines(points, lines)
    }

    pub fn with_lines(points: Vec<Point2<f64>>, lines: Vec<Option<Line>>) -> Self {
        let grid = PointGrid::from_points(scan_cell(&points), &points);
        Self {
            points,
            lines,
            grid,
        }
    }

    pub fn points(&self) -> &[Point2<f64>] {
        &self.points
    }

    pub fn lines(&self) -> &[Option<Line>] {
        &self.lines
    }
}

impl Target for ScanReference {
    fn nearest_within(&self, p: &Point2<f64>, max_d2: f64) -> Option<Neighbour> {
        self.grid
            .nearest_within(p, max_d2)
            .map(|hit| self.neighbour(&hit))
    }

    fn nearest_certified(
        &self,
        p: &Point2<f64>,
        max_d2: f64,
    ) -> (Option<Neighbour>, Option<Certificate>) {
        let (hit, margin) = self.grid.nearest_certified(p, max_d2);
        (
            hit.as_ref().map(|hit| self.neighbour(hit)),
            Certificate::new(*p, hit.as_ref(), margin),
        )
    }

    #[inline]
    fn nearest_reusing(
        &self,
        p: &Point2<f64>,
        max_d2: f64,
        certificate: &Certificate,
    ) -> Option<Neighbour> {
        certificate.again(p, max_d2).map(|hit| self.neighbour(&hit))
    }

    fn len(&self) -> usize {
        self.points.len()
    }
}

impl ScanReference {
    #[inline]
    fn neighbour(&self, hit: &Hit) -> Neighbour {
        let i = hit.item as usize;
        Neighbour {
            point: self.points[i],
            line: self.lines[i],
            dist2: hit.dist2,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normals_at_a_corner_follow_each_wall() {
        // An L: wall along y = 2 (x from -1 to 0), then wall along x = 0 (y from 2 down to 0).
        let mut pts: Vec<Point2<f64>> = (0..10)
            .map(|i| Point2::new(-1.0 + 0.1 * i as f64, 2.0))
            .collect();
        pts.extend((0..10).map(|i| Point2::new(0.0, 2.0 - 0.1 * i as f64)));
        let lines = estimate_lines(&pts, &Point2::new(-1.0, 0.0), &NormalParams::default());
        for (i, l) in lines.iter().enumerate() {
            let l = l.expect("every point lies on a straight wall");
            assert!((l.anchor - pts[i]).norm() < 1e-12);
            let n = l.normal;
            if i == 10 {
                // The corner itself lies on both walls; either normal is right.
                assert!(n.x.abs() < 1e-9 || n.y.abs() < 1e-9);
                continue;
            }
            let expect = if i < 10 {
                Vector2::new(0.0, -1.0)
            } else {
                Vector2::new(-1.0, 0.0)
            };
            assert!((n - expect).norm() < 1e-9, "point {i}: {n:?}");
        }
    }

    #[test]
    fn a_far_wall_keeps_its_lines_and_a_step_between_surfaces_still_ends_a_chain() {
        // Rays 1 degree apart meet a wall 20 m ahead about 35 cm apart: one surface.
        let on_wall = |deg: f64| {
            let a = deg.to_radians();
            Point2::new(20.0, 20.0 * a.tan())
        };
        let wall: Vec<Point2<f64>> = (-10..=10).map(|d| on_wall(d as f64)).collect();
        let lines = estimate_lines(&wall, &Point2::origin(), &NormalParams::default());
        for (i, l) in lines.iter().enumerate() {
            let l = l.unwrap_or_else(|| panic!("point {i} has no line"));
            assert!(
                (l.normal - Vector2::new(-1.0, 0.0)).norm() < 1e-9,
                "{i}: {l:?}"
            );
        }
        // With the fixed gap alone, every step is a gap and no point has a line.
        let fixed = NormalParams {
            gap_spacings: 0.0,
            ..NormalParams::default()
        };
        let lines = estimate_lines(&wall, &Point2::origin(), &fixed);
        assert!(lines.iter().all(Option::is_none));
        // Far, consecutive points 2 m apart in depth are another surface (4 spacings at
        // 20 m are 1.4 m); near, 0.3 m is the limit.
        let p = NormalParams::default();
        let o = Point2::origin();
        let gap = |u: Point2<f64>, v: Point2<f64>| is_gap(u - o, v - o, &p);
        assert!(!gap(on_wall(0.0), on_wall(1.0)));
        assert!(gap(
            on_wall(0.0),
            Point2::new(22.0, 22.0 * 1f64.to_radians().tan())
        ));
        let at = |r: f64, deg: f64| {
            let (s, c) = deg.to_radians().sin_cos();
            Point2::new(r * c, r * s)
        };
        assert!(!gap(at(2.0, 0.0), at(2.25, 1.0)));
        assert!(gap(at(2.0, 0.0), at(2.31, 1.0)));
    }

    #[test]
    fn nearest_matches_brute_force() {
        let pts: Vec<Point2<f64>> = (0..200)
            .map(|i| {
                let a = i as f64 * 0.37;
                Point2::new(a.cos() * (1.0 + 0.01 * i as f64), a.sin() * 2.0)
            })
            .collect();
        let r = ScanReference::with_lines(pts.clone(), vec![None; pts.len()]);
        for k in 0..50 {
            let q = Point2::new(-2.0 + 0.08 * k as f64, 1.5 - 0.06 * k as f64);
            let brute = pts
                .iter()
                .map(|p| (p - q).norm_squared())
                .fold(f64::INFINITY, f64::min);
            let got = r.nearest(&q).unwrap();
            assert!((got.dist2 - brute).abs() < 1e-12);
        }
    }
}
