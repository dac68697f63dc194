//! The pseudo-level scan's keep test (sect. 6, and beyond the paper): which points of one scan
//! lie on walls, given the pose's estimate. See the module above for the rules.

use super::PseudoLevelParams;
use crate::level::grid::{PlaneFit, PoseGrid};
use crate::level::patches::UNLABELLED;
use crate::level::{LevelEstimate, SurfaceKind, from_total_order_key, total_order_key};
use crate::level::{median_of, wall_mask_where};
use nalgebra::{Matrix3, Point3, Vector2};

/// Height window of a crowd at the floor's height \[m\]: the floor's hits of one pose, leveled,
/// gather within it at the noise of a level scan's rays (their vertical component is small).
const CROWD_WINDOW: f64 = 0.05;
/// Fewest points that make a crowd at the floor's height.
const MIN_GROUND_POINTS: usize = 20;
/// Half-width of the band around a crowd-found floor whose points are floor hits \[m\].
const GROUND_BAND: f64 = 0.02;
/// Fewest points of one scan in that crowd for the scan to count as seeing the floor there.
const MIN_ROW_CROWD: usize = 5;

/// The lowest height with at least `min_count` of `heights` within `window` above it: the
/// median of that crowd. `None` when no window holds that many.
fn lowest_crowded_height(heights: &[f64], window: f64, min_count: usize) -> Option<f64> {
    if min_count == 0 || heights.len() < min_count {
        return None;
    }
    // Sorted as `total_cmp` sorts them, by the integer key it compares (computed once per
    // height rather than twice per comparison); equal keys are equal bits, so an unstable
    // sort gives the stable one's order.
    let mut keys: Vec<i64> = heights.iter().map(|&z| total_order_key(z)).collect();
    let heights_of =
        |keys: &[i64]| -> Vec<f64> { keys.iter().map(|&k| from_total_order_key(k)).collect() };
    // The crowd is nearly always among the lowest few crowds' worth of points: sort only
    // those (the same values in the same order as the full sort's start), and sort the rest
    // only when the answer could depend on them.
    let lowest = 4 * min_count;
    if lowest < keys.len() {
        keys.select_nth_unstable(lowest);
        keys[..lowest].sort_unstable();
        if let Some(answer) =
            crowd_in_sorted(&heights_of(&keys[..lowest]), window, min_count, false)
        {
            return answer;
        }
    }
    keys.sort_unstable();
    crowd_in_sorted(&heights_of(&keys), window, min_count, true).flatten()
}

/// [`lowest_crowded_height`] on sorted heights, all of them (`complete`) or only the lowest
/// of them (the rest lie at or above the last): `Some(answer)` when these settle it.
fn crowd_in_sorted(
    sorted: &[f64],
    window: f64,
    min_count: usize,
    complete: bool,
) -> Option<Option<f64>> {
    let Some(i) =
        (0..=sorted.len() - min_count).find(|&i| sorted[i + min_count - 1] - sorted[i] <= window)
    else {
        return complete.then_some(None);
    };
    let top = sorted[i] + window;
    let end = sorted.partition_point(|&z| z <= top);
    (complete || end < sorted.len()).then(|| Some(sorted[(i + end) / 2]))
}

/// Where no floor patch gives the floor's height: the lowest crowd of leveled points (a
/// height nothing lies below), and that same height when it is the floor itself, i.e. when two
/// scans at different elevations put points there (one scan's line along a wall is a crowd of
/// one).
fn ground_crowd(
    grid: &PoseGrid,
    level_from_robot: &Matrix3<f64>,
    margin: f64,
) -> (Option<f64>, Option<f64>) {
    // Leveled heights of the valid points, and each one's row.
    let mut heights = Vec::with_capacity(grid.points.len());
    let mut rows = Vec::with_capacity(grid.points.len());
    for (row, points) in grid.points.chunks(grid.cols.max(1)).enumerate() {
        for g in points.iter().flatten() {
            heights.push((level_from_robot * g.p.coords).z);
            rows.push(row);
        }
    }
    let min_count = (heights.len() / 20).max(MIN_GROUND_POINTS);
    let Some(z0) = lowest_crowded_height(&heights, margin, min_count) else {
        return (None, None);
    };
    let mut per_row = vec![0usize; grid.rows()];
    for (&z, &row) in heights.iter().zip(&rows) {
        if z >= z0 - margin && z <= z0 + margin {
            per_row[row] += 1;
        }
    }
    let rows = per_row.iter().filter(|&&k| k >= MIN_ROW_CROWD).count();
    (Some(z0), (rows >= 2).then_some(z0))
}

