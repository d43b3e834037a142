//! Robust MPC design for a certified input error ε (the paper's Corollary 1).
//!
//! This module owns the **tube** of the error dynamics under input errors ‖e‖₂ ≤ ε and the
//! **tightened constraint sets** X_k, U_k it induces, plus the design loop that uses them.
//!
//! # The tube
//! Let `z_k, v_k` be a prediction of the MPC (`z_{k+1} = F(z_k, v_k)`) and `x_k` the true
//! state under `u_k = v_k + K(x_k − z_k) + e_k` with an ancillary gain K. With the
//! incremental Lyapunov function `V(Δ) = ‖Δ‖_P = √(ΔᵀPΔ)` and
//!
//! ```text
//! ρ  = sup_ξ ‖P^{1/2} (A(ξ) + B(ξ)K) P^{−1/2}‖₂      (contraction rate)
//! w̄  = ε · sup_ξ ‖P^{1/2} B(ξ)‖₂                    (one-step effect of ‖e‖ ≤ ε)
//! ```
//! (A, B the Jacobians of the discrete dynamics F over the set of arguments ξ that the
//! mean-value theorem can visit), the deviation `Δ_k = x_k − z_k` obeys
//! `‖Δ_{k+1}‖_P ≤ ρ‖Δ_k‖_P + w̄`, so from `Δ_0 = 0`
//!
//! ```text
//! ‖Δ_k‖_P ≤ s_k = w̄ · Σ_{j<k} ρ^j  ( = w̄ (1 − ρ^k)/(1 − ρ) for ρ ≠ 1 ).
//! ```
//! The tightened OCP uses `x_k ∈ X ⊖ {σ_i s_k}` with `σ_i = √((P⁻¹)_ii)` (the largest
//! |Δ_i| on the ellipsoid ‖Δ‖_P ≤ s_k) for k = 1..N, and
//! `u_k ∈ U ⊖ {ε + τ_j s_k}` with `τ_j = √(K_j P⁻¹ K_jᵀ)` for k = 0..N−1: ε because the
//! applied input is `κ(x) + e`, `τ_j s_k` because the feasibility candidate at the next
//! time (shifted solution + K·deviation) moves the inputs by `K Δ` (Köhler et al. 2018).
//! `method = "lipschitz"` is the special case K = 0, P = I: ρ = L_x, w̄ = ε L_u, and
//! `s_k = ε L_u Σ_{j<k} L_x^j` — hopeless for an unstable plant, kept for comparison.
//!
//! # What is sound and what is an estimate
//! The sup over ξ is computed as follows ([`JacobianBound`]):
//! - **double integrator**: the Jacobians are constant: exact.
//! - **pendulum** (≤ 2 RK4 sub-steps): the continuous Jacobian depends on the state only
//!   through `c = cos(x₁)` ∈ [−1, 1]; the RK4 Jacobian `(A, B)` is then a *multi-affine*
//!   function of the four (per sub-step) stage values c₁…c₄, each of which appears at most
//!   once in every product. Over c ∈ [−1, 1]^{4S} a norm of a multi-affine matrix function
//!   is convex in each c separately, so its maximum is attained at one of the 2^{4S}
//!   vertices: the bound is **sound over the whole state and input space** (no region
//!   assumption, the nonlinearity sin is covered exactly by its derivative's range).
//! - **other systems** (cart-pole): the maximum over `samples` random (x, u) ∈ X × U — an
//!   **estimate** (flagged), which also assumes the states stay in X.
//!
//! Conservatism: one quadratic P for all Jacobians; the ellipsoid is over-bounded by a box
//! (σ_i); the bang-bang worst case is charged at every step; K is an LQR gain of the
//! linearisation at the origin chosen from a small grid of input weights (the one that
//! tightens least), not an optimised one.
//!
//! # What the tightening guarantees, and what it does not
//! If the tightened OCP is feasible at x_t, its optimum is (z*, v*) and the plant receives
//! `v*_0 + e` with ‖e‖ ≤ ε, the candidate `ṽ_k = v*_{k+1} + K(z̃_k − z*_{k+1})` from
//! `x_{t+1}` satisfies the tightened bounds of stages k = 0..N−2 (the margins
//! `s_{k+1} − s_k = ρ^k w̄` absorb the deviation) and the true state satisfies X. The
//! last stage of the candidate needs a terminal set that is invariant under K with the
//! tightened constraints; the problem files have only a terminal cost, so **recursive
//! feasibility is not proven here** — it is checked by closed-loop Monte Carlo
//! (`mpc_soft_steps` counts the steps where the robust MPC had become infeasible).

use crate::certify::certificate::Certificate;
use crate::certify::Model;
use crate::io::write_atomic;
use crate::mpc::law::MpcLaw;
use crate::mpc::sqp::SqpStatus;
use crate::pipeline::{ClosedLoop, PipelineError, RunOptions};
use crate::problem::model::{Discrete, Pendulum, System};
use crate::problem::{ProblemConfig, StageBounds};
pub use crate::problem::{RobustMethod, RobustSettings};
use crate::rng::uniform;
use crate::study::closed_loop::{simulate, Controller, Disturbance, Run, SimSettings};
use nalgebra::DMatrix;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Errors of the robust design.
#[derive(Debug, thiserror::Error)]
pub enum RobustError {
    /// The tightened constraint set is empty (ε too large for the tube).
    #[error("robust design infeasible for `robust.eps` = {eps}: {reason}")]
    Infeasible {
        /// The design ε.
        eps: f64,
        /// Which bound became empty, with the numbers.
        reason: String,
    },
    /// A pipeline stage of the robust run failed.
    #[error(transparent)]
    Pipeline(#[from] PipelineError),
    /// Reading or writing a file of the robust run.
    #[error("robust design: {0}")]
    Io(String),
}

/// How the supremum over the Jacobians was obtained.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum JacobianBound {
    /// Constant Jacobians (linear system): exact.
    Exact,
    /// Vertex enumeration of a multi-affine Jacobian family: sound on all of R^nx × R^nu.
    Vertices,
    /// Maximum over random samples of X × U: an estimate.
    SampledEstimate,
}

/// A finite family of Jacobian pairs (A, B) of F whose norms bound the sup over ξ.
#[derive(Debug, Clone)]
pub struct JacobianSet {
    /// ∂F/∂x, nx × nx.
    pub a: Vec<DMatrix<f64>>,
    /// ∂F/∂u, nx × nu.
    pub b: Vec<DMatrix<f64>>,
    /// Soundness of the family.
    pub bound: JacobianBound,
}

