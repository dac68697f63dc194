//! Range noise from the data itself, so that `level` needs no parameters (contract).
//!
//! Three consecutive points of one scan that lie on a straight line (any plane cut by the scan
//! plane) satisfy, with `u = 1/r`, bearing steps `a = phi_i - phi_{i-1}`, `b = phi_{i+1} - phi_i`:
//! `e = sin(b) u_{i-1} + sin(a) u_{i+1} - sin(a + b) u_i = 0` (twice the triangle's area over
//! the product of the ranges). Range noise sigma gives, to first order,
//! `Var(e) = sigma^2 (sin^2 b / r_{i-1}^4 + sin^2 a / r_{i+1}^4 + sin^2 (a+b) / r_i^4)`, so each
//! triple yields one standardised residual; corners and jump edges are outliers, hence a start
//! from the median (MAD), then the RMS of the residuals within three of its sigmas, corrected
//! for the cut: the MAD alone uses 37% of the data's information and the outliers that it
//! does not ignore bias it (+3-6% over nine plans at 1-10 cm; the trimmed RMS +0-2%, with 40% less
//! spread from pose to pose).

use crate::level::params::noise::*;
use crate::scan::Scan;

/// Median absolute deviation to standard deviation for a Gaussian.
const MAD_TO_SIGMA: f64 = 1.482_602_218_505_602;

/// Estimates the range noise sigma \[m\] from the scans of one or more poses; `None` when
/// there are too few triples of consecutive valid rays (fewer than 20).
#[cfg(test)]
pub(crate) fn estimate_range_sigma(scans: &[Scan]) -> Option<f64> {
    estimate_range_sigma_with(scans, None)
}

/// [`estimate_range_sigma`], given the `(sin, cos)` of the bearings when every scan shares
/// them ([`super::grid::BearingTrigCache`]).
pub(crate) fn estimate_range_sigma_with(
    scans: &[Scan],
    shared_trig: Option<&[(f64, f64)]>,
) -> Option<f64> {
    let mut z = Vec::with_capacity(scans.iter().map(Scan::nrays).sum());
    let mut ranges = Vec::with_capacity(z.capacity());
    let mut steps = shared_trig.map(BearingSteps::new).unwrap_or_default();
    let mut trig_of: Option<&[f64]> = None;
    let mut inverse = Vec::new();
    for s in scans {
        // Scans of one pose nearly always share their bearings: their sines once per pose.
        if shared_trig.is_none() && trig_of != Some(&s.theta[..]) {
            let sin_cos: Vec<(f64, f64)> = s.theta.iter().map(|t| t.sin_cos()).collect();
            steps = BearingSteps::new(&sin_cos);
            trig_of = Some(&s.theta[..]);
        }
        standardised_residuals(s, &steps, &mut inverse, &mut z, &mut ranges);
    }
    if z.len() < 20 {
        return None;
    }
    // The pooled estimate reorders its copy; `z` stays in step with `ranges` for the screen.
    let (pooled, mad) = trimmed_sigma(&mut z.clone());
    let halves = looks_heteroscedastic(&z, &ranges, mad)
        .then(|| split_at_median_range(&z, &ranges))
        .flatten()
        .map(|(mut near, mut far)| (trimmed_sigma(&mut near).0, trimmed_sigma(&mut far).0));
    Some(far_if_noisier(pooled, halves))
}

/// How far a stated range noise may lie from the ranges' own scatter and still be believed [-]:
/// a factor of 3 either way. The scatter reads a little high on real surfaces (corners left in,
/// small-scale structure) and the statement may be a scanner's datasheet figure, but a
/// converter's placeholder (CSM's `readings_sigma` of 1 m, or 0) lies orders of magnitude off.
pub(crate) const STATED_NOISE_FACTOR: f64 = 3.0;

/// Whether a `stated` range noise is borne out by the `scatter` the ranges themselves show
/// (both \[m\]): within [`STATED_NOISE_FACTOR`] of it either way; believed when the data show
/// none.
pub(crate) fn stated_is_believable(stated: f64, scatter: Option<f64>) -> bool {
    scatter.is_none_or(|d| stated <= STATED_NOISE_FACTOR * d && stated * STATED_NOISE_FACTOR >= d)
}

