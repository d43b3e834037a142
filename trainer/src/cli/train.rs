//! `trainer train`: trains a network on a dataset of `trainer sample` (`--data`) with the
//! problem file's `[training]` table (`--config`), validates it on `--validation` (or on
//! freshly labelled random states), certifies it and writes the model with its
//! certificate (`--out`).

use super::common::{opt, problem_for_data, refuse_overwrite, sha256_file};
use anyhow::{bail, Result};
use std::path::{Path, PathBuf};
use trainer::certify::certificate::{certify, Certificate, CertifyOptions};
use trainer::certify::Model;
use trainer::data::dataset::Dataset;
use trainer::learn::setpoint::Hold;
use trainer::learn::train::{label_random_states, train, TrainOptions, TrainSet};
use trainer::problem::ProblemConfig;

/// The arguments of `trainer train` (their doc comments are the help text).
#[derive(clap::Args)]
pub(super) struct Args {
    /// Problem file (default: the embedded pendulum); its `[training]` table applies.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Dataset file from `trainer sample`.
    #[arg(long)]
    data: PathBuf,
    /// Output model file.
    #[arg(long)]
    out: PathBuf,
    /// Nominal training (λ₂ = λ₃ = 0).
    #[arg(long)]
    nominal: bool,
    /// Override the seed of the initial weights and shuffling.
    #[arg(long)]
    seed: Option<u64>,
    /// A labelled validation dataset (e.g. a run's validation.bin); default: label
    /// `training.validation_n` random states now.
    #[arg(long)]
    validation: Option<PathBuf>,
    /// No progress or summary.
    #[arg(long, short)]
    quiet: bool,
}

impl Args {
    /// Trains a net on `--data` into `--out`.
    pub(super) fn run(self) -> Result<()> {
        refuse_overwrite(
            &[&self.out],
            &[&self.data, opt(&self.config), opt(&self.validation)],
        )?;
        execute(
            self.config.as_deref(),
            &self.data,
            &self.out,
            self.nominal,
            self.seed,
            self.validation.as_deref(),
            self.quiet,
        )
    }
}

pub(super) fn execute(
    config: Option<&Path>,
    data: &Path,
    out: &Path,
    nominal: bool,
    seed: Option<u64>,
    validation: Option<&Path>,
    quiet: bool,
) -> Result<()> {
    let d = Dataset::load(data)?;
    let mut cfg = problem_for_data(config, data, &d)?;
    if let Some(s) = seed {
        cfg.training.seed = s;
    }
    if d.header.problem_hash != cfg.problem_hash() {
        bail!(
            "{} was labelled for another problem (hash {}…) than the config's {} ({}…)",
            data.display(),
            super::common::short(&d.header.problem_hash),
            cfg.name,
            super::common::short(&cfg.problem_hash())
        );
    }
    if let Some(l) = d.labels.as_ref().filter(|l| !l.jacobian && !nominal) {
        eprintln!(
            "note: {} holds labels imported from {} without Jacobian columns: the Jacobian \
             term is dropped at every point (λ₂ = 0 in effect; λ₁, λ₃ as configured)",
            data.display(),
            l.file
        );
    }
    let set = TrainSet::from_dataset(&d);
    if set.is_empty() {
        bail!("{}: no labelled points to train on", data.display());
    }
    let t0 = std::time::Instant::now();
    let val = validation_set(&cfg, &d, data, validation)?;
    let t_val = t0.elapsed().as_secs_f64();
    let t1 = std::time::Instant::now();
    let opts = TrainOptions {
        nominal,
        progress: None,
        hold: Hold::if_enabled(&cfg, cfg.training.hold_setpoint)?,
        keep_best: None,
    };
    let mut model = if cfg.keeps_sequences() {
        // The sequence net (`learn::sequence`); its curve's validation figure is on the
        // training data, the model's validation statistics (u₀) on `val`.
        let name = data.display().to_string();
        let mut m: trainer::certify::Model = trainer::learn::sequence::train_sequence(
            &cfg,
            &opts,
            &d,
            &d,
            (&name, &name),
            &d.header.problem_hash,
            &sha256_file(data)?,
        )?;
        m.validation_stats = trainer::learn::train::errors(&m.mlp, &val).1;
        m
    } else {
        train(
            &cfg.training,
            &opts,
            &set,
            &val,
            (&cfg.domain.lo, &cfg.domain.hi),
            (&cfg.ocp.u_lo, &cfg.ocp.u_hi),
            &d.header.problem_hash,
            &sha256_file(data)?,
        )
    };
    let t_train = t1.elapsed().as_secs_f64();
    let cert = certify(
        &model,
        &d,
        &cfg,
        &CertifyOptions {
            extra: Some(val),
            ..Default::default()
        },
    )?;
    model.certificate = Some(cert.clone());
    model.problem_toml = Some(cfg.to_toml_string()?);
    model.save(out)?;
    if !quiet {
        print_summary(&model, &cert, nominal, (t_train, t_val), out);
    }
    Ok(())
}

/// The validation set: the dataset at `validation` (labelled for the same problem as the
/// training data `d`, read from `data`), or `training.validation_n` random states labelled now.
fn validation_set(
    cfg: &ProblemConfig,
    d: &Dataset,
    data: &Path,
    validation: Option<&Path>,
) -> Result<TrainSet> {
    Ok(match validation {
        Some(p) => {
            let v = Dataset::load(p)?;
            if v.header.problem_hash != d.header.problem_hash {
                bail!(
                    "{} was labelled for another problem than {}",
                    p.display(),
                    data.display()
                );
            }
            TrainSet::from_dataset(&v)
        }
        None => label_random_states(cfg, cfg.training.validation_n, cfg.training.validation_seed),
    })
}

/// The one-line summary on stderr: net, epochs, timings (training, validation labels),
/// errors and the certificate's terms.
fn print_summary(
    model: &Model,
    cert: &Certificate,
    nominal: bool,
    seconds: (f64, f64),
    out: &Path,
) {
    let (t_train, t_val) = seconds;
    eprintln!(
        "{} net {:?}: {} epochs in {:.3} s (validation labels {:.3} s) | train ε_D {:.4}, median {:.4} | validation R² {:.5}, max err {:.4} | L_NN {:.2} ({:?}), naive {:.2}, lower {:.2} | ε {:.3} -> {}",
        if nominal { "nominal" } else { "regularized" },
        model.mlp.widths(),
        model.epochs_run,
        t_train,
        t_val,
        model.train_stats.max,
        model.train_stats.median,
        model.validation_stats.r2,
        model.validation_stats.max,
        cert.l_nn,
        cert.l_nn_method,
        cert.l_nn_naive,
        cert.l_nn_lower,
        cert.eps,
        out.display()
    );
}
