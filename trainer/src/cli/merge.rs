//! `trainer merge`: merges shard files of `trainer sample --shard` (`inputs`) into one
//! dataset (`out`, postcard, with a CSV export beside it), identical to an unsharded run.

use anyhow::Result;
use std::path::{Path, PathBuf};
use trainer::data::dataset::{self, Dataset};

pub(super) fn execute(out: &Path, inputs: &[PathBuf]) -> Result<()> {
    let ds = inputs
        .iter()
        .map(|p| Dataset::load(p))
        .collect::<Result<Vec<_>, _>>()?;
    let d = dataset::merge(&ds)?;
    d.save(out)?;
    trainer::io::write_atomic(&dataset::csv_path(out), d.to_csv().as_bytes())?;
    eprintln!(
        "merged {} shards ({} records) -> {}",
        inputs.len(),
        d.records.len(),
        out.display()
    );
    Ok(())
}
