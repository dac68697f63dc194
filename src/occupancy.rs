//! Occupancy grids from matched 2D scans: the map a user takes to ROS (`map_server`, AMCL,
//! Nav2), written by [`crate::formats::pgm_map`].
//!
//! The classic inverse sensor model in log-odds (Moravec and Elfes 1985; Thrun, Burgard and Fox,
//! "Probabilistic Robotics", 2005, sect. 9.2): each ray's end cell is hit, every cell it crossed
//! on the way is free. Cells a ray crosses are found exactly with the grid traversal of
//! Amanatides and Woo ("A fast voxel traversal algorithm for ray tracing", Eurographics 1987).
//! Within one scan a cell is updated once, a hit winning over a miss, so that rays grazing a
//! wall do not erase it and the many rays near the robot do not count many times.
//!
//! Pure: placed scans in, a grid out. Only valid rays are cast: a ray with no return (or a
//! pseudo-level ray that is not a wall point) says nothing about the cells along it.

use crate::geometry::Pose2;
use nalgebra::Point2;

/// Parameters of the grid and the sensor model.
#[derive(Clone, Debug, PartialEq)]
pub struct GridParams {
    /// Cell size \[m\]. Default 0.05, the usual ROS map resolution.
    pub resolution: f64,
    /// Log-odds added to a hit cell. Default ln(0.7 / 0.3) = 0.85: a return is fairly sure.
    pub hit: f32,
    /// Log-odds added to a cell a ray crossed. Default ln(0.4 / 0.6) = -0.41: weaker than a hit,
    /// so that a wall needs a few misses to be taken away.
    pub miss: f32,
    /// Log-odds are clamped to `[min, max]` so that the map stays able to change. Default
    /// -2 and 3.5 (probabilities 0.12 and 0.97, as OctoMap's).
    pub min: f32,
    pub max: f32,
    /// Free space around the data in the grid \[m\]. Default 0.5.
    pub margin: f64,
    /// Largest grid, in cells, before [`GridError::TooBig`]. Default 10^8 (a 500 x 500 m
    /// site at 5 cm).
    pub max_cells: usize,
}

impl Default for GridParams {
    fn default() -> Self {
        Self {
            resolution: 0.05,
            hit: (0.7f32 / 0.3).ln(),
            miss: (0.4f32 / 0.6).ln(),
            min: -2.0,
            max: 3.5,
            margin: 0.5,
            max_cells: 100_000_000,
        }
    }
}

/// Why no grid could be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GridError {
    #[error("resolution must be a positive number of metres, not {0}")]
    Resolution(f64),
    #[error("no scan with a pose and a valid ray: nothing to map")]
    Empty,
    #[error(
        "the map would be {width} x {height} cells ({:.0} x {:.0} m): more than {max} cells; \
         use a coarser resolution",
        *width as f64 * resolution, *height as f64 * resolution
    )]
    TooBig {
        width: usize,
        height: usize,
        resolution: f64,
        max: usize,
    },
}

/// A scan placed in the world: the sensor's pose and its returns in the sensor frame \[m\].
#[derive(Clone, Debug, PartialEq)]
pub struct PlacedScan {
    pub pose: Pose2,
    pub hits: Vec<Point2<f64>>,
}

/// An occupancy grid: log-odds per cell, row-major, row 0 the lowest y (the ROS map layout).
#[derive(Clone, Debug, PartialEq)]
pub struct OccupancyGrid {
    /// Cell size \[m\].
    pub resolution: f64,
    /// World position of the lower-left corner of cell (0, 0) \[m\] (map_server's `origin`).
    pub origin: [f64; 2],
    pub width: usize,
    pub height: usize,
    pub log_odds: Vec<f32>,
}

impl OccupancyGrid {
    /// The cell `(column, row)` holding world point `(x, y)`, if inside.
    pub fn cell(&self, x: f64, y: f64) -> Option<(usize, usize)> {
        let c = ((x - self.origin[0]) / self.resolution).floor();
        let r = ((y - self.origin[1]) / self.resolution).floor();
        (c >= 0.0 && r >= 0.0 && (c as usize) < self.width && (r as usize) < self.height)
            .then_some((c as usize, r as usize))
    }

    /// Occupancy probability of a cell (0.5 where nothing was seen).
    pub fn probability(&self, column: usize, row: usize) -> f64 {
        let l = f64::from(self.log_odds[row * self.width + column]);
        1.0 - 1.0 / (1.0 + l.exp())
    }
}

