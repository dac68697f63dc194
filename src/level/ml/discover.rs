//! Walls the segmentation lacks, found in the level frame of the first fit.
//!
//! Region growing needs a wall to fill several quads before it becomes a patch; at high noise
//! the small ones (a pillar's side, a short stretch between doors, a far wall met by a dozen
//! rays) never do. The last stage then has no surface for their points: it leaves them out,
//! and where such a wall stands on the floor its foot goes to the floor and pulls it (traced
//! at 10 cm noise: the leveler's model lacked a wall of the truth at 84% of leveled poses, and
//! the poses with more than ten points on the wrong surface erred by 1.3-1.4 of the bound
//! against 0.8-0.9 for those with none; docs/ESTIMATOR.md, section 18).
//!
//! Once the first fit has levelled the points, such a wall is easy to see: it is a straight
//! run of unexplained points in each scan that meets it, and the runs of different scans lie
//! on one line of the level frame. A wall met by one scan only is not looked for: any line in
//! space lies in some vertical plane, so it says nothing about up.

use super::model::{Placement, Plane, Rotations, predict_level};
use super::relabel::{Leveled, Neighbours, leveled};
use super::{LabelledPoint, MlParams, MlSolution, Surface};
use crate::geometry::minor_axis_2x2;
use nalgebra::{Matrix2, Vector2};

/// A run of points of one scan that lie on one line of the level frame.
struct Run {
    row: usize,
    members: Vec<usize>,
}

/// A candidate wall: the points of its runs, the rows they come from, and its line.
struct Found {
    members: Vec<usize>,
    rows: Vec<usize>,
    line: Line,
}

/// A 2D line of the level frame through `centroid` along unit `dir`, and the stretch of its
/// points' tangent coordinates.
#[derive(Clone, Copy)]
struct Line {
    centroid: Vector2<f64>,
    dir: Vector2<f64>,
    stretch: (f64, f64),
}

impl Line {
    /// The total-least-squares line through `xy` (at least two points).
    fn fit(xy: &[Vector2<f64>]) -> Option<Line> {
        let centroid = xy.iter().sum::<Vector2<f64>>() / xy.len() as f64;
        let scatter = xy.iter().fold(Matrix2::zeros(), |m, p| {
            let d = p - centroid;
            m + d * d.transpose()
        });
        // Along the scatter's major axis.
        let normal = minor_axis_2x2(&scatter);
        let dir = Vector2::new(normal.y, -normal.x);
        let mut stretch = (f64::INFINITY, f64::NEG_INFINITY);
        for p in xy {
            let t = dir.dot(&(p - centroid));
            stretch = (stretch.0.min(t), stretch.1.max(t));
        }
        (stretch.1 > stretch.0).then_some(Line {
            centroid,
            dir,
            stretch,
        })
    }

    fn distance(&self, p: &Vector2<f64>) -> f64 {
        let d = p - self.centroid;
        (d.x * self.dir.y - d.y * self.dir.x).abs()
    }

    fn tangent(&self, p: &Vector2<f64>) -> f64 {
        self.dir.dot(&(p - self.centroid))
    }
}

/// `labels` with the walls the model lacks added under new wall indices (above every index in
/// `labels`): among the points no surface of `sol` explains and that the floor and ceiling do
/// not explain either, straight runs of one scan in the level frame of `sol`, joined across
/// scans where they lie on one line; a wall is kept when at least two scans meet it.
pub(crate) fn with_missing_walls(
    points: &[LabelledPoint],
    neighbours: &Neighbours,
    labels: &[Option<Surface>],
    sol: &MlSolution,
    params: &MlParams,
) -> Vec<Option<Surface>> {
    let rot = Rotations::at(&Vector2::new(sol.attitude[0], sol.attitude[1]));
    let level: Vec<Leveled> = points.iter().map(|p| leveled(p, &rot)).collect();
    let xy: Vec<Vector2<f64>> = level.iter().map(|l| l.q.xy()).collect();
    let level_planes: Vec<Plane> = [(Surface::Floor, sol.floor), (Surface::Ceiling, sol.ceiling)]
        .into_iter()
        .filter_map(|(s, h)| Some(Plane::at(&Placement::level(h?), s)))
        .collect();
    let on_level_plane = |i: usize| {
        let (p, l) = (&points[i], &level[i]);
        level_planes.iter().any(|plane| {
            let t = predict_level(plane, &l.u, &l.o).0;
            t > 0.0 && (p.range - t).abs() <= params.huber_k * p.sigma
        })
    };
    let candidate: Vec<bool> = (0..points.len())
        .map(|i| labels[i].is_none() && !on_level_plane(i))
        .collect();
    let runs = straight_runs(points, neighbours, &xy, &candidate, params);
    let walls = joined(points, &xy, runs, params);
    let mut out = labels.to_vec();
    let next = labels
        .iter()
        .filter_map(|l| match l {
            Some(Surface::Wall(k)) => Some(k + 1),
            _ => None,
        })
        .max()
        .unwrap_or(0);
    for (n, wall) in walls.into_iter().enumerate() {
        for i in wall.members {
            out[i] = Some(Surface::Wall(next + n));
        }
    }
    out
}

