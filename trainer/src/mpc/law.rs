//! The MPC law κ(x_s) = u_0*(x_s) and its derivative: one labelled state.
//!
//! Solving a state means: the hard OCP by SQP (warm-started if a neighbour's solution is
//! given, retried cold if that fails); if the hard problem fails, the exact-penalty (soft)
//! OCP decides feasibility — with ℓ₁ weight above the multipliers, its solution has zero
//! slacks iff the hard problem is (locally) feasible. Hard-infeasible states are labelled by
//! the soft optimum and flagged [`SqpStatus::Soft`] when `solver.soft_fallback` is on, and
//! reported [`SqpStatus::Infeasible`] (no label) otherwise. The sensitivity is that of the
//! problem that produced the label.

use crate::mpc::sensitivity::{sensitivity, Degeneracy};
use crate::mpc::sqp::{PrimalDual, SqpInfo, SqpResult, SqpSolver, SqpStatus};
use crate::problem::ProblemConfig;

/// Slack size above which the soft optimum proves the hard OCP infeasible.
pub const SLACK_TOL: f64 = 1e-6;

/// One labelled state (x, κ(x), ∂κ/∂x) with its provenance.
#[derive(Debug, Clone, PartialEq)]
pub struct Label {
    /// The state x_s.
    pub x: Vec<f64>,
    /// u_0* (NaN when unlabelled).
    pub u: Vec<f64>,
    /// ∂u_0*/∂x_s, row-major nu × nx (NaN when unlabelled).
    pub du_dx: Vec<f64>,
    /// Optimal cost (of the soft problem for soft labels; NaN when unlabelled).
    pub cost: f64,
    /// Solve status.
    pub status: SqpStatus,
    /// Solver statistics of the solve that produced the label.
    pub info: SqpInfo,
    /// Sensitivity degeneracy, if any.
    pub degeneracy: Option<Degeneracy>,
    /// Largest state-bound slack (0 for hard labels).
    pub max_slack: f64,
    /// The strongly active constraint rows of the solution (empty when unlabelled): two
    /// labels with the same active set lie in the same smooth piece of κ.
    pub active: Vec<usize>,
}

/// A reusable MPC law evaluator: one hard and (lazily) one soft SQP workspace.
pub struct MpcLaw {
    cfg: ProblemConfig,
    hard: SqpSolver,
    soft: Option<SqpSolver>,
}

impl MpcLaw {
    /// Builds the workspaces for a validated problem.
    ///
    /// ```
    /// let cfg = trainer::problem::ProblemConfig::default();
    /// let mut law = trainer::mpc::law::MpcLaw::new(&cfg);
    /// let (label, _) = law.solve(&[0.0, 0.0], None);
    /// assert!(label.u[0].abs() < 1e-9);
    /// ```
    pub fn new(cfg: &ProblemConfig) -> Self {
        MpcLaw {
            cfg: cfg.clone(),
            hard: SqpSolver::new(cfg, false),
            soft: None,
        }
    }

    /// The hard problem's solver.
    pub fn hard_solver(&self) -> &SqpSolver {
        &self.hard
    }

    fn finish(&self, solver: &SqpSolver, xs: &[f64], r: &SqpResult, status: SqpStatus) -> Label {
        let ocp = &solver.ocp;
        let sens = sensitivity(solver, xs, &r.point, self.cfg.solver.degeneracy_tol);
        let iu = ocp.iu(0);
        Label {
            x: xs.to_vec(),
            u: r.point.z[iu..iu + ocp.nu].to_vec(),
            du_dx: sens.du0_dx,
            cost: ocp.objective(&r.point.z),
            status,
            info: r.info,
            degeneracy: sens.degeneracy,
            max_slack: r.point.z[ocp.is()..].iter().fold(0.0f64, |m, v| m.max(*v)),
            active: sens.active,
        }
    }

    fn unlabelled(&self, xs: &[f64], status: SqpStatus, info: SqpInfo) -> Label {
        let (nx, nu) = (self.hard.ocp.nx, self.hard.ocp.nu);
        Label {
            x: xs.to_vec(),
            u: vec![f64::NAN; nu],
            du_dx: vec![f64::NAN; nu * nx],
            cost: f64::NAN,
            status,
            info,
            degeneracy: None,
            max_slack: f64::NAN,
            active: Vec::new(),
        }
    }

