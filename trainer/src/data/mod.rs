//! Stage 3 — labelled data: D = {(x_i, κ(x_i), ∂κ/∂x(x_i))}, i = 1..N, over the box X.
//!
//! - [`sampling`]: the sampling plans (grid, random, Halton), each point a pure function of
//!   its index.
//! - [`dataset`]: labelling a plan with the MPC law (parallel, resumable, sharded), the
//!   dataset file, its CSV and the merge of shards.
//! - [`import`]: a dataset from another solver's CSV, checked and re-solved in part.
//! - [`unlabelled`]: where a dataset's states have no label (the feasibility pre-scan).
//!
//! Imports `problem` and `mpc`.

pub mod dataset;
pub mod import;
pub mod sampling;
pub mod states;
pub mod unlabelled;
