//! One SQP iteration ([`SqpSolver::step`]) on the workspace of one solve ([`Work`]): the
//! iterate (z, λ, ν), the evaluations at it, the QP's step d and the ℓ₁ merit's penalty μ.
//!
//! A step is steps 1–4 of the parent module's doc: evaluate at z, stop on `r ≤ tol` (or a
//! successful polish, or the iteration limit), solve the QP for d (exact Hessian where the
//! convexity test passes, else blockwise convexified), then the line search on
//! `φ(z) = f(z) + μ(‖c(z)‖₁ + Σ max(0, g(z)))` and `z ← z + αd`, `(λ, ν) ← (λ, ν) + α((λ⁺, ν⁺) − (λ, ν))`.
//! [`SqpSolver::solve`] only loops over steps.

use super::{
    convexify, non_finite_part, quadratic_form, residual, Evals, Failure, Globalisation,
    PrimalDual, Quantity, SqpInfo, SqpSolver, SqpStatus, PENALTY_RHO, QP_TOL_FACTOR, QP_TOL_MAX,
};
use crate::mpc::qp::ipm::{self, mul_e};
use crate::mpc::qp::{QpData, QpStatus};

/// The KKT residual below which a failed convexity test is retried with the bound
/// curvature ([`SqpSolver::add_bound_curvature`]). Above it (far from a solution: the first
/// iterate's scaled residual is 1) the multipliers' guess of the active bounds is
/// unreliable; without this gate 13 of the safe quadrotor's 6,000 labels took 100
/// iterations more (warm starts whose neighbour's bounds were not this state's).
const BOUND_CURVATURE_BELOW: f64 = 1.0;

/// The state and scratch space of one solve.
pub(super) struct Work {
    /// The iterate.
    pub(super) p: PrimalDual,
    /// Statistics so far.
    pub(super) info: SqpInfo,
    ev: Evals,
    hreg: Vec<f64>,
    gn: Vec<f64>,
    gn_ready: bool,
    zero_lam: Vec<f64>,
    d: Vec<f64>,
    lam_qp: Vec<f64>,
    nu_qp: Vec<f64>,
    c_trial: Vec<f64>,
    c_soc: Vec<f64>,
    d_soc: Vec<f64>,
    lam_soc: Vec<f64>,
    nu_soc: Vec<f64>,
    z_trial: Vec<f64>,
    mu: f64,
    /// Rounding floor of the merit near a setpoint ≠ 0 (see [`Work::new`]).
    floor_scale: f64,
    full_step: bool,
    soc_enabled: bool,
    conservative: bool,
    max_iter: usize,
    /// Whether this iteration's QP Hessian `hreg` is the exact one plus the bound
    /// curvature ([`SqpSolver::add_bound_curvature`]).
    bound_curvature: bool,
}

impl Work {
    /// The workspace of a solve of `s` from `start`.
    pub(super) fn new(s: &SqpSolver, start: PrimalDual) -> Self {
        let conservative = s.globalisation == Globalisation::Conservative;
        let max_iter = if conservative {
            3 * s.settings.max_iter
        } else {
            s.settings.max_iter
        };
        let max_iter = s.iteration_cap.map_or(max_iter, |c| c.min(max_iter));
        let ocp = &s.ocp;
        let ev = Evals::new(ocp);
        let n_var = ocp.n_var;
        let nh = ev.hess.len();
        Work {
            p: start,
            info: SqpInfo::default(),
            ev,
            hreg: vec![0.0; nh],
            gn: vec![0.0; nh],
            gn_ready: false,
            zero_lam: vec![0.0; ocp.n_eq],
            d: vec![0.0; n_var],
            lam_qp: vec![0.0; ocp.n_eq],
            nu_qp: vec![0.0; ocp.rows.len()],
            c_trial: vec![0.0; ocp.n_eq],
            c_soc: vec![0.0; ocp.n_eq],
            d_soc: vec![0.0; n_var],
            lam_soc: vec![0.0; ocp.n_eq],
            nu_soc: vec![0.0; ocp.rows.len()],
            z_trial: vec![0.0; n_var],
            mu: 1.0,
            // Rounding floor of the merit function near a setpoint (x_ref, u_ref) ≠ 0: there
            // the constraint residuals c carry an absolute rounding of about ε·|x_ref| per
            // entry (ε·|u_ref|-sized terms inside F), which a cost near its zero minimum
            // cannot resolve; without it the line search rejects every step there. 0 at the
            // origin.
            floor_scale: 8.0
                * f64::EPSILON
                * ocp.horizon as f64
                * (ocp.x_ref.iter().chain(&ocp.u_ref))
                    .map(|v| v.abs())
                    .sum::<f64>(),
            full_step: false,
            // The second-order correction acts where the merit's curvature comes from
            // constraints the linearisation misses: nonlinear rows, and the soft problem
            // (whose multipliers, up to the slack weight, raise the penalty μ so far that the
            // dynamics' second-order error rejects full steps). Elsewhere the line search runs
            // without it.
            soc_enabled: ocp.has_nonlinear_rows() || ocp.n_slack > 0,
            conservative,
            max_iter,
            bound_curvature: false,
        }
    }
}

