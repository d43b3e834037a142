//! [`ClosedLoopStatistical`]: the statistical tier for the closed loop — how likely a
//! trajectory of the deployed controller from a random initial state violates a constraint.
//!
//! n initial states x₀ i.i.d. uniform on X, drawn from the seed
//! [`statistical_seed`]`(model hash ‖ "closed loop", user seed)` (fresh for every model
//! tested); each runs `closed_loop.steps` steps of
//!
//! ```text
//! x_{k+1} = F(x_k, sat_U(κ̂(x_k)))          (nominal plant, no noise)
//! ```
//!
//! with κ̂ the deployed controller (f32 state, projection onto X, f32 network, clamp band:
//! `deploy::export::Deployed`, passed in as a [`TestedController`] because the device model
//! lives in `deploy`, which the caller may use),
//!
//! and counts as violating if any step violates a state bound or a path constraint by more
//! than [`VIOLATION_TOL`] ([`step_violation`], the closed-loop study's rule), and as failing
//! if it violates or does not converge: its last state is farther than [`CONVERGE_TOL`]
//! from the setpoint in the scaled ∞-norm, max_i |x_N,i − x_ref,i| / s_x,i (s_x: `[ocp]
//! x_scale`, default the half-widths of X). With k
//! violating trajectories, the Clopper–Pearson upper bound p̄ on
//! p = P(trajectory violates) at confidence 1 − β is
//! [`clopper_pearson_upper`](crate::certify::statistical::clopper_pearson_upper)(n, k, 1 − β).
//! It rests on the x₀ being i.i.d. uniform on X and on the plant model; nothing else. Starts
//! where the MPC itself has no hard-feasible solution (its label is soft) violate for
//! reasons no controller can remove, so the bound is also given over the feasible starts
//! alone (the conditional distribution: still i.i.d.). A start is feasible when the MPC's
//! hard OCP converges there (`MpcLaw::solve`'s status `Converged`: an MPC label).

use crate::certify::statistical::{clopper_pearson_upper, statistical_seed, TestedController};
use crate::mpc::law::MpcLaw;
use crate::problem::model::Discrete;
use crate::problem::ProblemConfig;
use crate::rng::uniform;
use crate::study::closed_loop::{step_violation, VIOLATION_TOL};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// A trajectory converges when its last state is within this of x_ref in the scaled
/// ∞-norm (5 % of each state's scale).
pub const CONVERGE_TOL: f64 = 0.05;

/// The MPC's own closed loop is run from this many of the initial states (the first ones
/// of the draw): a solve per step makes it far costlier than the controller's.
pub const MPC_STARTS: usize = 100;

/// A Clopper–Pearson bound from n trials with k events.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Bound {
    /// n: trajectories.
    pub trajectories: u64,
    /// k: of which violated a constraint.
    pub violating: u64,
    /// Upper bound on P(violation) at the confidence.
    pub p_violation_upper: f64,
}

impl Bound {
    fn new(n: u64, k: u64, confidence: f64) -> Self {
        Bound {
            trajectories: n,
            violating: k,
            p_violation_upper: clopper_pearson_upper(n, k, confidence),
        }
    }
}

/// The closed-loop statistical tier (`"statistical_closed_loop"` in `certificate.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ClosedLoopStatistical {
    /// Over all initial states of X.
    pub all: Bound,
    /// Over the initial states where the MPC is hard-feasible.
    pub feasible_starts: Bound,
    /// "Violates a constraint or does not converge" over all initial states (`violating`
    /// counts such failing trajectories). Absent in files written before it existed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub failing: Option<Bound>,
    /// The same over the MPC-feasible initial states.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub failing_feasible: Option<Bound>,
    /// Trajectories whose last state is not within [`CONVERGE_TOL`] of x_ref (scaled).
    #[serde(default)]
    pub not_converged: u64,
    /// The MPC's own closed loop (solved along the run at every step, its input saturated to U;
    /// no label: the centre of U) from the first [`MPC_STARTS`] of the same initial states,
    /// with the same rule "violates or does not converge": how often the reference law
    /// itself fails within `steps` — the scale against which the controller's failure
    /// bound is read. Absent in files written before it existed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mpc_failing: Option<Bound>,
    /// Of the same first [`MPC_STARTS`] initial states: how many runs of the deployed
    /// controller fail (the like-for-like count beside [`ClosedLoopStatistical::mpc_failing`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub controller_failing_same: Option<u64>,
    /// 1 − β.
    pub confidence: f64,
    /// Steps per trajectory.
    pub steps: usize,
    /// Seed of the initial states (`crate::rng::uniform` streams), derived from the model's
    /// hash and `user_seed`.
    pub seed: u64,
    /// The seed given by the user (`--closed-loop-seed`).
    #[serde(default)]
    pub user_seed: u64,
    /// The function simulated, in words.
    #[serde(default)]
    pub function: String,
    /// Largest violation seen.
    pub max_violation: f64,
    /// What the bound rests on, in words.
    pub rests_on: String,
}

