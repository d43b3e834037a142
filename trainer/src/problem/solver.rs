//! `[solver]`: the SQP's tolerances, iteration limit, soft-constraint fallback, QP
//! backend and the initial guesses a label is solved from (`starts`).

use serde::{Deserialize, Serialize};

/// SQP settings (`[solver]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SolverSettings {
    /// Convergence tolerance on the scaled KKT residual (default 1e-8).
    pub tol: f64,
    /// Maximum SQP iterations (default 100).
    pub max_iter: usize,
    /// SQP iterations the hard rungs of the retry ladder (`crate::mpc::law`: conservative
    /// solve, continuations) may spend on one state that the plain solve left without a
    /// label, as a multiple of `max_iter` (default [`DEFAULT_RETRY_BUDGET`]; the soft rung
    /// keeps its own limits; 0: no ladder at all). A state the ladder gives up on is reported
    /// unlabelled with its plain solve's status, counted and located like any other.
    // (Not written at its default, so the problem hashes of files that do not set it stay
    // those of before the key existed.)
    #[serde(skip_serializing_if = "is_default_retry_budget")]
    pub retry_budget: usize,
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
    /// Initial guesses of the hard problem, the lowest-cost hard optimum kept
    /// (`crate::mpc::law` `starts` module). `None` (key absent): the default of the
    /// problem — `["warm"]` for a convex OCP; for a non-convex one [`default_starts`] if the
    /// problem's pilot (`crate::mpc::law::pilot`) finds them reaching another optimum, else
    /// `["warm"]`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub starts: Option<Vec<Start>>,
}

/// One initial guess of the hard problem (`solver.starts`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Start {
    /// Today's solve: from the previous state's solution in the chunk (when
    /// `solver.warm_start`), else cold (the setpoint input rolled out), retried cold, soft
    /// fallback and retry ladder.
    Warm,
    /// Inputs u_ref (clamped to the bounds), states x_ref: the setpoint everywhere.
    Zero,
    /// Inputs u_ref (clamped), every state x₀ (IPOPT's usual guess).
    #[serde(rename = "repeat_x0")]
    RepeatX0,
    /// The finite-horizon LQR of the linearisation at the setpoint (weights Q, R, terminal
    /// P), rolled out from x₀ with clamped inputs.
    Lqr,
    /// The solution of the nearest already labelled state of the chunk.
    Neighbour,
    /// Every input at its lower bound, rolled out from x₀ (one bang-bang direction).
    #[serde(rename = "u_lo")]
    ULo,
    /// Every input at its upper bound, rolled out from x₀ (the other direction).
    #[serde(rename = "u_hi")]
    UHi,
    /// A barrier homotopy (`crate::mpc::law::homotopy`): from the inputs at the middle of
    /// their bounds, the OCP with the input bounds replaced by a log barrier μ·Σ −ln(slack)
    /// solved for geometrically decreasing μ, each solve warm-started from the last, its
    /// last solution the guess of the true OCP (an interior-point method's path).
    Barrier,
}

impl Start {
    /// The name in problem files.
    pub fn as_str(self) -> &'static str {
        match self {
            Start::Warm => "warm",
            Start::Zero => "zero",
            Start::RepeatX0 => "repeat_x0",
            Start::Lqr => "lqr",
            Start::Neighbour => "neighbour",
            Start::ULo => "u_lo",
            Start::UHi => "u_hi",
            Start::Barrier => "barrier",
        }
    }
}

/// The starts a non-convex OCP's pilot tries (`crate::mpc::law::pilot`; kept when they
/// matter there): `["warm"]` for a convex OCP (affine
/// dynamics, no nonlinear constraint: one optimum, one start), and for a non-convex one
/// `["warm", "u_lo", "u_hi"]` — the two bang-bang rollouts reach the other swing direction
/// of swing-up problems (BENCHMARKS.md, "Multi-start labels": the best of the 3-start lists
/// measured, at about 1.5× the pendulum's labelling time).
pub fn default_starts(convex: bool) -> Vec<Start> {
    if convex {
        vec![Start::Warm]
    } else {
        vec![Start::Warm, Start::ULo, Start::UHi]
    }
}

/// Default `solver.retry_budget`: the retry ladder's SQP iterations per state, in units of
/// `max_iter` (BENCHMARKS.md, "Retry budget").
pub const DEFAULT_RETRY_BUDGET: usize = 4;

fn is_default_retry_budget(b: &usize) -> bool {
    *b == DEFAULT_RETRY_BUDGET
}

impl Default for SolverSettings {
    fn default() -> Self {
        SolverSettings {
            tol: 1e-8,
            max_iter: 100,
            retry_budget: DEFAULT_RETRY_BUDGET,
            soft_fallback: true,
            soft_l1: 1e4,
            soft_l2: 1e2,
            degeneracy_tol: 1e-7,
            warm_start: true,
            qp: QpSolverKind::default(),
            starts: None,
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
