//! Closed-loop simulation of a controller on the plant model, and the paper's Table II
//! metrics.
//!
//! `x_{k+1} = F_plant(x_k, sat(π(y_k)))`, `y_k = x_k + w_k` (measurement noise), where
//! F_plant is the OCP's RK4 model, optionally with perturbed physical parameters (model
//! mismatch), and π is the MPC law κ (solved online at every step by
//! [`MpcLaw::solve_next`]: warm from the previous step's hard solution shifted one stage;
//! every start of `solver.starts`, the soft fallback and the retry ladder of
//! [`crate::mpc::law`] at the first step and where that warm start does not converge;
//! after a soft step, hard-infeasible states decided by the soft problem alone —
//! [`crate::mpc::law::along`]) or a network κ_NN. The plant receives the controller's input
//! saturated to the actuator limits U; a network's raw output outside the certified band
//! U ⊕ [−ε, ε] is recorded.
//!
//! Metrics of a run (Table II): share of steps whose state violates a state bound by more
//! than 1e-6 (the MPC rides x₂ = 1 during the upswing; solver tolerances must not count),
//! the largest violation, the largest input divergence ‖κ(x) − κ_NN(x)‖ along the network's
//! own trajectory (the MPC solved at each visited state), the quadratic cost
//! Σ (x_k − x_ref)ᵀQ(x_k − x_ref) + (u_k − u_ref)ᵀR(u_k − u_ref), the settling step (first k
//! after which ‖x − x_ref‖∞ stays ≤ 0.05) and the final offset |x_steps − x_ref| per state
//! (x_ref, u_ref: the OCP's setpoint, the origin unless `ocp.x_ref`, `ocp.u_ref` say).
//!
//! **A network's reference is the plain solve.** In a network's run the MPC is solved only
//! for the divergence, and without the retry ladder (as the counting stages label:
//! [`crate::mpc::law::ladder::counting_problem`]): the warm start, the starts and the soft
//! fallback as above; a state they leave unlabelled counts in `mpc_failures` and records no
//! divergence. A network that drives the plant out of X reaches states where every rung
//! fails, and there the ladder's up to `(retry_budget + 6) × max_iter` SQP iterations per
//! state cost 1 s a step: one diverging run of the quadrotor's regularized net took 4.8 s of
//! the stage's 5.2 s (BENCHMARKS.md, "Session 2026-12-07"). The MPC's own runs keep the
//! ladder.
//!
//! A run that diverges stops with status `diverged` ([`RunStatus`]): when the plant's next
//! state is not finite, or leaves the [`stop_box`] — the hull of X and the OCP's finite state
//! bounds widened by [`DIVERGED_MARGIN`] × X's width on some axis (x_i ∉ [l_i − m·w_i,
//! h_i + m·w_i], w = hi − lo of X) —, or the cost, a constraint value or the network's output
//! is not finite. Every number a run records is finite, so its JSON holds
//! no `null` (serde_json writes NaN and ±∞ as `null`).

use crate::learn::mlp::Mlp;
use crate::mpc::law::along::Along;
use crate::mpc::law::MpcLaw;
use crate::problem::model::expr::ConstraintSet;
use crate::problem::model::Discrete;
use crate::problem::ProblemConfig;
use crate::rng::uniform;
use serde::{Deserialize, Serialize};

/// Violations smaller than this do not count (solver tolerance).
pub const VIOLATION_TOL: f64 = 1e-6;

/// A run whose state leaves the [`stop_box`] (the hull of X and the finite state bounds,
/// widened by m·w: w X's width per axis, m this margin) stops as `diverged`. Ten widths,
/// as the safety study's stop box: an axis without a state bound (a rate) legitimately goes
/// far beyond X under the MPC itself — with one width of X, the planar quadrotor's MPC runs
/// (θ̇ reaching 6.3 rad/s in one step from X's edge, X: |θ̇| ≤ 1) were stopped as
/// "diverged" in 2 of 12 runs of the ordinary study; a real runaway (a reactor's
/// temperature growing without bound, a NaN) passes ten widths as well.
pub const DIVERGED_MARGIN: f64 = 10.0;

