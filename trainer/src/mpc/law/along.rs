//! The MPC law along a trajectory ([`Along`], [`MpcLaw::solve_next`]): the closed loop's
//! κ(x_k), solved from what step k − 1 left behind.
//!
//! The previous hard solution z*_{k−1} = (x_0, u_0, …, x_{N−1}, u_{N−1}, x_N), shifted one
//! stage, is the warm start of step k (the standard MPC warm start):
//! ```text
//! z⁰_k = (x_k, u_1, x_2, u_2, …, x_N, u_{N−1}, F(x_N, u_{N−1}))     λ⁰_k = (λ_1, …, λ_N, λ_N)
//! ```
//! (x_k the measured state, the last input repeated, the new terminal state projected onto
//! the state bounds; ν⁰ = 0). One step of the plant moves the optimum about as far as one
//! stage of the prediction, so the shifted guess is close and the solve takes few iterations.
//!
//! **Which steps get the extra starts.** A run's first step (no previous solution) is solved
//! as a label is ([`MpcLaw::solve`]: every start of `solver.starts`, lowest cost kept), so a
//! run starts on the branch a label would choose. After that a step whose shifted warm start
//! converges to a hard KKT point keeps it: the law continues its branch (the continuation
//! rule by which [`super::starts`] breaks ties among equal costs, and the branch the MPC
//! being simulated follows — re-choosing the branch at every step would make the simulated
//! controller switch between local optima that a real MPC, warm-started the same way,
//! does not visit). A step whose warm start does not converge to a hard optimum is solved
//! like a label from scratch: all starts, the soft fallback and the retry ladder. A
//! non-convex plant's closed loop can therefore sit in a local optimum of higher cost than
//! a fresh multi-start label of the same state; [`Along::extra_start_steps`] counts the
//! steps that used the extra starts.
//!
//! **Hard-infeasible states fail fast.** When step k − 1 was labelled by the soft problem
//! (its optimum has a slack > [`SLACK_TOL`](super::SLACK_TOL): the hard OCP is locally
//! infeasible there), step k first solves the soft problem warm from that optimum; if it
//! converges with a slack > `SLACK_TOL` again, that decides the step exactly as the plain
//! solve's soft fallback would after its hard solves failed (hard-infeasible, labelled soft,
//! or `infeasible` without `solver.soft_fallback`) — the hard solves, extra starts and the
//! retry ladder, which cannot label a hard-infeasible state, are skipped. A step whose soft
//! optimum has no slack, or whose soft solve fails, takes the full path.

use super::{Label, MpcLaw, SLACK_TOL};
use crate::mpc::finite::nan_max;
use crate::mpc::sqp::{PrimalDual, SqpSolver, SqpStatus};

/// What a trajectory carries from one step's solve to the next (start a new one per run).
#[derive(Debug, Clone, Default)]
pub struct Along {
    /// The last hard solution (for the shifted warm start).
    hard: Option<PrimalDual>,
    /// The last soft optimum (warm start of the soft problem).
    soft: Option<PrimalDual>,
    /// Whether the last step was labelled by the soft problem.
    last_soft: bool,
    /// Steps solved so far.
    pub steps: usize,
    /// Steps solved from every start of `solver.starts` (the first step and those whose
    /// warm start did not converge).
    pub extra_start_steps: usize,
    /// Steps decided by the soft problem alone (fail-fast on hard-infeasible states).
    pub soft_fast_steps: usize,
}

