//! **Verified** upper bounds for the tube and the terminal region: the smallest-known ρ with
//!
//! ```text
//! Mᵀ W M ≼ ρ² Q        (W, Q symmetric, Q ≻ 0; M: r × n, W: r × r, Q: n × n)
//! ```
//!
//! proven in f64 arithmetic. Every norm of the robust design is of this form:
//! `‖P^{1/2}(A + BK)P^{−1/2}‖₂` (M = A + BK, W = Q = P), `‖P^{1/2}B‖₂` (M = B, W = P,
//! Q = I), and the support function `√(aᵀP⁻¹a)` of a row over an ellipsoid (M = aᵀ, W = 1,
//! Q = P: by the Schur complement, aaᵀ ≼ σ²P ⇔ aᵀP⁻¹a ≤ σ²).
//!
//! Method: a floating-point estimate ρ̂ (the caller's closed form) is inflated to
//! ρ̃ = ρ̂·(1 + 2⁻⁴⁰) + 2⁻⁵⁰⁰; `S = fl(ρ̃²Q − MᵀWM)` is computed with an entrywise bound E on
//! its error — the products by |fl(XY) − XY| ≤ γ_k|X||Y| (Higham, Thm 3.5; γ_k = ku/(1 − ku),
//! u = 2⁻⁵³, taken twice over), an entrywise radius R of M's own uncertainty by
//! `Rᵀ|W||M| + |M|ᵀ|W|R + Rᵀ|W|R`, the scaling and subtraction by 3u of their magnitudes —
//! and S − E is proven positive semidefinite when the floating-point Cholesky factorisation of
//! `S − c·I`, `c = ‖E‖_F + α·tr|S| + 4n(2n + max|s_ii|)·2⁻¹⁰⁷⁴`, α = 2γ_{n+2}/(1 − 2γ_{n+2}),
//! runs to completion with positive pivots (Rump, "Verification of positive definiteness",
//! BIT 46 (2006), Thm 2.3, with its constant doubled; ‖E‖_F ≥ ‖E‖₂ covers S's error). Then
//! ρ̃²Q − MᵀWM ≽ 0 holds for the real numbers. If the factorisation fails, the inflation
//! grows 16-fold, up to 2⁻⁸; then `None` (not proven: the caller's tier becomes sampled).
//!
//! What it rests on: the matrices M, W, Q are the f64 values the code holds (the plant's
//! Jacobians as evaluated, `R` covering only the rounding of forming M from them), as for the
//! QP tier ([`crate::certify`] is later in the pipeline; see `QP_DATA_NOTE` there).

use nalgebra::DMatrix;

/// Unit roundoff of f64.
const U: f64 = f64::EPSILON / 2.0;

/// γ_k = k·u / (1 − k·u), doubled (room for the rounding of the bound's own computation).
fn gamma(k: usize) -> f64 {
    let ku = k as f64 * U;
    2.0 * ku / (1.0 - ku)
}

/// A value rounded up past the rounding of the operations that produced it (a few ulps).
pub fn up(x: f64) -> f64 {
    x + x.abs() * 8.0 * U + f64::MIN_POSITIVE
}

/// A value rounded down past the rounding of the operations that produced it.
pub fn down(x: f64) -> f64 {
    x - x.abs() * 8.0 * U - f64::MIN_POSITIVE
}

fn abs(m: &DMatrix<f64>) -> DMatrix<f64> {
    m.map(f64::abs)
}

/// Whether the floating-point Cholesky factorisation of `a` completes with positive pivots.
fn cholesky_completes(a: &DMatrix<f64>) -> bool {
    let n = a.nrows();
    let mut l = DMatrix::<f64>::zeros(n, n);
    for j in 0..n {
        let mut d = a[(j, j)];
        for k in 0..j {
            d -= l[(j, k)] * l[(j, k)];
        }
        if d.is_nan() || d <= 0.0 || !d.is_finite() {
            return false;
        }
        let djj = d.sqrt();
        l[(j, j)] = djj;
        for i in j + 1..n {
            let mut s = a[(i, j)];
            for k in 0..j {
                s -= l[(i, k)] * l[(j, k)];
            }
            l[(i, j)] = s / djj;
            if !l[(i, j)].is_finite() {
                return false;
            }
        }
    }
    true
}

/// Whether `ρ²Q − MᵀWM ≽ 0` is proven for every M' with |M' − M| ≤ `radius` (module doc).
pub fn proves(
    m: &DMatrix<f64>,
    radius: &DMatrix<f64>,
    w: &DMatrix<f64>,
    q: &DMatrix<f64>,
    rho: f64,
) -> bool {
    let (r, n) = (m.nrows(), m.ncols());
    if w.shape() != (r, r) || q.shape() != (n, n) || radius.shape() != (r, n) {
        return false;
    }
    let (am, aw) = (abs(m), abs(w));
    // W M and Mᵀ (W M): rounding of the two products, and M's own radius.
    let wm = w * m;
    let e_wm = (&aw * &am) * gamma(r);
    let t = m.transpose() * &wm;
    let mut e = (am.transpose() * abs(&wm)) * gamma(r) + am.transpose() * &e_wm;
    e += radius.transpose() * &aw * &am
        + am.transpose() * &aw * radius
        + radius.transpose() * &aw * radius;
    let r2 = rho * rho;
    let s = q * r2 - &t;
    e += (abs(q) * r2 + abs(&t)) * (3.0 * U) + abs(&s) * U;
    // The error bound's own rounding (sums of ≤ 3n + 3 non-negative products).
    let e_norm = up(e.norm() * (1.0 + gamma(3 * n + 3)));
    let trace: f64 = (0..n).map(|i| s[(i, i)].abs()).sum();
    let g = gamma(n + 2);
    let alpha = 2.0 * g / (1.0 - 2.0 * g);
    let max_diag = (0..n).map(|i| s[(i, i)].abs()).fold(0.0, f64::max);
    let underflow = 4.0 * n as f64 * (2.0 * n as f64 + max_diag) * f64::from_bits(1);
    let c = up(e_norm + up(alpha * trace * (1.0 + gamma(n))) + underflow);
    if !c.is_finite() || !s.iter().all(|v| v.is_finite()) {
        return false;
    }
    // Shifted so that the rounding of the subtraction only lowers the diagonal.
    let mut shifted = s.clone();
    for i in 0..n {
        shifted[(i, i)] = down(s[(i, i)] - up(c));
    }
    cholesky_completes(&shifted)
}

