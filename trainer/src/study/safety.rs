//! [`SafetyStudy`]: the safety study of `[closed_loop] safety = true` (issue 41 §6) — Monte
//! Carlo of closed loops of three controllers from the same i.i.d. starts x₀ ~ U(X) (seeded
//! by [`SAFETY_SEED`] and the run's index, so independent of the thread count):
//!
//! ```text
//! x_{k+1} = F(x_k, u_k)      F: the trainer's f64 model (nominal, or a parameter scaled by 1 ± r)
//! safe:   u_k = SafeController.step(x_k as f32)   (emulated bit for bit: deploy::safe_emulation)
//! plain:  u_k = Π_U(c_0(x_k))                     the sequence net's u₀ rows (= the model's net)
//! mpc:    u_k = sat_U(κ(x_k))                      solved along the run (MpcLaw::solve_next)
//! ```
//!
//! The safe controller is initialised with `init_with` by the MPC's sequence at x₀ (the first
//! solve of the MPC's own run from that x₀) when the MPC has one and it passes the online
//! check — the step then applies its first input; else by the terminal controller's f32
//! rollout Π_U(κ_f) when that passes (x₀ in the terminal set, as a rule); otherwise the first
//! feasible candidate becomes the safe sequence (`SafetyGroup::init_mpc` / `init_terminal` /
//! `init_candidate` count which). `mpc_feasible_starts` counts the starts whose first MPC
//! solve is a hard optimum: with `[ocp.online_check]` (the default of a safety problem in
//! `trainer run`) each of them should pass the check, so `init_mpc` ≈ `mpc_feasible_starts`.
//!
//! **Violation** (per step, [`step_violation`]): x_{k+1} outside the OCP's state box, or an
//! `[ocp]` path constraint violated where the OCP imposes it (states-only ones at x_{k+1},
//! inputs-only ones at u_k, mixed ones at (x_k, u_k) from k = 1), by more than
//! [`VIOLATION_TOL`], evaluated on the **true (f64 model) trajectory**, and a step whose next
//! state or cost is not finite. A run ends (`diverged`) when its next state is not finite
//! or leaves the hull of X and the finite state bounds widened by [`DIVERGED_MARGIN`] × X's
//! width (`stop_box`); that step counts as violating exactly when it violates by the rule
//! above (leaving the state box does; an unconstrained angle beyond the widened X does not). Terminal constraints are not checked along the
//! loop. **Converged**: the last state within [`CONVERGE_TOL`] of x_ref in the scaled
//! ∞-norm ([`distance_to_setpoint`]). **Cost**: Σ_k ℓ(x_k, u_k) in f64 over the simulated
//! steps. The cost ratio of a run is its cost over the MPC's from the same x₀ (runs where the
//! MPC's cost is positive and both are finite); the summaries give its median.
//!
//! What holds: for the nominal model, *deterministic: constraint satisfaction and convergence*
//! — resting on model match (here the f64 model against the device's f32 simulation: the
//! margins are **estimated**, `deploy::plant_rs_margin`), the terminal set's tier
//! (`TERMINAL_INVARIANCE`, `TERMINAL_DECREASE` of the generated plant) — once a safe sequence
//! exists. The study counts what happens; under mismatch nothing is claimed.

use crate::deploy::safe_emulation::{EmulatedPlant, SafeEmulation};
use crate::mpc::law::along::Along;
use crate::mpc::law::MpcLaw;
use crate::problem::model::expr::ConstraintSet;
use crate::problem::model::Discrete;
use crate::problem::{ProblemConfig, SequenceForm};
use crate::rng::uniform;
use crate::study::closed_loop::{step_violation, VIOLATION_TOL};
use crate::study::safety_diagnosis::CandidateCounts;
use crate::study::statistical_loop::{distance_to_setpoint, CONVERGE_TOL};
use controller_core::safe::{CandidateForm, SafeFlags};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// Seed of the initial states (`crate::rng::uniform` stream).
pub const SAFETY_SEED: u64 = 0x5afe_5eed;

/// The guarantee's words, exactly.
pub const GUARANTEE: &str =
    "deterministic for the nominal model: constraint satisfaction and convergence";

