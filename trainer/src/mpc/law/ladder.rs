//! The retry ladder of [`MpcLaw`] (the `law` module doc's rungs 1–3) and its budget: the
//! hard rungs (1, conservative; 2, the two continuations) spend at most
//! `B = solver.retry_budget × max_iter` SQP iterations on one state,
//! ```text
//! Σ_{solves of rungs 1–2} iterations ≤ B + (one solve's polish iterations),
//! ```
//! each solve capped at what is left ([`crate::mpc::sqp::SqpSolver::set_iteration_cap`]),
//! the hard rungs skipped as soon as nothing is left. Rung 3 (the soft problem, which
//! decides soft labels and infeasibility) runs after them with its own limits (two solves of
//! at most 3·max_iter). A budget of 0 skips the whole ladder, rung 3 included. A state the
//! ladder gives up on keeps the plain solve's status (no label).
//!
//! **Counting stages.** The stages that only count the states the MPC leaves unlabelled
//! (validation, the statistical tier's states, the closed-loop statistical starts) label
//! with [`counting_problem`]: no ladder at all. On the CSTR a failing state's cost is
//! proportional to its SQP iterations, and most of them were the ladder's (rung 3 alone up
//! to 6·max_iter); a state converged by the plain solve keeps its label bit for bit, a state
//! only the ladder would label is counted unlabelled there (BENCHMARKS.md, "Retry
//! budget").

use super::{Label, MpcLaw, Retry};
use crate::mpc::sqp::{Globalisation, PrimalDual, SqpInfo, SqpResult, SqpSolver, SqpStatus};
use crate::problem::ProblemConfig;

/// Step of the continuation parameter θ below which the continuation gives up.
const MIN_THETA_STEP: f64 = 1.0 / 256.0;
/// Hard solves one continuation may spend.
const MAX_CONTINUATION_SOLVES: usize = 40;

/// The labelling problem of a stage that only counts unlabelled states: `cfg` with
/// `solver.retry_budget = 0` (no retry ladder; module doc).
pub fn counting_problem(cfg: &ProblemConfig) -> ProblemConfig {
    let mut c = cfg.clone();
    c.solver.retry_budget = 0;
    c
}

impl MpcLaw {
    /// The retry ladder (module doc) for a state the plain solve left without a label.
    pub(super) fn retry(&mut self, xs: &[f64]) -> Option<(Label, Option<PrimalDual>, Retry)> {
        if self.cfg.solver.retry_budget == 0 {
            return None;
        }
        let budget = self.retry_budget();
        let mut spent = 0;
        let hard = self.retry_hard(xs, budget, &mut spent);
        self.hard.set_iteration_cap(None);
        hard.or_else(|| self.retry_soft(xs, &mut spent))
    }

    /// Sets `solver.retry_budget` of this law (0: no ladder, as [`counting_problem`]) and
    /// returns the one it replaces; nothing else about the law changes.
    pub fn set_retry_budget(&mut self, budget: usize) -> usize {
        std::mem::replace(&mut self.cfg.solver.retry_budget, budget)
    }

    /// The SQP iterations the retry ladder may spend on one state: `solver.retry_budget ×
    /// max_iter`.
    fn retry_budget(&self) -> usize {
        self.cfg
            .solver
            .retry_budget
            .saturating_mul(self.cfg.solver.max_iter)
    }

    /// Caps the ladder's next hard solve at what is left of `budget` after `spent`
    /// iterations; `None` when nothing is left.
    fn cap(&mut self, budget: usize, spent: usize) -> Option<()> {
        let left = budget.checked_sub(spent).filter(|l| *l > 0)?;
        self.hard.set_iteration_cap(Some(left));
        Some(())
    }

