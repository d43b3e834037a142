//! The tube: ρ = sup‖P^{1/2}(A + BK)P^{−1/2}‖₂, w̄ = ε·sup‖P^{1/2}B‖₂,
//! s_k = w̄ Σ_{j<k} ρ^j, and the tightened bounds X ⊖ {σ_i s_k}, U ⊖ {ε + τ_j s_k}.
//!
//! **Affine `[ocp]` constraints** aₓᵀx + a_uᵀu ≤ b ([`AffineConstraint`]): with the true
//! state x_k = z_k + Δ (‖Δ‖_P ≤ s_k) and the applied input u_k = v_k + KΔ + e (‖e‖₂ ≤ ε),
//! aₓᵀx_k + a_uᵀu_k = aₓᵀz_k + a_uᵀv_k + (aₓ + Kᵀa_u)ᵀΔ + a_uᵀe, and the largest value of the
//! last two terms is exactly `s_k·‖P^{−1/2}(aₓ + Kᵀa_u)‖₂ + ε‖a_u‖₂` (support functions of
//! the ellipsoid and the ball) — the margin subtracted from b at stage k
//! (`StageBounds::margins`). The boxes are the special case a = ±e_i (σ_i, τ_j). A nonlinear
//! constraint is refused ([`RobustError::UntightenedConstraints`]): its margin would need a
//! bound on its gradient over the tube, which is not computed.

use super::jacobians::{JacobianBound, JacobianSet};
use super::RobustError;
use crate::problem::{ProblemConfig, RobustMethod, StageBounds};
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

/// Symmetric square root and inverse square root of a symmetric positive definite matrix.
fn sqrt_pd(p: &DMatrix<f64>) -> (DMatrix<f64>, DMatrix<f64>) {
    let e = p.clone().symmetric_eigen();
    let d = e.eigenvalues.map(|l| l.max(0.0).sqrt());
    let di = e.eigenvalues.map(|l| 1.0 / l.max(1e-300).sqrt());
    let v = &e.eigenvectors;
    (
        v * DMatrix::from_diagonal(&d) * v.transpose(),
        v * DMatrix::from_diagonal(&di) * v.transpose(),
    )
}

fn spectral_norm(m: &DMatrix<f64>) -> f64 {
    m.clone().singular_values().max()
}

/// `(ρ, L_B)`: the largest `‖P^{1/2}(A + BK)P^{−1/2}‖₂` and `‖P^{1/2}B‖₂` over the family.
pub fn contraction(js: &JacobianSet, k: &DMatrix<f64>, p: &DMatrix<f64>) -> (f64, f64) {
    let (ph, pmh) = sqrt_pd(p);
    let mut rho = 0.0f64;
    let mut lb = 0.0f64;
    for (a, b) in js.a.iter().zip(&js.b) {
        rho = rho.max(spectral_norm(&(&ph * (a + b * k) * &pmh)));
        lb = lb.max(spectral_norm(&(&ph * b)));
    }
    (rho, lb)
}

/// `(ρ, L_B)` of [`contraction`] **proven** for every member of the family with rounding
/// margins ([`super::verified`]: MᵀPM ≼ ρ²P for M = A + BK, BᵀPB ≼ L_B²I), from the f64
/// estimates `est`; `None` when a bound cannot be proven (then the tier is sampled).
pub fn verified_contraction(
    js: &JacobianSet,
    k: &DMatrix<f64>,
    p: &DMatrix<f64>,
    est: (f64, f64),
) -> Option<(f64, f64)> {
    use super::verified::{bound, sum_product_radius};
    let eye = DMatrix::identity(k.nrows(), k.nrows());
    let (mut rho, mut lb) = (0.0f64, 0.0f64);
    for (a, b) in js.a.iter().zip(&js.b) {
        let m = a + b * k;
        rho = rho.max(bound(&m, &sum_product_radius(a, b, k), p, p, est.0)?);
        let zero = DMatrix::zeros(b.nrows(), b.ncols());
        lb = lb.max(bound(b, &zero, p, &eye, est.1)?);
    }
    Some((rho, lb))
}

