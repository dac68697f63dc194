//! The E-step of an EM over the segmentation, with the maximum-likelihood fit as its M-step:
//! every point is given to the surface of the fitted model that its ray meets first among
//! those that predict its range within `k` of its sigmas, and to none when none does (Thrun et
//! al. 2004's assignment, with occlusion deciding between surfaces the range alone cannot).
//!
//! A segmentation grown under noise takes in points of the neighbouring surface within its
//! tolerance (at 10 cm noise, floor points up to 30 cm in front of a wall's foot), and since
//! they lie within the robust kernel's threshold they pull at full weight: the fit is then
//! self-consistent and biased (traced: 10-20% of poses beyond three sigmas at 10 cm noise).
//! Against the fitted planes such a point is within reach of both its wall and the floor; its
//! ray meets the floor in front of the wall, so it is the floor's. A ray can only have met the
//! first surface in its way, so where the model is right this is the true label whatever the
//! noise did to the range; leaving such points out instead (as re-segmentation does,
//! [`crate::level::refine`]) cost the stage on the true segmentation at 10 cm noise a sixth of
//! the information (sigma over bound 1.31 against 1.19 at 3 scans; docs/ESTIMATOR.md,
//! section 10).
//!
//! A wall of the model is a whole vertical plane; its points are only taken along the stretch
//! its members already cover, widened by `margin`, so that a wall's line does not take in the
//! points of another wall it crosses beyond a corner.

use super::model::{Placement, Plane, Rotations, predict_level};
use super::{LabelledPoint, MlSolution, Surface};
use nalgebra::{Vector2, Vector3};

/// Per point, the valid points near it in the grid: its own and the adjacent scans, within
/// `window` bearings, itself excluded. Found when asked (only the floor's and ceiling's
/// points are), in row-major order.
pub(crate) struct Neighbours {
    /// Per grid index, the point's index, `None` for an invalid reading.
    pub at: Vec<Option<usize>>,
    /// Per point, its grid index.
    pub index: Vec<usize>,
    pub cols: usize,
    pub window: usize,
}

impl Neighbours {
    /// The neighbourhoods of the valid points of a grid of `len` cells, `cols` to a row (rows
    /// in ascending elevation), whose grid indices are `index` (ascending), within `window`
    /// bearings: where a vertical surface standing over a point shows.
    pub(crate) fn new(index: Vec<usize>, len: usize, cols: usize, window: usize) -> Self {
        let mut at = vec![None; len];
        for (k, &i) in index.iter().enumerate() {
            at[i] = Some(k);
        }
        Neighbours {
            at,
            index,
            cols,
            window,
        }
    }

    /// Whether `f` holds for any valid point within `scans` scans and `window` bearings of
    /// point `i`, itself excluded, tried in row-major order. Plain loops over each row's
    /// stretch of the grid: the chain of iterator adapters it replaces cost more than the
    /// tests it fed.
    fn any_around(
        &self,
        i: usize,
        scans: usize,
        window: usize,
        mut f: impl FnMut(usize) -> bool,
    ) -> bool {
        let cols = self.cols.max(1);
        let rows = self.at.len() / cols;
        let (row, col) = (self.index[i] / cols, self.index[i] % cols);
        let (first, end) = (col.saturating_sub(window), (col + window + 1).min(cols));
        for r in row.saturating_sub(scans)..(row + scans + 1).min(rows) {
            let stretch = &self.at[r * cols + first..r * cols + end];
            for (c, cell) in (first..end).zip(stretch) {
                if let Some(j) = *cell {
                    if (r, c) != (row, col) && f(j) {
                        return true;
                    }
                }
            }
        }
        false
    }

    /// Whether `f` holds for any valid point of `i`'s own scan within `window` bearings of it.
    fn any_along_scan(&self, i: usize, window: usize, f: impl FnMut(usize) -> bool) -> bool {
        self.any_around(i, 0, window, f)
    }

    /// Whether `f` holds for any valid point of `i`'s own and the adjacent scans within
    /// `self.window` bearings.
    fn any_of(&self, i: usize, f: impl FnMut(usize) -> bool) -> bool {
        self.any_around(i, 1, self.window, f)
    }
}

/// A point leveled with the fitted attitude, once for every surface it is tried on: the
/// measured point `L (o + u r)`, the ray's direction `L u` and its origin `L o`.
pub(super) struct Leveled {
    pub q: Vector3<f64>,
    pub u: Vector3<f64>,
    pub o: Vector3<f64>,
}

pub(super) fn leveled(p: &LabelledPoint, rot: &Rotations) -> Leveled {
    let l = &rot.level_from_robot;
    Leveled {
        q: l * (p.origin.coords + p.dir * p.range),
        u: l * p.dir,
        o: l * p.origin.coords,
    }
}