impl MpcLaw {
    /// κ at the next state `xs` of a trajectory (module doc): warm from the shifted previous
    /// solution, the extra starts and the retry ladder only where that warm start does not
    /// converge, hard-infeasible states decided by the soft problem alone. Updates `along`.
    /// A step that the warm start decides carries no sensitivity (`du_dx` NaN, `active`
    /// empty): a closed loop needs u and the solution only.
    pub fn solve_next(&mut self, xs: &[f64], along: &mut Along) -> Label {
        along.steps += 1;
        let valid = xs.len() == self.hard.ocp.nx && xs.iter().all(|v| v.is_finite());
        if valid && along.last_soft {
            if let Some(l) = self.soft_fast(xs, along) {
                along.soft_fast_steps += 1;
                return l;
            }
        }
        if let (true, Some(prev)) = (valid, along.hard.as_ref()) {
            let start = shifted(&self.hard, prev, xs);
            let r = self.hard.solve(xs, start);
            if r.status == SqpStatus::Converged {
                // κ(x_k) alone: a closed loop uses no sensitivity (`finish_input`).
                let l = self.finish_input(&self.hard, xs, &r, SqpStatus::Converged);
                if l.status.is_labelled() {
                    along.hard = Some(r.point);
                    along.last_soft = false;
                    return l;
                }
            }
        }
        along.extra_start_steps += 1;
        let (l, sol, soft) = self.solve_along(xs, along.hard.as_ref(), along.soft.as_ref());
        along.last_soft = l.status == SqpStatus::Soft && soft.is_some();
        if let Some(s) = soft {
            along.soft = Some(s);
        }
        if l.status.is_labelled() {
            if let Some(p) = sol {
                along.hard = Some(p);
            }
        }
        l
    }

    /// The soft problem at `xs` warm from the last soft optimum: the step's label if its
    /// optimum has a slack > [`SLACK_TOL`] (module doc), else `None` (take the full path).
    fn soft_fast(&mut self, xs: &[f64], along: &mut Along) -> Option<Label> {
        let mut w = along.soft.clone()?;
        let cfg = &self.cfg;
        let soft = self.soft.get_or_insert_with(|| SqpSolver::new(cfg, true));
        if w.z.len() != soft.ocp.n_var {
            return None;
        }
        w.z[..xs.len()].copy_from_slice(xs);
        let s = soft.solve(xs, w);
        if s.status != SqpStatus::Converged {
            return None;
        }
        let is = soft.ocp.is();
        let max_slack = s.point.z[is..].iter().fold(0.0, |m, v| nan_max(m, *v));
        if max_slack.is_nan() || max_slack <= SLACK_TOL {
            return None;
        }
        if !self.cfg.solver.soft_fallback {
            along.last_soft = true;
            along.soft = Some(s.point);
            return Some(self.unlabelled(xs, SqpStatus::Infeasible, s.info));
        }
        let soft = self.soft.as_ref().map_or(&self.hard, |s| s);
        let l = self.finish(soft, xs, &s, SqpStatus::Soft);
        if !l.status.is_labelled() {
            return None;
        }
        along.soft = Some(s.point);
        along.last_soft = true;
        Some(l)
    }
}

