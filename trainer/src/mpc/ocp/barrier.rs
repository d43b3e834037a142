//! The log barrier of the input bounds, added to the OCP's objective by the `barrier` start
//! (`crate::mpc::law::homotopy`) and absent from the true OCP:
//! ```text
//! B_μ(u) = −μ Σ_{k<N} Σ_j [ln(u_k,j − lo_j) + ln(hi_j − u_k,j)]     (finite bounds only)
//! ∂B/∂u_k,j = −μ/(u_k,j − lo_j) + μ/(hi_j − u_k,j),   ∂²B/∂u_k,j² = μ/(u_k,j − lo_j)² + μ/(hi_j − u_k,j)²
//! ```
//! B is +∞ on and outside a bound (the line search then rejects the trial point), so the
//! iterates of a barrier solve stay strictly inside the input box, as an interior-point
//! method's do, and the input rows of the QP are never active at its solution.

/// The barrier weight μ and the input bounds it keeps the iterates inside.
#[derive(Debug, Clone, PartialEq)]
pub struct InputBarrier {
    /// Barrier weight μ > 0.
    pub mu: f64,
    /// Lower input bounds (−∞: no barrier term).
    pub lo: Vec<f64>,
    /// Upper input bounds (+∞: no barrier term).
    pub hi: Vec<f64>,
}

impl InputBarrier {
    /// B_μ of one stage's input `u` (+∞ outside or on a finite bound, NaN for a NaN input).
    pub fn value(&self, u: &[f64]) -> f64 {
        let mut b = 0.0;
        for ((&v, &lo), &hi) in u.iter().zip(&self.lo).zip(&self.hi) {
            for s in [v - lo, hi - v] {
                if s.is_infinite() && s > 0.0 {
                    continue;
                }
                if s.is_nan() {
                    return f64::NAN;
                }
                if s <= 0.0 {
                    return f64::INFINITY;
                }
                b -= self.mu * s.ln();
            }
        }
        b
    }

    /// Adds ∂B/∂u of one stage's input `u` to `g`.
    pub fn add_gradient(&self, u: &[f64], g: &mut [f64]) {
        for (j, ((&v, &lo), &hi)) in u.iter().zip(&self.lo).zip(&self.hi).enumerate() {
            if lo.is_finite() {
                g[j] -= self.mu / (v - lo);
            }
            if hi.is_finite() {
                g[j] += self.mu / (hi - v);
            }
        }
    }

    /// ∂²B/∂u_j² of one stage's input `u` (the Hessian is diagonal).
    pub fn curvature(&self, u: &[f64], j: usize) -> f64 {
        let (v, lo, hi) = (u[j], self.lo[j], self.hi[j]);
        let mut c = 0.0;
        if lo.is_finite() {
            c += self.mu / ((v - lo) * (v - lo));
        }
        if hi.is_finite() {
            c += self.mu / ((hi - v) * (hi - v));
        }
        c
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The gradient and curvature against central differences of the value, inside the
    /// box; +∞ on and beyond a bound, nothing from an infinite bound.
    #[test]
    fn derivatives_match_finite_differences() {
        let b = InputBarrier {
            mu: 0.7,
            lo: vec![-2.0, f64::NEG_INFINITY],
            hi: vec![3.0, 1.5],
        };
        for u in [[0.3, -4.0], [-1.9, 1.4], [2.5, 0.0]] {
            let mut g = [0.0; 2];
            b.add_gradient(&u, &mut g);
            for j in 0..2 {
                let h = 1e-6;
                let (mut up, mut dn) = (u, u);
                up[j] += h;
                dn[j] -= h;
                let fd = (b.value(&up) - b.value(&dn)) / (2.0 * h);
                assert!((fd - g[j]).abs() <= 1e-6 * g[j].abs().max(1.0), "{u:?} {j}");
                let (mut gu, mut gd) = ([0.0; 2], [0.0; 2]);
                b.add_gradient(&up, &mut gu);
                b.add_gradient(&dn, &mut gd);
                let fd2 = (gu[j] - gd[j]) / (2.0 * h);
                let c = b.curvature(&u, j);
                assert!((fd2 - c).abs() <= 1e-5 * c.max(1.0), "{u:?} {j}: {fd2} {c}");
            }
        }
        assert_eq!(b.value(&[3.0, 0.0]), f64::INFINITY);
        assert_eq!(b.value(&[0.0, 2.0]), f64::INFINITY);
        assert!(b.value(&[0.0, -1e300]).is_finite());
    }
}
