//! Small dense linear algebra: the eigen-decomposition of symmetric 3x3 matrices.

use glam::{DMat3, DVec3};

/// Eigenvalues (decreasing) and unit eigenvectors (as matching columns) of the symmetric
/// matrix `m`, by cyclic Jacobi rotations (accurate to rounding for 3x3).
pub(crate) fn sym_eigen(m: DMat3) -> ([f64; 3], [DVec3; 3]) {
    let mut a = m.to_cols_array_2d(); // a[col][row]; symmetric, so a[i][j] = a[j][i]
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]; // columns
    for _ in 0..50 {
        let off = a[0][1].powi(2) + a[0][2].powi(2) + a[1][2].powi(2);
        let scale = a[0][0].powi(2) + a[1][1].powi(2) + a[2][2].powi(2) + off;
        if off <= 1e-30 * scale || off == 0.0 {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q] == 0.0 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let t = if theta == 0.0 { 1.0 } else { t };
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            // A <- J^T A J with J the rotation in the (p, q) plane.
            for k in 0..3 {
                let (akp, akq) = (a[k][p], a[k][q]);
                a[k][p] = c * akp - s * akq;
                a[k][q] = s * akp + c * akq;
            }
            for k in 0..3 {
                let (apk, aqk) = (a[p][k], a[q][k]);
                a[p][k] = c * apk - s * aqk;
                a[q][k] = s * apk + c * aqk;
            }
            for row in &mut v {
                let (vp, vq) = (row[p], row[q]);
                row[p] = c * vp - s * vq;
                row[q] = s * vp + c * vq;
            }
        }
    }
    // v[row][col]: eigenvector j is column j.
    let mut pairs: Vec<(f64, DVec3)> =
        (0..3).map(|j| (a[j][j], DVec3::new(v[0][j], v[1][j], v[2][j]).normalize_or_zero())).collect();
    pairs.sort_by(|x, y| y.0.total_cmp(&x.0));
    ([pairs[0].0, pairs[1].0, pairs[2].0], [pairs[0].1, pairs[1].1, pairs[2].1])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reconstructs_a_symmetric_matrix() {
        let m = DMat3::from_cols(
            DVec3::new(4.0, 1.0, -2.0),
            DVec3::new(1.0, 3.0, 0.5),
            DVec3::new(-2.0, 0.5, 1.0),
        );
        let (vals, vecs) = sym_eigen(m);
        assert!(vals[0] >= vals[1] && vals[1] >= vals[2]);
        for k in 0..3 {
            let r = m * vecs[k] - vals[k] * vecs[k];
            assert!(r.length() < 1e-10, "{k}: {r}");
        }
        assert!((vals.iter().sum::<f64>() - 8.0).abs() < 1e-10);
        let (d, _) = sym_eigen(DMat3::from_diagonal(DVec3::new(1.0, 5.0, 2.0)));
        assert_eq!(d, [5.0, 2.0, 1.0]);
    }
}