/// A proven ρ ≥ `estimate` with `ρ²Q − MᵀWM ≽ 0` for every M' within `radius` of M, or
/// `None` when the inflated estimate cannot be proven (module doc).
pub fn bound(
    m: &DMatrix<f64>,
    radius: &DMatrix<f64>,
    w: &DMatrix<f64>,
    q: &DMatrix<f64>,
    estimate: f64,
) -> Option<f64> {
    if !estimate.is_finite() || estimate < 0.0 {
        return None;
    }
    // Inflations 2⁻⁴⁰, 2⁻³⁶, …, 2⁻⁸: the first the arithmetic proves.
    (0..9)
        .map(|k| estimate * (1.0 + 2f64.powi(-40 + 4 * k)) + 2f64.powi(-500))
        .find(|rho| proves(m, radius, w, q, *rho))
}

/// The entrywise rounding radius of `fl(A + B·K)` (γ_n|B||K| for the product, u for the sum).
pub fn sum_product_radius(a: &DMatrix<f64>, b: &DMatrix<f64>, k: &DMatrix<f64>) -> DMatrix<f64> {
    let bk = abs(b) * abs(k) * gamma(b.ncols().max(1));
    let m = a + b * k;
    bk * (1.0 + U) + abs(&m) * (2.0 * U)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn m(r: usize, c: usize, v: &[f64]) -> DMatrix<f64> {
        DMatrix::from_row_slice(r, c, v)
    }

    /// The proven ρ of a matrix norm is above the true norm (by SVD) and within 10⁻⁵ of it;
    /// a value below the true norm is never proven; a support function agrees with
    /// √(aᵀP⁻¹a).
    #[test]
    fn bounds_are_above_the_true_norms_and_tight() {
        let p = m(2, 2, &[3.0, 0.4, 0.4, 1.5]);
        let a = m(2, 2, &[0.9, 0.1, -0.2, 0.8]);
        let z = DMatrix::zeros(2, 2);
        // ‖P^{1/2} A P^{−1/2}‖₂ = √λ_max(P⁻¹AᵀPA).
        let pinv = p.clone().try_inverse().unwrap();
        let g = &pinv * a.transpose() * &p * &a;
        let ev = g.complex_eigenvalues();
        let truth = ev.iter().map(|c| c.re).fold(0.0, f64::max).sqrt();
        let b = bound(&a, &z, &p, &p, truth).unwrap();
        assert!(b >= truth && b <= truth * (1.0 + 1e-8), "{b} vs {truth}");
        assert!(!proves(&a, &z, &p, &p, truth * (1.0 - 1e-9)));
        // Support function of the row a = (1, −2) over {dᵀPd ≤ 1}.
        let row = m(1, 2, &[1.0, -2.0]);
        let one = m(1, 1, &[1.0]);
        let sigma = (&row * &pinv * row.transpose())[(0, 0)].sqrt();
        let sb = bound(&row, &DMatrix::zeros(1, 2), &one, &p, sigma).unwrap();
        assert!(sb >= sigma && sb <= sigma * (1.0 + 1e-8));
        assert!(!proves(
            &row,
            &DMatrix::zeros(1, 2),
            &one,
            &p,
            sigma * (1.0 - 1e-9)
        ));
        // An uncertain M: the bound covers its worst entrywise perturbation.
        let rad = DMatrix::from_element(2, 2, 1e-3);
        let wide = bound(&a, &rad, &p, &p, truth).unwrap();
        let worst = m(2, 2, &[0.901, 0.101, -0.201, 0.801]);
        let gw = &pinv * worst.transpose() * &p * &worst;
        let tw = gw
            .complex_eigenvalues()
            .iter()
            .map(|c| c.re)
            .fold(0.0, f64::max)
            .sqrt();
        assert!(wide >= tw, "{wide} < {tw}");
    }

    /// Non-finite or ill-shaped inputs are never proven.
    #[test]
    fn bad_inputs_are_not_proven() {
        let p = m(2, 2, &[1.0, 0.0, 0.0, 1.0]);
        let z = DMatrix::zeros(2, 2);
        let a = m(2, 2, &[f64::NAN, 0.0, 0.0, 1.0]);
        assert_eq!(bound(&a, &z, &p, &p, 1.0), None);
        assert_eq!(bound(&p, &z, &p, &p, f64::INFINITY), None);
        assert!(!proves(&p, &DMatrix::zeros(1, 1), &p, &p, 2.0));
    }
}
