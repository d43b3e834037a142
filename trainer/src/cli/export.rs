//! `trainer export`: reads a trained model (`--model`) and its certificate (`--certificate`
//! JSON, or the one stored in the model) and writes the controller-core files: a generated
//! Rust file (`--rust`), a postcard blob (`--postcard`) and, with `--c-header`, the C API's
//! header, with the f32 allowance. The certificate's tier is the weaker of its JSON's
//! `"guarantee"` (if any) and what its numbers rest on (`Guarantee`).

use anyhow::{bail, Context, Result};
use std::path::Path;
use trainer::certify::certificate::Certificate;
use trainer::certify::Model;
use trainer::deploy::export::{export_files, render_c_header, ExportModel, Guarantee};

pub(super) fn execute(
    model: &Path,
    certificate: Option<&Path>,
    rust: &Path,
    postcard: &Path,
    name: &str,
    c_header: Option<&Path>,
) -> Result<()> {
    let m = Model::load(model)?;
    let (cert, declared) = load_certificate(model, &m, certificate)?;
    let em = ExportModel::from_trained(name, &m, &cert)?.with_declared_guarantee(declared);
    let r = export_files(&em, rust, postcard)?;
    if let Some(h) = c_header {
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
    Ok(())
}

/// The certificate of `--certificate` (with the tier its JSON declares, if any), or the one
/// stored in the model at `model_path`; either way it must be about this very network.
fn load_certificate(
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
