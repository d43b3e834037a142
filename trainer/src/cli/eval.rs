//! `trainer eval`: evaluates a trained model (`--model`) at every state of a states CSV
//! (`--states`, header `x1,…,xn`) and writes a CSV (`--out`).
//!
//! By default the output is the **controller's**: what `controller-core` computes for the
//! exported model under its certificate (`--certificate` JSON, or the one stored in the
//! model) — the state rounded to f32, projected onto the certified domain, the f32 network,
//! the clamp band, and the flags (`deploy::export::device`): columns `x1..xn,u1..um,flags`
//! (flags: 1 out of domain, 2 not finite, 4 clamped, 8 in a cell the certificate excludes). With `--raw`, the bare f64 network
//! and its Jacobian: `x1..xn,u1..um,du1_dx1,…,dum_dxn`.
//!
//! With `--config`, the model (and the certificate) must be of that problem; without it the
//! problem stored in the model is named on stderr and the certificate checked against it.
//! The certificate is read and re-checked as `export` reads it (`certify::file`: sealed,
//! ε from its terms, band, tier, X, U_d, hashes; `--accept-unsealed` for an unsealed one).

use super::common::{csv_numbers, jacobian_header, opt, read_states, refuse_overwrite};
use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};
use trainer::deploy::export::device::Device;
use trainer::deploy::export::{ExportModel, Tanh};
use trainer::learn::mlp::Activation;

/// The input files of `eval`.
pub(super) struct Inputs<'a> {
    /// `--config`.
    pub config: Option<&'a Path>,
    /// `--model`.
    pub model: &'a Path,
    /// `--states`.
    pub states: &'a Path,
    /// `--certificate`.
    pub certificate: Option<&'a Path>,
    /// `--accept-unsealed`: read a certificate without its checksum (tier `estimated`).
    pub accept_unsealed: bool,
}

/// The arguments of `trainer eval` (their doc comments are the help text).
#[derive(clap::Args)]
pub(super) struct Args {
    /// Problem file: the model (and certificate) must be of this problem (default: the
    /// problem stored in the model).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Model file, or an ONNX file (detected by content).
    #[arg(long)]
    model: PathBuf,
    /// Input CSV with header `x1,…,xn`.
    #[arg(long)]
    states: PathBuf,
    /// Output CSV: the controller's `x1..xn,u1..um,flags` (flags: 1 out of domain, 2 not
    /// finite, 4 clamped, 8 in a box the certificate excludes), or with --raw the bare
    /// network's
    /// `x1..xn,u1..um,du1_dx1,…,dum_dxn`.
    #[arg(long)]
    out: PathBuf,
    /// Certificate JSON whose domain and clamp band the controller uses (default: the
    /// one stored in the model).
    #[arg(long)]
    certificate: Option<PathBuf>,
    /// The bare f64 network and its Jacobian, without projection, clamp or f32.
    #[arg(long)]
    raw: bool,
    /// Read a certificate without a checksum (written before certificates were sealed):
    /// its numbers cannot be verified, so its tier is lowered to `estimated` (said on
    /// stderr and in the outputs). Without this flag such a file is refused.
    #[arg(long)]
    accept_unsealed: bool,
}

impl Args {
    /// Evaluates `--model` at the states of `--states` into `--out`.
    pub(super) fn run(self) -> Result<()> {
        refuse_overwrite(
            &[&self.out],
            &[
                &self.model,
                &self.states,
                opt(&self.certificate),
                opt(&self.config),
            ],
        )?;
        let inputs = Inputs {
            config: self.config.as_deref(),
            model: &self.model,
            states: &self.states,
            certificate: self.certificate.as_deref(),
            accept_unsealed: self.accept_unsealed,
        };
        execute(&inputs, &self.out, self.raw)
    }
}

pub(super) fn execute(inputs: &Inputs<'_>, out: &Path, raw: bool) -> Result<()> {
    let (model, states, certificate) = (inputs.model, inputs.states, inputs.certificate);
    let m = super::common::load_model(model)?;
    let problem = super::common::problem_for_model(inputs.config, model, &m)?;
    let (nx, nu) = (m.mlp.nx(), m.mlp.nu());
    if raw && certificate.is_some() {
        bail!("--raw evaluates the bare network: a certificate plays no part (drop --certificate)");
    }
    let xs = read_states(states, nx, problem.as_ref())?;
    let s = if raw {
        let mut s = jacobian_header(nx, nu).join(",");
        s.push('\n');
        let mut ws = trainer::learn::mlp::Workspace::default();
        let (mut u, mut jac) = (vec![0.0; nu], vec![0.0; nu * nx]);
        for x in &xs {
            m.mlp.eval(x, &mut u, &mut jac, &mut ws);
            s += &csv_numbers(x.iter().chain(&u).chain(&jac));
            s.push('\n');
        }
        s
    } else {
        if m.mlp.activation != Activation::Tanh {
            bail!(
                "{}: a {:?} network — controller-core runs tanh networks only; evaluate the \
                 bare network with --raw",
                model.display(),
                m.mlp.activation
            );
        }
        let (file, _) = super::export::load_certificate(
            model,
            &m,
            certificate,
            problem.as_ref(),
            inputs.accept_unsealed,
        )
        .context("the controller's output needs the certificate (domain and clamp band); --raw evaluates the bare network")?;
        let mut em = ExportModel::from_trained("eval", &m, &file.base)?;
        // The certificate's excluded boxes, as the exported controller flags them.
        em.excluded = file
            .local
            .as_ref()
            .and_then(|l| l.excluded.as_ref())
            .map_or_else(Vec::new, |e| e.boxes.clone());
        let dev = Device::new(&em, Tanh::Libm)?;
        let mut head: Vec<String> = (1..=nx).map(|i| format!("x{i}")).collect();
        head.extend((1..=nu).map(|j| format!("u{j}")));
        head.push("flags".into());
        let mut s = head.join(",");
        s.push('\n');
        for x in &xs {
            let xf: Vec<f32> = x.iter().map(|v| *v as f32).collect();
            let (u, flags) = dev.evaluate(&xf);
            let u: Vec<f64> = u.iter().map(|v| f64::from(*v)).collect();
            s += &csv_numbers(x.iter().chain(&u));
            s += &format!(",{flags}\n");
        }
        s
    };
    trainer::io::write_atomic(out, s.as_bytes())?;
    Ok(())
}