/// The RK4 Jacobian of the pendulum with the stage cosines `c` (4 per sub-step,
/// `c = cos(x₁)` at each RK4 stage point) given freely: multi-affine in `c`.
pub fn pendulum_rk4_jacobian(
    p: &Pendulum,
    ts: f64,
    substeps: usize,
    c: &[f64],
) -> (DMatrix<f64>, DMatrix<f64>) {
    let a_g = p.g / p.l;
    let bu = 1.0 / (p.m * p.l * p.l);
    let h = ts / substeps as f64;
    let mut a_tot = DMatrix::<f64>::identity(2, 2);
    let mut b_tot = DMatrix::<f64>::zeros(2, 1);
    for s in 0..substeps {
        // Tangents as 2×3 matrices (columns x₁, x₂, u).
        let x0 = DMatrix::from_row_slice(2, 3, &[1.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
        let eu = DMatrix::from_row_slice(2, 3, &[0.0, 0.0, 0.0, 0.0, 0.0, bu]);
        let jac = |ci: f64| DMatrix::from_row_slice(2, 2, &[0.0, 1.0, a_g * ci, 0.0]);
        let cs = &c[4 * s..4 * s + 4];
        let k1 = jac(cs[0]) * &x0 + &eu;
        let k2 = jac(cs[1]) * (&x0 + &k1 * (h / 2.0)) + &eu;
        let k3 = jac(cs[2]) * (&x0 + &k2 * (h / 2.0)) + &eu;
        let k4 = jac(cs[3]) * (&x0 + &k3 * h) + &eu;
        let d = &x0 + (k1 + k2 * 2.0 + k3 * 2.0 + k4) * (h / 6.0);
        let a_s = d.columns(0, 2).into_owned();
        let b_s = d.columns(2, 1).into_owned();
        b_tot = &a_s * b_tot + b_s;
        a_tot = a_s * a_tot;
    }
    (a_tot, b_tot)
}

fn linearize_at(model: &Discrete, x: &[f64], u: &[f64]) -> (DMatrix<f64>, DMatrix<f64>) {
    let (nx, nu) = (model.nx(), model.nu());
    let (mut f, mut jx, mut ju) = (vec![0.0; nx], vec![0.0; nx * nx], vec![0.0; nx * nu]);
    model.linearize(x, u, &mut f, &mut jx, &mut ju);
    (
        DMatrix::from_row_slice(nx, nx, &jx),
        DMatrix::from_row_slice(nx, nu, &ju),
    )
}

/// The Jacobian family of the problem's discrete dynamics (see the module doc).
pub fn jacobian_set(cfg: &ProblemConfig) -> JacobianSet {
    let model = Discrete::new(cfg.system.clone(), cfg.ocp.ts, cfg.ocp.rk4_substeps);
    let (nx, nu) = (model.nx(), model.nu());
    match &cfg.system {
        System::DoubleIntegrator(_) => {
            let (a, b) = linearize_at(&model, &vec![0.0; nx], &vec![0.0; nu]);
            JacobianSet {
                a: vec![a],
                b: vec![b],
                bound: JacobianBound::Exact,
            }
        }
        System::Pendulum(p) if model.substeps <= 2 => {
            let nc = 4 * model.substeps;
            let (mut av, mut bv) = (Vec::new(), Vec::new());
            for mask in 0..(1usize << nc) {
                let c: Vec<f64> = (0..nc)
                    .map(|i| if mask >> i & 1 == 1 { 1.0 } else { -1.0 })
                    .collect();
                let (a, b) = pendulum_rk4_jacobian(p, model.ts, model.substeps, &c);
                av.push(a);
                bv.push(b);
            }
            JacobianSet {
                a: av,
                b: bv,
                bound: JacobianBound::Vertices,
            }
        }
        _ => {
            let s = &cfg.robust;
            let (mut av, mut bv) = (Vec::new(), Vec::new());
            let (ulo, uhi) = (&cfg.ocp.u_lo, &cfg.ocp.u_hi);
            for n in 0..s.samples as u64 {
                let x: Vec<f64> = (0..nx)
                    .map(|i| {
                        let (l, h) = (cfg.domain.lo[i], cfg.domain.hi[i]);
                        l + (h - l) * uniform(s.seed, n, i as u64)
                    })
                    .collect();
                let u: Vec<f64> = (0..nu)
                    .map(|j| {
                        let (l, h) = (ulo[j].max(-1e3), uhi[j].min(1e3));
                        l + (h - l) * uniform(s.seed, n, (nx + j) as u64)
                    })
                    .collect();
                let (a, b) = linearize_at(&model, &x, &u);
                av.push(a);
                bv.push(b);
            }
            JacobianSet {
                a: av,
                b: bv,
                bound: JacobianBound::SampledEstimate,
            }
        }
    }
}

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
        let (rho, lb) = contraction(js, k, p);
        let w = eps * lb;
        let mut s = vec![0.0; horizon + 1];
        for i in 1..=horizon {
            s[i] = rho * s[i - 1] + w;
        }
        let pinv = p
            .clone()
            .try_inverse()
            .unwrap_or_else(|| DMatrix::from_element(p.nrows(), p.ncols(), f64::NAN));
        let x_margin = (0..p.nrows())
            .map(|i| pinv[(i, i)].max(0.0).sqrt())
            .collect();
        let u_margin = (0..k.nrows())
            .map(|j| {
                let kj = k.row(j);
                (kj * &pinv * kj.transpose())[(0, 0)].max(0.0).sqrt()
            })
            .collect();
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
            bound: js.bound,
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
                let d = m(i);
                if l[i].is_finite() {
                    l[i] += d;
                }
                if h[i].is_finite() {
                    h[i] -= d;
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
        Ok(st)
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

/// A robust design: the tube and the tightened bounds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Design {
    /// The tube.
    pub tube: Tube,
    /// The tightened OCP bounds.
    pub stages: StageBounds,
}

/// Designs the tube (LQR gain of the linearisation at the origin, its Riccati matrix as P,
/// the input weight chosen from `robust.lqr_r_scales` to minimise [`Tube::score`]) or the
/// Lipschitz tightening, and tightens the bounds for `cfg.robust.eps`.
pub fn design(cfg: &ProblemConfig) -> Result<Design, RobustError> {
    let rs = &cfg.robust;
    let js = jacobian_set(cfg);
    let (nx, nu) = (cfg.system.nx(), cfg.system.nu());
    let n = cfg.ocp.horizon;
    let tube = match rs.method {
        RobustMethod::Lipschitz => Tube::new(
            &js,
            &DMatrix::zeros(nu, nx),
            &DMatrix::identity(nx, nx),
            rs.eps,
            n,
            RobustMethod::Lipschitz,
        ),
        RobustMethod::Tube => {
            let model = Discrete::new(cfg.system.clone(), cfg.ocp.ts, cfg.ocp.rk4_substeps);
            let x0: Vec<f64> = (0..nx)
                .map(|i| 0.0f64.clamp(cfg.domain.lo[i], cfg.domain.hi[i]))
                .collect();
            let u0: Vec<f64> = (0..nu)
                .map(|j| 0.0f64.clamp(cfg.ocp.u_lo[j], cfg.ocp.u_hi[j]))
                .collect();
            let (a0, b0) = linearize_at(&model, &x0, &u0);
            let q = rs
                .lqr_q
                .as_ref()
                .and_then(|m| m.to_dmatrix())
                .unwrap_or_else(|| cfg.q());
            let mut best: Option<(f64, Tube)> = None;
            for &scale in &rs.lqr_r_scales {
                let Some((p, k)) = dare(&a0, &b0, &q, &(cfg.r() * scale)) else {
                    continue;
                };
                let mut t = Tube::new(&js, &k, &p, rs.eps, n, RobustMethod::Tube);
                t.lqr_r_scale = Some(scale);
                let sc = t.score(cfg);
                if best.as_ref().is_none_or(|b| sc < b.0) {
                    best = Some((sc, t));
                }
            }
            best.ok_or_else(|| RobustError::Infeasible {
                eps: rs.eps,
                reason: "the Riccati equation of the linearisation at the origin has no \
                         stabilising solution for any robust.lqr_r_scales"
                    .into(),
            })?
            .1
        }
    };
    let stages = tube.tighten(cfg)?;
    Ok(Design { tube, stages })
}

/// The data-generating problem of a design: `cfg` with the tightened stage bounds, named
/// `robust` (so a run goes to `DIR/<name>/robust/`). The constant bounds remain the true
/// constraints (actuator limits and the violation check of the closed loop).
pub fn robust_config(cfg: &ProblemConfig, d: &Design) -> ProblemConfig {
    let mut r = cfg.clone();
    r.name = "robust".into();
    r.ocp.stages = Some(d.stages.clone());
    r
}

/// Whether a trained net's certified ε covers the design ε.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Verdict {
    /// The ε the MPC was made robust against.
    pub design_eps: f64,
    /// The certified ε of the net (Theorem 1, or a tighter certificate).
    pub certified_eps: f64,
    /// certified_eps ≤ design_eps: Corollary 1 applies.
    pub certified: bool,
    /// One line for humans, with the numbers.
    pub message: String,
}

/// The verdict of a certificate against a design: the hook for local certificates /
/// adaptive refinement, which only need to supply a smaller `certified_eps`.
pub fn verdict(design_eps: f64, certified_eps: f64) -> Verdict {
    let certified = certified_eps.is_finite() && certified_eps <= design_eps;
    let message = if certified {
        format!(
            "certified: ε = {certified_eps:.4} ≤ design ε = {design_eps:.4}; Corollary 1 \
             applies (closed loop stays in the robust MPC's feasible set)"
        )
    } else {
        format!(
            "NOT certified: certified ε = {certified_eps:.4} exceeds the design ε = \
             {design_eps:.4} (factor {:.1}); the closed-loop guarantee does not hold, \
             only the Monte Carlo evidence below",
            certified_eps / design_eps
        )
    };
    Verdict {
        design_eps,
        certified_eps,
        certified,
        message,
    }
}

/// Aggregate of a set of closed-loop runs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunSummary {
    /// Number of runs.
    pub runs: usize,
    /// Runs with at least one violating step.
    pub runs_violating: usize,
    /// Violating steps over all runs.
    pub violation_steps: usize,
    /// Share of violating steps in %.
    pub violation_percent: f64,
    /// Largest violation.
    pub max_violation: f64,
    /// Largest input divergence from the MPC along the trajectories.
    pub max_input_divergence: f64,
    /// Steps where the robust MPC was infeasible at the visited state.
    pub mpc_soft_steps: usize,
    /// Mean closed-loop cost.
    pub mean_cost: f64,
}

