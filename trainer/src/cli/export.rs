//! `trainer export`: reads a trained model (`--model`: a model file or an ONNX file) and its
//! certificate (`--certificate` JSON, or the one stored in the model) and writes the
//! controller-core files — a generated Rust file (`--rust`) and a postcard blob
//! (`--postcard`), with the f32 allowance, and with `--c-header` the C API's header — and/or
//! a C library folder for this network (`--c-lib DIR`: header, C99 sources, Makefile,
//! CMakeLists.txt; `deploy::export::render_c_lib`) — and/or
//! an ONNX model (`--onnx`) of the same f32 network with the certificate in its metadata.
//! controller-core runs tanh networks only; a ReLU/softplus network can be exported to ONNX
//! alone (its f32 allowance is not analysed). Both paths clamp to (U_d ⊕ ε) ∩ actuator with
//! the actuator limits = U_d, i.e. to U_d. The certificate's tier is its `"guarantee"`, copied
//! (never recomputed); the certificate is read through `certify::file` — refused without its
//! checksum (unless `--accept-unsealed`, which lowers the tier to `estimated`), without its
//! `"guarantee"`, after a failed check, or when a value disagrees with what it is recomputed
//! from (ε from its terms, the band, the tier, X, U_d and the hashes).
//!
//! With `--statistical-band` ε is the statistical level of the certificate's `"statistical"`
//! block (`eps_at_p_target`: P(error > ε) ≤ its `p_target` at its confidence), the tier
//! `statistical` ([`StatisticalClaim`]); the block must be about this certificate (its `eps`
//! is the certificate's: the errors were counted with the certificate's clamp band, which
//! contains the narrower band exported, so each error can only shrink).
//!
//! The problem: `--config` (the model and the certificate must be of it), else the one
//! stored in the model (`learn::model_file`). The generated files' name (`--name`, default
//! that problem's name, else the model file's stem) is made an identifier ([`identifier`]).

use super::common::{opt, refuse_overwrite};
use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};
use trainer::certify::file::{read_certificate, Against, CertificateFile};
use trainer::certify::seal::Seal;
use trainer::certify::Model;
use trainer::deploy::export::{
    certify_f32, render_c_header, render_c_lib, render_files, write_files, ExportModel, Guarantee,
    PendingFiles, StatisticalClaim,
};
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
    /// `--c-lib`: the folder of the C library (`deploy::export::render_c_lib`).
    pub c_lib: Option<&'a Path>,
}

