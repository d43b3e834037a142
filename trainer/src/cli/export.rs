//! `trainer export`: reads a trained model (`--model`: a model file or an ONNX file) and its
//! certificate (`--certificate` JSON, or the one stored in the model) and writes the
//! controller-core files — a generated Rust file (`--rust`) and a postcard blob
//! (`--postcard`), with the f32 allowance, and with `--c-header` the C API's header — and/or
//! an ONNX model (`--onnx`) of the same f32 network with the certificate in its metadata.
//! controller-core runs tanh networks only; a ReLU/softplus network can be exported to ONNX
//! alone (its f32 allowance is not analysed). Both paths clamp to (U_d ⊕ ε) ∩ actuator with
//! the actuator limits = U_d, i.e. to U_d. The certificate's tier is the weaker of its JSON's
//! `"guarantee"` (if any) and what its numbers rest on (`Guarantee`).

use anyhow::{bail, Context, Result};
use std::path::Path;
use trainer::certify::certificate::Certificate;
use trainer::certify::Model;
use trainer::deploy::export::{certify_f32, export_files, render_c_header, ExportModel, Guarantee};
use trainer::learn::mlp::Activation;

/// The output files of an export.
pub(super) struct Outputs<'a> {
    /// `--rust`.
    pub rust: Option<&'a Path>,
    /// `--postcard`.
    pub postcard: Option<&'a Path>,
    /// `--onnx`.
    pub onnx: Option<&'a Path>,
    /// `--c-header` (with `--rust` and `--postcard`).
    pub c_header: Option<&'a Path>,
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
    if out.c_header.is_some() && out.rust.is_none() {
        bail!("--c-header goes with --rust and --postcard (the header describes that export)");
    }
    let m = super::common::load_model(model)?;
    let (cert, declared) = load_certificate(model, &m, certificate)?;
    let tanh = m.mlp.activation == Activation::Tanh;
    let mut allowance = None;
    if let (Some(rust), Some(postcard)) = (out.rust, out.postcard) {
        let em = ExportModel::from_trained(name, &m, &cert)
            .with_context(|| format!("cannot export {} for controller-core", model.display()))?
            .with_declared_guarantee(declared);
        let r = export_files(&em, rust, postcard)?;
        if let Some(h) = out.c_header {
            trainer::io::write_atomic(h, render_c_header(&em, &r)?.as_bytes())?;
        }
        eprintln!(
            "exported {} -> {} + {} | f32 allowance (sound) {:.3e}, largest difference on {} random states {:.3e} | certified ε {:.4} + {:.3e} ({})",
            model.display(),
            rust.display(),
            postcard.display(),
            r.f32_allowance[0],
            r.samples,
            r.f32_observed[0],
            cert.eps,
            r.f32_allowance[0],
            em.guarantee.name()
        );
        allowance = Some(r.f32_allowance[0]);
    }
    if let Some(onnx) = out.onnx {
        let em = ExportModel::from_certified(name, &m, &cert)?.with_declared_guarantee(declared);
        em.validate()?;
        if allowance.is_none() && tanh {
            allowance = Some(certify_f32(&em)?.f32_allowance[0]);
        }
        let bytes = trainer::deploy::onnx::render_onnx(&em, m.mlp.activation, allowance);
        trainer::io::write_atomic(onnx, &bytes)?;
        eprintln!(
            "exported {} -> {} (ONNX opset {}, {:?} MLP {:?}) | certified ε {:.4}{} ({})",
            model.display(),
            onnx.display(),
            trainer::deploy::onnx::write::OPSET,
            m.mlp.activation,
            m.mlp.widths(),
            cert.eps,
            match allowance {
                Some(a) => format!(" + f32 allowance {a:.3e} (controller-core's libm arithmetic)"),
                None => " (f32 allowance not analysed for this activation)".into(),
            },
            em.guarantee.name()
        );
    }
    Ok(())
}

/// The certificate of `--certificate` (with the tier its JSON declares, if any), or the one
/// stored in the model at `model_path`; either way it must be about this very network.
pub(super) fn load_certificate(
    model_path: &Path,
    m: &Model,
    certificate: Option<&Path>,
) -> Result<(Certificate, Option<Guarantee>)> {
    let (cert, declared): (Certificate, _) = match certificate {
        Some(p) => {
            let text = std::fs::read_to_string(p)
                .with_context(|| format!("cannot read {}", p.display()))?;
            let cert = serde_json::from_str(&text)
                .with_context(|| format!("{}: not a certificate", p.display()))?;
            (
                cert,
                Guarantee::declared_in(&text, &p.display().to_string())?,
            )
        }
        None => (
            m.certificate.clone().with_context(|| {
                format!(
                    "{} holds no certificate: pass --certificate",
                    model_path.display()
                )
            })?,
            None,
        ),
    };
    if cert.hash != m.content_hash() {
        bail!(
            "the certificate is about another network (hash {}), not {}",
            cert.hash,
            model_path.display()
        );
    }
    Ok((cert, declared))
}