/// Slack on how far a filled gap point may stray from its wall neighbours \[m\].
const GAP_SLACK: f64 = 0.05;

/// What the keep test needs of the whole pose, found once for all its scans: the floor's and
/// ceiling's heights in the level frame and the band about the floor that blocks a point.
#[derive(Clone, Debug)]
pub(super) struct Surfaces {
    /// Per grid point: on a wall patch, or inside the span of a wall quad that is vertical in
    /// the level frame ([`level_wall_mask`]).
    wall_mask: Vec<bool>,
    /// From ceiling patches (median of members).
    ceiling_z: Option<f64>,
    /// The floor's height for the height test: the floor patches', else the lowest crowd.
    ground_z: Option<f64>,
    /// The floor's height and the half-width about it, less the noise, that blocks a point.
    floor_band: Option<(f64, f64)>,
    /// The larger attitude sigma \[rad\].
    attitude_sigma: f64,
}

impl Surfaces {
    pub(super) fn of(
        grid: &PoseGrid,
        est: &LevelEstimate,
        params: &PseudoLevelParams,
        level_from_robot: &Matrix3<f64>,
    ) -> Self {
        let attitude_sigma = est.sigmas.map_or(0.0, |s| s[0].max(s[1]));
        let height_of = |kind| level_flat_height(grid, est, kind, level_from_robot, attitude_sigma);
        let floor_z = height_of(SurfaceKind::Floor);
        // The floor's height and the band about it that blocks a point. Without floor
        // patches, only the floor's own hits: a crowd's height is exact to the noise, and a
        // wider band would take the foot of every wall with it.
        let (ground_z, floor_band) = match floor_z {
            Some(f) => (Some(f), Some((f, params.floor_margin))),
            None => {
                let (crowd, floor) = ground_crowd(grid, level_from_robot, CROWD_WINDOW);
                (crowd, floor.map(|f| (f, GROUND_BAND)))
            }
        };
        Surfaces {
            wall_mask: level_wall_mask(grid, est, level_from_robot, attitude_sigma),
            ceiling_z: height_of(SurfaceKind::Ceiling),
            ground_z,
            floor_band,
            attitude_sigma,
        }
    }
}

/// Sigmas within which a wall quad's leveled normal must be horizontal for its span to count
/// as wall \[1\]: its normal's own uncertainty (`PlaneFit::normal_variance_along` the level
/// frame's up) plus the attitude's. Three, as for every other test on a Gaussian error: a true
/// wall quad fails it about once in 400. Measured (robust estimator, holdout plans, seed 202, 5
/// scans at 10 cm): floor and ceiling hits kept 0.87% -> 0.50%, coverage 95.9% -> 95.5%.
const QUAD_TILT_SIGMAS: f64 = 3.0;

/// The estimate's wall mask (`LevelEstimate::wall_mask`) with only the wall quads that are
/// vertical in the level frame: a quad is classified in the robot frame before the attitude is
/// known, and one that straddles a wall's meeting with the ceiling or the floor (its rows on
/// both, coplanar within the quad test's tolerance at high noise) passes as a wall while its
/// normal, leveled, is tilted far beyond its own uncertainty; its span would keep those
/// ceiling and floor hits.
fn level_wall_mask(
    grid: &PoseGrid,
    est: &LevelEstimate,
    level_from_robot: &Matrix3<f64>,
    attitude_sigma: f64,
) -> Vec<bool> {
    let up = level_from_robot.row(2).transpose();
    let sigma = est.range_sigma;
    wall_mask_where(grid, est, |q| {
        let tilt = q.fit.normal.dot(&up).abs();
        tilt <= QUAD_TILT_SIGMAS * (q.fit.normal_variance_along(&up, sigma).sqrt() + attitude_sigma)
    })
}

