//! `[solver]`: the SQP's tolerances, iteration limit, soft-constraint fallback and QP
//! backend.

use serde::{Deserialize, Serialize};

/// SQP settings (`[solver]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SolverSettings {
    /// Convergence tolerance on the scaled KKT residual (default 1e-8).
    pub tol: f64,
    /// Maximum SQP iterations (default 100).
    pub max_iter: usize,
    /// Label hard-infeasible states with the exact-penalty (soft) problem (default true).
    pub soft_fallback: bool,
    /// ℓ₁ weight of the state-bound slacks in the soft problem (default 1e4).
    pub soft_l1: f64,
    /// ℓ₂ weight of the state-bound slacks in the soft problem (default 1e2).
    pub soft_l2: f64,
    /// A constraint with slack ≤ this and multiplier ≤ this is weakly active (default 1e-7).
    pub degeneracy_tol: f64,
    /// Warm-start a sample from the nearest already-solved neighbour (default true).
    pub warm_start: bool,
    /// QP subproblem solver: `"structured"` (default; interior point on the banded OCP
    /// structure, cost linear in N, clarabel as fallback) or `"clarabel"` (reference).
    pub qp: QpSolverKind,
}

impl Default for SolverSettings {
    fn default() -> Self {
        SolverSettings {
            tol: 1e-8,
            max_iter: 100,
            soft_fallback: true,
            soft_l1: 1e4,
            soft_l2: 1e2,
            degeneracy_tol: 1e-7,
            warm_start: true,
            qp: QpSolverKind::default(),
        }
    }
}

/// Which QP solver the SQP uses (`solver.qp`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum QpSolverKind {
    /// Structure-exploiting primal-dual interior point (`mpc::qp::ipm`, banded KKT factorisation,
    /// cost linear in N), with clarabel as fallback for QPs it cannot solve.
    #[default]
    Structured,
    /// The general sparse conic solver clarabel (reference).
    Clarabel,
}
