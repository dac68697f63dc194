//! The attitude's covariance when the points' errors are not independent: the cluster-robust
//! ("sandwich") covariance, and the reported covariance widened to cover it.
//!
//! The information matrix's inverse is the covariance when every point's residual is its own
//! Gaussian range noise. A few points the segmentation gave to the wrong surface (floor hits
//! at a wall's foot taken as wall, a ledge's edge) break that: their residuals are not noise
//! but one shared error, and together they pull the attitude by more than the information
//! matrix allows, while the chi-square test barely moves (a few dozen points among a
//! thousand). The sandwich `S^-1 B S^-1` measures the spread from the residuals themselves
//! (Huber 1967; White 1980), with `B` the outer products of the scores summed per cluster of
//! neighbouring points (Liang and Zeger 1986), so that errors shared along a stretch of one
//! surface count as one, not as many independent ones. Each point's score is its weighted
//! residual times its attitude Jacobian with its surface's placement eliminated (the Schur
//! complement's effective Jacobian, [`super::solve`]); on a right model the sandwich equals the
//! information's inverse on average, so it widens nothing then but its own sampling spread.

use super::evaluate::{Arrow, Ray, Score};
use crate::geometry::pseudo_inverse_2x2;
use nalgebra::{Matrix2, Vector2};

/// `B`: over clusters of at most `cluster_rays` consecutive rays of one surface (`rays` in
/// surface order, each surface's in input order, hence scan order), the outer product of the
/// cluster's summed scores, from the range residual's pass at one state: its normal equations
/// `arrow` and its rays' `scores` (one per ray). `None` when a surface's block cannot be
/// inverted.
pub(crate) fn clustered_meat(
    rays: &[Ray],
    scores: &[Score],
    arrow: &Arrow,
    cluster_rays: usize,
) -> Option<Matrix2<f64>> {
    assert_eq!(rays.len(), scores.len(), "one score per ray");
    let mut meat = Matrix2::zeros();
    let mut start = 0;
    for run in rays.chunk_by(|a, b| a.slot == b.slot) {
        let (h_as, h_ss, _) = &arrow.blocks[run[0].slot];
        // The placement's share of each point's attitude Jacobian: ja - T js.
        let t = h_as * pseudo_inverse_2x2(h_ss)?;
        let run_scores = &scores[start..start + run.len()];
        start += run.len();
        for cluster in run_scores.chunks(cluster_rays.max(1)) {
            let mut score = Vector2::zeros();
            for s in cluster {
                let effective = Vector2::from(s.by_attitude) - t * Vector2::from(s.by_placement);
                score += effective * s.weighted;
            }
            meat += score * score.transpose();
        }
    }
    Some(meat)
}

/// The smallest widening of `model` that covers `robust` in every direction: in the
/// coordinates where `model` is the identity, `robust`'s eigenvalues below 1 are raised to 1.
/// `model` itself when `robust` lies inside it, or when `model` is not positive definite.
pub(crate) fn widened(model: &Matrix2<f64>, robust: &Matrix2<f64>) -> Matrix2<f64> {
    let Some(chol) = model.cholesky() else {
        return *model;
    };
    let l = chol.l();
    let Some(l_inv) = l.try_inverse() else {
        return *model;
    };
    let whitened = l_inv * robust * l_inv.transpose();
    let eig = ((whitened + whitened.transpose()) * 0.5).symmetric_eigen();
    let mut cover = Matrix2::zeros();
    for i in 0..2 {
        let v = eig.eigenvectors.column(i);
        cover += v * v.transpose() * eig.eigenvalues[i].max(1.0);
    }
    let out = l * cover * l.transpose();
    (out + out.transpose()) * 0.5
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn spd(a: f64, b: f64, c: f64) -> Matrix2<f64> {
        // L L^T of a lower triangle with a positive diagonal.
        let l = Matrix2::new(a, 0.0, b, c);
        l * l.transpose()
    }

    /// Inside: unchanged. Larger in one direction of the model's own axes: that direction
    /// takes the robust variance, the other keeps the model's.
    #[test]
    fn widening_on_known_matrices() {
        let model = Matrix2::new(4.0, 0.0, 0.0, 1.0);
        assert_eq!(widened(&model, &(model * 0.5)), model);
        let out = widened(&model, &Matrix2::new(9.0, 0.0, 0.0, 0.25));
        assert!(
            (out - Matrix2::new(9.0, 0.0, 0.0, 1.0)).abs().max() < 1e-12,
            "{out}"
        );
        // Not positive definite: the model as it is.
        let flat = Matrix2::new(1.0, 1.0, 1.0, 1.0);
        assert_eq!(widened(&flat, &model), flat);
    }

    proptest! {
        /// The result covers both: `out - model` and `out - robust` are positive
        /// semi-definite, and it is no larger than their sum.
        #[test]
        fn widening_covers_both(
            a in 0.1f64..3.0, b in -2.0f64..2.0, c in 0.1f64..3.0,
            d in 0.1f64..3.0, e in -2.0f64..2.0, f in 0.0f64..3.0,
        ) {
            let model = spd(a, b, c);
            let robust = spd(d, e, f);
            let out = widened(&model, &robust);
            let scale = out.norm();
            for m in [out - model, out - robust, model + robust - out] {
                let low = m.symmetric_eigenvalues().min();
                prop_assert!(low >= -1e-9 * scale, "{m} ({low})");
            }
        }
    }
}