/// One closed loop.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SafetyRun {
    /// Steps whose true (f64) transition violates a constraint (module doc).
    pub violation_steps: usize,
    /// Steps that applied the safe fallback (shifted sequence + κ_f); 0 for plain and MPC.
    pub fallback_steps: usize,
    /// Steps without a safe sequence (flag `NO_SAFE`); 0 for plain and MPC.
    pub no_safe_steps: usize,
    /// Steps simulated (`[closed_loop] steps`, fewer when the run diverged).
    #[serde(default)]
    pub steps: usize,
    /// Σ ℓ(x_k, u_k) over the simulated steps.
    pub cost: f64,
    /// The last state within `CONVERGE_TOL` of x_ref (scaled ∞-norm), and not diverged.
    pub converged: bool,
    /// Stopped early: the next state was not finite or left the stop box (module doc).
    #[serde(default, skip_serializing_if = "is_false")]
    pub diverged: bool,
    /// The safe controller's candidate, step by step (`study::safety_diagnosis`); absent for
    /// plain and MPC.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub candidate: Option<CandidateCounts>,
}

fn is_false(v: &bool) -> bool {
    !*v
}

/// One controller's runs and their summary.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ControllerRuns {
    /// Σ violation_steps.
    pub total_violations: u64,
    /// Runs with at least one violating step.
    pub violating_runs: u64,
    /// Σ fallback_steps / Σ steps (the steps simulated).
    pub fallback_share: f64,
    /// Σ no_safe_steps.
    pub no_safe_steps: u64,
    /// Runs that converged.
    pub converged: u64,
    /// Median over runs of cost / the MPC's cost from the same x₀ (absent without any
    /// comparable run).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub median_cost_ratio: Option<f64>,
    /// Runs entering the median (MPC cost > 0, both finite).
    pub cost_ratio_runs: u64,
    /// The safe controller's candidate counts summed over the runs
    /// (`study::safety_diagnosis`); absent for plain and MPC.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub candidate: Option<CandidateCounts>,
    /// The runs, in the order of the starts (in `closed_loop.json` the nominal group's lists
    /// are the top-level `safe`, `plain`, `mpc`: `study::scenarios::ClosedLoopFile`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub runs: Vec<SafetyRun>,
}

/// The three controllers from the same starts.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SafetyGroup {
    /// The safety-augmented controller.
    pub safe: ControllerRuns,
    /// The plain network.
    pub plain: ControllerRuns,
    /// The MPC.
    pub mpc: ControllerRuns,
    /// Starts whose first MPC solve is a hard optimum (status `converged`).
    #[serde(default)]
    pub mpc_feasible_starts: u64,
    /// Safe runs initialised by the MPC's sequence at x₀ (`init_with`).
    pub init_mpc: u64,
    /// Safe runs initialised by the terminal controller's rollout (`init_with`).
    #[serde(default)]
    pub init_terminal: u64,
    /// Safe runs whose first safe sequence was a feasible candidate.
    pub init_candidate: u64,
    /// Safe runs in which no safe sequence ever existed.
    pub runs_without_safe_sequence: u64,
}

/// The study (`closed_loop.json`: key `safety`, its nominal runs the top-level `safe`,
/// `plain`, `mpc` — `study::scenarios::ClosedLoopFile`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SafetyStudy {
    /// Runs per controller (nominal).
    pub runs: usize,
    /// Steps per run.
    pub steps: usize,
    /// Seed of the starts.
    pub seed: u64,
    /// How the safe controller is initialised, in words.
    pub initialisation: String,
    /// What a violation is, in words.
    pub violation_rule: String,
    /// The guarantee of the safe controller under the nominal model (its exact words).
    pub guarantee: String,
    /// What the guarantee rests on, in words.
    pub rests_on: String,
    /// The terminal set's invariance tier (`"proven"` / `"sampled"`).
    pub terminal_invariance: String,
    /// The terminal cost's decrease tier (`"sampled"` / `"not established"`).
    pub terminal_decrease: String,
    /// The online check's margins (m_s, m_f), estimated.
    pub margins: [f64; 2],
    /// The candidate's form and the choice rule (relaxed decrease σ), in words (empty in
    /// studies written before them: the open form and the strict rule).
    #[serde(default)]
    pub choice: String,
    /// Nominal model: the keys `safe`, `plain`, `mpc`.
    #[serde(flatten)]
    pub nominal: SafetyGroup,
    /// Model mismatch, keyed `<parameter>+` / `-` (no guarantee claimed).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub mismatch: BTreeMap<String, SafetyGroup>,
}

