//! The MPC law checked against independent computations (tests only), one file per
//! subject, with the fixtures they share:
//! - `cross_checks`: ∂κ/∂x against finite differences of the converged solver, the double
//!   integrator's gain against its condensed QP, first-order optimality recomputed from
//!   scratch, infeasibility proofs;
//! - `constraint_checks`: the `[ocp]` path and terminal constraints;
//! - `finite_checks`: the label gate on plants whose arithmetic is not finite;
//! - `plant_checks`: plants written as expressions against the built-in ones;
//! - `public_plants`: the problem files of plants from public sources against their
//!   sources' equations;
//! - `setpoint_tests`: the setpoint cost and the law at an equilibrium setpoint;
//! - `ipopt_labels`: the pendulum's IPOPT reference labels.
//!
//! Fixtures: [`load`] reads a problem file of `configs/`; [`point`] is the seeded point
//! `lo + (hi − lo)·uniform(seed, i, j)` of a box, [`random_state`] that point of X.

use crate::problem::ProblemConfig;
use crate::rng::uniform;

mod constraint_checks;
mod cross_checks;
pub(crate) mod finite_checks;
pub(crate) mod ipopt_labels;
mod plant_checks;
mod public_plants;
mod setpoint_tests;

/// The problem file `configs/<name>`; panics naming the error (a test fixture).
pub(super) fn load(name: &str) -> ProblemConfig {
    let path =
        std::path::PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/")).join(name);
    ProblemConfig::load(&path).unwrap_or_else(|e| panic!("{e}"))
}

/// A point of the box [lo, hi]: coordinate j is `lo_j + (hi_j − lo_j)·uniform(seed, i, j)`.
pub(super) fn point(seed: u64, i: u64, lo: &[f64], hi: &[f64]) -> Vec<f64> {
    lo.iter()
        .zip(hi)
        .enumerate()
        .map(|(j, (l, h))| l + (h - l) * uniform(seed, i, j as u64))
        .collect()
}

/// The seeded point `i` of the problem's domain X ([`point`] of X's box).
pub(super) fn random_state(cfg: &ProblemConfig, seed: u64, i: u64) -> Vec<f64> {
    point(seed, i, &cfg.domain.lo, &cfg.domain.hi)
}
