//! One cell of Table I for one estimator: its poses' outcomes pooled into statistics.

use super::efficiency::{AxisRecord, Efficiency};
use super::paper_mean;
use super::pose::PoseOutcome;
use crate::eval::metrics::{median, nearest_rank};
use crate::eval::true_segments::TrueSegmentsFit;
use crate::level::Estimator;
use std::collections::BTreeMap;

/// Statistics of one cell of Table I for one estimator.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct CellStats {
    pub scans: usize,
    /// The noise figure \[m\] (a sigma, or a uniform width: the run's noise model).
    pub noise: f64,
    pub estimator: String,
    pub poses: usize,
    pub leveled: usize,
    pub leveled_fraction: f64,
    /// Mean, median, 95th percentile and maximum error over leveled poses \[deg\].
    pub mean_deg: f64,
    /// Root mean square of the leveled poses' errors \[deg\]: what large errors weigh in.
    pub rms_deg: f64,
    pub median_deg: f64,
    pub p95_deg: f64,
    pub max_deg: f64,
    /// Leveled poses with an error above 5 degrees.
    pub wrong_over_5_deg: usize,
    /// How many leveled poses honest sigmas put above 5 degrees: the sum over them of
    /// [`chance_over`] 5 degrees at their reported sigmas. `wrong_over_5_deg` well above it
    /// means errors in a tail heavier than the sigmas say (docs/ESTIMATOR.md, section 6).
    pub expected_over_5_deg: f64,
    /// Fraction of leveled poses whose error lies within 3 reported sigmas.
    pub within_3_sigma: f64,
    /// Phantom pseudo-level points (farther than `phantom_distance` from every wall) over all
    /// valid pseudo-level points (leveled poses).
    pub phantom_rate: f64,
    /// Pseudo-level points whose ray met the floor or ceiling (the simulator's labels) over
    /// all valid pseudo-level points (leveled poses).
    pub floor_kept_rate: f64,
    /// Valid pseudo-level points over wall hits of each pose's best scan (leveled poses).
    pub coverage: f64,
    /// Where coverage goes: the base scan's wall hits over the best scan's ...
    pub base_wall_share: f64,
    /// ... and the base scan's wall hits kept in the pseudo-level scan over its wall hits ...
    pub walls_kept_rate: f64,
    /// ... and of those it left out, the share within `LOW_BAND` of the floor or ceiling.
    pub walls_dropped_low_share: f64,
    /// The paper's mean for this cell \[deg\], when it has one.
    pub paper_mean_deg: Option<f64>,
    /// Median over all poses of the larger Cramér-Rao bound on the attitude \[deg\]: what no
    /// leveler can beat ([`crate::eval::bound`]).
    pub bound_median_deg: f64,
    /// Poses whose bound lies within the leveling gate (`max_sigma`): the most a leveler with
    /// honest sigmas and that gate could level.
    pub bound_within_gate: f64,
    /// Poses whose sigma from the true segmentation lies within the leveling gate: what this
    /// estimator could level if it found every surface and nothing else.
    pub segmented_within_gate: f64,
    /// The estimator's efficiency over its leveled poses ([`Efficiency`]).
    #[serde(flatten)]
    pub efficiency: Efficiency,
    /// The maximum-likelihood core told the true segmentation, over every pose it fixes up
    /// at (the same for every estimator of a cell).
    pub true_segments_ml: Efficiency,
    /// Poses whose maximum-likelihood sigma on the true segmentation lies within the gate.
    pub true_segments_ml_within_gate: f64,
    /// The leveler's last stage told the true segmentation (relabelled and widened by its
    /// rivals as on the leveler's own), over every pose it fixes up at: what the stage's rules
    /// cost where the segmentation is right.
    pub true_segments_last_stage: Efficiency,
    /// Poses whose last-stage sigma on the true segmentation lies within the gate.
    pub true_segments_last_stage_within_gate: f64,
    /// Failed poses by reason.
    pub failures: BTreeMap<String, usize>,
    /// Every leveled pose's error \[deg\], in pose order (for histograms).
    pub errors_deg: Vec<f64>,
    /// Every pose's outcome, in pose order (written apart, as `poses.jsonl`).
    #[serde(skip)]
    pub outcomes: Vec<PoseOutcome>,
}