/// The arguments of `trainer export` (their doc comments are the help text).
#[derive(clap::Args)]
pub(super) struct Args {
    /// Problem file: the model and the certificate must be of this problem (default: the
    /// problem stored in the model).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Model file from `trainer train`, or an ONNX file (detected by content); not needed
    /// when only --plant-rs is written.
    #[arg(long, required_unless_present = "plant_rs")]
    model: Option<PathBuf>,
    /// Certificate JSON (default: the one stored in the model by `trainer train`).
    #[arg(long)]
    certificate: Option<PathBuf>,
    /// Output Rust file (with --postcard).
    #[arg(long)]
    rust: Option<PathBuf>,
    /// Output postcard blob (with --rust).
    #[arg(long)]
    postcard: Option<PathBuf>,
    /// Output ONNX file: the f32 network as the controller computes it (opset 13),
    /// certificate under `ampc.*` metadata keys.
    #[arg(long)]
    onnx: Option<PathBuf>,
    /// Name used in the generated files (default: the model's problem name), made a
    /// valid identifier (characters other than A–Z, a–z, 0–9, _ become _).
    #[arg(long)]
    name: Option<String>,
    /// Also write the C header of `controller-core/capi` for this network (`ampc.h`).
    #[arg(long)]
    c_header: Option<PathBuf>,
    /// Write a C library for this network into the folder DIR (created if missing):
    /// `ampc.h`, `ampc.c` (portable C99, bit-identical to the Rust controller), a
    /// `Makefile` and a `CMakeLists.txt` (see docs/deployment.md).
    #[arg(long, value_name = "DIR")]
    c_lib: Option<PathBuf>,
    /// Use the certificate's statistical level as ε (and so as the clamp band): the
    /// `"statistical"` block's `eps_at_p_target` of `--certificate` (from `trainer certify
    /// --statistical N --json`), tier `statistical`, instead of its certified ε.
    #[arg(long, requires = "certificate")]
    statistical_band: bool,
    /// Read a certificate without a checksum (written before certificates were sealed):
    /// its numbers cannot be verified, so its tier is lowered to `estimated` (said on
    /// stderr and in the outputs). Without this flag such a file is refused.
    #[arg(long)]
    accept_unsealed: bool,
    /// Write the plant of the problem (--config) as no_std f32 Rust for the online check of
    /// `controller_core::safe::SafeController`: dynamics (RK4 with the OCP's sub-steps),
    /// costs, boxes, `[ocp]` path and terminal constraints, the terminal set and controller
    /// (the robust design's region, else the nominal terminal ingredients), the online
    /// check's estimated margins `MARGINS`, and `impl Plant for SafePlant`
    /// (`deploy::plant_rs_safe`; needs the `libm` crate). Refused, naming the key, for
    /// plants or OCP parts without a generator and without a terminal set.
    #[arg(long, value_name = "FILE", requires = "config")]
    plant_rs: Option<PathBuf>,
    /// Write the model's sequence net (`[training] outputs = "sequence"`) as no_std f32 Rust,
    /// a module `sequence` (`Net`, `NET`, `N`) to `include!` beside weights.rs for
    /// `controller_core::safe::SequenceNet` (`deploy::sequence_rs`). Refused for a model
    /// without a sequence net.
    #[arg(long, value_name = "FILE", requires = "model")]
    sequence_rs: Option<PathBuf>,
    /// Write the safety-augmented controller of a sequence-net model as one no_std Rust file
    /// for `controller_core::include_safe_controller!`: the plant of --plant-rs (of --config,
    /// else the model's problem) in `mod plant`, the sequence net in `mod sequence`, `N`,
    /// the type `Controller` and the constant `CONTROLLER` (`deploy::safe_rs`). Refused for a
    /// model without a sequence net, a net whose outputs are not ocp.horizon × nu, and the
    /// plants --plant-rs refuses.
    #[arg(long, value_name = "FILE", requires = "model")]
    safe_rs: Option<PathBuf>,
}

impl Args {
    /// Writes the export files that were asked for.
    pub(super) fn run(self) -> Result<()> {
        if let (Some(file), Some(config)) = (&self.plant_rs, &self.config) {
            refuse_overwrite(&[file], &[config, opt(&self.model)])?;
            write_plant_rs(config, file)?;
        }
        if let (Some(file), Some(model)) = (&self.sequence_rs, &self.model) {
            refuse_overwrite(&[file], &[model, opt(&self.config)])?;
            write_sequence_rs(model, file)?;
            if self.rust.is_none()
                && self.onnx.is_none()
                && self.c_lib.is_none()
                && self.safe_rs.is_none()
            {
                return Ok(());
            }
        }
        if let (Some(file), Some(model)) = (&self.safe_rs, &self.model) {
            refuse_overwrite(&[file], &[model, opt(&self.config)])?;
            write_safe_rs(self.config.as_deref(), model, file)?;
            if self.rust.is_none() && self.onnx.is_none() && self.c_lib.is_none() {
                return Ok(());
            }
        }
        let Some(model) = &self.model else {
            if self.rust.is_some() || self.onnx.is_some() || self.c_lib.is_some() {
                bail!("--rust, --onnx and --c-lib export a trained model: give --model");
            }
            return Ok(());
        };
        refuse_overwrite(
            &[
                opt(&self.rust),
                opt(&self.postcard),
                opt(&self.onnx),
                opt(&self.c_header),
            ],
            &[model, opt(&self.certificate), opt(&self.config)],
        )?;
        let out = Outputs {
            rust: self.rust.as_deref(),
            postcard: self.postcard.as_deref(),
            onnx: self.onnx.as_deref(),
            c_header: self.c_header.as_deref(),
            c_lib: self.c_lib.as_deref(),
        };
        execute(
            self.config.as_deref(),
            model,
            self.certificate.as_deref(),
            &out,
            self.name.as_deref(),
            (self.statistical_band, self.accept_unsealed),
        )
    }
}

