//! The metascan (paper sect. 2.2, 8.2): a map of all earlier matched scans.
//!
//! Kept bounded as KISS-ICP keeps its map (Vizzo et al. 2023): points fall into voxels, each
//! voxel holds a running mean of its points and of their normals, and only a new voxel adds a
//! point to the search grid (inserted incrementally, never rebuilt). Revisiting a place therefore
//! costs nothing extra, and the cost per scan depends on the size of the place, not on the
//! length of the run.

use super::grid::{CellHasher, Hit, PointGrid, floor_i64};
use super::reference::{Certificate, Line, Neighbour, Target};
use nalgebra::{Point2, Vector2};
use std::collections::HashMap;
use std::hash::BuildHasherDefault;

/// Metascan map settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MapParams {
    /// Voxel edge \[m\]. Default 0.05.
    pub voxel_size: f64,
    /// A voxel stops averaging after this many points, so old well-seen places stay fixed
    /// and the update cost stays constant [-]. Default 20.
    pub max_points_per_voxel: u32,
}

impl Default for MapParams {
    fn default() -> Self {
        Self {
            voxel_size: 0.05,
            max_points_per_voxel: 20,
        }
    }
}

#[derive(Clone, Debug)]
struct Voxel {
    sum: Vector2<f64>,
    count: u32,
    normal_sum: Vector2<f64>,
    normal_count: u32,
    /// The mean point and the averaged line, as `nearest_within` answers them: kept up to
    /// date as points arrive (a voxel is asked far more often than it changes).
    mean: Point2<f64>,
    line: Option<Line>,
}

impl Voxel {
    fn new(p: Point2<f64>, normal: Option<Vector2<f64>>) -> Self {
        let mut voxel = Self {
            sum: p.coords,
            count: 1,
            normal_sum: normal.unwrap_or_else(Vector2::zeros),
            normal_count: u32::from(normal.is_some()),
            mean: p,
            line: None,
        };
        voxel.update();
        voxel
    }

    /// Recomputes the mean and the line from the sums.
    fn update(&mut self) {
        let mean = Point2::from(self.sum / self.count as f64);
        // Normals that disagree (two sides of a thin wall, a corner) cancel out: keep the
        // average only when it is clearly one direction.
        self.line = (self.normal_count > 0)
            .then(|| self.normal_sum / self.normal_count as f64)
            .filter(|n| n.norm() > 0.8)
            .map(|n| Line {
                normal: n.normalize(),
                anchor: mean,
            });
        self.mean = mean;
    }
}

/// A voxel map of world-frame points with normals, searchable through a grid.
pub struct VoxelMap {
    params: MapParams,
    /// Voxel key -> slot; keys are small integers, hashed by one multiply (`CellHasher`).
    index: HashMap<(i64, i64), u32, BuildHasherDefault<CellHasher>>,
    voxels: Vec<Voxel>,
    /// Each voxel's first point, found by `nearest_within`.
    grid: PointGrid,
}

impl VoxelMap {
    pub fn new(params: MapParams) -> Self {
        Self {
            params,
            index: HashMap::default(),
            voxels: Vec::new(),
            grid: PointGrid::default(),
        }
    }

    /// Number of voxels.
    pub fn len(&self) -> usize {
        self.voxels.len()
    }

    pub fn is_empty(&self) -> bool {
        self.voxels.is_empty()
    }

