//! `trainer`: from a control problem to a certified neural-network controller.
//!
//! Data flows one way: `config` → `model` → `ocp` → `sqp` (+ `qp`, `kkt`) → `sensitivity`
//! → `mpc` (the labelled law κ, ∂κ/∂x) → `dataset` (sampling, labelling, files, shards).
#![deny(missing_docs)]
// Numerical kernels index several arrays with one loop variable; explicit indices read
// closer to the equations than zipped iterators.
#![allow(clippy::needless_range_loop)]

pub mod certificate;
pub mod closed_loop;
pub mod config;
pub mod dataset;
pub mod export;
#[cfg(test)]
mod fixtures;
pub mod kkt;
pub mod lipschitz;
pub mod local;
pub mod mlp;
pub mod model;
pub mod mpc;
pub mod netbounds;
pub mod ocp;
pub mod pipeline;
pub mod plots;
pub mod qp;
pub mod refine;
pub mod report;
pub mod robust;
pub mod sampling;
pub mod sensitivity;
pub mod sqp;
pub mod train;
#[cfg(test)]
mod verification;
