//! ONNX out and in: the certified net as an ONNX model with its certificate in the metadata,
//! and a dense MLP trained elsewhere read from an ONNX file as a [`Model`].
//!
//! ```text
//! out:  u = Clip_band(W_L' α(… α(W_1' Clip_X(x) + b_1') …) + b_L')   (f32, as the device)
//! in:   κ_NN(x) = o + s ∘ (W_L α(… α(W_1 ((x − c) ⊘ h) + b_1) …) + b_L)   (f64)
//! ```
//! A model file is recognised by content: the trainer's own model files start with the magic
//! `AMPCMODL`; anything else is decoded as an ONNX `ModelProto`. The imported model's
//! [`Model::content_hash`] is the SHA-256 of the ONNX file's bytes, so its certificate is
//! bound to that very file.
//!
//! **Wire format.** Hand-written (`proto`): the exporter needs eight messages and the
//! importer the same fields; a generated-code crate (`prost` needs `protoc` at build time,
//! `protobuf`/`onnx-protobuf` bring a runtime and a generated ONNX schema of thousands of
//! lines) is more code than the format. The tests check the exporter against an
//! independent ONNX runtime (`tract-onnx`, in `tests/`), so reader and writer do not only
//! agree with each other.
//!
//! Files: `proto` (wire encoding), `graph` (ModelProto → [`graph::OnnxModel`]), `clips`
//! (opset, unique names, and the Clip nodes of an ampc export checked against its metadata),
//! `import` (graph → [`crate::learn::mlp::Mlp`], unsupported nodes named), `write` (the
//! export).

pub(crate) mod clips;
pub mod graph;
pub(crate) mod import;
pub mod proto;
#[cfg(test)]
mod tamper_tests;
#[cfg(test)]
mod tests;
pub mod write;

use crate::certify::Model;
use crate::learn::train::{ErrorStats, Kind, TrainedModel, MODEL_MAGIC, MODEL_VERSION};
use std::path::{Path, PathBuf};

pub use import::ImportNotes;
pub use write::{metadata, render_onnx};

/// Why a model file could not be read.
#[derive(Debug, thiserror::Error)]
pub enum ModelFileError {
    /// The file could not be read.
    #[error("cannot read {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// A trainer model file that does not decode.
    #[error(transparent)]
    Model(#[from] crate::data::dataset::DatasetError),
    /// Neither a model file nor an ONNX model.
    #[error("{path}: neither a trainer model file (magic AMPCMODL) nor an ONNX model ({source})")]
    Unrecognised {
        /// The file.
        path: String,
        /// Why it is not ONNX.
        source: graph::GraphError,
    },
    /// An ONNX model that is not a supported dense MLP (the message names the node).
    #[error("{path}: ONNX model not supported: {reason}")]
    Unsupported {
        /// The file.
        path: String,
        /// The node and what is wrong.
        reason: String,
    },
}

/// The network of an ONNX file as a model (`origin` names it in errors).
pub fn import_bytes(bytes: &[u8], origin: &str) -> Result<(Model, ImportNotes), ModelFileError> {
    let g = graph::decode(bytes).map_err(|source| ModelFileError::Unrecognised {
        path: origin.to_string(),
        source,
    })?;
    let (mlp, notes) = import::to_mlp(&g).map_err(|reason| ModelFileError::Unsupported {
        path: origin.to_string(),
        reason,
    })?;
    let mut settings = crate::problem::TrainSettings {
        activation: mlp.activation,
        ..Default::default()
    };
    settings.hidden = mlp.widths()[1..mlp.layers.len()].to_vec();
    let model = TrainedModel {
        magic: MODEL_MAGIC,
        version: MODEL_VERSION,
        mlp,
        kind: Kind::Imported,
        lambda: crate::learn::mlp::LossWeights {
            value: 0.0,
            jacobian: 0.0,
            weights: 0.0,
        },
        settings,
        problem_hash: String::new(),
        dataset_hash: String::new(),
        epochs_run: 0,
        train_stats: ErrorStats::default(),
        validation_stats: ErrorStats::default(),
        history: Vec::new(),
        certificate: None,
        source_hash: Some(crate::io::sha256_hex(bytes)),
        problem_toml: None,
        sequence: None,
    };
    Ok((model, notes))
}

/// A model from a file: the trainer's own model file (by its magic) or an ONNX file.
pub fn load_any(path: &Path) -> Result<(Model, Option<ImportNotes>), ModelFileError> {
    let bytes = std::fs::read(path).map_err(|source| ModelFileError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let origin = path.display().to_string();
    // Every ampc artifact starts with `AMPC`: another kind (a dataset, a checkpoint, a
    // blob) given as a model gets the model reader's "not an ampc model" error, not an
    // ONNX parse error.
    if bytes.starts_with(&MODEL_MAGIC) || bytes.starts_with(b"AMPC") {
        return Ok((Model::from_bytes(&bytes, &origin)?, None));
    }
    let (m, notes) = import_bytes(&bytes, &origin)?;
    Ok((m, Some(notes)))
}
