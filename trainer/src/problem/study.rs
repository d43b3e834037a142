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
    /// Relative mass mismatch of the robustness runs, ± (default 0.1).
    pub mass_mismatch: f64,
    /// Training seeds of the seed study (default 10: seeds `training.seed` ..
    /// `training.seed + 9`, the first one being the run's own nets): both nets are trained
    /// from each seed's initial weights and simulated from the reference initial state.
    /// 0 or 1 = no extra training.
    pub seeds: usize,
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
            seeds: 10,
        }
    }
}