/// The support function `√(aᵀP⁻¹a)` of the row `a = aₓ + Kᵀa_u` over {dᵀPd ≤ 1}, proven
/// from its estimate (`a_u` empty: the row aₓ alone); `None` when not proven.
pub fn verified_support(
    a_x: &[f64],
    a_u: &[f64],
    k: &DMatrix<f64>,
    p: &DMatrix<f64>,
    estimate: f64,
) -> Option<f64> {
    use super::verified::{bound, sum_product_radius};
    let nx = a_x.len();
    let ax = DMatrix::from_row_slice(1, nx, a_x);
    let (m, radius) = if a_u.is_empty() {
        (ax, DMatrix::zeros(1, nx))
    } else {
        let au = DMatrix::from_row_slice(1, a_u.len(), a_u);
        (&ax + &au * k, sum_product_radius(&ax, &au, k))
    };
    bound(&m, &radius, &DMatrix::identity(1, 1), p, estimate)
}

/// Solves the discrete algebraic Riccati equation by fixed-point iteration; returns
/// (P, K) with `u = Kx` (K = −(R + BᵀPB)⁻¹BᵀPA), or None if it does not converge.
pub fn dare(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
) -> Option<(DMatrix<f64>, DMatrix<f64>)> {
    let mut p = q.clone() + DMatrix::identity(q.nrows(), q.ncols()) * 1e-9;
    for _ in 0..100_000 {
        let s = r + b.transpose() * &p * b;
        let k = -s.clone().try_inverse()? * b.transpose() * &p * a;
        let next = q + a.transpose() * &p * a + a.transpose() * &p * b * &k;
        let next = (&next + next.transpose()) * 0.5;
        let diff = (&next - &p).amax();
        p = next;
        if !p.iter().all(|v| v.is_finite()) {
            return None;
        }
        if diff <= 1e-13 * p.amax().max(1.0) {
            let s = r + b.transpose() * &p * b;
            let k = -s.try_inverse()? * b.transpose() * &p * a;
            return Some((p, k));
        }
    }
    None
}

/// An affine `[ocp]` constraint aₓᵀx + a_uᵀu ≤ b with its tube factors (module doc).
#[derive(Debug, Clone, PartialEq)]
pub struct AffineConstraint {
    /// Its key, e.g. `ocp.constraints[0]`.
    pub key: String,
    /// aₓ.
    pub a_x: Vec<f64>,
    /// a_u.
    pub a_u: Vec<f64>,
    /// b.
    pub b: f64,
    /// ‖P^{−1/2}(aₓ + Kᵀa_u)‖₂: margin per unit of the tube radius s.
    pub per: f64,
    /// ‖a_u‖₂: margin per unit of ε.
    pub a_u_norm: f64,
}

/// The tube of a design: gain, Lyapunov matrix, rates and the per-stage radii.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Tube {
    /// Design input error ε.
    pub eps: f64,
    /// Method.
    pub method: RobustMethod,
    /// Ancillary gain K (nu rows of nx), u = v + K(x − z).
    pub k: Vec<Vec<f64>>,
    /// Incremental Lyapunov matrix P (nx rows).
    pub p: Vec<Vec<f64>>,
    /// The LQR input-weight scale that produced K (tube method).
    pub lqr_r_scale: Option<f64>,
    /// Contraction rate ρ.
    pub rho: f64,
    /// One-step disturbance bound w̄ = ε·L_B in the P-norm.
    pub w: f64,
    /// How ρ and w̄ were obtained.
    pub bound: JacobianBound,
    /// s_0..s_N: bounds on ‖x_k − z_k‖_P.
    pub s: Vec<f64>,
    /// σ_i = √((P⁻¹)_ii): state-coordinate tightening per unit of s.
    pub x_margin: Vec<f64>,
    /// τ_j = √(K_j P⁻¹ K_jᵀ): input tightening per unit of s.
    pub u_margin: Vec<f64>,
}

