//! The default starts of a non-convex OCP, decided by a pilot (issue 43 §1, "extra starts
//! only where they can matter"):
//! ```text
//! P = {x_1 … x_M} ⊂ X,  M = PILOT_STATES, x_i uniform in X (counter-based, PILOT_SEED)
//! starts = ["warm", "u_lo", "u_hi", "barrier", "repeat_x0", "lqr", "zero"]
//!                          if some x_i ∈ P has two distinct hard optima among ["warm", "u_lo",
//!                          "u_hi"], or a hard optimum only from a start other than warm
//!        = ["warm"]       otherwise
//! ```
//! The extra starts cost about three `warm` solves per state (the bang-bang rollouts are poor
//! guesses), and on many plants they never reach another optimum (the pendulum: none in 2,000
//! states; the planar quadrotor: none in 100 — BENCHMARKS.md). A pilot of M = 100 states of
//! X solved from every start decides, once per problem and process, whether they can matter:
//! when they never did on the pilot, the rate of states where they would is below 3 % at
//! 95 % confidence (rule of three, 3/M), and labels come from `warm` alone. Swing-up
//! problems, whose starts disagree on a sizeable share of X, keep all three and add:
//! - the barrier start (`super::homotopy`): where the starts disagree, the interior-point-like
//!   path reaches the lower optimum at most of the states the three miss (the acados
//!   swing-up: 8 of 540 states above IPOPT's cost instead of 26, at about 2.8× the CPU per
//!   state — BENCHMARKS.md);
//! - three guesses that are not open-loop rollouts — x₀ repeated, the terminal-LQR rollout
//!   and the setpoint. Every other start rolls inputs out open loop, and on an unstable plant
//!   over a long horizon (the safe cart-pole, N = 40) the pole falls in all of them, so the
//!   SQP starts beside a swing-down manoeuvre: J = 1,802 where these reach 2.5. They take the
//!   acados swing-up from 8 to 6 of 540 states above IPOPT's cost (and 1 unlabelled to 0), at
//!   about 2.4× the CPU per state again; the CSTR's 121 grid labels keep their statuses at
//!   1.16× its CPU.
//!
//! The pilot itself probes with the three cheaper starts only.
//!
//! Only the default is decided here: a problem file's `[solver] starts` is used as written,
//! and a convex OCP has one start whatever is listed. The pilot is deterministic (fixed
//! states, fixed seed, serial), so every process, shard and stage of a run decides the same;
//! its result is cached per problem (system, OCP, domain and solver settings) in the
//! process.

use super::MpcLaw;
use crate::mpc::sqp::SqpStatus;
use crate::problem::solver::{default_starts, Start};
use crate::problem::ProblemConfig;
use std::collections::HashMap;
use std::sync::{Mutex, OnceLock};

/// States of the pilot.
pub const PILOT_STATES: usize = 100;
/// Seed of the pilot's states (`crate::rng::uniform(PILOT_SEED, i, k)`).
pub const PILOT_SEED: u64 = 0x5747_a875_0e11_0743;

/// What the pilot found and the starts it chose.
#[derive(Debug, Clone, PartialEq)]
pub struct Pilot {
    /// States solved (the pilot stops at the first state where the extra starts matter).
    pub states: usize,
    /// States with two or more distinct hard optima among the starts.
    pub disagreed: usize,
    /// States labelled by a hard optimum only thanks to a start other than `warm`.
    pub rescued: usize,
    /// The starts chosen.
    pub starts: Vec<Start>,
}

impl Pilot {
    /// One sentence for logs and reports.
    pub fn describe(&self) -> String {
        if self.starts.len() > 1 {
            format!(
                "default starts {}: at the pilot's state {} of X {} (the pilot stops there)",
                names(&self.starts),
                self.states,
                if self.disagreed > 0 {
                    "the starts reached two distinct optima"
                } else {
                    "only an extra start reached a hard optimum"
                }
            )
        } else {
            format!(
                "default starts {}: a pilot of {} states of X solved from {} never reached \
                 another optimum (the share of X where extra starts matter is below {:.1} % at \
                 95 % confidence)",
                names(&self.starts),
                self.states,
                names(&default_starts(false)),
                300.0 / self.states.max(1) as f64
            )
        }
    }
}