/// A candidate source: x ↦ (c_0 … c_{N−1}), N rows of nu.
pub type Source<'a> = &'a (dyn Fn(&[f32]) -> Vec<Vec<f32>> + Sync);

/// Everything a run needs.
struct Setup<'a> {
    cfg: &'a ProblemConfig,
    plant: &'a EmulatedPlant,
    source: Source<'a>,
    cs: Option<ConstraintSet>,
}

/// The i-th start: uniform in X.
pub fn start(cfg: &ProblemConfig, i: u64) -> Vec<f64> {
    (0..cfg.system.nx())
        .map(|k| {
            let (lo, hi) = (cfg.domain.lo[k], cfg.domain.hi[k]);
            lo + (hi - lo) * uniform(SAFETY_SEED, i, k as u64)
        })
        .collect()
}

/// ℓ(x, u) in f64, term by term in row-major order (as the closed-loop study).
fn stage_cost(cfg: &ProblemConfig, x: &[f64], u: &[f64]) -> f64 {
    let (nx, nu) = (x.len(), u.len());
    let (q, r) = (cfg.q(), cfg.r());
    let (xr, ur) = (cfg.ocp.x_ref_or_origin(nx), cfg.ocp.u_ref_or_zero(nu));
    let mut c = 0.0;
    for i in 0..nx {
        for j in 0..nx {
            c += (x[i] - xr[i]) * q[(i, j)] * (x[j] - xr[j]);
        }
    }
    for i in 0..nu {
        for j in 0..nu {
            c += (u[i] - ur[i]) * r[(i, j)] * (u[j] - ur[j]);
        }
    }
    c
}

/// The controller of one run: its input at the true state `x` and step `k`, and what it
/// reports ((fallback, no safe)).
type Policy<'p> = dyn FnMut(usize, &[f64]) -> (Vec<f64>, bool, bool) + 'p;

/// Widening of the safety study's stop box, in widths of X per axis. Ten widths: an axis
/// without a state bound (a rate) legitimately goes far beyond X under the MPC itself — the
/// planar quadrotor's θ̇ reaches 6.3 rad/s in one step from X's edge (X: |θ̇| ≤ 1), which a
/// one-width margin (the ordinary study's `DIVERGED_MARGIN`) stopped as "diverged" in 80 of
/// 150 MPC runs; a real runaway (a reactor's temperature, a NaN) passes ten widths as well.
pub const DIVERGED_MARGIN: f64 = 10.0;

/// The box beyond which a run stops as diverged: the hull of X and the OCP's finite state
/// bounds, widened by [`DIVERGED_MARGIN`] × X's width per axis. (X alone is too small a
/// reference: the cart-pole's X has |ṗ|, |θ̇| ≤ 1 inside a state box of 5 and 10, and the
/// MPC's own swing-ups leave 3 × X within a few steps without violating anything.)
fn stop_box(cfg: &ProblemConfig) -> (Vec<f64>, Vec<f64>) {
    let (dlo, dhi) = (&cfg.domain.lo, &cfg.domain.hi);
    let (xlo, xhi) = (&cfg.ocp.x_lo, &cfg.ocp.x_hi);
    (0..dlo.len())
        .map(|i| {
            let m = DIVERGED_MARGIN * (dhi[i] - dlo[i]);
            let lo = if xlo[i].is_finite() {
                dlo[i].min(xlo[i])
            } else {
                dlo[i]
            };
            let hi = if xhi[i].is_finite() {
                dhi[i].max(xhi[i])
            } else {
                dhi[i]
            };
            (lo - m, hi + m)
        })
        .unzip()
}

