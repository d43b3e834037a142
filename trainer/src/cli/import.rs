//! `trainer import`: a dataset from another solver's CSV (`--csv`) for the problem file
//! (`--config`), checked (dimensions, domain X, finite labels), a seeded sample re-solved by
//! ampc's SQP (`--resolve N`, `--seed`; a disagreement beyond the tolerance is an error
//! unless `--trust-labels`), written as an ampc dataset with its provenance (`--out`,
//! default: the CSV's path with extension `.imported.bin`). No CSV export is written beside it (the
//! input is one).

use super::common::{load_config, opt, refuse_overwrite};
use anyhow::{bail, Result};
use std::path::{Path, PathBuf};
use trainer::data::import::{import, ImportOptions};

/// The arguments of `trainer import` (their doc comments are the help text).
#[derive(clap::Args)]
pub(super) struct Args {
    /// The CSV file.
    #[arg(long)]
    csv: PathBuf,
    /// Problem file (default: the embedded pendulum).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Output dataset file (default: the CSV's path with extension `.imported.bin`, so
    /// that importing a `dataset.csv` never replaces the `dataset.bin` beside it).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Rows re-solved by ampc's SQP to check the labels (0: none; all if fewer rows).
    #[arg(long, default_value_t = trainer::data::import::DEFAULT_RESOLVE)]
    resolve: usize,
    /// Seed of the re-solved sample.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Accept labels that disagree with ampc's re-solve (recorded in the dataset and
    /// the certificate, not an error).
    #[arg(long)]
    trust_labels: bool,
    /// No summary.
    #[arg(long, short)]
    quiet: bool,
}

impl Args {
    /// Imports `--csv` into a dataset (default: beside it, `.imported.bin`).
    pub(super) fn run(self) -> Result<()> {
        let out = self
            .out
            .clone()
            .unwrap_or_else(|| self.csv.with_extension("imported.bin"));
        refuse_overwrite(&[&out], &[&self.csv, opt(&self.config)])?;
        let opts = ImportOptions {
            resolve: self.resolve,
            seed: self.seed,
            trust_labels: self.trust_labels,
        };
        execute(self.config.as_deref(), &self.csv, &out, &opts, self.quiet)
    }
}

pub(super) fn execute(
    config: Option<&Path>,
    csv: &Path,
    out: &Path,
    opts: &ImportOptions,
    quiet: bool,
) -> Result<()> {
    let cfg = load_config(config)?;
    if cfg.robust.enabled() {
        bail!(
            "problem `{}` is a robust design ([robust] eps > 0): import labels of the \
             tightened MPC with a problem file without [robust]",
            cfg.name
        );
    }
    let t = std::time::Instant::now();
    let d = import(&cfg, csv, opts)?;
    d.save(out)?;
    if !quiet {
        let c = d.counts();
        let l = d.labels.as_ref();
        eprintln!(
            "{}: {} rows from {} ({} labelled, {}) in {:.2} s; re-solved {} by ampc: max |Δu| {:.3e}{}{} -> {}",
            cfg.name,
            c.total,
            csv.display(),
            c.converged + c.soft,
            if l.is_some_and(|l| l.jacobian) {
                "with Jacobians"
            } else {
                "no Jacobian columns: training drops the Jacobian term (λ₂ = 0 in effect)"
            },
            t.elapsed().as_secs_f64(),
            l.map_or(0, |l| l.resolved),
            l.map_or(0.0, |l| l.max_disagreement),
            l.filter(|l| l.max_line > 0)
                .map(|l| format!(" (line {})", l.max_line))
                .unwrap_or_default(),
            l.filter(|l| l.beyond_tolerance + l.unlabelled_by_ampc > 0)
                .map(|l| format!(
                    ", {} beyond tolerance and {} unlabelled by ampc ACCEPTED by --trust-labels",
                    l.beyond_tolerance, l.unlabelled_by_ampc
                ))
                .unwrap_or_default(),
            out.display()
        );
    }
    Ok(())
}
