//! The seed study computed beside the stages between `train` and `seeds` ([`Beside`]).
//!
//! `seeds` reads only what `train` leaves (the dataset, the validation set, both nets) and
//! none of what `certify` … `closed_loop` write, and those stages leave a core idle for
//! seconds at a time (the refinement's serial retrainings). So once `train` is done, a
//! thread starts the study (`study::seeds::seed_study`, no progress bar) on the files as
//! they are then:
//! ```text
//! train ─┬─ certify → refine → statistical → export → closed_loop ─┬─ seeds (join) → plots
//!        └─ seed study (thread) ────────────────────────────────────┘
//! ```
//! The `seeds` stage takes the result only if its inputs (the hashes of those files and the
//! settings) are the ones the thread started from; otherwise it computes the study itself.
//! Each seed's nets and runs are pure functions of their inputs, so the file is the same
//! bytes either way. A run that fails in between leaves the thread to finish on its own
//! (it writes nothing).

use super::manifest::sha_file;
use super::{fail, PipelineError, Stage};
use crate::certify::Model;
use crate::data::dataset::Dataset;
use crate::io::RunDir;
use crate::learn::setpoint::Hold;
use crate::problem::ProblemConfig;
use crate::study::seeds::{seed_study, SeedRun};
use std::time::Instant;

/// A stage's inputs: name → hash (as `stages` computes them).
pub(super) type Inputs = std::collections::BTreeMap<String, String>;

/// The seed study: one pair of runs (nominal, regularized) per seed.
pub(super) type Study = Vec<[SeedRun; 2]>;

/// A seed study running on its own thread, and the `seeds` inputs it started from.
pub(crate) struct Beside {
    inputs: Inputs,
    idler: Idler,
    handle: std::thread::JoinHandle<(Result<Study, PipelineError>, f64)>,
}

impl Beside {
    /// Starts the study on the files of `dir` (the `seeds` stage's inputs `inputs`).
    pub(super) fn start(cfg: &ProblemConfig, dir: &RunDir, inputs: Inputs) -> Beside {
        let (cfg, dir) = (cfg.clone(), RunDir::new(dir.path().to_path_buf()));
        let idler = Idler::default();
        let tid = idler.clone();
        let handle = std::thread::spawn(move || {
            let t = Instant::now();
            // One thread of its own: on the shared pool its long jobs (a seed's training)
            // would hold the workers that the stages' short parallel jobs wait for.
            let r = match rayon::ThreadPoolBuilder::new()
                .num_threads(1)
                .start_handler(move |_| tid.record())
                .build()
            {
                Ok(pool) => pool.install(|| seed_study_of(&cfg, &dir, false)),
                Err(_) => seed_study_of(&cfg, &dir, false),
            };
            (r, t.elapsed().as_secs_f64())
        });
        Beside {
            inputs,
            idler,
            handle,
        }
    }

    /// The handle that moves the study's thread to idle priority ([`Idler`]).
    pub(super) fn idler(&self) -> Idler {
        self.idler.clone()
    }

    /// The study and its own seconds if it started from `inputs`, else `None` (after the
    /// thread ends: no second study competes with it).
    pub(super) fn take(self, inputs: &Inputs) -> Option<(Result<Study, PipelineError>, f64)> {
        let joined = self.handle.join();
        if self.inputs != *inputs {
            return None;
        }
        Some(match joined {
            Ok(r) => r,
            Err(_) => (
                Err(fail(
                    Stage::Seeds.name(),
                    "the seed study's thread panicked",
                )),
                0.0,
            ),
        })
    }
}

/// The study's worker thread, to be moved to idle priority while a stage leaves a core idle
/// for long stretches (the refinement's serial retrainings, `tiers::refine`): it then runs
/// only on a core nothing else wants, and the refinement's parallel labelling and bounding
/// get both cores. Elsewhere (no refinement: the quadrotor) it keeps its share, so it is
/// done before the stages reach `seeds`. Lowering is one-way (an unprivileged thread cannot
/// raise it back); the results are the same bytes at any priority.
#[derive(Clone, Default)]
pub(crate) struct Idler(std::sync::Arc<std::sync::atomic::AtomicI64>);