/// One closed loop of `policy` on `model` from `x0` (module doc's rules).
fn run_loop(
    cfg: &ProblemConfig,
    cs: Option<&ConstraintSet>,
    model: &Discrete,
    x0: &[f64],
    policy: &mut Policy,
) -> SafetyRun {
    let nx = x0.len();
    let (slo, shi) = stop_box(cfg);
    let mut x = x0.to_vec();
    let mut next = vec![0.0; nx];
    let mut run = SafetyRun {
        violation_steps: 0,
        fallback_steps: 0,
        no_safe_steps: 0,
        steps: 0,
        cost: 0.0,
        converged: false,
        diverged: false,
        candidate: None,
    };
    for k in 0..cfg.closed_loop.steps {
        run.steps = k + 1;
        let (u, fallback, no_safe) = policy(k, &x);
        run.fallback_steps += usize::from(fallback);
        run.no_safe_steps += usize::from(no_safe);
        model.step(&x, &u, &mut next);
        let cost = run.cost + stage_cost(cfg, &x, &u);
        let v = step_violation(cfg, cs, k, &x, &u, &next);
        let finite = cost.is_finite() && next.iter().all(|v| v.is_finite());
        if !finite || v.is_nan() || v > VIOLATION_TOL {
            run.violation_steps += 1;
        }
        if !finite || (0..nx).any(|i| !(next[i] >= slo[i] && next[i] <= shi[i])) {
            run.diverged = true;
            return run;
        }
        run.cost = cost;
        x.copy_from_slice(&next);
    }
    run.converged = distance_to_setpoint(cfg, &x) <= CONVERGE_TOL;
    run
}

/// u saturated to U (a non-finite entry: the centre of U).
fn saturate(cfg: &ProblemConfig, u: &[f64]) -> Vec<f64> {
    let (lo, hi) = (&cfg.ocp.u_lo, &cfg.ocp.u_hi);
    (0..lo.len())
        .map(|j| match u.get(j) {
            Some(v) if v.is_finite() => v.clamp(lo[j], hi[j]),
            _ => 0.5 * (lo[j] + hi[j]),
        })
        .collect()
}

fn to32(x: &[f64]) -> Vec<f32> {
    x.iter().map(|v| *v as f32).collect()
}

fn to64(u: &[f32]) -> Vec<f64> {
    u.iter().map(|v| f64::from(*v)).collect()
}

/// How a safe run got its first safe sequence.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Init {
    Never,
    Mpc,
    Terminal,
    Candidate,
}

/// The terminal controller's f32 rollout from `x`: v_k = Π_U(κ_f(x_k)), x_{k+1} = F32(x_k, v_k).
pub fn terminal_rollout(p: &EmulatedPlant, n: usize, x: &[f32]) -> Vec<Vec<f32>> {
    let mut xk = x.to_vec();
    (0..n)
        .map(|_| {
            let u = p.project_input(&p.terminal_input(&xk));
            xk = p.step(&xk, &u);
            u
        })
        .collect()
}

/// One start's runs: (safe, plain, mpc, the safe run's initialisation, the MPC's first solve
/// a hard optimum).
type Triple = (SafetyRun, SafetyRun, SafetyRun, Init, bool);

/// The three runs from `x0` on `model` ([`Triple`]).
fn triple(s: &Setup, law: &mut MpcLaw, model: &Discrete, x0: &[f64]) -> Triple {
    let (nu, n) = (s.cfg.system.nu(), s.cfg.ocp.horizon);
    let mut along = Along::default();
    let mut first_seq: Option<Vec<f64>> = None;
    let mut hard = false;
    let mut last = vec![0.0; nu];
    let cs = s.cs.as_ref();
    let mpc = run_loop(s.cfg, cs, model, x0, &mut |k, x| {
        let l = law.solve_next(x, &mut along);
        if k == 0 && l.status.is_labelled() {
            first_seq = Some(l.seq.clone());
            hard = l.status == crate::mpc::sqp::SqpStatus::Converged;
        }
        if l.status.is_labelled() {
            last = saturate(s.cfg, &l.u);
        }
        (last.clone(), false, false)
    });
    let mut emu = SafeEmulation::new(s.plant, n)
        .with_form(candidate_form(s.cfg))
        .with_decrease(s.cfg.closed_loop.decrease());
    let x32 = to32(x0);
    let mut how = Init::Never;
    let mut init = first_seq.filter(|q| q.len() == n * nu).and_then(|q| {
        let rows: Vec<Vec<f32>> = q.chunks(nu).map(to32).collect();
        emu.init_with(&x32, &rows).map(|_| rows[0].clone())
    });
    if init.is_some() {
        how = Init::Mpc;
    } else {
        let rows = terminal_rollout(s.plant, n, &x32);
        init = emu.init_with(&x32, &rows).map(|_| rows[0].clone());
        if init.is_some() {
            how = Init::Terminal;
        }
    }
    let mut counts = CandidateCounts::default();
    let mut safe = run_loop(s.cfg, cs, model, x0, &mut |k, x| {
        if let (0, Some(u0)) = (k, &init) {
            return (to64(&s.plant.project_input(u0)), false, false);
        }
        let x32 = to32(x);
        let out = emu.step_with(&x32, (s.source)(&x32));
        counts.record(s.plant, &x32, &out);
        if out.flags.contains(SafeFlags::INITIALISED) {
            how = Init::Candidate;
        }
        (
            to64(&out.u),
            out.flags.contains(SafeFlags::FALLBACK),
            out.flags.contains(SafeFlags::NO_SAFE),
        )
    });
    safe.candidate = Some(counts);
    let plain = run_loop(s.cfg, cs, model, x0, &mut |_, x| {
        let c = (s.source)(&to32(x));
        let first = c.first().cloned().unwrap_or_default();
        (to64(&s.plant.project_input(&first)), false, false)
    });
    (safe, plain, mpc, how, hard)
}