/// The box beyond which a run stops as diverged: the hull of X and the OCP's finite state
/// bounds, widened by [`DIVERGED_MARGIN`] × X's width per axis (lower and upper corners).
pub fn stop_box(cfg: &ProblemConfig) -> (Vec<f64>, Vec<f64>) {
    let (dlo, dhi) = (&cfg.domain.lo, &cfg.domain.hi);
    let (xlo, xhi) = (&cfg.ocp.x_lo, &cfg.ocp.x_hi);
    (0..dlo.len())
        .map(|i| {
            let m = DIVERGED_MARGIN * (dhi[i] - dlo[i]);
            let lo = xlo
                .get(i)
                .filter(|v| v.is_finite())
                .map_or(dlo[i], |v| dlo[i].min(*v));
            let hi = xhi
                .get(i)
                .filter(|v| v.is_finite())
                .map_or(dhi[i], |v| dhi[i].max(*v));
            (lo - m, hi + m)
        })
        .unzip()
}

/// How a closed-loop run ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RunStatus {
    /// All steps simulated (not written: files of completed runs are unchanged).
    #[default]
    Completed,
    /// Stopped early: the state left X by more than [`DIVERGED_MARGIN`] of its width, or a
    /// state, the cost, a constraint value or the network's output was not finite
    /// ([`Run::stopped`] says which, and where).
    Diverged,
}

impl RunStatus {
    /// Whether the run completed (then `status` is not serialised).
    pub fn is_completed(&self) -> bool {
        *self == RunStatus::Completed
    }
}

/// A controller under test.
pub enum Controller<'a> {
    /// The MPC, solved online.
    Mpc,
    /// A network, with the certified band's half-width ε (for the band check) and, if
    /// given, the output clamp of its certificate (lo, hi): the deployed controller clamps
    /// its output there before the actuator saturation, and the input divergence is then
    /// measured on the clamped output (the quantity the certificate bounds).
    Net(&'a Mlp, f64, Option<(&'a [f64], &'a [f64])>),
}

/// An additive input disturbance `e_k` (the input error of Corollary 1): the plant
/// receives `sat(π(y_k) + e_k)`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Disturbance {
    /// No disturbance.
    #[default]
    None,
    /// Bang-bang at the bound: `e_k = eps·(−1)^⌊k/period⌋` on every input (`period` 0:
    /// constant `eps`; a negative `eps` flips the sign).
    BangBang {
        /// Amplitude (signed).
        eps: f64,
        /// Steps between sign changes (0 = never).
        period: usize,
    },
    /// Adversarial, ‖e‖₂ = eps: pushes the state towards the state bound that is closest
    /// to active at the next state, along the input sensitivity of that bound:
    /// `e = ±eps·(∂F_i/∂u)/‖∂F_i/∂u‖` for the coordinate i and side ± of the smallest
    /// margin of `F(x, u)` (one-step greedy; the adversary sees the true state).
    Adversarial {
        /// Amplitude.
        eps: f64,
    },
    /// Uniform in [−eps, eps] per input, seeded by the run's seed.
    Random {
        /// Amplitude.
        eps: f64,
    },
}

impl Disturbance {
    /// The disturbance at step `k`, state `x`, nominal input `u` (before saturation).
    pub fn at(
        &self,
        model: &Discrete,
        cfg: &ProblemConfig,
        k: usize,
        seed: u64,
        x: &[f64],
        u: &[f64],
    ) -> Vec<f64> {
        let nu = u.len();
        match *self {
            Disturbance::None => vec![0.0; nu],
            Disturbance::BangBang { eps, period } => {
                let sign = if period > 0 && (k / period) % 2 == 1 {
                    -1.0
                } else {
                    1.0
                };
                vec![sign * eps; nu]
            }
            Disturbance::Random { eps } => (0..nu)
                .map(|j| eps * (2.0 * uniform(seed ^ 0x5eed_d157, k as u64, j as u64) - 1.0))
                .collect(),
            Disturbance::Adversarial { eps } => {
                let nx = x.len();
                let (mut f, mut jx, mut ju) =
                    (vec![0.0; nx], vec![0.0; nx * nx], vec![0.0; nx * nu]);
                model.linearize(x, u, &mut f, &mut jx, &mut ju);
                // (margin, coordinate, side): side +1 = upper bound.
                let mut best: Option<(f64, usize, f64)> = None;
                for i in 0..nx {
                    for (m, side) in [
                        (cfg.ocp.x_hi[i] - f[i], 1.0),
                        (f[i] - cfg.ocp.x_lo[i], -1.0),
                    ] {
                        if m.is_finite() && best.is_none_or(|b| m < b.0) {
                            best = Some((m, i, side));
                        }
                    }
                }
                let Some((_, i, side)) = best else {
                    return vec![eps; nu];
                };
                let row = &ju[i * nu..(i + 1) * nu];
                let norm = row.iter().map(|v| v * v).sum::<f64>().sqrt();
                if norm == 0.0 {
                    return vec![side * eps; nu];
                }
                row.iter().map(|v| side * eps * v / norm).collect()
            }
        }
    }
}

