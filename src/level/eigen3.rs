//! Closed-form eigen decomposition of symmetric 3x3 matrices: every plane fit and every up
//! estimate needs one, thousands of times per second. Eigenvalues by the trigonometric
//! solution of the characteristic cubic (Smith 1961), eigenvectors as the best-conditioned
//! cross product of two rows of `A - lambda I`. Falls back to nalgebra's iterative solver when
//! two eigenvalues (nearly) coincide, where the cross products lose their accuracy.

use nalgebra::{Matrix3, SymmetricEigen, Vector3};

/// Eigenvalues in ascending order and their unit eigenvectors (`vectors[k]` for `values[k]`).
#[derive(Clone, Copy, Debug)]
pub struct Eigen3 {
    pub values: [f64; 3],
    pub vectors: [Vector3<f64>; 3],
}

/// Decomposes a symmetric matrix (only its upper triangle is read).
pub fn sym_eigen3(a: &Matrix3<f64>) -> Eigen3 {
    // Over the storage slice (column-major, the order `a.iter()` visits): no iterator adaptor.
    let scale = a.as_slice().iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if scale == 0.0 || !scale.is_finite() {
        return fallback(a);
    }
    let m = a / scale;
    let (a00, a01, a02, a11, a12, a22) = (
        m[(0, 0)],
        m[(0, 1)],
        m[(0, 2)],
        m[(1, 1)],
        m[(1, 2)],
        m[(2, 2)],
    );
    let p1 = a01 * a01 + a02 * a02 + a12 * a12;
    let q = (a00 + a11 + a22) / 3.0;
    let p2 = (a00 - q).powi(2) + (a11 - q).powi(2) + (a22 - q).powi(2) + 2.0 * p1;
    let p = (p2 / 6.0).sqrt();
    if p < 1e-9 {
        return fallback(a);
    }
    let b = (m - Matrix3::identity() * q) / p;
    let r = (b.determinant() / 2.0).clamp(-1.0, 1.0);
    let phi = r.acos() / 3.0;
    let two_pi_3 = 2.0 * std::f64::consts::PI / 3.0;
    let l_max = q + 2.0 * p * phi.cos();
    let l_min = q + 2.0 * p * (phi + two_pi_3).cos();
    let l_mid = 3.0 * q - l_max - l_min;
    // Well separated eigenvalues give accurate cross products; otherwise iterate.
    let gap = (l_mid - l_min).min(l_max - l_mid);
    if gap < 1e-6 * p {
        return fallback(a);
    }
    let (Some(v_min), Some(v_max)) = (null_vector(&m, l_min), null_vector(&m, l_max)) else {
        return fallback(a);
    };
    let v_mid = v_max.cross(&v_min);
    Eigen3 {
        values: [l_min * scale, l_mid * scale, l_max * scale],
        vectors: [v_min, v_mid, v_max],
    }
}

/// A unit vector spanning the null space of `m - l I` (the largest cross product of its rows).
fn null_vector(m: &Matrix3<f64>, l: f64) -> Option<Vector3<f64>> {
    let s = m - Matrix3::identity() * l;
    let (r0, r1, r2) = (
        s.row(0).transpose(),
        s.row(1).transpose(),
        s.row(2).transpose(),
    );
    let c = [r0.cross(&r1), r0.cross(&r2), r1.cross(&r2)];
    // Each length once; `max_by` keeps the last of equal lengths.
    let len2 = c.map(|v| v.norm_squared());
    let best = (0..3).max_by(|&i, &j| len2[i].total_cmp(&len2[j]))?;
    c[best].try_normalize(1e-150)
}

fn fallback(a: &Matrix3<f64>) -> Eigen3 {
    let e = SymmetricEigen::new(*a);
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

    fn check(a: &Matrix3<f64>) {
        let e = sym_eigen3(a);
        let twin = fallback(a);
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
    }
}