fn median(mut v: Vec<f64>) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let m = v.len() / 2;
    Some(if v.len() % 2 == 1 {
        v[m]
    } else {
        0.5 * (v[m - 1] + v[m])
    })
}

/// The summary of `runs` against the MPC's `mpc` runs from the same starts.
pub fn summarise(runs: Vec<SafetyRun>, mpc: &[SafetyRun]) -> ControllerRuns {
    let total_steps: usize = runs.iter().map(|r| r.steps).sum();
    let ratios: Vec<f64> = runs
        .iter()
        .zip(mpc)
        .filter(|(r, m)| m.cost > 0.0 && m.cost.is_finite() && r.cost.is_finite())
        .map(|(r, m)| r.cost / m.cost)
        .collect();
    let fallback: usize = runs.iter().map(|r| r.fallback_steps).sum();
    ControllerRuns {
        total_violations: runs.iter().map(|r| r.violation_steps as u64).sum(),
        violating_runs: runs.iter().filter(|r| r.violation_steps > 0).count() as u64,
        fallback_share: if total_steps == 0 {
            0.0
        } else {
            fallback as f64 / total_steps as f64
        },
        no_safe_steps: runs.iter().map(|r| r.no_safe_steps as u64).sum(),
        converged: runs.iter().filter(|r| r.converged).count() as u64,
        cost_ratio_runs: ratios.len() as u64,
        median_cost_ratio: median(ratios),
        candidate: CandidateCounts::total(runs.iter().map(|r| r.candidate.as_ref())),
        runs,
    }
}

/// `n` triples from the first `n` starts on `model`.
fn group(s: &Setup, model: &Discrete, n: usize) -> SafetyGroup {
    let cfg = s.cfg;
    let out: Vec<Triple> = (0..n as u64)
        .into_par_iter()
        .map_init(
            || MpcLaw::new(cfg),
            |law, i| triple(s, law, model, &start(cfg, i)),
        )
        .collect();
    let count = |w: Init| out.iter().filter(|t| t.3 == w).count() as u64;
    let mpc_feasible_starts = out.iter().filter(|t| t.4).count() as u64;
    let (init_mpc, init_terminal, init_candidate, never) = (
        count(Init::Mpc),
        count(Init::Terminal),
        count(Init::Candidate),
        count(Init::Never),
    );
    let mut safe = Vec::new();
    let mut plain = Vec::new();
    let mut mpc = Vec::new();
    for (a, b, c, _, _) in out {
        safe.push(a);
        plain.push(b);
        mpc.push(c);
    }
    SafetyGroup {
        safe: summarise(safe, &mpc),
        plain: summarise(plain, &mpc),
        mpc: summarise(mpc.clone(), &mpc),
        mpc_feasible_starts,
        init_mpc,
        init_terminal,
        init_candidate,
        runs_without_safe_sequence: never,
    }
}

