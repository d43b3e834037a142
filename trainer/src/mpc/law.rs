//! The MPC law κ(x_s) = u_0*(x_s) and its derivative: one labelled state.
//!
//! Solving a state means: the hard OCP by SQP (warm-started if a neighbour's solution is
//! given, retried cold if that fails); if the hard problem fails, the exact-penalty (soft)
//! OCP decides feasibility — with ℓ₁ weight above the multipliers, its solution has zero
//! slacks iff the hard problem is (locally) feasible. Hard-infeasible states are labelled by
//! the soft optimum and flagged [`SqpStatus::Soft`] when `solver.soft_fallback` is on, and
//! reported [`SqpStatus::Infeasible`] (no label) otherwise. The sensitivity is that of the
//! problem that produced the label.
//!
//! A state that still has no label (`max_iterations` or `numerical_failure`) climbs a retry
//! ladder before it is reported ([`Retry`] records the rung that labelled it):
//! 1. the hard problem with the conservative globalisation ([`Globalisation::Conservative`](crate::mpc::sqp::Globalisation::Conservative));
//! 2. continuation from the setpoint x_c (x_ref, or the origin): the hard problem at
//!    x_c + θ(x_s − x_c) for θ = 0 → 1, each solve warm-started from the last solved θ
//!    (step doubled on success, halved on failure), first with the default globalisation,
//!    then with the conservative one — warm starts from solved neighbours on a path that
//!    depends only on x_s (deterministic, independent of the order of the states);
//! 3. the exact-penalty (soft) problem with the conservative globalisation, deciding
//!    feasibility as above (a hard re-solve from its optimum if the slacks vanish).
//!
//! The ladder runs only where the plain solve found no label, so every state labelled without
//! it keeps its label bit for bit.
//!
//! **Budget.** Rungs 1–2 may spend at most `solver.retry_budget × max_iter` SQP iterations
//! on one state (summed; each solve capped at what is left, the rungs skipped once it is
//! spent; rung 3 keeps its own limits; 0: no ladder at all — [`ladder`] module): a state in an infeasible or runaway
//! region, where every rung fails, costs a bounded number of iterations more than its plain
//! solve instead of the thousands the two continuations can take (BENCHMARKS.md, "Retry
//! budget"). A state the ladder gives up on keeps its plain solve's status (no label),
//! counted and located by the stages as before.

pub mod along;
pub mod homotopy;
pub mod ladder;
pub mod pilot;
pub mod starts;

use crate::mpc::finite::{check_label, nan_max, Failure, LabelParts, Quantity};
use crate::mpc::sensitivity::{sensitivity, Degeneracy};
use crate::mpc::sqp::{PrimalDual, SqpInfo, SqpResult, SqpSolver, SqpStatus};
use crate::problem::ProblemConfig;

/// Slack size above which the soft optimum proves the hard OCP infeasible.
pub const SLACK_TOL: f64 = 1e-6;

/// The rung of the retry ladder (module doc) that labelled a state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Retry {
    /// Hard problem, conservative globalisation, cold start.
    Conservative,
    /// Continuation from the setpoint, default globalisation.
    Continuation,
    /// Continuation from the setpoint, conservative globalisation.
    ContinuationConservative,
    /// Soft problem, conservative globalisation (its label, or the hard re-solve from it).
    Soft,
    /// Hard problem warm-started from a solved neighbour ([`MpcLaw::solve_from_neighbour`]).
    Neighbour,
}

impl Retry {
    /// Name used in summaries.
    pub fn as_str(self) -> &'static str {
        match self {
            Retry::Conservative => "conservative",
            Retry::Continuation => "continuation",
            Retry::ContinuationConservative => "continuation_conservative",
            Retry::Soft => "soft_conservative",
            Retry::Neighbour => "neighbour",
        }
    }
}

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
    /// The retry that labelled the state (`None`: the plain solve did, or no label).
    pub retry: Option<Retry>,
    /// Distinct hard optima the starts reached ([`starts`]; 0 when none was set, e.g. a
    /// single start): 2 or more means the starts disagree.
    pub optima: u32,
    /// The optimal input sequence u_0*, …, u_{N−1}*, row-major N × nu (empty when
    /// unlabelled); its first nu entries are [`u`](Self::u).
    pub seq: Vec<f64>,
}

impl Label {
    /// Why the state has no label, when a number it rests on is not finite or the KKT
    /// conditions re-checked after the solve fail ([`crate::mpc::finite`]).
    pub fn failure(&self) -> Option<Failure> {
        self.info.failure
    }
}

