//! `trainer run`: one command from a problem file to a certified controller.
//!
//! Stages, each writing its artifacts under `DIR/<name>/` with a manifest
//! (`manifest_<stage>.json`: input hashes, settings, crate version, timing):
//! `sample` (dataset.bin/.csv) → `validate` (validation.bin: MPC labels of random states)
//! → `train` (model_nominal.bin, model_regularized.bin, same initial weights) → `certify`
//! (certificate.json, certificate_nominal.json) → `refine` (refine.json, refine/: local
//! certificates when Theorem 1 is vacuous and nx ≤ 3) → `statistical` (statistical.json,
//! certificate_statistical.json: the deployed controller on i.i.d. states, see `tiers`) →
//! `export` (weights.rs, weights.bin, export_report.json: the strongest non-vacuous band and
//! its tier, see `tiers` and `choice`, for controller-core) → `closed_loop`
//! (closed_loop.json, closed_loop_statistical.json) → `seeds` (seeds.json: both nets retrained from other seeds' initial
//! weights and simulated from the reference initial state) → `plots` (plots/*.svg,
//! plots/*.png) → `report` (report.md, report.html). A stage whose manifest matches its current inputs and whose
//! outputs exist is skipped; `force` redoes named stages (and, through the changed hashes,
//! everything downstream). Dataset generation resumes from its checkpoint when killed.

//!
//! Files: `stages` (each stage as a value: name, inputs, outputs, body), [`manifest`]
//! (skip-if-unchanged), `beside` (the seed study on its own thread from the end of `train`
//! on, handed to `seeds` when its inputs are unchanged), [`robust`] (the Corollary 1 design loop, which runs these stages on
//! the tightened problem). `pipeline` and the CLI are the only places that know every stage.
//!
//! **Library use.** [`run`] takes a problem file's text; [`run_problem`] a problem held in
//! memory — built in code, or with a plant implemented in Rust by the calling program
//! (`System::Custom`, see `problem::model::custom`): the same stages, the same files.
//! `RunOptions::until` stops after a stage (e.g. `export`: dataset → nets → certificates →
//! weights). The CLI cannot reopen a custom plant's files; the program that has the plant
//! can ([`ProblemConfig::from_toml_str_with`]).

pub(crate) mod api;
mod beside;
mod choice;
mod exported;
pub mod manifest;
pub mod robust;
mod safety;
pub use safety::{labelling_problem, CHECK_SLACK};
mod stages;
pub use stages::validation_config;
mod tiers;

use crate::io::{write_atomic, RunDir};
use crate::problem::ProblemConfig;
use crate::study::report::Timing;
use manifest::Ctx;
use std::collections::BTreeMap;
use std::path::PathBuf;

/// A stage of `trainer run`, in pipeline order (`Ord` is that order). Its name — the
/// spelling of `--force <stage>`, of `manifest_<stage>.json` and of the stage lines — is
/// [`Stage::name`]; [`str::parse`] reads it back.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Stage {
    /// The labelled sampling plan (`dataset.bin`, `dataset.csv`).
    Sample,
    /// MPC labels of random states (`validation.bin`).
    Validate,
    /// The nominal and regularized nets.
    Train,
    /// Theorem 1 for both nets.
    Certify,
    /// Local certificates where Theorem 1 is vacuous and nx ≤ 3 (`[refine] enabled`).
    Refine,
    /// The statistical tier of the deployed controller (`[certify] statistical`).
    Statistical,
    /// The strongest non-vacuous band's net for controller-core.
    Export,
    /// MPC and both nets in the closed loop.
    ClosedLoop,
    /// The nets from other seeds' initial weights.
    Seeds,
    /// The figures.
    Plots,
    /// The report, Markdown and HTML.
    Report,
}

impl Stage {
    /// The stages in order.
    pub const ALL: [Stage; 11] = [
        Stage::Sample,
        Stage::Validate,
        Stage::Train,
        Stage::Certify,
        Stage::Refine,
        Stage::Statistical,
        Stage::Export,
        Stage::ClosedLoop,
        Stage::Seeds,
        Stage::Plots,
        Stage::Report,
    ];

