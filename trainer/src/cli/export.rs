//! `trainer export`: reads a trained model (`--model`: a model file or an ONNX file) and its
//! certificate (`--certificate` JSON, or the one stored in the model) and writes the
//! controller-core files — a generated Rust file (`--rust`) and a postcard blob
//! (`--postcard`), with the f32 allowance — and/or an ONNX model (`--onnx`) of the same
//! f32 network with the certificate in its metadata. controller-core runs tanh networks
//! only; a ReLU/softplus network can be exported to ONNX alone (its f32 allowance is not
//! analysed: the ONNX clamp band is U_d ⊕ ε).

use anyhow::{bail, Context, Result};
use std::path::Path;
use trainer::certify::certificate::Certificate;
use trainer::certify::Model;
use trainer::deploy::export::{certify_f32, export_files, ExportModel};
use trainer::learn::mlp::Activation;

/// The output files of an export.
pub(super) struct Outputs<'a> {
    /// `--rust`.
    pub rust: Option<&'a Path>,
    /// `--postcard`.
    pub postcard: Option<&'a Path>,
    /// `--onnx`.
    pub onnx: Option<&'a Path>,
}

pub(super) fn execute(
    model: &Path,
    certificate: Option<&Path>,
    out: &Outputs<'_>,
    name: &str,
) -> Result<()> {
    if out.rust.is_some() != out.postcard.is_some() {
        bail!("--rust and --postcard go together (the Rust file and the blob of one export)");
    }
    if out.rust.is_none() && out.onnx.is_none() {
        bail!("nothing to export: give --rust and --postcard, or --onnx, or all three");
    }
    let m = super::common::load_model(model)?;
    let cert = load_certificate(model, &m, certificate)?;
    let tanh = m.mlp.activation == Activation::Tanh;
    let mut allowance = None;
    if let (Some(rust), Some(postcard)) = (out.rust, out.postcard) {
        let em = ExportModel::from_trained(name, &m, &cert)
            .with_context(|| format!("cannot export {} for controller-core", model.display()))?;
        let r = export_files(&em, rust, postcard)?;
        eprintln!(
            "exported {} -> {} + {} | f32 allowance (sound) {:.3e}, largest difference on {} random states {:.3e} | certified ε {:.4} + {:.3e}",
            model.display(),
            rust.display(),
            postcard.display(),
            r.f32_allowance[0],
            r.samples,
            r.f32_observed[0],
            cert.eps,
            r.f32_allowance[0]
        );
        allowance = Some(r.f32_allowance[0]);
    }
    if let Some(onnx) = out.onnx {
        let em = ExportModel::from_certified(name, &m, &cert)?;
        em.validate()?;
        if allowance.is_none() && tanh {
            allowance = Some(certify_f32(&em)?.f32_allowance[0]);
        }
        let bytes = trainer::deploy::onnx::render_onnx(&em, m.mlp.activation, allowance);
        trainer::io::write_atomic(onnx, &bytes)?;
        eprintln!(
            "exported {} -> {} (ONNX opset {}, {:?} MLP {:?}) | certified ε {:.4}{}",
            model.display(),
            onnx.display(),
            trainer::deploy::onnx::write::OPSET,
            m.mlp.activation,
            m.mlp.widths(),
            cert.eps,
            match allowance {
                Some(a) => format!(" + f32 allowance {a:.3e} (controller-core's libm arithmetic)"),
                None => " (f32 allowance not analysed for this activation)".into(),
            }
        );
    }
    Ok(())
}

/// The certificate of `--certificate`, or the one stored in the model at `model_path`;
/// either way it must be about this very network.
fn load_certificate(
    model_path: &Path,
    m: &Model,
    certificate: Option<&Path>,
) -> Result<Certificate> {
    let cert: Certificate = match certificate {
        Some(p) => serde_json::from_str(
            &std::fs::read_to_string(p).with_context(|| format!("cannot read {}", p.display()))?,
        )
        .with_context(|| format!("{}: not a certificate", p.display()))?,
        None => m.certificate.clone().with_context(|| {
            format!(
                "{} holds no certificate: pass --certificate",
                model_path.display()
            )
        })?,
    };
    if cert.hash != m.content_hash() {
        bail!(
            "the certificate is about another network (hash {}), not {}",
            cert.hash,
            model_path.display()
        );
    }
    Ok(cert)
}