    /// Adds world-frame points with their world-frame local lines; where a line is known its
    /// anchor (the denoised point) goes into the map instead of the raw point.
    pub fn insert(&mut self, points: &[Point2<f64>], lines: &[Option<Line>]) {
        let v = self.params.voxel_size;
        for (i, raw) in points.iter().enumerate() {
            let line = lines.get(i).copied().flatten();
            let p = line.map_or(*raw, |l| l.anchor);
            let normal = line.map(|l| l.normal);
            let key = (floor_i64(p.x / v), floor_i64(p.y / v));
            match self.index.get(&key) {
                Some(&slot) => {
                    let voxel = &mut self.voxels[slot as usize];
                    if voxel.count >= self.params.max_points_per_voxel {
                        continue;
                    }
                    voxel.sum += p.coords;
                    voxel.count += 1;
                    if let Some(n) = normal {
                        voxel.normal_sum += n;
                        voxel.normal_count += 1;
                    }
                    voxel.update();
                }
                None => {
                    let slot = self.voxels.len() as u32;
                    // The grid holds the voxel's first point; the mean moves less than a voxel,
                    // which only makes the neighbour search approximate by that much.
                    if !(p.x.is_finite() && p.y.is_finite()) {
                        continue;
                    }
                    self.grid.insert(p, slot);
                    self.index.insert(key, slot);
                    self.voxels.push(Voxel::new(p, normal));
                }
            }
        }
    }

    /// Every voxel's mean point, for drawing.
    pub fn points(&self) -> Vec<Point2<f64>> {
        self.voxels.iter().map(|v| v.mean).collect()
    }
}

impl VoxelMap {
    /// The grid's bound for a query within `max_d2`: the nearest first point decides the
    /// voxel; its mean lies in the same voxel, at most a voxel's diagonal away, so a first
    /// point farther than that beyond the radius has its mean outside the radius too.
    #[inline]
    fn reach2(&self, max_d2: f64) -> f64 {
        let reach = max_d2.sqrt() + self.params.voxel_size * std::f64::consts::SQRT_2;
        reach * reach * (1.0 + 1e-9)
    }

    /// The neighbour the grid's `hit` (the nearest first point) gives.
    #[inline]
    fn neighbour(&self, p: &Point2<f64>, max_d2: f64, hit: &Hit) -> Option<Neighbour> {
        let voxel = self.voxels.get(hit.item as usize)?;
        let (mean, line) = (voxel.mean, voxel.line);
        let dist2 = (mean - p).norm_squared();
        (dist2 <= max_d2).then_some(Neighbour {
            point: mean,
            line,
            dist2,
        })
    }
}

impl Target for VoxelMap {
    fn nearest_within(&self, p: &Point2<f64>, max_d2: f64) -> Option<Neighbour> {
        let hit = self.grid.nearest_within(p, self.reach2(max_d2))?;
        self.neighbour(p, max_d2, &hit)
    }

    fn nearest_certified(
        &self,
        p: &Point2<f64>,
        max_d2: f64,
    ) -> (Option<Neighbour>, Option<Certificate>) {
        let (hit, margin) = self.grid.nearest_certified(p, self.reach2(max_d2));
        (
            hit.as_ref().and_then(|hit| self.neighbour(p, max_d2, hit)),
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
        let hit = certificate.again(p, self.reach2(max_d2))?;
        self.neighbour(p, max_d2, &hit)
    }

    fn len(&self) -> usize {
        self.voxels.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn revisiting_adds_no_voxels() {
        let pts: Vec<Point2<f64>> = (0..100)
            .map(|i| Point2::new(0.01 * i as f64, 1.0))
            .collect();
        let normals: Vec<Option<Line>> = pts
            .iter()
            .map(|p| {
                Some(Line {
                    normal: Vector2::new(0.0, -1.0),
                    anchor: *p,
                })
            })
            .collect();
        let mut map = VoxelMap::new(MapParams::default());
        map.insert(&pts, &normals);
        let after_first = map.len();
        for _ in 0..30 {
            map.insert(&pts, &normals);
        }
        assert_eq!(map.len(), after_first);
        assert_eq!(after_first, 20);
        let nb = map.nearest(&Point2::new(0.5, 1.2)).unwrap();
        assert!((nb.point.y - 1.0).abs() < 1e-12);
        assert_eq!(nb.line.map(|l| l.normal), Some(Vector2::new(0.0, -1.0)));
    }
}