fn names(s: &[Start]) -> String {
    let v: Vec<&str> = s.iter().map(|s| s.as_str()).collect();
    format!("[{}]", v.join(", "))
}

impl MpcLaw {
    /// The law with exactly these starts (no pilot; a convex OCP still gets `warm` alone).
    pub fn with_starts(cfg: &ProblemConfig, starts: Vec<Start>) -> Self {
        let hard = crate::mpc::sqp::SqpSolver::new(cfg, false);
        let convex = cfg.system.is_affine() && !hard.ocp.has_nonlinear_rows();
        let starts = if convex { vec![Start::Warm] } else { starts };
        Self::assemble(cfg, hard, starts)
    }
}

/// The cache key: what the labels depend on.
fn key(cfg: &ProblemConfig) -> String {
    serde_json::to_string(&(&cfg.system, &cfg.ocp, &cfg.domain, &cfg.solver))
        .unwrap_or_else(|_| format!("{cfg:?}"))
}

fn cache() -> &'static Mutex<HashMap<String, Pilot>> {
    static CACHE: OnceLock<Mutex<HashMap<String, Pilot>>> = OnceLock::new();
    CACHE.get_or_init(|| Mutex::new(HashMap::new()))
}

/// The pilot of `cfg` (a non-convex OCP without `[solver] starts`), run once per process.
pub fn pilot(cfg: &ProblemConfig) -> Pilot {
    let k = key(cfg);
    // A poisoned lock only means another thread panicked mid-pilot: recompute.
    let mut map = cache().lock().unwrap_or_else(|e| e.into_inner());
    if let Some(p) = map.get(&k) {
        return p.clone();
    }
    let p = run(cfg);
    map.insert(k, p.clone());
    p
}

/// The starts kept where the pilot finds that extra starts matter: the probed ones, then the
/// barrier start (skipped by the law when U has no finite bound), then the three guesses that
/// are not open-loop rollouts (module doc). Later starts only replace a label by a strictly
/// cheaper optimum (ties go to the earlier start).
pub fn extra_starts() -> Vec<Start> {
    let mut s = default_starts(false);
    s.extend([Start::Barrier, Start::RepeatX0, Start::Lqr, Start::Zero]);
    s
}

/// The pilot itself (uncached).
pub fn run(cfg: &ProblemConfig) -> Pilot {
    let all = default_starts(false);
    let mut law = MpcLaw::with_starts(cfg, all.clone());
    let (lo, hi) = (&cfg.domain.lo, &cfg.domain.hi);
    let (mut disagreed, mut rescued) = (0, 0);
    for i in 0..PILOT_STATES {
        let x: Vec<f64> = (0..lo.len())
            .map(|k| lo[k] + (hi[k] - lo[k]) * crate::rng::uniform(PILOT_SEED, i as u64, k as u64))
            .collect();
        let (single, _) = law.solve_single(&x, None);
        let (l, _) = law.solve(&x, None);
        disagreed += usize::from(l.optima >= 2);
        rescued +=
            usize::from(single.status != SqpStatus::Converged && l.status == SqpStatus::Converged);
        if disagreed + rescued > 0 {
            // Decided: the extra starts matter (no need to solve the rest).
            return Pilot {
                states: i + 1,
                disagreed,
                rescued,
                starts: extra_starts(),
            };
        }
    }
    Pilot {
        states: PILOT_STATES,
        disagreed,
        rescued,
        starts: vec![Start::Warm],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The pendulum: no extra start ever reaches another optimum on the pilot (and the
    /// labels are those of `warm`); the decision is cached and repeatable.
    #[test]
    fn pendulum_pilot_keeps_warm_alone() {
        let cfg = ProblemConfig::default();
        let p = pilot(&cfg);
        eprintln!("{}", p.describe());
        assert_eq!(p, run(&cfg));
        assert_eq!((p.states, p.disagreed, p.rescued), (PILOT_STATES, 0, 0));
        assert_eq!(p.starts, vec![Start::Warm]);
        assert_eq!(MpcLaw::new(&cfg).starts(), p.starts.as_slice());
        // A problem file's list is used as written.
        let mut listed = cfg.clone();
        listed.solver.starts = Some(vec![Start::Warm, Start::Zero]);
        assert_eq!(
            MpcLaw::new(&listed).starts(),
            &[Start::Warm, Start::Zero][..]
        );
    }
}