/// Summarises runs.
pub fn summarize(runs: &[Run]) -> RunSummary {
    let steps: usize = runs.iter().map(|r| r.steps).sum();
    let vs: usize = runs.iter().map(|r| r.violation_steps).sum();
    RunSummary {
        runs: runs.len(),
        runs_violating: runs.iter().filter(|r| r.violation_steps > 0).count(),
        violation_steps: vs,
        violation_percent: 100.0 * vs as f64 / steps.max(1) as f64,
        max_violation: runs.iter().map(|r| r.max_violation).fold(0.0, f64::max),
        max_input_divergence: runs
            .iter()
            .map(|r| r.max_input_divergence)
            .fold(0.0, f64::max),
        mpc_soft_steps: runs.iter().map(|r| r.mpc_soft_steps).sum(),
        mean_cost: runs.iter().map(|r| r.cost).sum::<f64>() / runs.len().max(1) as f64,
    }
}

/// Seeded uniform states of X at which the robust MPC (`rcfg`) is feasible (its hard
/// problem converges), `n` of them, in draw order.
pub fn feasible_states(rcfg: &ProblemConfig, n: usize, seed: u64) -> Vec<Vec<f64>> {
    let nx = rcfg.system.nx();
    let mut out = Vec::new();
    let mut next = 0u64;
    while out.len() < n && next < 200 * (n as u64 + 10) {
        let batch: Vec<Vec<f64>> = (next..next + 256)
            .map(|m| {
                (0..nx)
                    .map(|i| {
                        let (l, h) = (rcfg.domain.lo[i], rcfg.domain.hi[i]);
                        l + (h - l) * uniform(seed ^ 0xfea5, m, i as u64)
                    })
                    .collect()
            })
            .collect();
        next += 256;
        let ok: Vec<bool> = batch
            .par_iter()
            .map_init(
                || MpcLaw::new(rcfg),
                |law, x| law.solve(x, None).0.status == SqpStatus::Converged,
            )
            .collect();
        for (x, f) in batch.into_iter().zip(ok) {
            if f && out.len() < n {
                out.push(x);
            }
        }
    }
    out
}

/// The disturbances of the robust-MPC runs, with their `closed_loop.json` keys.
pub fn disturbances(eps: f64) -> Vec<(&'static str, Disturbance)> {
    vec![
        ("robust_mpc_bang+", Disturbance::BangBang { eps, period: 0 }),
        (
            "robust_mpc_bang-",
            Disturbance::BangBang {
                eps: -eps,
                period: 0,
            },
        ),
        (
            "robust_mpc_bang_alt",
            Disturbance::BangBang { eps, period: 5 },
        ),
        ("robust_mpc_adversarial", Disturbance::Adversarial { eps }),
        ("robust_mpc_random", Disturbance::Random { eps }),
    ]
}

/// The robust closed-loop study. Keys: `robust` (the robust-design net from the upswing
/// state, then from every Monte Carlo state; same per-run format as the other keys),
/// `nominal_net` (if given: the nominal design's net from the same states, its divergence
/// measured against the nominal MPC), `robust_mpc` (the robust MPC, no disturbance),
/// `robust_mpc_<disturbance>` (the robust MPC with the applied input κ(x) + e, |e| ≤ ε),
/// `nominal_mpc` (the untightened MPC, for the cost degradation). The MPC runs use the
/// upswing state and the first `disturbed_states` Monte Carlo states. Violations are
/// always measured against the true (untightened) constraints.
pub fn study(
    cfg: &ProblemConfig,
    rcfg: &ProblemConfig,
    net: (&Model, f64),
    nominal_net: Option<(&Model, f64)>,
    mc_states: &[Vec<f64>],
) -> ClosedLoop {
    let eps = cfg.robust.eps;
    let base = SimSettings {
        steps: cfg.closed_loop.steps,
        noise: vec![],
        seed: 0,
        mass_mismatch: 0.0,
        disturbance: Disturbance::None,
    };
    let up = crate::pipeline::initial_states(cfg)[0].clone();
    let mut net_x0 = vec![up.clone()];
    net_x0.extend(mc_states.iter().cloned());
    let mut mpc_x0 = vec![up];
    mpc_x0.extend(mc_states.iter().take(cfg.robust.disturbed_states).cloned());
    type Job<'a> = (
        String,
        bool,
        Option<(&'a Model, f64)>,
        Vec<f64>,
        SimSettings,
    );
    // (key, robust law?, net, x0, settings)
    let mut jobs: Vec<Job> = Vec::new();
    for x0 in &net_x0 {
        jobs.push(("robust".into(), true, Some(net), x0.clone(), base.clone()));
        if let Some(nn) = nominal_net {
            jobs.push((
                "nominal_net".into(),
                false,
                Some(nn),
                x0.clone(),
                base.clone(),
            ));
        }
    }
    for (i, x0) in mpc_x0.iter().enumerate() {
        jobs.push(("robust_mpc".into(), true, None, x0.clone(), base.clone()));
        jobs.push(("nominal_mpc".into(), false, None, x0.clone(), base.clone()));
        for (key, d) in disturbances(eps) {
            let s = SimSettings {
                disturbance: d,
                seed: i as u64,
                ..base.clone()
            };
            jobs.push((key.into(), true, None, x0.clone(), s));
        }
    }
    let runs: Vec<(String, Run)> = jobs
        .par_iter()
        .map_init(
            || (MpcLaw::new(rcfg), MpcLaw::new(cfg)),
            |(rlaw, nlaw), (key, robust, m, x0, s)| {
                let law = if *robust { rlaw } else { nlaw };
                let ctrl = match m {
                    Some((m, e)) => Controller::Net(
                        &m.mlp,
                        *e,
                        m.certificate
                            .as_ref()
                            .map(|c| (&c.clamp_lo[..], &c.clamp_hi[..])),
                    ),
                    None => Controller::Mpc,
                };
                (key.clone(), simulate(rcfg, law, &ctrl, x0, s))
            },
        )
        .collect();
    let mut out = ClosedLoop::new();
    for (k, r) in runs {
        out.entry(k).or_default().push(r);
    }
    out
}

