//! Trimming a patch's edge rows and the runs at its rows' ends that stand in front of its
//! plane (a wall patch that took in the floor at its foot).

use super::*;

/// The members without the rows at either edge of the patch that the plane of its other rows
/// does not explain; `None` when no row goes, and none at all (an empty list) when the patch
/// spans three rows and one of its edge rows goes. At the foot of a wall the scan below the wall
/// meets the floor within centimetres of the wall's plane, and the wall's patch takes that
/// floor line in and tilts towards it: in a ceiling room, with a hinge offset and 2 cm noise,
/// such patches leveled poses 7-15 degrees off with sigmas near 1 degree. Fitted with the
/// line, the plane absorbs most of its offset (what [`bent_across_rows`] sees); left out, the
/// offset is plain: the edge row's mean residual from the other rows' plane, over its noise
/// (each point's range noise along the normal, `sigma |d . n|`) and that plane's own
/// uncertainty at the row (offset, and tilt over the lever arm), scaled by the plane's misfit.
pub(super) fn trim_edge_rows(
    grid: &PoseGrid,
    members: &[usize],
    all: &PlaneAccumulator,
    all_fit: &PlaneFit,
    sigma: f64,
    params: &LevelParams,
) -> Option<Vec<usize>> {
    // Over four rows or more the rest is still a three-row wall. Over three, an edge row
    // standing off leaves no wall to keep: trimmed to two rows, such patches let other,
    // wrong planes decide some poses at 10 cm; the patch goes (an empty list). Over two,
    // nothing is tested. A plane the noise explains has no row standing off it worth the
    // test either: a floor line taken in at a wall's foot leaves the whole patch's fit about
    // half as scattered again.
    let (lo, hi) = rows_span_sorted(members, grid.cols);
    if params.trim_sigmas <= 0.0 || hi < lo + 2 || plane_explained(all_fit, sigma, params) {
        return None;
    }
    // Each row's own sums, so that the other rows' plane is a subtraction away.
    let mut per_row = vec![PlaneAccumulator::default(); hi + 1];
    for &i in members {
        if let Some(g) = &grid.points[i] {
            per_row[grid.row(i)].add(g);
        }
    }
    let rows = EdgeRows {
        grid,
        members,
        all,
        per_row: &per_row,
        sigma,
        params,
    };
    let (mut first, mut last) = (lo, hi);
    if hi == lo + 2 {
        // A wall line and the floor line at its foot, 2-15 cm out, with a few points of the
        // third scan near the hinge axis: a "wall" 11.6 degrees off at 1 cm noise.
        return (rows.stands_off(lo, lo, hi) || rows.stands_off(hi, lo, hi)).then(Vec::new);
    }
    if rows.stands_off(first, first, last) {
        first += 1;
    }
    if last >= first + 3 && rows.stands_off(last, first, last) {
        last -= 1;
    }
    let counts: Vec<usize> = (first..=last).map(|r| per_row[r].n).collect();
    if (first, last) == (lo, hi) || !trimmed_rows_hold(&counts, all.n) {
        return None;
    }
    let kept = |i: &usize| (first..=last).contains(&grid.row(*i));
    Some(members.iter().copied().filter(kept).collect())
}

/// A patch's rows for [`trim_edge_rows`]: its members, their sums and each row's own sums (up
/// to its highest row; those below its lowest are empty).
struct EdgeRows<'a> {
    grid: &'a PoseGrid,
    members: &'a [usize],
    all: &'a PlaneAccumulator,
    per_row: &'a [PlaneAccumulator],
    sigma: f64,
    params: &'a LevelParams,
}

impl EdgeRows<'_> {
    /// Whether `row` stands off the plane of the rows `first..=last` other than it: its mean
    /// residual from that plane beyond `trim_sigmas` of its spread (the row's noise along the
    /// normal, plus the plane's own offset and tilt uncertainty at the row, scaled by the
    /// plane's misfit), as the doc of [`trim_edge_rows`] explains.
    fn stands_off(&self, row: usize, first: usize, last: usize) -> bool {
        let (params, s) = (self.params, self.sigma.max(self.params.min_sigma));
        let others = (0..self.per_row.len())
            .filter(|&r| r == row || !(first..=last).contains(&r))
            .fold(*self.all, |acc, r| acc.minus(&self.per_row[r]));
        let enough = others.n >= params.min_patch_points;
        let Some(fit) = others.fit(self.sigma).filter(|_| enough) else {
            return false;
        };
        let (mut sum, mut var, mut at, mut n) = (0.0, 0.0, Vector3::zeros(), 0.0);
        for g in self
            .members
            .iter()
            .filter(|&&i| self.grid.row(i) == row)
            .filter_map(|&i| self.grid.points[i].as_ref())
        {
            sum += fit.distance(&g.p);
            var += (s * g.dir.dot(&fit.normal).abs().max(params.min_ray_share)).powi(2);
            at += g.p.coords;
            n += 1.0;
        }
        if n == 0.0 {
            return false;
        }
        // The mean residual's noise, plus the other rows' plane's own uncertainty where the
        // row lies: its offset at the centroid and its tilt over the lever arm to the row.
        let arm = at / n - fit.centroid.coords;
        let arm = arm - fit.normal * fit.normal.dot(&arm);
        let tilt = arm.try_normalize(1e-12).map_or(0.0, |u| {
            arm.norm_squared() * fit.normal_variance_along(&u, s)
        });
        let offset = s * s * fit.dn2 / fit.weight;
        let spread = (var / (n * n) + offset + tilt) * fit.misfit_ratio(s).max(1.0);
        edge_row_off(sum / n, spread, params)
    }
}

