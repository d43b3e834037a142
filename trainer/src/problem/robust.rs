//! `[robust]`: the robust MPC design for a certified input error ε (Corollary 1) — the
//! design ε, the tightening method, the ancillary LQR weights and the Monte Carlo sizes.

use super::{check_matrix, invalid, ConfigError, MatrixSpec};
use serde::{Deserialize, Serialize};

/// How the state constraints are tightened along the horizon.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RobustMethod {
    /// Tube with an LQR ancillary gain and its Riccati P as incremental Lyapunov function.
    #[default]
    Tube,
    /// Plain Lipschitz propagation (K = 0, P = I).
    Lipschitz,
}

/// Robust design settings (`[robust]`); off (`eps = 0`) by default.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RobustSettings {
    /// Design input error ε (2-norm; 0 = robust design off). `trainer run --robust-eps E`
    /// overrides it.
    pub eps: f64,
    /// Tightening method (default `tube`).
    pub method: RobustMethod,
    /// State weight of the ancillary LQR (default: `ocp.q`).
    pub lqr_q: Option<MatrixSpec>,
    /// Input weights of the ancillary LQR tried, as multiples of `ocp.r`; the one whose
    /// tightening is smallest is used (default 1e-4 … 10, half-decades).
    pub lqr_r_scales: Vec<f64>,
    /// Samples of (x, u) ∈ X × U for the estimated bound of systems without a sound one
    /// (default 20000).
    pub samples: usize,
    /// Seed of those samples and of the Monte Carlo initial states (default 7).
    pub seed: u64,
    /// Initial states of the closed-loop Monte Carlo with the robust-design net (default
    /// 1000, drawn uniformly in X and kept if the robust MPC is feasible there).
    pub monte_carlo_states: usize,
    /// Initial states (the first ones of the Monte Carlo set) of the robust MPC runs with
    /// input disturbances |e| ≤ ε and of the nominal-MPC cost comparison (default 100).
    pub disturbed_states: usize,
    /// When the pipeline net's (global) certificate misses the design ε, run the adaptive
    /// refinement with local certificates (`trainer refine`, the problem's `[refine]`
    /// settings) on the tightened MPC with the design ε as target, and use the refined net
    /// as the robust design's net (default false: minutes of solves).
    pub refine: bool,
    /// Add the proven terminal region `(x − x_r)ᵀP(x − x_r) ≤ α` (`robust::terminal`) to the
    /// tightened OCP as a terminal constraint, which makes recursive feasibility follow
    /// (default false: the region shrinks the MPC's feasible set, e.g. the full pendulum's
    /// upswing is no longer feasible within the horizon; without it recursive feasibility
    /// is reported `unknown`).
    pub terminal_constraint: bool,
}

impl Default for RobustSettings {
    fn default() -> Self {
        RobustSettings {
            eps: 0.0,
            method: RobustMethod::Tube,
            lqr_q: None,
            lqr_r_scales: vec![
                1e-4, 3e-4, 1e-3, 3e-3, 1e-2, 3e-2, 1e-1, 3e-1, 1.0, 3.0, 10.0,
            ],
            samples: 20_000,
            seed: 7,
            monte_carlo_states: 1000,
            disturbed_states: 100,
            refine: false,
            terminal_constraint: false,
        }
    }
}

impl RobustSettings {
    /// Whether these are the defaults (then `[robust]` is not serialised).
    pub fn is_default(&self) -> bool {
        *self == Self::default()
    }
    /// Whether a robust design is requested (ε > 0).
    pub fn enabled(&self) -> bool {
        self.eps > 0.0
    }
    /// Validation (called by [`ProblemConfig::validate`](super::ProblemConfig::validate)); errors name the key.
    pub fn validate(&self, nx: usize, _nu: usize) -> Result<(), ConfigError> {
        if !(self.eps.is_finite() && self.eps >= 0.0) {
            return Err(invalid(
                "robust.eps",
                format!("must be finite and ≥ 0, got {}", self.eps),
            ));
        }
        if self.lqr_r_scales.is_empty() {
            return Err(invalid("robust.lqr_r_scales", "needs at least one value"));
        }
        if let Some(i) = self
            .lqr_r_scales
            .iter()
            .position(|s| !(s.is_finite() && *s > 0.0))
        {
            return Err(invalid(
                format!("robust.lqr_r_scales[{i}]"),
                "must be finite and > 0",
            ));
        }
        if let Some(q) = &self.lqr_q {
            check_matrix("robust.lqr_q", q, nx, false)?;
        }
        if self.samples == 0 {
            return Err(invalid("robust.samples", "must be at least 1"));
        }
        if self.disturbed_states > self.monte_carlo_states {
            return Err(invalid(
                "robust.disturbed_states",
                "must not exceed robust.monte_carlo_states",
            ));
        }
        Ok(())
    }
}