impl Tube {
    /// The tube of a given gain K and Lyapunov matrix P over a Jacobian family.
    pub fn new(
        js: &JacobianSet,
        k: &DMatrix<f64>,
        p: &DMatrix<f64>,
        eps: f64,
        horizon: usize,
        method: RobustMethod,
    ) -> Tube {
        let est = contraction(js, k, p);
        let pinv = p
            .clone()
            .try_inverse()
            .unwrap_or_else(|| DMatrix::from_element(p.nrows(), p.ncols(), f64::NAN));
        let x_est: Vec<f64> = (0..p.nrows())
            .map(|i| pinv[(i, i)].max(0.0).sqrt())
            .collect();
        let u_est: Vec<f64> = (0..k.nrows())
            .map(|j| {
                let kj = k.row(j);
                (kj * &pinv * kj.transpose())[(0, 0)].max(0.0).sqrt()
            })
            .collect();
        // A sound family gets proven ρ, L_B, σ, τ (rounding margins, `verified`); one that
        // cannot be proven falls to the sampled tier with the estimates.
        let nx = p.nrows();
        let unit = |i: usize| {
            (0..nx)
                .map(|c| f64::from(u8::from(c == i)))
                .collect::<Vec<_>>()
        };
        let proven = (js.bound != JacobianBound::SampledEstimate)
            .then(|| {
                let (rho, lb) = verified_contraction(js, k, p, est)?;
                let xm = (0..nx)
                    .map(|i| verified_support(&unit(i), &[], k, p, x_est[i]))
                    .collect::<Option<Vec<_>>>()?;
                let um = (0..k.nrows())
                    .map(|j| {
                        let kj: Vec<f64> = k.row(j).iter().copied().collect();
                        verified_support(&kj, &[], k, p, u_est[j])
                    })
                    .collect::<Option<Vec<_>>>()?;
                Some((rho, lb, xm, um))
            })
            .flatten();
        let (bound, (rho, lb), x_margin, u_margin) = match proven {
            Some((rho, lb, xm, um)) => (js.bound, (rho, lb), xm, um),
            None => (JacobianBound::SampledEstimate, est, x_est, u_est),
        };
        // s_k rounded up (sound: each s_k an upper bound of the real recursion's).
        let up = super::verified::up;
        let w = up(eps * lb);
        let mut s = vec![0.0; horizon + 1];
        for i in 1..=horizon {
            s[i] = up(up(rho * s[i - 1]) + w);
        }
        let rows = |m: &DMatrix<f64>| {
            (0..m.nrows())
                .map(|i| m.row(i).iter().copied().collect())
                .collect()
        };
        Tube {
            eps,
            method,
            k: rows(k),
            p: rows(p),
            lqr_r_scale: None,
            rho,
            w,
            bound,
            s,
            x_margin,
            u_margin,
        }
    }

    /// The tightened bounds of `cfg`'s OCP; an error names the first empty interval.
    pub fn tighten(&self, cfg: &ProblemConfig) -> Result<StageBounds, RobustError> {
        let o = &cfg.ocp;
        let n = o.horizon;
        let shrink = |lo: &[f64], hi: &[f64], m: &dyn Fn(usize) -> f64, what: &str, k: usize| {
            let mut l = lo.to_vec();
            let mut h = hi.to_vec();
            for i in 0..lo.len() {
                // Rounded outward: the tightened interval is never wider than the exact one.
                let d = super::verified::up(m(i));
                if l[i].is_finite() {
                    l[i] = super::verified::up(l[i] + d);
                }
                if h[i].is_finite() {
                    h[i] = super::verified::down(h[i] - d);
                }
                if l[i] >= h[i] || l[i].is_nan() || h[i].is_nan() {
                    return Err(RobustError::Infeasible {
                        eps: self.eps,
                        reason: format!(
                            "{what}[{i}] at stage {k}: tightening {d:.4} leaves [{:.4}, {:.4}] \
                             (ρ = {:.4}, w̄ = {:.4e})",
                            l[i], h[i], self.rho, self.w
                        ),
                    });
                }
            }
            Ok((l, h))
        };
        let mut st = StageBounds {
            x_lo: vec![],
            x_hi: vec![],
            u_lo: vec![],
            u_hi: vec![],
            margins: vec![],
        };
        for k in 1..=n {
            let (l, h) = shrink(&o.x_lo, &o.x_hi, &|i| self.x_margin[i] * self.s[k], "x", k)?;
            st.x_lo.push(l);
            st.x_hi.push(h);
        }
        for k in 0..n {
            let (l, h) = shrink(
                &o.u_lo,
                &o.u_hi,
                &|j| self.eps + self.u_margin[j] * self.s[k],
                "u",
                k,
            )?;
            st.u_lo.push(l);
            st.u_hi.push(h);
        }
        st.margins = self
            .affine_constraints(cfg)?
            .iter()
            .map(|c| (0..=n).map(|k| self.margin(c, k)).collect())
            .collect();
        Ok(st)
    }

