//! Stage 5 — bounds on the error e(x) = κ(x) − κ_NN(x) over X.
//!
//! ```text
//! Theorem 1:  ε = ε_D + (L_MPC + L_NN)·δ        ε_D = max_i ‖e(x_i)‖,  δ the covering radius
//! local:      ε_C ≥ sup_{x∈C} ‖κ(x) − sat(κ_NN(x))‖  per cell C, refined adaptively
//! ```
//! - [`lipschitz`]: L_NN (product of norms, LipSDP-Neuron, slope vertices, sampled lower
//!   bound) and the L_MPC estimates.
//! - [`netbounds`]: sound interval enclosures of κ_NN, ∂κ_NN/∂x, ∂²κ_NN/∂x² over a box.
//! - [`norm`]: the scaled norm ‖S_u⁻¹Δu‖₂, ‖S_x⁻¹Δx‖₂ every bound is stated in.
//! - [`certificate`]: Theorem 1 and its inverse (what a target ε requires).
//! - [`nearest`]: the k-d tree behind the covering radius's nearest-point distances.
//! - [`local`]: the cell bound ε_C from corner labels, enclosures and a remainder.
//! - [`critical`]: where the MPC is a QP, the proof that κ is affine on a cell (exact MPC part).
//! - [`refine`]: adaptive refinement of the cells until the target ε is met.
//! - [`local_summary`]: what `certificate.json` records of a local certificate.
//! - [`tier`]: sound / statistical / estimated, per term and for ε as a whole.
//! - [`statistical`]: the Clopper–Pearson bound on P(‖κ − sat κ_NN‖ > ε) from i.i.d. states.
//! - [`seal`]: the checksum `certificate.json` carries over its own bytes.
//! - [`file`]: `certificate.json` as one typed value, its only reader and writer.
//!
//! Imports `problem`, `mpc`, `data` and `learn`.

pub mod certificate;
pub mod critical;
pub mod file;
pub mod lipschitz;
pub(crate) mod local;
pub(crate) mod local_summary;
pub(crate) mod nearest;
pub(crate) mod netbounds;
pub mod norm;
pub mod refine;
pub mod seal;
pub mod statistical;
pub mod tier;

/// A model file as the later stages see it: the trained net with its certificate slot.
pub type Model = crate::learn::train::TrainedModel<certificate::Certificate>;
