//! `controller-core`: fixed-size f32 inference of a certified approximate MPC law.
//!
//! `no_std`, no allocation, no `unsafe`, no panic path in [`Controller::evaluate`]
//! (checked mechanically: `#[no_panic]` on a release host build with the `no-panic`
//! feature, and a call-graph check of the firmware ELF — see the README).
//!
//! - [`layer`]: `Dense<I, O>`, one affine layer, fixed operation order.
//! - [`activation`]: the device tanh (libm `tanhf`, or `fast-tanh`) and its error bound.
//! - [`mlp`]: the network as a chain of layers whose sizes the compiler checks.
//! - [`controller`]: `evaluate`: domain projection, forward pass, clamp, flags.
//! - [`certificate`]: the certificate's numbers.
//! - [`blob`]: the postcard weight format and its validating decoder.
//! - [`generated::weights`]: the compiled-in weights and certificates (`trainer export`).
//!
//! ```
//! use controller_core::{CONTROLLER, Flags};
//! let out = CONTROLLER.evaluate(&[-3.0, 0.0]);
//! assert!(out.u[0].is_finite());
//! assert!(!out.flags.contains(Flags::NON_FINITE));
//! ```
#![cfg_attr(not(test), no_std)]
#![deny(missing_docs, unsafe_code)]

pub mod activation;
pub mod blob;
pub mod certificate;
pub mod controller;
pub mod generated;
pub mod layer;
pub mod mlp;

pub use certificate::Certificate;
pub use controller::{Controller, Flags, InvalidController, Output};

use generated::weights;

/// Version of the weight/certificate format this core understands.
pub const FORMAT_VERSION: u16 = 1;

/// State dimension of the compiled-in controller.
pub const NX: usize = weights::NX;
/// Input dimension of the compiled-in controller.
pub const NU: usize = weights::NU;

/// The certificate of this build (for its tanh: libm, or fast with `fast-tanh`).
pub const CERTIFICATE: Certificate<NX, NU> = if cfg!(feature = "fast-tanh") {
    weights::CERTIFICATE_FAST
} else {
    weights::CERTIFICATE_LIBM
};

/// The compiled-in controller (weights in flash), with this build's clamp band.
pub const CONTROLLER: Controller<NX, NU, weights::Net> = Controller::new(
    weights::NET,
    weights::X_LO,
    weights::X_HI,
    CERTIFICATE.clamp_lo,
    CERTIFICATE.clamp_hi,
    CERTIFICATE.fallback,
);

// The invariants `evaluate` relies on, checked at compile time.
const _: () = assert!(CONTROLLER.validate().is_ok());

/// The same weights as a postcard blob (`generated/weights.bin`, written by `trainer export`
/// next to `weights.rs`); [`blob::decode`] turns it into a controller equal to [`CONTROLLER`].
pub const WEIGHTS_BLOB: &[u8] = include_bytes!("generated/weights.bin");

/// `CONTROLLER.evaluate(x)`.
///
/// ```
/// let u = controller_core::evaluate(&[0.0, 0.0]).u;
/// assert!(u[0].is_finite());
/// ```
#[inline]
pub fn evaluate(x: &[f32; NX]) -> Output<NU> {
    CONTROLLER.evaluate(x)
}
