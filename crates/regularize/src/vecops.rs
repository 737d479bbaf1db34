//! Parallel vector kernels on `[DVec3]` for the iterative solvers.

use glam::DVec3;
use rayon::prelude::*;

/// Vertices per parallel task: small enough to balance, large enough to amortize.
pub(crate) const CHUNK: usize = 2048;

/// `sum_i a_i . b_i`.
///
/// Every parallel sum of the solvers adds per-chunk partial sums in chunk order
/// ([`ordered`]), so results do not depend on the number of threads.
pub(crate) fn dot(a: &[DVec3], b: &[DVec3]) -> f64 {
    ordered(
        a.par_chunks(CHUNK)
            .zip(b.par_chunks(CHUNK))
            .map(|(a, b)| a.iter().zip(b).map(|(x, y)| x.dot(*y)).sum::<f64>()),
    )
}

/// The sum of a parallel iterator's items in their order (partials collected, then added
/// sequentially): the same bits at every thread count.
pub(crate) fn ordered(parts: impl IndexedParallelIterator<Item = f64>) -> f64 {
    parts.collect::<Vec<f64>>().iter().sum()
}

/// `sum_{i < n} f(i)`, in parallel over chunks of [`CHUNK`] indices, in a fixed order.
pub(crate) fn ordered_sum(n: usize, f: impl Fn(usize) -> f64 + Sync + Send) -> f64 {
    ordered(
        (0..n.div_ceil(CHUNK))
            .into_par_iter()
            .map(|c| (c * CHUNK..((c + 1) * CHUNK).min(n)).map(&f).sum::<f64>()),
    )
}

/// `sqrt(sum_i |a_i|^2)`.
pub(crate) fn norm(a: &[DVec3]) -> f64 {
    dot(a, a).sqrt()
}

/// `a <- a * s + b` (`s = 0` copies).
pub(crate) fn scale_add(a: &mut [DVec3], s: f64, b: &[DVec3]) {
    a.par_chunks_mut(CHUNK).zip(b.par_chunks(CHUNK)).for_each(|(a, b)| {
        for (x, y) in a.iter_mut().zip(b) {
            *x = *x * s + *y;
        }
    });
}

/// The CG update in one pass: `u += a p`, `r -= a q`; returns `(|r|^2, max_i |p_i|^2)`.
pub(crate) fn cg_update(u: &mut [DVec3], r: &mut [DVec3], a: f64, p: &[DVec3], q: &[DVec3]) -> (f64, f64) {
    u.par_chunks_mut(CHUNK)
        .zip(r.par_chunks_mut(CHUNK))
        .zip(p.par_chunks(CHUNK).zip(q.par_chunks(CHUNK)))
        .map(|((u, r), (p, q))| {
            let (mut s, mut m) = (0.0, 0.0f64);
            for i in 0..u.len() {
                u[i] += a * p[i];
                r[i] -= a * q[i];
                s += r[i].length_squared();
                m = m.max(p[i].length_squared());
            }
            (s, m)
        })
        .collect::<Vec<_>>()
        .into_iter()
        .fold((0.0, 0.0), |x, y| (x.0 + y.0, x.1.max(y.1)))
}

/// Geometric-series estimate of the remaining error from the last step's largest vertex
/// correction and the recent residual reduction rate: `c / (1 - rho)`, `rho` the mean
/// reduction factor of the residual norm over the last (up to) 5 iterations, capped at
/// 0.99.
pub(crate) fn tail_estimate(correction: f64, residuals: &[f64]) -> f64 {
    tail_estimate_over(correction, residuals, 5, 0.99)
}

/// [`tail_estimate`] with the rate taken over the last (up to) `window` iterations and
/// capped at `cap`: a method whose residual zigzags and whose rate comes close to 1 (the
/// projected descent) needs a longer window and a higher cap, or the estimate undershoots.
pub(crate) fn tail_estimate_over(correction: f64, residuals: &[f64], window: usize, cap: f64) -> f64 {
    let k = residuals.len();
    let w = (k - 1).min(window);
    let rho = if w == 0 || residuals[k - 1 - w] <= 0.0 {
        cap
    } else {
        (residuals[k - 1] / residuals[k - 1 - w]).powf(1.0 / w as f64).min(cap)
    };
    correction / (1.0 - rho)
}

/// `y = M x` for symmetric 3x3 blocks `[xx, yy, zz, xy, xz, yz]`.
#[inline(always)]
pub(crate) fn sym_mul(m: &[f64; 6], x: DVec3) -> DVec3 {
    DVec3::new(
        m[0] * x.x + m[3] * x.y + m[4] * x.z,
        m[3] * x.x + m[1] * x.y + m[5] * x.z,
        m[4] * x.x + m[5] * x.y + m[2] * x.z,
    )
}

/// The inverse of a symmetric positive definite 3x3 block (same layout).
pub(crate) fn sym_inverse(m: &[f64; 6]) -> [f64; 6] {
    let [a, d, f, b, c, e] = *m;
    // | a b c |
    // | b d e |
    // | c e f |
    let c00 = d * f - e * e;
    let c01 = c * e - b * f;
    let c02 = b * e - c * d;
    let det = a * c00 + b * c01 + c * c02;
    if det == 0.0 || !det.is_finite() {
        let inv = |x: f64| if x > 0.0 { 1.0 / x } else { 0.0 };
        return [inv(a), inv(d), inv(f), 0.0, 0.0, 0.0];
    }
    let c11 = a * f - c * c;
    let c12 = b * c - a * e;
    let c22 = a * d - b * b;
    let s = 1.0 / det;
    [c00 * s, c11 * s, c22 * s, c01 * s, c02 * s, c12 * s]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn symmetric_block_inverse() {
        let m = [4.0, 3.0, 2.0, 0.5, -0.3, 0.2];
        let inv = sym_inverse(&m);
        for x in [DVec3::X, DVec3::Y, DVec3::new(0.3, -1.0, 2.0)] {
            assert!((sym_mul(&m, sym_mul(&inv, x)) - x).length() < 1e-12);
        }
        // Singular blocks fall back to the inverse diagonal.
        assert_eq!(sym_inverse(&[1.0, 0.0, 2.0, 0.0, 0.0, 0.0]), [1.0, 0.0, 0.5, 0.0, 0.0, 0.0]);
    }

    #[test]
    fn tail_estimate_extrapolates_geometrically() {
        // Residuals halving each step: rho = 1/2, the tail is twice the last correction.
        let r = [1.0, 0.5, 0.25, 0.125];
        assert!((tail_estimate(1e-3, &r) - 2e-3).abs() < 1e-12);
        assert!((tail_estimate(1e-3, &[1.0]) - 0.1).abs() < 1e-9);
    }
}
