//! `controller-core`: fixed-size f32 inference of a certified approximate MPC law.
//!
//! `no_std`, no allocation, no `unsafe`, no panic path in [`Controller::evaluate`]
//! (checked mechanically: `#[no_panic]` on a release host build with the `no-panic`
//! feature, and a call-graph check of the firmware ELF — see the README).
//!
//! - [`layer`]: `Dense<I, O>`, one affine layer, fixed operation order.
//! - [`activation`]: the device tanh (its own accurate tanh, or `fast-tanh`) and its error
//!   bound.
//! - [`mlp`]: the network as a chain of layers whose sizes the compiler checks.
//! - [`controller`]: `evaluate`: domain projection, forward pass, clamp, flags.
//! - [`certificate`]: the certificate's numbers.
//! - [`blob`]: the postcard weight format and its validating decoder.
//! - [`safe`]: the safety-augmented controller: a sequence network's candidate, checked
//!   online with the nominal model against the shifted safe sequence ([`SafeController`]).
//! - [`demo`]: the paper's pendulum, compiled in as an example controller (`trainer export`);
//!   not re-exported at the root: a firmware names the controller it runs.
//! - [`include_controller!`]: the same for a crate's own exported controller (no fork of
//!   this crate); [`demo`] includes the paper's pendulum with it.
//! - [`include_safe_controller!`]: a crate's own safety-augmented controller (`trainer
//!   export --safe-rs`: plant, sequence net and [`SafeController`] in one file).
//!
//! ```
//! use controller_core::{demo::CONTROLLER, Flags};
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
pub mod demo;
pub mod layer;
pub mod mlp;
pub mod safe;

pub use certificate::{Certificate, Guarantee};
pub use controller::{Controller, Flags, InvalidController, Output};
pub use safe::{
    CandidateForm, Margins, Plant, SafeController, SafeFlags, SafeOutput, SequenceNet,
    SequenceSource,
};

/// Version of the weight/certificate format this core understands.
pub const FORMAT_VERSION: u16 = 1;

/// Whether this build runs the rational tanh (feature `fast-tanh`): selects the certificate
/// [`include_controller!`] uses (evaluated in this crate, so it follows this crate's feature).
pub const FAST_TANH: bool = cfg!(feature = "fast-tanh");

/// Compiles a controller exported by `trainer export` into the calling crate: no fork of
/// this repository, the same checks as the compiled-in one.
///
/// `include_controller!("weights.rs")` (path relative to the invoking file, as `include!`)
/// expands, in the current module, to
/// - `mod weights`: the generated file (its `NX`, `NU`, `Net`, `NET`, `X_LO`, `X_HI`,
///   `CERTIFICATE_LIBM`, `CERTIFICATE_FAST`);
/// - `NX`, `NU`, `CERTIFICATE` (the one for this build's tanh, see [`FAST_TANH`]),
///   `CONTROLLER` and `fn evaluate(&[f32; NX]) -> Output<NU>`.
///
/// Compile-time checks, as for the compiled-in pendulum: layer sizes chain (type of `Net`),
/// the certificate's dimensions are the network's, and [`Controller::validate`] passes
/// (a `const` assertion: a broken file does not compile). `evaluate` is
/// [`Controller::evaluate`], so the `no-panic` feature covers it. Invoke it once per module
/// (wrap several controllers in their own `mod`).
///
/// (Not a doctest: the path is the user crate's file; `tests/own_weights.rs` builds such a
/// crate.)
///
/// ```text
/// mod pendulum {
///     controller_core::include_controller!("weights.rs");
/// }
/// let out = pendulum::evaluate(&[0.1, 0.0]);
/// assert_eq!(pendulum::CERTIFICATE.guarantee, controller_core::Guarantee::Estimated);
/// ```
#[macro_export]
macro_rules! include_controller {
    ($path:expr) => {
        /// The controller written by `trainer export` (see the header of its file).
        #[allow(
            clippy::approx_constant,
            clippy::excessive_precision,
            clippy::unreadable_literal,
            unused_imports
        )]
        pub mod weights {
            use $crate::certificate::{Certificate, Guarantee};
            use $crate::layer::Dense;
            use $crate::mlp::Hidden;
            include!($path);
        }

        /// State dimension of this controller.
        pub const NX: usize = weights::NX;
        /// Input dimension of this controller.
        pub const NU: usize = weights::NU;

        /// The certificate of this build (for its tanh: the default, label `libm`, or fast
        /// with `fast-tanh`).
        pub const CERTIFICATE: $crate::Certificate<NX, NU> = if $crate::FAST_TANH {
            weights::CERTIFICATE_FAST
        } else {
            weights::CERTIFICATE_LIBM
        };

        /// The controller (weights in flash), with this build's clamp band.
        pub const CONTROLLER: $crate::Controller<NX, NU, weights::Net> = $crate::Controller::new(
            weights::NET,
            weights::X_LO,
            weights::X_HI,
            CERTIFICATE.clamp_lo,
            CERTIFICATE.clamp_hi,
            CERTIFICATE.fallback,
        )
        .with_excluded(CERTIFICATE.excluded);

        // The invariants `evaluate` relies on, checked at compile time.
        const _: () = assert!(
            CONTROLLER.validate().is_ok(),
            "invalid controller file: a non-finite bound, an empty box or a fallback outside \
             the clamp band (Controller::validate)"
        );

        /// `CONTROLLER.evaluate(x)`: never panics, `u` finite and inside the clamp band.
        #[inline]
        pub fn evaluate(x: &[f32; NX]) -> $crate::Output<NU> {
            CONTROLLER.evaluate(x)
        }
    };
}

/// Compiles a safety-augmented controller exported by `trainer export --safe-rs FILE` into
/// the calling crate (no fork of this repository).
///
/// `include_safe_controller!("pendulum_safe.rs")` (path relative to the invoking file, as
/// `include!`) expands, in the current module, to `pub mod safe` holding the generated
/// file: `safe::plant` (the problem's f32 plant, OCP and terminal ingredients,
/// `safe::plant::SafePlant`, `safe::plant::MARGINS`), `safe::sequence` (the sequence net),
/// `safe::N`, `safe::NX`, `safe::NU`, `safe::GUARANTEE`, the type `safe::Controller` =
/// [`SafeController`]`<SafePlant, SequenceNet<&'static Net>, NX, NU, N>` and the constant
/// `safe::CONTROLLER` (no safe sequence yet; the weights stay in flash, the controller itself
/// is the last sequence, N·NU floats). The file names this crate as `controller_core`: the
/// calling crate depends on it under that name. A margin that is not finite and ≥ 0 fails
/// to compile ([`SafeController::validate`] in a `const` assertion).
///
/// (Not a doctest: the path is the user crate's file; `tests/safe_controller.rs` compiles
/// the committed fixtures the same way.)
///
/// ```text
/// controller_core::include_safe_controller!("pendulum_safe.rs");
/// let mut ctl = safe::CONTROLLER;
/// let out = ctl.step(&[0.1, 0.0]);   // out.u, out.flags (SafeFlags)
/// ```
#[macro_export]
macro_rules! include_safe_controller {
    ($path:expr) => {
        /// The safety-augmented controller written by `trainer export --safe-rs` (see the
        /// header of its file).
        #[allow(
            clippy::all,
            clippy::approx_constant,
            clippy::excessive_precision,
            clippy::unreadable_literal,
            dead_code,
            unused_imports,
            unused_parens
        )]
        pub mod safe {
            include!($path);
        }
    };
}