/// Simulation settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SimSettings {
    /// Number of steps (pendulum: 90 = 4.5 s).
    pub steps: usize,
    /// Uniform measurement noise amplitude per state (0 = none).
    pub noise: Vec<f64>,
    /// Seed of the noise.
    pub seed: u64,
    /// Relative change of the plant's parameter (0.1 = +10 %): of `mismatch_parameter`,
    /// else of the plant's mass.
    pub mass_mismatch: f64,
    /// The parameter `mass_mismatch` scales (`None`: the mass, see
    /// [`with_mass_scaled`](crate::problem::model::System::with_mass_scaled)).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mismatch_parameter: Option<String>,
    /// Additive input disturbance (default none).
    #[serde(default)]
    pub disturbance: Disturbance,
}

/// One closed-loop run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Run {
    /// Initial state.
    pub x0: Vec<f64>,
    /// Number of steps simulated.
    pub steps: usize,
    /// States x_0..x_steps.
    pub x: Vec<Vec<f64>>,
    /// Inputs applied u_0..u_{steps−1}.
    pub u: Vec<Vec<f64>>,
    /// Steps with a violation > 1e-6 of a state bound (x_1..x_steps) or a path constraint
    /// ([`step_violation`]).
    pub violation_steps: usize,
    /// Share of violating steps in %.
    pub violation_percent: f64,
    /// Largest violation ([`step_violation`]).
    pub max_violation: f64,
    /// Largest ‖κ(x_k) − κ_NN(x_k)‖ along the trajectory (0 for the MPC).
    pub max_input_divergence: f64,
    /// Input divergence at each step (empty for the MPC).
    pub divergence: Vec<f64>,
    /// Σ (x_k − x_ref)ᵀQ(x_k − x_ref) + (u_k − u_ref)ᵀR(u_k − u_ref).
    pub cost: f64,
    /// First step after which ‖x − x_ref‖∞ ≤ 0.05 for good (None: never; then not written,
    /// so that the JSON holds no `null`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub settling_step: Option<usize>,
    /// |x_steps − x_ref| per state: the offset from the setpoint where the run ends (a
    /// steady-state offset if the run has settled). Empty in files written before it existed.
    #[serde(default)]
    pub final_offset: Vec<f64>,
    /// Whether the network's raw output ever left the certified band U ⊕ [−ε, ε].
    pub left_band: bool,
    /// Steps where the MPC found no label (its input then held at the last one).
    pub mpc_failures: usize,
    /// Steps where the MPC's hard problem was infeasible at the visited state (its label
    /// was the soft one): the state had left the MPC's feasible set (counted for the MPC
    /// and, through the MPC solved for the divergence, for networks).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub mpc_soft_steps: usize,
    /// Set when the run ended early because it diverged (see [`RunStatus::Diverged`]): the
    /// run stops at that step with a defined status instead of carrying NaN along (and
    /// into JSON). Not written for a run that completed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stopped: Option<Stopped>,
    /// `diverged` when the run stopped early ([`Run::stopped`] says why); not written for
    /// a completed run.
    #[serde(default, skip_serializing_if = "RunStatus::is_completed")]
    pub status: RunStatus,
}

