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
//!
//! ## The facade
//!
//! The crate root re-exports what a program needs: the problem ([`ProblemConfig`], custom
//! plants through [`Dynamics`]), the data and model types ([`Dataset`], [`Model`],
//! [`CertificateFile`]), the stage functions [`sample`], [`train`], [`certify`] and
//! [`export`] (the computations of the subcommands of the same names, `pipeline::api`),
//! and [`run`] (the whole pipeline with its run directory, as `trainer run`); [`Controller`]
//! is the exported controller of a model file, state by state as `trainer eval` computes
//! it. From a problem file's text to a certificate and the device's weights:
//!
//! ```
//! let text = r#"
//! name = "di_doctest"
//! [system]
//! kind = "double_integrator"
//! [ocp]
//! ts = 0.1
//! horizon = 10
//! q = [1.0, 0.1]
//! r = [0.1]
//! p = [1.0, 0.1]
//! x_lo = [-5.0, -1.0]
//! x_hi = [5.0, 1.0]
//! u_lo = [-1.0]
//! u_hi = [1.0]
//! [domain]
//! lo = [-2.0, -1.0]
//! hi = [2.0, 1.0]
//! [sampling]
//! sampler = "grid"
//! counts = [9, 5]
//! [training]
//! hidden = [8]
//! epochs = 60
//! validation_n = 20
//! "#;
//! let cfg = trainer::ProblemConfig::from_toml_str(text, "the doctest's problem")?;
//! let dir = std::env::temp_dir().join(format!("ampc-facade-{}", std::process::id()));
//! std::fs::create_dir_all(&dir)?;
//! let data = trainer::sample(&cfg, &dir.join("dataset.bin"))?;
//! let model = trainer::train(&cfg, &data, &data, false)?;
//! let cert = trainer::certify(&cfg, &model, &data, None)?;
//! // Theorem 1: ε bounds the error at every state of X, so at the data's too.
//! assert!(cert.base.eps >= model.train_stats.max);
//! println!("ε = {:.3} ({})", cert.base.eps, cert.tier().name());
//! trainer::export(&cfg, &model, &cert, &dir.join("weights.rs"), &dir.join("weights.bin"))?;
//! assert!(std::fs::read_to_string(dir.join("weights.rs"))?.contains("pub const NX: usize = 2;"));
//! std::fs::remove_dir_all(&dir)?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
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

pub use certify::certificate::Certificate;
pub use certify::file::CertificateFile;
pub use certify::Model;
pub use data::dataset::Dataset;
pub use deploy::controller::{Controller, ControllerError};
pub use deploy::export::ExportReport;
pub use mpc::law::MpcLaw;
pub use pipeline::api::{certify, export, sample, train, ApiError};
pub use pipeline::{run, run_problem, RunOptions, Stage, StageReport};
pub use problem::model::{CustomPlant, DualNum, Dynamics};
pub use problem::ProblemConfig;