/// What a robust run produced (also written as `robust.json`).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RobustReport {
    /// The design.
    pub design: Design,
    /// The certificate's verdict.
    pub verdict: Verdict,
    /// Parts of the certificate (ε_D, L_NN, L_MPC, r).
    pub certificate: BTreeMap<String, f64>,
    /// Whether the robust MPC's hard problem is feasible at the upswing state.
    pub upswing_feasible: bool,
    /// Monte Carlo states found in the robust MPC's feasible set.
    pub monte_carlo_states: usize,
    /// Summaries per `closed_loop.json` key.
    pub summaries: BTreeMap<String, RunSummary>,
    /// The upswing run per key (Table II rows).
    pub upswing: BTreeMap<String, RunSummary>,
    /// Mean cost of the robust MPC over that of the nominal MPC from the same states.
    pub cost_ratio_mean: f64,
    /// The same ratio for the upswing.
    pub cost_ratio_upswing: f64,
    /// Wall time of the closed-loop study in s.
    pub study_seconds: f64,
}

fn io(p: &Path, e: impl std::fmt::Display) -> RobustError {
    RobustError::Io(format!("{}: {e}", p.display()))
}

/// The robust design loop for `cfg` (with `cfg.robust.eps` > 0): design the tightened
/// MPC, run the pipeline's stages on it in `DIR/<name>/robust/` (data, training,
/// certificate, export, closed loop, report), add the robust closed-loop study to its
/// `closed_loop.json`, and write `robust.json` and `robust.md` with the verdict.
pub fn run(cfg: &ProblemConfig, opts: &RunOptions) -> Result<RobustReport, RobustError> {
    let d = design(cfg)?;
    let rcfg = robust_config(cfg, &d);
    let text = toml::to_string(&rcfg).map_err(|e| RobustError::Io(e.to_string()))?;
    let root: PathBuf = opts.root.join(&cfg.name);
    let dir = root.join(&rcfg.name);
    let mut o = opts.clone();
    o.root = root.clone();
    o.until = Some("closed_loop".into());
    crate::pipeline::run(&rcfg, &text, &o)?;
    let model_path = dir.join("model_regularized.bin");
    let mut net = Model::load(&model_path).map_err(|e| io(&model_path, e))?;
    let cpath = dir.join("certificate.json");
    let ctext = std::fs::read_to_string(&cpath).map_err(|e| io(&cpath, e))?;
    let cert: Certificate = serde_json::from_str(&ctext).map_err(|e| io(&cpath, e))?;
    net.certificate = Some(cert.clone());
    let mut cert = cert;
    let mut v = verdict(cfg.robust.eps, cert.eps);
    if !v.certified && cfg.robust.refine {
        // The design loop's second step: refine data and network with local certificates
        // until the certified ε meets the design ε (or the refinement budget is spent).
        let mut fcfg = rcfg.clone();
        fcfg.refine.target_eps = cfg.robust.eps;
        let rdir = dir.join("refine");
        std::fs::create_dir_all(&rdir).map_err(|e| io(&rdir, e))?;
        let r = crate::certify::refine::refine(
            &fcfg,
            &fcfg.refine,
            Some(&rdir.join("refine_state.bin")),
            &crate::certify::refine::RefineOptions::default(),
        )
        .map_err(|e| io(&rdir, e))?;
        let lc = crate::certify::refine::write_outputs(&fcfg, &fcfg.refine, &r, &rdir)
            .map_err(|e| io(&rdir, e))?;
        if lc.base.eps < cert.eps {
            net = r.model;
            net.certificate = Some(lc.base.clone());
            cert = lc.base;
            v = verdict(cfg.robust.eps, cert.eps);
        }
    }

    // The study (skipped when closed_loop.json already holds it for the same inputs).
    let clpath = dir.join("closed_loop.json");
    let cltext = std::fs::read_to_string(&clpath).map_err(|e| io(&clpath, e))?;
    let mut cl: ClosedLoop = serde_json::from_str(&cltext).map_err(|e| io(&clpath, e))?;
    let nominal_hash = std::fs::read(root.join("model_regularized.bin"))
        .map(|b| crate::io::hex(&<sha2::Sha256 as sha2::Digest>::digest(&b)))
        .unwrap_or_default();
    let inputs = format!(
        "{}|{}|{}|{}|{}|{}",
        env!("CARGO_PKG_VERSION"),
        nominal_hash,
        rcfg.problem_hash(),
        cert.hash,
        serde_json::to_string(&cfg.robust).unwrap_or_default(),
        serde_json::to_string(&cfg.closed_loop).unwrap_or_default()
    );
    let spath = dir.join("robust_study.json");
    let cached: Option<(String, RobustReport)> = std::fs::read_to_string(&spath)
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok());
    let up = crate::pipeline::initial_states(cfg)[0].clone();
    if let Some((inp, rep)) = cached {
        if inp == inputs && cl.contains_key("robust") && rep.verdict == v {
            return Ok(rep);
        }
    }
    let t = std::time::Instant::now();
    let upswing_feasible = MpcLaw::new(&rcfg).solve(&up, None).0.status == SqpStatus::Converged;
    let mc = feasible_states(&rcfg, cfg.robust.monte_carlo_states, cfg.robust.seed);
    // The nominal design's net (from the nominal run in `DIR/<name>/`), for comparison.
    let load_nominal = || -> Option<(Model, f64)> {
        let m = Model::load(&root.join("model_regularized.bin")).ok()?;
        let c: Certificate =
            serde_json::from_str(&std::fs::read_to_string(root.join("certificate.json")).ok()?)
                .ok()?;
        Some((m, c.eps))
    };
    let nominal = load_nominal();
    let st = study(
        cfg,
        &rcfg,
        (&net, cert.eps),
        nominal.as_ref().map(|(m, e)| (m, *e)),
        &mc,
    );
    let study_seconds = t.elapsed().as_secs_f64();
    let mut summaries = BTreeMap::new();
    let mut upswing = BTreeMap::new();
    for (k, runs) in &st {
        summaries.insert(k.clone(), summarize(runs));
        upswing.insert(k.clone(), summarize(&runs[..1]));
    }
    let ratio = |a: &[Run], b: &[Run]| {
        let n = a.len().min(b.len());
        a[..n].iter().map(|r| r.cost).sum::<f64>() / b[..n].iter().map(|r| r.cost).sum::<f64>()
    };
    let (rm, nm) = (&st["robust_mpc"], &st["nominal_mpc"]);
    let rep = RobustReport {
        design: d,
        verdict: v,
        certificate: BTreeMap::from([
            ("eps".to_string(), cert.eps),
            ("eps_d".to_string(), cert.eps_d),
            ("l_nn".to_string(), cert.l_nn),
            ("l_mpc".to_string(), cert.l_mpc),
            ("covering_radius".to_string(), cert.covering_radius),
        ]),
        upswing_feasible,
        monte_carlo_states: mc.len(),
        summaries,
        upswing,
        cost_ratio_mean: ratio(rm, nm),
        cost_ratio_upswing: rm[0].cost / nm[0].cost,
        study_seconds,
    };
    for (k, runs) in st {
        cl.insert(k, runs);
    }
    let text = serde_json::to_string(&cl).map_err(|e| io(&clpath, e))?;
    write_atomic(&clpath, text.as_bytes()).map_err(|e| io(&clpath, e))?;
    let json = serde_json::to_string_pretty(&rep).map_err(|e| io(&dir, e))?;
    write_atomic(&dir.join("robust.json"), json.as_bytes()).map_err(|e| io(&dir, e))?;
    write_atomic(&dir.join("robust.md"), markdown(&rep).as_bytes()).map_err(|e| io(&dir, e))?;
    let cached = serde_json::to_string(&(&inputs, &rep)).map_err(|e| io(&spath, e))?;
    write_atomic(&spath, cached.as_bytes()).map_err(|e| io(&spath, e))?;
    // The report stage (re-runs because closed_loop.json changed).
    let mut o = opts.clone();
    o.root = root;
    crate::pipeline::run(&rcfg, &text, &o)?;
    Ok(rep)
}

