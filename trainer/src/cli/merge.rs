//! `trainer merge`: merges shard files of `trainer sample --shard` (`inputs`) into one
//! dataset (`out`, postcard, with a CSV export beside it), identical to an unsharded run.
//! With `--config`, every shard must be labelled for that problem.

use super::common::{opt, refuse_overwrite};
use anyhow::Result;
use std::path::{Path, PathBuf};
use trainer::data::dataset::{self, Dataset};

/// The arguments of `trainer merge` (their doc comments are the help text).
#[derive(clap::Args)]
pub(super) struct Args {
    /// Problem file: every shard must be labelled for this problem (default: the shards'
    /// own, which must agree).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Output dataset file.
    out: PathBuf,
    /// Shard files.
    #[arg(required = true)]
    inputs: Vec<PathBuf>,
}

impl Args {
    /// Merges the shard files into `out` and its CSV export.
    pub(super) fn run(self) -> Result<()> {
        let csv = dataset::csv_path(&self.out);
        let mut ins: Vec<&Path> = self.inputs.iter().map(PathBuf::as_path).collect();
        ins.push(opt(&self.config));
        refuse_overwrite(&[&self.out, &csv], &ins)?;
        execute(self.config.as_deref(), &self.out, &self.inputs)
    }
}

pub(super) fn execute(config: Option<&Path>, out: &Path, inputs: &[PathBuf]) -> Result<()> {
    let ds = inputs
        .iter()
        .map(|p| Dataset::load(p))
        .collect::<Result<Vec<_>, _>>()?;
    if let Some(c) = config {
        let cfg = super::common::load_config(Some(c))?;
        for (d, p) in ds.iter().zip(inputs) {
            if d.header.problem_hash != cfg.problem_hash() {
                anyhow::bail!(
                    "{} was labelled for problem `{}` (hash {}…), not for problem `{}` of {} \
                     (hash {}…)",
                    p.display(),
                    d.header.problem,
                    super::common::short(&d.header.problem_hash),
                    cfg.name,
                    c.display(),
                    super::common::short(&cfg.problem_hash())
                );
            }
        }
    }
    // The library names inputs by position: name them by path.
    let d = dataset::merge(&ds).map_err(|e| {
        let mut msg = e.to_string();
        for (i, p) in inputs.iter().enumerate().rev() {
            msg = msg.replace(&format!("input {}", i + 1), &p.display().to_string());
        }
        anyhow::anyhow!(msg)
    })?;
    let csv = dataset::csv_path(out);
    trainer::io::write_atomic_all(&[(&csv, d.to_csv().as_bytes()), (out, &d.to_bytes())])?;
    eprintln!(
        "merged {} shards ({} records) -> {}",
        inputs.len(),
        d.records.len(),
        out.display()
    );
    Ok(())
}
