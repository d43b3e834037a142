//! `[closed_loop]` and `[plots]`: the closed-loop study (initial states, steps, noise,
//! model mismatch, training seeds) and the figures of the report.

use serde::{Deserialize, Serialize};

/// Figures of the report (`[plots]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PlotSettings {
    /// Grid of MPC-labelled states over two axes of X for the error map (default [60, 30];
    /// for nx > 2 a slice, see `study::plots::slice_axes`).
    pub error_map_grid: [usize; 2],
    /// PNG pixels per SVG unit (default 1.5).
    pub png_scale: f64,
}

impl Default for PlotSettings {
    fn default() -> Self {
        PlotSettings {
            error_map_grid: [60, 30],
            png_scale: 1.5,
        }
    }
}

/// Closed-loop study settings (`[closed_loop]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ClosedLoopSettings {
    /// Simulated steps (default 90: the paper's 4.5 s at Ts = 0.05 s).
    pub steps: usize,
    /// Initial state of the reference run (default: the pendulum's (−π, 0); for other
    /// systems the default is a quarter of the way from the domain's centre to its lower
    /// corner).
    pub x0: Option<Vec<f64>>,
    /// Number of additional seeded random initial states (default 20).
    pub random_initial_states: usize,
    /// Number of measurement-noise runs (default 5 seeds).
    pub noise_runs: usize,
    /// Noise amplitude as a fraction of each domain half-width (default 0.01).
    pub noise_fraction: f64,
    /// Relative mass mismatch of the robustness runs, ± (default 0.1): the paper's
    /// scenario, run only for a plant with a mass (the built-ins; an expression or custom
    /// plant's parameter `mass`, else `m`) and only when [`mismatch`](Self::mismatch) is
    /// not given.
    pub mass_mismatch: f64,
    /// Model-mismatch scenarios named by the parameter perturbed:
    /// `mismatch = [{ parameter = "k0", relative = 0.1 }]` runs the loops with the plant's
    /// parameter scaled by 1 + relative and by 1 − relative (keys `<controller>_<parameter>+`
    /// and `-`). When given it replaces the mass scenario; `[]` runs none. Not serialised
    /// when absent.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mismatch: Option<Vec<Mismatch>>,
    /// Training seeds of the seed study (default 10: seeds `training.seed` ..
    /// `training.seed + 9`, the first one being the run's own nets): both nets are trained
    /// from each seed's initial weights and simulated from the reference initial state.
    /// 0 or 1 = no extra training.
    pub seeds: usize,
    /// The safety study (`study::safety`, issue 41 §6): Monte Carlo of closed loops of the
    /// safety-augmented controller (`controller_core::safe`, emulated bit for bit by
    /// `deploy::safe_emulation`), the plain network and the MPC from the same i.i.d. starts
    /// in X, written to `closed_loop.json` under `safe`, `plain`, `mpc` and `safety`
    /// (`study::scenarios::ClosedLoopFile`). Needs `[training] outputs =
    /// "sequence"`. Default false; not serialised when false.
    #[serde(skip_serializing_if = "is_false")]
    pub safety: bool,
    /// Closed loops per controller of the nominal safety study (default 10 000).
    #[serde(skip_serializing_if = "is_default_safety_runs")]
    pub safety_runs: usize,
    /// Closed loops per controller and mismatch scenario sign of the safety study (default
    /// 1 000; 0 = none). The scenarios are [`mismatch_scenarios`](Self::mismatch_scenarios).
    #[serde(skip_serializing_if = "is_default_safety_mismatch_runs")]
    pub safety_mismatch_runs: usize,
    /// With [`safety`](Self::safety): the MPC that labels the data and runs in the study
    /// imposes the safe controller's online check — its terminal set, terminal cost and
    /// margins (`[ocp.online_check]`, filled by `trainer run` from the generated safe plant) —
    /// so that the MPC's own sequence passes the check wherever the OCP is feasible (the
    /// method of Hose et al.). Default true; not serialised when true.
    #[serde(skip_serializing_if = "is_true")]
    pub safety_terminal: bool,
    /// σ of the safe controller's relaxed decrease (`controller_core::safe`, module doc): a
    /// feasible candidate is applied when its cost is at most the safe candidate's, or at
    /// most J_prev − σ·ℓ(x_prev, u_prev); every step then lowers the applied sequence's cost
    /// by at least σ·ℓ (convergence; closed-loop cost ≤ V_0/σ). Default 0.5, in [0, 1];
    /// 0 = the strict rule J(c) ≤ J(s) only. Written into the exported safe controller
    /// (`export --safe-rs`) and used by the safety study. Not serialised at its default.
    #[serde(skip_serializing_if = "is_default_safety_decrease")]
    pub safety_decrease: f64,
}

