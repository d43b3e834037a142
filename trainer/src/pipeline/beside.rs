//! The seed study computed beside the stages from `train` to `closed_loop` ([`Beside`]).
//!
//! `seeds` reads only what `sample`, `validate` and `train` leave (the dataset, the
//! validation set, both nets) and none of what `certify` … `closed_loop` write, and those
//! stages leave a core idle for seconds at a time: `train`'s two nets rarely take the same
//! time, and the refinement's retrainings are serial. So the study runs on a thread of its
//! own, in two halves:
//! ```text
//! validate ─┬─ train ───────┬─ certify → refine → … → closed_loop ─┬─ seeds (join) → plots
//!           └─ first half ──┴─ second half ────────────────────────┘
//!              (other seeds' trainings: dataset, validation set)
//!                             (every net's run: needs train's nets)
//! ```
//! The first half starts with `train` when `train` will run (new nets mean a new study);
//! otherwise the whole study starts once `train` is done, if `seeds` will run. The second
//! half starts when `train` hands over the `seeds` stage's inputs, and reads the nets as
//! they are then; a study never handed over is cancelled after its first half. If the
//! dataset or the validation set changed between the halves, the second half computes the
//! whole study afresh. The `seeds` stage takes the result only if its inputs (the hashes of
//! those files and the settings) are the ones handed over; otherwise it computes the study
//! itself. Each seed's nets and runs are pure functions of their inputs, so the file is the
//! same bytes either way. A run that fails in between leaves the thread to finish on its
//! own (it writes nothing).

use super::manifest::sha_file;
use super::{fail, PipelineError, Stage};
use crate::certify::Model;
use crate::data::dataset::Dataset;
use crate::io::RunDir;
use crate::learn::setpoint::Hold;
use crate::problem::ProblemConfig;
use crate::study::seeds::{retrain_seeds, seed_study, simulate_seeds, SeedRun};
use std::time::Instant;

/// A stage's inputs: name → hash (as `stages` computes them).
pub(super) type Inputs = std::collections::BTreeMap<String, String>;

/// The seed study: one pair of runs (nominal, regularized) per seed.
pub(super) type Study = Vec<[SeedRun; 2]>;

/// A seed study running on its own thread, and the `seeds` inputs it was handed.
pub(crate) struct Beside {
    /// The `seeds` stage's inputs, once handed over ([`Beside::go`]).
    inputs: Option<Inputs>,
    /// Lets the second half start; dropped unsent, it cancels the study.
    go: Option<std::sync::mpsc::Sender<()>>,
    /// Set when the study is cancelled: the first half skips its remaining trainings.
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
    handle: Option<std::thread::JoinHandle<(Result<Study, PipelineError>, f64)>>,
}

impl Drop for Beside {
    /// A study dropped before it was handed over is cancelled (its thread ends after the
    /// training in progress; it writes nothing).
    fn drop(&mut self) {
        if self.go.is_some() {
            self.stop.store(true, std::sync::atomic::Ordering::SeqCst);
        }
    }
}

impl Beside {
    /// Starts the study's first half (the other seeds' trainings, which need only the
    /// dataset and the validation set) on the files of `dir`; the second half (the runs,
    /// which need the run's own nets) waits for [`go`](Self::go).
    pub(super) fn start_early(cfg: &ProblemConfig, dir: &RunDir) -> Beside {
        let (cfg, dir) = (cfg.clone(), RunDir::new(dir.path().to_path_buf()));
        let (go, wait) = std::sync::mpsc::channel::<()>();
        let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let stopped = stop.clone();
        let handle = std::thread::spawn(move || {
            let body = move || {
                let t = Instant::now();
                let first = first_half(&cfg, &dir, &stopped);
                let worked = t.elapsed();
                if wait.recv().is_err() {
                    return (Err(fail(Stage::Seeds, "the seed study was cancelled")), 0.0);
                }
                let t = Instant::now();
                let r = first.and_then(|first| second_half(&cfg, &dir, first));
                (r, (worked + t.elapsed()).as_secs_f64())
            };
            // One thread of its own: on the shared pool its long jobs (a seed's training)
            // would hold the workers that the stages' short parallel jobs wait for.
            match rayon::ThreadPoolBuilder::new().num_threads(1).build() {
                Ok(pool) => pool.install(body),
                Err(_) => body(),
            }
        });
        Beside {
            inputs: None,
            go: Some(go),
            stop,
            handle: Some(handle),
        }
    }