    /// The hard rungs (1 and 2) of [`retry`](Self::retry) within `budget` SQP iterations,
    /// every solve capped at what is left and the rungs skipped once it is spent; their
    /// iterations are added to `spent`. The caller lifts the cap afterwards.
    fn retry_hard(
        &mut self,
        xs: &[f64],
        budget: usize,
        spent: &mut usize,
    ) -> Option<(Label, Option<PrimalDual>, Retry)> {
        // 1. Conservative globalisation, cold start.
        if self.cap(budget, *spent).is_some() {
            self.hard.set_globalisation(Globalisation::Conservative);
            let r = self.hard.solve(xs, self.hard.cold_start(xs));
            self.hard.set_globalisation(Globalisation::Default);
            *spent += r.info.iterations;
            if r.status == SqpStatus::Converged {
                let (mut l, point) =
                    self.finish_with_point(&self.hard, xs, r, SqpStatus::Converged);
                l.info.iterations = *spent;
                return Some((l, point, Retry::Conservative));
            }
        }
        // 2. Continuation from the setpoint.
        for (g, rung) in [
            (Globalisation::Default, Retry::Continuation),
            (Globalisation::Conservative, Retry::ContinuationConservative),
        ] {
            self.hard.set_globalisation(g);
            let c = self.continuation(xs, budget, spent);
            self.hard.set_globalisation(Globalisation::Default);
            if let Some(r) = c {
                let (mut l, point) =
                    self.finish_with_point(&self.hard, xs, r, SqpStatus::Converged);
                l.info.iterations = *spent;
                return Some((l, point, rung));
            }
        }
        None
    }

    /// Rung 3 of [`retry`](Self::retry): the soft problem, conservative globalisation
    /// (outside the budget: its solves have their own limits, and it decides the soft
    /// labels); its iterations are added to `spent`.
    fn retry_soft(
        &mut self,
        xs: &[f64],
        spent: &mut usize,
    ) -> Option<(Label, Option<PrimalDual>, Retry)> {
        let cfg = &self.cfg;
        let soft = self.soft.get_or_insert_with(|| SqpSolver::new(cfg, true));
        soft.set_globalisation(Globalisation::Conservative);
        let s = soft.solve(xs, soft.cold_start(xs));
        soft.set_globalisation(Globalisation::Default);
        *spent += s.info.iterations;
        if s.status != SqpStatus::Converged {
            return None;
        }
        if let Some(start) = self.hard_start_from_soft(&s) {
            self.hard.set_globalisation(Globalisation::Conservative);
            let h = self.hard.solve(xs, start);
            self.hard.set_globalisation(Globalisation::Default);
            *spent += h.info.iterations;
            if h.status != SqpStatus::Converged {
                return None;
            }
            let (mut l, point) = self.finish_with_point(&self.hard, xs, h, SqpStatus::Converged);
            l.info.iterations = *spent;
            return Some((l, point, Retry::Soft));
        }
        let status = if self.cfg.solver.soft_fallback {
            SqpStatus::Soft
        } else {
            SqpStatus::Infeasible
        };
        if status == SqpStatus::Infeasible {
            let info = SqpInfo {
                iterations: *spent,
                ..s.info
            };
            return Some((self.unlabelled(xs, status, info), None, Retry::Soft));
        }
        let soft = self.soft.as_ref().map_or(&self.hard, |s| s);
        let mut l = self.finish(soft, xs, &s, SqpStatus::Soft);
        l.info.iterations = *spent;
        Some((l, None, Retry::Soft))
    }