/// The range noise `scans` state in their `readings_sigma` (the median over their valid rays)
/// when their ranges' own scatter bears it out ([`stated_is_believable`]); `None` when they
/// state none or one the data contradict. What `match` takes a scan's noise from.
pub fn believed_range_sigma(scans: &[Scan]) -> Option<f64> {
    let mut stated: Vec<f64> = scans.iter().filter_map(Scan::stated_range_sigma).collect();
    if stated.is_empty() {
        return None;
    }
    let mid = stated.len() / 2;
    let s = *stated.select_nth_unstable_by(mid, f64::total_cmp).1;
    stated_is_believable(s, estimate_range_sigma_with(scans, None)).then_some(s)
}

/// A cheap screen before the halves' own estimates ([`far_if_noisier`]): whether the residuals
/// within three of the pooled MAD sigma `mad` are [`SCREEN_RATIO`] times larger in RMS beyond
/// the mean range than within it. Most poses' noise is the same at every range and pay for
/// one pass, not for two more medians (3% of `level`'s instructions at 1 cm).
fn looks_heteroscedastic(z: &[u64], ranges: &[f64], mad: f64) -> bool {
    let mean = ranges.iter().sum::<f64>() / ranges.len() as f64;
    let cut2 = (3.0 * mad).powi(2);
    let (mut near, mut far) = ((0.0, 0usize), (0.0, 0usize));
    for (&b, &r) in z.iter().zip(ranges) {
        let x2 = f64::from_bits(b);
        if x2 <= cut2 {
            let side = if r < mean { &mut near } else { &mut far };
            side.0 += x2;
            side.1 += 1;
        }
    }
    let rms = |(sum, n): (f64, usize)| (sum / n as f64).sqrt();
    near.1 >= 20 && far.1 >= 20 && rms(far) > SCREEN_RATIO * rms(near)
}

/// The noise of all readings, `pooled`, or the farther half's when it exceeds the nearer
/// half's by [`HETEROSCEDASTIC_RATIO`] (`halves`: near, far). Many scanners' noise grows
/// with range, and one sigma for all made far walls' fits overconfident: with noise of 1% of
/// the range, 4 scans at 1 cm (2700 poses, the example and holdout plans), 3 poses were
/// reported ok while more than 5 degrees off and 31 lay beyond 3 sigmas; with the farther
/// half's, none and 5, for 0.5 points fewer leveled; at 0.5 cm + 0.5% of the range, beyond 3
/// sigmas 24 -> 6; at 2% of the range, more than 3 degrees off 21 -> 10 for 5 points fewer
/// leveled. With noise the same at every range it never applies (243,000 protocol poses at
/// 1-10 cm gave the same results).
pub(crate) fn far_if_noisier(pooled: f64, halves: Option<(f64, f64)>) -> f64 {
    match halves {
        Some((near, far)) if far > HETEROSCEDASTIC_RATIO * near => far.max(pooled),
        _ => pooled,
    }
}

/// `values` split into those whose `ranges` lie below the median range and the rest; `None`
/// when either half has fewer than 20.
pub(crate) fn split_at_median_range<T: Copy>(
    values: &[T],
    ranges: &[f64],
) -> Option<(Vec<T>, Vec<T>)> {
    if ranges.len() < 40 || ranges.len() != values.len() {
        return None;
    }
    let median = super::median_of(&mut ranges.to_vec());
    let (mut near, mut far) = (Vec::new(), Vec::new());
    for (&x, &r) in values.iter().zip(ranges) {
        if r < median {
            near.push(x);
        } else {
            far.push(x);
        }
    }
    (near.len() >= 20 && far.len() >= 20).then_some((near, far))
}

/// The noise from squared standardised residuals (as bits): their trimmed RMS, started from
/// their MAD's sigma; with that sigma. Reorders `z`.
fn trimmed_sigma(z: &mut [u64]) -> (f64, f64) {
    // The residuals are squared: the median's root is the median of their magnitudes. The upper
    // median (element `len / 2`) as bits: for non-negative, non-NaN numbers the order of the
    // bit patterns as integers is their numeric order (and `total_cmp`'s), and integer
    // comparisons are cheaper.
    let mid = z.len() / 2;
    let mad = f64::from_bits(*z.select_nth_unstable(mid).1).sqrt() * MAD_TO_SIGMA;
    (trimmed_rms(z.iter().map(|&b| f64::from_bits(b)), mad), mad)
}

/// Gaussian truncated at 3 sigma: its RMS over its sigma, `sqrt(1 - 2 c phi(c) / (2 Phi(c) - 1))`
/// at `c = 3`.
const TRUNCATED_RMS_3: f64 = 0.986_577;