    /// Starts the whole study on the files of `dir` (the `seeds` stage's inputs `inputs`).
    pub(super) fn start(cfg: &ProblemConfig, dir: &RunDir, inputs: Inputs) -> Beside {
        Self::start_early(cfg, dir).go(inputs)
    }

    /// Hands the study the `seeds` stage's inputs (the files as they are after `train`)
    /// and lets its second half run.
    pub(super) fn go(mut self, inputs: Inputs) -> Beside {
        if let Some(go) = self.go.take() {
            // A thread that has ended (it panicked) is reported by `take`.
            let _ = go.send(());
        }
        self.inputs = Some(inputs);
        self
    }

    /// The study and its own seconds (its computing, not its wait for [`go`](Self::go)) if
    /// it was handed `inputs`, else `None` (after the thread ends: no second study
    /// competes with it).
    pub(super) fn take(mut self, inputs: &Inputs) -> Option<(Result<Study, PipelineError>, f64)> {
        // Never handed over: cancel (the sender dropped), then wait for the thread.
        if self.go.take().is_some() {
            self.stop.store(true, std::sync::atomic::Ordering::SeqCst);
        }
        let joined = self.handle.take().map(std::thread::JoinHandle::join);
        if self.inputs.as_ref() != Some(inputs) {
            return None;
        }
        Some(match joined {
            Some(Ok(r)) => r,
            _ => (
                Err(fail(
                    Stage::Seeds.name(),
                    "the seed study's thread panicked",
                )),
                0.0,
            ),
        })
    }
}

/// The first half's trainings and the hashes of the files they were trained on.
struct FirstHalf {
    nets: Vec<Option<Model>>,
    dataset: String,
    validation: String,
}

/// The other seeds' nets ([`retrain_seeds`]) on the dataset and validation set of `d`;
/// once `stop` is set, the trainings not begun are skipped (the study is cancelled).
fn first_half(
    cfg: &ProblemConfig,
    d: &RunDir,
    stop: &std::sync::atomic::AtomicBool,
) -> Result<FirstHalf, PipelineError> {
    let (data, val, dh, vh) = read_sets(d)?;
    let hold =
        Hold::if_enabled(cfg, cfg.training.hold_setpoint).map_err(|e| fail(Stage::Seeds, e))?;
    let bar = indicatif::ProgressBar::hidden();
    Ok(FirstHalf {
        nets: retrain_seeds(cfg, (&data, &val), &dh, hold.as_ref(), (&bar, Some(stop))),
        dataset: dh,
        validation: vh,
    })
}

/// The runs of every net ([`simulate_seeds`]) with the run's own nets as `d` holds them
/// now; if the dataset or the validation set changed since the first half, the whole study
/// afresh.
fn second_half(cfg: &ProblemConfig, d: &RunDir, first: FirstHalf) -> Result<Study, PipelineError> {
    let hash = |p: std::path::PathBuf| sha_file(&p).map_err(|e| at(&p, &e));
    if hash(d.dataset())? != first.dataset || hash(d.validation())? != first.validation {
        return seed_study_of(cfg, d, false);
    }
    let own = own_nets(d)?;
    let bar = indicatif::ProgressBar::hidden();
    Ok(simulate_seeds(cfg, &own, &first.nets, &bar))
}

/// An error of the `seeds` stage naming the file `p`.
fn at(p: &std::path::Path, e: &dyn std::fmt::Display) -> PipelineError {
    fail(Stage::Seeds.name(), format!("{}: {e}", p.display()))
}

/// The dataset and the validation set of `d`, and the hashes of their files.
fn read_sets(d: &RunDir) -> Result<(Dataset, Dataset, String, String), PipelineError> {
    let dataset = |p: std::path::PathBuf| Dataset::load(&p).map_err(|e| fail(Stage::Seeds, e));
    let (data, val) = (dataset(d.dataset())?, dataset(d.validation())?);
    let dh = sha_file(&d.dataset()).map_err(|e| at(&d.dataset(), &e))?;
    let vh = sha_file(&d.validation()).map_err(|e| at(&d.validation(), &e))?;
    Ok((data, val, dh, vh))
}