impl SqpSolver {
    /// One SQP iteration from `w.p`: `Some(status)` when the solve ends here (converged,
    /// polished, out of iterations, or failed), `None` after a step was taken.
    pub(super) fn step(&mut self, w: &mut Work, xs: &[f64]) -> Option<SqpStatus> {
        self.ocp.relinearize(&w.p.z);
        w.ev.first_order(&self.ocp, &w.p.z, xs);
        let res = residual(&self.ocp, &w.p.z, &w.ev, &w.p.lam, &w.p.nu);
        w.info.kkt = res;
        // A non-finite residual (NaN or ±∞ in the plant's equations, the cost, a row, the
        // multipliers) ends the solve at once, also at the first iterate: no QP is built on
        // such data and nothing after it can be a label.
        if !res.max().is_finite() {
            w.info.failure = Some(Failure::NonFinite(non_finite_part(
                &self.ocp, &w.p, &w.ev, &res,
            )));
            return Some(SqpStatus::NumericalFailure);
        }
        if res.max() <= self.settings.tol {
            return Some(SqpStatus::Converged);
        }
        if w.full_step && res.max() < 1e-1 {
            if let Some(q) = self.polish(xs, &w.p, &mut w.info) {
                w.p = q;
                return Some(SqpStatus::Converged);
            }
        }
        if w.info.iterations >= w.max_iter {
            return Some(SqpStatus::MaxIterations);
        }
        self.ocp
            .hessian_blocks(&w.p.z, &w.p.lam, &w.p.nu, &mut w.ev.hess);
        if w.ev.hess.iter().any(|v| !v.is_finite()) {
            w.info.failure = Some(Failure::NonFinite(Quantity::Hessian));
            return Some(SqpStatus::NumericalFailure);
        }
        // The exact Hessian wherever the test passes, the soft problem and nonlinear
        // constraint rows included: there the blockwise rule drops the curvature λᵀ∇²F of
        // multipliers as large as the slack weight (~1e4) and crawled to the iteration limit
        // on infeasible ball-beam states (BENCHMARKS, "Soft problems"). A QP with the exact
        // Hessian that the QP solver fails on (or calls infeasible) is re-solved with the
        // blockwise rule.
        // (Inexact only after a full step or at the start: while the line search cuts
        // steps, an inexact QP would mostly be solved twice.)
        let mut qp_tol = if self.inexact_qp && (w.full_step || w.info.iterations == 0) {
            (QP_TOL_FACTOR * res.max())
                .powi(2)
                .clamp(ipm::TOL, QP_TOL_MAX)
        } else {
            ipm::TOL
        };
        let mut convex = !w.conservative
            && self
                .convexity
                .is_positive_definite(&self.ocp, &w.ev.hess, &w.ev.jac_x, &w.ev.jac_u);
        // Where the test fails, the exact Hessian with the bound curvature of the rows
        // guessed active (parent module doc, step 2) before the blockwise rule: on the hard
        // problem only (on the soft one it cost a CSTR state its soft label), and once the
        // iterate is near a solution (r < 1), where the guessed active set means something.
        w.bound_curvature = false;
        if !convex
            && !w.conservative
            && self.ocp.n_slack == 0
            && res.max() < BOUND_CURVATURE_BELOW
            && self.add_bound_curvature(w)
        {
            convex =
                self.convexity
                    .is_positive_definite(&self.ocp, &w.hreg, &w.ev.jac_x, &w.ev.jac_u);
            w.bound_curvature = convex;
        }
        // One pass per QP accuracy: the inexact one, then (if its full step is rejected) the
        // exact one with the penalty as it was.
        let alpha = loop {
            let mu_before = w.mu;
            let st = self.direction(w, convex, qp_tol);
            w.info.iterations += 1;
            match st {
                QpStatus::Solved => {}
                QpStatus::Infeasible => return Some(SqpStatus::Infeasible),
                QpStatus::Failed => return Some(SqpStatus::NumericalFailure),
            }
            match self.line_search(w, xs, qp_tol) {
                Some(alpha) => break alpha,
                None if qp_tol > ipm::TOL => {
                    // (Its IPM iterations count; the discarded QP is no SQP iteration.)
                    w.info.iterations -= 1;
                    qp_tol = ipm::TOL;
                    w.mu = mu_before;
                }
                None => return Some(SqpStatus::NumericalFailure),
            }
        };
        w.full_step = alpha == 1.0;
        w.p.z.copy_from_slice(&w.z_trial);
        for (l, q) in w.p.lam.iter_mut().zip(&w.lam_qp) {
            *l += alpha * (q - *l);
        }
        for (l, q) in w.p.nu.iter_mut().zip(&w.nu_qp) {
            *l += alpha * (q - *l);
        }
        None
    }