/// One trajectory of the deployed `controller`: its largest violation and its final
/// distance to the setpoint.
fn trajectory(
    cfg: &ProblemConfig,
    plant: &Discrete,
    controller: &dyn TestedController,
    x0: &[f64],
) -> (f64, f64) {
    trajectory_of(cfg, plant, &mut |x| controller.input(x), x0)
}

/// One trajectory of the input law `input` (its output saturated to U; a non-finite output
/// is the centre of U): its largest violation and its final distance to the setpoint.
fn trajectory_of(
    cfg: &ProblemConfig,
    plant: &Discrete,
    input: &mut dyn FnMut(&[f64]) -> Vec<f64>,
    x0: &[f64],
) -> (f64, f64) {
    let (nx, nu) = (cfg.system.nx(), cfg.system.nu());
    let constraints = cfg.constraint_set().ok().flatten();
    let (ulo, uhi) = (&cfg.ocp.u_lo, &cfg.ocp.u_hi);
    let mut x = x0.to_vec();
    let mut next = vec![0.0; nx];
    let mut worst = 0.0f64;
    for k in 0..cfg.closed_loop.steps {
        let mut u = input(&x);
        u.resize(nu, f64::NAN);
        for j in 0..nu {
            // The actuator saturates the deployed controller's output; a non-finite one
            // (the device never gives one) is the centre of U.
            u[j] = if u[j].is_finite() {
                u[j].clamp(ulo[j], uhi[j])
            } else {
                0.5 * (ulo[j] + uhi[j])
            };
        }
        plant.step(&x, &u, &mut next);
        let v = step_violation(cfg, constraints.as_ref(), k, &x, &u, &next);
        worst = worst.max(if v.is_nan() { f64::INFINITY } else { v });
        x.copy_from_slice(&next);
    }
    (worst, distance_to_setpoint(cfg, &x))
}

/// max_i |x_i − x_ref,i| / s_x,i (NaN → +∞): how far from the setpoint a trajectory ends.
pub fn distance_to_setpoint(cfg: &ProblemConfig, x: &[f64]) -> f64 {
    let scale = cfg.ocp.x_scale_or_default(&cfg.domain.lo, &cfg.domain.hi);
    let xr = cfg.ocp.x_ref.clone().unwrap_or_else(|| vec![0.0; x.len()]);
    x.iter()
        .zip(&xr)
        .zip(&scale)
        .map(|((v, r), s)| {
            let d = (v - r).abs() / s;
            if d.is_nan() {
                f64::INFINITY
            } else {
                d
            }
        })
        .fold(0.0, f64::max)
}

