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
//! x_scale`, default the half-widths of X), or it left the closed-loop study's
//! [`stop_box`] (a runaway: it does not converge).
//!
//! **The run length N comes from the MPC's own convergence** ([`run_length`]): a fixed
//! `closed_loop.steps` can be too short for the plant (the pendulum with |ω| ≤ 1 needs
//! ≥ 2π s ≈ 126 steps to come round from θ = 2π, and 90 steps made the MPC itself "fail" on
//! 44 of 100 starts). The MPC is run in closed loop from [`MPC_STARTS`] further i.i.d.
//! starts (their own seed stream, independent of the tested starts) for up to
//! [`LENGTH_CAP`] × `closed_loop.steps`; its slowest settling step s (after which every
//! state stays within [`CONVERGE_TOL`]) gives N = min(max(steps, ⌈[`LENGTH_FACTOR`]·s⌉),
//! cap). A reference run whose state comes within [`REST_TOL`] = 10⁻³ × [`CONVERGE_TOL`] of
//! the setpoint is at rest: its remaining steps are not simulated and count as that last
//! state (no further violation, within the tolerance). This assumes the MPC's closed loop,
//! once that close, stays within [`CONVERGE_TOL`] — the local stability its terminal
//! ingredients give — and is checked against full runs in the tests; it only shapes N and
//! the MPC's own reported failures, never the bound. On the quadrotor the runs settle
//! within 35 steps of a cap of 300 (3.3 → 0.7 s). The MPC's failures at N on those starts and the controller's on the same starts
//! are reported side by side; the bound itself is over the tested starts only, whose
//! length N does not depend on them. A controller with a steady offset at the setpoint
//! (run from x_ref for N steps, it ends farther than [`CONVERGE_TOL`] away) cannot
//! converge in this sense: [`ClosedLoopStatistical::setpoint_offset`] says so. With k
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
use crate::study::closed_loop::{step_violation, stop_box, VIOLATION_TOL};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// A trajectory converges when its last state is within this of x_ref in the scaled
/// ∞-norm (5 % of each state's scale).
pub const CONVERGE_TOL: f64 = 0.05;

/// The MPC's own closed loop is run from this many initial states (a draw of their own,
/// [`run_length`]): a solve per step makes it far costlier than the controller's.
pub const MPC_STARTS: usize = 100;

/// The MPC's runs that fix the run length last up to this many times `closed_loop.steps`.
pub const LENGTH_CAP: usize = 3;

/// An MPC reference run within this of x_ref (scaled ∞-norm, 10⁻³ × [`CONVERGE_TOL`]) is at
/// rest: its remaining steps are not simulated (module doc).
pub const REST_TOL: f64 = 5e-5;

/// The run length is this many times the MPC's slowest settling step (the network, an
/// approximation of the MPC, is given half as long again).
pub const LENGTH_FACTOR: f64 = 1.5;

/// The run length N (module doc): `configured` (`closed_loop.steps`) when no MPC run
/// settled, else ⌈[`LENGTH_FACTOR`]·slowest⌉, at least `configured` and at most
/// [`LENGTH_CAP`] × `configured`.
pub fn run_length(configured: usize, slowest: Option<usize>) -> usize {
    let cap = LENGTH_CAP * configured;
    slowest.map_or(configured, |s| {
        ((LENGTH_FACTOR * s as f64).ceil() as usize)
            .max(configured)
            .min(cap)
    })
}

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
    /// no label: the centre of U) from [`MPC_STARTS`] i.i.d. uniform starts of their own
    /// draw (module doc), with the same rule "violates or does not converge" after `steps`
    /// steps: how often the reference law itself fails — the scale against which the
    /// controller's failure bound is read. Absent in files written before it existed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mpc_failing: Option<Bound>,
    /// Of the MPC's starts: how many runs of the deployed controller fail (the like-for-like
    /// count beside [`ClosedLoopStatistical::mpc_failing`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub controller_failing_same: Option<u64>,
    /// The slowest settling step of the MPC's runs within [`LENGTH_CAP`] ×
    /// `steps_configured` (`None`: no run settled, or files written before it existed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mpc_slowest_settling: Option<usize>,
    /// The deployed controller started at x_ref and run `steps` steps: the scaled ∞-norm
    /// distance to x_ref where it ends (above [`CONVERGE_TOL`]: a steady offset at the
    /// setpoint, no run can converge). Absent in files written before it existed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub setpoint_offset: Option<f64>,
    /// 1 − β.
    pub confidence: f64,
    /// Steps per trajectory: the run length N of [`run_length`].
    pub steps: usize,
    /// `closed_loop.steps` of the problem file (0 in files written before the run length
    /// was derived: there `steps` is it).
    #[serde(default)]
    pub steps_configured: usize,
    /// The convergence rule and the run length's origin, in words (empty in older files).
    #[serde(default)]
    pub convergence: String,
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
    /// Runs that evaluated the controller at a state outside X, where the device projects
    /// the state onto X before the network (the band was established on X only). Absent
    /// in files written before it was counted.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub left_domain: Option<u64>,
    /// Of the failing runs (`failing`), those that left X.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub failing_left_domain: Option<u64>,
    /// The smallest box (lower, upper corner) holding every state at which the tested runs
    /// evaluated the controller: where the closed loop goes, to compare with X.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reach: Option<(Vec<f64>, Vec<f64>)>,
}