/// Builds the grid of `scans`: bounds from every sensor position and hit, then each scan cast.
pub fn build_grid(scans: &[PlacedScan], params: &GridParams) -> Result<OccupancyGrid, GridError> {
    let res = params.resolution;
    if !(res.is_finite() && res > 0.0) {
        return Err(GridError::Resolution(res));
    }
    let world: Vec<(Point2<f64>, Vec<Point2<f64>>)> = scans
        .iter()
        .filter(|s| !s.hits.is_empty())
        .map(|s| {
            let hits = s.hits.iter().map(|p| s.pose.transform_point(p)).collect();
            (Point2::new(s.pose.x, s.pose.y), hits)
        })
        .collect();
    let (lo, hi) = bounds(&world).ok_or(GridError::Empty)?;
    let origin = [lo[0] - params.margin, lo[1] - params.margin];
    // The last cell holds the highest point: floor, plus one.
    let width = ((hi[0] + params.margin - origin[0]) / res).floor() as usize + 1;
    let height = ((hi[1] + params.margin - origin[1]) / res).floor() as usize + 1;
    if width.saturating_mul(height) > params.max_cells {
        return Err(GridError::TooBig {
            width,
            height,
            resolution: res,
            max: params.max_cells,
        });
    }
    let mut grid = OccupancyGrid {
        resolution: res,
        origin,
        width,
        height,
        log_odds: vec![0.0; width * height],
    };
    // The scan (1-based) that last updated each cell: one update per cell and scan.
    let mut stamp = vec![0u32; width * height];
    for (k, (sensor, hits)) in world.iter().enumerate() {
        insert_scan(&mut grid, &mut stamp, k as u32 + 1, sensor, hits, params);
    }
    Ok(grid)
}

fn bounds(world: &[(Point2<f64>, Vec<Point2<f64>>)]) -> Option<([f64; 2], [f64; 2])> {
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    for p in world.iter().flat_map(|(s, h)| std::iter::once(s).chain(h)) {
        for d in 0..2 {
            lo[d] = lo[d].min(p[d]);
            hi[d] = hi[d].max(p[d]);
        }
    }
    lo[0].is_finite().then_some((lo, hi))
}

/// One scan: its hit cells first, then the free cells of every ray that are not hit.
fn insert_scan(
    grid: &mut OccupancyGrid,
    stamp: &mut [u32],
    id: u32,
    sensor: &Point2<f64>,
    hits: &[Point2<f64>],
    params: &GridParams,
) {
    let w = grid.width;
    let update = |grid: &mut OccupancyGrid, i: usize, delta: f32| {
        let l = &mut grid.log_odds[i];
        *l = (*l + delta).clamp(params.min, params.max);
    };
    for h in hits {
        if let Some((c, r)) = grid.cell(h.x, h.y)
            && stamp[r * w + c] != id
        {
            stamp[r * w + c] = id;
            update(grid, r * w + c, params.hit);
        }
    }
    let (origin, res, height) = (grid.origin, grid.resolution, grid.height);
    let to_grid = |p: &Point2<f64>| [(p.x - origin[0]) / res, (p.y - origin[1]) / res];
    let start = to_grid(sensor);
    for h in hits {
        let mut crossed = Vec::new();
        traverse(start, to_grid(h), |c, r| crossed.push((c, r)));
        crossed.pop(); // the end cell is the hit's
        for (c, r) in crossed {
            if c < 0 || r < 0 || c as usize >= w || r as usize >= height {
                continue;
            }
            let i = r as usize * w + c as usize;
            if stamp[i] != id {
                stamp[i] = id;
                update(grid, i, params.miss);
            }
        }
    }
}

