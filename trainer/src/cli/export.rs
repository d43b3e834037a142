//! `trainer export`: reads a trained model (`--model`) and its certificate (`--certificate`
//! JSON, or the one stored in the model) and writes the controller-core files: a generated
//! Rust file (`--rust`) and a postcard blob (`--postcard`), with the f32 allowance.

use anyhow::{bail, Context, Result};
use std::path::Path;
use trainer::certify::certificate::Certificate;
use trainer::certify::Model;
use trainer::deploy::export::{export_files, ExportModel};

pub(super) fn execute(
    model: &Path,
    certificate: Option<&Path>,
    rust: &Path,
    postcard: &Path,
    name: &str,
) -> Result<()> {
    let m = Model::load(model)?;
    let cert = load_certificate(model, &m, certificate)?;
    let em = ExportModel::from_trained(name, &m, &cert)?;
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
