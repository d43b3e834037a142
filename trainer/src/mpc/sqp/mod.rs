//! Sequential quadratic programming for the multiple-shooting OCP, with a Newton polish.
//!
//! Iteration (Nocedal & Wright, Alg. 18.3 with an ℓ₁ merit function):
//! 1. At (z, λ, ν) evaluate ∇f, c, ∇c (exact, AD) and the exact Hessian of the Lagrangian
//!    `∇²L = ∇²f + Σ_k ∇²(λ_{k+1}ᵀ F(x_k, u_k)) + Σ_r ν_r ∇²g_r` (the last sum over the
//!    nonlinear constraint rows), stage block by stage block.
//! 2. Keep the exact Hessian if the QP is strictly convex with it on the null space of the
//!    linearised dynamics (`convexity` module: a Riccati recursion, O(N)); otherwise
//!    convexify block by block: keep the exact block where it is positive semidefinite, use
//!    the Gauss–Newton block (the objective's Hessian 2·diag(Q, R)) where it is not. Between
//!    the two, where the exact test fails: the exact Hessian plus the curvature of the bounds
//!    the iterate holds active, `M·e_i e_iᵀ` on each variable z_i at a bound with ν_r > slack_r
//!    (`M = max(1, max|∇²L_ii|)`), kept if the test passes with it (on the hard problem, at
//!    iterates with KKT residual r < 1: near a solution). The term vanishes on a
//!    step that keeps those bounds active, so there it is the exact Newton step; without it
//!    the test fails at every iterate near an optimum whose indefinite directions are closed
//!    by active input bounds (the acados swing-up: 13 active bounds), and the Gauss–Newton
//!    blocks then crawl at step lengths 1/8–1/4 to the iteration limit (BENCHMARKS.md,
//!    "Bound curvature"). The line search's penalty rule uses the exact Hessian then. Solve
//!    the QP subproblem (`qp` module: structured interior point, or clarabel) for the step d
//!    and multipliers (λ⁺, ν⁺). The exact Hessian gives Newton steps where the blockwise test
//!    would discard curvature the constraints make harmless (the cart-pole's blocks are
//!    indefinite at most iterates).
//!    The QP is solved only as accurately as the iterate deserves: to `(0.01·r)²` (r the
//!    KKT residual of the iterate), clamped to `[1e-10, 1e-4]` (an inexact Newton method's
//!    forcing sequence; squared because the QP's complementarity enters r as √gap on weakly
//!    active rows, where a tolerance linear in r stalls the SQP at r ≈ 1e-3). The QPs are
//!    exact (`1e-10`) near a solution (r < 1e-3), for an OCP that is itself a QP (affine
//!    plant, linear rows: its first QP is its solution), and for the soft problem (inexact
//!    steps there send stress states to the retry ladder, 20× slower). Inexact only at the
//!    first iteration or after a full step; an inexact step whose full step the line search
//!    rejects is discarded and the QP solved exactly, the penalty unchanged (an inexact step
//!    from a nearly feasible point can ask for a penalty ~1e7 times larger). BENCHMARKS.md
//!    gives the solve times (planar_quadrotor_nl, with the polish rule of step 4).
//! 3. Backtracking Armijo line search on `φ(z) = f(z) + μ(‖c(z)‖₁ + Σ_r max(0, g_r(z)))`
//!    (inequality rows enter by their violation), with the penalty raised only as far as the
//!    step needs to be a descent direction (Nocedal & Wright, eq. 18.36, with the total
//!    violation `v = ‖c‖₁ + Σ max(0, g)` in place of ‖c‖₁ — the QP step satisfies the
//!    linearised rows, so φ's directional derivative is at most ∇fᵀd − μv):
//!    `μ ≥ (∇fᵀd + ½ max(dᵀHd, 0)) / ((1 − ρ)v)`, ρ = 0.1, then μ += 1. The classical
//!    `μ ≥ 1.1·‖λ⁺‖_∞` is far larger when λ spans orders of magnitude along the horizon (an
//!    unstable plant's costates grow backwards in time) and then forces step lengths of
//!    1/8–1/4 for many iterations.
//!    Measured on 100 random cart-pole states (`examples/profile_solve`, see BENCHMARKS.md):
//!    mean 14.1 SQP + polish iterations with `1.1·‖λ⁺‖_∞` and blockwise convexification,
//!    6.1 with this penalty, 5.7 with both changes; pendulum 3.27 → 3.21.
//!    Where the full step is rejected on a problem with nonlinear rows or slacks, a
//!    second-order correction is tried first (Nocedal & Wright §18.3, against the Maratos
//!    effect): the QP again with the constant terms of the constraints taken at z + d
//!    (`c(z + d) − ∇c d`, nonlinear rows shifted by their linearisation remainder), its
//!    step d̂ accepted as a full step if z + d̂ passes the same Armijo test.
//! 4. Once a step is full and the KKT residual is below 0.1, guess the active set
//!    `A = {r : ν_r > slack_r}` and run Newton's method on the KKT conditions restricted to A
//!    (`kkt` module, exact Hessian): quadratic convergence to machine precision, independent
//!    of the interior-point QP's tolerance. The polish is accepted only if the full KKT
//!    residual (including ν ≥ 0 and the inactive rows' feasibility) falls below `tol`.
//!    A wrong guess costs two or three Newton iterations (its residual stops falling) and
//!    the SQP goes on. Guessing at once, rather than waiting for the QP's active set to
//!    repeat, saves a whole QP in most solves; on the soft problem the wait can leave the
//!    full step's neighbourhood for good (cartpole_public_nl, BENCHMARKS "state 86").
//!
//! Convergence is declared on the scaled KKT residual ([`KktResidual::max`]) ≤ `tol`.
//! Status is data ([`SqpStatus`]); nothing here panics on a bad state.

