//! `export`: a trained network → `controller-core`'s generated Rust file and postcard blob,
//! with the certificate's f32 allowance.
//!
//! **Model.** [`ExportModel`] is a neutral description in physical units:
//! κ_NN,f64(x) = m_u + s_u ∘ (W_L tanh(… tanh(W_1 ((x − m_x) ⊘ s_x) + b_1) …) + b_L),
//! layers `w` stored out × in. The learning side converts its trained model into it.
//!
//! **Folding.** Both scalings are folded into the first and last layer (in f64):
//! W_1' = W_1 diag(1/s_x), b_1' = b_1 − W_1' m_x, W_L' = diag(s_u) W_L, b_L' = s_u ∘ b_L + m_u,
//! then rounded to f32 (nearest). The device runs `controller-core`'s `Dense::apply` (order:
//! bias, then `+ w·x` per input in order, no FMA) and its tanh.
//!
//! **f32 allowance**: the bound on |κ_NN,f32(x) − κ_NN,f64(x)| for x ∈ X, by forward error
//! analysis with interval arithmetic on sub-boxes of X (see `allowance`).
//!
//! **Clamp band** `(U_d ⊕ [−ε_j, ε_j]) ∩ [act_lo, act_hi]` per input j, ε_j = s_u,j·(eps +
//! allowance) (both in the certificate's norm ‖S_u⁻¹Δu‖₂, `u_scale`; s_u,j = 1 unscaled: the
//! physical per-input bound), rounded to f32
//! so that it contains U_d and lies within the actuator limits. **Domain** rounded outward to
//! f32 (the f32 box contains X, so X's own corners are in domain; a projected state lies at
//! most one f32 step outside X, a box the allowance's interval analysis covers).
//!
//! This file holds the model ([`ExportModel`]: validation, reference evaluation, folding,
//! f32 domain and clamp band), the errors and [`export_files`]; the rest is split by object:
//! - `tanh`: the device tanh implementations and their error bounds ([`Tanh`]);
//! - `allowance`: the f32 error analysis ([`f32_allowance`], [`sampled_max_diff`],
//!   [`certify_f32`]);
//! - `boxes`: the grid of sub-boxes of X the allowance is a maximum over, pruned through
//!   coarse boxes;
//! - `rust`: the generated Rust file ([`render_rust`]);
//! - `device`: the exported controller evaluated as `controller-core` does ([`device::Device`]);
//! - `tested`: that controller as the function the statistical tiers test ([`Deployed`]);
//! - `c_header`: the C header of `controller-core/capi` ([`render_c_header`]; template
//!   `c/ampc.h.in`);
//! - `c_lib`: the C library folder of `--c-lib` ([`render_c_lib`]: `ampc.h`, `ampc.c`,
//!   `Makefile`, `CMakeLists.txt`; templates in `c/`);
//! - `guarantee`: the certificate's tier ([`Guarantee`]);
//! - `blob`: the postcard blob ([`render_postcard`]);
//! - `placeholder`: the untrained stand-in pendulum ([`placeholder_pendulum`]).

mod allowance;
mod blob;
mod boxes;
mod c_header;
mod c_lib;
pub mod device;
mod guarantee;
mod lanes;
mod placeholder;
pub(crate) mod range;
pub(crate) mod rust;
mod tanh;
mod tested;
#[cfg(test)]
mod tests;

use serde::Serialize;
use std::path::{Path, PathBuf};

use crate::io::FileError;
pub use allowance::{certify_f32, eval_f32, f32_allowance, sampled_max_diff, SAMPLES};
use allowance::{f32_down, f32_up};
pub use blob::render_postcard;
pub use c_header::render_c_header;
pub use c_lib::{hex32, link_id, render_c_lib};
pub use guarantee::{
    default_guarantee, rust_name, supported_guarantee, Guarantee, GuaranteeDef, StatisticalClaim,
};
pub use placeholder::placeholder_pendulum;
pub use rust::render_rust;
pub use tanh::Tanh;
pub use tested::{certify_deployed, deployed_allowance, Deployed};

/// One affine layer in f64: `w` is out × in.
#[derive(Clone, Debug, PartialEq, Serialize, serde::Deserialize)]
pub struct DenseF64 {
    /// Weights, one row per output.
    pub w: Vec<Vec<f64>>,
    /// Biases.
    pub b: Vec<f64>,
}

