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
//! tightened constraints: [`terminal`] computes the sublevel set
//! `X_f = {(x − x_r)ᵀP(x − x_r) ≤ α}` of the tube's Lyapunov function, proves (a) X_f ⊆ X_N,
//! (b) κ_f(X_f) ⊆ U_N and (c) robust invariance `ρ_f(√α + ρ^{N−1}w̄) + d₀ ≤ √α`, and the
//! tightened problem gets it as a terminal constraint. Recursive feasibility of the **hard**
//! tightened OCP is then `proven` (linear plants, the pendulum), `sampled` (a sampled ρ, w̄
//! or ρ_f) or `unknown` (no region found); the closed-loop Monte Carlo still counts the
//! steps where the soft fallback was needed (`mpc_soft_steps`).
//!
//! Files: [`jacobians`] (the family of (A, B) and how its sup is bounded), [`tube`] (ρ, w̄,
//! the radii s_k and the tightening), [`terminal`] (the terminal region X_f),
//! [`terminal_nominal`] (the nominal terminal set, controller and cost of the
//! safety-augmented controller, without a tube), [`design`](mod@design) (the LQR choice, the tightened problem),
//! [`exclusion`] (the proof that an excluded box is infeasible for the tightened
//! OCP), [`verdict`](mod@verdict) (the verdict of a certificate against the design ε: certified,
//! conditional with what it rests on, or not certified). The robust closed-loop study is
//! `study::robust`; the design loop that runs the pipeline on the tightened problem is
//! `pipeline::robust`. Imports `problem`, `mpc` and `certify`.

pub mod design;
pub(crate) mod exclusion;
pub(crate) mod jacobians;
pub(crate) mod terminal;
pub mod terminal_nominal;
pub(crate) mod tube;
pub mod verdict;
pub(crate) mod verified;

pub use crate::problem::{RobustMethod, RobustSettings};
pub use design::{design, robust_config, Design, REFINE_TARGET_FRACTION};
pub use jacobians::{jacobian_set, pendulum_rk4_jacobian, JacobianBound, JacobianSet};
pub use terminal::{terminal_region, Feasibility, TerminalCheck, TerminalRegion};
pub use tube::{contraction, dare, AffineConstraint, Tube};
pub use verdict::{verdict, Check, Evidence, Verdict, VerdictStatus};

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
    /// An `[ocp]` constraint the tube cannot tighten (a nonlinear one): a robust guarantee
    /// would not cover it.
    #[error(
        "robust design: `{key}` is not tightened by the tube ({reason}): a robust guarantee \
         would not cover it. Write it as an affine constraint, remove it, or use the nominal \
         design"
    )]
    UntightenedConstraints {
        /// The constraint's key, e.g. `ocp.constraints[1]`.
        key: String,
        /// Why.
        reason: String,
    },
}

#[cfg(test)]
pub(crate) mod tests;
