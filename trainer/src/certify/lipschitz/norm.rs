//! The spectral norm ‖A‖₂ (largest singular value) of the bounds' matrices and of the
//! Jacobians of the sampled bounds, `‖A‖₂ = σ_max(A)`: `nalgebra`'s SVD, and for a row
//! (one output's Jacobian) the operations that SVD performs on it, without its allocations.

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