/// Where a run evaluated the controller: whether at a state outside X, and the box of
/// those states (lower, upper corner).
#[derive(Debug, Clone, PartialEq)]
struct Reach {
    left: bool,
    lo: Vec<f64>,
    hi: Vec<f64>,
}

impl Reach {
    fn new(nx: usize) -> Self {
        Reach {
            left: false,
            lo: vec![f64::INFINITY; nx],
            hi: vec![f64::NEG_INFINITY; nx],
        }
    }
    fn see(&mut self, cfg: &ProblemConfig, x: &[f64]) {
        for (i, v) in x.iter().enumerate() {
            self.lo[i] = self.lo[i].min(*v);
            self.hi[i] = self.hi[i].max(*v);
            // A non-finite state is outside X too.
            self.left |= !(*v >= cfg.domain.lo[i] && *v <= cfg.domain.hi[i]);
        }
    }
    fn join(mut self, o: &Reach) -> Self {
        self.left |= o.left;
        for i in 0..self.lo.len() {
            self.lo[i] = self.lo[i].min(o.lo[i]);
            self.hi[i] = self.hi[i].max(o.hi[i]);
        }
        self
    }
}

/// One trajectory of the deployed `controller` of `steps` steps: its largest violation and
/// its final distance to the setpoint ([`outcome`]).
fn trajectory(
    cfg: &ProblemConfig,
    plant: &Discrete,
    controller: &dyn TestedController,
    x0: &[f64],
    steps: usize,
) -> (f64, f64) {
    trajectory_reach(cfg, plant, controller, x0, steps).0
}

/// [`trajectory`] and where the run evaluated the controller ([`Reach`]).
fn trajectory_reach(
    cfg: &ProblemConfig,
    plant: &Discrete,
    controller: &dyn TestedController,
    x0: &[f64],
    steps: usize,
) -> ((f64, f64), Reach) {
    let mut reach = Reach::new(cfg.system.nx());
    let mut input = |x: &[f64]| {
        reach.see(cfg, x);
        controller.input(x)
    };
    let t = trace_of(cfg, plant, &mut input, x0, (steps, None));
    (outcome(cfg, x0, &t, steps), reach)
}

/// (largest violation, distance to the setpoint) after `n` steps of the trace `t` from `x0`.
fn outcome(cfg: &ProblemConfig, x0: &[f64], t: &[(f64, f64)], n: usize) -> (f64, f64) {
    match n.checked_sub(1).and_then(|k| t.get(k)) {
        Some(r) => *r,
        None => (0.0, distance_to_setpoint(cfg, x0)),
    }
}

/// Whether a run's (violation, distance) fails: violates, or does not converge.
fn fails((v, d): (f64, f64)) -> bool {
    v > VIOLATION_TOL || d > CONVERGE_TOL
}

/// The first step after which every state of the trace (x₀ = `x0` included) stays within
/// [`CONVERGE_TOL`] of the setpoint; `None` when its last state is not.
fn settling(cfg: &ProblemConfig, x0: &[f64], t: &[(f64, f64)]) -> Option<usize> {
    let d: Vec<f64> = std::iter::once(distance_to_setpoint(cfg, x0))
        .chain(t.iter().map(|r| r.1))
        .collect();
    if d.last().is_some_and(|v| *v > CONVERGE_TOL) {
        return None;
    }
    Some(
        d.iter()
            .rposition(|v| *v > CONVERGE_TOL)
            .map_or(0, |k| k + 1),
    )
}

/// A run step by step ([`trace_of`]): (largest violation so far, distance to x_ref).
type Trace = Vec<(f64, f64)>;