/// The chance that the paper's error `max(|e_x|, |e_y|)` exceeds `limit` when the two angle
/// errors are independent Gaussians of sigmas `sigmas` (same unit as `limit`).
fn chance_over(limit: f64, sigmas: [f64; 2]) -> f64 {
    let outside = |s: f64| {
        if s > 0.0 {
            erfc(limit / (s * std::f64::consts::SQRT_2))
        } else {
            0.0
        }
    };
    1.0 - (1.0 - outside(sigmas[0])) * (1.0 - outside(sigmas[1]))
}

/// The complementary error function for `x >= 0`, by the Chebyshev fit of Press et al.,
/// *Numerical Recipes* (2nd ed., 1992), sect. 6.2: relative error below 1.2e-7 everywhere, so
/// the far tails that a sum over many poses adds up stay right too.
fn erfc(x: f64) -> f64 {
    const C: [f64; 10] = [
        -1.26551223,
        1.00002368,
        0.37409196,
        0.09678418,
        -0.18628806,
        0.27886807,
        -1.13520398,
        1.48851587,
        -0.82215223,
        0.17087277,
    ];
    let t = 1.0 / (1.0 + 0.5 * x);
    let poly = C.iter().rev().fold(0.0, |acc, c| c + t * acc);
    t * (-x * x + poly).exp()
}

fn ratio(a: usize, b: usize) -> f64 {
    if b == 0 {
        f64::NAN
    } else {
        a as f64 / b as f64
    }
}

fn sorted_copy(v: &[f64]) -> Vec<f64> {
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    v
}

/// How many poses failed for each reason, by the reason's name.
fn failure_counts(o: &[&PoseOutcome]) -> BTreeMap<String, usize> {
    let mut failures = BTreeMap::new();
    for p in o {
        if let Some(f) = p.failure {
            *failures.entry(f.as_str().to_string()).or_insert(0) += 1;
        }
    }
    failures
}