impl Idler {
    /// Records the calling thread (the study's worker) as the one to lower.
    fn record(&self) {
        self.0
            .store(this_thread(), std::sync::atomic::Ordering::SeqCst);
    }

    /// Moves the recorded thread to idle priority (Linux `SCHED_IDLE`; elsewhere, or before
    /// the thread is recorded, nothing).
    pub(super) fn lower(&self) {
        set_idle(self.0.load(std::sync::atomic::Ordering::SeqCst));
    }
}

/// The calling thread's id (0 where there is none to lower).
#[cfg(target_os = "linux")]
fn this_thread() -> i64 {
    // SAFETY: gettid has no preconditions.
    i64::from(unsafe { libc::gettid() })
}

#[cfg(not(target_os = "linux"))]
fn this_thread() -> i64 {
    0
}

/// Puts thread `tid` in the `SCHED_IDLE` class (0: nothing). A failure leaves it as it
/// was, which costs only time.
#[cfg(target_os = "linux")]
fn set_idle(tid: i64) {
    let Ok(tid) = libc::pid_t::try_from(tid) else {
        return;
    };
    if tid <= 0 {
        return;
    }
    let param = libc::sched_param { sched_priority: 0 };
    // SAFETY: sched_setscheduler only reads `param`, a valid sched_param.
    let _ = unsafe { libc::sched_setscheduler(tid, libc::SCHED_IDLE, &param) };
}

#[cfg(not(target_os = "linux"))]
fn set_idle(_tid: i64) {}

/// The seed study on the files of `d` (dataset, validation set, both nets), as the `seeds`
/// stage computes it in place.
pub(super) fn seed_study_of(
    cfg: &ProblemConfig,
    d: &RunDir,
    progress: bool,
) -> Result<Study, PipelineError> {
    let at = |p: &std::path::Path, e: &dyn std::fmt::Display| {
        fail(Stage::Seeds.name(), format!("{}: {e}", p.display()))
    };
    let dataset = |p: std::path::PathBuf| Dataset::load(&p).map_err(|e| fail(Stage::Seeds, e));
    let model = |p: std::path::PathBuf| Model::load(&p).map_err(|e| fail(Stage::Seeds, e));
    let (data, val) = (dataset(d.dataset())?, dataset(d.validation())?);
    let own = [model(d.model_nominal())?, model(d.model_regularized())?];
    let dh = sha_file(&d.dataset()).map_err(|e| at(&d.dataset(), &e))?;
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

    /// The policy line of the calling thread's scheduler statistics (Linux).
    #[cfg(target_os = "linux")]
    fn policy() -> String {
        std::fs::read_to_string("/proc/thread-self/sched")
            .unwrap()
            .lines()
            .find(|l| l.starts_with("policy"))
            .and_then(|l| l.split(':').nth(1))
            .unwrap()
            .trim()
            .to_string()
    }

    /// `lower` moves the recorded thread, and only it, to `SCHED_IDLE` (policy 5); before a
    /// thread is recorded it does nothing.
    #[cfg(target_os = "linux")]
    #[test]
    fn the_idler_lowers_the_recorded_thread_only() {
        let idler = Idler::default();
        idler.lower();
        assert_eq!(policy(), "0");
        let (tx, rx) = std::sync::mpsc::channel();
        let (go, wait) = std::sync::mpsc::channel::<()>();
        let recorded = idler.clone();
        let t = std::thread::spawn(move || {
            recorded.record();
            tx.send(policy()).unwrap();
            wait.recv().unwrap();
            policy()
        });
        assert_eq!(rx.recv().unwrap(), "0");
        idler.lower();
        go.send(()).unwrap();
        assert_eq!(t.join().unwrap(), "5");
        assert_eq!(policy(), "0", "the caller keeps its class");
    }

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
        assert!(Beside::start(&cfg, &dir, inputs).take(&other).is_none());
        let _ = std::fs::remove_dir_all(&root);
    }
}