/// `--sequence-rs FILE`: the model's sequence net (`deploy::sequence_rs`).
fn write_sequence_rs(model: &Path, file: &Path) -> Result<()> {
    let m = trainer::certify::Model::load(model)?;
    let Some(seq) = &m.sequence else {
        bail!(
            "{}: the model has no sequence net (train it with [training] outputs = \"sequence\")",
            model.display()
        );
    };
    let nu = m.mlp.nu();
    let name = m
        .problem_toml
        .as_deref()
        .map_or("controller".to_string(), |t| {
            trainer::problem::ProblemConfig::from_stored_toml(t, "model")
                .map_or("controller".to_string(), |c| c.name)
        });
    let text = trainer::deploy::sequence_rs::render_sequence_rs(&name, seq, nu);
    std::fs::write(file, text).with_context(|| format!("cannot write {}", file.display()))?;
    eprintln!(
        "{}: sequence net of `{name}` ({} outputs = N {} × nu {nu})",
        file.display(),
        seq.nu(),
        seq.nu() / nu.max(1)
    );
    Ok(())
}

/// `--safe-rs FILE`: the safe controller of the model's sequence net (`deploy::safe_rs`).
fn write_safe_rs(config: Option<&Path>, model: &Path, file: &Path) -> Result<()> {
    let m = super::common::load_model(model)?;
    let Some(seq) = &m.sequence else {
        bail!(
            "{}: the model has no sequence net (train it with [training] outputs = \"sequence\")",
            model.display()
        );
    };
    let Some(cfg) = super::common::problem_for_model(config, model, &m)? else {
        bail!(
            "{}: the model stores no problem: pass --config (the plant is generated from it)",
            model.display()
        );
    };
    let (text, g) = trainer::deploy::safe_rs::render_safe_rs(&cfg, seq, m.settings.sequence_form)
        .with_context(|| {
        format!(
            "cannot generate the safe controller of {} for `{}`",
            model.display(),
            cfg.name
        )
    })?;
    trainer::io::write_atomic(file, text.as_bytes())
        .with_context(|| format!("cannot write {}", file.display()))?;
    eprintln!(
        "{}: safe controller of `{}`: sequence net {:?}, N {}, terminal set alpha {:e} \
         (invariance {}, decrease {}), margins stage {:e} / terminal {:e} (estimated)",
        file.display(),
        cfg.name,
        seq.widths(),
        cfg.ocp.horizon,
        g.terminal.alpha(),
        g.invariance(),
        g.decrease,
        g.margins.stage,
        g.margins.terminal,
    );
    Ok(())
}

/// `--plant-rs FILE`: the generated plant of the problem `config` (`deploy::plant_rs_safe`).
fn write_plant_rs(config: &Path, file: &Path) -> Result<()> {
    let cfg = trainer::problem::ProblemConfig::load(config)?;
    let g = trainer::deploy::plant_rs_safe::safe_plant_rs(&cfg)
        .with_context(|| format!("cannot generate the plant of {} as Rust", config.display()))?;
    std::fs::write(file, &g.source).with_context(|| format!("cannot write {}", file.display()))?;
    use trainer::deploy::plant_rs_safe::TerminalSource;
    let (from, invariance) = match &g.terminal {
        TerminalSource::Robust(t) if t.proven() => ("the robust design", "proven"),
        TerminalSource::Robust(_) => ("the robust design", "sampled"),
        TerminalSource::Nominal(_) => ("the nominal terminal ingredients", "sampled"),
    };
    eprintln!(
        "{}: plant of `{}` as f32 Rust; terminal set from {from}: alpha {:e} (invariance \
         {invariance}), decrease condition for the generated V_f: {} (worst over the samples {:e})",
        file.display(),
        cfg.name,
        g.terminal.alpha(),
        g.decrease,
        g.decrease_worst
    );
    Ok(())
}