/// Why a closed-loop run ended before its last step.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Stopped {
    /// The step k at which the run diverged (its successor x_{k+1}, its cost or a
    /// constraint value not finite, x_{k+1} beyond X's margin, or the network's output at
    /// x_k not finite); the run holds x_0..x_k and u_0..u_{k−1}, and step k counts as a
    /// violating step.
    pub step: usize,
    /// What was not finite, in words.
    pub reason: String,
}

fn is_zero(v: &usize) -> bool {
    *v == 0
}

/// The simulated plant: the problem's, with the parameter `parameter` (else its mass,
/// [`with_mass_scaled`](crate::problem::model::System::with_mass_scaled)) scaled by
/// `1 + mismatch`. A plant without that parameter is simulated unchanged (the scenarios
/// make no mismatch runs for it; `closed_loop.mismatch` is validated against the plant).
fn plant(cfg: &ProblemConfig, mismatch: f64, parameter: Option<&str>) -> Discrete {
    let sys = if mismatch == 0.0 {
        None
    } else {
        match parameter {
            Some(p) => cfg.system.with_parameter_scaled(p, 1.0 + mismatch),
            None => cfg.system.with_mass_scaled(1.0 + mismatch),
        }
    }
    .unwrap_or_else(|| cfg.system.clone());
    Discrete::new(sys, cfg.ocp.ts, cfg.ocp.rk4_substeps)
}

/// The violation of step k of a closed loop: the largest of the state-bound violations of
/// x_{k+1} and the `[ocp]` path constraints as the OCP places them — one in states only at
/// x_{k+1}, one in inputs only at u_k, one in both at (x_k, u_k) for k ≥ 1 (the measured
/// x₀ is never constrained). Terminal constraints shape the prediction only and are not
/// checked along the closed loop. A non-finite constraint value, and a non-finite entry of
/// x_{k+1} (which `f64::max` would read as no violation), count as infinite.
pub fn step_violation(
    cfg: &ProblemConfig,
    constraints: Option<&ConstraintSet>,
    k: usize,
    x: &[f64],
    u: &[f64],
    next: &[f64],
) -> f64 {
    if next.iter().any(|v| !v.is_finite()) {
        return f64::INFINITY;
    }
    let mut viol = (0..next.len())
        .map(|i| {
            (next[i] - cfg.ocp.x_hi[i])
                .max(cfg.ocp.x_lo[i] - next[i])
                .max(0.0)
        })
        .fold(0.0f64, f64::max);
    let Some(cs) = constraints else {
        return viol;
    };
    let nx = x.len();
    let mut g = vec![0.0; cs.len()];
    let mut g_next = vec![0.0; cs.len()];
    cs.values(x, u, &mut g);
    cs.values(next, u, &mut g_next);
    for (i, c) in cs.items.iter().enumerate() {
        let v = match (c.terminal, c.uses_states(nx), c.uses_inputs(nx)) {
            (true, ..) => continue,
            (false, true, false) => g_next[i],
            (false, false, true) => g[i],
            _ if k >= 1 => g[i],
            _ => continue,
        };
        viol = viol.max(if v.is_nan() {
            f64::INFINITY
        } else {
            v.max(0.0)
        });
    }
    viol
}

/// Adds the stage cost (x − x_ref)ᵀQ(x − x_ref) + (u − u_ref)ᵀR(u − u_ref) to `cost`, term by
/// term in row-major order.
fn add_stage_cost(
    cost: &mut f64,
    (x, x_ref, q): (&[f64], &[f64], &nalgebra::DMatrix<f64>),
    (u, u_ref, r): (&[f64], &[f64], &nalgebra::DMatrix<f64>),
) {
    for i in 0..x.len() {
        for j in 0..x.len() {
            *cost += (x[i] - x_ref[i]) * q[(i, j)] * (x[j] - x_ref[j]);
        }
    }
    for i in 0..u.len() {
        for j in 0..u.len() {
            *cost += (u[i] - u_ref[i]) * r[(i, j)] * (u[j] - u_ref[j]);
        }
    }
}