/// An affine scaling `physical = mean + scale ∘ normalised`.
#[derive(Clone, Debug, PartialEq, Serialize, serde::Deserialize)]
pub struct Scaling {
    /// Offset m.
    pub mean: Vec<f64>,
    /// Scale s (nonzero).
    pub scale: Vec<f64>,
}

impl Scaling {
    /// The identity scaling of dimension `n`.
    ///
    /// ```
    /// let s = trainer::deploy::export::Scaling::identity(2);
    /// assert_eq!(s.scale, vec![1.0, 1.0]);
    /// ```
    pub fn identity(n: usize) -> Self {
        Self {
            mean: vec![0.0; n],
            scale: vec![1.0; n],
        }
    }
}

/// A trained network and its certificate numbers, in physical units (see the module doc).
#[derive(Clone, Debug, PartialEq, Serialize, serde::Deserialize)]
pub struct ExportModel {
    /// Short name (problem), used in the generated file's doc.
    pub name: String,
    /// Layers, input to output; tanh between them, linear output.
    pub layers: Vec<DenseF64>,
    /// Input normalisation: x̃ = (x − mean) ⊘ scale.
    pub input: Scaling,
    /// Output un-normalisation: u = mean + scale ∘ ũ.
    pub output: Scaling,
    /// Lower corner of the certified domain X.
    pub domain_lo: Vec<f64>,
    /// Upper corner of X.
    pub domain_hi: Vec<f64>,
    /// Lower input bound U_d the MPC was solved with.
    pub u_lo: Vec<f64>,
    /// Upper input bound U_d.
    pub u_hi: Vec<f64>,
    /// Actuator lower limits (⊆-wise: U_d must lie within the actuator limits).
    pub actuator_lo: Vec<f64>,
    /// Actuator upper limits.
    pub actuator_hi: Vec<f64>,
    /// Input for non-finite states; `None` = centre of U_d.
    pub fallback: Option<Vec<f64>>,
    /// ε for the f64 network (learning side's certificate `eps`).
    pub eps: f64,
    /// ε_D.
    pub eps_d: f64,
    /// Sound upper bound on L_NN.
    pub l_nn: f64,
    /// How L_NN was bounded.
    pub l_nn_method: String,
    /// L_MPC.
    pub l_mpc: f64,
    /// Whether L_MPC is a sampled estimate.
    pub l_mpc_is_estimate: bool,
    /// Covering radius r of the data in X.
    pub covering_radius: f64,
    /// Content hash of the trained model (hex).
    pub hash: String,
    /// True for a stand-in network without a certificate.
    pub placeholder: bool,
    /// Tier of the certificate's claim (default: the weakest, `estimated`).
    #[serde(default = "default_guarantee", with = "GuaranteeDef")]
    pub guarantee: Guarantee,
    /// Set when `eps` is a statistical level ([`ExportModel::with_statistical_eps`]): what
    /// it rests on. `None` for a certificate's ε.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub statistical: Option<StatisticalClaim>,
    /// Boxes (lower, upper corner) of X the certificate excludes (a local certificate's
    /// `local.excluded.boxes`, `refine.exclude_infeasible`): ε holds on X minus them; the
    /// generated controller flags states inside them (`Flags::EXCLUDED`). Usually empty.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub excluded: Vec<(Vec<f64>, Vec<f64>)>,
    /// What ε rests on besides proof (the certificate's `assumptions` and `premises`),
    /// written into every exported file. Empty: nothing but arithmetic.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub rests_on: Vec<String>,
    /// S_u of the certificate's norm (`certificate.json`'s `norm.u_scale`): `eps` bounds
    /// ‖S_u⁻¹(κ − κ_NN)‖₂, so input j's band is U_d,j ⊕ [−s_u,j·ε, s_u,j·ε]; the f32
    /// allowance is stated in the same norm. Empty: the unscaled norm (all 1).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub u_scale: Vec<f64>,
}

/// What can go wrong in an export.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// The model is inconsistent (the message names the field).
    #[error("invalid export model: {0}")]
    Invalid(String),
    /// Writing an output failed.
    #[error("cannot write {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
}

impl From<FileError> for ExportError {
    /// A failed [`crate::io::write_atomic`] (which only fails with [`FileError::Io`]).
    fn from(e: FileError) -> Self {
        use std::io::{Error, ErrorKind::InvalidData};
        let (path, source) = match e {
            FileError::Io { path, source } => (path, source),
            FileError::Format { path, reason } => (path, Error::new(InvalidData, reason)),
            FileError::Decode { path, source } => (path, Error::new(InvalidData, source)),
        };
        ExportError::Io {
            path: path.into(),
            source,
        }
    }
}