/// The height in the level frame of the floor (or ceiling) patches whose leveled normal is
/// vertical within [`QUAD_TILT_SIGMAS`] of its uncertainty and the attitude's: the median over
/// all their points, `None` without any. A patch is classified in the robot frame, as a floor
/// when its plane passes below the scanner; one grown over a wall's foot or top (a wall's
/// points with the floor's) can pass while tilted by 15-55 degrees once leveled, its points
/// metres above the floor. Its height would put the floor band where no floor is, and the
/// floor's hits through. Measured (robust estimator, holdout plans, seed 202, 5 scans at 10
/// cm): such patches tilted 5-45 sigmas, true floors and ceilings at most 3.2 sigmas.
fn level_flat_height(
    grid: &PoseGrid,
    est: &LevelEstimate,
    kind: SurfaceKind,
    level_from_robot: &Matrix3<f64>,
    attitude_sigma: f64,
) -> Option<f64> {
    let (ex, ey) = (
        level_from_robot.row(0).transpose(),
        level_from_robot.row(1).transpose(),
    );
    let sigma = est.range_sigma;
    let level_flat = |fit: &PlaneFit| {
        let tilt = fit.normal.dot(&ex).hypot(fit.normal.dot(&ey));
        let sd =
            (fit.normal_variance_along(&ex, sigma) + fit.normal_variance_along(&ey, sigma)).sqrt();
        tilt <= QUAD_TILT_SIGMAS * (sd + attitude_sigma)
    };
    let mut z: Vec<f64> = est
        .patches
        .iter()
        .filter(|p| p.kind == kind && level_flat(&p.fit))
        .flat_map(|p| p.members.iter())
        .filter_map(|&i| grid.points[i].as_ref())
        .map(|g| (level_from_robot * g.p.coords).z)
        .collect();
    (!z.is_empty()).then(|| median_of(&mut z))
}

/// Which points of grid row `row` are wall points (before and after gap filling), one per
/// column.
pub(super) fn kept_in_row(
    grid: &PoseGrid,
    est: &LevelEstimate,
    params: &PseudoLevelParams,
    surfaces: &Surfaces,
    row: usize,
    level_from_robot: &Matrix3<f64>,
) -> Vec<bool> {
    let n = grid.cols;
    let sigma = est.range_sigma;
    let level = |p: &Point3<f64>| level_from_robot * p.coords;
    let Surfaces {
        ref wall_mask,
        ceiling_z,
        ground_z,
        floor_band,
        attitude_sigma,
    } = *surfaces;
    let mut is_wall = vec![false; n];
    let mut blocked = vec![false; n];
    let mut flat_points: Vec<Option<Vector2<f64>>> = vec![None; n];
    for (c, slot) in is_wall.iter_mut().enumerate() {
        let i = row * grid.cols + c;
        let Some(g) = &grid.points[i] else {
            blocked[c] = true;
            continue;
        };
        let lp = level(&g.p);
        flat_points[c] = Some(lp.xy());
        let dz_noise = 3.0 * sigma * (level_from_robot * g.dir).z.abs();
        let near = |(h, margin): (f64, f64)| (lp.z - h).abs() < margin + dz_noise;
        let on_ceiling = ceiling_z.is_some_and(|h| near((h, params.floor_margin)));
        let label = est.labels.get(i).copied().unwrap_or(UNLABELLED);
        let on_flat = label != UNLABELLED && est.patches[label as usize].kind != SurfaceKind::Wall;
        if floor_band.is_some_and(near) || on_ceiling || on_flat {
            blocked[c] = true;
            continue;
        }
        if wall_mask.get(i).copied().unwrap_or(false) {
            *slot = true;
            continue;
        }
        if params.height_test {
            let margin = params.floor_margin + dz_noise + 2.0 * attitude_sigma * lp.x.hypot(lp.y);
            let above_floor = ground_z.is_some_and(|f| lp.z > f + margin);
            // Without a ceiling, up to the scanner's own height, within the same margin: a level
            // scan meets a far wall at that height, on either side of it by the attitude's error.
            let below_top = ceiling_z.map_or(lp.z < margin, |h| lp.z < h - margin);
            if above_floor && below_top {
                *slot = true;
                continue;
            }
        }
        if params.vertical_ratio > 0.0 {
            let neighbours = [
                row.checked_sub(1),
                Some(row + 1).filter(|&r| r < grid.rows()),
            ];
            *slot = neighbours.into_iter().flatten().any(|r| {
                grid.at(r, c).is_some_and(|q| {
                    let d = level(&q.p) - lp;
                    let dh = d.x.hypot(d.y);
                    let dz = d.z.abs();
                    // Wall: the vertical separation the elevation step gives at this range.
                    let expected = 0.5 * g.range * (grid.elevation[r] - grid.elevation[row]).abs();
                    dz >= expected && dz >= params.vertical_ratio * (dh - 3.0 * sigma).max(0.0)
                })
            });
        }
    }
    filled_gaps(&is_wall, &blocked, &flat_points, sigma, params.max_gap)
}

