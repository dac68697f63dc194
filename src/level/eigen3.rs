//! Closed-form eigen decomposition of symmetric 3x3 matrices: every plane fit and every up
//! estimate needs one, thousands of times per second. Eigenvalues by the trigonometric solution
//! of the characteristic cubic (Smith 1961); eigenvectors as the best-conditioned cross product
//! of two rows of `A - lambda I`. Falls back to nalgebra's iterative solver when two eigenvalues
//! (nearly) coincide, where the cross products lose their accuracy.

use nalgebra::{Matrix3, SymmetricEigen, Vector3};

/// Eigenvalues in ascending order and their unit eigenvectors (`vectors[k]` for `values[k]`).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Eigen3 {
    pub(crate) values: [f64; 3],
    pub(crate) vectors: [Vector3<f64>; 3],
}

/// Decomposes a symmetric matrix (only its upper triangle is read).
pub(crate) fn sym_eigen3(a: &Matrix3<f64>) -> Eigen3 {
    sym_eigen3_upper(&upper_triangle(a))
}

/// Row and column of each entry of a symmetric matrix's upper triangle as laid out here and in
/// the plane sums (xx, xy, xz, yy, yz, zz).
pub(crate) const UPPER_I: [usize; 6] = [0, 0, 0, 1, 1, 2];
pub(crate) const UPPER_J: [usize; 6] = [0, 1, 2, 1, 2, 2];

/// A matrix's upper triangle (xx, xy, xz, yy, yz, zz).
fn upper_triangle(a: &Matrix3<f64>) -> [f64; 6] {
    std::array::from_fn(|t| a[(UPPER_I[t], UPPER_J[t])])
}

/// [`sym_eigen3`] of the symmetric matrix with upper triangle `upper` (xx, xy, xz, yy, yz, zz).
pub(crate) fn sym_eigen3_upper(upper: &[f64; 6]) -> Eigen3 {
    let scale = upper.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if scale == 0.0 || !scale.is_finite() {
        return fallback(upper);
    }
    // Scaled to unit size so that the cubic's terms stay well inside the float range.
    let inv = 1.0 / scale;
    let m = upper.map(|v| v * inv);
    let Some([l_min, l_mid, l_max]) = eigenvalues_trig(&m) else {
        return fallback(upper);
    };
    // Well separated eigenvalues give accurate cross products; otherwise iterate.
    let gap = (l_mid - l_min).min(l_max - l_mid);
    if gap.is_nan() || gap < 1e-6 * (l_max - l_min) || l_max - l_min < 1e-9 {
        return fallback(upper);
    }
    let (Some(v_min), Some(v_max)) = (null_vector(&m, l_min), null_vector(&m, l_max)) else {
        return fallback(upper);
    };
    let v_mid = v_max.cross(&v_min);
    Eigen3 {
        values: [l_min * scale, l_mid * scale, l_max * scale],
        vectors: [v_min, v_mid, v_max],
    }
}

/// Ascending eigenvalues by the trigonometric solution of the characteristic cubic (Smith
/// 1961), for any symmetric matrix; `None` when it is (nearly) a multiple of the identity.
fn eigenvalues_trig(m: &[f64; 6]) -> Option<[f64; 3]> {
    let [a00, a01, a02, a11, a12, a22] = *m;
    let p1 = a01 * a01 + a02 * a02 + a12 * a12;
    let q = (a00 + a11 + a22) / 3.0;
    let (d0, d1, d2) = (a00 - q, a11 - q, a22 - q);
    let p2 = d0 * d0 + d1 * d1 + d2 * d2 + 2.0 * p1;
    let p = (p2 / 6.0).sqrt();
    if p < 1e-9 {
        return None;
    }
    // det((A - q I) / p) / 2 = cos(3 phi).
    let det =
        d0 * (d1 * d2 - a12 * a12) - a01 * (a01 * d2 - a12 * a02) + a02 * (a01 * a12 - d1 * a02);
    let r = (det / (2.0 * p * p * p)).clamp(-1.0, 1.0);
    let phi = r.acos() / 3.0;
    // cos(phi + 2 pi / 3) by the angle sum, with sin(phi) >= 0 for phi in [0, pi / 3].
    let c = phi.cos();
    let s = (1.0 - c * c).max(0.0).sqrt();
    let l_max = q + 2.0 * p * c;
    let l_min = q + 2.0 * p * (-0.5 * c - 0.5 * 3f64.sqrt() * s);
    Some([l_min, 3.0 * q - l_max - l_min, l_max])
}