/// A reusable MPC law evaluator: one hard and (lazily) one soft SQP workspace.
pub struct MpcLaw {
    cfg: ProblemConfig,
    hard: SqpSolver,
    soft: Option<SqpSolver>,
    /// The soft problem's warm start of the current [`solve_along`](Self::solve_along) call
    /// (None outside it: nothing carries over from one call to the next).
    soft_warm: Option<PrimalDual>,
    /// The soft optimum that labelled the state of the current call, if any.
    soft_solution: Option<PrimalDual>,
    /// The initial guesses of a label ([`starts`]).
    starts: Vec<crate::problem::solver::Start>,
    /// The LQR gains of the `lqr` start (computed on first use; inner `None`: none exist).
    lqr: Option<Option<Vec<nalgebra::DMatrix<f64>>>>,
}

impl MpcLaw {
    /// The hard problem's start from a soft optimum `s` whose slacks all vanish
    /// (≤ [`SLACK_TOL`]): its primal variables and stage multipliers; None when a slack is
    /// positive (the hard problem is then infeasible at that point).
    fn hard_start_from_soft(&self, s: &SqpResult) -> Option<PrimalDual> {
        let soft = self.soft.as_ref().map_or(&self.hard, |s| s);
        let max_slack = s.point.z[soft.ocp.is()..]
            .iter()
            .fold(0.0, |m, v| nan_max(m, *v));
        (max_slack <= SLACK_TOL).then(|| PrimalDual {
            z: s.point.z[..self.hard.ocp.n_var].to_vec(),
            lam: s.point.lam.clone(),
            nu: vec![0.0; self.hard.ocp.rows.len()],
        })
    }

    /// Builds the workspaces for a validated problem. The starts: `[solver] starts` as
    /// written, `warm` alone for a convex OCP, else the default decided by the problem's
    /// pilot ([`pilot`]: run once per process, about 100 × 4 solves).
    ///
    /// ```
    /// let cfg = trainer::problem::ProblemConfig::default();
    /// let mut law = trainer::mpc::law::MpcLaw::new(&cfg);
    /// let (label, _) = law.solve(&[0.0, 0.0], None);
    /// assert!(label.u[0].abs() < 1e-9);
    /// ```
    pub fn new(cfg: &ProblemConfig) -> Self {
        let hard = SqpSolver::new(cfg, false);
        let convex = cfg.system.is_affine() && !hard.ocp.has_nonlinear_rows();
        let starts = match &cfg.solver.starts {
            _ if convex => vec![crate::problem::solver::Start::Warm],
            Some(s) => s.clone(),
            None => pilot::pilot(cfg).starts,
        };
        Self::assemble(cfg, hard, starts)
    }

    fn assemble(
        cfg: &ProblemConfig,
        hard: SqpSolver,
        starts: Vec<crate::problem::solver::Start>,
    ) -> Self {
        MpcLaw {
            cfg: cfg.mpc_problem().into_owned(),
            hard,
            soft: None,
            soft_warm: None,
            soft_solution: None,
            starts,
            lqr: None,
        }
    }

    /// The hard problem's solver.
    pub fn hard_solver(&self) -> &SqpSolver {
        &self.hard
    }

    /// The label of a converged solve `r` of `solver` (its last solve), through the gate of
    /// [`crate::mpc::finite`]: the solution, the cost, the KKT residual re-computed at the
    /// returned point and the sensitivity finite, the residual ≤ tol. Otherwise the state is
    /// unlabelled, `numerical_failure`, with the failure in `info.failure`.
    fn finish(&self, solver: &SqpSolver, xs: &[f64], r: &SqpResult, status: SqpStatus) -> Label {
        let sens = sensitivity(solver, xs, &r.point, self.cfg.solver.degeneracy_tol);
        self.finish_with(solver, xs, r, status, Some(sens))
    }

    /// [`finish`](Self::finish) without the sensitivity, for a step of a simulated closed
    /// loop, which uses κ(x) and the solution only: `du_dx` is NaN, `active` empty,
    /// `degeneracy` none; the gate checks the rest (solution, cost, re-computed KKT
    /// residual). The sensitivity (a KKT factorisation and nx solves) was a fifth of the
    /// quadrotor's closed-loop step.
    fn finish_input(
        &self,
        solver: &SqpSolver,
        xs: &[f64],
        r: &SqpResult,
        status: SqpStatus,
    ) -> Label {
        self.finish_with(solver, xs, r, status, None)
    }

