//! `trainer run`: one command from a problem file to a certified controller.
//!
//! Stages, each writing its artifacts under `DIR/<name>/` with a manifest
//! (`manifest_<stage>.json`: input hashes, settings, crate version, timing):
//! `sample` (dataset.bin/.csv) → `validate` (validation.bin: MPC labels of random states)
//! → `train` (model_nominal.bin, model_regularized.bin, same initial weights) → `certify`
//! (certificate.json, certificate_nominal.json) → `export` (weights.rs, weights.bin,
//! export_report.json: the regularized net for controller-core) → `closed_loop`
//! (closed_loop.json) → `seeds` (seeds.json: both nets retrained from other seeds' initial
//! weights and simulated from the reference initial state) → `plots` (plots/*.svg,
//! plots/*.png) → `report` (report.md, report.html). A stage whose manifest matches its current inputs and whose
//! outputs exist is skipped; `force` redoes named stages (and, through the changed hashes,
//! everything downstream). Dataset generation resumes from its checkpoint when killed.

//!
//! Files: `stages` (each stage as a value: name, inputs, outputs, body), [`manifest`]
//! (skip-if-unchanged), [`robust`] (the Corollary 1 design loop, which runs these stages on
//! the tightened problem). `pipeline` and the CLI are the only places that know every stage.
//!
//! **Library use.** [`run`] takes a problem file's text; [`run_problem`] a problem held in
//! memory — built in code, or with a plant implemented in Rust by the calling program
//! (`System::Custom`, see `problem::model::custom`): the same stages, the same files.
//! `RunOptions::until` stops after a stage (e.g. `export`: dataset → nets → certificates →
//! weights). The CLI cannot reopen a custom plant's files; the program that has the plant
//! can ([`ProblemConfig::from_toml_str_with`]).

pub mod manifest;
pub mod robust;
mod stages;

use crate::io::write_atomic;
use crate::problem::ProblemConfig;
use crate::study::report::Timing;
use manifest::Ctx;
use std::collections::BTreeMap;
use std::path::PathBuf;

/// The stages in order.
pub const STAGES: [&str; 9] = [
    "sample",
    "validate",
    "train",
    "certify",
    "export",
    "closed_loop",
    "seeds",
    "plots",
    "report",
];

/// A failure, naming the stage and the cause.
#[derive(Debug, thiserror::Error)]
#[error("stage `{stage}` failed: {cause}")]
pub struct PipelineError {
    /// The stage.
    pub stage: String,
    /// What went wrong (names the file or setting).
    pub cause: String,
}

fn fail(stage: &str, e: impl std::fmt::Display) -> PipelineError {
    PipelineError {
        stage: stage.to_string(),
        cause: e.to_string(),
    }
}

/// What happened to a stage.
#[derive(Debug, Clone)]
pub struct StageReport {
    /// Stage name.
    pub stage: String,
    /// Skipped because its inputs were unchanged.
    pub skipped: bool,
    /// Wall time (of this run, or of the run that produced the artifacts when skipped).
    pub seconds: f64,
    /// One-line summary.
    pub summary: String,
    /// Input name → hash, as in the manifest.
    pub inputs: BTreeMap<String, String>,
    /// Output files (relative to the run directory).
    pub outputs: Vec<String>,
}

/// Options of a pipeline run.
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// Run directory root (the run goes to `root/<name>/`).
    pub root: PathBuf,
    /// Stages to redo even if unchanged.
    pub force: Vec<String>,
    /// Progress bars on a terminal.
    pub progress: bool,
    /// Called after each stage (for one summary line per stage).
    pub on_stage: Option<fn(&StageReport)>,
    /// Stop after this stage (default: run all).
    pub until: Option<String>,
}

/// Runs the pipeline for a problem held in memory (built in code, or holding a custom
/// plant): [`run`] with the problem written out ([`ProblemConfig::to_toml_string`]) as
/// `problem.toml`. Returns what happened to each stage; the files are in
/// `opts.root/<cfg.name>/`.
pub fn run_problem(
    cfg: &ProblemConfig,
    opts: &RunOptions,
) -> Result<Vec<StageReport>, PipelineError> {
    let text = cfg.to_toml_string().map_err(|e| fail("setup", e))?;
    run(cfg, &text, opts)
}

/// Runs the pipeline for `cfg`; `config_text` is the problem file's text (written to
/// `problem.toml`).
pub fn run(
    cfg: &ProblemConfig,
    config_text: &str,
    opts: &RunOptions,
) -> Result<Vec<StageReport>, PipelineError> {
    let dir = opts.root.join(&cfg.name);
    std::fs::create_dir_all(&dir).map_err(|e| fail("setup", format!("{}: {e}", dir.display())))?;
    let _lock = lock(&dir)?;
    remove_stale_temporaries(&dir);
    same_problem(&dir, cfg, opts)?;
    write_atomic(&dir.join("problem.toml"), config_text.as_bytes())
        .map_err(|e| fail("setup", e))?;
    let mut cx = Ctx {
        dir,
        opts,
        reports: Vec::new(),
    };
    for stage in &stages::ALL {
        let inputs = (stage.inputs)(&cx, cfg)?;
        let outputs = (stage.outputs)();
        let outputs: Vec<&str> = outputs.iter().map(String::as_str).collect();
        let env = stages::Env {
            cfg,
            progress: opts.progress,
            timings: cx
                .reports
                .iter()
                .map(|r| Timing {
                    stage: r.stage.clone(),
                    seconds: r.seconds,
                    skipped: r.skipped,
                })
                .collect(),
        };
        cx.stage(stage.name, inputs, &outputs, |d| (stage.body)(&env, d))?;
        if opts.until.as_deref() == Some(stage.name) {
            break;
        }
    }
    Ok(cx.reports)
}

