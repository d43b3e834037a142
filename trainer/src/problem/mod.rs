//! Problem files: the system, the OCP data, the domain X, solver and sampler settings.
//!
//! A problem file is TOML (see `configs/*.toml`); it is deserialised into
//! [`ProblemConfig`] and validated once by [`ProblemConfig::validate`], whose errors name
//! the key at fault. Everything downstream trusts a validated config.
//!
//! Matrices (`q`, `r`, `p`) are written either as a diagonal (`q = [10.0, 1.0]`) or as a
//! full row-major matrix (`q = [[10.0, 0.0], [0.0, 1.0]]`). Bounds may be `inf`/`-inf`.

pub mod model;

use crate::io::hex;
use crate::problem::model::System;
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use std::path::Path;

/// The paper's pendulum problem file, embedded so that the CLI runs without any file.
pub const PENDULUM_TOML: &str = include_str!("../../../configs/pendulum.toml");

/// Errors from reading or validating a problem file.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("cannot read problem file {path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The TOML did not parse or had wrong types/unknown keys.
    #[error("problem file {path}: {message}")]
    Parse {
        /// The file (or `<embedded>`).
        path: String,
        /// The parser's message (it names the key and line).
        message: String,
    },
    /// A value is out of range or inconsistent.
    #[error("invalid setting `{key}`: {reason}")]
    Invalid {
        /// The dotted key at fault, e.g. `ocp.q`.
        key: String,
        /// What is wrong with it.
        reason: String,
    },
}

pub(crate) fn invalid(key: impl Into<String>, reason: impl Into<String>) -> ConfigError {
    ConfigError::Invalid {
        key: key.into(),
        reason: reason.into(),
    }
}

/// A square matrix given as a diagonal or as full rows.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum MatrixSpec {
    /// Diagonal entries.
    Diagonal(Vec<f64>),
    /// Full matrix, row-major rows.
    Full(Vec<Vec<f64>>),
}

impl MatrixSpec {
    /// Dense matrix; `None` if the rows are ragged.
    pub fn to_dmatrix(&self) -> Option<DMatrix<f64>> {
        match self {
            MatrixSpec::Diagonal(d) => Some(DMatrix::from_diagonal(
                &nalgebra::DVector::from_column_slice(d),
            )),
            MatrixSpec::Full(rows) => {
                let n = rows.len();
                let m = rows.first().map_or(0, |r| r.len());
                if rows.iter().any(|r| r.len() != m) {
                    return None;
                }
                Some(DMatrix::from_fn(n, m, |i, j| rows[i][j]))
            }
        }
    }
}

/// The optimal control problem's data (`[ocp]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OcpSettings {
    /// Sampling time Ts in s (pendulum: 0.05).
    pub ts: f64,
    /// Horizon N ≥ 1 (pendulum: 20).
    pub horizon: usize,
    /// RK4 sub-steps per sample (default 1).
    #[serde(default = "one")]
    pub rk4_substeps: usize,
    /// Stage state weight Q (symmetric PSD).
    pub q: MatrixSpec,
    /// Stage input weight R (symmetric positive definite).
    pub r: MatrixSpec,
    /// Terminal weight P (symmetric PSD).
    pub p: MatrixSpec,
    /// Lower state bounds on x₁..x_N (`-inf` for none).
    pub x_lo: Vec<f64>,
    /// Upper state bounds on x₁..x_N (`inf` for none).
    pub x_hi: Vec<f64>,
    /// Lower input bounds on u₀..u_{N−1}.
    pub u_lo: Vec<f64>,
    /// Upper input bounds on u₀..u_{N−1}.
    pub u_hi: Vec<f64>,
    /// Stage-dependent bounds (a tightened, robust OCP; see `trainer::robust`). When
    /// present they replace the constant bounds above inside the OCP; the constant bounds
    /// stay the true constraint set X × U (actuator limits, closed-loop violation checks).
    /// Absent by default, and then not serialised, so hashes of existing problems are
    /// unchanged.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stages: Option<StageBounds>,
}