/// The run of the input law `input` (its output saturated to U; a non-finite output is the
/// centre of U) from `x0` for `steps` steps, step by step: entry k is (the largest
/// violation of steps 0..=k, the scaled distance of x_{k+1} to the setpoint). A run that
/// leaves the [`stop_box`] stops there; its remaining entries keep its violation with
/// distance +∞ (a runaway does not converge; no solve is spent on it). With `rest`
/// ([`REST_TOL`], the MPC's reference runs), a run whose state comes within `rest` of the
/// setpoint stops there too, its remaining entries its last one (module doc).
fn trace_of(
    cfg: &ProblemConfig,
    plant: &Discrete,
    input: &mut dyn FnMut(&[f64]) -> Vec<f64>,
    x0: &[f64],
    (steps, rest): (usize, Option<f64>),
) -> Trace {
    let (nx, nu) = (cfg.system.nx(), cfg.system.nu());
    let constraints = cfg.constraint_set().ok().flatten();
    let (ulo, uhi) = (&cfg.ocp.u_lo, &cfg.ocp.u_hi);
    let (slo, shi) = stop_box(cfg);
    let mut x = x0.to_vec();
    let mut next = vec![0.0; nx];
    let mut worst = 0.0f64;
    let mut out = Vec::with_capacity(steps);
    for k in 0..steps {
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
        if (0..nx).any(|i| !(x[i] >= slo[i] && x[i] <= shi[i])) {
            out.resize(steps, (worst, f64::INFINITY));
            return out;
        }
        let d = distance_to_setpoint(cfg, &x);
        out.push((worst, d));
        if rest.is_some_and(|r| d <= r) {
            out.resize(steps, (worst, d));
            return out;
        }
    }
    out
}