/// Why a run diverges at this step, if it does by a non-finite next state or cost.
fn divergence(next: &[f64], cost: f64, x: &[f64], u: &[f64]) -> Option<String> {
    if next.iter().any(|v| !v.is_finite()) {
        Some(format!(
            "the plant's next state from x = {x:?}, u = {u:?} is not finite (NaN or ±∞)"
        ))
    } else if !cost.is_finite() {
        Some(format!(
            "the closed-loop cost overflowed at x = {x:?}, u = {u:?}"
        ))
    } else {
        None
    }
}

/// The MPC's input at `y`, solved along the run ([`MpcLaw::solve_next`]; soft solves
/// counted); `None` when it has no label there.
fn reference(law: &mut MpcLaw, y: &[f64], along: &mut Along, run: &mut Run) -> Option<Vec<f64>> {
    let l = law.solve_next(y, along);
    if l.status == crate::mpc::sqp::SqpStatus::Soft {
        run.mpc_soft_steps += 1;
    }
    l.status.is_labelled().then_some(l.u)
}

/// The network's output at `y`, clamped to `clamp` where finite; notes when it leaves
/// U ⊕ [−ε, ε].
fn net_output(
    m: &Mlp,
    eps: f64,
    clamp: Option<(&[f64], &[f64])>,
    y: &[f64],
    (ulo, uhi): (&[f64], &[f64]),
    run: &mut Run,
) -> Vec<f64> {
    let mut u = m.predict(y);
    if u.iter()
        .zip(ulo.iter().zip(uhi))
        .any(|(v, (l, h))| !(*v >= l - eps && *v <= h + eps))
    {
        run.left_band = true;
    }
    if let Some((lo, hi)) = clamp {
        for ((v, l), h) in u.iter_mut().zip(lo).zip(hi) {
            if v.is_finite() {
                *v = v.clamp(*l, *h);
            }
        }
    }
    u
}

/// Records ‖κ(y) − u‖₂; a non-finite one (a diverged net) is the reason the run ends.
fn record_divergence(run: &mut Run, kappa: &[f64], u: &[f64], y: &[f64]) -> Option<String> {
    let d = kappa
        .iter()
        .zip(u)
        .map(|(a, b)| (a - b).powi(2))
        .sum::<f64>()
        .sqrt();
    if d.is_finite() {
        run.divergence.push(d);
        run.max_input_divergence = run.max_input_divergence.max(d);
        None
    } else {
        Some(format!(
            "the network's output {u:?} at x = {y:?} is not finite"
        ))
    }
}