    /// The label of `r` with the sensitivity `sens` ([`finish`](Self::finish)), or without
    /// one ([`finish_input`](Self::finish_input)).
    fn finish_with(
        &self,
        solver: &SqpSolver,
        xs: &[f64],
        r: &SqpResult,
        status: SqpStatus,
        sens: Option<crate::mpc::sensitivity::Sensitivity>,
    ) -> Label {
        let ocp = &solver.ocp;
        let gated = sens.is_some();
        let (du0_dx, degeneracy, active) = match sens {
            Some(s) => (s.du0_dx, s.degeneracy, s.active),
            None => (vec![f64::NAN; ocp.nu * ocp.nx], None, Vec::new()),
        };
        let iu = ocp.iu(0);
        let cost = ocp.objective(&r.point.z);
        let res = solver.residual_at_solution(xs, &r.point);
        let gate = check_label(&LabelParts {
            z: &r.point.z,
            cost,
            residual: [res.stationarity, res.primal, res.dual, res.complementarity],
            sensitivity: if gated { &du0_dx } else { &[] },
            tol: self.cfg.solver.tol,
        });
        if let Err(f) = gate {
            let info = SqpInfo {
                kkt: res,
                failure: Some(f),
                ..r.info
            };
            return self.unlabelled(xs, SqpStatus::NumericalFailure, info);
        }
        Label {
            x: xs.to_vec(),
            u: r.point.z[iu..iu + ocp.nu].to_vec(),
            du_dx: du0_dx,
            cost,
            status,
            info: r.info,
            degeneracy,
            max_slack: r.point.z[ocp.is()..]
                .iter()
                .fold(0.0, |m, v| nan_max(m, *v)),
            active,
            retry: None,
            optima: 0,
            seq: (0..ocp.horizon)
                .flat_map(|k| r.point.z[ocp.iu(k)..ocp.iu(k) + ocp.nu].iter().copied())
                .collect(),
        }
    }

