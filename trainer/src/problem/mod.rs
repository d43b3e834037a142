//! Problem files: the system, the OCP data, the domain X, solver and sampler settings.
//!
//! A problem file is TOML (see `configs/*.toml`); it is deserialised into
//! [`ProblemConfig`] and validated once by [`ProblemConfig::validate`], whose errors name
//! the key at fault. Everything downstream trusts a validated config.
//!
//! Matrices (`q`, `r`, `p`) are written either as a diagonal (`q = [10.0, 1.0]`) or as a
//! full row-major matrix (`q = [[10.0, 0.0], [0.0, 1.0]]`). State bounds may be
//! `inf`/`-inf` (no bound); every other number — input bounds, weights, parameters, the
//! domain, tolerances — must be finite. Sizes have documented upper limits ([`limits`]).

//!
//! The files of this folder each own one part of the file's settings — plain structs with
//! `Default`, deserialised from TOML — and `validate` checks them all once, at the edge:
//! [`ocp`] (`[ocp]`), [`sampling`] (`[domain]`, `[sampling]`), [`solver`] (`[solver]`),
//! [`training`] (`[training]`), [`refine`] (`[refine]`), [`robust`] (`[robust]`),
//! [`study`] (`[closed_loop]`, `[plots]`) and [`model`] (`[system]`: the plant models).
//! Every later stage reads its settings from here; `problem` imports nothing of the crate
//! but `io`.

mod certify;
pub(crate) mod limits;
pub mod model;
pub(crate) mod ocp;
pub(crate) mod online_check;
pub(crate) mod refine;
pub(crate) mod robust;
pub(crate) mod sampling;
pub(crate) mod setpoint;
pub(crate) mod solver;
pub(crate) mod study;
pub(crate) mod training;
mod validate;

pub use certify::{CertifySettings, DEFAULT_STATISTICAL};
pub use ocp::{MatrixSpec, OcpSettings, StageBounds};
pub use online_check::OnlineCheck;
pub use refine::{CheckSettings, RefineSettings, RefineSwitch};
pub use robust::{RobustMethod, RobustSettings};
pub use sampling::{Domain, SamplerKind, SamplingSettings};
pub use solver::{default_starts, QpSolverKind, SolverSettings, Start};
pub use study::{ClosedLoopSettings, Mismatch, MismatchScenario, PlotSettings};
pub use training::{Activation, Outputs, Precision, Schedule, SequenceForm, TrainSettings};
pub(crate) use validate::check_matrix;

use crate::io::hex;
use crate::problem::model::expr::{ConstraintSet, ExprError};
use crate::problem::model::{CustomPlant, System};
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
    #[error("{}invalid setting `{key}`: {reason}", in_file(.path))]
    Invalid {
        /// The problem file it was read from (empty for a config built in code).
        path: String,
        /// The dotted key at fault, e.g. `ocp.q`.
        key: String,
        /// What is wrong with it.
        reason: String,
    },
}

fn in_file(path: &str) -> String {
    if path.is_empty() {
        String::new()
    } else {
        format!("problem file {path}: ")
    }
}

pub(crate) fn invalid(key: impl Into<String>, reason: impl Into<String>) -> ConfigError {
    ConfigError::Invalid {
        path: String::new(),
        key: key.into(),
        reason: reason.into(),
    }
}

impl ConfigError {
    /// The same error, naming the problem file `origin` it was read from.
    fn in_file(self, origin: &str) -> Self {
        match self {
            ConfigError::Invalid { key, reason, .. } => ConfigError::Invalid {
                path: origin.to_string(),
                key,
                reason,
            },
            e => e,
        }
    }
}

