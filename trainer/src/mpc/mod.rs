//! Stage 2 — the MPC law κ(x) = u₀*(x) and its sensitivity ∂κ/∂x.
//!
//! ```text
//! min_{x,u} Σ_k ℓ(x_k, u_k) + V_f(x_N)  s.t.  x_0 = x_s,  x_{k+1} = F(x_k, u_k),  x_k ∈ X, u_k ∈ U
//! ∂κ/∂x_s = −[0 I 0] K⁻¹ ∂r/∂x_s        (K the KKT matrix of the active set at the optimum)
//! ```
//! - [`ocp`]: the OCP's functions, constraints and their derivatives (from `problem::model`).
//! - [`sqp`]: the SQP solver (allocate once, `step`, `solve`), with [`qp`] inside it:
//!   the structured interior point (`qp::ipm`) or Clarabel.
//! - [`convexity`]: whether a QP subproblem is strictly convex on the dynamics' null space.
//! - [`kkt`]: banded KKT layouts and factorisations shared by the QP and the sensitivity.
//! - [`sensitivity`]: ∂u₀*/∂x_s from the converged KKT system, with degeneracy flags.
//! - [`law`]: one labelled state: hard OCP, soft fallback, warm starts.
//! - [`finite`]: the label gate — a solve is a label only if every number it rests on is
//!   finite and the KKT conditions hold when re-checked; NaN-keeping folds.
//!
//! Imports only `problem` (and the leaf modules `io`, `rng`).

pub(crate) mod convexity;
pub(crate) mod finite;
pub mod kkt;
pub mod law;
pub mod ocp;
pub mod qp;
pub(crate) mod sensitivity;
pub mod sqp;

// Tests only: the law against independent computations, with shared fixtures (`tests/`).
#[cfg(test)]
pub(crate) mod tests;