    /// Sets `w.hreg` to the exact Hessian plus `M·e_i e_iᵀ/a_r²` for every row `a_r z_i ≤ h_r`
    /// on one variable (a bound) that the iterate holds active — `ν_r > slack_r`, the
    /// polish's guess — with `M = max(1, max_i |∇²L_ii|)`. The term is zero on every QP
    /// step that keeps such a bound active (`d_i = 0`), so there the QP's solution and
    /// multipliers are the exact Hessian's; it only damps a step off the bound. With it the
    /// reduced-Hessian test sees the curvature an active bound supplies (an interior-point
    /// method's barrier term `ν_r/slack_r`), where the dynamics' null space alone is
    /// indefinite. Returns whether any row was added (else `w.hreg` is the exact Hessian).
    fn add_bound_curvature(&self, w: &mut Work) -> bool {
        w.hreg.copy_from_slice(&w.ev.hess);
        let nz = self.ocp.nx + self.ocp.nu;
        // The entry (i, i) of the stage blocks (`Ocp::hessian_blocks` layout) for variable
        // z_i of the plant (the caller's problem has no slacks).
        let n_plant = self.ocp.is();
        let diag = |i: usize| (i / nz) * nz * nz + (i % nz) * (nz + 1);
        let m = (0..n_plant)
            .map(|i| w.ev.hess[diag(i)].abs())
            .fold(1.0f64, f64::max);
        let mut any = false;
        for (r, row) in self.ocp.rows.iter().enumerate() {
            let (i, a) = (row.idx[0], row.coef[0]);
            if row.len == 1 && i < n_plant && a != 0.0 && w.p.nu[r] > row.slack(&w.p.z).max(0.0) {
                w.hreg[diag(i)] += m / (a * a);
                any = true;
            }
        }
        any
    }

    /// The QP step `w.d` and multipliers `(w.lam_qp, w.nu_qp)` at `w.p`: with the exact
    /// Hessian if `convex` (falling back to the blockwise convexified one if the QP solver
    /// fails on it), else the convexified one.
    fn direction(&mut self, w: &mut Work, convex: bool, qp_tol: f64) -> QpStatus {
        let mut exact = convex;
        loop {
            if exact && w.bound_curvature {
                // (`w.hreg` holds the exact Hessian with the bound curvature already.)
            } else if exact {
                w.hreg.copy_from_slice(&w.ev.hess);
            } else {
                if !w.gn_ready {
                    // With zero multipliers only the objective's (constant) Hessian remains.
                    self.ocp.hessian_blocks(&w.p.z, &w.zero_lam, &[], &mut w.gn);
                    w.gn_ready = true;
                }
                convexify(&self.ocp, &w.ev.hess, &w.gn, &mut w.hreg);
            }
            let data = QpData {
                z: &w.p.z,
                hess: &w.hreg,
                grad: &w.ev.grad,
                c: &w.ev.c,
                jac_x: &w.ev.jac_x,
                jac_u: &w.ev.jac_u,
                tol: qp_tol,
            };
            let st = self
                .qp
                .solve(&self.ocp, &data, &mut w.d, &mut w.lam_qp, &mut w.nu_qp);
            w.info.qp_iterations += self.qp.last_iterations as usize;
            // (Also on `Infeasible`: the soft problem's QP is feasible whenever its hard input
            // rows are, and an indefinite full H may mislead the QP solver.)
            if st != QpStatus::Solved && exact {
                exact = false;
                w.bound_curvature = false;
                continue;
            }
            return st;
        }
    }