/// A surface of the fitted model and, for a wall, the stretch of its line it may take points
/// from (the tangent coordinate `(-sin a, cos a) . (x, y)` in the level frame), with the
/// azimuth's `(sin a, cos a)`.
#[derive(Clone, Copy)]
struct Fitted {
    surface: Surface,
    placement: Placement,
    stretch: (f64, f64),
    sin_cos: (f64, f64),
}

/// New labels for `points` (their `surface` is ignored) under `sol`, given the current labels
/// (`None`: unlabelled), which set each wall's stretch. Points whose ray meets their surface
/// below `min_incidence` stay out, as the fit leaves them out.
pub(crate) fn relabel(
    points: &[LabelledPoint],
    neighbours: &Neighbours,
    labels: &[Option<Surface>],
    sol: &MlSolution,
    k: f64,
    margin: f64,
    min_incidence: f64,
) -> Vec<Option<Surface>> {
    let rot = Rotations::at(&Vector2::new(sol.attitude[0], sol.attitude[1]));
    let level: Vec<Leveled> = points.iter().map(|p| leveled(p, &rot)).collect();
    let fitted = fitted_surfaces(&level, labels, sol, margin);
    assign(points, &level, &fitted, k, min_incidence)
        .into_iter()
        .enumerate()
        .map(|(i, a)| {
            // A wall of the model predicts this range too: the model has the wall whose foot
            // the point may lie at, and `assign` already gave the point to the surface its ray
            // meets first. The test below is for the walls the model lacks.
            if a.wall_too {
                return a.label;
            }
            let level_plane = match (a.label, sol.floor, sol.ceiling) {
                (Some(Surface::Floor), Some(h), _) => (1.0, h),
                (Some(Surface::Ceiling), _, Some(h)) => (-1.0, h),
                _ => return a.label,
            };
            let on = (&points[i], &level[i]);
            let stood_over = neighbours.any_of(i, |j| {
                stands_over(on, (&points[j], &level[j]), k, level_plane)
            });
            if stood_over { None } else { a.label }
        })
        .collect()
}

/// Whether `q` (a point near `p` in the grid) stands over `p`, a point of the level plane
/// `(side, height)` (side 1 for the floor, -1 for the ceiling), as on a vertical surface:
/// horizontally within `k` sigmas of the pair's horizontal noise, and off the plane, on its
/// room side, by more than `k` of `q`'s own vertical noise. Such a `p` is within the noise of
/// a wall's foot (or top), asked only where the model lacks that wall: traced at 10 cm noise,
/// 5-20% of the floor's points were hits on a wall the model lacked within 9 cm of the floor,
/// and their pull put the pose 3-7 sigmas off. Judging `q` against the fitted plane rather
/// than against `p` (whose own vertical noise at a steep ray is a third of the range noise)
/// catches the feet near the scanner, where adjacent scans stand only 10-20 cm apart on the
/// wall.
fn stands_over(
    (p, lp): (&LabelledPoint, &Leveled),
    (q, lq): (&LabelledPoint, &Leveled),
    k: f64,
    (side, height): (f64, f64),
) -> bool {
    let ((a, da), (b, db)) = ((&lp.q, &lp.u), (&lq.q, &lq.u));
    let h2 = |d: &Vector3<f64>, s: f64| (d.x * d.x + d.y * d.y) * s * s;
    let var_h = h2(da, p.sigma) + h2(db, q.sigma);
    let dh2 = (a.x - b.x).powi(2) + (a.y - b.y).powi(2);
    let off = (b.z - height) * side;
    dh2 <= k * k * var_h && off > 0.0 && off * off > k * k * (db.z * q.sigma).powi(2)
}

/// A point's surface under the fitted model, and whether a wall of the model predicts its
/// range within `k` sigmas as well.
#[derive(Clone, Copy)]
struct Assigned {
    label: Option<Surface>,
    wall_too: bool,
}

/// Each point to the fitted surface its ray meets first (the shortest predicted range) among
/// those that predict its range within `k` sigmas, `None` when none does.
fn assign(
    points: &[LabelledPoint],
    level: &[Leveled],
    fitted: &[Fitted],
    k: f64,
    min_incidence: f64,
) -> Vec<Assigned> {
    // Each surface's plane once, not per point (a wall's takes a sine and a cosine).
    let planes: Vec<Plane> = fitted
        .iter()
        .map(|f| Plane::at(&f.placement, f.surface))
        .collect();
    points
        .iter()
        .zip(level)
        .map(|(p, l)| {
            let (mut found, mut nearest, mut wall_too) = (None, f64::INFINITY, false);
            for (f, plane) in fitted.iter().zip(&planes) {
                if plane.normal.dot(&l.u).abs() < min_incidence {
                    continue;
                }
                if let Surface::Wall(_) = f.surface {
                    let along = tangent(f.sin_cos, &l.q);
                    if along < f.stretch.0 || along > f.stretch.1 {
                        continue;
                    }
                }
                // The range at which the ray meets the plane.
                let t = predict_level(plane, &l.u, &l.o).0;
                let rho = (p.range - t) / p.sigma;
                if rho.abs() <= k {
                    wall_too |= matches!(f.surface, Surface::Wall(_));
                    if t < nearest {
                        (found, nearest) = (Some(f.surface), t);
                    }
                }
            }
            Assigned {
                label: found,
                wall_too,
            }
        })
        .collect()
}