/// Per-stage bounds of a tightened OCP: `x_lo[k−1]`, `x_hi[k−1]` bound x_k (k = 1..N),
/// `u_lo[k]`, `u_hi[k]` bound u_k (k = 0..N−1). Infinite entries mean no bound.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StageBounds {
    /// Lower state bounds of x_1..x_N (N rows of nx).
    pub x_lo: Vec<Vec<f64>>,
    /// Upper state bounds of x_1..x_N (N rows of nx).
    pub x_hi: Vec<Vec<f64>>,
    /// Lower input bounds of u_0..u_{N−1} (N rows of nu).
    pub u_lo: Vec<Vec<f64>>,
    /// Upper input bounds of u_0..u_{N−1} (N rows of nu).
    pub u_hi: Vec<Vec<f64>>,
}

impl OcpSettings {
    /// Bounds `(lo, hi)` on the predicted state x_k, k = 1..N (stage-dependent if
    /// [`stages`](Self::stages) is set).
    pub fn x_bounds(&self, k: usize) -> (&[f64], &[f64]) {
        match &self.stages {
            Some(s) => (&s.x_lo[k - 1], &s.x_hi[k - 1]),
            None => (&self.x_lo, &self.x_hi),
        }
    }
    /// Bounds `(lo, hi)` on the input u_k, k = 0..N−1.
    pub fn u_bounds(&self, k: usize) -> (&[f64], &[f64]) {
        match &self.stages {
            Some(s) => (&s.u_lo[k], &s.u_hi[k]),
            None => (&self.u_lo, &self.u_hi),
        }
    }
}

fn one() -> usize {
    1
}

/// The state domain X (`[domain]`): the box that is sampled and certified.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Domain {
    /// Lower corner (finite).
    pub lo: Vec<f64>,
    /// Upper corner (finite).
    pub hi: Vec<f64>,
}

/// SQP settings (`[solver]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SolverSettings {
    /// Convergence tolerance on the scaled KKT residual (default 1e-8).
    pub tol: f64,
    /// Maximum SQP iterations (default 100).
    pub max_iter: usize,
    /// Label hard-infeasible states with the exact-penalty (soft) problem (default true).
    pub soft_fallback: bool,
    /// ℓ₁ weight of the state-bound slacks in the soft problem (default 1e4).
    pub soft_l1: f64,
    /// ℓ₂ weight of the state-bound slacks in the soft problem (default 1e2).
    pub soft_l2: f64,
    /// A constraint with slack ≤ this and multiplier ≤ this is weakly active (default 1e-7).
    pub degeneracy_tol: f64,
    /// Warm-start a sample from the nearest already-solved neighbour (default true).
    pub warm_start: bool,
    /// QP subproblem solver: `"structured"` (default; interior point on the banded OCP
    /// structure, cost linear in N, clarabel as fallback) or `"clarabel"` (reference).
    pub qp: crate::mpc::qp::QpSolverKind,
}

impl Default for SolverSettings {
    fn default() -> Self {
        SolverSettings {
            tol: 1e-8,
            max_iter: 100,
            soft_fallback: true,
            soft_l1: 1e4,
            soft_l2: 1e2,
            degeneracy_tol: 1e-7,
            warm_start: true,
            qp: crate::mpc::qp::QpSolverKind::default(),
        }
    }
}

/// How dataset states are chosen in X.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SamplerKind {
    /// Full tensor grid with per-axis counts, endpoints included.
    Grid,
    /// Uniform random states (seeded).
    Random,
    /// Halton low-discrepancy sequence (scrambled by the seed's offset).
    Halton,
    /// Points chosen by adaptive refinement (`trainer refine`); not a sampling plan, so
    /// rejected in `[sampling]`.
    Adaptive,
}

/// Sampler settings (`[sampling]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SamplingSettings {
    /// Sampler (default grid).
    pub sampler: SamplerKind,
    /// Grid points per axis (grid only; default: the paper's 35 × 10).
    pub counts: Vec<usize>,
    /// Number of states (random / halton; default 350).
    pub n: usize,
    /// Seed (default 0).
    pub seed: u64,
}

impl Default for SamplingSettings {
    fn default() -> Self {
        SamplingSettings {
            sampler: SamplerKind::Grid,
            counts: vec![35, 10],
            n: 350,
            seed: 0,
        }
    }
}

