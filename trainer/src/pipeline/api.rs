//! The library's stage functions — what a program calls instead of the CLI: each is the
//! computation of the `trainer` subcommand and of `trainer run`'s stage of the same name,
//! without run directories or manifests.
//!
//! ```text
//! D  = sample(P, path)          κ(x_i) and ∂κ/∂x(x_i) on P's sampling plan (SQP + KKT), saved
//! κ_NN = train(P, D, V, nominal) min λ₁·MSE + λ₂·‖∂κ_NN/∂x − ∂κ/∂x‖² + λ₃·Σ‖W_j‖² (V: validation)
//! C  = certify(P, κ_NN, D, V)   ε = ε_D + (L_MPC + L_NN)·r (Theorem 1) + the f32 allowance
//! export(P, κ_NN, C, rs, bin)   weights.rs + weights.bin for controller-core, C's tier
//! ```
//!
//! `trainer::run` (the whole pipeline with its files) and the modules stay available for
//! everything else; these four are re-exported at the crate root.

use crate::certify::certificate::{CertifyOptions, MismatchError};
use crate::certify::file::CertificateFile;
use crate::certify::Model;
use crate::data::dataset::{generate, Dataset, DatasetError, GenerateOptions};
use crate::deploy::export::{
    certify_deployed, export_files, ExportError, ExportModel, ExportReport,
};
use crate::learn::setpoint::{Hold, HoldError};
use crate::learn::train::{TrainOptions, TrainSet};
use crate::problem::ProblemConfig;
use std::path::Path;

/// What can go wrong in a stage function; each names its cause.
#[derive(Debug, thiserror::Error)]
pub enum ApiError {
    /// The dataset has no labelled state to train on.
    #[error("the dataset has no labelled points (every state failed or was infeasible)")]
    EmptyDataset,
    /// Labelling or reading a dataset failed.
    #[error(transparent)]
    Dataset(#[from] DatasetError),
    /// The setpoint to hold could not be solved (`training.hold_setpoint`).
    #[error(transparent)]
    Hold(#[from] HoldError),
    /// Model, dataset and problem do not belong together.
    #[error(transparent)]
    Mismatch(#[from] MismatchError),
    /// The net cannot be exported for controller-core.
    #[error(transparent)]
    Export(#[from] ExportError),
    /// A sequence net cannot be trained on the dataset.
    #[error(transparent)]
    Sequence(#[from] crate::learn::sequence::SequenceError),
}

/// Labels `cfg`'s sampling plan with the MPC (κ and ∂κ/∂x per state; the status of every
/// solve) and saves the dataset at `out` — `trainer sample`.
pub fn sample(cfg: &ProblemConfig, out: &Path) -> Result<Dataset, ApiError> {
    Ok(generate(cfg, out, &GenerateOptions::default())?)
}

/// Trains the regularized net (`nominal`: λ₂ = λ₃ = 0) on `data`, with `validation` for its
/// statistics, from `cfg`'s `[training]` — the net `trainer train` writes.
pub fn train(
    cfg: &ProblemConfig,
    data: &Dataset,
    validation: &Dataset,
    nominal: bool,
) -> Result<Model, ApiError> {
    let (set, vset) = (
        TrainSet::from_dataset(data),
        TrainSet::from_dataset(validation),
    );
    if set.is_empty() {
        return Err(ApiError::EmptyDataset);
    }
    let hold = Hold::if_enabled(cfg, cfg.training.hold_setpoint)?;
    if cfg.keeps_sequences() {
        let opts = TrainOptions {
            nominal,
            progress: None,
            hold,
            keep_best: None,
        };
        let dh = crate::io::sha256_hex(&data.to_bytes());
        let names = ("dataset", "validation dataset");
        let mut m: Model = crate::learn::sequence::train_sequence(
            cfg,
            &opts,
            data,
            validation,
            names,
            &data.header.problem_hash,
            &dh,
        )?;
        m.problem_toml = cfg.to_toml_string().ok();
        return Ok(m);
    }
    let mut m: Model = crate::learn::train::train(
        &cfg.training,
        &TrainOptions {
            nominal,
            progress: None,
            hold,
            keep_best: None,
        },
        &set,
        &vset,
        (&cfg.domain.lo, &cfg.domain.hi),
        (&cfg.ocp.u_lo, &cfg.ocp.u_hi),
        &data.header.problem_hash,
        &crate::io::sha256_hex(&data.to_bytes()),
    );
    m.problem_toml = cfg.to_toml_string().ok();
    Ok(m)
}

/// Theorem 1's certificate of `model` on `data` (L_MPC estimated from `data` and, when
/// given, `validation`), with the deployed controller's f32 allowance — the
/// `certificate.json` `trainer certify` writes ([`crate::certify::file::write_certificate`]
/// saves it).
pub fn certify(
    cfg: &ProblemConfig,
    model: &Model,
    data: &Dataset,
    validation: Option<&Dataset>,
) -> Result<CertificateFile, ApiError> {
    let opts = CertifyOptions {
        extra: validation.map(TrainSet::from_dataset),
        ..Default::default()
    };
    let (c, _) = certify_deployed(&cfg.name, model, data, cfg, &opts)?;
    Ok(CertificateFile::theorem1(c))
}

/// Writes `model` with `cert` for controller-core — `weights.rs` at `rust` and the blob at
/// `postcard`, one transaction — with the certificate's tier and what it rests on; returns
/// the f32 analysis. `trainer export --rust … --postcard …`.
pub fn export(
    cfg: &ProblemConfig,
    model: &Model,
    cert: &CertificateFile,
    rust: &Path,
    postcard: &Path,
) -> Result<ExportReport, ApiError> {
    let em = ExportModel::from_trained(&cfg.name, model, &cert.base)?
        .with_certificate_guarantee(&cert.guarantee);
    Ok(export_files(&em, rust, postcard)?)
}
