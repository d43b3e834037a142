//! `demo`: an example controller compiled into the core — the paper's pendulum
//! (2-10-10-1, written by `trainer export`; do not edit `weights.rs` by hand), through
//! [`crate::include_controller!`] as any other crate includes its own. The QEMU firmware,
//! the C API's default build and the tests use it; your firmware includes its own.
//!
//! ```
//! use controller_core::demo::{evaluate, weights, CERTIFICATE, NX};
//! assert_eq!(NX, weights::NX);
//! assert!(CERTIFICATE.eps >= CERTIFICATE.f32_allowance);
//! assert!(evaluate(&[0.0; NX]).u[0].is_finite());
//! ```

crate::include_controller!("weights.rs");

/// The same weights as a postcard blob (`weights.bin`, written by `trainer export` next to
/// `weights.rs`); [`crate::blob::decode_for`] with [`CERTIFICATE`] turns it into a controller
/// equal to [`CONTROLLER`] ([`crate::blob::decode`] alone carries no excluded boxes: the blob
/// does not hold them, the certificate does).
pub const WEIGHTS_BLOB: &[u8] = include_bytes!("weights.bin");