/// The noise from the standardised residuals within three of `start`'s sigmas (the MAD's):
/// their RMS, corrected for the truncation, so that the corners beyond the cut do not count.
/// Takes the residuals squared.
fn trimmed_rms(z2: impl Iterator<Item = f64>, start: f64) -> f64 {
    let cut2 = (3.0 * start).powi(2);
    let (mut sum, mut n) = (0.0, 0usize);
    for x2 in z2.filter(|&x2| x2 <= cut2) {
        sum += x2;
        n += 1;
    }
    if n == 0 {
        return start;
    }
    (sum / n as f64).sqrt() / TRUNCATED_RMS_3
}

/// Sines of the bearing differences of a scan: `one[i] = sin(phi_i - phi_{i-1})` and
/// `two[i] = sin(phi_{i+1} - phi_{i-1})`, as `s_j c_i - c_j s_i` (no sines per triple).
#[derive(Default)]
struct BearingSteps {
    one: Vec<f64>,
    two: Vec<f64>,
}

impl BearingSteps {
    /// From the `(sin, cos)` of each bearing.
    fn new(sc: &[(f64, f64)]) -> Self {
        let sin_diff = |a: &(f64, f64), b: &(f64, f64)| b.0 * a.1 - b.1 * a.0;
        // Zero where a bearing has no neighbour on a side.
        let (mut one, mut two) = (vec![0.0; sc.len()], vec![0.0; sc.len()]);
        for (x, w) in one.iter_mut().skip(1).zip(sc.windows(2)) {
            *x = sin_diff(&w[0], &w[1]);
        }
        for (x, w) in two.iter_mut().skip(1).zip(sc.windows(3)) {
            *x = sin_diff(&w[0], &w[2]);
        }
        Self { one, two }
    }
}