/// A TOML error's message with the problem first: the parser's own text (for a `[system]`
/// expression: the key, the column and what is wrong, e.g. ``system.rhs[1], column 5 of
/// `u + thetaa`: unknown name `thetaa` …``), then where it is in the file (toml's "TOML
/// parse error at line …" and the line quoted), which toml's `Display` puts first.
fn problem_first(e: &toml::de::Error) -> String {
    let message = e.message().trim_end();
    let full = e.to_string();
    let place = full.replacen(message, "", 1);
    let place = place.trim();
    if place.is_empty() {
        message.to_string()
    } else {
        format!("{message}\n{place}")
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
    /// refine`; not serialised when it is the default, so a problem without it serialises
    /// the same whether or not the section is written out).
    #[serde(default, skip_serializing_if = "RefineSettings::is_default")]
    pub refine: RefineSettings,
    /// Robust MPC design for a certified ε (`[robust]`, off by default; not serialised
    /// when it is the default, so a problem without it hashes and serialises the same
    /// whether or not the section is written out).
    #[serde(default, skip_serializing_if = "RobustSettings::is_default")]
    pub robust: RobustSettings,
    /// Figures of the report.
    #[serde(default)]
    pub plots: PlotSettings,
    /// The tiers `trainer run` adds after Theorem 1 (`[certify]`: statistical states and
    /// closed loops; not serialised when it is the default).
    #[serde(default, skip_serializing_if = "CertifySettings::is_default")]
    pub certify: CertifySettings,
}

impl Default for ProblemConfig {
    /// The paper's pendulum (the embedded `configs/pendulum.toml`).
    fn default() -> Self {
        // The embedded file is validated by the unit test `shipped_configs_parse_and_validate`.
        Self::from_toml_str(PENDULUM_TOML, "<embedded pendulum>")
            .expect("the embedded configs/pendulum.toml is valid")
    }
}

impl ProblemConfig {
    /// Parses and validates a problem file's text; `origin` names it in errors. A plant of
    /// `kind = "custom"` is an error naming it: use [`from_toml_str_with`](Self::from_toml_str_with).
    pub fn from_toml_str(text: &str, origin: &str) -> Result<Self, ConfigError> {
        Self::from_toml_str_with(text, origin, &[])
    }

    /// Parses and validates a problem file's text whose `[system]` may be one of `plants`,
    /// plants implemented in Rust by the calling program (`kind = "custom"`, found by
    /// name; see [`model::custom`] for the checks). A custom plant not among them is an
    /// error naming it.
    pub fn from_toml_str_with(
        text: &str,
        origin: &str,
        plants: &[CustomPlant],
    ) -> Result<Self, ConfigError> {
        let cfg: ProblemConfig = model::custom::reading_with(plants, || toml::from_str(text))
            .map_err(|e| ConfigError::Parse {
                path: origin.to_string(),
                message: problem_first(&e),
            })?;
        let mut cfg = cfg;
        // `sequence_form` defaults to feedback in a file, but means nothing (and is not
        // stored) without a sequence net.
        for t in [&mut cfg.training, &mut cfg.refine.training] {
            if t.outputs.is_first() {
                t.sequence_form = SequenceForm::Open;
            }
        }
        cfg.validate().map_err(|e| e.in_file(origin))?;
        cfg.settle_setpoint().map_err(|e| e.in_file(origin))?;
        // `[refine] target_eps` not given: a fraction of the input range in the
        // certificate's norm (`refine::default_target_eps`).
        let given = toml::from_str::<toml::Table>(text)
            .ok()
            .is_some_and(|t| t.get("refine").and_then(|r| r.get("target_eps")).is_some());
        if !given {
            cfg.refine.target_eps = refine::default_target_eps(&cfg.ocp);
        }
        Ok(cfg)
    }

    /// Parses and validates a problem file that this program stored (the copy in a
    /// dataset's header, `toml::to_string` of a config). There a missing
    /// `training.hold_setpoint` means off: it is written only when on, and copies stored
    /// before it existed come from runs without the hold. (In a file a user writes, a
    /// missing key means the default, on.) The same for `refine.training` when `[refine]`
    /// was stored. Likewise a missing `training.precision` means f64 (written only when f32),
    /// and a missing `training.sequence_form` means open (written only when feedback).
    pub fn from_stored_toml(text: &str, origin: &str) -> Result<Self, ConfigError> {
        let mut cfg = Self::from_toml_str(text, origin)?;
        let table: toml::Table = toml::from_str(text).map_err(|e| ConfigError::Parse {
            path: origin.to_string(),
            message: e.to_string(),
        })?;
        let hold = |t: Option<&toml::Value>| {
            t.and_then(|t| t.get("hold_setpoint"))
                .and_then(toml::Value::as_bool)
                .unwrap_or(false)
        };
        let precision = |t: Option<&toml::Value>| match t
            .and_then(|t| t.get("precision"))
            .and_then(toml::Value::as_str)
        {
            Some("f32") => Precision::F32,
            _ => Precision::F64,
        };
        let form = |t: Option<&toml::Value>| match t
            .and_then(|t| t.get("sequence_form"))
            .and_then(toml::Value::as_str)
        {
            Some("feedback") => SequenceForm::Feedback,
            _ => SequenceForm::Open,
        };
        cfg.training.hold_setpoint = hold(table.get("training"));
        cfg.training.precision = precision(table.get("training"));
        cfg.training.sequence_form = form(table.get("training"));
        if let Some(r) = table.get("refine") {
            cfg.refine.training.hold_setpoint = hold(r.get("training"));
            cfg.refine.training.precision = precision(r.get("training"));
            cfg.refine.training.sequence_form = form(r.get("training"));
        }
        Ok(cfg)
    }

    /// The problem file as text (TOML), as stored in `problem.toml` and in datasets; a
    /// custom plant is written as its record (name, version, names, parameters,
    /// fingerprint).
    pub fn to_toml_string(&self) -> Result<String, ConfigError> {
        toml::to_string(self).map_err(|e| ConfigError::Parse {
            path: format!("problem `{}`", self.name),
            message: format!("cannot be written as TOML: {e}"),
        })
    }

    /// Reads, parses and validates a problem file.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Io {
            path: path.display().to_string(),
            source,
        })?;
        Self::from_toml_str(&text, &path.display().to_string())
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

    /// The compiled `[ocp]` path and terminal constraints over the plant's names
    /// ([`System::names`]); `None` when there are none. Errors name the key and column.
    pub fn constraint_set(&self) -> Result<Option<ConstraintSet>, ExprError> {
        let o = &self.ocp;
        if o.constraints.is_empty() && o.terminal_constraints.is_empty() {
            return Ok(None);
        }
        ConstraintSet::compile(
            &self.system.names(),
            &o.constraints,
            &o.terminal_constraints,
        )
        .map(Some)
    }

    /// Whether the dataset keeps every labelled state's optimal input sequence (a sequence
    /// net is trained: `[training] outputs = "sequence"`).
    pub fn keeps_sequences(&self) -> bool {
        !self.training.outputs.is_first()
    }

    /// Content hash (SHA-256, hex) of everything that determines a label: system, OCP and
    /// solver settings. Sampler settings are not part of it.
    pub fn problem_hash(&self) -> String {
        // The norm's scales are not part of the MPC (its labels do not depend on them).
        let mut ocp = std::borrow::Cow::Borrowed(&self.ocp);
        if ocp.x_scale.is_some() || ocp.u_scale.is_some() {
            let o = ocp.to_mut();
            o.x_scale = None;
            o.u_scale = None;
        }
        let bytes = postcard::to_allocvec(&(&self.system, &*ocp, &self.solver)).unwrap_or_default();
        hex(&Sha256::digest(&bytes))
    }
}

#[cfg(test)]
mod finite_tests;
#[cfg(test)]
mod plant_tests;
#[cfg(test)]
mod tests;
