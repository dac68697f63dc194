//! A start for poses whose walls all face one way (a corridor seen from inside, a hall's long
//! wall): the walls pin up to the plane normal to them and leave one angle free. Of the ups
//! that angle allows, the one under which most of the points no wall holds lie at one height
//! (a floor or a ceiling) is taken, with that plane as level. It needs no quads and no range
//! steps, which both fail where such poses see the floor: at the ends of the scans, where the
//! hinge turns about the scans' end rays and scans at different elevations meet nearly the same
//! spots (docs/ESTIMATOR.md section 17).

use super::*;
use crate::level::first_pass::{level_obs, wall_obs};
use crate::level::grid::PlaneAccumulator;
use crate::level::params::up::*;
use crate::level::patches::{Patch, UNLABELLED};

/// Coarse and fine steps of the sweep over the free angle \[deg\].
const COARSE_DEG: f64 = 1.0;
const FINE_DEG: f64 = 0.1;
/// Wall patches farther than this from their mean normal are not one family \[deg\].
const FAMILY_DEG: f64 = 10.0;
/// Another angle at least this far from the best that puts this share of its count at one
/// height, mostly other points, makes the sweep ambiguous \[deg, 1\].
const RIVAL_DEG: f64 = 2.0;
const RIVAL_SHARE: f64 = 0.8;
/// Points the coarse sweep counts at most.
const COARSE_POINTS: usize = 160;

/// The start (see the module's notes): `None` when the wall patches are not one family, or no
/// angle puts `level_line_min_points` of the other points at one height away from the
/// scanner, or another angle does nearly as well.
pub(crate) fn swept_start(
    grid: &PoseGrid,
    patches: &[Patch],
    labels: &[u32],
    params: &LevelParams,
    sigma: f64,
) -> Option<UpSolution> {
    let s = sigma.max(params.min_sigma);
    let walls: Vec<&Patch> = patches
        .iter()
        .filter(|p| p.kind == SurfaceKind::Wall)
        .collect();
    let n = family_normal(&walls)?;
    // Up = cos(a) z + sin(a) e: the robot's up made normal to the walls, turned about them.
    let z = (Vector3::z() - n * n.z).try_normalize(1e-9)?;
    let e = n.cross(&z);
    let up_at = |a: f64| z * a.cos() + e * a.sin();
    let free: Vec<&GridPoint> = grid
        .points
        .iter()
        .zip(labels)
        .filter(|&(_, &l)| l == UNLABELLED || patches[l as usize].kind != SurfaceKind::Wall)
        .filter_map(|(g, _)| g.as_ref())
        .collect();
    let min_points = params.level_line_min_points;
    if free.len() < min_points {
        return None;
    }
    // A point's tolerance along up: `refine_k` sigmas of its range noise along up (a floor
    // seen at a grazing angle holds its points within millimetres of its height).
    let ms2 = params.min_sigma * params.min_sigma;
    let tolerance = |g: &GridPoint, up: &Vector3<f64>| {
        params.refine_k * (s * s * g.dir.dot(up).powi(2) + ms2).sqrt()
    };
    // The coarse sweep on at most `COARSE_POINTS` of them, evenly taken (the counts only
    // compare angles), the fine one on all.
    let stride = free.len().div_ceil(COARSE_POINTS).max(1);
    let mut coarse_sweep = HeightSweep::new(free.iter().step_by(stride).copied().collect());
    let max = MAX_TILT_DEG.to_radians();
    let coarse: Vec<(f64, (usize, f64))> = (0..)
        .map(|i| -max + i as f64 * COARSE_DEG.to_radians())
        .take_while(|&a| a <= max)
        .map(|a| (a, coarse_sweep.most_at_one_height(&up_at(a), &tolerance)))
        .collect();
    let &(a0, (c0, h0)) = coarse.iter().max_by_key(|x| x.1.0)?;
    if c0 * stride < min_points {
        return None;
    }
    // Which of the coarse sweep's points lie at `height` under the up of angle `a`.
    let some = &coarse_sweep.points;
    let on = |a: f64, height: f64| -> Vec<bool> {
        let up = up_at(a);
        some.iter()
            .map(|g| (up.dot(&g.p.coords) - height).abs() <= tolerance(g, &up))
            .collect()
    };
    // A rival is another angle that puts nearly as many points at one height, mostly other
    // points (a box's top beside the floor). The same points at neighbouring angles are one
    // short floor seen over a range of angles, which the fit below weighs.
    let best = on(a0, h0);
    let rival = coarse.iter().any(|&(a, (c, h))| {
        (a - a0).abs() > RIVAL_DEG.to_radians() && c as f64 >= RIVAL_SHARE * c0 as f64 && {
            let theirs = on(a, h);
            let shared = theirs.iter().zip(&best).filter(|&(&t, &b)| t && b).count();
            2 * shared < c
        }
    });
    if rival {
        return None;
    }
    let mut fine_sweep = HeightSweep::new(free);
    let mut level_at = |a: f64| fine_sweep.most_at_one_height(&up_at(a), &tolerance);
    let (a, (count, height)) = (-10..=10)
        .map(|i| a0 + i as f64 * FINE_DEG.to_radians())
        .map(|a| (a, level_at(a)))
        .max_by_key(|x| x.1.0)?;
    if count < min_points {
        return None;
    }
    let up = up_at(a);
    let mut acc = PlaneAccumulator::default();
    for g in fine_sweep
        .points
        .iter()
        .filter(|g| (up.dot(&g.p.coords) - height).abs() <= tolerance(g, &up))
    {
        acc.add(g);
    }
    let level = acc.fit(sigma)?;
    let mut obs: Vec<PlaneObs> = walls
        .iter()
        .map(|w| wall_obs(&w.fit, params, sigma))
        .collect();
    obs.push(level_obs(&level, params, sigma));
    up::up_robust(&obs, s, params.iterations)
}

