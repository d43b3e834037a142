//! The **terminal region** of the tightened MPC: a sublevel set of the ancillary LQR's
//! Lyapunov function,
//!
//! ```text
//! X_f = { x : (x − x_r)ᵀ P (x − x_r) ≤ α },   c = √α   (a ball of radius c in ‖·‖_P),
//! κ_f(x) = u_r + K (x − x_r)                  (the local feedback, the tube's K and P)
//! ```
//! and the proof that it closes the recursive-feasibility argument of the tube
//! (`robust` module doc). With `s_k` the tube radii, `m = s_N − s_{N−1} = ρ^{N−1} w̄` the
//! deviation of the shifted candidate at its last stage, it must satisfy
//!
//! ```text
//! (a) x_r,i ± σ_i c  ∈ [x_lo,i + σ_i s_N, x_hi,i − σ_i s_N]         (X_f ⊆ X_N)
//! (b) u_r,j ± τ_j c  ∈ [u_lo,j + ε + τ_j s_N, u_hi,j − ε − τ_j s_N]  (κ_f(X_f) ⊆ U_N)
//! (c) ρ_f · (c + m) + d₀ ≤ c                                        (robust invariance)
//! ```
//! (d) every affine `[ocp]` constraint aₓᵀx + a_uᵀu ≤ b (path and terminal) holds on X_f
//! under κ_f with its stage-N margin (`tube` module doc):
//! `aₓᵀx_r + a_uᵀu_r + c·‖P^{−1/2}(aₓ + Kᵀa_u)‖₂ ≤ b − s_N‖P^{−1/2}(aₓ + Kᵀa_u)‖₂ − ε‖a_u‖₂`
//! (covering the shifted candidate's stage N − 1, whose deviation m = s_N − s_{N−1} the
//! margin's extra s_N − s_{N−1} absorbs, and its stage N).
//!
//! (a), (b), (d) are exact: the largest value of a row aᵀ(x − x_r) over the ellipsoid is its
//! support function `c·√(aᵀP⁻¹a)`, i.e. `σ_i c` and `τ_j c` with the tube's σ, τ. For (c):
//! a state within `m` of X_f, `‖y − x_r‖_P ≤ c + m`, is mapped by the local feedback to
//! `F(y, κ_f(y))` with
//! `‖F(y, κ_f(y)) − x_r‖_P ≤ ρ_f ‖y − x_r‖_P + d₀`, `d₀ = ‖F(x_r, u_r) − x_r‖_P`,
//! `ρ_f = sup_ξ ‖P^{1/2}(A(ξ) + B(ξ)K)P^{−1/2}‖₂` over ξ in that ball (mean-value theorem
//! along the segment from x_r). The candidate's last input `κ_f(z*_N) + Kδ = κ_f(z*_N + δ)`
//! then satisfies U_{N−1}, its last state lies in X_f again, so the shifted candidate is
//! feasible for the tightened OCP with the terminal constraint x_N ∈ X_f.
//!
//! How ρ_f is obtained ([`TerminalCheck`]):
//! - **linear plants** (constant Jacobians): exact — **proven**;
//! - **pendulum** (≤ 2 RK4 sub-steps): the same vertex argument as the tube's ρ, with the
//!   stage cosines restricted to the range cos takes on the ball's bounding box widened by
//!   the distance an RK4 stage point can move in one step (`ts·(|ω|max + ts·(g/l + |u|max/(ml²)))`):
//!   the linearisation remainder is bounded on that box — **proven**;
//! - **other plants**: the maximum over `robust.samples` seeded points of the ball's
//!   bounding box — **sampled** (an estimate).
//!
//! "Proven" means with rounding margins ([`super::verified`]): ρ_f, d₀ and the tube's ρ, w̄,
//! σ, τ and constraint factors are upper bounds proven by a Cholesky certificate of
//! ρ²Q − MᵀWM ≽ 0, m = ρ^{N−1}w̄ and the fits (a)–(d) and (c) are evaluated in outward
//! rounding, and α = c² is rounded down; when the arithmetic cannot prove a bound, ρ_f is
//! the f64 estimate and the check is `sampled`. The premise left: the Jacobians and
//! F(x_r, u_r) are the f64 values the code evaluates.
//!
//! The radius is the largest c ≤ c_max (from (a), (b)) of the sequence c_max·0.8^k that
//! satisfies (c). With `robust.terminal_constraint = true` the region is enforced as a
//! terminal constraint of the tightened OCP (`ocp.terminal_constraints`, a quadratic
//! expression linearised by the SQP like any other, [`TerminalRegion::constraint`]);
//! recursive feasibility of the hard tightened OCP is then [`Feasibility::Proven`] when ρ,
//! w̄ and ρ_f are all sound. Without it (the default: the region shrinks the feasible set —
//! the full pendulum's upswing is no longer feasible within the horizon) the region is
//! computed and reported but **not enforced**, and recursive feasibility is `unknown`. The
//! OCP's soft fallback (`solver.soft_fallback`) is outside the argument: the theorem is about
//! the hard problem, and the closed-loop study counts the steps that needed the fallback.