/// Removes the temporary files (`.<name>.<pid>.tmp`, see `io::write_atomic`) that a run
/// killed mid-write left in the run directory or its `plots/`: with the lock held, no other
/// process is writing them.
fn remove_stale_temporaries(dir: &std::path::Path) {
    for d in [dir.to_path_buf(), dir.join("plots")] {
        let Ok(entries) = std::fs::read_dir(&d) else {
            continue;
        };
        for e in entries.flatten() {
            let name = e.file_name().to_string_lossy().to_string();
            if name.starts_with('.') && name.ends_with(".tmp") {
                let _ = std::fs::remove_file(e.path());
            }
        }
    }
}

/// Refuses to replace a run of another problem (other labels: system, OCP or solver) that
/// has the same name, unless `--force sample` asks for it: the old run would be lost.
fn same_problem(
    dir: &std::path::Path,
    cfg: &ProblemConfig,
    opts: &RunOptions,
) -> Result<(), PipelineError> {
    let p = dir.join("problem.toml");
    let Ok(text) = std::fs::read_to_string(&p) else {
        return Ok(());
    };
    let forced = opts.force.iter().any(|f| f == "sample");
    let refuse = |why: String| {
        fail(
            "setup",
            format!(
                "{} holds a run of another problem named `{}` ({why}): use another name or \
                 --out, or pass --force sample to replace it",
                dir.display(),
                cfg.name
            ),
        )
    };
    let origin = p.display().to_string();
    match ProblemConfig::from_toml_str_with(&text, &origin, cfg.system.custom_plants()) {
        Ok(old) if old.problem_hash() != cfg.problem_hash() && !forced => {
            Err(refuse("other system, OCP or solver".into()))
        }
        Ok(_) => Ok(()),
        // A custom plant on either side that does not read back as this problem's plant
        // (another plant, version or equations) is another problem.
        Err(e)
            if !forced && (cfg.system.custom_plants().len() == 1 || names_custom_plant(&text)) =>
        {
            Err(refuse(format!("its plant is not this one: {e}")))
        }
        Err(_) => Ok(()), // not a problem of this version: the stages' hashes decide
    }
}

/// Whether a problem file's `[system]` is `kind = "custom"`.
fn names_custom_plant(text: &str) -> bool {
    toml::from_str::<toml::Table>(text).is_ok_and(|t| {
        t.get("system")
            .and_then(|s| s.get("kind"))
            .and_then(|k| k.as_str())
            == Some("custom")
    })
}

/// Takes the run directory's lock (`.lock`, an advisory `flock` that the kernel releases
/// when the process ends, even by `kill -9`): a second `trainer run` into the same directory
/// fails at once instead of interleaving its files with the first.
fn lock(dir: &std::path::Path) -> Result<std::fs::File, PipelineError> {
    let p = dir.join(".lock");
    let f = std::fs::OpenOptions::new()
        .create(true)
        .truncate(false)
        .write(true)
        .open(&p)
        .map_err(|e| fail("setup", format!("{}: {e}", p.display())))?;
    match f.try_lock() {
        Ok(()) => Ok(f),
        Err(std::fs::TryLockError::WouldBlock) => Err(fail(
            "setup",
            format!(
                "{} is in use by another `trainer run` (lock {}); wait for it to finish or use another --out",
                dir.display(),
                p.display()
            ),
        )),
        Err(std::fs::TryLockError::Error(e)) => {
            Err(fail("setup", format!("{}: {e}", p.display())))
        }
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_stage_list_is_the_documented_order() {
        let names: Vec<&str> = super::stages::ALL.iter().map(|s| s.name).collect();
        assert_eq!(names, super::STAGES);
    }

    #[test]
    fn stale_temporaries_are_removed_and_nothing_else() {
        let dir = std::env::temp_dir().join(format!("ampc_stale_{}", std::process::id()));
        std::fs::create_dir_all(dir.join("plots")).unwrap();
        for f in [
            ".dataset.bin.77.tmp",
            "plots/.errors.png.77.tmp",
            "keep.tmp",
            ".keep",
        ] {
            std::fs::write(dir.join(f), "x").unwrap();
        }
        super::remove_stale_temporaries(&dir);
        assert!(!dir.join(".dataset.bin.77.tmp").exists());
        assert!(!dir.join("plots/.errors.png.77.tmp").exists());
        assert!(dir.join("keep.tmp").exists() && dir.join(".keep").exists());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_second_run_into_a_locked_directory_fails_at_once() {
        let dir = std::env::temp_dir().join(format!("ampc_lock_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let held = super::lock(&dir).unwrap();
        let e = super::lock(&dir).unwrap_err().to_string();
        assert!(e.contains("in use by another `trainer run`"), "{e}");
        drop(held);
        assert!(
            super::lock(&dir).is_ok(),
            "the lock is released with its file"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