/// Per scan, the candidates' runs (neighbours in bearing within `missing_wall_max_gap`), split
/// where they leave a straight line (Douglas-Peucker at `huber_k` sigmas), of at least
/// `missing_wall_min_run` points.
fn straight_runs(
    points: &[LabelledPoint],
    neighbours: &Neighbours,
    xy: &[Vector2<f64>],
    candidate: &[bool],
    params: &MlParams,
) -> Vec<Run> {
    let cols = neighbours.cols.max(1);
    let mut runs = Vec::new();
    let mut current: Vec<usize> = Vec::new();
    let mut last: Option<(usize, usize)> = None;
    // Points are in row-major grid order.
    for (i, &c) in candidate.iter().enumerate() {
        if !c {
            continue;
        }
        let (row, col) = (neighbours.index[i] / cols, neighbours.index[i] % cols);
        let joins = last.is_some_and(|(r, c0)| r == row && col - c0 <= params.missing_wall_max_gap);
        if let Some((done, _)) = last.filter(|_| !joins) {
            split_straight(points, xy, &current, done, params, &mut runs);
            current.clear();
        }
        current.push(i);
        last = Some((row, col));
    }
    if let Some((done, _)) = last {
        split_straight(points, xy, &current, done, params, &mut runs);
    }
    runs
}

/// Douglas-Peucker on one run of scan `row`: kept whole when every point lies within
/// `huber_k` of its sigmas of the chord, else split at the farthest point.
fn split_straight(
    points: &[LabelledPoint],
    xy: &[Vector2<f64>],
    run: &[usize],
    row: usize,
    params: &MlParams,
    out: &mut Vec<Run>,
) {
    if run.len() < params.missing_wall_min_run {
        return;
    }
    let (a, b) = (xy[run[0]], xy[run[run.len() - 1]]);
    let Some(dir) = (b - a).try_normalize(1e-9) else {
        return;
    };
    let off = |i: usize| {
        let d = xy[i] - a;
        (d.x * dir.y - d.y * dir.x).abs() / points[i].sigma
    };
    let (far, worst) = run
        .iter()
        .enumerate()
        .map(|(j, &i)| (j, off(i)))
        .fold((0, 0.0), |m, x| if x.1 > m.1 { x } else { m });
    if worst <= params.huber_k {
        out.push(Run {
            row,
            members: run.to_vec(),
        });
        return;
    }
    let far = far.clamp(1, run.len() - 2);
    split_straight(points, xy, &run[..=far], row, params, out);
    split_straight(points, xy, &run[far..], row, params, out);
}

