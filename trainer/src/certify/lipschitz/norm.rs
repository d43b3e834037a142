//! The spectral norm ‖A‖₂ (largest singular value) of the bounds' matrices and of the
//! Jacobians of the sampled bounds, `‖A‖₂ = σ_max(A)`: `nalgebra`'s SVD, and for a row
//! (one output's Jacobian) the operations that SVD performs on it, without its allocations;
//! the squared norms of the vertex enumeration (`‖J‖₂²`, closed form for two rows or
//! columns, and the largest `Σ_e (l_e + h_e)²` over a table of vectors).

use super::dense;
use nalgebra::DMatrix;

/// ‖A‖₂ (largest singular value).
///
/// A finite row (one output's Jacobian, the common case of the lower bound's thousands of
/// norms) takes [`row_norm`]: `nalgebra`'s SVD reduced to its operations on a row, the
/// same bits without the factorisation's allocations.
pub fn spectral_norm(a: &DMatrix<f64>) -> f64 {
    if a.is_empty() {
        return 0.0;
    }
    if a.nrows() == 1 {
        if let Some(v) = finite_row_norm(a.as_slice()) {
            return v;
        }
    }
    a.singular_values().max()
}

/// ‖x‖₂ of a finite row by the operations `nalgebra`'s SVD performs on a 1 × n matrix:
/// scaled by its largest |x_i| (`camax`, `unscale_mut`), one Householder reflection whose
/// norm is `√(0 + x·x)` (the dot product's own summation order, [`dense::dot8`]), the
/// scale multiplied back.
/// [`row_norm`] of a nonempty finite row; `None` otherwise (the SVD decides those).
fn finite_row_norm(x: &[f64]) -> Option<f64> {
    (!x.is_empty() && x.iter().all(|v| v.is_finite())).then(|| row_norm(x))
}

fn row_norm(x: &[f64]) -> f64 {
    let amax = x
        .iter()
        .fold(0.0f64, |m, v| if v.abs() > m { v.abs() } else { m });
    if amax == 0.0 {
        return 0.0;
    }
    let scaled = |y: &mut [f64]| {
        for (y, v) in y.iter_mut().zip(x) {
            *y = v / amax;
        }
        (0.0 + dense::dot8(y, y)).sqrt() * amax
    };
    if x.len() <= 16 {
        scaled(&mut [0.0; 16][..x.len()])
    } else {
        scaled(&mut vec![0.0; x.len()])
    }
}

/// ‖J‖₂ of the nu × nx row-major `j` ([`spectral_norm`]; a finite row without a matrix).
pub(super) fn jacobian_norm(j: &[f64], nu: usize, nx: usize) -> f64 {
    if nu == 1 {
        if let Some(v) = finite_row_norm(j) {
            return v;
        }
    }
    spectral_norm(&DMatrix::from_row_slice(nu, nx, j))
}

/// `max(+0, max_s Σ_e (lo[e·n + s] + h_e)²)` over the `n` patterns s of the column-major
/// table `lo` (one column per entry e of `h`), each sum `(−0 + t₀²) + t₁² + …` in entry order
/// as the vertex loop forms it; the maximum in eight independent lanes (the sums are
/// ≥ +0, so `f64::max` gives the same maximum in any order; `f64::max` ignores NaNs).
pub(super) fn max_sq_sum(lo: &[f64], n: usize, h: &[f64]) -> f64 {
    const W: usize = 8;
    let mut best = [0.0f64; W];
    let full = n / W * W;
    let mut s = 0;
    while s < full {
        let mut acc = [-0.0f64; W];
        for (col, &he) in lo.chunks_exact(n).zip(h) {
            let x: &[f64; W] = col[s..s + W].try_into().expect("W patterns");
            for i in 0..W {
                let t = x[i] + he;
                acc[i] += t * t;
            }
        }
        for i in 0..W {
            best[i] = best[i].max(acc[i]);
        }
        s += W;
    }
    let mut m = best.iter().fold(0.0f64, |m, &b| m.max(b));
    for s in full..n {
        let mut acc = -0.0f64;
        for (col, &he) in lo.chunks_exact(n).zip(h) {
            let t = col[s] + he;
            acc += t * t;
        }
        m = m.max(acc);
    }
    m
}

/// ‖J‖₂² of a row-major r × c matrix: closed form for a 2 × 2 Gram matrix, SVD otherwise.
pub(super) fn squared_spectral_norm(j: &[f64], r: usize, c: usize) -> f64 {
    if r == 2 || c == 2 {
        // G = J Jᵀ (r = 2) or JᵀJ (c = 2); λ_max = (tr + √((g₁₁ − g₂₂)² + 4g₁₂²)) / 2.
        let (mut g11, mut g22, mut g12) = (0.0, 0.0, 0.0);
        if r == 2 {
            for k in 0..c {
                let (x, y) = (j[k], j[c + k]);
                g11 += x * x;
                g22 += y * y;
                g12 += x * y;
            }
        } else {
            for k in 0..r {
                let (x, y) = (j[k * 2], j[k * 2 + 1]);
                g11 += x * x;
                g22 += y * y;
                g12 += x * y;
            }
        }
        let disc = ((g11 - g22) * (g11 - g22) + 4.0 * g12 * g12).sqrt();
        return 0.5 * (g11 + g22 + disc);
    }
    spectral_norm(&DMatrix::from_row_slice(r, c, j)).powi(2)
}
