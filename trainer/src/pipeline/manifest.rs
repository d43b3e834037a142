//! Skip-if-unchanged: a stage's manifest (`manifest_<stage>.json`) records the SHA-256 of
//! its inputs (files of earlier stages, settings serialised as JSON), of its outputs, the
//! trainer version and its wall time; a stage whose recorded inputs equal the current ones,
//! built by the same version, whose every output is present with the recorded hash, is not
//! run again. An output modified or corrupted since the stage wrote it makes the stage run
//! again, and its summary says which file.

use super::{fail, fail_at, PipelineError, RunOptions, Stage, StageReport};
use crate::io::{hex, write_atomic, RunDir};
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use std::collections::BTreeMap;
use std::path::Path;
use std::time::Instant;

/// A stage's manifest.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// Stage name.
    pub stage: String,
    /// trainer version.
    pub version: String,
    /// Input name → SHA-256 (files) or settings hash.
    pub inputs: BTreeMap<String, String>,
    /// Output files (relative to the run directory).
    pub outputs: Vec<String>,
    /// Output file → SHA-256 of what the stage wrote (a manifest without it is not trusted).
    #[serde(default)]
    pub output_hashes: BTreeMap<String, String>,
    /// Wall time in seconds.
    pub seconds: f64,
}

/// Why a stage cannot be skipped.
enum Stale {
    /// No manifest, other inputs or another trainer version: run it.
    Inputs,
    /// Inputs unchanged, but an output is missing or differs from what the stage wrote.
    Output(String),
}

/// SHA-256 of each output file of a run directory.
fn output_hashes(
    dir: &Path,
    stage: &str,
    outputs: &[&str],
) -> Result<BTreeMap<String, String>, PipelineError> {
    outputs
        .iter()
        .map(|o| {
            let p = dir.join(o);
            let h = sha_file(&p).map_err(|e| fail_at(stage, &p, e))?;
            Ok((o.to_string(), h))
        })
        .collect()
}

/// Records the current hash of `file` in `stage`'s manifest, after a later step of the
/// same run legitimately rewrote it (the robust loop adds its runs to `closed_loop.json`).
pub fn reseal(dir: &RunDir, stage: Stage, file: &str) -> Result<(), PipelineError> {
    let mpath = dir.manifest(stage.name());
    let text = std::fs::read_to_string(&mpath).map_err(|e| fail_at(stage, &mpath, e))?;
    let mut m: Manifest = serde_json::from_str(&text).map_err(|e| fail_at(stage, &mpath, e))?;
    let p = dir.join(file);
    let h = sha_file(&p).map_err(|e| fail_at(stage, &p, e))?;
    m.output_hashes.insert(file.to_string(), h);
    let json = serde_json::to_string_pretty(&m).map_err(|e| fail(stage, e))?;
    write_atomic(&mpath, json.as_bytes()).map_err(|e| fail(stage, e))
}

pub(super) fn sha_file(p: &Path) -> Result<String, std::io::Error> {
    Ok(hex(&Sha256::digest(std::fs::read(p)?)))
}

fn sha_str(s: &str) -> String {
    hex(&Sha256::digest(s.as_bytes()))
}

/// The hash of a settings value (its JSON serialisation).
pub(super) fn settings_hash<T: Serialize>(v: &T) -> String {
    sha_str(&serde_json::to_string(v).unwrap_or_default())
}

/// The run directory and what happened so far.
pub(super) struct Ctx<'a> {
    pub(super) dir: RunDir,
    pub(super) opts: &'a RunOptions,
    pub(super) reports: Vec<StageReport>,
}