/// A state (a corner of [`ClosedLoopStatistical::reach`]) with four decimals.
pub fn short(x: &[f64]) -> String {
    x.iter()
        .map(|v| format!("{v:.4}"))
        .collect::<Vec<_>>()
        .join(", ")
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

/// The i-th state of the uniform draw on X of stream `seed`.
fn uniform_start(cfg: &ProblemConfig, seed: u64, i: u64) -> Vec<f64> {
    (0..cfg.system.nx())
        .map(|k| {
            let (lo, hi) = (cfg.domain.lo[k], cfg.domain.hi[k]);
            lo + (hi - lo) * uniform(seed, i, k as u64)
        })
        .collect()
}

/// The MPC's closed loop and the controller's from the `m` starts of the length draw
/// `seed`, each `cap` steps: (the run length N, the MPC's slowest settling, the MPC's
/// failures at N, the controller's failures at N on the same starts).
fn mpc_reference(
    cfg: &ProblemConfig,
    plant: &Discrete,
    controller: &dyn TestedController,
    (m, seed): (usize, u64),
) -> (usize, Option<usize>, u64, u64) {
    let steps = cfg.closed_loop.steps;
    let cap = LENGTH_CAP * steps;
    let runs: Vec<(Vec<f64>, Trace)> = (0..m as u64)
        .into_par_iter()
        .map_init(
            || MpcLaw::new(cfg),
            |law, i| {
                let x0 = uniform_start(cfg, seed, i);
                // Solved along the run (`MpcLaw::solve_next`), as the closed-loop study does.
                let mut along = crate::mpc::law::along::Along::default();
                let t = trace_of(
                    cfg,
                    plant,
                    &mut |x| law.solve_next(x, &mut along).u,
                    &x0,
                    (cap, Some(REST_TOL)),
                );
                (x0, t)
            },
        )
        .collect();
    let slowest = runs.iter().filter_map(|(x0, t)| settling(cfg, x0, t)).max();
    let n = run_length(steps, slowest);
    let mpc_fail = runs
        .iter()
        .filter(|(x0, t)| fails(outcome(cfg, x0, t, n)))
        .count() as u64;
    let same = runs
        .par_iter()
        .filter(|(x0, _)| fails(trajectory(cfg, plant, controller, x0, n)))
        .count() as u64;
    (n, slowest, mpc_fail, same)
}

/// Runs `n` trajectories of the deployed `controller` (of the model with content hash
/// `model_hash`) from uniform initial states drawn from the model's hash and `user_seed`,
/// and bounds the violation probability at `confidence`; the run length comes from the
/// MPC's own closed loop (module doc).
pub fn closed_loop_statistical(
    cfg: &ProblemConfig,
    controller: &dyn TestedController,
    model_hash: &str,
    n: usize,
    user_seed: u64,
    confidence: f64,
) -> ClosedLoopStatistical {
    let seed = statistical_seed(&format!("{model_hash}\0closed loop"), user_seed);
    let length_seed = statistical_seed(&format!("{model_hash}\0closed loop length"), user_seed);
    let plant = Discrete::new(cfg.system.clone(), cfg.ocp.ts, cfg.ocp.rk4_substeps);
    let m = n.min(MPC_STARTS);
    let configured = cfg.closed_loop.steps;
    let (steps, slowest, mpc_fail, same) = if m > 0 {
        mpc_reference(cfg, &plant, controller, (m, length_seed))
    } else {
        (configured, None, 0, 0)
    };
    // The starts' feasibility only counts: no retry ladder.
    let counting = crate::mpc::law::ladder::counting_problem(cfg);
    // (MPC-feasible start, ((violation, distance), where the controller was evaluated)).
    type Run = (bool, ((f64, f64), Reach));
    let runs: Vec<Run> = (0..n as u64)
        .into_par_iter()
        .map_init(
            || MpcLaw::new(&counting),
            |law, i| {
                let x0 = uniform_start(cfg, seed, i);
                let feasible = law.is_hard_feasible(&x0);
                (
                    feasible,
                    trajectory_reach(cfg, &plant, controller, &x0, steps),
                )
            },
        )
        .collect();
    let results: Vec<(bool, (f64, f64))> = runs.iter().map(|(f, (r, _))| (*f, *r)).collect();
    let left_domain = runs.iter().filter(|(_, (_, w))| w.left).count() as u64;
    let failing_left_domain = runs
        .iter()
        .filter(|(_, (r, w))| w.left && fails(*r))
        .count() as u64;
    let reach = runs
        .iter()
        .map(|(_, (_, w))| w)
        .fold(None::<Reach>, |acc, w| {
            Some(acc.map_or_else(|| w.clone(), |a| a.join(w)))
        })
        // No evaluation at all (0 steps): no box (JSON has no infinity).
        .filter(|w| w.lo.iter().chain(&w.hi).all(|v| v.is_finite()));
    let violates = |(v, _): (f64, f64)| v > VIOLATION_TOL;
    let count = |rs: &mut dyn Iterator<Item = (f64, f64)>, f: &dyn Fn((f64, f64)) -> bool| {
        rs.filter(|r| f(*r)).count() as u64
    };
    let all = || results.iter().map(|(_, r)| *r);
    let feas = || results.iter().filter(|(f, _)| *f).map(|(_, r)| *r);
    let n_feas = feas().count() as u64;
    let not_converged = count(&mut all(), &|(_, d)| d > CONVERGE_TOL);
    let x_ref = cfg.ocp.x_ref_or_origin(cfg.system.nx());
    let setpoint_offset = trajectory(cfg, &plant, controller, &x_ref, steps).1;
    let convergence = format!(
        "a run converges when its last state (after {steps} steps) is within {CONVERGE_TOL} \
         of x_ref in the scaled ∞-norm max_i |x_i − x_ref,i| / s_x,i and it never left X \
         and the state bounds widened by ten widths of X; {steps} steps = {}",
        match slowest {
            Some(s) if steps > configured => format!(
                "{LENGTH_FACTOR} × the slowest settling ({s} steps) of the MPC's own closed \
                 loop from {m} i.i.d. starts (closed_loop.steps = {configured}{})",
                if steps == LENGTH_CAP * configured {
                    format!(", capped at {LENGTH_CAP} × it")
                } else {
                    String::new()
                }
            ),
            Some(s) => format!(
                "closed_loop.steps (the MPC's own closed loop from {m} i.i.d. starts settles \
                 within {s} steps)"
            ),
            None => format!(
                "closed_loop.steps (no run of the MPC's own closed loop from {m} i.i.d. \
                 starts settled within {} steps)",
                LENGTH_CAP * configured
            ),
        }
    );
    ClosedLoopStatistical {
        all: Bound::new(n as u64, count(&mut all(), &violates), confidence),
        feasible_starts: Bound::new(n_feas, count(&mut feas(), &violates), confidence),
        failing: Some(Bound::new(n as u64, count(&mut all(), &fails), confidence)),
        failing_feasible: Some(Bound::new(n_feas, count(&mut feas(), &fails), confidence)),
        not_converged,
        mpc_failing: (m > 0).then(|| Bound::new(m as u64, mpc_fail, confidence)),
        controller_failing_same: (m > 0).then_some(same),
        mpc_slowest_settling: slowest,
        setpoint_offset: Some(setpoint_offset),
        confidence,
        steps,
        steps_configured: configured,
        seed,
        user_seed,
        function: controller.describe(),
        // A NaN violation is already +∞ (trajectory); the fold cannot drop one.
        max_violation: all().map(|(v, _)| v).fold(0.0, f64::max),
        rests_on: format!(
            "initial states i.i.d. uniform on X (seed {seed}, from the model's hash and the \
             user seed {user_seed}); the nominal plant model; {}, then the actuator \
             saturation; {steps} steps per trajectory; a violation is > {VIOLATION_TOL:e} of a \
             state bound or path constraint; {convergence}; a start is MPC-feasible when the \
             hard OCP converges there",
            controller.describe(),
        ),
        convergence,
        left_domain: Some(left_domain),
        failing_left_domain: Some(failing_left_domain),
        reach: reach.map(|w| (w.lo, w.hi)),
    }
}

#[cfg(test)]
#[path = "statistical_loop_tests.rs"]
mod tests;