use super::jacobians::{linearize_at, pendulum_rk4_jacobian, JacobianBound};
use super::tube::{contraction, Tube};
use super::verified::{down, up};
use crate::problem::model::{Discrete, System};
use crate::problem::ProblemConfig;
use crate::rng::uniform;
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// How a claim of the robust loop is established.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Feasibility {
    /// Follows from the code's arithmetic (exact or vertex bounds).
    Proven,
    /// Rests on sampled bounds (an estimate).
    Sampled,
    /// Not established.
    Unknown,
}

impl Feasibility {
    /// The name written in files: `"proven"`, `"sampled"`, `"unknown"`.
    pub fn name(self) -> &'static str {
        match self {
            Feasibility::Proven => "proven",
            Feasibility::Sampled => "sampled",
            Feasibility::Unknown => "unknown",
        }
    }
}

/// How the local contraction rate ρ_f was bounded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TerminalCheck {
    /// Constant Jacobians: exact.
    Exact,
    /// Vertices of the stage-cosine box (pendulum): sound.
    Vertices,
    /// Maximum over seeded samples of the ball's bounding box: an estimate.
    Sampled,
}

/// The terminal region X_f = {(x − x_r)ᵀP(x − x_r) ≤ α} and its invariance certificate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TerminalRegion {
    /// Centre x_r.
    pub x_ref: Vec<f64>,
    /// Input at the centre u_r.
    pub u_ref: Vec<f64>,
    /// Level α = c².
    pub alpha: f64,
    /// Radius c = √α in the P-norm.
    pub radius: f64,
    /// Largest radius allowed by the tightened boxes, (a) and (b).
    pub radius_max: f64,
    /// The local contraction rate ρ_f on the ball of radius c + m.
    pub rho_local: f64,
    /// The candidate's last-stage deviation m = ρ^{N−1} w̄.
    pub margin: f64,
    /// d₀ = ‖F(x_r, u_r) − x_r‖_P (0 at an exact equilibrium).
    pub offset: f64,
    /// How ρ_f was bounded.
    pub check: TerminalCheck,
    /// The terminal constraint as text over the plant's state names.
    pub constraint: String,
    /// Whether the tightened OCP enforces it (`robust.terminal_constraint`).
    pub enforced: bool,
}

impl TerminalRegion {
    /// Whether the invariance (c) rests on a sound ρ_f.
    pub fn proven(&self) -> bool {
        self.check != TerminalCheck::Sampled
    }
}

fn mat(rows: &[Vec<f64>]) -> DMatrix<f64> {
    let (r, c) = (rows.len(), rows.first().map_or(0, Vec::len));
    DMatrix::from_fn(r, c, |i, j| rows[i][j])
}

/// The P-norm √(dᵀPd).
pub fn p_norm(p: &DMatrix<f64>, d: &[f64]) -> f64 {
    let v = DVector::from_column_slice(d);
    (v.transpose() * p * &v)[(0, 0)].max(0.0).sqrt()
}

/// The range of cos on [a, b].
fn cos_range(a: f64, b: f64) -> (f64, f64) {
    use std::f64::consts::PI;
    if b - a >= 2.0 * PI {
        return (-1.0, 1.0);
    }
    let contains = |t: f64| ((a - t) / (2.0 * PI)).ceil() * 2.0 * PI + t <= b;
    let hi = if contains(0.0) {
        1.0
    } else {
        a.cos().max(b.cos())
    };
    let lo = if contains(PI) {
        -1.0
    } else {
        a.cos().min(b.cos())
    };
    (lo, hi)
}

/// The centre of the region: the setpoint clamped into X and U (as in the tube's LQR).
fn centre(cfg: &ProblemConfig) -> (Vec<f64>, Vec<f64>) {
    let (nx, nu) = (cfg.system.nx(), cfg.system.nu());
    let (xr, ur) = (cfg.ocp.x_ref_or_origin(nx), cfg.ocp.u_ref_or_zero(nu));
    (
        (0..nx)
            .map(|i| xr[i].clamp(cfg.domain.lo[i], cfg.domain.hi[i]))
            .collect(),
        (0..nu)
            .map(|j| ur[j].clamp(cfg.ocp.u_lo[j], cfg.ocp.u_hi[j]))
            .collect(),
    )
}

