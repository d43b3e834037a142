//! `trainer merge`: merges shard files of `trainer sample --shard` (`inputs`) into one
//! dataset (`out`, postcard, with a CSV export beside it), identical to an unsharded run.
//! With `--config`, every shard must be labelled for that problem.

use anyhow::Result;
use std::path::{Path, PathBuf};
use trainer::data::dataset::{self, Dataset};

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