pub(super) fn execute(
    config: Option<&Path>,
    model: &Path,
    certificate: Option<&Path>,
    out: &Outputs<'_>,
    name: Option<&str>,
    (statistical_band, accept_unsealed): (bool, bool),
) -> Result<()> {
    if out.rust.is_some() != out.postcard.is_some() {
        bail!("--rust and --postcard go together (the Rust file and the blob of one export)");
    }
    if out.rust.is_none() && out.onnx.is_none() && out.c_lib.is_none() {
        bail!("nothing to export: give --rust and --postcard, --onnx or --c-lib DIR (or several)");
    }
    if out.c_header.is_some() && out.rust.is_none() {
        bail!("--c-header goes with --rust and --postcard (the header describes that export)");
    }
    let m = super::common::load_model(model)?;
    let problem = super::common::problem_for_model(config, model, &m)?;
    let (file, seal) = load_certificate(model, &m, certificate, problem.as_ref(), accept_unsealed)?;
    let cert = file.base.clone();
    let band = match (statistical_band, certificate) {
        (true, Some(p)) => Some(statistical_level(p, &file)?),
        _ => None,
    };
    let excluded = file
        .local
        .as_ref()
        .and_then(|l| l.excluded.as_ref())
        .map_or_else(Vec::new, |e| e.boxes.clone());
    // The model to export: the certificate's ε and tier, or its statistical level.
    let prepare = |em: ExportModel| -> Result<ExportModel> {
        let mut em = em.with_certificate_guarantee(&file.guarantee);
        em.excluded = excluded.clone();
        let mut em = match &band {
            Some((eps_p, claim)) => em.with_statistical_eps(*eps_p, claim.clone())?,
            None => em,
        };
        if seal == Seal::Absent {
            // An unsealed certificate's numbers are not verified: estimated, whatever ε is.
            em.guarantee = Guarantee::Estimated;
        }
        Ok(em)
    };
    let name = export_name(name, problem.as_ref().map(|c| c.name.as_str()), model);
    let name = name.as_str();
    let tanh = m.mlp.activation == Activation::Tanh;
    let mut allowance = None;
    // Every output is rendered first and written at the end as one set (a failed
    // write leaves no Rust file without its blob); the messages follow the write.
    let mut files: PendingFiles = Vec::new();
    let mut said: Vec<String> = Vec::new();
    if out.rust.is_some() || out.c_lib.is_some() {
        let em = ExportModel::from_trained(name, &m, &cert).with_context(|| {
            format!(
                "cannot export {} for controller-core with the certificate of {}",
                model.display(),
                certificate.unwrap_or(model).display()
            )
        })?;
        let em = prepare(em)?;
        let r = match (out.rust, out.postcard) {
            (Some(rust), Some(postcard)) => {
                let (r, rendered) = render_files(&em, rust, postcard)?;
                files.extend(rendered);
                r
            }
            _ => certify_f32(&em)?,
        };
        if let Some(h) = out.c_header {
            files.push((h.to_path_buf(), render_c_header(&em, &r)?.into_bytes()));
        }
        if let Some(dir) = out.c_lib {
            std::fs::create_dir_all(dir)
                .with_context(|| format!("cannot create the --c-lib folder {}", dir.display()))?;
            files.extend(render_c_lib(&em, &r, dir)?);
        }
        said.push(format!(
            "exported {} -> {} | f32 allowance (sound) {:.3e}, largest difference on {} random states {:.3e} | {} ε {:.4} + {:.3e} ({}{})",
            model.display(),
            [out.rust, out.postcard, out.c_lib]
                .iter()
                .flatten()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
                .join(" + "),
            r.f32_allowance[0],
            r.samples,
            r.f32_observed[0],
            if em.statistical.is_some() { "statistical" } else { "certified" },
            em.eps,
            r.f32_allowance[0],
            em.guarantee.name(),
            em.statistical.as_ref().map_or(String::new(), |s| format!(": {}", s.words()))
        ));
        if !em.excluded.is_empty() {
            said.push(format!(
                "the certificate excludes {} boxes of X (outside the MPC's feasible set): the \
                 controller flags states in them (EXCLUDED)",
                em.excluded.len()
            ));
        }
        allowance = Some(r.f32_allowance[0]);
    }
    if let Some(onnx) = out.onnx {
        let em = ExportModel::from_certified(name, &m, &cert).with_context(|| {
            format!(
                "cannot export {} with the certificate of {}",
                model.display(),
                certificate.unwrap_or(model).display()
            )
        })?;
        let em = prepare(em)?;
        em.validate()?;
        if allowance.is_none() && tanh {
            allowance = Some(certify_f32(&em)?.f32_allowance[0]);
        }
        let bytes = trainer::deploy::onnx::render_onnx(&em, m.mlp.activation, allowance);
        files.push((onnx.to_path_buf(), bytes));
        said.push(format!(
            "exported {} -> {} (ONNX opset {}, {:?} MLP {:?}) | certified ε {:.4}{} ({})",
            model.display(),
            onnx.display(),
            trainer::deploy::onnx::write::OPSET,
            m.mlp.activation,
            m.mlp.widths(),
            em.eps,
            match allowance {
                Some(a) => format!(" + f32 allowance {a:.3e} (controller-core's libm arithmetic)"),
                None => " (f32 allowance not analysed for this activation)".into(),
            },
            em.guarantee.name()
        ));
    }
    write_files(&files)?;
    for s in said {
        eprintln!("{s}");
    }
    Ok(())
}