/// ρ_f of a sound Jacobian family, proven with rounding margins
/// ([`super::tube::verified_contraction`]); the f64 estimate and `Sampled` when it cannot be.
fn proven_rate(
    js: &super::jacobians::JacobianSet,
    k: &DMatrix<f64>,
    p: &DMatrix<f64>,
    check: TerminalCheck,
) -> (f64, TerminalCheck) {
    let est = contraction(js, k, p);
    match super::tube::verified_contraction(js, k, p, est) {
        Some((rho, _)) => (rho, check),
        None => (est.0, TerminalCheck::Sampled),
    }
}

/// ρ_f over the P-ball of radius `r` around x_r, and how it was bounded.
fn local_rate(cfg: &ProblemConfig, t: &Tube, r: f64) -> (f64, TerminalCheck) {
    let (k, p) = (mat(&t.k), mat(&t.p));
    let (xr, ur) = centre(cfg);
    let model = Discrete::new(cfg.system.clone(), cfg.ocp.ts, cfg.ocp.rk4_substeps);
    let (nx, nu) = (model.nx(), model.nu());
    match &cfg.system {
        System::DoubleIntegrator(_) => {
            let (a, b) = linearize_at(&model, &xr, &ur);
            let js = super::jacobians::JacobianSet {
                a: vec![a],
                b: vec![b],
                bound: JacobianBound::Exact,
            };
            proven_rate(&js, &k, &p, TerminalCheck::Exact)
        }
        System::Pendulum(pd) if model.substeps <= 2 => {
            let ts = model.ts;
            let w_max = xr[1].abs() + t.x_margin[1] * r;
            let u_max = ur[0].abs() + t.u_margin[0] * r;
            let acc = pd.g / pd.l + u_max / (pd.m * pd.l * pd.l);
            let drift = ts * (w_max + ts * acc);
            let (lo, hi) = (
                xr[0] - t.x_margin[0] * r - drift,
                xr[0] + t.x_margin[0] * r + drift,
            );
            let (cl, ch) = cos_range(lo, hi);
            let nc = 4 * model.substeps;
            let (mut av, mut bv) = (Vec::new(), Vec::new());
            for mask in 0..(1usize << nc) {
                let c: Vec<f64> = (0..nc)
                    .map(|i| if mask >> i & 1 == 1 { ch } else { cl })
                    .collect();
                let (a, b) = pendulum_rk4_jacobian(pd, ts, model.substeps, &c);
                av.push(a);
                bv.push(b);
            }
            let js = super::jacobians::JacobianSet {
                a: av,
                b: bv,
                bound: JacobianBound::Vertices,
            };
            proven_rate(&js, &k, &p, TerminalCheck::Vertices)
        }
        _ => {
            let s = &cfg.robust;
            let (mut av, mut bv) = (Vec::new(), Vec::new());
            for n in 0..s.samples.max(1) as u64 {
                let x: Vec<f64> = (0..nx)
                    .map(|i| {
                        let h = t.x_margin[i] * r;
                        xr[i] - h + 2.0 * h * uniform(s.seed ^ 0x7e51, n, i as u64)
                    })
                    .collect();
                let d: Vec<f64> = (0..nx).map(|i| x[i] - xr[i]).collect();
                let u: Vec<f64> = (0..nu)
                    .map(|j| ur[j] + (0..nx).map(|i| t.k[j][i] * d[i]).sum::<f64>())
                    .collect();
                let (a, b) = linearize_at(&model, &x, &u);
                av.push(a);
                bv.push(b);
            }
            let js = super::jacobians::JacobianSet {
                a: av,
                b: bv,
                bound: JacobianBound::SampledEstimate,
            };
            (contraction(&js, &k, &p).0, TerminalCheck::Sampled)
        }
    }
}