/// [`Check::PatchEdgeRow`](crate::level::checks::Check::PatchEdgeRow): whether an edge row
/// whose mean residual from the other rows' plane is `mean`, of variance `spread`, stands off
/// it by more than `trim_sigmas`.
pub(crate) fn edge_row_off(mean: f64, spread: f64, params: &LevelParams) -> bool {
    mean.abs() > params.trim_sigmas * spread.sqrt()
}

/// [`Check::PatchTrimmedRows`](crate::level::checks::Check::PatchTrimmedRows): whether the
/// rows left after a trim, with `counts` points each of the patch's `total`, are still a wall
/// over three adjacent rows, each holding [`MIN_TRIMMED_ROW_SHARE`] of the points. Else the
/// row that stood off may be the true wall and the rest a wall line and the floor line at its
/// foot, coplanar, with a few stray points in other rows: trimmed, such a patch leveled a pose
/// 28 degrees off at 1 cm noise.
pub(crate) fn trimmed_rows_hold(counts: &[usize], total: usize) -> bool {
    let held: Vec<usize> = (0..counts.len())
        .filter(|&r| counts[r] as f64 >= MIN_TRIMMED_ROW_SHARE * total as f64)
        .collect();
    held.len() >= 3 && held.windows(2).all(|w| w[1] == w[0] + 1)
}

/// The members (ascending) without the runs of points at either end of their rows that stand
/// in front of the plane `fit`; `None` when no run does.
///
/// Where a wall meets the floor, the floor just in front of its foot lies within the growing
/// tolerance of the wall's plane at high noise, and the scans that reach below the foot meet it
/// at one end of their run over the wall, where the floor takes over along the scan line. Those
/// points all lie on the scanner's side of the wall and tilt it: at 10 cm noise with 361 rays,
/// one pose leveled 2.4 degrees off on average over 300 noise draws (the true segmentation: 0.0).
/// The ceiling over a wall's top, a wall's foot in a floor patch and the other wall of a
/// concave corner join the same way. A true plane's residuals take no side, so the test is the
/// sum of the residuals towards the scanner over the first `m` points of the run (`m` from
/// [`MIN_FRONT_RUN`] to half the run), over that sum's standard deviation (each point's
/// `sigma |d . n|` in quadrature), above `front_end_sigmas`. [`Growth::make_patch`] applies it
/// to the plane it has fitted and fits again without the runs that go. Over 129,600 protocol poses at
/// 5-10 cm (two seed sets, nine plans), poses reported ok and more than 5 degrees off fell from
/// 14 to 4 and those beyond 3 sigmas from 157 to 110, with 0.24 points more leveled; at 1 cm,
/// 0.04 points more.
pub(super) fn without_front_row_ends(
    grid: &PoseGrid,
    members: &[usize],
    fit: &PlaneFit,
    params: &LevelParams,
    sigma: f64,
) -> Option<Vec<usize>> {
    if params.front_end_sigmas <= 0.0 {
        return None;
    }
    let s = sigma.max(params.min_sigma);
    // The scanner sits at the robot frame's origin. Residuals towards it are in units of `s`,
    // their variances in units of `s^2`.
    let towards = fit.distance(&Point3::origin()).signum();
    let along = fit.normal * (towards / s);
    let at = along.dot(&fit.centroid.coords);
    let in_front = |i: usize| {
        grid.points[i].as_ref().map_or((0.0, 0.0), |g| {
            let share = g.dir.dot(&fit.normal).abs().max(params.min_ray_share);
            (along.dot(&g.p.coords) - at, share * share)
        })
    };
    let k = params.front_end_sigmas;
    let mut keep = vec![true; members.len()];
    let mut dropped = false;
    // Members ascend: each row's are one slice, in column order.
    let mut start = 0;
    while start < members.len() {
        let next_row = (grid.row(members[start]) + 1) * grid.cols;
        let len = members[start..].partition_point(|&i| i < next_row);
        let run = &members[start..start + len];
        let half = len / 2;
        let left = front_run(run[..half].iter().map(|&i| in_front(i)), k);
        let right = front_run(run[len - half..].iter().rev().map(|&i| in_front(i)), k);
        keep[start..start + left].fill(false);
        keep[start + len - right..start + len].fill(false);
        dropped |= left + right > 0;
        start += len;
    }
    let kept = || {
        members
            .iter()
            .zip(&keep)
            .filter_map(|(&i, &k)| k.then_some(i))
    };
    dropped.then(|| kept().collect())
}

/// Length of the leading run of `residuals` whose sum (with their variances) stands out most in
/// standard deviations of that sum, when by more than `k` and the run is at least
/// [`MIN_FRONT_RUN`] long; 0 otherwise.
pub(super) fn front_run(residuals: impl Iterator<Item = (f64, f64)>, k: f64) -> usize {
    let (mut sum, mut var) = (0.0, 0.0);
    // Compared squared and cross-multiplied, `sum^2 / var > best`, with no root or division
    // per point.
    let (mut best_sum2, mut best_var, mut best) = (k * k, 1.0, 0);
    for (m, (r, v)) in residuals.enumerate() {
        sum += r;
        var += v;
        if m + 1 >= MIN_FRONT_RUN && sum > 0.0 && sum * sum * best_var > best_sum2 * var {
            (best_sum2, best_var, best) = (sum * sum, var, m + 1);
        }
    }
    best
}