/// A whole problem file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProblemConfig {
    /// Short name used for run directories.
    pub name: String,
    /// The plant.
    pub system: System,
    /// The OCP.
    pub ocp: OcpSettings,
    /// The certified/sampled domain X.
    pub domain: Domain,
    /// Solver settings.
    #[serde(default)]
    pub solver: SolverSettings,
    /// Sampler settings.
    #[serde(default)]
    pub sampling: SamplingSettings,
    /// Training settings.
    #[serde(default)]
    pub training: TrainSettings,
    /// Closed-loop study settings.
    #[serde(default)]
    pub closed_loop: ClosedLoopSettings,
    /// Adaptive refinement with local certificates (`[refine]`, used by `trainer
    /// refine`; not serialised when it is the default, so existing problems serialise as
    /// before).
    #[serde(default, skip_serializing_if = "RefineSettings::is_default")]
    pub refine: RefineSettings,
    /// Robust MPC design for a certified ε (`[robust]`, off by default; not serialised
    /// when it is the default, so existing problems hash and serialise as before).
    #[serde(
        default,
        skip_serializing_if = "crate::robust::RobustSettings::is_default"
    )]
    pub robust: crate::robust::RobustSettings,
    /// Figures of the report.
    #[serde(default)]
    pub plots: PlotSettings,
}

/// Adaptive refinement settings (`[refine]`, used by `trainer refine`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RefineSettings {
    /// Target certified ε (default 0.75; `--target-eps` overrides).
    pub target_eps: f64,
    /// Budget of OCP solves (default 50 000; `--budget` overrides).
    pub budget: usize,
    /// Points per axis of the initial grid (default: 9 per axis).
    pub initial: Vec<usize>,
    /// Largest number of refinement rounds (default 80).
    pub max_rounds: usize,
    /// Adam epochs of each warm-started retraining (default 60).
    pub round_epochs: usize,
    /// Learning rate of the warm-started retrainings (default 1e-3, cosine decay).
    pub round_learning_rate: f64,
    /// Retrain only when a failing cell's corner error exceeds this fraction of the target
    /// (default 0.6); otherwise a round only splits cells.
    pub retrain_at: f64,
    /// Safety factor on the estimated MPC parts of the local certificate (default 2).
    pub safety: f64,
    /// Points whose error exceeds this fraction of the target are repeated `emphasis`
    /// times in the training set (default 0.5).
    pub emphasis_at: f64,
    /// Repetitions of such points (default 4; 1 = no emphasis).
    pub emphasis: usize,
    /// Cells narrower than this fraction of the domain on every axis are not split
    /// (default 1e-5).
    pub min_width: f64,
    /// The network and its first training (defaults: 2-32-32-1 tanh, 600 epochs, batch 64,
    /// learning rate 3e-3 with cosine decay, λ = (1, 0.1, 0), saturation-aware loss).
    pub training: TrainSettings,
}

impl Default for RefineSettings {
    fn default() -> Self {
        RefineSettings {
            target_eps: 0.75,
            budget: 50_000,
            initial: Vec::new(),
            max_rounds: 80,
            round_epochs: 60,
            round_learning_rate: 1e-3,
            retrain_at: 0.6,
            safety: 2.0,
            emphasis_at: 0.5,
            emphasis: 4,
            min_width: 1e-5,
            training: TrainSettings {
                hidden: vec![32, 32],
                epochs: 600,
                batch_size: 64,
                learning_rate: 3e-3,
                schedule: Schedule::Cosine,
                lambda: [1.0, 0.1, 0.0],
                validation_n: 0,
                log_every: 1_000_000,
                saturation_aware: true,
                ..TrainSettings::default()
            },
        }
    }
}