/// The run's own nets, [nominal, regularized].
fn own_nets(d: &RunDir) -> Result<[Model; 2], PipelineError> {
    let model = |p: std::path::PathBuf| Model::load(&p).map_err(|e| fail(Stage::Seeds, e));
    Ok([model(d.model_nominal())?, model(d.model_regularized())?])
}

/// The seed study on the files of `d` (dataset, validation set, both nets), as the `seeds`
/// stage computes it in place.
pub(super) fn seed_study_of(
    cfg: &ProblemConfig,
    d: &RunDir,
    progress: bool,
) -> Result<Study, PipelineError> {
    let (data, val, dh, _) = read_sets(d)?;
    let own = own_nets(d)?;
    let hold =
        Hold::if_enabled(cfg, cfg.training.hold_setpoint).map_err(|e| fail(Stage::Seeds, e))?;
    Ok(seed_study(
        cfg,
        &data,
        &val,
        &dh,
        &own,
        hold.as_ref(),
        progress,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The study on its own one-thread pool (`Beside`) is the same bytes as the study on the
    /// shared pool, and it is handed over only for the inputs it started from.
    #[test]
    fn the_study_beside_is_the_study_in_place() {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../configs/double_integrator.toml"
        );
        let text = std::fs::read_to_string(path)
            .unwrap()
            .replace("counts = [21, 11]", "counts = [9, 5]")
            + "\n[training]\nepochs = 60\nbatch_size = 9\nvalidation_n = 40\n"
            + "\n[closed_loop]\nsteps = 30\nseeds = 3\n";
        let cfg = ProblemConfig::from_toml_str(&text, "small double integrator").unwrap();
        let root = std::env::temp_dir().join(format!("ampc-beside-{}", std::process::id()));
        let opts = crate::pipeline::RunOptions {
            root: root.clone(),
            until: Some(Stage::Train),
            ..Default::default()
        };
        crate::pipeline::run(&cfg, &text, &opts).unwrap();
        let dir = RunDir::new(root.join(&cfg.name));
        let here = seed_study_of(&cfg, &dir, false).unwrap();
        let inputs: Inputs = [("a".to_string(), "1".to_string())].into();
        let (there, secs) = Beside::start(&cfg, &dir, inputs.clone())
            .take(&inputs)
            .expect("the same inputs");
        let json = |s: &Study| serde_json::to_string(s).unwrap();
        assert_eq!(json(&there.unwrap()), json(&here));
        assert!(secs > 0.0);
        let other: Inputs = [("a".to_string(), "2".to_string())].into();
        assert!(Beside::start(&cfg, &dir, inputs.clone())
            .take(&other)
            .is_none());
        // Started early (before the nets exist in their final form), handed over later: the
        // second half reads the nets as they are at the hand-over.
        let nets = [dir.model_nominal(), dir.model_regularized()];
        let kept: Vec<Vec<u8>> = nets.iter().map(|p| std::fs::read(p).unwrap()).collect();
        for p in &nets {
            std::fs::write(p, b"not yet").unwrap();
        }
        let early = Beside::start_early(&cfg, &dir);
        std::thread::sleep(std::time::Duration::from_millis(50));
        for (p, k) in nets.iter().zip(&kept) {
            std::fs::write(p, k).unwrap();
        }
        let (early, _) = early
            .go(inputs.clone())
            .take(&inputs)
            .expect("the same inputs");
        assert_eq!(json(&early.unwrap()), json(&here));
        // Never handed over: cancelled, nothing taken; a cancelled first half trains nothing.
        assert!(Beside::start_early(&cfg, &dir).take(&inputs).is_none());
        let stopped = std::sync::atomic::AtomicBool::new(true);
        let none = first_half(&cfg, &dir, &stopped).unwrap();
        assert_eq!(none.nets.len(), 6);
        assert!(none.nets.iter().all(Option::is_none));
        // A dataset changed between the halves: the study is computed afresh on the new
        // one (here the validation set's file in its place), not from the first half.
        let data = std::fs::read(dir.dataset()).unwrap();
        let first = first_half(&cfg, &dir, &Default::default()).unwrap();
        std::fs::copy(dir.validation(), dir.dataset()).unwrap();
        let afresh = json(&seed_study_of(&cfg, &dir, false).unwrap());
        assert_ne!(afresh, json(&here));
        assert_eq!(json(&second_half(&cfg, &dir, first).unwrap()), afresh);
        std::fs::write(dir.dataset(), data).unwrap();
        let _ = std::fs::remove_dir_all(&root);
    }
}