/// The outcome of an export: allowances and observed differences, per tanh.
#[derive(Clone, Debug, PartialEq)]
pub struct ExportReport {
    /// Sound bound on |κ_NN,f32 − κ_NN,f64| over X, for [libm, fast].
    pub f32_allowance: [f64; 2],
    /// Largest difference seen on [`SAMPLES`] random states in X, for [libm, fast].
    pub f32_observed: [f64; 2],
    /// Number of random states.
    pub samples: usize,
    /// Sub-boxes of X in the interval analysis.
    pub boxes: usize,
}

/// One folded layer rounded to f32: `(inputs, outputs, w row-major, b)`.
pub type LayerF32 = (usize, usize, Vec<f32>, Vec<f32>);

/// The network with scalings folded in, in f64 and rounded to f32.
#[derive(Clone, Debug, PartialEq)]
pub struct Folded {
    /// Folded layers (f64).
    pub layers: Vec<DenseF64>,
    /// Folded weights rounded to f32: (w row-major, b) per layer, with dims (in, out).
    pub f32_layers: Vec<LayerF32>,
}

fn dims_ok(v: &[f64], n: usize, what: &str) -> Result<(), ExportError> {
    if v.len() != n {
        return Err(ExportError::Invalid(format!(
            "{what}: length {} (expected {n})",
            v.len()
        )));
    }
    if let Some(i) = v.iter().position(|x| !x.is_finite()) {
        return Err(ExportError::Invalid(format!("{what}[{i}] is not finite")));
    }
    Ok(())
}

impl ExportModel {
    /// State dimension.
    pub fn nx(&self) -> usize {
        self.layers
            .first()
            .and_then(|l| l.w.first())
            .map_or(0, Vec::len)
    }

    /// Input dimension.
    pub fn nu(&self) -> usize {
        self.layers.last().map_or(0, |l| l.b.len())
    }