impl RefineSettings {
    /// Checks the settings (errors name the key).
    pub fn validate(&self, nx: usize) -> Result<(), ConfigError> {
        if !(self.target_eps.is_finite() && self.target_eps > 0.0) {
            return Err(invalid("refine.target_eps", "must be positive and finite"));
        }
        if self.budget == 0 {
            return Err(invalid("refine.budget", "must be at least 1"));
        }
        if !self.initial.is_empty() && self.initial.len() != nx {
            return Err(invalid(
                "refine.initial",
                format!("expected {nx} per-axis counts, got {}", self.initial.len()),
            ));
        }
        if let Some(i) = self.initial.iter().position(|&c| !(2..=8193).contains(&c)) {
            return Err(invalid(
                format!("refine.initial[{i}]"),
                "must be in 2..=8193 (the lattice has 40 bisection levels below it)",
            ));
        }
        let grid = self
            .initial_counts(nx)
            .iter()
            .try_fold(1usize, |a, &c| a.checked_mul(c));
        if grid.is_none_or(|g| g > self.budget) {
            return Err(invalid(
                "refine.initial",
                format!(
                    "the initial grid ({:?} points per axis) needs more solves than the budget {}",
                    self.initial_counts(nx),
                    self.budget
                ),
            ));
        }
        if !(self.safety.is_finite() && self.safety >= 1.0) {
            return Err(invalid("refine.safety", "must be at least 1"));
        }
        if !(self.round_learning_rate.is_finite() && self.round_learning_rate > 0.0) {
            return Err(invalid("refine.round_learning_rate", "must be positive"));
        }
        if !(self.retrain_at.is_finite() && self.retrain_at >= 0.0) {
            return Err(invalid("refine.retrain_at", "must be ≥ 0"));
        }
        if !(self.min_width.is_finite() && self.min_width > 0.0 && self.min_width < 1.0) {
            return Err(invalid("refine.min_width", "must be in (0, 1)"));
        }
        if !(self.emphasis_at.is_finite() && self.emphasis_at >= 0.0) || self.emphasis == 0 {
            return Err(invalid(
                "refine.emphasis",
                "emphasis ≥ 1 and emphasis_at ≥ 0",
            ));
        }
        let t = &self.training;
        if t.hidden.is_empty() || t.hidden.contains(&0) || t.epochs == 0 || t.batch_size == 0 {
            return Err(invalid(
                "refine.training",
                "hidden widths, epochs and batch_size must be positive",
            ));
        }
        if !(t.learning_rate.is_finite() && t.learning_rate > 0.0) {
            return Err(invalid("refine.training.learning_rate", "must be positive"));
        }
        Ok(())
    }

    /// Whether these are the default settings (then not serialised).
    pub fn is_default(&self) -> bool {
        *self == Self::default()
    }

    /// Initial grid counts for an `nx`-dimensional domain.
    pub fn initial_counts(&self, nx: usize) -> Vec<usize> {
        if self.initial.is_empty() {
            vec![9; nx]
        } else {
            self.initial.clone()
        }
    }
}

/// Figures of the report (`[plots]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PlotSettings {
    /// Grid of MPC-labelled states over the first two axes of X for the error map
    /// (default [60, 30]; the other coordinates sit at the centre of X).
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

/// Learning-rate schedule.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Schedule {
    /// Constant learning rate.
    Constant,
    /// Cosine decay from the learning rate to 1 % of it over the epochs.
    Cosine,
}

/// Training settings (`[training]`); defaults are the paper's setting.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrainSettings {
    /// Hidden layer widths (default [10, 10]).
    pub hidden: Vec<usize>,
    /// Hidden activation (default tanh).
    pub activation: crate::learn::mlp::Activation,
    /// Epochs (default 2000).
    pub epochs: usize,
    /// Minibatch size (default 35: 10 Adam steps per epoch on the 350-point grid).
    pub batch_size: usize,
    /// Adam learning rate (default 1e-2).
    pub learning_rate: f64,
    /// Learning-rate schedule (default constant).
    pub schedule: Schedule,
    /// (λ₁, λ₂, λ₃) of the sensitivity-regularized loss (default the paper's (1, 3, 0.05));
    /// the nominal net uses (λ₁, 0, 0).
    pub lambda: [f64; 3],
    /// Seed of the initial weights and of the minibatch shuffling (default 0).
    pub seed: u64,
    /// Stop early once ε_D (max error over the dataset) is at most this (default: none).
    pub target_eps_d: Option<f64>,
    /// Number of uniformly random validation states labelled by the MPC (default 1000).
    pub validation_n: usize,
    /// Seed of the validation states (default 12345).
    pub validation_seed: u64,
    /// Record the training curve every this many epochs (default 20).
    pub log_every: usize,
    /// Saturation-aware loss (default false): the deployed output is clamped to the input
    /// bounds, so a saturated label whose prediction is at or beyond its bound costs
    /// nothing (see `mlp::Batch::band`). Lets the net overshoot where κ saturates instead
    /// of rounding off the saturation kink.
    pub saturation_aware: bool,
}

