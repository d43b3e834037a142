//! `[training]`: the network's shape and activation, the loss weights λ₁, λ₂, λ₃ and the
//! optimiser (Adam, schedule, epochs, batch size, early stopping).

use serde::{Deserialize, Serialize};

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
    pub activation: Activation,
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
    /// Hold the setpoint exactly (default true): after training, the constant
    /// c = κ(x_ref) − κ_NN(x_ref) is folded into the last layer's bias, so that the net
    /// reproduces the MPC's own input at the setpoint, u = κ_NN(x) − κ_NN(x_ref) + κ(x_ref)
    /// (`learn::setpoint`; L_NN is unchanged, ε_D is that of the corrected net). Written
    /// into stored copies of the problem file only when on: a stored copy without it
    /// ([`ProblemConfig::from_stored_toml`](crate::problem::ProblemConfig::from_stored_toml))
    /// means off, so that a run with it off stores, trains and hashes as one whose problem
    /// file never mentions it.
    #[serde(skip_serializing_if = "is_false")]
    pub hold_setpoint: bool,
    /// Arithmetic of the training passes (default f32, `learn::mlp::Lanes`). Written into
    /// stored copies of the problem file only when f32: a stored copy without it
    /// ([`ProblemConfig::from_stored_toml`](crate::problem::ProblemConfig::from_stored_toml))
    /// means f64, the only engine before f32 existed.
    #[serde(skip_serializing_if = "Precision::is_f64")]
    pub precision: Precision,
    /// What the net predicts (default `"first"`: u₀ = κ(x), nu outputs). `"sequence"`: the
    /// MPC's whole optimal input sequence u₀*, …, u_{N−1}*, N·nu outputs (the dataset then
    /// keeps every labelled state's sequence, N·nu f64 more per state; the sensitivity term
    /// stays on u₀; the certificates bound the u₀ rows). Written into stored copies only
    /// when `"sequence"`, so a run with the default stores and hashes as before.
    #[serde(skip_serializing_if = "Outputs::is_first")]
    pub outputs: Outputs,
    /// Per-step weights w_0, …, w_{N−1} of the value term of a sequence net (exactly N
    /// values, each finite and ≥ 0, w_0 > 0): output (k, j) costs w_k·(u − κ)². Default:
    /// all 1 (every step of the sequence counts as much as u₀). Only with
    /// `outputs = "sequence"`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sequence_weights: Option<Vec<f64>>,
    /// How a sequence net's outputs become the input sequence on the device
    /// (`controller_core::safe::CandidateForm`). `"feedback"` (the default in a problem
    /// file with `outputs = "sequence"`): outputs 1 … N−1 are offsets from the terminal
    /// controller along the simulated trajectory, v_k = Π_U(κ_f(x̂_k) + c_k), trained on
    /// c_k* = u_k* − κ_f(x_k*) along the MPC's predicted trajectory — the net's errors then
    /// pass through the stabilised loop, not the open-loop plant. `"open"`: the outputs are
    /// the inputs. Only with `outputs = "sequence"`; written into stored copies only when
    /// `"feedback"` (a stored copy without it, and `TrainSettings::default()`, mean open: the
    /// only form before it existed).
    #[serde(
        default = "SequenceForm::file_default",
        skip_serializing_if = "SequenceForm::is_open"
    )]
    pub sequence_form: SequenceForm,
}

/// `[training] sequence_form`: the candidate form of a sequence net (see the field).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SequenceForm {
    /// The outputs are the inputs u_0 … u_{N−1}.
    #[default]
    Open,
    /// u_0, then offsets c_k from κ_f: v_k = Π_U(κ_f(x̂_k) + c_k).
    Feedback,
}

impl SequenceForm {
    /// Whether this is [`SequenceForm::Open`].
    pub fn is_open(&self) -> bool {
        *self == SequenceForm::Open
    }

    /// The default of a problem file that does not name it (normalised to open by the
    /// validation when the net is not a sequence net).
    pub fn file_default() -> Self {
        SequenceForm::Feedback
    }
}

/// What the network predicts (`[training] outputs`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Outputs {
    /// The first input u₀ = κ(x) (nu outputs): the controller of the paper.
    #[default]
    First,
    /// The whole optimal input sequence u₀*, …, u_{N−1}* (N·nu outputs, row-major N × nu),
    /// for the safety-augmented controller (`controller_core::safe`).
    Sequence,
}

impl Outputs {
    /// Whether this is [`Outputs::First`].
    pub fn is_first(&self) -> bool {
        *self == Outputs::First
    }
}

impl TrainSettings {
    /// The per-step weights of a sequence net over `horizon` steps (the setting, else all 1).
    pub fn step_weights(&self, horizon: usize) -> Vec<f64> {
        self.sequence_weights
            .clone()
            .unwrap_or_else(|| vec![1.0; horizon])
    }
}

/// Arithmetic of the training passes (forward, tangent, reverse); Adam and the master
/// weights are f64 in both.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Precision {
    /// f32 passes over groups of 8 samples in vector lanes, with the deployed controller's
    /// f32 tanh (`learn::mlp::Lanes`).
    #[default]
    F32,
    /// f64 passes (`learn::mlp::Mlp::loss_grad`, libm's tanh): bit-identical to training
    /// before the f32 engine existed.
    F64,
}

impl Precision {
    /// Whether this is [`Precision::F64`].
    pub fn is_f64(&self) -> bool {
        *self == Precision::F64
    }
}

fn is_false(v: &bool) -> bool {
    !*v
}

impl Default for TrainSettings {
    fn default() -> Self {
        TrainSettings {
            hidden: vec![10, 10],
            activation: Activation::Tanh,
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
            hold_setpoint: true,
            precision: Precision::F32,
            outputs: Outputs::First,
            sequence_weights: None,
            sequence_form: SequenceForm::Open,
        }
    }
}

/// Hidden-layer activation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Activation {
    /// tanh (slope in [0, 1]).
    Tanh,
    /// ln(1 + eᶻ) (slope in [0, 1]).
    Softplus,
    /// max(0, z) (slope in {0, 1}).
    Relu,
}