    /// Checks dimensions, finiteness and the boxes.
    pub fn validate(&self) -> Result<(), ExportError> {
        let inv = |m: String| Err(ExportError::Invalid(m));
        if self.layers.is_empty() {
            return inv("layers: empty".into());
        }
        let (nx, nu) = (self.nx(), self.nu());
        if nx == 0 || nu == 0 {
            return inv("layers: zero dimension".into());
        }
        let mut n_in = nx;
        for (k, l) in self.layers.iter().enumerate() {
            if l.w.len() != l.b.len() || l.w.is_empty() {
                return inv(format!(
                    "layers[{k}]: {} rows, {} biases",
                    l.w.len(),
                    l.b.len()
                ));
            }
            for (o, row) in l.w.iter().enumerate() {
                dims_ok(row, n_in, &format!("layers[{k}].w[{o}]"))?;
            }
            dims_ok(&l.b, l.b.len(), &format!("layers[{k}].b"))?;
            n_in = l.b.len();
        }
        dims_ok(&self.input.mean, nx, "input.mean")?;
        dims_ok(&self.input.scale, nx, "input.scale")?;
        dims_ok(&self.output.mean, nu, "output.mean")?;
        dims_ok(&self.output.scale, nu, "output.scale")?;
        if self
            .input
            .scale
            .iter()
            .chain(&self.output.scale)
            .any(|s| *s == 0.0)
        {
            return inv("scaling: zero scale".into());
        }
        for (v, n, w) in [
            (&self.domain_lo, nx, "domain_lo"),
            (&self.domain_hi, nx, "domain_hi"),
            (&self.u_lo, nu, "u_lo"),
            (&self.u_hi, nu, "u_hi"),
            (&self.actuator_lo, nu, "actuator_lo"),
            (&self.actuator_hi, nu, "actuator_hi"),
        ] {
            dims_ok(v, n, w)?;
        }
        for i in 0..nx {
            if self.domain_lo[i] > self.domain_hi[i] {
                return inv(format!("domain_lo[{i}] > domain_hi[{i}]"));
            }
        }
        for j in 0..nu {
            if !(self.actuator_lo[j] <= self.u_lo[j]
                && self.u_lo[j] <= self.u_hi[j]
                && self.u_hi[j] <= self.actuator_hi[j])
            {
                return inv(format!(
                    "u_{j}: need actuator_lo ≤ u_lo ≤ u_hi ≤ actuator_hi"
                ));
            }
        }
        if let Some(f) = &self.fallback {
            dims_ok(f, nu, "fallback")?;
            for j in 0..nu {
                if f[j] < self.actuator_lo[j] || f[j] > self.actuator_hi[j] {
                    return inv(format!("fallback[{j}] outside the actuator limits"));
                }
            }
        }
        if let Some(s) = &self.statistical {
            s.validate()?;
        }
        for (k, (lo, hi)) in self.excluded.iter().enumerate() {
            dims_ok(lo, nx, &format!("excluded[{k}].lo"))?;
            dims_ok(hi, nx, &format!("excluded[{k}].hi"))?;
            let ordered = |i: usize| lo[i].is_finite() && hi[i].is_finite() && lo[i] <= hi[i];
            if !(0..nx).all(ordered) {
                return inv(format!("excluded[{k}]: an empty or non-finite box"));
            }
        }
        let supported = supported_guarantee(self.placeholder, self.statistical.is_some());
        if self.guarantee < supported {
            return inv(format!(
                "guarantee: {} claims more than the exported function supports ({}: ε is a \
                 statistical level or the network is a placeholder)",
                self.guarantee.name(),
                supported.name()
            ));
        }
        for (v, w) in [
            (self.eps, "eps"),
            (self.eps_d, "eps_d"),
            (self.l_nn, "l_nn"),
            (self.l_mpc, "l_mpc"),
            (self.covering_radius, "covering_radius"),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return inv(format!("{w} must be finite and ≥ 0"));
            }
        }
        range::check_model(self)
    }

    /// κ_NN,f64(x): the reference network, scalings applied explicitly.
    pub fn eval_f64(&self, x: &[f64]) -> Vec<f64> {
        let mut h: Vec<f64> = x
            .iter()
            .zip(self.input.mean.iter().zip(&self.input.scale))
            .map(|(x, (m, s))| (x - m) / s)
            .collect();
        let n = self.layers.len();
        for (k, l) in self.layers.iter().enumerate() {
            h =
                l.w.iter()
                    .zip(&l.b)
                    .map(|(row, b)| {
                        let z = row.iter().zip(&h).fold(*b, |acc, (w, x)| acc + w * x);
                        if k + 1 < n {
                            z.tanh()
                        } else {
                            z
                        }
                    })
                    .collect();
        }
        h.iter()
            .zip(self.output.mean.iter().zip(&self.output.scale))
            .map(|(y, (m, s))| m + s * y)
            .collect()
    }

    /// The folded network (module doc), in f64 and in f32.
    pub fn folded(&self) -> Folded {
        let mut layers = self.layers.clone();
        let first = &mut layers[0];
        for (row, b) in first.w.iter_mut().zip(first.b.iter_mut()) {
            for (i, w) in row.iter_mut().enumerate() {
                *w /= self.input.scale[i];
                *b -= *w * self.input.mean[i];
            }
        }
        let last = layers.last_mut().expect("validated: at least one layer");
        for (j, (row, b)) in last.w.iter_mut().zip(last.b.iter_mut()).enumerate() {
            let (m, s) = (self.output.mean[j], self.output.scale[j]);
            for w in row.iter_mut() {
                *w *= s;
            }
            *b = m + s * *b;
        }
        let f32_layers = layers
            .iter()
            .map(|l| {
                let w: Vec<f32> = l.w.iter().flatten().map(|v| *v as f32).collect();
                let b: Vec<f32> = l.b.iter().map(|v| *v as f32).collect();
                (l.w[0].len(), l.b.len(), w, b)
            })
            .collect();
        Folded { layers, f32_layers }
    }

    /// The excluded boxes rounded outward to f32 (every state of a box stays flagged).
    pub fn excluded_f32(&self) -> Vec<(Vec<f32>, Vec<f32>)> {
        self.excluded
            .iter()
            .map(|(lo, hi)| {
                (
                    lo.iter().map(|v| f32_down(*v)).collect(),
                    hi.iter().map(|v| f32_up(*v)).collect(),
                )
            })
            .collect()
    }

    /// The certified box rounded outward to f32: the smallest f32 box containing X, so the
    /// f32 state nearest any state of X (its corners included) is inside and not flagged
    /// out of domain. States of this box outside X lie within one f32 step of X's bounds.
    pub fn domain_f32(&self) -> (Vec<f32>, Vec<f32>) {
        (
            self.domain_lo.iter().map(|v| f32_down(*v)).collect(),
            self.domain_hi.iter().map(|v| f32_up(*v)).collect(),
        )
    }

    /// Input j's scale s_u,j of the certificate's norm (1 when unscaled).
    pub fn u_scale_of(&self, j: usize) -> f64 {
        self.u_scale.get(j).copied().unwrap_or(1.0)
    }

    /// Clamp band for a total ε in the certificate's norm (module doc), in f32: input j's
    /// half-width is s_u,j·ε rounded up, its physical bound.
    pub fn clamp_band(&self, eps: f64) -> (Vec<f32>, Vec<f32>) {
        let nu = self.nu();
        let mut lo = Vec::with_capacity(nu);
        let mut hi = Vec::with_capacity(nu);
        for j in 0..nu {
            let eps = crate::certify::norm::mul_up(self.u_scale_of(j), eps);
            let mut l = f32_down((self.u_lo[j] - eps).max(self.actuator_lo[j]));
            if f64::from(l) < self.actuator_lo[j] {
                l = f32_up(self.actuator_lo[j]);
            }
            let mut h = f32_up((self.u_hi[j] + eps).min(self.actuator_hi[j]));
            if f64::from(h) > self.actuator_hi[j] {
                h = f32_down(self.actuator_hi[j]);
            }
            lo.push(l);
            hi.push(h);
        }
        (lo, hi)
    }

    /// Fallback input in f32 (default: centre of U_d), inside `[lo, hi]`.
    pub fn fallback_f32(&self, lo: &[f32], hi: &[f32]) -> Vec<f32> {
        (0..self.nu())
            .map(|j| {
                let v = match &self.fallback {
                    Some(f) => f[j],
                    None => 0.5 * (self.u_lo[j] + self.u_hi[j]),
                };
                (v as f32).max(lo[j]).min(hi[j])
            })
            .collect()
    }
}
/// Validates `model`, computes the f32 allowances, writes the Rust file and the blob as
/// one set ([`write_files`]: both or neither) and returns the report.
pub fn export_files(
    model: &ExportModel,
    rust_out: &Path,
    postcard_out: &Path,
) -> Result<ExportReport, ExportError> {
    let (report, files) = render_files(model, rust_out, postcard_out)?;
    write_files(&files)?;
    Ok(report)
}