/// A unit vector spanning the null space of `M - l I` (the largest cross product of its
/// rows), for `M`'s upper triangle `m` (xx, xy, xz, yy, yz, zz).
fn null_vector(m: &[f64; 6], l: f64) -> Option<Vector3<f64>> {
    let r0 = Vector3::new(m[0] - l, m[1], m[2]);
    let r1 = Vector3::new(m[1], m[3] - l, m[4]);
    let r2 = Vector3::new(m[2], m[4], m[5] - l);
    let c = [r0.cross(&r1), r0.cross(&r2), r1.cross(&r2)];
    let norms = c.map(|v| v.norm_squared());
    // The first of the largest.
    let best = (1..3).fold(0, |b, k| if norms[k] > norms[b] { k } else { b });
    c[best].try_normalize(1e-150)
}

fn fallback(u: &[f64; 6]) -> Eigen3 {
    let a = Matrix3::new(u[0], u[1], u[2], u[1], u[3], u[4], u[2], u[4], u[5]);
    let e = SymmetricEigen::new(a);
    let mut idx = [0usize, 1, 2];
    idx.sort_by(|&x, &y| e.eigenvalues[x].total_cmp(&e.eigenvalues[y]));
    Eigen3 {
        values: idx.map(|k| e.eigenvalues[k]),
        vectors: idx.map(|k| e.eigenvectors.column(k).into_owned()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// The decomposition against nalgebra's.
    fn check(a: &Matrix3<f64>) {
        let upper = upper_triangle(a);
        let e = sym_eigen3_upper(&upper);
        let twin = fallback(&upper);
        let scale = a.norm().max(1e-300);
        for k in 0..3 {
            assert!(
                (e.values[k] - twin.values[k]).abs() <= 1e-9 * scale,
                "{k}: {:?} {:?}",
                e.values,
                twin.values
            );
            let v = e.vectors[k];
            assert!((v.norm() - 1.0).abs() < 1e-9);
            // A v = lambda v.
            assert!((a * v - v * e.values[k]).norm() <= 1e-7 * scale, "{k}");
        }
    }

    #[test]
    fn diagonal_and_repeated_eigenvalues() {
        check(&Matrix3::from_diagonal(&Vector3::new(3.0, 1.0, 2.0)));
        check(&Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, 2.0)));
        check(&Matrix3::identity());
        check(&Matrix3::zeros());
    }

    proptest! {
        #[test]
        fn matches_nalgebra_on_random_scatter_matrices(
            v in proptest::collection::vec(-10.0f64..10.0, 9),
            flat in 1e-6f64..1.0,
        ) {
            // A scatter-like matrix: B^T B with one direction squashed (a plane).
            let b = Matrix3::from_row_slice(&v);
            let squash = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, flat));
            let a = b.transpose() * squash * b;
            check(&a);
        }

        #[test]
        fn matches_nalgebra_below_zero(
            v in proptest::collection::vec(-10.0f64..10.0, 9),
            d in proptest::collection::vec(-1.0f64..1.0, 3),
            k in 0.0f64..2.0,
        ) {
            // A plane's scatter minus a noise term k d d^T, as in a bias-corrected fit: its
            // smallest eigenvalue can be negative, but not below -k |d|^2.
            let b = Matrix3::from_row_slice(&v);
            let squash = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, 1e-3));
            let d = Vector3::from_row_slice(&d);
            let a = b.transpose() * squash * b - d * d.transpose() * k;
            check(&a);
        }
    }

    #[test]
    fn handles_a_negative_smallest_eigenvalue() {
        let a = Matrix3::from_diagonal(&Vector3::new(-0.25, 4.0, 9.0));
        let e = sym_eigen3_upper(&[-0.25, 0.0, 0.0, 4.0, 0.0, 9.0]);
        assert!((e.values[0] + 0.25).abs() < 1e-12, "{:?}", e.values);
        check(&a);
    }
}