/// Calls `visit(column, row)` for every cell the segment from `a` to `b` (in cell units: cell
/// (c, r) spans `[c, c + 1) x [r, r + 1)`) passes through, in order from `a`'s cell to `b`'s
/// (Amanatides and Woo 1987). Where it passes exactly through a corner, the cell across the
/// x border comes first.
pub(crate) fn traverse(a: [f64; 2], b: [f64; 2], mut visit: impl FnMut(i64, i64)) {
    let mut cell = [a[0].floor() as i64, a[1].floor() as i64];
    let end = [b[0].floor() as i64, b[1].floor() as i64];
    let d = [b[0] - a[0], b[1] - a[1]];
    let mut step = [0i64; 2];
    // Parameter t (0 at a, 1 at b) of the next border crossing along each axis, and its
    // increment per cell.
    let mut t_max = [f64::INFINITY; 2];
    let mut t_delta = [f64::INFINITY; 2];
    for k in 0..2 {
        if d[k] > 0.0 {
            step[k] = 1;
            t_max[k] = ((cell[k] + 1) as f64 - a[k]) / d[k];
            t_delta[k] = 1.0 / d[k];
        } else if d[k] < 0.0 {
            step[k] = -1;
            t_max[k] = (cell[k] as f64 - a[k]) / d[k];
            t_delta[k] = -1.0 / d[k];
        }
    }
    // The segment crosses |end - start| borders along each axis.
    let crossings = (end[0] - cell[0]).abs() + (end[1] - cell[1]).abs();
    visit(cell[0], cell[1]);
    for _ in 0..crossings {
        let k = if t_max[0] <= t_max[1] { 0 } else { 1 };
        cell[k] += step[k];
        t_max[k] += t_delta[k];
        visit(cell[0], cell[1]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::collections::BTreeSet;

    #[test]
    fn a_ray_along_x_frees_the_cells_before_its_hit() {
        // Sensor at the origin, a hit 1 m ahead, 1 cm of margin: the grid starts at -0.01, the
        // sensor is in cell 0 and the hit in cell 20 (1.01 / 0.05 = 20.2); 0..19 are crossed.
        let params = GridParams {
            margin: 0.01,
            ..GridParams::default()
        };
        let scan = PlacedScan {
            pose: Pose2::new(0.0, 0.0, 0.0),
            hits: vec![Point2::new(1.0, 0.0)],
        };
        let g = build_grid(&[scan], &params).unwrap();
        assert_eq!((g.width, g.height), (21, 1));
        assert_eq!(g.origin, [-0.01, -0.01]);
        for c in 0..20 {
            assert_eq!(g.log_odds[c], params.miss, "cell {c}");
        }
        assert_eq!(g.log_odds[20], params.hit);
        assert!(g.probability(20, 0) > 0.69 && g.probability(0, 0) < 0.41);
    }

    #[test]
    fn a_hit_wins_over_a_miss_in_one_scan_and_scans_add_up_to_the_clamp() {
        // Two rays of one scan: the second passes through the first one's hit cell.
        let scan = PlacedScan {
            pose: Pose2::new(0.0, 0.0, 0.0),
            hits: vec![Point2::new(0.52, 0.01), Point2::new(1.02, 0.01)],
        };
        let params = GridParams::default();
        let g = build_grid(&vec![scan; 10], &params).unwrap();
        let (c, r) = g.cell(0.52, 0.01).unwrap();
        assert_eq!(g.log_odds[r * g.width + c], params.max);
        let (c, r) = g.cell(0.25, 0.01).unwrap();
        assert_eq!(g.log_odds[r * g.width + c], params.min);
    }

    #[test]
    fn empty_input_and_absurd_sizes_are_errors() {
        assert_eq!(
            build_grid(&[], &GridParams::default()),
            Err(GridError::Empty)
        );
        let far = PlacedScan {
            pose: Pose2::new(0.0, 0.0, 0.0),
            hits: vec![Point2::new(1e6, 1e6)],
        };
        let e = build_grid(&[far], &GridParams::default()).unwrap_err();
        assert!(matches!(e, GridError::TooBig { .. }), "{e}");
        let bad = GridParams {
            resolution: 0.0,
            ..GridParams::default()
        };
        assert_eq!(build_grid(&[], &bad), Err(GridError::Resolution(0.0)));
    }

    fn traversed(a: [f64; 2], b: [f64; 2]) -> Vec<(i64, i64)> {
        let mut v = Vec::new();
        traverse(a, b, |c, r| v.push((c, r)));
        v
    }

    #[test]
    fn traversal_of_a_diagonal_visits_each_cell_it_crosses() {
        assert_eq!(
            traversed([0.5, 0.2], [2.5, 1.2]),
            vec![(0, 0), (1, 0), (2, 0), (2, 1)]
        );
        assert_eq!(traversed([0.5, 0.5], [0.7, 0.9]), vec![(0, 0)]);
        assert_eq!(
            traversed([2.5, 0.5], [-0.5, 0.5]),
            vec![(2, 0), (1, 0), (0, 0), (-1, 0)]
        );
    }

    proptest! {
        /// Brute-force twin: every cell a dense sampling of the segment lands in is visited,
        /// the visits are 4-connected steps from a's cell to b's, and none is off the segment.
        #[test]
        fn traversal_covers_the_sampled_cells(
            a in prop::array::uniform2(-20.0f64..20.0),
            b in prop::array::uniform2(-20.0f64..20.0),
        ) {
            let cells = traversed(a, b);
            let set: BTreeSet<(i64, i64)> = cells.iter().copied().collect();
            prop_assert_eq!(cells[0], (a[0].floor() as i64, a[1].floor() as i64));
            prop_assert_eq!(*cells.last().unwrap(), (b[0].floor() as i64, b[1].floor() as i64));
            for w in cells.windows(2) {
                prop_assert_eq!((w[0].0 - w[1].0).abs() + (w[0].1 - w[1].1).abs(), 1);
            }
            for k in 0..=4000 {
                let t = f64::from(k) / 4000.0;
                let p = [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])];
                let c = (p[0].floor() as i64, p[1].floor() as i64);
                // Samples within 1e-9 of a border may round into the neighbour.
                let on_border = (p[0] - p[0].round()).abs() < 1e-9 || (p[1] - p[1].round()).abs() < 1e-9;
                prop_assert!(set.contains(&c) || on_border, "sample cell {:?} not visited", c);
            }
            // Each visited cell is within a cell's diagonal of the segment.
            let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
            let len2 = (dx * dx + dy * dy).max(1e-300);
            for &(c, r) in &cells {
                let m = [c as f64 + 0.5, r as f64 + 0.5];
                let t = (((m[0] - a[0]) * dx + (m[1] - a[1]) * dy) / len2).clamp(0.0, 1.0);
                let dist = (m[0] - a[0] - t * dx).hypot(m[1] - a[1] - t * dy);
                prop_assert!(dist <= std::f64::consts::FRAC_1_SQRT_2 + 1e-9);
            }
        }
    }
}