impl Default for TrainSettings {
    fn default() -> Self {
        TrainSettings {
            hidden: vec![10, 10],
            activation: crate::learn::mlp::Activation::Tanh,
            epochs: 2000,
            batch_size: 35,
            learning_rate: 1e-2,
            schedule: Schedule::Constant,
            lambda: [1.0, 3.0, 0.05],
            seed: 0,
            target_eps_d: None,
            validation_n: 1000,
            validation_seed: 12345,
            log_every: 20,
            saturation_aware: false,
        }
    }
}

impl Default for ProblemConfig {
    /// The paper's pendulum (the embedded `configs/pendulum.toml`).
    fn default() -> Self {
        // The embedded file is validated by the unit test `shipped_configs_parse_and_validate`.
        Self::from_toml_str(PENDULUM_TOML, "<embedded pendulum>")
            .expect("the embedded configs/pendulum.toml is valid")
    }
}

fn check_vec(key: &str, v: &[f64], n: usize, allow_inf: bool) -> Result<(), ConfigError> {
    if v.len() != n {
        return Err(invalid(
            key,
            format!("expected {n} entries, got {}", v.len()),
        ));
    }
    for (i, x) in v.iter().enumerate() {
        if x.is_nan() || (!allow_inf && x.is_infinite()) {
            return Err(invalid(
                format!("{key}[{i}]"),
                format!("must be a finite number, got {x}"),
            ));
        }
    }
    Ok(())
}

fn check_bounds(
    key_lo: &str,
    key_hi: &str,
    lo: &[f64],
    hi: &[f64],
    strict: bool,
) -> Result<(), ConfigError> {
    for (i, (l, h)) in lo.iter().zip(hi).enumerate() {
        if l > h || (strict && l >= h) {
            return Err(invalid(
                format!("{key_lo}[{i}]"),
                format!("lower bound {l} is not below {key_hi}[{i}] = {h}"),
            ));
        }
    }
    Ok(())
}

pub(crate) fn check_matrix(
    key: &str,
    m: &MatrixSpec,
    n: usize,
    definite: bool,
) -> Result<DMatrix<f64>, ConfigError> {
    let mat = m
        .to_dmatrix()
        .ok_or_else(|| invalid(key, "rows have different lengths"))?;
    if mat.nrows() != n || mat.ncols() != n {
        return Err(invalid(
            key,
            format!(
                "expected a {n}×{n} matrix (or {n} diagonal entries), got {}×{}",
                mat.nrows(),
                mat.ncols()
            ),
        ));
    }
    if mat.iter().any(|x| !x.is_finite()) {
        return Err(invalid(key, "entries must be finite numbers"));
    }
    let scale = mat.amax().max(1.0);
    if (&mat - mat.transpose()).amax() > 1e-12 * scale {
        return Err(invalid(key, "must be symmetric"));
    }
    let min_eig = mat.clone().symmetric_eigen().eigenvalues.min();
    if definite && min_eig <= 1e-12 * scale {
        return Err(invalid(
            key,
            format!("must be positive definite (smallest eigenvalue {min_eig:.3e})"),
        ));
    }
    if !definite && min_eig < -1e-12 * scale {
        return Err(invalid(
            key,
            format!("must be positive semidefinite (smallest eigenvalue {min_eig:.3e})"),
        ));
    }
    Ok(mat)
}

impl ProblemConfig {
    /// Parses and validates a problem file's text; `origin` names it in errors.
    pub fn from_toml_str(text: &str, origin: &str) -> Result<Self, ConfigError> {
        let cfg: ProblemConfig = toml::from_str(text).map_err(|e| ConfigError::Parse {
            path: origin.to_string(),
            message: e.to_string(),
        })?;
        cfg.validate()?;
        Ok(cfg)
    }

