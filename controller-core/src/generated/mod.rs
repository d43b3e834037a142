//! `generated`: the compiled-in controller, written by `trainer export` (do not edit
//! `weights.rs` by hand): the paper's pendulum, through [`crate::include_controller!`] as
//! any other crate would include its own.
//!
//! ```
//! use controller_core::generated::{evaluate, weights, CERTIFICATE, NX};
//! assert_eq!(NX, weights::NX);
//! assert!(CERTIFICATE.eps >= CERTIFICATE.f32_allowance);
//! assert!(evaluate(&[0.0; NX]).u[0].is_finite());
//! ```

crate::include_controller!("weights.rs");