use crate::mpc::convexity::ReducedHessian;
use crate::mpc::finite::{nan_max, Failure, Quantity};
use crate::mpc::kkt::{ActiveSetKkt, KktLayout};
use crate::mpc::ocp::Ocp;
use crate::mpc::qp::QpSolver;
use crate::problem::{ProblemConfig, SolverSettings};
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

mod polish;
mod residual;
mod step;
use residual::{non_finite_part, residual};
use step::Work;

/// How a solve ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SqpStatus {
    /// KKT residual ≤ tol on the hard problem.
    Converged,
    /// The hard problem is infeasible; the label is the exact-penalty (soft) solution.
    Soft,
    /// The hard problem is infeasible and the soft fallback is off: no label.
    Infeasible,
    /// Iteration limit reached.
    MaxIterations,
    /// The QP solver failed, the line search stalled or a non-finite value appeared.
    NumericalFailure,
}

impl SqpStatus {
    /// Whether the point carries a usable label (hard or soft optimum).
    pub fn is_labelled(self) -> bool {
        matches!(self, SqpStatus::Converged | SqpStatus::Soft)
    }
    /// Name used in CSV files.
    pub fn as_str(self) -> &'static str {
        match self {
            SqpStatus::Converged => "converged",
            SqpStatus::Soft => "soft",
            SqpStatus::Infeasible => "infeasible",
            SqpStatus::MaxIterations => "max_iterations",
            SqpStatus::NumericalFailure => "numerical_failure",
        }
    }
}

/// How a solve globalises its steps.
///
/// `Conservative` is the retry ladder's second rung ([`crate::mpc::law`]): the blockwise
/// convexified Hessian at every iteration (never the exact one), the penalty also at least
/// the classical `1.1·‖λ⁺‖_∞` (steps favour feasibility), and three times the iterations.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Globalisation {
    /// The rules of the module doc.
    #[default]
    Default,
    /// Convexified Hessian, the larger penalty, `3·max_iter`.
    Conservative,
}

/// The parts of the KKT residual (all ∞-norms).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct KktResidual {
    /// ‖∇f + ∇cᵀλ + Gᵀν‖ / max(1, ‖∇f‖).
    pub stationarity: f64,
    /// max(‖c‖, max(0, Gz − h)).
    pub primal: f64,
    /// max(0, −ν) / max(1, ‖ν‖).
    pub dual: f64,
    /// max |min(ν_r, h_r − g_rᵀz)| / max(1, ‖ν‖).
    pub complementarity: f64,
}