    /// The stage's name (`closed_loop` for [`Stage::ClosedLoop`]).
    pub const fn name(self) -> &'static str {
        match self {
            Stage::Sample => "sample",
            Stage::Validate => "validate",
            Stage::Train => "train",
            Stage::Certify => "certify",
            Stage::Refine => "refine",
            Stage::Statistical => "statistical",
            Stage::Export => "export",
            Stage::ClosedLoop => "closed_loop",
            Stage::Seeds => "seeds",
            Stage::Plots => "plots",
            Stage::Report => "report",
        }
    }
}

/// The names of the stages in order ([`Stage::ALL`]'s names).
pub const STAGES: [&str; 11] = {
    let mut names = [""; 11];
    let mut i = 0;
    while i < names.len() {
        names[i] = Stage::ALL[i].name();
        i += 1;
    }
    names
};

impl std::fmt::Display for Stage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A name that is not a stage's.
#[derive(Debug, Clone, thiserror::Error)]
#[error("unknown stage `{0}` (one of {list})", list = STAGES.join(", "))]
pub struct UnknownStage(pub String);

impl std::str::FromStr for Stage {
    type Err = UnknownStage;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Stage::ALL
            .into_iter()
            .find(|st| st.name() == s)
            .ok_or_else(|| UnknownStage(s.to_string()))
    }
}

/// A failure, naming the stage (or `setup`) and keeping its cause as the error's source.
#[derive(Debug, thiserror::Error)]
#[error("stage `{stage}` failed: {cause}")]
pub struct PipelineError {
    /// The stage (`setup` before the first stage).
    pub stage: String,
    /// What went wrong (names the file or setting).
    #[source]
    pub cause: Box<dyn std::error::Error + Send + Sync>,
}

/// A failure of `stage` (a [`Stage`] or `"setup"`) caused by `e` (an error, or a message).
fn fail(
    stage: impl std::fmt::Display,
    e: impl Into<Box<dyn std::error::Error + Send + Sync>>,
) -> PipelineError {
    PipelineError {
        stage: stage.to_string(),
        cause: e.into(),
    }
}

/// A cause that concerns a file (or names what was being done): that, then the error
/// (`"{context}: {source}"`).
#[derive(Debug, thiserror::Error)]
#[error("{context}: {source}")]
pub struct InContext {
    /// The file (or the files and what was done with them).
    pub context: String,
    /// What went wrong with it.
    #[source]
    pub source: Box<dyn std::error::Error + Send + Sync>,
}

/// A failure of `stage` with the file `path` (reading, writing or parsing it).
fn fail_at(
    stage: impl std::fmt::Display,
    path: &std::path::Path,
    e: impl Into<Box<dyn std::error::Error + Send + Sync>>,
) -> PipelineError {
    fail_in(stage, path.display(), e)
}

