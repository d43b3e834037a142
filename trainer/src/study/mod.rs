//! Stage 8 — what the controller does and how it is reported.
//!
//! - [`closed_loop`]: x_{t+1} = F(x_t, κ_NN(x_t)) against the MPC, with noise, model
//!   mismatch and input disturbances; violations, divergence, cost.
//! - [`plots`]: the figures (trajectories, error box plots, the error map, training curves,
//!   the local-certificate map), SVG and PNG.
//! - [`report`]: the run report in Markdown and self-contained HTML.
//! - [`safety`]: the safety study (`[closed_loop] safety = true`): the safety-augmented
//!   controller, the plain network and the MPC in ≥ 10⁴ closed loops from i.i.d. starts.
//! - [`statistical_loop`]: the Clopper–Pearson bound on P(a closed-loop trajectory from a
//!   uniform random x₀ violates a constraint).
//!
//! Imports every earlier stage; nothing but `pipeline` and `cli` imports it.

pub mod closed_loop;
pub mod plots;
pub mod report;
pub(crate) mod robust;
pub mod safety;
pub mod safety_diagnosis;
pub mod scenarios;
pub(crate) mod seeds;
pub mod statistical_loop;