/// Simulates `ctrl` from `x0`. `law` is used for the MPC and for the input divergence.
pub fn simulate(
    cfg: &ProblemConfig,
    law: &mut MpcLaw,
    ctrl: &Controller,
    x0: &[f64],
    s: &SimSettings,
) -> Run {
    let nx = cfg.system.nx();
    let nu = cfg.system.nu();
    let model = plant(cfg, s.mass_mismatch, s.mismatch_parameter.as_deref());
    let (q, r) = (cfg.q(), cfg.r());
    let (x_ref, u_ref) = (cfg.ocp.x_ref_or_origin(nx), cfg.ocp.u_ref_or_zero(nu));
    let (ulo, uhi) = (&cfg.ocp.u_lo, &cfg.ocp.u_hi);
    let mut x = x0.to_vec();
    let mut run = Run {
        x0: x0.to_vec(),
        steps: s.steps,
        x: vec![x.clone()],
        u: Vec::new(),
        violation_steps: 0,
        violation_percent: 0.0,
        max_violation: 0.0,
        max_input_divergence: 0.0,
        divergence: Vec::new(),
        cost: 0.0,
        settling_step: None,
        final_offset: Vec::new(),
        left_band: false,
        mpc_failures: 0,
        mpc_soft_steps: 0,
        stopped: None,
        status: RunStatus::Completed,
    };
    let (slo, shi) = stop_box(cfg);
    let outside = |v: &[f64]| (0..nx).find(|&i| !(v[i] >= slo[i] && v[i] <= shi[i]));
    let constraints = cfg.constraint_set().ok().flatten();
    let mut along = Along::default();
    // A network's divergence reference is the MPC's plain solve (no retry ladder: module
    // doc); the law's own budget comes back when the run ends.
    let budget = matches!(ctrl, Controller::Net(..)).then(|| law.set_retry_budget(0));
    let mut last_u = vec![0.0; nu];
    let mut next = vec![0.0; nx];
    for k in 0..s.steps {
        let y: Vec<f64> = (0..nx)
            .map(|i| {
                x[i] + s.noise.get(i).copied().unwrap_or(0.0)
                    * (2.0 * uniform(s.seed, k as u64, i as u64) - 1.0)
            })
            .collect();
        let mut net_reason = None;
        let mut u = match ctrl {
            Controller::Mpc => match reference(law, &y, &mut along, &mut run) {
                Some(u) => u,
                None => {
                    run.mpc_failures += 1;
                    last_u.clone()
                }
            },
            Controller::Net(m, eps, clamp) => {
                let u = net_output(m, *eps, *clamp, &y, (ulo, uhi), &mut run);
                match reference(law, &y, &mut along, &mut run) {
                    Some(k) => net_reason = record_divergence(&mut run, &k, &u, &y),
                    None => run.mpc_failures += 1,
                }
                u
            }
        };
        if let Some(reason) = net_reason {
            run.violation_steps += 1;
            run.steps = k;
            run.stopped = Some(Stopped { step: k, reason });
            run.status = RunStatus::Diverged;
            break;
        }
        if s.disturbance != Disturbance::None {
            let e = s.disturbance.at(&model, cfg, k, s.seed, &x, &u);
            for (v, e) in u.iter_mut().zip(e) {
                *v += e;
            }
        }
        for (j, v) in u.iter_mut().enumerate() {
            *v = if v.is_finite() {
                v.clamp(ulo[j], uhi[j])
            } else {
                0.5 * (ulo[j] + uhi[j])
            };
        }
        last_u = u.clone();
        let cost_before = run.cost;
        add_stage_cost(&mut run.cost, (&x, &x_ref, &q), (&u, &u_ref, &r));
        model.step(&x, &u, &mut next);
        let reason = divergence(&next, run.cost, &x, &u).or_else(|| {
            outside(&next).map(|i| {
                format!(
                    "state {} = {} left X = [{}, {}] (with the state bounds) by more than \
                     {DIVERGED_MARGIN} × its width: outside [{}, {}] (from x = {x:?}, u = {u:?})",
                    i + 1,
                    next[i],
                    cfg.domain.lo[i],
                    cfg.domain.hi[i],
                    slo[i],
                    shi[i]
                )
            })
        });
        let viol = match reason {
            Some(_) => f64::INFINITY,
            None => step_violation(cfg, constraints.as_ref(), k, &x, &u, &next),
        };
        let reason = reason.or_else(|| {
            (!viol.is_finite())
                .then(|| format!("a constraint value at x = {x:?}, u = {u:?} is not finite"))
        });
        if let Some(reason) = reason {
            // A diverged run ends here: the step counts as violating (a state that is not
            // a number, or far outside X, satisfies no bound), the recorded values stay
            // finite.
            run.cost = cost_before;
            run.violation_steps += 1;
            run.steps = k;
            run.stopped = Some(Stopped { step: k, reason });
            run.status = RunStatus::Diverged;
            break;
        }
        x.copy_from_slice(&next);
        if viol > VIOLATION_TOL {
            run.violation_steps += 1;
        }
        run.max_violation = run.max_violation.max(viol);
        run.u.push(u);
        run.x.push(x.clone());
    }
    if let Some(b) = budget {
        law.set_retry_budget(b);
    }
    run.violation_percent = 100.0 * run.violation_steps as f64 / s.steps.max(1) as f64;
    let settled = |v: &Vec<f64>| v.iter().zip(&x_ref).all(|(c, r)| (c - r).abs() <= 0.05);
    run.settling_step = (0..run.x.len())
        .find(|&k| run.x[k..].iter().all(settled))
        .filter(|_| run.stopped.is_none());
    run.final_offset = x.iter().zip(&x_ref).map(|(v, r)| (v - r).abs()).collect();
    run
}

#[cfg(test)]
#[path = "closed_loop_tests.rs"]
mod tests;