/// The runs joined into walls, longest first: a run joins a wall when every point of it lies
/// within `huber_k` of its sigmas of the wall's line and it reaches the wall's stretch within
/// `missing_wall_along_gap`. Walls of one scan, or of fewer than `missing_wall_min_points`,
/// are dropped.
fn joined(
    points: &[LabelledPoint],
    xy: &[Vector2<f64>],
    mut runs: Vec<Run>,
    params: &MlParams,
) -> Vec<Found> {
    runs.sort_by_key(|r| std::cmp::Reverse(r.members.len()));
    let mut walls: Vec<Found> = Vec::new();
    let fit = |members: &[usize]| Line::fit(&members.iter().map(|&i| xy[i]).collect::<Vec<_>>());
    for run in runs {
        let fits = |w: &Found| {
            let along = run.members.iter().map(|&i| w.line.tangent(&xy[i]));
            let (lo, hi) = along.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), t| {
                (a.min(t), b.max(t))
            });
            lo <= w.line.stretch.1 + params.missing_wall_along_gap
                && hi >= w.line.stretch.0 - params.missing_wall_along_gap
                && run
                    .members
                    .iter()
                    .all(|&i| w.line.distance(&xy[i]) <= params.huber_k * points[i].sigma)
        };
        match walls.iter_mut().find(|w| fits(w)) {
            Some(w) => {
                w.members.extend(&run.members);
                if !w.rows.contains(&run.row) {
                    w.rows.push(run.row);
                }
                if let Some(line) = fit(&w.members) {
                    w.line = line;
                }
            }
            None => {
                if let Some(line) = fit(&run.members) {
                    walls.push(Found {
                        members: run.members,
                        rows: vec![run.row],
                        line,
                    });
                }
            }
        }
    }
    walls.retain(|w| w.rows.len() >= 2 && w.members.len() >= params.missing_wall_min_points);
    walls
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::bound::pose_rays;
    use crate::eval::test_scenes::tilted_room_scans;
    use crate::eval::true_segments::in_grid;
    use crate::geometry::{Attitude, Pose};
    use crate::level::LevelParams;
    use crate::level::ml::from_segmentation::last_stage;
    use crate::level::ml::solve::refine_labelled;

    const DEG: f64 = std::f64::consts::PI / 180.0;

    /// A tilted pose in a 6 x 4 m room with a floor and a ceiling, met by four scans at range
    /// noise `noise`: its points in grid order with their true surfaces, their neighbourhoods,
    /// and the truth.
    fn scene(noise: f64, sigma: f64, seed: u64) -> (Vec<LabelledPoint>, Neighbours, Pose) {
        let (truth, scans, world, planes) =
            tilted_room_scans(2.4, (7.0 * DEG, -5.0 * DEG), noise, seed);
        let rays = pose_rays(&world, &planes, &scans, &truth, 30.0);
        let (points, neighbours) = in_grid(&rays, &scans, sigma, 1).unwrap();
        (points, neighbours, truth)
    }

    /// The wall with the most points, and the true labels without it.
    fn without_largest_wall(points: &[LabelledPoint]) -> (Surface, Vec<Option<Surface>>) {
        let count = |s: Surface| points.iter().filter(|p| p.surface == s).count();
        let wall = (0..8).map(Surface::Wall).max_by_key(|&s| count(s)).unwrap();
        let labels = points
            .iter()
            .map(|p| (p.surface != wall).then_some(p.surface))
            .collect();
        (wall, labels)
    }

    fn fit_at_truth(
        points: &[LabelledPoint],
        labels: &[Option<Surface>],
        truth: &Pose,
    ) -> MlSolution {
        let up = Attitude::new(truth.rx, truth.ry).up_in_robot();
        refine_labelled(points, labels, &up, &MlParams::default()).unwrap()
    }

    /// Noise-free, a wall left out of the labels comes back as one new wall: every point
    /// given to it is one of that wall's, and it takes all of them but the few the floor or
    /// the ceiling explains as well (its foot and top), under an index no label had.
    #[test]
    fn a_wall_the_labels_lack_is_found_whole() {
        let (points, neighbours, truth) = scene(0.0, 0.01, 1);
        let (wall, labels) = without_largest_wall(&points);
        let sol = fit_at_truth(&points, &labels, &truth);
        let out = with_missing_walls(&points, &neighbours, &labels, &sol, &MlParams::default());
        let new: Vec<usize> = (0..points.len()).filter(|&i| out[i] != labels[i]).collect();
        let on_wall = points.iter().filter(|p| p.surface == wall).count();
        assert!(new.len() >= on_wall * 9 / 10, "{} of {on_wall}", new.len());
        assert!(new.iter().all(|&i| points[i].surface == wall));
        let found = out[new[0]];
        assert!(new.iter().all(|&i| out[i] == found));
        assert!(!labels.contains(&found), "{found:?} was already a label");
    }

    /// A wall whose points only one scan leaves unexplained is not looked for: one scan's line
    /// lies in some vertical plane whatever up is.
    #[test]
    fn a_wall_one_scan_meets_is_not_looked_for() {
        let (points, neighbours, truth) = scene(0.0, 0.01, 1);
        let (wall, _) = without_largest_wall(&points);
        let row = |i: usize| neighbours.index[i] / neighbours.cols;
        let first_row = (0..points.len())
            .find(|&i| points[i].surface == wall)
            .map(row)
            .unwrap();
        let labels: Vec<Option<Surface>> = (0..points.len())
            .map(|i| {
                (points[i].surface != wall || row(i) != first_row).then_some(points[i].surface)
            })
            .collect();
        let sol = fit_at_truth(&points, &labels, &truth);
        let out = with_missing_walls(&points, &neighbours, &labels, &sol, &MlParams::default());
        assert_eq!(out, labels);
    }

    /// At 5 cm noise, the last stage given labels that lack the largest wall: with the search
    /// it fits the wall again (whole, or in pieces where a stretch of it is not straight enough
    /// at this noise to join), lands within three of its sigmas of the truth, and its sigmas
    /// lie within a tenth of those of the stage given every label; without the search the wall
    /// stays out.
    #[test]
    fn the_last_stage_recovers_a_wall_the_segmentation_lacks() {
        let sigma = 0.05;
        for seed in 1..=3 {
            let (points, neighbours, truth) = scene(sigma, sigma, seed);
            let (_, labels) = without_largest_wall(&points);
            let all: Vec<Option<Surface>> = points.iter().map(|p| Some(p.surface)).collect();
            let up = Attitude::new(truth.rx + 0.5 * DEG, truth.ry).up_in_robot();
            let stage = |labels: &[Option<Surface>], missing_walls: bool| {
                let mut params = LevelParams::default();
                params.ml.missing_walls = missing_walls;
                last_stage(&points, &neighbours, labels, &up, sigma, &params).unwrap()
            };
            let (with, without, whole) = (
                stage(&labels, true),
                stage(&labels, false),
                stage(&all, true),
            );
            assert!(with.walls.len() >= whole.walls.len(), "seed {seed}");
            assert_eq!(without.walls.len() + 1, whole.walls.len(), "seed {seed}");
            let err = [with.attitude[0] - truth.rx, with.attitude[1] - truth.ry];
            for a in 0..2 {
                let s = with.sigmas()[a];
                assert!(err[a].abs() < 3.0 * s, "seed {seed}: {err:?} against {s}");
                assert!(
                    s < 1.1 * whole.sigmas()[a],
                    "seed {seed}, axis {a}: {s} against {:?}",
                    whole.sigmas()
                );
            }
        }
    }
}