impl KktResidual {
    /// The largest part: what `tol` is compared with (∞ if a part is NaN).
    pub fn max(&self) -> f64 {
        let m = nan_max(
            nan_max(self.stationarity, self.primal),
            nan_max(self.dual, self.complementarity),
        );
        if m.is_nan() {
            f64::INFINITY
        } else {
            m
        }
    }
}

/// Solver statistics of one solve.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct SqpInfo {
    /// SQP iterations (QP solves) plus Newton polish iterations.
    pub iterations: usize,
    /// Interior-point iterations summed over the QP solves.
    pub qp_iterations: usize,
    /// Final KKT residual.
    pub kkt: KktResidual,
    /// Whether the final point came from the active-set Newton polish.
    pub polished: bool,
    /// Why the solve is no label when a number it rests on is not finite, or (set by the
    /// law's gate, [`crate::mpc::finite`]) its re-checked KKT residual is above `tol`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub failure: Option<Failure>,
}

/// A primal-dual point of the OCP.
#[derive(Debug, Clone, PartialEq)]
pub struct PrimalDual {
    /// Variables z.
    pub z: Vec<f64>,
    /// Equality multipliers λ.
    pub lam: Vec<f64>,
    /// Inequality multipliers ν (one per row).
    pub nu: Vec<f64>,
}

/// Result of one SQP run on one problem (hard or soft).
#[derive(Debug, Clone)]
pub struct SqpResult {
    /// How it ended.
    pub status: SqpStatus,
    /// The last iterate.
    pub point: PrimalDual,
    /// Statistics.
    pub info: SqpInfo,
}

/// Evaluations at one iterate.
struct Evals {
    grad: Vec<f64>,
    c: Vec<f64>,
    jac_x: Vec<f64>,
    jac_u: Vec<f64>,
    hess: Vec<f64>,
}

impl Evals {
    fn new(ocp: &Ocp) -> Self {
        let (nx, nu, n) = (ocp.nx, ocp.nu, ocp.horizon);
        Evals {
            grad: vec![0.0; ocp.n_var],
            c: vec![0.0; ocp.n_eq],
            jac_x: vec![0.0; n * nx * nx],
            jac_u: vec![0.0; n * nx * nu],
            hess: vec![0.0; (n + 1) * (nx + nu) * (nx + nu)],
        }
    }
    fn first_order(&mut self, ocp: &Ocp, z: &[f64], xs: &[f64]) {
        ocp.gradient(z, &mut self.grad);
        ocp.constraints(z, xs, &mut self.c, &mut self.jac_x, &mut self.jac_u);
    }
}

/// The QP's Hessian, block by block: the exact block `∇²L_k` where it is positive
/// semidefinite, else the Gauss–Newton block `∇²f_k` (the objective's, PSD by validation).
fn convexify(ocp: &Ocp, exact: &[f64], gauss_newton: &[f64], out: &mut [f64]) {
    let nz = ocp.nx + ocp.nu;
    out.copy_from_slice(exact);
    for (blk, gn) in out.chunks_mut(nz * nz).zip(gauss_newton.chunks(nz * nz)) {
        let m = DMatrix::from_row_slice(nz, nz, blk);
        if m.symmetric_eigen().eigenvalues.min() < 0.0 {
            blk.copy_from_slice(gn);
        }
    }
}

/// ρ of the penalty rule (step 3 of the module doc).
const PENALTY_RHO: f64 = 0.1;
/// The QP accuracy far from a solution (step 2 of the module doc): `(0.01·r)²`, r the KKT
/// residual of the iterate, between the QP solver's own `1e-10` and `1e-4`.
const QP_TOL_FACTOR: f64 = 0.01;
/// The largest QP tolerance asked for.
const QP_TOL_MAX: f64 = 1e-4;

