//! Stage 4 — the network κ_NN and its training.
//!
//! ```text
//! L(θ) = λ₁·(1/N)Σ‖κ(x_i) − κ_NN(x_i)‖² + λ₂·(1/N)Σ‖∂κ/∂x(x_i) − ∂κ_NN/∂x(x_i)‖²_F + λ₃·Σ_j‖W_j‖²_F
//! ```
//! - [`mlp`]: the multilayer perceptron, its forward, tangent and backward passes, the loss.
//! - [`train`]: Adam over the loss, learning-rate schedules, early stopping, the model file.
//!
//! Imports `problem`, `mpc` and `data`.

pub mod mlp;
pub mod train;
