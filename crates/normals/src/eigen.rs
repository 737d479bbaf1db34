//! Eigen-decomposition of small symmetric matrices (cyclic Jacobi).

use glam::{DMat3, DVec3};

/// Eigenvalues (ascending) and unit eigenvectors of the symmetric matrix `m`.
///
/// Cyclic Jacobi rotations: unconditionally stable, orthonormal eigenvectors to machine
/// precision, and a handful of sweeps for a 3 x 3 matrix.
pub(crate) fn symmetric_eigen(m: DMat3) -> ([f64; 3], [DVec3; 3]) {
    let mut a = m.to_cols_array_2d(); // a[col][row]; symmetric, so a[i][j] == a[j][i]
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]; // v[col][row]
    for _sweep in 0..32 {
        let off = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
        let diag = a[0][0] * a[0][0] + a[1][1] * a[1][1] + a[2][2] * a[2][2];
        if off <= 1e-34 * diag || off == 0.0 {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            let apq = a[p][q];
            if apq == 0.0 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * apq);
            let t = if theta.abs() > 1e150 {
                0.5 / theta
            } else {
                theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt())
            };
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            a[p][p] -= t * apq;
            a[q][q] += t * apq;
            a[p][q] = 0.0;
            a[q][p] = 0.0;
            let r = 3 - p - q;
            let (arp, arq) = (a[r][p], a[r][q]);
            a[r][p] = c * arp - s * arq;
            a[p][r] = a[r][p];
            a[r][q] = s * arp + c * arq;
            a[q][r] = a[r][q];
            for k in 0..3 {
                let (vkp, vkq) = (v[p][k], v[q][k]);
                v[p][k] = c * vkp - s * vkq;
                v[q][k] = s * vkp + c * vkq;
            }
        }
    }
    let mut order = [0usize, 1, 2];
    order.sort_by(|&i, &j| a[i][i].total_cmp(&a[j][j]));
    let values = order.map(|i| a[i][i]);
    let vectors = order.map(|i| DVec3::from_array(v[i]));
    (values, vectors)
}

/// The unit eigenvector of the smallest eigenvalue of the symmetric matrix `m`, in closed
/// form, when that eigenvalue is well separated: at least `1e-3` times the spectral
/// spread below the next one. `None` otherwise (ask [`symmetric_eigen`]).
///
/// Eigenvalues by the trigonometric formula (Smith 1961), the eigenvector as the largest
/// cross product of two rows of `m - lambda I`; its error is about `eps / gap`, so the
/// gap test keeps it near `1e-13`. About ten times faster than Jacobi rotations.
pub(crate) fn smallest_eigenvector(m: DMat3) -> Option<DVec3> {
    let a = m.to_cols_array_2d();
    let q = (a[0][0] + a[1][1] + a[2][2]) / 3.0;
    let p1 = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
    let (d0, d1, d2) = (a[0][0] - q, a[1][1] - q, a[2][2] - q);
    let p2 = d0 * d0 + d1 * d1 + d2 * d2 + 2.0 * p1;
    let p = (p2 / 6.0).sqrt();
    if p.is_nan() || p <= 0.0 {
        return None; // a multiple of the identity (or not finite)
    }
    // B = (m - q I) / p has eigenvalues 2 cos(phi + 2 k pi / 3).
    let b = |i: usize, j: usize| (a[i][j] - if i == j { q } else { 0.0 }) / p;
    let det = b(0, 0) * (b(1, 1) * b(2, 2) - b(1, 2) * b(2, 1))
        - b(0, 1) * (b(1, 0) * b(2, 2) - b(1, 2) * b(2, 0))
        + b(0, 2) * (b(1, 0) * b(2, 1) - b(1, 1) * b(2, 0));
    let phi = (det / 2.0).clamp(-1.0, 1.0).acos() / 3.0;
    let two_pi_3 = 2.0 * std::f64::consts::FRAC_PI_3;
    // Ascending: cos(phi + 2pi/3) <= cos(phi - 2pi/3) <= cos(phi) for phi in [0, pi/3].
    let (low, mid, high) = (2.0 * (phi + two_pi_3).cos(), 2.0 * (phi - two_pi_3).cos(), 2.0 * phi.cos());
    if mid - low < 1e-3 * (high - low) {
        return None;
    }
    let lambda = q + p * low;
    let rows = [
        DVec3::new(a[0][0] - lambda, a[1][0], a[2][0]),
        DVec3::new(a[0][1], a[1][1] - lambda, a[2][1]),
        DVec3::new(a[0][2], a[1][2], a[2][2] - lambda),
    ];
    let c = [rows[0].cross(rows[1]), rows[0].cross(rows[2]), rows[1].cross(rows[2])];
    let best = c.into_iter().max_by(|x, y| x.length_squared().total_cmp(&y.length_squared()))?;
    best.try_normalize()
}

#[cfg(test)]
mod tests {
    use super::*;
    use voxreg_testkit::Lcg;

    #[test]
    fn closed_form_agrees_with_jacobi() {
        let mut rng = Lcg::new(99);
        let mut rnd = || rng.range(-0.5, 0.5);
        let mut closed = 0;
        for k in 0..2000 {
            let b = DMat3::from_cols_array(&[(); 9].map(|_| rnd()));
            // Some nearly degenerate spectra too.
            let m = if k % 4 == 0 {
                DMat3::from_diagonal(DVec3::new(1.0, 1.0 + 1e-5, 3.0)) + 1e-7 * b
            } else {
                b + b.transpose()
            };
            let (_, vectors) = symmetric_eigen(m);
            if let Some(v) = smallest_eigenvector(m) {
                closed += 1;
                assert!(1.0 - v.dot(vectors[0]).abs() < 1e-12, "{m}: {v} vs {}", vectors[0]);
            }
        }
        assert!(closed > 1400, "{closed}");
        assert_eq!(smallest_eigenvector(DMat3::IDENTITY), None);
        assert_eq!(smallest_eigenvector(DMat3::ZERO), None);
    }

    #[test]
    fn decomposes_random_symmetric_matrices() {
        let mut rng = Lcg::new(12345);
        let mut rnd = || rng.range(-0.5, 0.5);
        for _ in 0..1000 {
            let b = DMat3::from_cols_array(&[(); 9].map(|_| rnd()));
            let m = b + b.transpose();
            let (values, vectors) = symmetric_eigen(m);
            assert!(values[0] <= values[1] && values[1] <= values[2]);
            for k in 0..3 {
                let residual = m * vectors[k] - values[k] * vectors[k];
                assert!(residual.length() < 1e-12, "{residual}");
                assert!((vectors[k].length() - 1.0).abs() < 1e-12);
            }
            assert!(vectors[0].dot(vectors[1]).abs() < 1e-12);
        }
    }

    #[test]
    fn diagonal_and_zero_matrices() {
        let (values, vectors) = symmetric_eigen(DMat3::from_diagonal(DVec3::new(3.0, 1.0, 2.0)));
        assert_eq!(values, [1.0, 2.0, 3.0]);
        assert_eq!(vectors[0], DVec3::Y);
        let (values, _) = symmetric_eigen(DMat3::ZERO);
        assert_eq!(values, [0.0; 3]);
    }
}
