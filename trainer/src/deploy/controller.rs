//! [`Controller`]: the deployed controller of a model file, as a library object — what
//! `trainer eval` (without `--raw`) computes for each state, for programs (the Python
//! package) that evaluate many states without a CSV:
//!
//! ```text
//! u = clamp(κ_NN,f32(proj_X(x as f32)), U ⊕ [−(ε + f32 allowance), ε + f32 allowance]),
//! flags: 1 out of domain, 2 not finite, 4 clamped, 8 in an excluded box
//! ```
//!
//! The model is read as `trainer eval` reads it (the trainer's model file or ONNX), its
//! certificate from a `certificate.json` or the one stored in the model, re-checked against
//! the model's hash and its stored problem; the computation is [`Device`] with the libm
//! tanh, the same object `trainer eval` uses, so the bits are the same.

use super::export::device::Device;
use super::export::{ExportError, ExportModel, Tanh};
use super::onnx::{load_any, ModelFileError};
use crate::certify::file::{read_certificate, Against, CertFileError, CertificateFile};
use crate::certify::Model;
use crate::learn::mlp::Activation;
use crate::problem::{ConfigError, ProblemConfig};
use std::path::{Path, PathBuf};

/// Why a controller could not be built; each names the file at fault.
#[derive(Debug, thiserror::Error)]
pub enum ControllerError {
    /// The model file cannot be read.
    #[error(transparent)]
    Model(#[from] ModelFileError),
    /// The problem file stored in the model is invalid.
    #[error(transparent)]
    Problem(#[from] ConfigError),
    /// The certificate is missing, unreadable or not about this model and problem.
    #[error(transparent)]
    Certificate(#[from] CertFileError),
    /// The model holds no certificate and none was given.
    #[error("{0}: the model holds no certificate: pass the certificate.json of this model")]
    NoCertificate(PathBuf),
    /// The network is not one controller-core runs (not tanh, or invalid for export).
    #[error("{path}: {source}")]
    Export {
        /// The model file.
        path: PathBuf,
        /// What the export check found.
        source: ExportError,
    },
    /// The certificate's vectors do not fit the network's dimensions.
    #[error("{origin}: `{key}` has {len} entries, but {model} maps {nx} states to {nu} inputs")]
    Dimensions {
        /// The certificate (file, or "the certificate stored in <model>").
        origin: String,
        /// The key of the certificate at fault.
        key: &'static str,
        /// Its length.
        len: usize,
        /// The model file.
        model: String,
        /// The network's state dimension.
        nx: usize,
        /// The network's input dimension.
        nu: usize,
    },
}

/// The controller the exported model runs on the device (module doc): the state in, u and
/// the flags out.
#[derive(Debug, Clone)]
pub struct Controller {
    dev: Device,
    nx: usize,
    nu: usize,
}

impl Controller {
    /// The controller of the model at `model` (trainer model file or ONNX) under the
    /// certificate at `certificate`, or the one stored in the model when `None` — read and
    /// re-checked as `trainer eval` reads it (a certificate without its checksum is refused).
    pub fn load(model: &Path, certificate: Option<&Path>) -> Result<Self, ControllerError> {
        let (m, _) = load_any(model)?;
        let problem = stored_problem(model, &m)?;
        let export_err = |source| ControllerError::Export {
            path: model.into(),
            source,
        };
        if m.mlp.activation != Activation::Tanh {
            return Err(export_err(ExportError::Invalid(format!(
                "a {:?} network — controller-core runs tanh networks only",
                m.mlp.activation
            ))));
        }
        let model_hash = m.content_hash();
        let against = Against {
            model_hash: Some(&model_hash),
            problem: problem.as_ref(),
            dataset_hash: None,
            cells_csv: None,
        };
        let (file, origin) = match certificate {
            Some(p) => (
                read_certificate(p, false, &against)?.0,
                p.display().to_string(),
            ),
            None => {
                let stored = m
                    .certificate
                    .clone()
                    .ok_or_else(|| ControllerError::NoCertificate(model.into()))?;
                let origin = format!("the certificate stored in {}", model.display());
                let file = CertificateFile::theorem1(stored);
                file.recheck_against(&origin, &against)?;
                (file, origin)
            }
        };
        let (nx, nu) = (m.mlp.nx(), m.mlp.nu());
        let c = &file.base;
        for (key, len, want) in [
            ("domain_lo", c.domain_lo.len(), nx),
            ("domain_hi", c.domain_hi.len(), nx),
            ("u_lo", c.u_lo.len(), nu),
            ("u_hi", c.u_hi.len(), nu),
            ("clamp_lo", c.clamp_lo.len(), nu),
            ("clamp_hi", c.clamp_hi.len(), nu),
        ] {
            if len != want {
                return Err(ControllerError::Dimensions {
                    origin,
                    key,
                    len,
                    model: model.display().to_string(),
                    nx,
                    nu,
                });
            }
        }
        let mut em = ExportModel::from_trained("eval", &m, c).map_err(export_err)?;
        em.excluded = file
            .local
            .as_ref()
            .and_then(|l| l.excluded.as_ref())
            .map_or_else(Vec::new, |e| e.boxes.clone());
        let dev = Device::new(&em, Tanh::Libm).map_err(export_err)?;
        Ok(Controller { dev, nx, nu })
    }

    /// The state dimension n_x.
    pub fn nx(&self) -> usize {
        self.nx
    }

    /// The input dimension n_u.
    pub fn nu(&self) -> usize {
        self.nu
    }

    /// u (f32, n_u entries) and the flags for the state `x` (n_x entries, rounded to f32 as
    /// the device receives it) — `trainer eval`'s row for `x`.
    pub fn evaluate(&self, x: &[f64]) -> (Vec<f32>, u8) {
        let xf: Vec<f32> = x.iter().map(|v| *v as f32).collect();
        self.dev.evaluate(&xf)
    }
}

/// The problem a model names: its stored problem file, else the embedded pendulum when the
/// model's problem hash is the pendulum's, else none (as `trainer eval` without `--config`).
fn stored_problem(path: &Path, m: &Model) -> Result<Option<ProblemConfig>, ConfigError> {
    if let Some(t) = &m.problem_toml {
        let origin = format!("{} (its stored problem file)", path.display());
        return ProblemConfig::from_stored_toml(t, &origin).map(Some);
    }
    let pendulum = ProblemConfig::default();
    Ok((m.problem_hash == pendulum.problem_hash()).then_some(pendulum))
}
