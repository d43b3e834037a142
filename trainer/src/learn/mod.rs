//! Stage 4 — the network κ_NN and its training.
//!
//! ```text
//! L(θ) = λ₁·(1/N)Σ‖κ(x_i) − κ_NN(x_i)‖² + λ₂·(1/N)Σ‖∂κ/∂x(x_i) − ∂κ_NN/∂x(x_i)‖²_F + λ₃·Σ_j‖W_j‖²_F
//! ```
//! - [`mlp`]: the multilayer perceptron, its forward, tangent and backward passes, the loss.
//! - `adam`: the Adam optimiser's moments and update.
//! - `epoch`: one epoch — the learning-rate schedule, the seeded shuffle, the minibatch
//!   passes and their Adam steps.
//! - `metrics`: the training set's layout, the error statistics (ε_D, R²) and the points of
//!   the training curve.
//! - [`train`]: Adam over the loss, learning-rate schedules, early stopping, the model file.
//! - [`setpoint`]: the setpoint hold κ_NN(x) − κ_NN(x_ref) + κ(x_ref), folded into the
//!   last bias after training.
//! - [`sequence`]: the sequence net (`[training] outputs = "sequence"`): N·nu outputs, the
//!   model's net its u₀ rows.
//! - `stored_settings`: the model file's encoding of the training settings.
//! - [`model_file`]: the model file (encoding, checks, the trailer holding the problem file).
//!
//! Imports `problem`, `mpc` and `data`.

mod adam;
mod epoch;
mod metrics;
pub mod mlp;
pub(crate) mod model_file;
pub mod sequence;
pub mod setpoint;
mod stored_settings;
pub mod train;