/// The model's surfaces with the stretch of each wall: its labelled points' tangent
/// coordinates, widened by `margin` at both ends.
fn fitted_surfaces(
    level: &[Leveled],
    labels: &[Option<Surface>],
    sol: &MlSolution,
    margin: f64,
) -> Vec<Fitted> {
    let mut fitted: Vec<Fitted> = sol
        .walls
        .iter()
        .map(|w| Fitted {
            surface: w.surface,
            placement: w.placement(),
            stretch: (f64::INFINITY, f64::NEG_INFINITY),
            sin_cos: w.azimuth.sin_cos(),
        })
        .collect();
    // One pass over the points (a wall's stretch is its labelled points' extremes).
    for (l, label) in level.iter().zip(labels) {
        let Some(f) = fitted.iter_mut().find(|f| Some(f.surface) == *label) else {
            continue;
        };
        let t = tangent(f.sin_cos, &l.q);
        f.stretch = (f.stretch.0.min(t), f.stretch.1.max(t));
    }
    for f in &mut fitted {
        f.stretch = (f.stretch.0 - margin, f.stretch.1 + margin);
    }
    for (surface, height) in [(Surface::Floor, sol.floor), (Surface::Ceiling, sol.ceiling)] {
        if let Some(offset) = height {
            fitted.push(Fitted {
                surface,
                placement: Placement::level(offset),
                stretch: (f64::NEG_INFINITY, f64::INFINITY),
                sin_cos: (0.0, 1.0),
            });
        }
    }
    fitted
}

/// The coordinate along a wall's line, of azimuth's `(sin a, cos a)`, of a level-frame point.
fn tangent((s, c): (f64, f64), q: &Vector3<f64>) -> f64 {
    -s * q.x + c * q.y
}