/// The statistical level of the certificate at `path` and what it rests on: its
/// `"statistical"` block's `eps_at_p_target` (an error naming the file and the key when the
/// block is missing, about another ε, or has no level).
fn statistical_level(path: &Path, file: &CertificateFile) -> Result<(f64, StatisticalClaim)> {
    let cert = &file.base;
    let Some(st) = &file.statistical else {
        bail!(
            "{}: --statistical-band needs a \"statistical\" block: make the certificate with \
             `trainer certify … --statistical N --json {}`",
            path.display(),
            path.display()
        );
    };
    if st.eps != cert.eps {
        bail!(
            "{}: the \"statistical\" block counts exceedances of ε = {}, not of this \
             certificate's ε = {}: it is about another certificate",
            path.display(),
            st.eps,
            cert.eps
        );
    }
    let Some(eps_p) = st.eps_at_p_target else {
        bail!(
            "{}: \"statistical\".eps_at_p_target is null: {} states are too few for \
             P ≤ {:e} at confidence {} (need more --statistical states)",
            path.display(),
            st.samples,
            st.p_target,
            st.confidence
        );
    };
    if eps_p > cert.eps {
        eprintln!(
            "warning: the statistical level {eps_p:.4} is above the certificate's ε {:.4} \
             ({}): exporting the weaker, larger band as asked",
            cert.eps,
            path.display()
        );
    }
    Ok((
        eps_p,
        StatisticalClaim {
            p_exceed_upper: st.p_target,
            confidence: st.confidence,
            samples: st.samples,
            unlabelled_p_upper: None,
        },
    ))
}

/// The generated files' name: `--name`, else the problem's name, else the model file's
/// stem (said on stderr), as an [`identifier`] (a change is said on stderr).
fn export_name(given: Option<&str>, problem: Option<&str>, model: &Path) -> String {
    let raw = match (given, problem) {
        (Some(n), _) | (None, Some(n)) => n.to_string(),
        (None, None) => {
            let stem = model
                .file_stem()
                .map_or("model".into(), |s| s.to_string_lossy().into_owned());
            eprintln!(
                "note: {} names no problem (an ONNX file or a model of an older build): the \
                 generated files are named after the file, `{}` (pass --name or --config)",
                model.display(),
                identifier(&stem)
            );
            stem
        }
    };
    let id = identifier(&raw);
    if id != raw {
        eprintln!("note: name `{raw}` written as the identifier `{id}`");
    }
    id
}

/// `s` as an identifier of Rust and C: every character other than A–Z, a–z, 0–9 and `_`
/// becomes `_`, a leading digit gets a `_` before it, and the empty name is `model`.
pub(super) fn identifier(s: &str) -> String {
    let mut id: String = s
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    if id.is_empty() {
        id = "model".into();
    } else if id.starts_with(|c: char| c.is_ascii_digit()) {
        id.insert(0, '_');
    }
    id
}

