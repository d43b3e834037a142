//! `trainer sample`: generates the labelled dataset of the problem file's sampling plan
//! (`--config`), or with `--validation` its validation set (what `trainer run`'s `validate`
//! stage labels), or one shard of either (`--shard K/N`), into `--out` (postcard) with a
//! CSV export beside it; resumes an interrupted run.

use super::common::{load_config, opt, refuse_overwrite};
use anyhow::Result;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use trainer::data::dataset::{self, GenerateOptions, Shard};

/// The arguments of `trainer sample` (their doc comments are the help text).
#[derive(clap::Args)]
pub(super) struct Args {
    /// Problem file (default: the embedded pendulum).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Output dataset file (postcard); a CSV export is written beside it.
    #[arg(long)]
    out: PathBuf,
    /// Compute only shard K of N (`K/N`, 0 ≤ K < N).
    #[arg(long)]
    shard: Option<Shard>,
    /// Label the validation set instead of the sampling plan: the `[training]
    /// validation_n` random states of `validation_seed` that `trainer run`'s `validate` stage
    /// labels into `validation.bin` (with --shard: one shard of it; `trainer merge` of all
    /// shards is byte-identical to that file).
    #[arg(long)]
    validation: bool,
    /// No progress bar or summary.
    #[arg(long, short)]
    quiet: bool,
}

impl Args {
    /// Generates the dataset (or one shard) into `--out` and its CSV export.
    pub(super) fn run(self) -> Result<()> {
        let csv = dataset::csv_path(&self.out);
        refuse_overwrite(&[&self.out, &csv], &[opt(&self.config)])?;
        let mut cfg = load_config(self.config.as_deref())?;
        if self.validation {
            cfg = trainer::pipeline::validation_config(&cfg);
        }
        execute_with(&cfg, &self.out, self.shard, self.quiet)
    }
}

/// Generates `cfg`'s sampling plan (or one shard) into `out` and its CSV export.
fn execute_with(
    cfg: &trainer::problem::ProblemConfig,
    out: &Path,
    shard: Option<Shard>,
    quiet: bool,
) -> Result<()> {
    let t = std::time::Instant::now();
    let opts = GenerateOptions {
        shard,
        progress: !quiet && std::io::stderr().is_terminal(),
    };
    let d = dataset::generate(cfg, out, &opts)?;
    if !quiet {
        let c = d.counts();
        eprintln!(
            "{}: {} states{} in {:.2} s: {} converged, {} soft, {} infeasible, {} failed, {} degenerate -> {} (+ {})",
            cfg.name,
            c.total,
            shard.map(|s| format!(" (shard {}/{})", s.index, s.count)).unwrap_or_default(),
            t.elapsed().as_secs_f64(),
            c.converged,
            c.soft,
            c.infeasible,
            c.failed,
            c.degenerate,
            out.display(),
            dataset::csv_path(out).display()
        );
        // How the default starts were chosen (a non-convex OCP without `solver.starts`).
        let law = trainer::mpc::law::MpcLaw::new(cfg);
        if cfg.solver.starts.is_none() && !law.is_convex() {
            eprintln!("{}", trainer::mpc::law::pilot::pilot(cfg).describe());
        }
        // Where `solver.starts` reached different local optima (the label: the lowest
        // cost, ties to the warm start — continuation from the previous state).
        if !d.disagree.is_empty() {
            eprintln!(
                "{} states where the starts disagree (different local optima; labelled by the \
                 lowest cost, ties to the warm start): first {:?}",
                d.disagree.len(),
                &d.disagree[..d.disagree.len().min(8)]
            );
        }
        // Why the first numerical failure has no label (re-solved once: the record does
        // not store it).
        if let Some((index, x, failure)) = d.first_failure(cfg) {
            let why = failure.map_or_else(
                || "the solver broke down (QP or line search)".to_string(),
                |f| f.to_string(),
            );
            eprintln!("first numerical_failure: state {index}, x = {x:?}: {why}");
        }
    }
    Ok(())
}