    /// The margin of an affine constraint at stage k: `s_k·per + ε‖a_u‖₂` (module doc),
    /// rounded up.
    pub fn margin(&self, c: &AffineConstraint, k: usize) -> f64 {
        let up = super::verified::up;
        up(up(self.s[k] * c.per) + up(self.eps * up(c.a_u_norm)))
    }

    /// The `[ocp]` constraints of `cfg` (path, then terminal: the compiled set's order) as
    /// affine rows with their tube factors; an error names the first nonlinear one.
    pub fn affine_constraints(
        &self,
        cfg: &ProblemConfig,
    ) -> Result<Vec<AffineConstraint>, RobustError> {
        let cs = match cfg.constraint_set() {
            Ok(Some(cs)) => cs,
            Ok(None) => return Ok(vec![]),
            Err(e) => {
                return Err(RobustError::UntightenedConstraints {
                    key: e.key.clone(),
                    reason: e.reason(),
                })
            }
        };
        let (nx, nu) = (cs.nx(), cs.nu());
        let (mut g0, mut jac) = (vec![0.0; cs.len()], vec![0.0; cs.len() * (nx + nu)]);
        cs.linearize(&vec![0.0; nx], &vec![0.0; nu], &mut g0, &mut jac);
        let p = DMatrix::from_fn(nx, nx, |i, j| self.p[i][j]);
        let pinv = p
            .clone()
            .try_inverse()
            .unwrap_or_else(|| DMatrix::from_element(nx, nx, f64::NAN));
        let k = DMatrix::from_fn(nu, nx, |i, j| self.k[i][j]);
        cs.items
            .iter()
            .enumerate()
            .map(|(c, item)| {
                if !item.affine {
                    return Err(RobustError::UntightenedConstraints {
                        key: item.key.clone(),
                        reason: format!(
                            "`{}` is nonlinear: the tube tightens affine constraints only",
                            item.text
                        ),
                    });
                }
                let row = &jac[c * (nx + nu)..(c + 1) * (nx + nu)];
                let (a_x, a_u) = (row[..nx].to_vec(), row[nx..].to_vec());
                let v = nalgebra::DVector::from_fn(nx, |i, _| {
                    a_x[i] + (0..nu).map(|j| k[(j, i)] * a_u[j]).sum::<f64>()
                });
                let est = (v.transpose() * &pinv * &v)[(0, 0)].max(0.0).sqrt();
                // Proven (rounding margins); NaN when not, which no fit accepts.
                let per = verified_support(&a_x, &a_u, &k, &p, est).unwrap_or(f64::NAN);
                Ok(AffineConstraint {
                    key: item.key.clone(),
                    b: -g0[c],
                    per,
                    a_u_norm: a_u.iter().map(|a| a * a).sum::<f64>().sqrt(),
                    a_x,
                    a_u,
                })
            })
            .collect()
    }

    /// The largest tightening relative to the half-width of each finite bound (the
    /// design's score: smaller is better, ≥ 1 is infeasible).
    pub fn score(&self, cfg: &ProblemConfig) -> f64 {
        let o = &cfg.ocp;
        let n = o.horizon;
        let mut worst = 0.0f64;
        for i in 0..o.x_lo.len() {
            let half = 0.5 * (o.x_hi[i] - o.x_lo[i]);
            if half.is_finite() {
                worst = worst.max(self.x_margin[i] * self.s[n] / half);
            }
        }
        for j in 0..o.u_lo.len() {
            let half = 0.5 * (o.u_hi[j] - o.u_lo[j]);
            if half.is_finite() {
                worst = worst.max((self.eps + self.u_margin[j] * self.s[n - 1]) / half);
            }
        }
        if worst.is_nan() {
            f64::INFINITY
        } else {
            worst
        }
    }
}