    /// The hard problem at x_c + θ(x_s − x_c), θ = 0 → 1, each solve warm-started from the
    /// last solved θ. Returns the solve at θ = 1, or `None` if a step below
    /// [`MIN_THETA_STEP`] fails, the solves run out or the ladder's `budget` is spent.
    fn continuation(&mut self, xs: &[f64], budget: usize, spent: &mut usize) -> Option<SqpResult> {
        let nx = xs.len();
        let centre: Vec<f64> = if self.hard.ocp.x_ref.len() == nx {
            self.hard.ocp.x_ref.clone()
        } else {
            vec![0.0; nx]
        };
        self.cap(budget, *spent)?;
        let mut r = self.hard.solve(&centre, self.hard.cold_start(&centre));
        *spent += r.info.iterations;
        if r.status != SqpStatus::Converged {
            return None;
        }
        let (mut theta, mut step) = (0.0f64, 0.25f64);
        let mut x = vec![0.0; nx];
        for _ in 0..MAX_CONTINUATION_SOLVES {
            let t = (theta + step).min(1.0);
            for i in 0..nx {
                x[i] = centre[i] + t * (xs[i] - centre[i]);
            }
            if t == 1.0 {
                x.copy_from_slice(xs);
            }
            let mut start = r.point.clone();
            start.z[..nx].copy_from_slice(&x);
            self.cap(budget, *spent)?;
            let next = self.hard.solve(&x, start);
            *spent += next.info.iterations;
            if next.status == SqpStatus::Converged {
                if t == 1.0 {
                    return Some(next);
                }
                (theta, r) = (t, next);
                step = (2.0 * step).min(0.5);
            } else {
                step *= 0.5;
                if step < MIN_THETA_STEP {
                    return None;
                }
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use crate::mpc::law::MpcLaw;
    use crate::mpc::sqp::SqpStatus;
    use crate::problem::solver::Start;
    use crate::problem::ProblemConfig;

    fn cstr(budget: usize) -> ProblemConfig {
        let path =
            std::path::PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/cstr.toml"));
        let mut cfg = ProblemConfig::load(&path).unwrap_or_else(|e| panic!("{e}"));
        // One start: the ladder is the `warm` start's (and no pilot to run).
        cfg.solver.starts = Some(vec![Start::Warm]);
        cfg.solver.retry_budget = budget;
        cfg
    }

    /// The CSTR's runaway state (Ca, T) = (0.55, 359) (configs/cstr.toml: even full cooling
    /// cannot hold it inside the constraints): the plain solve and every rung fail. With the
    /// budget lifted its hard rungs spend more than one `max_iter`; with a budget of one
    /// `max_iter` they spend at most that plus one solve's polish iterations (the bound of the
    /// module doc), and with 0 none; the state is unlabelled either way, with the plain
    /// solve's status, and the soft rung still runs (its iterations are counted as before).
    #[test]
    fn the_budget_bounds_the_hard_rungs_of_a_failing_state() {
        let xs = [0.55, 359.0];
        let spent_with = |budget: usize| {
            let cfg = cstr(budget);
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
            let b = law.retry_budget();
            assert_eq!(b, budget * cfg.solver.max_iter);
            // The hard rungs alone: the soft rung's solver given no iteration at all.
            let mut hard = 0;
            let out = law.retry_hard(&xs, b, &mut hard);
            assert!(out.is_none(), "the runaway state got a label");
            let (l, _) = law.solve(&xs, None);
            assert!(!l.status.is_labelled(), "{:?}", l.status);
            assert_eq!(l.status, plain.status);
            hard
        };
        let max_iter = cstr(0).solver.max_iter;
        let free = spent_with(1000);
        assert!(
            free > max_iter + 10,
            "unbudgeted hard rungs spent only {free}"
        );
        let one = spent_with(1);
        assert!(one <= max_iter + 10, "budget {max_iter}: spent {one}");
        assert!(one > 0);
        assert_eq!(spent_with(0), 0);
    }

    /// The counting stages' problem has no ladder: the cart-pole state only a retry labels
    /// (`law` tests, `a_state_the_plain_solve_fails_is_labelled_by_a_retry`) stays
    /// unlabelled, with the plain solve's status, while states the plain solve labels get
    /// the very same label as with the ladder.
    #[test]
    fn counting_labels_without_the_ladder_and_keeps_plain_labels() {
        let path = std::path::PathBuf::from(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../configs/cartpole.toml"
        ));
        let mut cfg = ProblemConfig::load(&path).unwrap_or_else(|e| panic!("{e}"));
        // The `warm` start alone: the ladder is its (no other start to label the state).
        cfg.solver.starts = Some(vec![Start::Warm]);
        let counting = super::counting_problem(&cfg);
        assert_eq!(counting.solver.retry_budget, 0);
        let (mut full, mut count) = (MpcLaw::new(&cfg), MpcLaw::new(&counting));
        let xs = [
            -0.9926724302168126,
            -0.5835645472878936,
            0.6658719350262772,
            -0.8970441797758042,
        ];
        let (with, _) = full.solve(&xs, None);
        assert!(with.status.is_labelled() && with.retry.is_some());
        let (without, _) = count.solve(&xs, None);
        assert!(!without.status.is_labelled(), "{:?}", without.status);
        assert!(without.retry.is_none());
        let (lo, hi) = (&cfg.domain.lo, &cfg.domain.hi);
        for i in 0..10u64 {
            let x: Vec<f64> = (0..4)
                .map(|k| lo[k] + (hi[k] - lo[k]) * crate::rng::uniform(43, i, k as u64))
                .collect();
            let (a, _) = full.solve(&x, None);
            if a.status.is_labelled() && a.retry.is_none() {
                assert_eq!(a, count.solve(&x, None).0, "{x:?}");
            }
        }
    }
}