/// A failure of `stage` in `context` (what was being done, with which files).
fn fail_in(
    stage: impl std::fmt::Display,
    context: impl std::fmt::Display,
    e: impl Into<Box<dyn std::error::Error + Send + Sync>>,
) -> PipelineError {
    fail(
        stage,
        InContext {
            context: context.to_string(),
            source: e.into(),
        },
    )
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
    pub force: Vec<Stage>,
    /// Progress bars on a terminal.
    pub progress: bool,
    /// Called after each stage (for one summary line per stage).
    pub on_stage: Option<fn(&StageReport)>,
    /// Stop after this stage (default: run all).
    pub until: Option<Stage>,
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
    std::fs::create_dir_all(&dir).map_err(|e| fail_at("setup", &dir, e))?;
    let _lock = lock(&dir)?;
    remove_stale_temporaries(&dir);
    same_problem(&dir, cfg, opts)?;
    let dir = RunDir::new(dir);
    write_atomic(&dir.problem(), config_text.as_bytes()).map_err(|e| fail("setup", e))?;
    // With the safety study, the MPC imposes the device's online check (`labelling_problem`).
    let labelling = labelling_problem(cfg)?;
    let cfg = &labelling;
    let mut cx = Ctx {
        dir,
        opts,
        reports: Vec::new(),
    };
    // The seed study, started beside `train` (or once it is done) and joined in `seeds`
    // (`beside`).
    let mut beside: Option<beside::Beside> = None;
    for stage in &stages::ALL {
        let inputs = (stage.inputs)(&cx, cfg)?;
        let outputs = (stage.outputs)();
        let outputs: Vec<&str> = outputs.iter().map(String::as_str).collect();
        let study_after = opts.until.is_none_or(|u| u >= Stage::Seeds);
        if stage.stage == Stage::Train
            && study_after
            && cx.will_run(Stage::Train, &inputs, &outputs)
        {
            // New nets, so a new study: its trainings start beside `train` itself, whose
            // two nets rarely take the same time (the faster one's core would idle).
            beside = Some(beside::Beside::start_early(cfg, &cx.dir));
        }
        let seeds = match stage.stage {
            Stage::Seeds => beside.take().map(|b| (b, inputs.clone())),
            _ => None,
        };
        let env = Env {
            cfg,
            progress: opts.progress,
            seeds: std::cell::RefCell::new(seeds),
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
        cx.stage(stage.stage, inputs, &outputs, |d| (stage.body)(&env, d))?;
        if opts.until == Some(stage.stage) {
            break;
        }
        if stage.stage == Stage::Train && study_after {
            beside = start_seeds(&cx, cfg, beside.take())?;
        }
    }
    Ok(cx.reports)
}

/// The seed study on its own thread ([`beside`]) when the `seeds` stage will run (forced,
/// or its inputs changed), else `None`: `early` (started beside `train`) handed the
/// stage's inputs, or a study started now. An early study that is not needed is cancelled.
fn start_seeds(
    cx: &Ctx,
    cfg: &ProblemConfig,
    early: Option<beside::Beside>,
) -> Result<Option<beside::Beside>, PipelineError> {
    let Some(step) = stages::ALL.iter().find(|s| s.stage == Stage::Seeds) else {
        return Ok(None);
    };
    let inputs = (step.inputs)(cx, cfg)?;
    let outputs = (step.outputs)();
    let outputs: Vec<&str> = outputs.iter().map(String::as_str).collect();
    if !cx.will_run(Stage::Seeds, &inputs, &outputs) {
        // An early study dropped unsent is cancelled: its thread ends after the training
        // in progress.
        drop(early);
        return Ok(None);
    }
    Ok(Some(match early {
        Some(b) => b.go(inputs),
        None => beside::Beside::start(cfg, &cx.dir, inputs),
    }))
}

/// Removes the temporary files (`.<name>.<pid>.tmp`, see `io::write_atomic`) that a run
/// killed mid-write left in the run directory or its `plots/`: with the lock held, no other
/// process is writing them.
fn remove_stale_temporaries(dir: &std::path::Path) {
    for d in [dir.to_path_buf(), RunDir::new(dir).plots()] {
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
    let p = RunDir::new(dir).problem();
    let Ok(text) = std::fs::read_to_string(&p) else {
        return Ok(());
    };
    let forced = opts.force.contains(&Stage::Sample);
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
        .map_err(|e| fail_at("setup", &p, e))?;
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
            Err(fail_at("setup", &p, e))
        }
    }
}

/// What a stage's body sees: the problem, whether to draw progress bars, and the timings of
/// the stages before it (for the report).
pub(super) struct Env<'a> {
    pub(super) cfg: &'a ProblemConfig,
    pub(super) progress: bool,
    pub(super) timings: Vec<Timing>,
    /// For the `seeds` stage: the study running beside the earlier stages ([`beside`]) and
    /// the stage's inputs, to be joined inside the stage (its wait counts in the stage's
    /// seconds) and taken if it started from those inputs.
    pub(super) seeds: std::cell::RefCell<Option<(beside::Beside, beside::Inputs)>>,
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_stage_list_is_the_documented_order() {
        let names: Vec<super::Stage> = super::stages::ALL.iter().map(|s| s.stage).collect();
        assert_eq!(names, super::Stage::ALL);
        let spelled: Vec<&str> = super::Stage::ALL.iter().map(|s| s.name()).collect();
        assert_eq!(spelled, super::STAGES);
        for st in super::Stage::ALL {
            assert_eq!(st.name().parse::<super::Stage>().unwrap(), st);
        }
        assert!("closed-loop".parse::<super::Stage>().is_err());
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