    /// [`finish`](Self::finish) with the solution for warm starts, only if it is a label.
    fn finish_with_point(
        &self,
        solver: &SqpSolver,
        xs: &[f64],
        r: SqpResult,
        status: SqpStatus,
    ) -> (Label, Option<PrimalDual>) {
        let label = self.finish(solver, xs, &r, status);
        let point = label.status.is_labelled().then_some(r.point);
        (label, point)
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
            retry: None,
            optima: 0,
            seq: Vec::new(),
        }
    }

    /// The MPC law at `xs`: OCP(xs) solved from every start of [`starts`](Self::starts), the
    /// lowest-cost hard optimum kept ([`starts`] module; [`solve_single`](Self::solve_single)
    /// alone for a convex OCP or `starts = ["warm"]`). `warm` is a neighbour's hard solution
    /// (same problem). Returns the label and, for converged hard solves, the solution (to
    /// warm-start neighbours).
    pub fn solve(&mut self, xs: &[f64], warm: Option<&PrimalDual>) -> (Label, Option<PrimalDual>) {
        self.solve_starts(xs, warm, None)
    }

    /// Solves OCP(xs) from one start, the `warm` one: `warm` is a neighbour's hard solution
    /// (same problem), else the cold guess. Returns the label and, for converged hard solves,
    /// the solution (to warm-start neighbours). States the plain solve leaves without a label
    /// climb the retry ladder (module doc).
    pub fn solve_single(
        &mut self,
        xs: &[f64],
        warm: Option<&PrimalDual>,
    ) -> (Label, Option<PrimalDual>) {
        let (label, sol) = self.solve_plain(xs, warm);
        if !matches!(
            label.status,
            SqpStatus::MaxIterations | SqpStatus::NumericalFailure
        ) || xs.iter().any(|v| !v.is_finite())
            || xs.len() != self.hard.ocp.nx
        {
            return (label, sol);
        }
        let spent = label.info.iterations;
        match self.retry(xs) {
            Some((mut l, sol, retry)) => {
                l.info.iterations += spent;
                // (A rung whose solve the gate refused labelled nothing.)
                if l.status != SqpStatus::NumericalFailure {
                    l.retry = Some(retry);
                }
                (l, sol)
            }
            None => (label, sol),
        }
    }

    fn solve_plain(
        &mut self,
        xs: &[f64],
        warm: Option<&PrimalDual>,
    ) -> (Label, Option<PrimalDual>) {
        if xs.iter().any(|v| !v.is_finite()) || xs.len() != self.hard.ocp.nx {
            let info = SqpInfo {
                failure: xs
                    .iter()
                    .any(|v| !v.is_finite())
                    .then_some(Failure::NonFinite(Quantity::State)),
                ..SqpInfo::default()
            };
            return (self.unlabelled(xs, SqpStatus::NumericalFailure, info), None);
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
            // (Converged to numbers that are no label — the gate — gives no point: no soft
            // problem can repair the plant's arithmetic; the retry ladder may still try.)
            return self.finish_with_point(&self.hard, xs, r, SqpStatus::Converged);
        }
        // Hard solve failed: let the exact-penalty problem decide feasibility.
        let cfg = &self.cfg;
        let soft = self.soft.get_or_insert_with(|| SqpSolver::new(cfg, true));
        let mut s = match self.soft_warm.take() {
            // Warm-started from the last soft optimum along a trajectory, retried cold if
            // that does not converge.
            Some(mut w) if w.z.len() == soft.ocp.n_var => {
                w.z[..xs.len()].copy_from_slice(xs);
                let s = soft.solve(xs, w);
                if s.status == SqpStatus::Converged {
                    s
                } else {
                    let mut cold = soft.solve(xs, soft.cold_start(xs));
                    cold.info.iterations += s.info.iterations;
                    cold
                }
            }
            _ => soft.solve(xs, soft.cold_start(xs)),
        };
        s.info.iterations += r.info.iterations;
        if s.status != SqpStatus::Converged {
            let status = if r.status == SqpStatus::Infeasible {
                s.status
            } else {
                r.status
            };
            // (The hard solve's failure, e.g. the non-finite quantity, if the soft one
            // names none.)
            let info = SqpInfo {
                failure: s.info.failure.or(r.info.failure),
                ..s.info
            };
            return (self.unlabelled(xs, status, info), None);
        }
        if let Some(start) = self.hard_start_from_soft(&s) {
            // Feasible after all: re-solve the hard problem from the soft optimum.
            let mut h = self.hard.solve(xs, start);
            h.info.iterations += s.info.iterations;
            if h.status == SqpStatus::Converged {
                return self.finish_with_point(&self.hard, xs, h, SqpStatus::Converged);
            }
            // Feasible, yet the hard solve fails: report the failure, not a soft label.
            return (self.unlabelled(xs, r.status, h.info), None);
        }
        if !self.cfg.solver.soft_fallback {
            return (self.unlabelled(xs, SqpStatus::Infeasible, s.info), None);
        }
        let soft = self.soft.as_ref().map_or(&self.hard, |s| s);
        let label = self.finish(soft, xs, &s, SqpStatus::Soft);
        if label.status.is_labelled() {
            self.soft_solution = Some(s.point);
        }
        (label, None)
    }

    /// [`solve`](Self::solve) at a state of a trajectory: `warm` is the last hard solution
    /// (as for `solve`), `warm_soft` the last soft optimum, from which the soft problem is
    /// warm-started (then retried cold if that does not converge). Returns the label, the
    /// hard solution (for hard labels) and the soft optimum (for soft labels by the plain
    /// solve), to warm-start the next state.
    pub fn solve_along(
        &mut self,
        xs: &[f64],
        warm: Option<&PrimalDual>,
        warm_soft: Option<&PrimalDual>,
    ) -> (Label, Option<PrimalDual>, Option<PrimalDual>) {
        self.soft_warm = warm_soft.cloned();
        self.soft_solution = None;
        let (label, sol) = self.solve(xs, warm);
        self.soft_warm = None;
        let soft = self
            .soft_solution
            .take()
            .filter(|_| label.status == SqpStatus::Soft);
        (label, sol, soft)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mpc::tests::ipopt_labels::PENDULUM_IPOPT;

    /// Along a trajectory through hard-infeasible states (the pendulum's corner, θ = 2π,
    /// ω > 0.5), `solve_along` hands back the soft optimum, and the next state's soft problem
    /// warm-started from it converges to the cold soft label in fewer iterations; with no warm
    /// start, `solve_along` is `solve` bit for bit; a bad warm start is retried cold.
    #[test]
    fn solve_along_warm_starts_the_soft_problem() {
        let cfg = ProblemConfig::default();
        let two_pi = 2.0 * std::f64::consts::PI;
        let (a, b) = ([two_pi, 1.0], [two_pi, 0.98]);
        let mut law = MpcLaw::new(&cfg);
        let (la, _, soft) = law.solve_along(&a, None, None);
        assert_eq!(la.status, SqpStatus::Soft);
        let soft = soft.expect("a soft label hands back its optimum");
        let (cold, _) = MpcLaw::new(&cfg).solve(&b, None);
        let (plain, _, _) = law.solve_along(&b, None, None);
        assert_eq!(plain, cold);
        let (warm, _, next) = law.solve_along(&b, None, Some(&soft));
        assert_eq!(warm.status, SqpStatus::Soft);
        assert!(next.is_some());
        assert!(
            (warm.u[0] - cold.u[0]).abs() <= 1e-6,
            "{} vs {}",
            warm.u[0],
            cold.u[0]
        );
        assert!(
            warm.info.iterations < cold.info.iterations,
            "warm {} vs cold {} iterations",
            warm.info.iterations,
            cold.info.iterations
        );
        // A warm start that cannot converge (NaN multipliers) falls back to the cold solve.
        let mut bad = soft.clone();
        bad.lam.iter_mut().for_each(|v| *v = f64::NAN);
        let (l, _, _) = law.solve_along(&b, None, Some(&bad));
        assert_eq!(l.status, SqpStatus::Soft);
        assert_eq!(l.u, cold.u);
    }

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

    fn config(name: &str) -> ProblemConfig {
        let path = std::path::PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/"))
            .join(name);
        ProblemConfig::load(&path).unwrap_or_else(|e| panic!("{e}"))
    }

    /// A cart-pole state (i = 2127 of 3000 uniform random states of `configs/cartpole.toml`'s
    /// X, coordinates `rng::uniform(77, i, j)`; the only one of them the plain solve leaves
    /// unlabelled since the soft problem's second-order correction, which lets the plain
    /// path label this test's earlier state) where IPOPT (tol 1e-10,
    /// `tests/reference/ipopt_compare.py`'s OCP) converges to u₀ = −20 (saturated), cost
    /// 866.7252011371372. The ladder labels it: a KKT point of the hard problem (residual
    /// recomputed from the returned point) with IPOPT's input and cost.
    #[test]
    fn a_state_the_plain_solve_fails_is_labelled_by_a_retry() {
        let cfg = config("cartpole.toml");
        let xs = [
            -0.9926724302168126,
            -0.5835645472878936,
            0.6658719350262772,
            -0.8970441797758042,
        ];
        let (ipopt_u, ipopt_cost) = (-19.99999999999944, 866.7252011371372);
        let mut law = MpcLaw::new(&cfg);
        let (plain, _) = law.solve_plain(&xs, None);
        assert!(
            matches!(
                plain.status,
                SqpStatus::MaxIterations | SqpStatus::NumericalFailure
            ),
            "{:?}",
            plain.status
        );
        let (l, sol) = law.solve(&xs, None);
        eprintln!("{:?} {:?} u {:?} cost {}", l.status, l.retry, l.u, l.cost);
        assert_eq!(l.status, SqpStatus::Converged);
        assert!(l.retry.is_some());
        let sol = sol.expect("a converged hard solve returns its point");
        let res = law.hard_solver().kkt_residual(&xs, &sol);
        assert!(res.max() <= cfg.solver.tol, "{res:?}");
        assert_eq!(l.u, sol.z[law.hard_solver().ocp.iu(0)..][..1].to_vec());
        assert!(
            (l.u[0] - ipopt_u).abs() <= 1e-6,
            "u {} vs IPOPT {ipopt_u}",
            l.u[0]
        );
        assert!(
            (l.cost - ipopt_cost).abs() <= 1e-6 * ipopt_cost,
            "cost {} vs IPOPT {ipopt_cost}",
            l.cost
        );
        assert!(l.du_dx.iter().all(|v| v.is_finite()));
    }

    /// States the plain solve labels get exactly its label: the ladder runs only after a
    /// failure (random cart-pole states, compared field by field).
    #[test]
    fn labels_without_a_retry_are_the_plain_ones() {
        let cfg = config("cartpole.toml");
        let (lo, hi) = (&cfg.domain.lo, &cfg.domain.hi);
        let mut law = MpcLaw::new(&cfg);
        for i in 0..20u64 {
            let xs: Vec<f64> = (0..4)
                .map(|k| lo[k] + (hi[k] - lo[k]) * crate::rng::uniform(41, i, k as u64))
                .collect();
            let (a, pa) = law.solve_plain(&xs, None);
            let (b, pb) = law.solve_single(&xs, None);
            if a.status.is_labelled() {
                assert_eq!(a, b, "{xs:?}");
                assert_eq!(pa, pb, "{xs:?}");
                assert!(b.retry.is_none());
            }
        }
    }
}