/// Default of [`ClosedLoopSettings::safety_decrease`].
pub const SAFETY_DECREASE: f64 = 0.5;

fn is_default_safety_decrease(v: &f64) -> bool {
    *v == SAFETY_DECREASE
}

impl ClosedLoopSettings {
    /// σ as the device takes it: `None` for 0 (the strict rule), else `Some(σ)` in f32.
    pub fn decrease(&self) -> Option<f32> {
        (self.safety_decrease > 0.0).then_some(self.safety_decrease as f32)
    }
}

/// Default of [`ClosedLoopSettings::safety_runs`].
pub const SAFETY_RUNS: usize = 10_000;

/// Default of [`ClosedLoopSettings::safety_mismatch_runs`].
pub const SAFETY_MISMATCH_RUNS: usize = 1_000;

fn is_false(v: &bool) -> bool {
    !*v
}

fn is_true(v: &bool) -> bool {
    *v
}

fn is_default_safety_runs(v: &usize) -> bool {
    *v == SAFETY_RUNS
}

fn is_default_safety_mismatch_runs(v: &usize) -> bool {
    *v == SAFETY_MISMATCH_RUNS
}

impl Default for ClosedLoopSettings {
    fn default() -> Self {
        ClosedLoopSettings {
            steps: 90,
            x0: None,
            random_initial_states: 20,
            noise_runs: 5,
            noise_fraction: 0.01,
            mass_mismatch: 0.1,
            mismatch: None,
            seeds: 10,
            safety: false,
            safety_runs: SAFETY_RUNS,
            safety_mismatch_runs: SAFETY_MISMATCH_RUNS,
            safety_terminal: true,
            safety_decrease: SAFETY_DECREASE,
        }
    }
}

/// One model-mismatch scenario: the plant's parameter `parameter` scaled by 1 ± `relative`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Mismatch {
    /// The parameter's name: a built-in's field (pendulum `m`, `l`, `g`; cart-pole
    /// `m_cart`, `m_pole`, `l`, `g`; double integrator `mass`) or an expression or custom
    /// plant's parameter.
    pub parameter: String,
    /// Relative change, in (0, 1).
    pub relative: f64,
}

/// A scenario as the study runs it: the key's tag (`mass`, or the parameter's name), the
/// parameter scaled and the relative change (applied with both signs).
#[derive(Debug, Clone, PartialEq)]
pub struct MismatchScenario {
    /// Tag of the closed-loop keys `<controller>_<tag>+` / `-`.
    pub tag: String,
    /// The parameter scaled (`None`: the plant's mass, see `System::with_mass_scaled`).
    pub parameter: Option<String>,
    /// Relative change.
    pub relative: f64,
}

impl ClosedLoopSettings {
    /// The mismatch scenarios to run for a plant: the listed [`mismatch`](Self::mismatch)
    /// entries, else the mass scenario when `mass_mismatch > 0` and the plant has a mass
    /// (`has_mass`), else none.
    pub fn mismatch_scenarios(&self, has_mass: bool) -> Vec<MismatchScenario> {
        match &self.mismatch {
            Some(list) => list
                .iter()
                .map(|m| MismatchScenario {
                    tag: m.parameter.clone(),
                    parameter: Some(m.parameter.clone()),
                    relative: m.relative,
                })
                .collect(),
            None if self.mass_mismatch > 0.0 && has_mass => vec![MismatchScenario {
                tag: "mass".into(),
                parameter: None,
                relative: self.mass_mismatch,
            }],
            None => Vec::new(),
        }
    }
}