/// The hard solution `p` shifted one stage, with x₀ = `xs` (module doc).
fn shifted(solver: &SqpSolver, p: &PrimalDual, xs: &[f64]) -> PrimalDual {
    let ocp = &solver.ocp;
    let (nx, nu, n) = (ocp.nx, ocp.nu, ocp.horizon);
    let nz = nx + nu;
    let mut z = p.z.clone();
    if n >= 1 {
        z.copy_within(nz..n * nz + nx, 0);
        // (u_{N−1} stays: the last input repeated.)
        let (x_last, u_last) = (ocp.ix(n - 1), ocp.iu(n - 1));
        let mut xn = vec![0.0; nx];
        ocp.model
            .step(&z[x_last..x_last + nx], &z[u_last..u_last + nu], &mut xn);
        let (lo, hi) = solver.state_bounds();
        for i in 0..nx {
            let v = if xn[i].is_finite() {
                xn[i]
            } else {
                z[x_last + i]
            };
            z[ocp.ix(n) + i] = v.clamp(lo[i], hi[i]);
        }
    }
    z[..nx].copy_from_slice(xs);
    let mut lam = p.lam.clone();
    if lam.len() == (n + 1) * nx && n >= 1 {
        lam.copy_within(nx.., 0);
    }
    PrimalDual {
        z,
        lam,
        nu: vec![0.0; p.nu.len()],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::problem::ProblemConfig;

    fn config(name: &str) -> ProblemConfig {
        let path = std::path::PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/"))
            .join(name);
        ProblemConfig::load(&path).unwrap_or_else(|e| panic!("{e}"))
    }

    /// The quadrotor's MPC closed loop from the study's first state: every step labelled
    /// with the input of a fresh multi-start label of the same state (1e-6; the warm steps
    /// without a sensitivity, the fresh labels with one), the extra starts
    /// used at the first step only, and fewer SQP iterations in all than the unshifted warm
    /// start of `solve_along` (the closed loop before the shift).
    #[test]
    fn the_shifted_warm_start_keeps_the_labels_and_saves_iterations() {
        let cfg = config("planar_quadrotor.toml");
        let mut law = MpcLaw::new(&cfg);
        let mut fresh = MpcLaw::new(&cfg);
        let mut along = Along::default();
        let (mut warm, mut warm_soft) = (None, None);
        let mut x = vec![-0.5, -0.5, -0.25, -0.5, -0.5, -0.5];
        let (mut shifted_iters, mut unshifted_iters) = (0, 0);
        let mut next = vec![0.0; 6];
        for _ in 0..40 {
            let l = law.solve_next(&x, &mut along);
            let (old, sol, soft) = fresh.solve_along(&x, warm.as_ref(), warm_soft.as_ref());
            (warm, warm_soft) = (sol.or(warm), soft.or(warm_soft));
            let (cold, _) = MpcLaw::new(&cfg).solve(&x, None);
            assert_eq!(l.status, SqpStatus::Converged, "{x:?}");
            for (a, b) in l.u.iter().zip(&cold.u) {
                assert!((a - b).abs() <= 1e-6, "{x:?}: {:?} vs {:?}", l.u, cold.u);
            }
            // A warm step is decided without the sensitivity (`finish_input`); the first
            // (a label's solve) and a fresh label have it.
            let warm_step = along.steps > 1 && along.extra_start_steps == 1;
            assert_eq!(l.du_dx.iter().all(|v| v.is_nan()), warm_step, "{x:?}");
            assert!(cold.du_dx.iter().all(|v| v.is_finite()), "{x:?}");
            shifted_iters += l.info.iterations;
            unshifted_iters += old.info.iterations;
            law.hard_solver().ocp.model.step(&x, &l.u, &mut next);
            x.copy_from_slice(&next);
        }
        eprintln!("iterations: shifted {shifted_iters}, unshifted {unshifted_iters}");
        assert_eq!(along.steps, 40);
        assert_eq!(along.extra_start_steps, 1);
        assert!(shifted_iters < unshifted_iters);
    }

    /// Through the pendulum's hard-infeasible corner (θ = 2π, ω > 0.5; soft labels): after a
    /// soft step the next soft step is decided by the soft problem alone (no hard solve, no
    /// extra start), with the label of the full path (`solve_along` from the same soft
    /// optimum) and fewer iterations.
    #[test]
    fn hard_infeasible_steps_fail_fast() {
        let cfg = ProblemConfig::default();
        let two_pi = 2.0 * std::f64::consts::PI;
        let mut law = MpcLaw::new(&cfg);
        let mut along = Along::default();
        let a = law.solve_next(&[two_pi, 1.0], &mut along);
        assert_eq!(a.status, SqpStatus::Soft);
        assert_eq!((along.soft_fast_steps, along.extra_start_steps), (0, 1));
        let soft = along.soft.clone().expect("the soft optimum is kept");
        let b = law.solve_next(&[two_pi, 0.98], &mut along);
        assert_eq!(b.status, SqpStatus::Soft);
        assert_eq!((along.soft_fast_steps, along.extra_start_steps), (1, 1));
        let (full, _, _) = MpcLaw::new(&cfg).solve_along(&[two_pi, 0.98], None, Some(&soft));
        assert_eq!(full.status, SqpStatus::Soft);
        assert!(
            (b.u[0] - full.u[0]).abs() <= 1e-6,
            "{} vs {}",
            b.u[0],
            full.u[0]
        );
        assert!(
            b.info.iterations < full.info.iterations,
            "fast {} vs full {}",
            b.info.iterations,
            full.info.iterations
        );
        // Back in the feasible set, the full path again.
        let c = law.solve_next(&[0.5, 0.0], &mut along);
        assert_eq!(c.status, SqpStatus::Converged);
        assert_eq!(along.soft_fast_steps, 1);
    }
}