/// The largest radius allowed by the tightened boxes and constraints at stage N, (a), (b)
/// and (d).
fn radius_max(cfg: &ProblemConfig, t: &Tube) -> f64 {
    let (xr, ur) = centre(cfg);
    let o = &cfg.ocp;
    let n = o.horizon;
    let sn = t.s[n];
    let mut c = f64::INFINITY;
    // Rounded down: the room and the radius it allows are never above the exact ones
    // (`per` and `shrink` are proven upper bounds, `verified`).
    let mut fit = |centre: f64, lo: f64, hi: f64, per: f64, shrink: f64| {
        let room = down(down(centre - up(lo + shrink)).min(down(down(hi - shrink) - centre)));
        if room < 0.0 || room.is_nan() || per.is_nan() {
            c = f64::NEG_INFINITY;
        } else if per > 0.0 {
            c = c.min(down(room / per));
        }
    };
    for i in 0..xr.len() {
        let m = t.x_margin[i];
        fit(xr[i], o.x_lo[i], o.x_hi[i], m, up(m * sn));
    }
    for j in 0..ur.len() {
        let m = t.u_margin[j];
        fit(ur[j], o.u_lo[j], o.u_hi[j], m, up(t.eps + up(m * sn)));
    }
    // (d) the affine `[ocp]` constraints under the local feedback, tightened as at stage N.
    match t.affine_constraints(cfg) {
        Ok(rows) => {
            for a in &rows {
                let at_ref: f64 = a.a_x.iter().zip(&xr).map(|(a, x)| a * x).sum::<f64>()
                    + a.a_u.iter().zip(&ur).map(|(a, u)| a * u).sum::<f64>();
                fit(at_ref, f64::NEG_INFINITY, a.b, a.per, t.margin(a, n));
            }
        }
        Err(_) => c = f64::NEG_INFINITY,
    }
    c
}

/// d₀ = ‖d‖_P proven with rounding margins (`verified`: dᵀPd ≤ d₀², d within u|d| of the
/// computed difference); `None` when not finite or not proven.
fn offset_bound(p: &DMatrix<f64>, d: &[f64]) -> Option<f64> {
    let n = d.len();
    let col = DMatrix::from_column_slice(n, 1, d);
    let radius = col.map(|v| v.abs() * f64::EPSILON);
    super::verified::bound(&col, &radius, p, &DMatrix::identity(1, 1), p_norm(p, d))
}

/// The terminal constraint `Σ P_ij (x_i − x_r,i)(x_j − x_r,j) <= α` over the state names.
fn constraint_text(cfg: &ProblemConfig, p: &[Vec<f64>], xr: &[f64], alpha: f64) -> String {
    let names = cfg.system.names().states;
    let mut terms = Vec::new();
    for i in 0..xr.len() {
        for j in 0..xr.len() {
            terms.push(format!(
                "({}) * ({} - ({})) * ({} - ({}))",
                p[i][j], names[i], xr[i], names[j], xr[j]
            ));
        }
    }
    format!("{} <= {}", terms.join(" + "), alpha)
}

/// The terminal region of a tube design (module doc), or None when no radius satisfies
/// (a)–(c) (e.g. the local feedback does not contract, ρ_f ≥ 1).
pub fn terminal_region(cfg: &ProblemConfig, t: &Tube) -> Option<TerminalRegion> {
    let n = cfg.ocp.horizon;
    if n == 0 || t.s.len() != n + 1 {
        return None;
    }
    let (xr, ur) = centre(cfg);
    let p = mat(&t.p);
    let model = Discrete::new(cfg.system.clone(), cfg.ocp.ts, cfg.ocp.rk4_substeps);
    let mut f = vec![0.0; xr.len()];
    model.step(&xr, &ur, &mut f);
    let d: Vec<f64> = f.iter().zip(&xr).map(|(a, b)| a - b).collect();
    // d₀ proven from F(x_r, u_r) as evaluated (the subtraction's rounding covered), and
    // m = ρ^{N−1} w̄ rounded up (not s_N − s_{N−1} of the rounded-up radii).
    let offset = offset_bound(&p, &d)?;
    let mut margin = t.w;
    for _ in 1..n {
        margin = up(margin * t.rho);
    }
    let cmax = radius_max(cfg, t);
    if !cmax.is_finite() || cmax <= 0.0 {
        return None;
    }
    let mut c = cmax;
    for _ in 0..60 {
        let (rho, check) = local_rate(cfg, t, up(c + margin));
        // (c) in outward rounding, for the level α = c² rounded down: states within m of
        // X_f lie within c + m of x_r and are mapped within √α.
        let alpha = down(c * c);
        if up(up(rho * up(c + margin)) + offset) <= down(alpha.sqrt()) {
            return Some(TerminalRegion {
                constraint: constraint_text(cfg, &t.p, &xr, alpha),
                x_ref: xr,
                u_ref: ur,
                alpha,
                radius: c,
                radius_max: cmax,
                rho_local: rho,
                margin,
                offset,
                check,
                enforced: cfg.robust.terminal_constraint,
            });
        }
        c *= 0.8;
    }
    None
}

#[cfg(test)]
#[path = "terminal_tests.rs"]
mod tests;