    /// Reads, parses and validates a problem file.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Io {
            path: path.display().to_string(),
            source,
        })?;
        Self::from_toml_str(&text, &path.display().to_string())
    }

    /// Checks every setting once; the error names the key at fault.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if self.name.is_empty() || self.name.contains(['/', '\\']) {
            return Err(invalid(
                "name",
                "must be a non-empty name without path separators",
            ));
        }
        self.system.validate().map_err(|(k, r)| invalid(k, r))?;
        let (nx, nu) = (self.system.nx(), self.system.nu());
        let o = &self.ocp;
        if !(o.ts.is_finite() && o.ts > 0.0) {
            return Err(invalid(
                "ocp.ts",
                format!("must be finite and > 0, got {}", o.ts),
            ));
        }
        if o.horizon == 0 {
            return Err(invalid("ocp.horizon", "must be at least 1"));
        }
        if o.rk4_substeps == 0 {
            return Err(invalid("ocp.rk4_substeps", "must be at least 1"));
        }
        check_matrix("ocp.q", &o.q, nx, false)?;
        check_matrix("ocp.r", &o.r, nu, true)?;
        check_matrix("ocp.p", &o.p, nx, false)?;
        check_vec("ocp.x_lo", &o.x_lo, nx, true)?;
        check_vec("ocp.x_hi", &o.x_hi, nx, true)?;
        check_vec("ocp.u_lo", &o.u_lo, nu, true)?;
        check_vec("ocp.u_hi", &o.u_hi, nu, true)?;
        check_bounds("ocp.x_lo", "ocp.x_hi", &o.x_lo, &o.x_hi, false)?;
        check_bounds("ocp.u_lo", "ocp.u_hi", &o.u_lo, &o.u_hi, false)?;
        if let Some(st) = &o.stages {
            for (key, rows, n_rows, dim) in [
                ("ocp.stages.x_lo", &st.x_lo, o.horizon, nx),
                ("ocp.stages.x_hi", &st.x_hi, o.horizon, nx),
                ("ocp.stages.u_lo", &st.u_lo, o.horizon, nu),
                ("ocp.stages.u_hi", &st.u_hi, o.horizon, nu),
            ] {
                if rows.len() != n_rows {
                    return Err(invalid(
                        key,
                        format!("expected {n_rows} stages (N), got {}", rows.len()),
                    ));
                }
                for (k, r) in rows.iter().enumerate() {
                    check_vec(&format!("{key}[{k}]"), r, dim, true)?;
                }
            }
            for k in 0..o.horizon {
                check_bounds(
                    &format!("ocp.stages.x_lo[{k}]"),
                    &format!("ocp.stages.x_hi[{k}]"),
                    &st.x_lo[k],
                    &st.x_hi[k],
                    false,
                )?;
                check_bounds(
                    &format!("ocp.stages.u_lo[{k}]"),
                    &format!("ocp.stages.u_hi[{k}]"),
                    &st.u_lo[k],
                    &st.u_hi[k],
                    false,
                )?;
            }
        }
        check_vec("domain.lo", &self.domain.lo, nx, false)?;
        check_vec("domain.hi", &self.domain.hi, nx, false)?;
        check_bounds(
            "domain.lo",
            "domain.hi",
            &self.domain.lo,
            &self.domain.hi,
            true,
        )?;
        let s = &self.solver;
        if !(s.tol.is_finite() && s.tol > 0.0 && s.tol < 1.0) {
            return Err(invalid(
                "solver.tol",
                format!("must be in (0, 1), got {}", s.tol),
            ));
        }
        if s.max_iter == 0 {
            return Err(invalid("solver.max_iter", "must be at least 1"));
        }
        for (k, v) in [("solver.soft_l1", s.soft_l1), ("solver.soft_l2", s.soft_l2)] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(invalid(k, format!("must be finite and ≥ 0, got {v}")));
            }
        }
        if s.soft_l1 <= 0.0 && s.soft_l2 <= 0.0 {
            return Err(invalid(
                "solver.soft_l1",
                "soft_l1 and soft_l2 cannot both be 0",
            ));
        }
        if !(s.degeneracy_tol.is_finite() && s.degeneracy_tol > 0.0) {
            return Err(invalid("solver.degeneracy_tol", "must be finite and > 0"));
        }
        let t = &self.training;
        if t.hidden.is_empty() || t.hidden.contains(&0) {
            return Err(invalid(
                "training.hidden",
                "needs at least one hidden layer, all widths ≥ 1",
            ));
        }
        if t.epochs == 0 {
            return Err(invalid("training.epochs", "must be at least 1"));
        }
        if t.batch_size == 0 {
            return Err(invalid("training.batch_size", "must be at least 1"));
        }
        if !(t.learning_rate.is_finite() && t.learning_rate > 0.0) {
            return Err(invalid("training.learning_rate", "must be finite and > 0"));
        }
        if let Some(i) = t.lambda.iter().position(|l| !(l.is_finite() && *l >= 0.0)) {
            return Err(invalid(
                format!("training.lambda[{i}]"),
                "must be finite and ≥ 0",
            ));
        }
        if t.lambda[0] <= 0.0 {
            return Err(invalid(
                "training.lambda[0]",
                "the value term's weight must be > 0",
            ));
        }
        if t.target_eps_d.is_some_and(|e| !(e.is_finite() && e > 0.0)) {
            return Err(invalid("training.target_eps_d", "must be finite and > 0"));
        }
        if t.log_every == 0 {
            return Err(invalid("training.log_every", "must be at least 1"));
        }
        let c = &self.closed_loop;
        if c.steps == 0 {
            return Err(invalid("closed_loop.steps", "must be at least 1"));
        }
        if let Some(x0) = &c.x0 {
            check_vec("closed_loop.x0", x0, nx, false)?;
        }
        for (k, v) in [
            ("closed_loop.noise_fraction", c.noise_fraction),
            ("closed_loop.mass_mismatch", c.mass_mismatch),
        ] {
            if !(v.is_finite() && (0.0..1.0).contains(&v)) {
                return Err(invalid(k, format!("must be in [0, 1), got {v}")));
            }
        }
        self.robust.validate(nx, nu)?;
        if c.seeds > 1000 {
            return Err(invalid(
                "closed_loop.seeds",
                format!("at most 1000, got {}", c.seeds),
            ));
        }
        let pl = &self.plots;
        if let Some(i) = pl
            .error_map_grid
            .iter()
            .position(|&n| !(2..=2000).contains(&n))
        {
            return Err(invalid(
                format!("plots.error_map_grid[{i}]"),
                format!("must be in 2..=2000, got {}", pl.error_map_grid[i]),
            ));
        }
        if !(pl.png_scale.is_finite() && (0.1..=8.0).contains(&pl.png_scale)) {
            return Err(invalid(
                "plots.png_scale",
                format!("must be in [0.1, 8], got {}", pl.png_scale),
            ));
        }
        let sm = &self.sampling;
        match sm.sampler {
            SamplerKind::Grid => {
                if sm.counts.len() != nx {
                    return Err(invalid(
                        "sampling.counts",
                        format!("expected {nx} per-axis counts, got {}", sm.counts.len()),
                    ));
                }
                if let Some(i) = sm.counts.iter().position(|&c| c == 0) {
                    return Err(invalid(
                        format!("sampling.counts[{i}]"),
                        "must be at least 1",
                    ));
                }
                let total = sm.counts.iter().try_fold(1usize, |a, &c| a.checked_mul(c));
                if total.is_none_or(|t| t > 100_000_000) {
                    return Err(invalid("sampling.counts", "grid has more than 1e8 points"));
                }
            }
            SamplerKind::Random | SamplerKind::Halton => {
                if sm.n == 0 || sm.n > 100_000_000 {
                    return Err(invalid("sampling.n", "must be between 1 and 1e8"));
                }
            }
            SamplerKind::Adaptive => {
                return Err(invalid(
                    "sampling.sampler",
                    "\"adaptive\" datasets are made by `trainer refine`, not sampled",
                ));
            }
        }
        self.refine.validate(nx)?;
        Ok(())
    }

    /// Q as a dense matrix (valid after [`validate`](Self::validate)).
    pub fn q(&self) -> DMatrix<f64> {
        self.ocp
            .q
            .to_dmatrix()
            .unwrap_or_else(|| DMatrix::zeros(0, 0))
    }
    /// R as a dense matrix.
    pub fn r(&self) -> DMatrix<f64> {
        self.ocp
            .r
            .to_dmatrix()
            .unwrap_or_else(|| DMatrix::zeros(0, 0))
    }
    /// P as a dense matrix.
    pub fn p(&self) -> DMatrix<f64> {
        self.ocp
            .p
            .to_dmatrix()
            .unwrap_or_else(|| DMatrix::zeros(0, 0))
    }

    /// Content hash (SHA-256, hex) of everything that determines a label: system, OCP and
    /// solver settings. Sampler settings are not part of it.
    pub fn problem_hash(&self) -> String {
        let bytes =
            postcard::to_allocvec(&(&self.system, &self.ocp, &self.solver)).unwrap_or_default();
        hex(&Sha256::digest(&bytes))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const DIR: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/");

    #[test]
    fn shipped_configs_parse_and_validate() {
        for f in [
            "pendulum.toml",
            "cartpole.toml",
            "double_integrator.toml",
            "pendulum_robust.toml",
        ] {
            let path = std::path::PathBuf::from(DIR).join(f);
            ProblemConfig::load(&path).unwrap_or_else(|e| panic!("{f}: {e}"));
        }
        let d = ProblemConfig::default();
        assert_eq!(d.name, "pendulum");
        assert_eq!(d, ProblemConfig::from_toml_str(PENDULUM_TOML, "x").unwrap());
        assert_eq!(d.ocp.horizon, 20);
        assert_eq!(d.sampling.counts, vec![35, 10]);
    }

    fn err_key(edit: impl Fn(&mut ProblemConfig)) -> String {
        let mut c = ProblemConfig::default();
        edit(&mut c);
        match c.validate() {
            Err(ConfigError::Invalid { key, .. }) => key,
            other => panic!("expected Invalid, got {other:?}"),
        }
    }

    #[test]
    fn validation_names_the_key_at_fault() {
        assert_eq!(err_key(|c| c.ocp.horizon = 0), "ocp.horizon");
        assert_eq!(
            err_key(|c| c.ocp.q = MatrixSpec::Diagonal(vec![1.0])),
            "ocp.q"
        );
        assert_eq!(
            err_key(|c| c.ocp.q = MatrixSpec::Diagonal(vec![1.0, -1.0])),
            "ocp.q"
        );
        assert_eq!(
            err_key(|c| c.ocp.p = MatrixSpec::Full(vec![vec![1.0, 2.0], vec![0.0, 1.0]])),
            "ocp.p"
        );
        assert_eq!(
            err_key(|c| c.ocp.r = MatrixSpec::Diagonal(vec![0.0])),
            "ocp.r"
        );
        assert_eq!(err_key(|c| c.ocp.x_lo[1] = 2.0), "ocp.x_lo[1]");
        assert_eq!(err_key(|c| c.ocp.u_hi[0] = f64::NAN), "ocp.u_hi[0]");
        assert_eq!(err_key(|c| c.ocp.ts = f64::NAN), "ocp.ts");
        assert_eq!(err_key(|c| c.domain.hi[0] = f64::INFINITY), "domain.hi[0]");
        assert_eq!(err_key(|c| c.domain.lo = vec![0.0]), "domain.lo");
        assert_eq!(err_key(|c| c.sampling.counts = vec![3]), "sampling.counts");
        assert_eq!(err_key(|c| c.refine.target_eps = 0.0), "refine.target_eps");
        assert_eq!(err_key(|c| c.refine.budget = 80), "refine.initial");
        assert_eq!(
            err_key(|c| c.refine.initial = vec![1, 3]),
            "refine.initial[0]"
        );
        assert_eq!(
            err_key(|c| c.refine.initial = vec![3, 9000]),
            "refine.initial[1]"
        );
        assert_eq!(err_key(|c| c.refine.safety = 0.5), "refine.safety");
        assert_eq!(
            err_key(|c| c.sampling.sampler = SamplerKind::Adaptive),
            "sampling.sampler"
        );
        assert_eq!(err_key(|c| c.solver.tol = 0.0), "solver.tol");
        assert_eq!(
            err_key(
                |c| c.system = System::Pendulum(crate::problem::model::Pendulum {
                    m: -1.0,
                    ..Default::default()
                })
            ),
            "system.m"
        );
    }

    #[test]
    fn parse_errors_name_the_key() {
        let bad = PENDULUM_TOML.replace("horizon = 20", "horizon = \"twenty\"");
        let e = ProblemConfig::from_toml_str(&bad, "f.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("horizon") && e.contains("f.toml"), "{e}");
        let unknown = format!("{PENDULUM_TOML}\n[extra]\nfoo = 1\n");
        let e = ProblemConfig::from_toml_str(&unknown, "f.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("extra"), "{e}");
    }

    #[test]
    fn problem_hash_tracks_labels_only() {
        let a = ProblemConfig::default();
        let mut b = a.clone();
        b.sampling.seed = 7;
        assert_eq!(a.problem_hash(), b.problem_hash());
        b.ocp.horizon = 21;
        assert_ne!(a.problem_hash(), b.problem_hash());
    }
}