/// `robust.md`: design, verdict, Table II rows and the Monte Carlo summaries.
pub fn markdown(r: &RobustReport) -> String {
    let t = &r.design.tube;
    let mut s = String::new();
    s += "# Robust design (Corollary 1)\n\n";
    s += &format!(
        "Design ε = {} ({:?}); ρ = {:.4}, w̄ = {:.4e} ({:?}); K = {:?}, LQR R-scale {:?}\n\n",
        t.eps, t.method, t.rho, t.w, t.bound, t.k, t.lqr_r_scale
    );
    let n = t.s.len() - 1;
    s += &format!(
        "Tightening at stage N: states {:?}, inputs {:?} (ε + τ·s_(N−1))\n\n",
        t.x_margin.iter().map(|m| m * t.s[n]).collect::<Vec<_>>(),
        t.u_margin
            .iter()
            .map(|m| t.eps + m * t.s[n - 1])
            .collect::<Vec<_>>()
    );
    s += &format!("**{}**\n\n", r.verdict.message);
    s += &format!(
        "Certificate: {:?}\n\nUpswing state feasible for the robust MPC: {}; Monte Carlo \
         states: {}; robust/nominal MPC cost: mean {:.4}, upswing {:.4}\n\n",
        r.certificate,
        r.upswing_feasible,
        r.monte_carlo_states,
        r.cost_ratio_mean,
        r.cost_ratio_upswing
    );
    let table = |title: &str, m: &BTreeMap<String, RunSummary>| {
        let mut s = format!(
            "## {title}\n\n| key | runs | runs violating | % steps violating | max violation | \
             max input divergence | MPC infeasible steps | mean cost |\n|---|---|---|---|---|---|---|---|\n"
        );
        for (k, v) in m {
            s += &format!(
                "| {k} | {} | {} | {:.3} | {:.4} | {:.4} | {} | {:.2} |\n",
                v.runs,
                v.runs_violating,
                v.violation_percent,
                v.max_violation,
                v.max_input_divergence,
                v.mpc_soft_steps,
                v.mean_cost
            );
        }
        s + "\n"
    };
    s += &table("Upswing (Table II rows)", &r.upswing);
    s += &table("Monte Carlo", &r.summaries);
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mpc::sqp::SqpStatus;
    use crate::problem::{ConfigError, MatrixSpec};

    fn load(name: &str) -> ProblemConfig {
        let path = std::path::PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/"))
            .join(name);
        ProblemConfig::load(&path).unwrap()
    }

    fn pendulum(eps: f64) -> ProblemConfig {
        let mut c = ProblemConfig::default();
        c.robust.eps = eps;
        c
    }

    fn di(eps: f64) -> ProblemConfig {
        let mut c = load("double_integrator.toml");
        c.robust.eps = eps;
        c
    }

    /// σ_max of a 2×2 matrix in closed form.
    fn sigma_max_2x2(m: &DMatrix<f64>) -> f64 {
        let f2 = m.iter().map(|v| v * v).sum::<f64>();
        let det = m[(0, 0)] * m[(1, 1)] - m[(0, 1)] * m[(1, 0)];
        ((f2 + (f2 * f2 - 4.0 * det * det).max(0.0).sqrt()) / 2.0).sqrt()
    }

    #[test]
    fn double_integrator_lipschitz_tightening_in_closed_form() {
        let mut cfg = di(0.1);
        cfg.robust.method = RobustMethod::Lipschitz;
        let d = design(&cfg).unwrap();
        let t = &d.tube;
        let h: f64 = cfg.ocp.ts; // mass 1: A = [[1, h], [0, 1]], B = [h²/2, h]
        let lx = (h + (h * h + 4.0).sqrt()) / 2.0; // σ_max of the shear [[1, h], [0, 1]]
        let lu = h * (1.0 + h * h / 4.0).sqrt();
        assert_eq!(t.bound, JacobianBound::Exact);
        assert!((t.rho - lx).abs() < 1e-12, "{} vs {lx}", t.rho);
        assert!((t.w - 0.1 * lu).abs() < 1e-12);
        for k in 0..=cfg.ocp.horizon {
            let r = 0.1 * lu * (lx.powi(k as i32) - 1.0) / (lx - 1.0);
            assert!((t.s[k] - r).abs() < 1e-12 * (1.0 + r), "s_{k}");
        }
        // P = I: σ_i = 1; K = 0: the inputs lose exactly ε.
        for k in 1..=cfg.ocp.horizon {
            assert!((d.stages.x_hi[k - 1][1] - (1.0 - t.s[k])).abs() < 1e-12);
            assert!((d.stages.x_lo[k - 1][0] - (-5.0 + t.s[k])).abs() < 1e-12);
        }
        assert!(d.stages.u_hi.iter().all(|u| (u[0] - 0.9).abs() < 1e-12));
        assert!(d.stages.u_lo.iter().all(|u| (u[0] + 0.9).abs() < 1e-12));
    }

    #[test]
    fn double_integrator_tube_for_a_chosen_gain_by_hand() {
        let cfg = di(0.1);
        let js = jacobian_set(&cfg);
        let h: f64 = cfg.ocp.ts;
        let k = DMatrix::from_row_slice(1, 2, &[-2.0, -3.0]);
        let t = Tube::new(
            &js,
            &k,
            &DMatrix::identity(2, 2),
            0.1,
            cfg.ocp.horizon,
            RobustMethod::Tube,
        );
        let m = DMatrix::from_row_slice(
            2,
            2,
            &[
                1.0 - 2.0 * h * h / 2.0,
                h - 3.0 * h * h / 2.0,
                -2.0 * h,
                1.0 - 3.0 * h,
            ],
        );
        let rho = sigma_max_2x2(&m); // ≈ 1.013: P = I is not a contraction metric here
        assert!((rho - 1.0).abs() > 1e-3);
        assert!((t.rho - rho).abs() < 1e-12, "{} vs {rho}", t.rho);
        let w = 0.1 * h * (1.0 + h * h / 4.0).sqrt();
        assert!((t.w - w).abs() < 1e-12);
        for kk in 0..=cfg.ocp.horizon {
            let r = w * (1.0 - rho.powi(kk as i32)) / (1.0 - rho);
            assert!((t.s[kk] - r).abs() < 1e-12);
        }
        assert!((t.u_margin[0] - 13f64.sqrt()).abs() < 1e-12);
        let st = t.tighten(&cfg).unwrap();
        let n = cfg.ocp.horizon;
        assert!((st.u_hi[n - 1][0] - (1.0 - 0.1 - 13f64.sqrt() * t.s[n - 1])).abs() < 1e-12);
        assert!((st.u_hi[0][0] - 0.9).abs() < 1e-12);
    }

    #[test]
    fn pendulum_vertex_jacobian_matches_the_ad_linearisation() {
        let p = Pendulum::default();
        for substeps in [1usize, 2] {
            let model = Discrete::new(System::Pendulum(p.clone()), 0.05, substeps);
            for n in 0..20u64 {
                let x = [
                    -6.0 + 12.0 * uniform(3, n, 0),
                    -3.0 + 6.0 * uniform(3, n, 1),
                ];
                let u = [-15.0 + 30.0 * uniform(3, n, 2)];
                // The stage cosines of the actual RK4 step.
                let h = 0.05 / substeps as f64;
                let f = |x: [f64; 2]| [x[1], u[0] - 9.81 * (x[0] + std::f64::consts::PI).sin()];
                let mut c = Vec::new();
                let mut xs = x;
                for _ in 0..substeps {
                    let k1 = f(xs);
                    let p2 = [xs[0] + h / 2.0 * k1[0], xs[1] + h / 2.0 * k1[1]];
                    let k2 = f(p2);
                    let p3 = [xs[0] + h / 2.0 * k2[0], xs[1] + h / 2.0 * k2[1]];
                    let k3 = f(p3);
                    let p4 = [xs[0] + h * k3[0], xs[1] + h * k3[1]];
                    let k4 = f(p4);
                    c.extend([xs[0].cos(), p2[0].cos(), p3[0].cos(), p4[0].cos()]);
                    for i in 0..2 {
                        xs[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
                    }
                }
                let (a, b) = pendulum_rk4_jacobian(&p, 0.05, substeps, &c);
                let (a2, b2) = linearize_at(&model, &x, &u);
                assert!((&a - &a2).amax() < 1e-12, "{a} vs {a2}");
                assert!((&b - &b2).amax() < 1e-12, "{b} vs {b2}");
            }
        }
    }

    /// Simulates the error dynamics x⁺ = F(x, v + K(x − z) + e), z⁺ = F(z, v) along random
    /// nominal trajectories with bang-bang, alternating, random and greedy worst-case
    /// |e| ≤ ε, and checks ‖x_k − z_k‖_P ≤ s_k and |x_k,i − z_k,i| ≤ σ_i s_k. Returns the
    /// largest ratio ‖Δ_k‖_P / s_k seen.
    fn check_tube_soundness(cfg: &ProblemConfig, trajectories: u64) -> f64 {
        let d = design(cfg).unwrap();
        let t = &d.tube;
        let model = Discrete::new(cfg.system.clone(), cfg.ocp.ts, cfg.ocp.rk4_substeps);
        let nx = cfg.system.nx();
        let p = DMatrix::from_fn(nx, nx, |i, j| t.p[i][j]);
        let k = DMatrix::from_fn(1, nx, |_, j| t.k[0][j]);
        let pnorm = |d: &[f64]| {
            let v = nalgebra::DVector::from_column_slice(d);
            (v.transpose() * &p * &v)[(0, 0)].sqrt()
        };
        let eps = cfg.robust.eps;
        let step = |x: &[f64], z: &[f64], v: f64, e: f64| {
            let dz: Vec<f64> = (0..nx).map(|i| x[i] - z[i]).collect();
            let kd = (0..nx).map(|i| k[(0, i)] * dz[i]).sum::<f64>();
            let mut out = vec![0.0; nx];
            model.step(x, &[v + kd + e], &mut out);
            out
        };
        let mut worst_ratio = 0.0f64;
        for n in 0..trajectories {
            for mode in 0..4 {
                let mut z: Vec<f64> = (0..nx)
                    .map(|i| {
                        let (l, h) = (cfg.domain.lo[i], cfg.domain.hi[i]);
                        l + (h - l) * uniform(11, n, i as u64)
                    })
                    .collect();
                let mut x = z.clone();
                for kk in 0..cfg.ocp.horizon {
                    let (ul, uh) = (cfg.ocp.u_lo[0], cfg.ocp.u_hi[0]);
                    let v = ul + (uh - ul) * uniform(12, n, kk as u64);
                    let e = match mode {
                        0 => eps,
                        1 => {
                            if kk % 2 == 0 {
                                eps
                            } else {
                                -eps
                            }
                        }
                        2 => eps * (2.0 * uniform(13, n, kk as u64) - 1.0),
                        _ => {
                            let mut zn = vec![0.0; nx];
                            model.step(&z, &[v], &mut zn);
                            let grow = |e: f64| {
                                let xn = step(&x, &z, v, e);
                                pnorm(&(0..nx).map(|i| xn[i] - zn[i]).collect::<Vec<_>>())
                            };
                            if grow(eps) >= grow(-eps) {
                                eps
                            } else {
                                -eps
                            }
                        }
                    };
                    let xn = step(&x, &z, v, e);
                    let mut zn = vec![0.0; nx];
                    model.step(&z, &[v], &mut zn);
                    x = xn;
                    z = zn;
                    let dlt: Vec<f64> = (0..nx).map(|i| x[i] - z[i]).collect();
                    let s = t.s[kk + 1];
                    let pn = pnorm(&dlt);
                    assert!(
                        pn <= s * (1.0 + 1e-9) + 1e-14,
                        "‖Δ_{}‖_P = {pn} > s = {s} (mode {mode})",
                        kk + 1
                    );
                    for i in 0..nx {
                        assert!(dlt[i].abs() <= t.x_margin[i] * s * (1.0 + 1e-9) + 1e-14);
                    }
                    worst_ratio = worst_ratio.max(pn / s);
                }
            }
        }
        worst_ratio
    }

    #[test]
    fn tube_is_sound_for_the_error_dynamics() {
        let r = check_tube_soundness(&di(0.1), 50);
        eprintln!("double integrator: largest ‖Δ‖_P / s_k = {r:.4}");
        // Bang-bang at the bound of a linear system nearly attains the bound.
        assert!(r > 0.5, "{r}");
        let r = check_tube_soundness(&pendulum(0.5), 200);
        eprintln!("pendulum: largest ‖Δ‖_P / s_k = {r:.4}");
        assert!(r > 0.05, "{r}");
    }

    #[test]
    fn pendulum_design_is_a_contraction_and_leaves_the_upswing_feasible() {
        let cfg = pendulum(0.5);
        let d = design(&cfg).unwrap();
        let t = &d.tube;
        eprintln!(
            "ρ {:.5} w̄ {:.4e} K {:?} scale {:?} s_N {:.4} σ {:?} τ {:?}",
            t.rho, t.w, t.k, t.lqr_r_scale, t.s[20], t.x_margin, t.u_margin
        );
        assert_eq!(t.bound, JacobianBound::Vertices);
        assert!(t.rho < 1.0, "ρ = {}", t.rho);
        assert!(
            d.stages.x_hi.iter().all(|x| x[1] > 0.3),
            "{:?}",
            d.stages.x_hi
        );
        // The Lipschitz tightening is hopeless here.
        let mut lip = cfg.clone();
        lip.robust.method = RobustMethod::Lipschitz;
        let e = design(&lip).unwrap_err();
        eprintln!("lipschitz: {e}");
        assert!(matches!(e, RobustError::Infeasible { .. }));
        // The robust MPC swings up from (−π, 0) under adversarial input errors |e| ≤ ε.
        let rcfg = robust_config(&cfg, &d);
        let mut law = MpcLaw::new(&rcfg);
        let up = [-std::f64::consts::PI, 0.0];
        assert_eq!(law.solve(&up, None).0.status, SqpStatus::Converged);
        for (key, dist) in disturbances(0.5) {
            let s = SimSettings {
                steps: 90,
                noise: vec![],
                seed: 1,
                mass_mismatch: 0.0,
                disturbance: dist,
            };
            let r = simulate(&rcfg, &mut law, &Controller::Mpc, &up, &s);
            eprintln!(
                "{key}: viol {} max {:.3e} soft {} cost {:.2} last {:?}",
                r.violation_steps,
                r.max_violation,
                r.mpc_soft_steps,
                r.cost,
                r.x.last()
            );
            assert_eq!(r.violation_steps, 0, "{key}");
            assert_eq!(r.mpc_soft_steps, 0, "{key}");
            assert_eq!(r.mpc_failures, 0, "{key}");
        }
    }

    /// ∂κ/∂x of the tightened OCP against central differences, at states where a
    /// tightened (stage-dependent) bound is active; and the solution against the
    /// reference QP solver (clarabel).
    #[test]
    fn tightened_ocp_sensitivities_match_finite_differences_and_clarabel() {
        let cfg = pendulum(0.5);
        let d = design(&cfg).unwrap();
        let rcfg = robust_config(&cfg, &d);
        let mut law = MpcLaw::new(&rcfg);
        let mut reference = rcfg.clone();
        reference.solver.qp = crate::mpc::qp::QpSolverKind::Clarabel;
        let mut ref_law = MpcLaw::new(&reference);
        let ocp = crate::mpc::ocp::Ocp::new(&rcfg, false);
        // States along the robust upswing (x₂ rides its tightened bound).
        let s = SimSettings {
            steps: 40,
            noise: vec![],
            seed: 0,
            mass_mismatch: 0.0,
            disturbance: Disturbance::None,
        };
        let run = simulate(
            &rcfg,
            &mut law,
            &Controller::Mpc,
            &[-std::f64::consts::PI, 0.0],
            &s,
        );
        let h = 1e-6;
        let (mut checked, mut with_tight_active) = (0, 0);
        for x in run.x.iter().step_by(3) {
            let (l, sol) = law.solve(x, None);
            assert_eq!(l.status, SqpStatus::Converged);
            let (lr, _) = ref_law.solve(x, None);
            assert!(
                (l.u[0] - lr.u[0]).abs() < 1e-6,
                "{x:?}: {} vs {}",
                l.u[0],
                lr.u[0]
            );
            assert!((l.cost - lr.cost).abs() < 1e-6 * l.cost.max(1.0));
            if l.degeneracy.is_some() {
                continue;
            }
            let z = sol.unwrap().z;
            let tight_active = (1..=rcfg.ocp.horizon).any(|k| {
                let (lo, hi) = rcfg.ocp.x_bounds(k);
                (0..2).any(|i| {
                    let v = z[ocp.ix(k) + i];
                    ((v - hi[i]).abs() < 1e-7 && hi[i] < cfg.ocp.x_hi[i])
                        || ((v - lo[i]).abs() < 1e-7 && lo[i] > cfg.ocp.x_lo[i])
                })
            });
            let mut ok = true;
            let mut fd = [0.0; 2];
            for j in 0..2 {
                let (mut xp, mut xm) = (x.clone(), x.clone());
                xp[j] += h;
                xm[j] -= h;
                let up = law.solve(&xp, None).0.u[0];
                let um = law.solve(&xm, None).0.u[0];
                let (fwd, bwd) = ((up - l.u[0]) / h, (l.u[0] - um) / h);
                if (fwd - bwd).abs() > 1e-3 * (1.0 + fwd.abs()) {
                    ok = false; // a kink within ±h
                }
                fd[j] = (up - um) / (2.0 * h);
            }
            if !ok {
                continue;
            }
            for j in 0..2 {
                assert!(
                    (fd[j] - l.du_dx[j]).abs() <= 1e-4 * (1.0 + fd[j].abs()),
                    "{x:?}: ∂u/∂x{j} {} vs FD {}",
                    l.du_dx[j],
                    fd[j]
                );
            }
            checked += 1;
            if tight_active {
                with_tight_active += 1;
            }
        }
        eprintln!("checked {checked}, with a tightened bound active {with_tight_active}");
        assert!(checked >= 5 && with_tight_active >= 2);
    }

    fn mpc_monte_carlo(cfg: &ProblemConfig, states: usize, steps: usize) {
        let d = design(cfg).unwrap();
        let rcfg = robust_config(cfg, &d);
        let xs = feasible_states(&rcfg, states, 3);
        assert_eq!(xs.len(), states);
        let mut jobs = Vec::new();
        for (i, x) in xs.iter().enumerate() {
            for (key, dist) in disturbances(cfg.robust.eps) {
                jobs.push((key, i as u64, x.clone(), dist));
            }
        }
        let bad: Vec<String> = jobs
            .par_iter()
            .map_init(
                || MpcLaw::new(&rcfg),
                |law, (key, seed, x, dist)| {
                    let s = SimSettings {
                        steps,
                        noise: vec![],
                        seed: *seed,
                        mass_mismatch: 0.0,
                        disturbance: *dist,
                    };
                    let r = simulate(&rcfg, law, &Controller::Mpc, x, &s);
                    (r.violation_steps + r.mpc_soft_steps + r.mpc_failures > 0).then(|| {
                        format!(
                            "{key} from {x:?}: {} violations (max {:.3e}), {} infeasible, {} failed",
                            r.violation_steps, r.max_violation, r.mpc_soft_steps, r.mpc_failures
                        )
                    })
                },
            )
            .flatten()
            .collect();
        assert!(
            bad.is_empty(),
            "{} bad runs: {:?}",
            bad.len(),
            &bad[..bad.len().min(5)]
        );
    }

    #[test]
    fn double_integrator_monte_carlo_has_no_violations() {
        mpc_monte_carlo(&di(0.1), 100, 60);
    }

    #[test]
    fn pendulum_monte_carlo_has_no_violations() {
        mpc_monte_carlo(&pendulum(0.5), 16, 90);
    }

    #[test]
    fn settings_defaults_serialise_as_before_and_validate_with_keys() {
        let c = ProblemConfig::default();
        let text = toml::to_string(&c).unwrap();
        assert!(
            !text.contains("robust") && !text.contains("stages"),
            "{text}"
        );
        let mut r = c.clone();
        r.ocp.stages = Some(design(&pendulum(0.5)).unwrap().stages);
        assert_ne!(r.problem_hash(), c.problem_hash());
        let back = ProblemConfig::from_toml_str(&toml::to_string(&r).unwrap(), "r").unwrap();
        assert_eq!(back.ocp.stages, r.ocp.stages);
        let key = |edit: &dyn Fn(&mut ProblemConfig)| {
            let mut c = ProblemConfig::default();
            edit(&mut c);
            match c.validate() {
                Err(ConfigError::Invalid { key, .. }) => key,
                other => panic!("{other:?}"),
            }
        };
        assert_eq!(key(&|c| c.robust.eps = -1.0), "robust.eps");
        assert_eq!(
            key(&|c| c.robust.lqr_r_scales = vec![1.0, 0.0]),
            "robust.lqr_r_scales[1]"
        );
        assert_eq!(
            key(&|c| c.robust.lqr_q = Some(MatrixSpec::Diagonal(vec![1.0]))),
            "robust.lqr_q"
        );
        let st = r.ocp.stages.clone();
        assert_eq!(
            key(&|c| {
                c.ocp.stages = st.clone();
                c.ocp.stages.as_mut().unwrap().x_lo.pop();
            }),
            "ocp.stages.x_lo"
        );
        let parsed = ProblemConfig::from_toml_str(
            &format!(
                "{}\n[robust]\neps = 0.7\nmethod = \"lipschitz\"\n",
                crate::problem::PENDULUM_TOML
            ),
            "f",
        )
        .unwrap();
        assert_eq!(parsed.robust.eps, 0.7);
        assert_eq!(parsed.robust.method, RobustMethod::Lipschitz);
    }

    #[test]
    fn adversarial_disturbance_pushes_towards_the_nearest_bound() {
        let cfg = ProblemConfig::default();
        let model = Discrete::new(cfg.system.clone(), cfg.ocp.ts, 1);
        let d = Disturbance::Adversarial { eps: 0.5 };
        // x₂ near its upper bound 1: push up (∂x₂⁺/∂u > 0), so e = +ε.
        assert_eq!(d.at(&model, &cfg, 0, 0, &[0.0, 0.95], &[0.0]), vec![0.5]);
        // x₂ near −1: e = −ε.
        assert_eq!(d.at(&model, &cfg, 0, 0, &[0.0, -0.95], &[0.0]), vec![-0.5]);
        // x₁ near 2π with x₂ = 0: the x₁ bound is the nearest: e = +ε.
        assert_eq!(d.at(&model, &cfg, 0, 0, &[6.2, 0.0], &[0.0]), vec![0.5]);
        let b = Disturbance::BangBang {
            eps: 0.5,
            period: 2,
        };
        let seq: Vec<f64> = (0..6)
            .map(|k| b.at(&model, &cfg, k, 0, &[0.0, 0.0], &[0.0])[0])
            .collect();
        assert_eq!(seq, vec![0.5, 0.5, -0.5, -0.5, 0.5, 0.5]);
        let r = Disturbance::Random { eps: 0.5 };
        assert!((0..100).all(|k| r.at(&model, &cfg, k, 3, &[0.0, 0.0], &[0.0])[0].abs() <= 0.5));
    }

    /// The whole robust loop on the double integrator with small sizes: files, keys,
    /// per-run format, verdict, the certificate's U_d, and the cached second run.
    #[test]
    fn robust_run_end_to_end_on_the_double_integrator() {
        let mut cfg = di(0.1);
        cfg.robust.monte_carlo_states = 12;
        cfg.robust.disturbed_states = 3;
        cfg.closed_loop.steps = 40;
        cfg.closed_loop.random_initial_states = 2;
        cfg.closed_loop.noise_runs = 1;
        cfg.training.epochs = 50;
        cfg.training.validation_n = 50;
        let root = std::env::temp_dir().join(format!("ampc_robust_{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let opts = RunOptions {
            root: root.clone(),
            ..Default::default()
        };
        let rep = run(&cfg, &opts).unwrap();
        let dir = root.join("double_integrator").join("robust");
        for f in [
            "robust.json",
            "robust.md",
            "report.md",
            "certificate.json",
            "weights.rs",
        ] {
            assert!(dir.join(f).exists(), "{f}");
        }
        assert!(!rep.verdict.certified);
        assert_eq!(rep.monte_carlo_states, 12);
        let cl: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("closed_loop.json")).unwrap())
                .unwrap();
        let robust = cl["robust"].as_array().unwrap();
        assert_eq!(robust.len(), 13);
        for k in [
            "x0",
            "steps",
            "violation_steps",
            "max_violation",
            "max_input_divergence",
            "cost",
        ] {
            assert!(robust[0].get(k).is_some(), "{k}");
        }
        for (k, _) in disturbances(0.1) {
            let runs = cl[k].as_array().unwrap();
            assert_eq!(runs.len(), 4, "{k}");
            assert!(runs.iter().all(|r| r["violation_steps"] == 0), "{k}");
        }
        assert!(cl.get("mpc").is_some(), "the pipeline's own keys stay");
        let cert: Certificate =
            serde_json::from_str(&std::fs::read_to_string(dir.join("certificate.json")).unwrap())
                .unwrap();
        assert!((cert.u_hi[0] - 0.9).abs() < 1e-12 && (cert.u_lo[0] + 0.9).abs() < 1e-12);
        // Unchanged inputs: the study is not redone.
        let again = run(&cfg, &opts).unwrap();
        assert_eq!(again.study_seconds, rep.study_seconds);
        let _ = std::fs::remove_dir_all(&root);
    }

    #[test]
    fn verdict_compares_certified_with_design_eps() {
        assert!(verdict(0.5, 0.4).certified);
        assert!(verdict(0.5, 0.5).certified);
        let v = verdict(0.5, 31.0);
        assert!(!v.certified && v.message.contains("NOT certified") && v.message.contains("31"));
        assert!(!verdict(0.5, f64::NAN).certified);
    }
}