/// The walls' common normal (weighted by their points, one sign), when every wall lies within
/// `FAMILY_DEG` of it.
fn family_normal(walls: &[&Patch]) -> Option<Vector3<f64>> {
    let first = walls.first()?.fit.normal;
    let sum = walls.iter().fold(Vector3::zeros(), |acc, w| {
        let n = w.fit.normal;
        acc + if n.dot(&first) < 0.0 { -n } else { n } * w.fit.n as f64
    });
    let n = sum.try_normalize(1e-12)?;
    let family = FAMILY_DEG.to_radians().cos();
    walls
        .iter()
        .all(|w| w.fit.normal.dot(&n).abs() >= family)
        .then_some(n)
}

/// The points a sweep counts, with the order of their intervals' ends kept from one angle to
/// the next: a turn of a degree hardly reorders them, so the ends are re-sorted by insertion
/// in about linear time.
struct HeightSweep<'p> {
    points: Vec<&'p GridPoint>,
    /// Each interval's end: its height, +1 opening or -1 closing, and its point.
    ends: Vec<(f64, i32, usize)>,
    /// Scratch: each point's interval under the current up.
    bounds: Vec<(f64, f64)>,
}

impl<'p> HeightSweep<'p> {
    fn new(points: Vec<&'p GridPoint>) -> Self {
        let ends = (0..points.len())
            .flat_map(|i| [(0.0, 1, i), (0.0, -1, i)])
            .collect();
        HeightSweep {
            bounds: Vec::with_capacity(points.len()),
            points,
            ends,
        }
    }

    /// The most points within their `tolerance` of one height along `up`, away from the
    /// scanner (a plane through it is one scan's own, not a surface): `(count, height)`. The
    /// deepest overlap of the intervals `height ± tolerance`, by a sweep line over their
    /// sorted ends: the count at each interval's lower end, outside the band about the
    /// scanner.
    fn most_at_one_height(
        &mut self,
        up: &Vector3<f64>,
        tolerance: &impl Fn(&GridPoint, &Vector3<f64>) -> f64,
    ) -> (usize, f64) {
        let mut widest: f64 = 0.0;
        self.bounds.clear();
        self.bounds.extend(self.points.iter().map(|g| {
            let (h, t) = (up.dot(&g.p.coords), tolerance(g, up));
            widest = widest.max(t);
            (h - t, h + t)
        }));
        for end in self.ends.iter_mut() {
            let (lo, hi) = self.bounds[end.2];
            end.0 = if end.1 > 0 { lo } else { hi };
        }
        // Opening ends before closing ones at one height: touching intervals overlap.
        let ends = &mut self.ends;
        let before = |a: &(f64, i32, usize), b: &(f64, i32, usize)| {
            a.0.total_cmp(&b.0).then(b.1.cmp(&a.1)) == std::cmp::Ordering::Less
        };
        for i in 1..ends.len() {
            let mut j = i;
            while j > 0 && before(&ends[j], &ends[j - 1]) {
                ends.swap(j, j - 1);
                j -= 1;
            }
        }
        let mut best = (0, 0.0);
        let mut depth = 0i32;
        for &(at, step, _) in ends.iter() {
            depth += step;
            if step > 0 && at.abs() >= 2.0 * widest && depth as usize > best.0 {
                best = (depth as usize, at);
            }
        }
        best
    }
}
