//! Robust plane fits of a patch's points (Cauchy weights, per-ray tolerances) and the
//! orders its members are visited in.

use super::*;

impl Growth<'_> {
    /// The plane `fit` of a patch's `members` refitted with ray weights and, when it misfits,
    /// Cauchy weights on each point's residual over its own noise along the normal
    /// (`sigma |d . n|`), so that the few floor points caught at a wall's foot, all on one side
    /// of it, stop tilting the wall ([`ray_weighted_fit`]).
    pub(super) fn robust_fit(&self, members: &[usize], fit: PlaneFit) -> Option<PlaneFit> {
        let points = members.iter().filter_map(|&i| self.grid.points[i].as_ref());
        ray_weighted_fit(points, self.params, self.sigma, fit)
    }
}

/// Cauchy weight of a point's residual over its own noise along the normal.
pub(super) fn cauchy_weight(fit: &PlaneFit, g: &GridPoint, s: f64, params: &LevelParams) -> f64 {
    let sd = s * g.dir.dot(&fit.normal).abs().max(CAUCHY_RAY_SHARE);
    let z = fit.distance(&g.p) / (params.plane_cauchy * sd);
    1.0 / (1.0 + z * z)
}

/// How far from a patch's plane a point may lie and still join it: `grow_k` sigmas of the
/// point's own range noise along the plane's normal, `sigma |d . n|` (at least
/// `min_ray_share` of sigma).
///
/// A floor seen at a grazing angle carries its range noise almost along itself, so its points
/// lie within centimetres of its plane even at 10 cm noise, while the foot of a wall rises
/// out of it at once; an isotropic `grow_k sigma` (30 cm at 10 cm noise) let floor patches run
/// up the walls and tilted them by degrees.
pub(super) fn ray_tolerance(
    fit: &PlaneFit,
    g: &GridPoint,
    sigma: f64,
    params: &LevelParams,
) -> f64 {
    params.grow_k * sigma * g.dir.dot(&fit.normal).abs().max(params.min_ray_share)
}

/// A plane refitted with each point weighted by the inverse variance of its range noise
/// along the normal, `1 / (d . n)^2` (with `|d . n|` at least `ray_weight_floor`), normalised
/// to a mean of one so that [`PlaneFit::normal_variance_along`] stays the weighted fit's
/// variance; plus the Cauchy weights of [`Growth::robust_fit`] when the plane misfits. Points met at
/// an oblique incidence are the precise ones along the normal; an unweighted fit lets the
/// head-on points' noise dominate. One pass, with the weights from the unweighted fit's normal:
/// a second pass, with weights from the weighted normal, moved no statistic beyond its noise
/// (75,600 protocol poses at 5-10 cm: leveled 73.94 vs 73.92%, ok and > 5 degrees off 16 vs
/// 17; the 1 cm cells of Table I unchanged) and cost 4% of `level`'s time.
pub(super) fn ray_weighted_fit<'a>(
    points: impl Iterator<Item = &'a GridPoint>,
    params: &LevelParams,
    sigma: f64,
    fit: PlaneFit,
) -> Option<PlaneFit> {
    let s = sigma.max(params.min_sigma);
    let robust = fit.misfit_ratio(s) > params.split_misfit;
    let (mut acc, mut ray_weights, mut n) = (PlaneAccumulator::default(), 0.0, 0.0);
    for g in points {
        let w = 1.0
            / g.dir
                .dot(&fit.normal)
                .abs()
                .max(params.ray_weight_floor)
                .powi(2);
        let cauchy = if robust {
            cauchy_weight(&fit, g, s, params)
        } else {
            1.0
        };
        acc.add_weighted(g, w * cauchy);
        ray_weights += w;
        n += 1.0;
    }
    // The ray weights' mean scaled to one, after the sums (they are linear in the weights).
    acc.scale(n / ray_weights.max(1e-300));
    acc.fit(sigma)
}

/// Distinct grid indices in ascending order: marked in a bitset over their range and read
/// back word by word, cheaper than a comparison sort for a patch's members (dense in their
/// range).
pub(super) fn ascending(members: &[usize]) -> Vec<usize> {
    let (Some(&lo), Some(&hi)) = (members.iter().min(), members.iter().max()) else {
        return Vec::new();
    };
    if hi - lo > 16 * members.len() {
        let mut v = members.to_vec();
        v.sort_unstable();
        return v;
    }
    let mut bits = vec![0u64; (hi - lo) / 64 + 1];
    for &i in members {
        bits[(i - lo) / 64] |= 1 << ((i - lo) % 64);
    }
    let mut out = Vec::with_capacity(members.len());
    for (k, &word) in bits.iter().enumerate() {
        let mut w = word;
        while w != 0 {
            out.push(lo + 64 * k + w.trailing_zeros() as usize);
            w &= w - 1;
        }
    }
    out
}