/// `dᵀ H d` for stage blocks `hess` ([`Ocp::hessian_blocks`] layout) plus the slack diagonal.
fn quadratic_form(ocp: &Ocp, hess: &[f64], d: &[f64]) -> f64 {
    let (nx, nu, n) = (ocp.nx, ocp.nu, ocp.horizon);
    let nz = nx + nu;
    let mut acc = 0.0;
    for s in 0..=n {
        let size = if s < n { nz } else { nx };
        let (blk, ds) = (
            &hess[s * nz * nz..(s + 1) * nz * nz],
            &d[s * nz..s * nz + size],
        );
        for i in 0..size {
            let row: f64 = (0..size).map(|j| blk[i * nz + j] * ds[j]).sum();
            acc += ds[i] * row;
        }
    }
    acc + ocp.slack_curvature() * d[ocp.is()..].iter().map(|v| v * v).sum::<f64>()
}

/// An SQP solver for one OCP (hard or soft), with its workspace allocated once.
pub struct SqpSolver {
    /// The transcribed problem.
    pub ocp: Ocp,
    settings: SolverSettings,
    qp: QpSolver,
    convexity: ReducedHessian,
    x_lo: Vec<f64>,
    x_hi: Vec<f64>,
    u_lo: Vec<f64>,
    u_hi: Vec<f64>,
    globalisation: Globalisation,
    /// The KKT ordering of the last successful polish (reused by [`Self::active_set_kkt`]).
    polish_layout: Option<KktLayout>,
    /// Whether the QPs may be solved inexactly far from a solution (step 2 of the module
    /// doc): not for an OCP that is itself a QP (affine plant, linear rows), whose first QP
    /// is its solution, nor for the soft problem.
    inexact_qp: bool,
    /// A cap on the iterations of the following solves below their own limit (`None`:
    /// none), set by the retry ladder's budget ([`crate::mpc::law`]).
    iteration_cap: Option<usize>,
}

impl SqpSolver {
    /// Sets how the following solves globalise (until set again).
    pub fn set_globalisation(&mut self, g: Globalisation) {
        self.globalisation = g;
    }

    /// Caps the iterations of the following solves (until set again) at `cap`, below the
    /// limit of their globalisation (`max_iter`, or `3·max_iter` when conservative); `None`
    /// lifts the cap. A solve that reaches the cap ends `max_iterations`.
    pub fn set_iteration_cap(&mut self, cap: Option<usize>) {
        self.iteration_cap = cap;
    }

    /// The structured QP solver factorises by the band LU only (tests).
    #[cfg(test)]
    pub(crate) fn without_riccati(&mut self) {
        self.qp.without_riccati();
    }

    /// How many QPs of this solver's solves the structured QP solver handed to clarabel.
    #[cfg(test)]
    pub(crate) fn qp_fallbacks(&self) -> usize {
        self.qp.fallbacks
    }

    /// Workspace for the hard (`soft = false`) or exact-penalty (`soft = true`) problem.
    pub fn new(cfg: &ProblemConfig, soft: bool) -> Self {
        let ocp = Ocp::new(cfg, soft);
        // The OCP is itself a QP: affine plant, linear rows.
        let is_qp = cfg.system.is_affine() && !ocp.has_nonlinear_rows();
        let qp = QpSolver::new(&ocp, cfg.solver.qp);
        let convexity = ReducedHessian::new(&ocp);
        SqpSolver {
            ocp,
            settings: cfg.solver.clone(),
            qp,
            convexity,
            x_lo: cfg.ocp.x_lo.clone(),
            x_hi: cfg.ocp.x_hi.clone(),
            u_lo: cfg.ocp.u_lo.clone(),
            u_hi: cfg.ocp.u_hi.clone(),
            globalisation: Globalisation::Default,
            polish_layout: None,
            inexact_qp: !(soft || is_qp),
            iteration_cap: None,
        }
    }

    /// The state bounds (x_lo, x_hi) of `[ocp]`.
    pub fn state_bounds(&self) -> (&[f64], &[f64]) {
        (&self.x_lo, &self.x_hi)
    }