/// The plant simulated under a scenario: the problem's, with `parameter` (else the mass)
/// scaled by 1 + `rel`.
fn perturbed(cfg: &ProblemConfig, parameter: Option<&str>, rel: f64) -> Discrete {
    let sys = match parameter {
        Some(p) => cfg.system.with_parameter_scaled(p, 1.0 + rel),
        None => cfg.system.with_mass_scaled(1.0 + rel),
    }
    .unwrap_or_else(|| cfg.system.clone());
    Discrete::new(sys, cfg.ocp.ts, cfg.ocp.rk4_substeps)
}

/// The candidate's form and the choice rule of `cfg`'s safe controller, in words.
pub fn choice_rule(cfg: &ProblemConfig) -> String {
    let form = match cfg.training.sequence_form {
        SequenceForm::Open => "the candidate's entries are the inputs (open form)",
        SequenceForm::Feedback => {
            "the candidate's entries 1 … N−1 are offsets from the terminal controller, \
             realised along the check's simulation as v_k = Π_U(κ_f(x̂_k) + c_k) (feedback form)"
        }
    };
    let rule = match cfg.closed_loop.decrease() {
        None => "a feasible candidate is applied when J(c) ≤ J(s) (strict rule)".to_string(),
        Some(sigma) => format!(
            "a feasible candidate is applied when J(c) ≤ J(s) or J(c) ≤ J_prev − {sigma}·ℓ(x_prev, \
             u_prev) (relaxed decrease σ = {sigma}: every step lowers the applied sequence's \
             cost by at least σ·ℓ, so convergence holds with closed-loop cost ≤ V_0/σ)"
        ),
    };
    format!("{form}; {rule}")
}

/// The device's candidate form of `cfg`'s sequence net (`[training] sequence_form`).
pub fn candidate_form(cfg: &ProblemConfig) -> CandidateForm {
    match cfg.training.sequence_form {
        SequenceForm::Open => CandidateForm::Open,
        SequenceForm::Feedback => CandidateForm::Feedback,
    }
}