/// The certificate of `--certificate` at `certificate`, or the one stored in the model at
/// `model_path`; either way about this very network (`hash`), of `problem` when known
/// (`problem_hash`, X, U_d) and consistent in itself ([`CertificateFile::recheck`]: ε from
/// its terms, the band, the tier, a passed check). A file without its checksum is refused
/// unless `accept_unsealed`, which lowers its tier to `estimated` (said on stderr). The
/// certificate stored in a model file (sealed with the model) has no tier of its own: it is
/// read as Theorem 1's ([`CertificateFile::theorem1`]).
pub(super) fn load_certificate(
    model_path: &Path,
    m: &Model,
    certificate: Option<&Path>,
    problem: Option<&trainer::problem::ProblemConfig>,
    accept_unsealed: bool,
) -> Result<(CertificateFile, Seal)> {
    let model_hash = m.content_hash();
    let against = Against {
        model_hash: Some(&model_hash),
        problem,
        dataset_hash: None,
        cells_csv: None,
    };
    let (file, seal) =
        match certificate {
            Some(p) => {
                let (file, seal) = read_certificate(p, accept_unsealed, &against)?;
                if seal == Seal::Absent {
                    eprintln!(
                        "warning: {} carries no checksum (--accept-unsealed): its numbers are not \
                     verified, its tier is lowered to `estimated` in every output",
                        p.display()
                    );
                }
                (file, seal)
            }
            None => {
                let stored = m.certificate.clone().with_context(|| {
                    format!(
                        "{} holds no certificate: pass --certificate",
                        model_path.display()
                    )
                })?;
                // The model file stores the certificate without its norm (postcard keeps the old
                // format); its band tells which: U_d ⊕ [−s_u,j·ε, s_u,j·ε] in the problem's norm,
                // U_d ⊕ [−ε, ε] in an older, unscaled certificate (then it reads as unscaled).
                let mut stored = stored;
                if let Some(p) = problem {
                    let norm = trainer::certify::norm::Norm::of_problem(p);
                    let per = norm.per_input(stored.eps);
                    let scaled =
                        per.len() == stored.u_lo.len()
                            && stored.u_lo.iter().zip(&stored.clamp_lo).zip(&per).all(
                                |((u, c), w)| {
                                    ((u - c) - w).abs() <= 1e-12 * (u.abs() + w).max(1e-300)
                                },
                            );
                    if scaled && stored.scales.is_none() {
                        stored.scales = Some(norm);
                        stored.epsilon_per_input = per;
                    }
                }
                let file = CertificateFile::theorem1(stored);
                file.recheck_against(
                    &format!("the certificate stored in {}", model_path.display()),
                    &against,
                )?;
                // Sealed with the model file (its envelope's checksum).
                (file, Seal::Verified)
            }
        };
    let cert = &file.base;
    let origin = || {
        certificate.map_or_else(
            || format!("the certificate stored in {}", model_path.display()),
            |p| p.display().to_string(),
        )
    };
    let (nx, nu) = (m.mlp.nx(), m.mlp.nu());
    for (key, len, want) in [
        ("domain_lo", cert.domain_lo.len(), nx),
        ("domain_hi", cert.domain_hi.len(), nx),
        ("u_lo", cert.u_lo.len(), nu),
        ("u_hi", cert.u_hi.len(), nu),
        ("clamp_lo", cert.clamp_lo.len(), nu),
        ("clamp_hi", cert.clamp_hi.len(), nu),
    ] {
        if len != want {
            bail!(
                "{}: `{key}` has {len} entries, but {} maps {nx} states to {nu} inputs",
                origin(),
                model_path.display()
            );
        }
    }
    Ok((file, seal))
}

#[cfg(test)]
mod tests {
    #[test]
    fn identifiers() {
        use super::identifier;
        assert_eq!(identifier("double_integrator"), "double_integrator");
        assert_eq!(identifier("cart-pole v2"), "cart_pole_v2");
        assert_eq!(identifier("2link"), "_2link");
        assert_eq!(identifier(""), "model");
        assert_eq!(identifier("a*/\nb"), "a___b");
        assert_eq!(identifier("θ"), "_");
    }
}