/// Appends e^2 / Var(e) at sigma = 1, as bits (all are non-negative), for every triple of
/// consecutive valid rays, and the middle ray's range to `ranges`. `inverse` is scratch space
/// for the rays' `(1 / r, 1 / r^4)`.
fn standardised_residuals(
    s: &Scan,
    steps: &BearingSteps,
    inverse: &mut Vec<(f64, f64)>,
    out: &mut Vec<u64>,
    ranges: &mut Vec<f64>,
) {
    let n = s.nrays().min(steps.one.len());
    inverse.clear();
    // A ray without a return is NaN: every triple holding it gets a NaN `e`, which the
    // finiteness test below drops, as skipping the triple would.
    inverse.extend(s.ranges().take(n).map(|r| match r {
        Some(r) => {
            let u = 1.0 / r;
            (u, u.powi(4))
        }
        None => (f64::NAN, f64::NAN),
    }));
    if inverse.len() < 3 {
        return;
    }
    // Triple i (rays i - 1, i, i + 1, for i in 1..n - 1) uses one[i], one[i + 1] and two[i].
    let steps = steps.one[1..].windows(2).zip(&steps.two[1..]);
    for (w, (one, &sab)) in inverse.windows(3).zip(steps) {
        let ((u0, q0), (u1, q1), (u2, q2)) = (w[0], w[1], w[2]);
        let (sa, sb) = (one[0], one[1]);
        let e = sb * u0 + sa * u2 - sab * u1;
        let var = sb * sb * q0 + sa * sa * q2 + sab * sab * q1;
        // Squared, which spares a square root per triple: the median's element and the
        // trimmed sum come out the same. Non-negative and not NaN (as `trimmed_sigma`'s median needs).
        let z2 = e * e / var;
        if var > 0.0 && z2.is_finite() {
            out.push(z2.to_bits());
            ranges.push(1.0 / u1);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_distr::{Distribution, Normal};

    /// A level scan of the wall x = d (ranges d / cos phi), with Gaussian range noise.
    fn wall_scan(d: f64, sigma: f64, seed: u64) -> Scan {
        let mut s = Scan::with_even_bearings(121, -1.0, 1.0);
        let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(seed);
        let noise = Normal::new(0.0, sigma.max(1e-300)).unwrap();
        for i in 0..s.nrays() {
            let r = d / s.theta[i].cos()
                + if sigma > 0.0 {
                    noise.sample(&mut rng)
                } else {
                    0.0
                };
            // A corner every 30 rays: the median must shrug it off.
            let r = if i % 30 == 0 {
                r * rng.random_range(1.1..1.5)
            } else {
                r
            };
            s.readings[i] = Some(r);
            s.valid[i] = true;
        }
        s
    }

    #[test]
    fn a_stated_noise_is_believed_within_a_factor_of_three_of_the_scatter() {
        assert!(stated_is_believable(0.05, Some(0.05)));
        assert!(stated_is_believable(0.03, Some(0.01)));
        assert!(stated_is_believable(0.01, Some(0.03)));
        assert!(!stated_is_believable(0.031, Some(0.01)));
        assert!(!stated_is_believable(0.01, Some(0.031)));
        assert!(!stated_is_believable(1.0, Some(0.01)));
        assert!(!stated_is_believable(0.0, Some(0.01)));
        // Nothing to test it against.
        assert!(stated_is_believable(1.0, None));
    }

    /// Scans that state their true noise are believed; a converter's placeholder of 1 m (or 0)
    /// on the same ranges is not, nor is anything on scans that state nothing.
    #[test]
    fn believed_range_sigma_sets_placeholders_aside() {
        let stating = |sigma: f64, stated: f64| -> Vec<Scan> {
            (0..3)
                .map(|k| {
                    let mut s = wall_scan(3.0, sigma, k);
                    s.readings_sigma = Some(vec![Some(stated); s.nrays()]);
                    s
                })
                .collect()
        };
        assert_eq!(believed_range_sigma(&stating(0.01, 0.01)), Some(0.01));
        assert_eq!(believed_range_sigma(&stating(0.05, 0.05)), Some(0.05));
        assert_eq!(believed_range_sigma(&stating(0.01, 1.0)), None);
        assert_eq!(believed_range_sigma(&stating(0.05, 0.0)), None);
        let unstated: Vec<Scan> = (0..3).map(|k| wall_scan(3.0, 0.01, k)).collect();
        assert_eq!(believed_range_sigma(&unstated), None);
    }

    #[test]
    fn noise_estimate_recovers_one_and_ten_centimetres() {
        for &sigma in &[0.01, 0.1] {
            let scans: Vec<Scan> = (0..5).map(|k| wall_scan(3.0, sigma, k)).collect();
            let est = estimate_range_sigma(&scans).unwrap();
            assert!(
                (est / sigma - 1.0).abs() < 0.15,
                "sigma {sigma} estimated {est}"
            );
        }
    }

    /// Over 200 poses of five wall scans with a corner every 30 rays (a tenth of the triples
    /// are outliers), the estimate is within 3.5% on average and varies by under 5.5% from pose
    /// to pose (measured +2.3% and 5.0%; the MAD alone gave +12.4% and 6.5%).
    #[test]
    fn noise_estimate_is_unbiased_and_steady() {
        let sigma = 0.05;
        let ratios: Vec<f64> = (0..200u64)
            .map(|p| {
                let scans: Vec<Scan> = (0..5).map(|k| wall_scan(3.0, sigma, 10 * p + k)).collect();
                estimate_range_sigma(&scans).unwrap() / sigma
            })
            .collect();
        let n = ratios.len() as f64;
        let mean = ratios.iter().sum::<f64>() / n;
        let sd = (ratios.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        assert!((mean - 1.0).abs() < 0.035, "mean {mean}");
        assert!(sd < 0.055, "sd {sd}");
    }

    /// Noise that grows with range is taken at the farther half's level: a wall 1 m away at
    /// 1 cm and one 6 m away at 6 cm give about 6 cm (the pooled estimate, under 3 cm, made
    /// the far wall's fit overconfident); the same walls at 3 cm each give 3 cm.
    #[test]
    fn noise_growing_with_range_is_taken_at_the_far_half() {
        let scans = |near: f64, far: f64| -> Vec<Scan> {
            (0..3)
                .map(|k| wall_scan(1.0, near, k))
                .chain((0..3).map(|k| wall_scan(6.0, far, 10 + k)))
                .collect()
        };
        let est = estimate_range_sigma(&scans(0.01, 0.06)).unwrap();
        assert!((est / 0.06 - 1.0).abs() < 0.15, "estimated {est}");
        let est = estimate_range_sigma(&scans(0.03, 0.03)).unwrap();
        assert!((est / 0.03 - 1.0).abs() < 0.15, "estimated {est}");
    }

    #[test]
    fn noise_estimate_is_zero_without_noise() {
        let est = estimate_range_sigma(&[wall_scan(2.0, 0.0, 1)]).unwrap();
        assert!(est < 1e-9, "{est}");
    }

    /// The estimate as first written: each triple checked for three valid rays, sines per
    /// triple from the bearings, a median by `total_cmp`, then the same trimmed RMS, over all
    /// triples and over those nearer and farther than their median range.
    fn estimate_by_triples(scans: &[Scan]) -> Option<f64> {
        let (mut z, mut ranges) = (Vec::new(), Vec::new());
        for s in scans {
            let sc: Vec<(f64, f64)> = s.theta.iter().map(|t| t.sin_cos()).collect();
            let sin_diff = |i: usize, j: usize| sc[j].0 * sc[i].1 - sc[j].1 * sc[i].0;
            let inv = |i: usize| s.range(i).map(|r| (1.0 / r, (1.0 / r).powi(4)));
            for i in 1..s.nrays().saturating_sub(1) {
                let (Some((u0, q0)), Some((u1, q1)), Some((u2, q2))) =
                    (inv(i - 1), inv(i), inv(i + 1))
                else {
                    continue;
                };
                let (sa, sb, sab) = (
                    sin_diff(i - 1, i),
                    sin_diff(i, i + 1),
                    sin_diff(i - 1, i + 1),
                );
                let e = sb * u0 + sa * u2 - sab * u1;
                let var = sb * sb * q0 + sa * sa * q2 + sab * sab * q1;
                if var > 0.0 && e.is_finite() {
                    z.push(e.abs() / var.sqrt());
                    ranges.push(1.0 / u1);
                }
            }
        }
        if z.len() < 20 {
            return None;
        }
        let sigma = |z: &mut [f64]| {
            let mid = z.len() / 2;
            let (_, m, _) = z.select_nth_unstable_by(mid, f64::total_cmp);
            let mad = *m * MAD_TO_SIGMA;
            trimmed_rms(z.iter().map(|x| x * x), mad)
        };
        let mad = {
            let mut all = z.clone();
            let mid = all.len() / 2;
            *all.select_nth_unstable_by(mid, f64::total_cmp).1 * MAD_TO_SIGMA
        };
        let squared: Vec<u64> = z.iter().map(|x| (x * x).to_bits()).collect();
        let halves = looks_heteroscedastic(&squared, &ranges, mad)
            .then(|| split_at_median_range(&z, &ranges))
            .flatten()
            .map(|(mut near, mut far)| (sigma(&mut near), sigma(&mut far)));
        Some(far_if_noisier(sigma(&mut z), halves))
    }

    /// Scans with invalid rays, exact zeros (noise-free walls), bearing sets shared or not and
    /// too few rays: the same estimate as checking every triple.
    #[test]
    fn noise_estimate_matches_checking_every_triple() {
        let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(3);
        for case in 0..200 {
            let nscans = rng.random_range(1..6);
            let scans: Vec<Scan> = (0..nscans)
                .map(|k| {
                    let mut s =
                        wall_scan(rng.random_range(0.5..5.0), [0.0, 0.01, 0.1][case % 3], k);
                    let drop = rng.random::<f64>() * 0.5;
                    for i in 0..s.nrays() {
                        if rng.random::<f64>() < drop {
                            s.valid[i] = false;
                        }
                    }
                    if case % 7 == 0 && k % 2 == 1 {
                        s.theta.iter_mut().for_each(|t| *t *= 0.9);
                    }
                    if case % 11 == 0 {
                        s.theta.truncate(2 + k as usize);
                        s.readings.truncate(2 + k as usize);
                        s.valid.truncate(2 + k as usize);
                    }
                    s
                })
                .collect();
            // The same triples and median; the trimmed sum may add in another order.
            let same = |a: Option<f64>, b: Option<f64>| match (a, b) {
                (Some(a), Some(b)) => (a - b).abs() <= 1e-12 * b.abs(),
                (a, b) => a.is_none() && b.is_none(),
            };
            let slow = estimate_by_triples(&scans);
            let fast = estimate_range_sigma(&scans);
            assert!(same(fast, slow), "case {case}: {fast:?} {slow:?}");
            let trig = crate::level::grid::BearingTrigCache::default().shared(&scans);
            let shared = estimate_range_sigma_with(&scans, trig.as_deref());
            assert!(
                same(shared, slow),
                "case {case}, shared bearings {}: {shared:?} {slow:?}",
                trig.is_some()
            );
        }
    }
}