/// `is_wall` with short gaps filled: runs of at most `max_gap` rays between two wall points,
/// only with rays that had a return, are not known floor or ceiling points (`blocked`), and lie
/// near the two wall points either side (`flat_points`, their level-frame positions): a ray
/// through a doorway that meets the floor metres beyond is exactly the phantom to keep out.
fn filled_gaps(
    is_wall: &[bool],
    blocked: &[bool],
    flat_points: &[Option<Vector2<f64>>],
    sigma: f64,
    max_gap: usize,
) -> Vec<bool> {
    let near_gap = |k: usize, l: usize, c: usize| -> bool {
        let (Some(p), Some(a), Some(b)) = (flat_points[k], flat_points[l], flat_points[c]) else {
            return false;
        };
        let ab = b - a;
        let t = ((p - a).dot(&ab) / ab.norm_squared().max(1e-12)).clamp(0.0, 1.0);
        (p - (a + ab * t)).norm() <= 0.5 * ab.norm() + 3.0 * sigma + GAP_SLACK
    };
    let mut keep = is_wall.to_vec();
    let mut last: Option<usize> = None;
    for (c, &wall) in is_wall.iter().enumerate() {
        if !wall {
            continue;
        }
        if let Some(l) = last {
            let gap = c - l - 1;
            if gap > 0 && gap <= max_gap {
                for k in l + 1..c {
                    keep[k] |= !blocked[k] && near_gap(k, l, c);
                }
            }
        }
        last = Some(c);
    }
    keep
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::level::grid::GridPoint;
    use crate::level::patches::Patch;
    use crate::level::polygons::Polygon;
    use nalgebra::Vector3;

    /// A fit with the given unit normal, its in-plane spread 1 m^2 along both axes (a normal
    /// good to about a hundredth of a sigma-normalised radian).
    fn fit_with_normal(normal: Vector3<f64>) -> PlaneFit {
        let a = normal
            .cross(&Vector3::z())
            .try_normalize(1e-9)
            .unwrap_or(Vector3::x());
        let b = normal.cross(&a).normalize();
        PlaneFit {
            centroid: Point3::origin(),
            normal,
            in_plane: [(1.0, a), (1.0, b)],
            n: 100,
            weight: 100.0,
            dn2: 1.0,
            residual_ss: 0.0,
        }
    }

    /// One row of `n` points at height `z` (robot frame, level pose).
    fn grid_at(z: f64, n: usize) -> PoseGrid {
        let points = (0..n)
            .map(|c| {
                let p = Point3::new(2.0, c as f64 * 0.1, z);
                Some(GridPoint {
                    p,
                    dir: p.coords.normalize(),
                    range: p.coords.norm(),
                })
            })
            .collect();
        PoseGrid {
            scan_index: vec![0],
            elevation: vec![0.0],
            cols: n,
            points,
        }
    }

    fn estimate(grid: &PoseGrid) -> LevelEstimate {
        LevelEstimate {
            range_sigma: 0.01,
            sigmas: Some([1e-3, 1e-3]),
            labels: vec![UNLABELLED; grid.points.len()],
            ..LevelEstimate::default()
        }
    }

    /// A floor patch counts for the floor's height when level once leveled, and not when its
    /// leveled normal is tilted beyond its uncertainty (as at 20 degrees).
    #[test]
    fn floor_height_only_from_level_patches() {
        let grid = grid_at(-0.4, 5);
        let level = Matrix3::identity();
        // The bound: 3 (sqrt(2) 0.01 + 0.001) rad, 2.6 degrees.
        for (tilt_deg, expect) in [
            (0.0, Some(-0.4)),
            (2.0, Some(-0.4)),
            (3.2, None),
            (20.0, None),
        ] {
            let t: f64 = f64::to_radians(tilt_deg);
            let mut est = estimate(&grid);
            est.patches = vec![Patch {
                fit: fit_with_normal(Vector3::new(t.sin(), 0.0, t.cos())),
                kind: SurfaceKind::Floor,
                members: (0..5).collect(),
                row_range: (0, 0),
            }];
            let got = level_flat_height(&grid, &est, SurfaceKind::Floor, &level, 1e-3);
            assert_eq!(got, expect, "tilt {tilt_deg} deg");
        }
    }

    /// A wall quad's span is wall when its leveled normal is horizontal, and not when tilted
    /// (as at 30 degrees, one straddling a wall's top and the ceiling).
    #[test]
    fn wall_mask_only_from_vertical_quads() {
        let grid = grid_at(0.5, 6);
        let level = Matrix3::identity();
        // The bound: 3 (0.01 + 0.001) rad, 1.9 degrees.
        for (tilt_deg, expect) in [(0.0, true), (1.5, true), (2.5, false), (30.0, false)] {
            let t: f64 = f64::to_radians(tilt_deg);
            let mut est = estimate(&grid);
            est.quads = vec![Polygon {
                row: 0,
                col: 1,
                rows: 1,
                cols: 3,
                corners: [Point3::origin(); 4],
                area: 1.0,
                fit: fit_with_normal(Vector3::new(t.cos(), 0.0, t.sin())),
                kind: SurfaceKind::Wall,
            }];
            let mask = level_wall_mask(&grid, &est, &level, 1e-3);
            let want = [false, expect, expect, expect, false, false];
            assert_eq!(mask, want, "tilt {tilt_deg} deg");
        }
    }

    #[test]
    fn lowest_crowd_is_the_floor_under_walls_and_stray_points() {
        let floor = (0..30).map(|k| -0.45 + 0.001 * (k % 7) as f64);
        let walls = (0..60).map(|k| -0.3 + 0.02 * k as f64);
        let strays = [-1.2, -0.9, -0.7];
        let heights: Vec<f64> = floor.chain(walls).chain(strays).collect();
        let z = lowest_crowded_height(&heights, 0.05, 20).unwrap();
        assert!((z + 0.447).abs() < 0.004, "{z}");
    }

    #[test]
    fn no_crowd_no_floor() {
        let spread: Vec<f64> = (0..50).map(|k| 0.1 * k as f64).collect();
        assert_eq!(lowest_crowded_height(&spread, 0.05, 20), None);
        assert_eq!(lowest_crowded_height(&[0.0; 5], 0.05, 20), None);
    }

    /// Sorting only the lowest heights gives what sorting all of them gives.
    #[test]
    fn lowest_crowd_matches_sorting_everything() {
        use rand::{RngExt, SeedableRng};
        let full = |mut h: Vec<f64>, window: f64, min_count: usize| {
            h.sort_by(f64::total_cmp);
            (0..=h.len() - min_count)
                .find(|&i| h[i + min_count - 1] - h[i] <= window)
                .map(|i| h[(i + h.partition_point(|&z| z <= h[i] + window)) / 2])
        };
        let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(9);
        for case in 0..400 {
            let n = rng.random_range(20..400);
            let floor_share = [0.0, 0.02, 0.3, 0.9][case % 4];
            let heights: Vec<f64> = (0..n)
                .map(|_| {
                    if rng.random::<f64>() < floor_share {
                        -0.45 + 0.01 * rng.random::<f64>()
                    } else {
                        rng.random_range(-1.0..2.0)
                    }
                })
                .collect();
            let min_count = rng.random_range(1..20);
            let window = rng.random_range(0.001..0.1);
            assert_eq!(
                lowest_crowded_height(&heights, window, min_count),
                full(heights, window, min_count),
                "case {case}"
            );
        }
    }
}