pub(crate) fn cell_stats(
    scans: usize,
    noise: f64,
    estimator: Estimator,
    gate_deg: f64,
    o: &[&PoseOutcome],
) -> CellStats {
    let errors: Vec<f64> = o.iter().filter_map(|p| p.error_deg).collect();
    let sorted = sorted_copy(&errors);
    let n = sorted.len();
    let bounds: Vec<f64> = o.iter().filter_map(|p| p.bound_deg).collect();
    let segmented: Vec<f64> = o.iter().filter_map(|p| p.segmented_deg).collect();
    // The larger sigma of a fit on the true segmentation, per pose with a bound.
    let fit_sigmas = |fit: fn(&PoseOutcome) -> Option<TrueSegmentsFit>| -> Vec<f64> {
        o.iter()
            .filter(|p| p.bound_deg.is_some())
            .map(|p| fit(p).map_or(f64::INFINITY, |f| f.sigmas[0].max(f.sigmas[1]).to_degrees()))
            .collect()
    };
    let ml_sigmas = fit_sigmas(|p| p.true_segments);
    let last_stage_sigmas = fit_sigmas(|p| p.true_segments_last_stage);
    let leveled: Vec<&&PoseOutcome> = o.iter().filter(|p| p.error_deg.is_some()).collect();
    let sum = |f: fn(&PoseOutcome) -> usize| leveled.iter().map(|p| f(p)).sum::<usize>();
    let valid = sum(|p| p.pseudo_valid);
    let within_gate = |sigmas: &[f64]| {
        ratio(
            sigmas.iter().filter(|&&s| s <= gate_deg).count(),
            sigmas.len(),
        )
    };
    let records = |f: fn(&PoseOutcome) -> Option<AxisRecord>| -> Vec<AxisRecord> {
        o.iter().filter_map(|p| f(p)).collect()
    };
    CellStats {
        scans,
        noise,
        estimator: estimator.to_string(),
        poses: o.len(),
        leveled: n,
        leveled_fraction: ratio(n, o.len()),
        mean_deg: if n == 0 {
            f64::NAN
        } else {
            errors.iter().sum::<f64>() / n as f64
        },
        rms_deg: if n == 0 {
            f64::NAN
        } else {
            (errors.iter().map(|e| e * e).sum::<f64>() / n as f64).sqrt()
        },
        median_deg: median(&sorted),
        p95_deg: nearest_rank(&sorted, 0.95),
        max_deg: sorted.last().copied().unwrap_or(f64::NAN),
        wrong_over_5_deg: errors.iter().filter(|&&e| e > 5.0).count(),
        expected_over_5_deg: leveled
            .iter()
            .filter_map(|p| p.sigmas_deg)
            .map(|s| chance_over(5.0, s))
            .sum(),
        within_3_sigma: ratio(leveled.iter().filter(|p| p.within_3_sigma).count(), n),
        phantom_rate: ratio(sum(|p| p.phantoms), valid),
        floor_kept_rate: ratio(sum(|p| p.floor_kept), valid),
        coverage: ratio(valid, sum(|p| p.best_wall_hits)),
        base_wall_share: ratio(sum(|p| p.base_wall_hits), sum(|p| p.best_wall_hits)),
        walls_kept_rate: ratio(sum(|p| p.walls_kept), sum(|p| p.base_wall_hits)),
        walls_dropped_low_share: ratio(
            sum(|p| p.walls_dropped_low),
            sum(|p| p.base_wall_hits) - sum(|p| p.walls_kept),
        ),
        paper_mean_deg: paper_mean(scans, noise),
        bound_median_deg: median(&sorted_copy(&bounds)),
        bound_within_gate: within_gate(&bounds),
        segmented_within_gate: within_gate(&segmented),
        efficiency: Efficiency::of(&records(AxisRecord::of_leveled)),
        true_segments_ml: Efficiency::of(&records(AxisRecord::of_true_segments)),
        true_segments_ml_within_gate: within_gate(&ml_sigmas),
        true_segments_last_stage: Efficiency::of(&records(AxisRecord::of_true_segments_last_stage)),
        true_segments_last_stage_within_gate: within_gate(&last_stage_sigmas),
        failures: failure_counts(o),
        errors_deg: errors,
        outcomes: o.iter().map(|&p| p.clone()).collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::true_segments::TrueSegmentsFit;
    use crate::level::FailReason;

    /// erfc against known values (Abramowitz and Stegun, table 7.1), and the chance of the
    /// max-axis error against its closed form for one axis.
    #[test]
    fn erfc_and_chance_over_on_known_values() {
        for (x, want) in [
            (0.0, 1.0),
            (0.5, 0.479_500_122_186_953_5),
            (1.0, 0.157_299_207_050_285_1),
            (2.0, 0.004_677_734_981_047_266),
            (3.0, 2.209_049_699_858_544e-5),
            (5.0, 1.537_459_794_428_035e-12),
        ] {
            let got = erfc(x);
            assert!(
                (got / want - 1.0).abs() < 2e-7,
                "erfc({x}) = {got}, want {want}"
            );
        }
        // One axis with no spread: the other axis's two-sided tail, 2 Phi(-k).
        let k2 = chance_over(2.0, [1.0, 0.0]);
        assert!((k2 - 0.045_500_263_896_358_42).abs() < 1e-8, "{k2}");
        // Two equal axes: 1 - (1 - p)^2.
        let p = erfc(2.0 / std::f64::consts::SQRT_2);
        assert!((chance_over(2.0, [1.0, 1.0]) - (1.0 - (1.0 - p) * (1.0 - p))).abs() < 1e-15);
    }

    #[test]
    fn cell_stats_on_known_errors() {
        let mk = |e: Option<f64>| PoseOutcome {
            estimate_deg: e.map(|x| [x, 0.0]),
            failure: if e.is_none() {
                Some(FailReason::ParallelWalls)
            } else {
                None
            },
            error_deg: e,
            within_3_sigma: e.is_some_and(|x| x < 2.0),
            pseudo_valid: 10,
            phantoms: 1,
            floor_kept: 2,
            walls_kept: 8,
            best_wall_hits: 20,
            base_wall_hits: 16,
            walls_dropped_low: 4,
            sigmas_deg: e.map(|x| [x / 2.0, x / 4.0]),
            sigma_deg: e.map(|x| x / 2.0),
            bound_deg: Some(if e.is_none() { f64::INFINITY } else { 0.25 }),
            efficient_over_bound: e.map(|_| 0.8),
            segmented_deg: Some(if e == Some(1.0) { 0.5 } else { 2.0 }),
            true_segments: Some(TrueSegmentsFit {
                attitude: [0.01, 0.0],
                sigmas: [0.02, 0.01],
                inflation: 1.0,
                converged: true,
            }),
            // The last stage: sigma 2 degrees (beyond the gate) on the pose with error 3.
            true_segments_last_stage: Some(TrueSegmentsFit {
                attitude: [0.0, -0.02],
                sigmas: [
                    if e == Some(3.0) {
                        2f64.to_radians()
                    } else {
                        0.02
                    },
                    0.01,
                ],
                inflation: 1.0,
                converged: true,
            }),
            ..PoseOutcome::default()
        };
        let outcomes = [mk(Some(1.0)), mk(Some(3.0)), mk(None), mk(Some(6.0))];
        let refs: Vec<&PoseOutcome> = outcomes.iter().collect();
        let s = cell_stats(3, 0.01, Estimator::Robust, 1.5, &refs);
        assert_eq!(s.leveled, 3);
        assert!((s.mean_deg - 10.0 / 3.0).abs() < 1e-12);
        assert!((s.rms_deg - (46.0f64 / 3.0).sqrt()).abs() < 1e-12);
        assert_eq!(s.median_deg, 3.0);
        assert_eq!(s.max_deg, 6.0);
        assert_eq!(s.wrong_over_5_deg, 1);
        // Sigmas (0.5, 0.25), (1.5, 0.75), (3, 1.5): 5 degrees is 10, 3.33 and 1.67 x-sigmas.
        let expected = chance_over(5.0, [0.5, 0.25])
            + chance_over(5.0, [1.5, 0.75])
            + chance_over(5.0, [3.0, 1.5]);
        assert!((s.expected_over_5_deg - expected).abs() < 1e-12);
        assert_eq!(s.failures.get("parallel_walls"), Some(&1));
        assert!((s.phantom_rate - 0.1).abs() < 1e-12);
        assert!((s.floor_kept_rate - 0.2).abs() < 1e-12);
        assert!((s.coverage - 0.5).abs() < 1e-12);
        assert!((s.base_wall_share - 0.8).abs() < 1e-12);
        assert!((s.walls_kept_rate - 0.5).abs() < 1e-12);
        assert!((s.walls_dropped_low_share - 0.5).abs() < 1e-12);
        // Bounds 0.25, 0.25, inf, 0.25: three of four within the gate.
        assert_eq!(s.bound_median_deg, 0.25);
        assert!((s.bound_within_gate - 0.75).abs() < 1e-12);
        // From the true segmentation 0.5, 2, 2, 2: one of four.
        assert!((s.segmented_within_gate - 0.25).abs() < 1e-12);
        // Errors 1, 3, 6 and sigmas 0.5, 1.5, 3.0 over 0.25; x errors at 2 sigmas, y at 0.
        let e = &s.efficiency;
        assert_eq!(e.efficiency_poses, 3);
        assert!((e.error_over_bound - 12.0).abs() < 1e-12);
        assert!((e.sigma_over_bound - 6.0).abs() < 1e-12);
        assert_eq!(e.efficient_over_bound, 0.8);
        assert_eq!(e.within_sigma[0], [0.0, 1.0]);
        assert_eq!(e.within_sigma[1], [1.0, 1.0]);
        // The core on true segments: three poses with a finite bound; its error 0.01 rad.
        let ml = &s.true_segments_ml;
        assert_eq!(ml.efficiency_poses, 3);
        let err = 0.01f64.to_degrees();
        assert!((ml.error_over_bound - err / 0.25).abs() < 1e-9);
        assert!((s.true_segments_ml_within_gate - 1.0).abs() < 1e-12);
        // The last stage: its error 0.02 rad in y; three of the four within the gate.
        let last = &s.true_segments_last_stage;
        assert_eq!(last.efficiency_poses, 3);
        assert!((last.error_over_bound - 2.0 * err / 0.25).abs() < 1e-9);
        assert!((s.true_segments_last_stage_within_gate - 0.75).abs() < 1e-12);
    }
}