    /// Solves OCP(xs). `warm` is a neighbour's hard solution (same problem). Returns the
    /// label and, for converged hard solves, the solution (to warm-start neighbours).
    pub fn solve(&mut self, xs: &[f64], warm: Option<&PrimalDual>) -> (Label, Option<PrimalDual>) {
        if xs.iter().any(|v| !v.is_finite()) || xs.len() != self.hard.ocp.nx {
            return (
                self.unlabelled(xs, SqpStatus::NumericalFailure, SqpInfo::default()),
                None,
            );
        }
        let mut r = match warm {
            Some(w) => {
                let mut start = w.clone();
                start.z[..xs.len()].copy_from_slice(xs);
                self.hard.solve(xs, start)
            }
            None => self.hard.solve(xs, self.hard.cold_start(xs)),
        };
        if r.status != SqpStatus::Converged && warm.is_some() {
            let cold = self.hard.solve(xs, self.hard.cold_start(xs));
            let iters = r.info.iterations;
            r = cold;
            r.info.iterations += iters;
        }
        if r.status == SqpStatus::Converged {
            let label = self.finish(&self.hard, xs, &r, SqpStatus::Converged);
            return (label, Some(r.point));
        }
        // Hard solve failed: let the exact-penalty problem decide feasibility.
        let cfg = &self.cfg;
        let soft = self.soft.get_or_insert_with(|| SqpSolver::new(cfg, true));
        let start = soft.cold_start(xs);
        let mut s = soft.solve(xs, start);
        s.info.iterations += r.info.iterations;
        if s.status != SqpStatus::Converged {
            let status = if r.status == SqpStatus::Infeasible {
                s.status
            } else {
                r.status
            };
            return (self.unlabelled(xs, status, s.info), None);
        }
        let soft = self.soft.as_ref().map_or(&self.hard, |s| s);
        let max_slack = s.point.z[soft.ocp.is()..]
            .iter()
            .fold(0.0f64, |m, v| m.max(*v));
        if max_slack <= SLACK_TOL {
            // Feasible after all: re-solve the hard problem from the soft optimum.
            let nw = self.hard.ocp.n_var;
            let start = PrimalDual {
                z: s.point.z[..nw].to_vec(),
                lam: s.point.lam.clone(),
                nu: vec![0.0; self.hard.ocp.rows.len()],
            };
            let mut h = self.hard.solve(xs, start);
            h.info.iterations += s.info.iterations;
            if h.status == SqpStatus::Converged {
                let label = self.finish(&self.hard, xs, &h, SqpStatus::Converged);
                return (label, Some(h.point));
            }
            // Feasible, yet the hard solve fails: report the failure, not a soft label.
            return (self.unlabelled(xs, r.status, h.info), None);
        }
        if !self.cfg.solver.soft_fallback {
            return (self.unlabelled(xs, SqpStatus::Infeasible, s.info), None);
        }
        let soft = self.soft.as_ref().map_or(&self.hard, |s| s);
        (self.finish(soft, xs, &s, SqpStatus::Soft), None)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mpc::ipopt_labels::PENDULUM_IPOPT;

    #[test]
    fn pendulum_matches_ipopt_reference() {
        let cfg = ProblemConfig::default();
        let mut law = MpcLaw::new(&cfg);
        for row in PENDULUM_IPOPT {
            let xs = [row[0], row[1]];
            let (l, _) = law.solve(&xs, None);
            eprintln!(
                "{xs:?}: {:?} u {:?} du {:?} cost {} iters {} kkt {:e} deg {:?}",
                l.status,
                l.u,
                l.du_dx,
                l.cost,
                l.info.iterations,
                l.info.kkt.max(),
                l.degeneracy
            );
            assert_eq!(l.status, SqpStatus::Converged, "{xs:?}");
            assert!(
                (l.u[0] - row[2]).abs() <= 1e-5,
                "{xs:?}: u {} vs {}",
                l.u[0],
                row[2]
            );
            for i in 0..2 {
                let (a, b) = (l.du_dx[i], row[3 + i]);
                assert!(
                    (a - b).abs() <= 1e-4 * b.abs().max(1.0),
                    "{xs:?}: du/dx{i} {a} vs {b}"
                );
            }
            assert!(
                (l.cost - row[5]).abs() <= 1e-6 * row[5].abs().max(1.0),
                "{xs:?}: cost {} vs {}",
                l.cost,
                row[5]
            );
        }
    }
}