impl Ctx<'_> {
    /// Runs `body` unless the manifest says its inputs are unchanged.
    pub(super) fn stage(
        &mut self,
        stage: Stage,
        inputs: BTreeMap<String, String>,
        outputs: &[&str],
        body: impl FnOnce(&RunDir) -> Result<String, PipelineError>,
    ) -> Result<(), PipelineError> {
        let name = stage.name();
        let mpath = self.dir.manifest(name);
        let forced = self.opts.force.contains(&stage);
        let mut note = None;
        if !forced {
            match self.unchanged(&mpath, &inputs, outputs) {
                Ok(m) => {
                    let r = StageReport {
                        stage: name.into(),
                        skipped: true,
                        seconds: m.seconds,
                        summary: "unchanged inputs, skipped".into(),
                        inputs: m.inputs,
                        outputs: m.outputs,
                    };
                    self.report(r);
                    return Ok(());
                }
                Err(Stale::Output(why)) => note = Some(why),
                Err(Stale::Inputs) => {}
            }
        }
        let t = Instant::now();
        // Labelling and seed stages draw their own progress bar; the others show a spinner.
        let spinner = if self.opts.progress
            && ![Stage::Sample, Stage::Validate, Stage::Seeds].contains(&stage)
        {
            let b = indicatif::ProgressBar::new_spinner();
            b.set_style(
                indicatif::ProgressStyle::with_template("{spinner} [{prefix:>11}] {elapsed}")
                    .unwrap_or_else(|_| indicatif::ProgressStyle::default_spinner()),
            );
            b.set_prefix(name.to_string());
            b.enable_steady_tick(std::time::Duration::from_millis(100));
            Some(b)
        } else {
            None
        };
        let summary = body(&self.dir);
        if let Some(b) = spinner {
            b.finish_and_clear();
        }
        let mut summary = summary?;
        if let Some(why) = note {
            summary = format!("{why}: redone; {summary}");
        }
        let seconds = t.elapsed().as_secs_f64();
        let m = Manifest {
            stage: name.into(),
            version: env!("CARGO_PKG_VERSION").into(),
            inputs: inputs.clone(),
            outputs: outputs.iter().map(|s| s.to_string()).collect(),
            output_hashes: output_hashes(self.dir.path(), name, outputs)?,
            seconds,
        };
        let json = serde_json::to_string_pretty(&m).map_err(|e| fail(name, e))?;
        write_atomic(&mpath, json.as_bytes()).map_err(|e| fail(name, e))?;
        self.report(StageReport {
            stage: name.into(),
            skipped: false,
            seconds,
            summary,
            inputs,
            outputs: m.outputs,
        });
        Ok(())
    }

    /// Whether [`stage`](Self::stage) would run `stage` on these inputs (forced, or not
    /// [`unchanged`](Self::unchanged)) rather than skip it.
    pub(super) fn will_run(
        &self,
        stage: Stage,
        inputs: &BTreeMap<String, String>,
        outputs: &[&str],
    ) -> bool {
        self.opts.force.contains(&stage)
            || self
                .unchanged(&self.dir.manifest(stage.name()), inputs, outputs)
                .is_err()
    }

    /// The manifest at `mpath` if it records these inputs and this version, and every
    /// output is present with the hash it was written with.
    fn unchanged(
        &self,
        mpath: &Path,
        inputs: &BTreeMap<String, String>,
        outputs: &[&str],
    ) -> Result<Manifest, Stale> {
        let text = std::fs::read_to_string(mpath).map_err(|_| Stale::Inputs)?;
        let m = serde_json::from_str::<Manifest>(&text).map_err(|_| Stale::Inputs)?;
        if m.inputs != *inputs || m.version != env!("CARGO_PKG_VERSION") {
            return Err(Stale::Inputs);
        }
        for o in outputs {
            let p = self.dir.join(o);
            let Ok(h) = sha_file(&p) else {
                return Err(Stale::Output(format!("{} is missing", p.display())));
            };
            if m.output_hashes.get(*o) != Some(&h) {
                return Err(Stale::Output(format!(
                    "{} differs from what this stage wrote",
                    p.display()
                )));
            }
        }
        Ok(m)
    }

    fn report(&mut self, r: StageReport) {
        if let Some(f) = self.opts.on_stage {
            f(&r);
        }
        self.reports.push(r);
    }

    /// SHA-256 of a file of the run directory (the error names the stage and the file).
    pub(super) fn hash(&self, stage: Stage, file: &str) -> Result<String, PipelineError> {
        let p = self.dir.join(file);
        sha_file(&p).map_err(|e| fail_at(stage, &p, e))
    }
}