/// Runs `n` trajectories of the deployed `controller` (of the model with content hash
/// `model_hash`) from uniform initial states drawn from the model's hash and `user_seed`,
/// and bounds the violation probability at `confidence`.
pub fn closed_loop_statistical(
    cfg: &ProblemConfig,
    controller: &dyn TestedController,
    model_hash: &str,
    n: usize,
    user_seed: u64,
    confidence: f64,
) -> ClosedLoopStatistical {
    let seed = statistical_seed(&format!("{model_hash}\0closed loop"), user_seed);
    let nx = cfg.system.nx();
    let plant = Discrete::new(cfg.system.clone(), cfg.ocp.ts, cfg.ocp.rk4_substeps);
    // The i-th initial state of the draw: uniform in X.
    let start = |i: u64| -> Vec<f64> {
        (0..nx)
            .map(|k| {
                let (lo, hi) = (cfg.domain.lo[k], cfg.domain.hi[k]);
                lo + (hi - lo) * uniform(seed, i, k as u64)
            })
            .collect()
    };
    let results: Vec<(bool, (f64, f64))> = (0..n as u64)
        .into_par_iter()
        .map_init(
            || MpcLaw::new(cfg),
            |law, i| {
                let x0 = start(i);
                let feasible = law.is_hard_feasible(&x0);
                (feasible, trajectory(cfg, &plant, controller, &x0))
            },
        )
        .collect();
    let violates = |(v, _): (f64, f64)| v > VIOLATION_TOL;
    let fails = |(v, d): (f64, f64)| v > VIOLATION_TOL || d > CONVERGE_TOL;
    let count = |rs: &mut dyn Iterator<Item = (f64, f64)>, f: &dyn Fn((f64, f64)) -> bool| {
        rs.filter(|r| f(*r)).count() as u64
    };
    let all = || results.iter().map(|(_, r)| *r);
    let feas = || results.iter().filter(|(f, _)| *f).map(|(_, r)| *r);
    let n_feas = feas().count() as u64;
    let not_converged = count(&mut all(), &|(_, d)| d > CONVERGE_TOL);
    // The MPC's own closed loop from the first starts of the same draw.
    let m = n.min(MPC_STARTS);
    let mpc: Vec<(f64, f64)> = (0..m as u64)
        .into_par_iter()
        .map_init(
            || MpcLaw::new(cfg),
            |law, i| {
                let x0 = start(i);
                // Solved along the run (`MpcLaw::solve_next`), as the closed-loop study does.
                let mut along = crate::mpc::law::along::Along::default();
                trajectory_of(cfg, &plant, &mut |x| law.solve_next(x, &mut along).u, &x0)
            },
        )
        .collect();
    let mpc_fail = count(&mut mpc.iter().copied(), &fails);
    let same = count(&mut results[..m].iter().map(|(_, r)| *r), &fails);
    ClosedLoopStatistical {
        all: Bound::new(n as u64, count(&mut all(), &violates), confidence),
        feasible_starts: Bound::new(n_feas, count(&mut feas(), &violates), confidence),
        failing: Some(Bound::new(n as u64, count(&mut all(), &fails), confidence)),
        failing_feasible: Some(Bound::new(n_feas, count(&mut feas(), &fails), confidence)),
        not_converged,
        mpc_failing: (m > 0).then(|| Bound::new(m as u64, mpc_fail, confidence)),
        controller_failing_same: (m > 0).then_some(same),
        confidence,
        steps: cfg.closed_loop.steps,
        seed,
        user_seed,
        function: controller.describe(),
        // A NaN violation is already +∞ (trajectory); the fold cannot drop one.
        max_violation: all().map(|(v, _)| v).fold(0.0, f64::max),
        rests_on: format!(
            "initial states i.i.d. uniform on X (seed {seed}, from the model's hash and the \
             user seed {user_seed}); the nominal plant model; {}, then the actuator \
             saturation; {} steps per trajectory; a violation is > {VIOLATION_TOL:e} of a \
             state bound or path constraint; a run converges when its last state is within \
             {CONVERGE_TOL} of x_ref in the scaled ∞-norm; a start is MPC-feasible when the \
             hard OCP converges there",
            controller.describe(),
            cfg.closed_loop.steps
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A controller of constant output.
    struct Constant(f64);

    impl TestedController for Constant {
        fn input(&self, _: &[f64]) -> Vec<f64> {
            vec![self.0]
        }
        fn describe(&self) -> String {
            format!("u = {}", self.0)
        }
    }

    /// Counted against an independent count: every trajectory re-simulated here with the
    /// plant stepped by hand, and the bound against the closed form of k = 0.
    #[test]
    fn counts_match_a_direct_simulation() {
        let mut cfg = ProblemConfig::default();
        cfg.closed_loop.steps = 30;
        for u in [0.0, 15.0] {
            let s = closed_loop_statistical(&cfg, &Constant(u), "model", 40, 7, 0.99);
            assert_eq!(s.seed, statistical_seed("model\0closed loop", 7));
            assert_eq!(s.user_seed, 7);
            let plant = Discrete::new(cfg.system.clone(), cfg.ocp.ts, cfg.ocp.rk4_substeps);
            let mut k = 0;
            for i in 0..40u64 {
                let mut x: Vec<f64> = (0..2)
                    .map(|j| {
                        let (lo, hi) = (cfg.domain.lo[j], cfg.domain.hi[j]);
                        lo + (hi - lo) * uniform(s.seed, i, j as u64)
                    })
                    .collect();
                let mut bad = false;
                let mut next = vec![0.0; 2];
                for _ in 0..30 {
                    plant.step(&x, &[u], &mut next);
                    bad |= (0..2).any(|j| {
                        next[j] > cfg.ocp.x_hi[j] + 1e-6 || next[j] < cfg.ocp.x_lo[j] - 1e-6
                    });
                    x.copy_from_slice(&next);
                }
                k += bad as u64;
            }
            assert_eq!(s.all.violating, k, "u = {u}");
            assert_eq!(s.all.trajectories, 40);
            assert!(s.feasible_starts.trajectories <= 40);
            assert!(s.feasible_starts.violating <= s.all.violating);
            if k == 0 {
                assert!((s.all.p_violation_upper - (1.0 - 0.01f64.powf(1.0 / 40.0))).abs() < 1e-12);
            }
        }
        // A constant full torque drives the pendulum's velocity out of its bound from
        // most states: the two inputs cannot both give no violations.
        let full = closed_loop_statistical(&cfg, &Constant(15.0), "model", 40, 7, 0.99);
        assert!(full.all.violating > 0, "{full:?}");
        // Another model: other initial states.
        let other = closed_loop_statistical(&cfg, &Constant(15.0), "other", 40, 7, 0.99);
        assert_ne!(other.seed, full.seed);
    }

    /// A run that stays inside the constraints but ends far from the setpoint fails: the
    /// count of failing runs is checked against a hand-stepped simulation of each start.
    #[test]
    fn a_run_that_does_not_converge_fails() {
        let mut cfg = ProblemConfig::default();
        cfg.closed_loop.steps = 3;
        let s = closed_loop_statistical(&cfg, &Constant(0.0), "model", 30, 3, 0.99);
        let plant = Discrete::new(cfg.system.clone(), cfg.ocp.ts, cfg.ocp.rk4_substeps);
        let scale = cfg.ocp.x_scale_or_default(&cfg.domain.lo, &cfg.domain.hi);
        let (mut failing, mut far) = (0, 0);
        for i in 0..30u64 {
            let mut x: Vec<f64> = (0..2)
                .map(|j| {
                    let (lo, hi) = (cfg.domain.lo[j], cfg.domain.hi[j]);
                    lo + (hi - lo) * uniform(s.seed, i, j as u64)
                })
                .collect();
            let mut bad = false;
            let mut next = vec![0.0; 2];
            for _ in 0..3 {
                plant.step(&x, &[0.0], &mut next);
                bad |= (0..2)
                    .any(|j| next[j] > cfg.ocp.x_hi[j] + 1e-6 || next[j] < cfg.ocp.x_lo[j] - 1e-6);
                x.copy_from_slice(&next);
            }
            // The pendulum's setpoint is the origin.
            let d = (0..2).map(|j| x[j].abs() / scale[j]).fold(0.0, f64::max);
            far += u64::from(d > CONVERGE_TOL);
            failing += u64::from(bad || d > CONVERGE_TOL);
        }
        assert!(
            far > 0,
            "three steps of u = 0 leave most starts far from the origin"
        );
        assert_eq!(s.not_converged, far);
        let f = s.failing.as_ref().unwrap();
        assert_eq!((f.trajectories, f.violating), (30, failing));
        assert!(f.violating > s.all.violating, "{s:?}");
        assert!(f.p_violation_upper >= s.all.p_violation_upper);
        let ff = s.failing_feasible.as_ref().unwrap();
        assert_eq!(ff.trajectories, s.feasible_starts.trajectories);
        assert!(ff.violating >= s.feasible_starts.violating);
        // The controller's count on the MPC's starts (all 30 here) is its failing count.
        assert_eq!(s.controller_failing_same, Some(failing));
        // The MPC's own closed loop from the same starts, re-simulated by hand.
        let mut law = MpcLaw::new(&cfg);
        let mut mpc_failing = 0;
        for i in 0..30u64 {
            let mut x: Vec<f64> = (0..2)
                .map(|j| {
                    let (lo, hi) = (cfg.domain.lo[j], cfg.domain.hi[j]);
                    lo + (hi - lo) * uniform(s.seed, i, j as u64)
                })
                .collect();
            let (mut bad, mut next) = (false, vec![0.0; 2]);
            for _ in 0..3 {
                let u = law.solve(&x, None).0.u[0];
                let (lo, hi) = (cfg.ocp.u_lo[0], cfg.ocp.u_hi[0]);
                let u = if u.is_finite() {
                    u.clamp(lo, hi)
                } else {
                    0.5 * (lo + hi)
                };
                plant.step(&x, &[u], &mut next);
                bad |= (0..2)
                    .any(|j| next[j] > cfg.ocp.x_hi[j] + 1e-6 || next[j] < cfg.ocp.x_lo[j] - 1e-6);
                x.copy_from_slice(&next);
            }
            let d = (0..2).map(|j| x[j].abs() / scale[j]).fold(0.0, f64::max);
            mpc_failing += u64::from(bad || d > CONVERGE_TOL);
        }
        let m = s.mpc_failing.as_ref().unwrap();
        assert_eq!((m.trajectories, m.violating), (30, mpc_failing));
    }
}