/// `labels` without the floor's and ceiling's edges: a floor (ceiling) point whose own scan
/// holds, within `window` bearings, a valid point of another label or of none. That is where
/// the floor meets another surface along the scan, and at high noise often a wall the model
/// lacks: the scan that meets a wall only at its foot (no scan sees the wall standing over
/// the floor there) gives hits a few centimetres up that lie within the floor's noise and
/// pull it (docs/ESTIMATOR.md, section 7). The fit without them is the rival segmentation
/// whose distance widens the covariance ([`super::from_segmentation`]).
pub(crate) fn without_level_edges(
    labels: &[Option<Surface>],
    neighbours: &Neighbours,
    window: usize,
) -> Vec<Option<Surface>> {
    let level = |l: &Option<Surface>| matches!(l, Some(Surface::Floor | Surface::Ceiling));
    labels
        .iter()
        .enumerate()
        .map(|(i, &l)| {
            let edge = level(&l) && neighbours.any_along_scan(i, window, |j| labels[j] != l);
            if edge { None } else { l }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::level::ml::WallLine;
    use nalgebra::Point3;

    /// A level scanner at the origin, the floor 0.45 m below, a wall at x = 2 (stretch
    /// -5..5 m): a ray whose range both explain goes to the surface it meets first, whatever
    /// the range says; one that neither explains goes to none.
    #[test]
    fn a_range_both_surfaces_explain_goes_to_the_one_met_first() {
        let sigma = 0.1;
        let wall = Fitted {
            surface: Surface::Wall(0),
            placement: Placement {
                offset: 2.0,
                azimuth: 0.0,
            },
            stretch: (-5.0, 5.0),
            sin_cos: (0.0, 1.0),
        };
        let floor = Fitted {
            surface: Surface::Floor,
            placement: Placement {
                offset: -0.45,
                azimuth: 0.0,
            },
            stretch: (f64::NEG_INFINITY, f64::INFINITY),
            sin_cos: (0.0, 1.0),
        };
        // Rays down towards the wall's foot: meeting the floor at x = 1.9 (before the wall),
        // and the wall 5 cm above the floor (before the floor); each range within 3 sigmas of
        // both predictions.
        let ray = |x: f64, z: f64, range_shift: f64| {
            let dir = Vector3::new(x, 0.0, z).normalize();
            let t = (x * x + z * z).sqrt();
            LabelledPoint {
                origin: Point3::origin(),
                dir,
                range: t + range_shift,
                sigma,
                surface: Surface::Floor,
            }
        };
        let points = [
            // The floor at 1.9 m; range read 15 cm long, nearer the wall's prediction.
            ray(1.9, -0.45, 0.15),
            // The wall at 0.40 m below the scanner; range read 16 cm long, nearer the floor's.
            ray(2.0, -0.40, 0.16),
            // The floor far short of the wall, read 60 cm long: neither explains it.
            ray(1.0, -0.45, 0.6),
        ];
        let rot = Rotations::at(&Vector2::zeros());
        let level: Vec<Leveled> = points.iter().map(|p| leveled(p, &rot)).collect();
        // Both orders of the surfaces give the same labels.
        for fitted in [[wall, floor], [floor, wall]] {
            let got = assign(&points, &level, &fitted, 3.0, 0.02);
            let labels: Vec<Option<Surface>> = got.iter().map(|a| a.label).collect();
            assert_eq!(labels, [Some(Surface::Floor), Some(Surface::Wall(0)), None]);
            // The first two are the wall's too (its foot); the third is nobody's.
            let wall_too: Vec<bool> = got.iter().map(|a| a.wall_too).collect();
            assert_eq!(wall_too, [true, true, false]);
        }
    }

    /// A floor point 10 cm before a wall's foot, and a wall point 25 cm up standing over it in
    /// the next scan: where the model has the wall, the ray met the floor first and the point
    /// stays on the floor; where the model lacks the wall, the point is within the noise of an
    /// unmodelled wall's foot and is left out.
    #[test]
    fn a_foot_is_left_out_only_where_the_model_lacks_its_wall() {
        let sigma = 0.1;
        let ray = |x: f64, z: f64| {
            let dir = Vector3::new(x, 0.0, z).normalize();
            LabelledPoint {
                origin: Point3::origin(),
                dir,
                range: (x * x + z * z).sqrt(),
                sigma,
                surface: Surface::Floor,
            }
        };
        let points = [ray(1.9, -0.45), ray(2.0, -0.2)];
        let labels = [Some(Surface::Floor), Some(Surface::Wall(0))];
        let neighbours = Neighbours::new(vec![0, 1], 2, 1, 1);
        let floor_only = MlSolution {
            floor: Some(-0.45),
            ..MlSolution::default()
        };
        let with_wall = MlSolution {
            walls: vec![WallLine {
                surface: Surface::Wall(0),
                azimuth: 0.0,
                offset: 2.0,
            }],
            ..floor_only.clone()
        };
        let relabelled =
            |sol: &MlSolution| relabel(&points, &neighbours, &labels, sol, 3.0, 0.3, 0.02);
        assert_eq!(relabelled(&with_wall), labels);
        assert_eq!(relabelled(&floor_only), [None, None]);
    }

    /// Two scans of 8 bearings (one invalid reading): a floor point loses its label where a
    /// point of its own scan within the window holds another label or none, and only then;
    /// walls and unlabelled points keep theirs, and the other scan's points are not looked at.
    #[test]
    fn level_edges_are_the_floor_points_next_to_another_label_along_their_scan() {
        use Surface::{Ceiling, Floor, Wall};
        let (f, w, c) = (Some(Floor), Some(Wall(0)), Some(Ceiling));
        // Grid rows: scan 0 = F F F F F W W ., scan 1 = C C C C - F F F (`.` a reading with
        // no label, `-` no reading).
        let grid: [Option<Option<Surface>>; 16] = [
            Some(f),
            Some(f),
            Some(f),
            Some(f),
            Some(f),
            Some(w),
            Some(w),
            Some(None),
            Some(c),
            Some(c),
            Some(c),
            Some(c),
            None,
            Some(f),
            Some(f),
            Some(f),
        ];
        let mut at = vec![None; grid.len()];
        let (mut index, mut labels) = (Vec::new(), Vec::new());
        for (g, cell) in grid.iter().enumerate() {
            if let Some(l) = cell {
                at[g] = Some(index.len());
                index.push(g);
                labels.push(*l);
            }
        }
        let neighbours = Neighbours {
            at,
            index,
            cols: 8,
            window: 1,
        };
        let got = without_level_edges(&labels, &neighbours, 2);
        // Scan 0: the two floor points within 2 bearings of the wall go; scan 1: the ceiling
        // and floor meet across an invalid reading, 2 bearings apart.
        let want = [f, f, f, None, None, w, w, None, c, c, c, None, None, f, f];
        assert_eq!(got, want);
        assert_eq!(without_level_edges(&labels, &neighbours, 0), labels);
        let wide = without_level_edges(&labels, &neighbours, 8);
        assert!(wide.iter().zip(&labels).all(|(g, l)| g == l || g.is_none()));
        assert_eq!(wide[5..8], labels[5..8]);
    }
}