/// The study of `cfg` with the candidate source `source` (the sequence net, or any other in
/// tests) and the emulated plant `plant` whose generation `tiers` ((invariance, decrease))
/// describes.
pub fn safety_study(
    cfg: &ProblemConfig,
    plant: &EmulatedPlant,
    tiers: (&str, &str),
    source: Source,
) -> SafetyStudy {
    let st = &cfg.closed_loop;
    let s = Setup {
        cfg,
        plant,
        source,
        cs: cfg.constraint_set().ok().flatten(),
    };
    let nominal_model = Discrete::new(cfg.system.clone(), cfg.ocp.ts, cfg.ocp.rk4_substeps);
    let nominal = group(&s, &nominal_model, st.safety_runs);
    let mut mismatch = BTreeMap::new();
    if st.safety_mismatch_runs > 0 {
        let has_mass = cfg.system.with_mass_scaled(1.0).is_some();
        for sc in st.mismatch_scenarios(has_mass) {
            for (sign, r) in [("+", sc.relative), ("-", -sc.relative)] {
                let m = perturbed(cfg, sc.parameter.as_deref(), r);
                let g = group(&s, &m, st.safety_mismatch_runs);
                mismatch.insert(format!("{}{sign}", sc.tag), g);
            }
        }
    }
    let (m_s, m_f) = plant.margins;
    SafetyStudy {
        runs: st.safety_runs,
        steps: st.steps,
        seed: SAFETY_SEED,
        initialisation: "init_with the MPC's optimal sequence at x0 (its first solve along the \
                         run) when the MPC labels x0 and the sequence passes the online check; \
                         else init_with the terminal controller's rollout when it passes; else \
                         the first feasible network candidate (before it: NO_SAFE steps, the \
                         candidate's first input projected onto U)"
            .into(),
        violation_rule: format!(
            "a step violates when the true (f64 model) x_(k+1) leaves the OCP's state box or an \
             [ocp] path constraint is violated where the OCP imposes it, by more than \
             {VIOLATION_TOL:e}, or its next state or cost is not finite; a run stops \
             (diverged) when its next state is not finite or leaves the hull of X and the \
             finite state bounds widened by {DIVERGED_MARGIN} x the width of X; converged: \
             last state within {CONVERGE_TOL} of x_ref in the scaled max-norm"
        ),
        guarantee: GUARANTEE.into(),
        rests_on: format!(
            "model match (the device's f32 simulation against the f64 model the loop runs \
             on; the margins m_s = {m_s:e}, m_f = {m_f:e} are estimated, \
             deploy::plant_rs_margin), the terminal set's tiers (invariance {}, decrease {}), \
             and a safe sequence existing (from the MPC at x0 or a feasible candidate); under \
             model mismatch nothing is claimed",
            tiers.0, tiers.1
        ),
        terminal_invariance: tiers.0.into(),
        terminal_decrease: tiers.1.into(),
        margins: [f64::from(m_s), f64::from(m_f)],
        choice: choice_rule(cfg),
        nominal,
        mismatch,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn r(v: usize, f: usize, cost: f64, converged: bool) -> SafetyRun {
        SafetyRun {
            violation_steps: v,
            fallback_steps: f,
            no_safe_steps: 0,
            steps: 10,
            cost,
            converged,
            diverged: false,
            candidate: None,
        }
    }

    /// Totals, shares and the median ratio by hand; a run whose MPC cost is 0 is left out of
    /// the median.
    #[test]
    fn summaries_count_by_hand() {
        let mpc = vec![
            r(0, 0, 2.0, true),
            r(0, 0, 4.0, true),
            r(0, 0, 0.0, true),
            r(0, 0, 1.0, true),
        ];
        let runs = vec![
            r(0, 3, 2.2, true),
            r(2, 0, 4.0, false),
            r(0, 1, 7.0, true),
            r(1, 0, 3.0, true),
        ];
        let s = summarise(runs, &mpc);
        assert_eq!(s.total_violations, 3);
        assert_eq!(s.violating_runs, 2);
        assert!((s.fallback_share - 4.0 / 40.0).abs() < 1e-15);
        assert_eq!(s.converged, 3);
        assert_eq!(s.cost_ratio_runs, 3);
        // Ratios 1.1, 1.0, 3.0: median 1.1.
        assert!((s.median_cost_ratio.unwrap() - 1.1).abs() < 1e-12);
        assert_eq!(median(vec![]), None);
        assert_eq!(median(vec![3.0, 1.0]), Some(2.0));
    }

    /// The double integrator pushed by u = 1 from rest (v_k = 0.1·k) in an X much smaller than
    /// its state box (|v| ≤ 0.097 in a box |v| ≤ 1): the run continues while inside the box's
    /// hull widened by 10 × 0.194 (|v| ≤ 2.94), counts exactly the steps with v > 1, and stops
    /// at v = 3.0; with v unbounded it stops at the widened X (|v| ≤ 2.037, at v = 2.1) and
    /// counts nothing. (No boundary is hit exactly: v's rounding cannot move a step.)
    #[test]
    fn divergence_stops_a_run_without_inventing_violations() {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../configs/double_integrator.toml"
        );
        let mut cfg = ProblemConfig::load(std::path::Path::new(path)).unwrap();
        cfg.domain.lo = vec![-0.5, -0.097];
        cfg.domain.hi = vec![0.5, 0.097];
        cfg.closed_loop.steps = 40;
        let model = Discrete::new(cfg.system.clone(), cfg.ocp.ts, cfg.ocp.rk4_substeps);
        let mut push = |_: usize, _: &[f64]| (vec![1.0], false, false);
        let r = run_loop(&cfg, None, &model, &[0.0, 0.0], &mut push);
        assert!(r.diverged, "{r:?}");
        assert_eq!(r.steps, 30, "{r:?}");
        assert_eq!(r.violation_steps, 20, "v = 1.1 … 3.0: {r:?}");
        cfg.ocp.x_lo[1] = f64::NEG_INFINITY;
        cfg.ocp.x_hi[1] = f64::INFINITY;
        let r = run_loop(&cfg, None, &model, &[0.0, 0.0], &mut push);
        assert!(
            r.diverged && r.steps == 21 && r.violation_steps == 0,
            "{r:?}"
        );
    }

    /// The starts are a pure function of the index, inside X.
    #[test]
    fn starts_are_keyed_and_inside_the_domain() {
        let cfg = ProblemConfig::default();
        for i in 0..100 {
            let x = start(&cfg, i);
            assert_eq!(x, start(&cfg, i));
            for (k, v) in x.iter().enumerate() {
                assert!(cfg.domain.lo[k] <= *v && *v <= cfg.domain.hi[k]);
            }
        }
        assert_ne!(start(&cfg, 0), start(&cfg, 1));
    }
}