/// The files of an export, rendered and not yet written: `(path, bytes)`.
pub type PendingFiles = Vec<(PathBuf, Vec<u8>)>;

/// Validates `model`, computes the f32 allowances and renders the Rust file and the blob
/// for `rust_out` and `postcard_out` (written by [`write_files`], with any other file of
/// the same export).
pub fn render_files(
    model: &ExportModel,
    rust_out: &Path,
    postcard_out: &Path,
) -> Result<(ExportReport, PendingFiles), ExportError> {
    let report = certify_f32(model)?;
    let files = vec![
        (
            rust_out.to_path_buf(),
            render_rust(model, &report).into_bytes(),
        ),
        (postcard_out.to_path_buf(), render_postcard(model, &report)),
    ];
    Ok((report, files))
}

/// Writes an export's files as one transaction ([`crate::io::write_atomic_all`]): each is
/// written in full beside its destination first, and only then are all renamed into place,
/// so a failure (a full disk, a missing directory) leaves every previous file as it was.
pub fn write_files(files: &[(PathBuf, Vec<u8>)]) -> Result<(), ExportError> {
    let set: Vec<(&Path, &[u8])> = files
        .iter()
        .map(|(p, b)| (p.as_path(), b.as_slice()))
        .collect();
    crate::io::write_atomic_all(&set)?;
    Ok(())
}

impl ExportModel {
    /// The export description of a trained tanh network and its certificate (physical
    /// units; the actuator limits are the data's input bounds U_d unless given).
    /// controller-core runs tanh networks only: other activations are refused.
    pub fn from_trained(
        name: &str,
        model: &crate::certify::Model,
        cert: &crate::certify::certificate::Certificate,
    ) -> Result<Self, ExportError> {
        if model.mlp.activation != crate::learn::mlp::Activation::Tanh {
            return Err(ExportError::Invalid(format!(
                "activation {:?}: controller-core (the Rust and postcard export) runs tanh \
                 networks only; export this one with --onnx",
                model.mlp.activation
            )));
        }
        Self::from_certified(name, model, cert)
    }