    /// The ℓ₁ merit line search along `w.d` (step 3 of the parent module's doc), with the
    /// penalty raised first: the accepted step length (the trial point left in `w.z_trial`),
    /// or `None` if no step is accepted (an inexact QP's step is taken only in full).
    fn line_search(&mut self, w: &mut Work, xs: &[f64], qp_tol: f64) -> Option<f64> {
        // Inequalities enter the merit by their violation Σ max(0, g). A QP step satisfies the
        // linearised rows, so the merit's directional derivative is at most
        // ∇fᵀd − μ(‖c‖₁ + Σ max(0, g)) (N&W Thm 18.2 with inequalities): the N&W 18.36 rule
        // applies with the total violation in place of ‖c‖₁.
        let c1: f64 =
            w.ev.c.iter().map(|v| v.abs()).sum::<f64>() + self.ocp.inequality_violation(&w.p.z);
        let gd: f64 = w.ev.grad.iter().zip(&w.d).map(|(g, d)| g * d).sum();
        if c1 > 0.0 {
            // (With the bound curvature, the exact Hessian's model: the added term measures
            // only how far d leaves a bound, and would raise μ for nothing.)
            let h = if w.bound_curvature {
                &w.ev.hess
            } else {
                &w.hreg
            };
            let dhd = quadratic_form(&self.ocp, h, &w.d);
            let needed = (gd + 0.5 * dhd.max(0.0)) / ((1.0 - PENALTY_RHO) * c1);
            if w.mu < needed {
                w.mu = needed + 1.0;
            }
        }
        if w.conservative {
            let lam_max = (w.lam_qp.iter().chain(&w.nu_qp)).fold(0.0f64, |m, v| m.max(v.abs()));
            w.mu = w.mu.max(1.1 * lam_max);
        }
        let mu = w.mu;
        let floor_scale = w.floor_scale;
        let f0 = self.ocp.objective(&w.p.z);
        let phi0 = f0 + mu * c1;
        let dd = gd - mu * c1;
        let armijo = |phi: f64, alpha: f64| {
            phi.is_finite()
                && phi <= phi0 + 1e-4 * alpha * dd.min(0.0) + 1e-12 * phi0.abs() + mu * floor_scale
        };
        let mut alpha = 1.0;
        loop {
            let phi = self.trial_merit(&w.p.z, &w.d, alpha, xs, mu, &mut w.z_trial, &mut w.c_trial);
            if armijo(phi, alpha) {
                return Some(alpha);
            }
            // An inexact QP's step is taken only in full (parent module doc, step 2).
            if alpha == 1.0 && qp_tol > ipm::TOL {
                return None;
            }
            // (Not from a non-finite trial point: its data would only fail the QP.)
            if alpha == 1.0
                && w.soc_enabled
                && phi.is_finite()
                && w.c_trial.iter().all(|v| v.is_finite())
            {
                // Second-order correction (Nocedal & Wright §18.3): the QP again with the
                // constraints' constant terms taken at z + d (c(z + d) − ∇c d, the nonlinear
                // rows shifted alike), tried as a full step before backtracking.
                mul_e(&self.ocp, &w.ev.jac_x, &w.ev.jac_u, &w.d, &mut w.c_soc);
                for (cs, ct) in w.c_soc.iter_mut().zip(&w.c_trial) {
                    *cs = ct - *cs;
                }
                let saved = self.ocp.shift_for_correction(&w.p.z, &w.d);
                let data = QpData {
                    z: &w.p.z,
                    hess: &w.hreg,
                    grad: &w.ev.grad,
                    c: &w.c_soc,
                    jac_x: &w.ev.jac_x,
                    jac_u: &w.ev.jac_u,
                    tol: qp_tol,
                };
                let st = self.qp.solve(
                    &self.ocp,
                    &data,
                    &mut w.d_soc,
                    &mut w.lam_soc,
                    &mut w.nu_soc,
                );
                w.info.qp_iterations += self.qp.last_iterations as usize;
                self.ocp.restore_rhs(&saved);
                if st == QpStatus::Solved {
                    let phi = self.trial_merit(
                        &w.p.z,
                        &w.d_soc,
                        1.0,
                        xs,
                        mu,
                        &mut w.z_trial,
                        &mut w.c_trial,
                    );
                    if armijo(phi, 1.0) {
                        w.lam_qp.copy_from_slice(&w.lam_soc);
                        w.nu_qp.copy_from_slice(&w.nu_soc);
                        return Some(1.0);
                    }
                }
            }
            alpha *= 0.5;
            if alpha < 1e-10 {
                return None;
            }
        }
    }
}
