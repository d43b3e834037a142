//! Stage 7 — the trained, certified net for a device.
//!
//! ```text
//! u = clamp(κ_NN,f32(proj_X(x)), U ⊕ [−ε, ε]),   |κ_NN,f32 − κ_NN,f64| ≤ f32 allowance
//! ```
//! - [`export`]: folding of the scaling, the f32 error analysis, the generated Rust source
//!   (`controller-core/src/demo/weights.rs`) and the postcard blob for `controller-core`;
//! - [`onnx`]: the same net as an ONNX model with the certificate in its metadata, and the
//!   import of a dense MLP from an ONNX file trained elsewhere.
//!
//! - [`plant_rs`]: the plant's discrete map F as `no_std` f32 Rust, for the online check of
//!   `controller_core::safe` (expression plants and the cart-pole).
//! - [`safe_rs`]: the safety-augmented controller of a sequence-net model as one file
//!   (plant, sequence net, `CONTROLLER`) for `controller_core::include_safe_controller!`.
//! - [`controller`]: the deployed controller of a model file as a library object (what
//!   `trainer eval` computes per state).
//!
//! Imports `problem`, `learn` and `certify`.

pub mod controller;
pub mod export;
pub mod onnx;
pub mod plant_rs;
pub mod plant_rs_margin;
pub mod plant_rs_safe;
pub mod safe_emulation;
pub mod safe_rs;
pub mod sequence_rs;