    /// Cold-start primal-dual guess for `xs`.
    pub fn cold_start(&self, xs: &[f64]) -> PrimalDual {
        PrimalDual {
            z: self
                .ocp
                .initial_guess(&self.x_lo, &self.x_hi, &self.u_lo, &self.u_hi, xs),
            lam: vec![0.0; self.ocp.n_eq],
            nu: vec![0.0; self.ocp.rows.len()],
        }
    }

    /// Evaluates the KKT residual of a point (used by tests and by callers that verify).
    pub fn kkt_residual(&self, xs: &[f64], p: &PrimalDual) -> KktResidual {
        let relinearized;
        let ocp = if self.ocp.has_nonlinear_rows() {
            let mut o = self.ocp.clone();
            o.relinearize(&p.z);
            relinearized = o;
            &relinearized
        } else {
            &self.ocp
        };
        let mut ev = Evals::new(ocp);
        ev.first_order(ocp, &p.z, xs);
        residual(ocp, &p.z, &ev, &p.lam, &p.nu)
    }

    /// The KKT residual at `p`, the result of this solver's last [`solve`](Self::solve)
    /// (nonlinear rows are linearised there, so no copy of the OCP is needed): the solve's
    /// own final residual, re-computed for the label gate ([`crate::mpc::finite`]).
    pub fn residual_at_solution(&self, xs: &[f64], p: &PrimalDual) -> KktResidual {
        let mut ev = Evals::new(&self.ocp);
        ev.first_order(&self.ocp, &p.z, xs);
        residual(&self.ocp, &p.z, &ev, &p.lam, &p.nu)
    }

    /// The factorised active-set KKT matrix at a point (exact Hessian), for sensitivities.
    /// `p` is the result of the last [`solve`](Self::solve): nonlinear rows are linearised
    /// there.
    pub fn active_set_kkt(&self, xs: &[f64], p: &PrimalDual, active: Vec<usize>) -> ActiveSetKkt {
        let mut ev = Evals::new(&self.ocp);
        ev.first_order(&self.ocp, &p.z, xs);
        self.ocp.hessian_blocks(&p.z, &p.lam, &p.nu, &mut ev.hess);
        match &self.polish_layout {
            // The ordering of the polish's last factorisation, for the same active rows (the
            // ordering is a function of the OCP's structure and the active rows only).
            Some(l) if l.active == active => {
                ActiveSetKkt::with_layout(&self.ocp, &ev.hess, &ev.jac_x, &ev.jac_u, l.clone())
            }
            _ => ActiveSetKkt::new(&self.ocp, &ev.hess, &ev.jac_x, &ev.jac_u, active),
        }
    }

    /// The ℓ₁ merit `φ(z + α·step) = f + μ(‖c‖₁ + Σ max(0, g))` at the trial point, which
    /// is left in `z_trial` (its equality residuals in `c_trial`).
    #[allow(clippy::too_many_arguments)]
    fn trial_merit(
        &self,
        z: &[f64],
        step: &[f64],
        alpha: f64,
        xs: &[f64],
        mu: f64,
        z_trial: &mut [f64],
        c_trial: &mut [f64],
    ) -> f64 {
        for ((t, &zi), &si) in z_trial.iter_mut().zip(z).zip(step) {
            *t = zi + alpha * si;
        }
        self.ocp.constraint_values(z_trial, xs, c_trial);
        self.ocp.objective(z_trial)
            + mu * (c_trial.iter().map(|v| v.abs()).sum::<f64>()
                + self.ocp.inequality_violation(z_trial))
    }

    /// Solves OCP(xs) from the primal-dual guess `start`: [`step`](Self::step) until a step
    /// ends the solve.
    pub fn solve(&mut self, xs: &[f64], start: PrimalDual) -> SqpResult {
        self.qp.reset();
        let mut w = Work::new(self, start);
        let status = loop {
            if let Some(status) = self.step(&mut w, xs) {
                break status;
            }
        };
        let (p, info) = (w.p, w.info);
        // Leave the rows linearised at the returned point (for sensitivities).
        self.ocp.relinearize(&p.z);
        SqpResult {
            status,
            point: p,
            info,
        }
    }
}