    /// [`ExportModel::from_trained`] for any hidden activation (the layers and scalings are
    /// the same; [`ExportModel::eval_f64`] and the f32 analysis assume tanh, so the caller
    /// of a non-tanh network uses only the folding, domain and band: the ONNX export).
    pub fn from_certified(
        name: &str,
        model: &crate::certify::Model,
        cert: &crate::certify::certificate::Certificate,
    ) -> Result<Self, ExportError> {
        let m = &model.mlp;
        let own = model.content_hash();
        if cert.hash != own {
            return Err(ExportError::Invalid(format!(
                "the certificate is about the model with hash {}, not this model (hash {own}): \
                 certify this model (`trainer certify`) and export with that certificate",
                cert.hash
            )));
        }
        if cert.problem_hash.is_empty() {
            return Err(ExportError::Invalid(
                "the certificate names no problem (made by an older trainer): certify the model \
                 again"
                    .into(),
            ));
        }
        if !model.problem_hash.is_empty() && cert.problem_hash != model.problem_hash {
            return Err(ExportError::Invalid(format!(
                "the certificate is for problem hash {}, the model was trained on labels of \
                 problem hash {}",
                cert.problem_hash, model.problem_hash
            )));
        }
        let layers = m
            .layers
            .iter()
            .map(|l| DenseF64 {
                w: (0..l.out)
                    .map(|r| l.w[r * l.inp..(r + 1) * l.inp].to_vec())
                    .collect(),
                b: l.b.clone(),
            })
            .collect();
        Ok(ExportModel {
            name: name.to_string(),
            layers,
            input: Scaling {
                mean: m.in_center.clone(),
                scale: m.in_half.clone(),
            },
            output: Scaling {
                mean: m.out_center.clone(),
                scale: m.out_half.clone(),
            },
            domain_lo: cert.domain_lo.clone(),
            domain_hi: cert.domain_hi.clone(),
            u_lo: cert.u_lo.clone(),
            u_hi: cert.u_hi.clone(),
            actuator_lo: cert.u_lo.clone(),
            actuator_hi: cert.u_hi.clone(),
            fallback: None,
            eps: cert.eps,
            eps_d: cert.eps_d,
            l_nn: cert.l_nn,
            l_nn_method: format!("{:?}", cert.l_nn_method),
            l_mpc: cert.l_mpc,
            l_mpc_is_estimate: cert.l_mpc_is_estimate,
            covering_radius: cert.covering_radius,
            hash: cert.hash.clone(),
            placeholder: false,
            // The certificate's tier is set by the caller, who read it from the certificate
            // file (`with_certificate_tier`); without it, the weakest.
            guarantee: Guarantee::Estimated,
            statistical: None,
            excluded: Vec::new(),
            rests_on: Vec::new(),
            u_scale: cert.norm().u_scale,
        })
    }

    /// This model with its tier lowered to `declared` (the certificate's `"guarantee"`,
    /// as `certify::file::CertificateFile` reads it) when that is weaker: a claim is never
    /// raised.
    pub fn with_declared_guarantee(mut self, declared: Option<Guarantee>) -> Self {
        if let Some(d) = declared {
            self.guarantee = self.guarantee.weakest(d);
        }
        self
    }

    /// This model with ε replaced by the statistical level `eps_p` of a certificate's
    /// `"statistical"` block (P(‖κ − sat κ_NN‖ > eps_p) ≤ `claim.p_exceed_upper` with
    /// confidence `claim.confidence`) and the tier `statistical` (see [`StatisticalClaim`]).
    /// The clamp band becomes (U_d ⊕ [−ε_p − allowance, ε_p + allowance]) ∩ actuator: κ lies
    /// in U_d, so a band narrower than the one the errors were counted with (the
    /// certificate's, which contains it) can only shrink each error.
    pub fn with_statistical_eps(
        mut self,
        eps_p: f64,
        claim: StatisticalClaim,
    ) -> Result<Self, ExportError> {
        claim.validate()?;
        if !(eps_p.is_finite() && eps_p >= 0.0) {
            return Err(ExportError::Invalid(format!(
                "statistical ε must be finite and ≥ 0, got {eps_p}"
            )));
        }
        if self.placeholder {
            return Err(ExportError::Invalid(
                "a placeholder network has no statistical ε".into(),
            ));
        }
        self.eps = eps_p;
        self.guarantee = Guarantee::Statistical;
        self.statistical = Some(claim);
        Ok(self)
    }
}
