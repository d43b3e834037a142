//! `trainer`: from a control problem to a certified neural-network controller.
//!
//! The folders are the pipeline, in the order data flows; a module imports only modules
//! above it in this list (checked by `tests/layout.rs`; see `ARCHITECTURE.md`):
//!
//! ```text
//! io, rng     leaves: atomic writes, checked file envelopes, hashes; keyed random numbers
//! problem     the problem file: system and plant models, OCP, domain X, every stage's settings
//! robust      the tube for a design ε: tightened bounds X_k, U_k (Corollary 1) — a new problem
//! mpc         κ(x) = u₀*(x) and ∂κ/∂x: OCP, SQP, QP (structured IPM, Clarabel), KKT, sensitivity
//! data        D = {x_i, κ(x_i), ∂κ/∂x(x_i)}: sampling plans, labelling, dataset files, shards
//! learn       κ_NN: the MLP and its Sobolev training λ₁·MSE + λ₂·Jacobian + λ₃·Σ‖W‖²
//! certify     ε = ε_D + (L_MPC + L_NN)·δ (Theorem 1), network enclosures, local cells, refinement
//! deploy      the net as the device computes it: f32 allowance, weights.rs, the postcard blob
//! study       closed loop, seed and robust studies, figures, the report
//! pipeline    `trainer run`: the stages as a list, manifests, skip-if-unchanged, the robust loop
//! ```
//!
//! The binary adds `cli/` (one file per subcommand) on top of all of these.
#![deny(missing_docs)]
// Numerical kernels index several arrays with one loop variable; explicit indices read
// closer to the equations than zipped iterators.
#![allow(clippy::needless_range_loop)]

pub mod io;
pub mod rng;

pub mod problem;

pub mod robust;

pub mod mpc;

pub mod data;

pub mod learn;

pub mod certify;

pub mod deploy;

pub mod study;

pub mod pipeline;
