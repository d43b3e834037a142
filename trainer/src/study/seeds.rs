//! The seed study (`seeds.json`): both nets retrained from `closed_loop.seeds` training
//! seeds' initial weights, each simulated from the reference initial state — the spread of
//! R², ε_D and the closed loop over seeds (Table II as median [min, max]).

use crate::certify::Model;
use crate::data::dataset::Dataset;
use crate::learn::setpoint::Hold;
use crate::learn::train::{train, TrainOptions, TrainSet};
use crate::mpc::law::MpcLaw;
use crate::problem::ProblemConfig;
use crate::study::closed_loop::{simulate, Controller, Run, SimSettings};
use crate::study::scenarios::initial_states;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// One net of one seed in the seed study.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SeedRun {
    /// Training seed (initial weights and shuffling).
    pub seed: u64,
    /// `nominal` or `regularized`.
    pub kind: String,
    /// R² on the validation states.
    pub r2_validation: f64,
    /// ε_D on the dataset.
    pub eps_d: f64,
    /// Closed loop from the reference initial state (nominal plant, no noise).
    pub run: Run,
}

/// The seed study: for `closed_loop.seeds` seeds starting at `training.seed`, both nets
/// (the run's own models for the first seed, freshly trained ones otherwise) simulated from
/// the reference initial state. Returned per seed: [nominal, regularized]. `hold` is the
/// setpoint hold of the run's nets (`training.hold_setpoint`), applied to the other seeds'
/// nets too. `progress` draws a bar over the trainings and runs. The same as
/// [`simulate_seeds`] of [`retrain_seeds`] (the two halves, which the pipeline runs apart).
pub fn seed_study(
    cfg: &ProblemConfig,
    data: &Dataset,
    validation: &Dataset,
    dataset_hash: &str,
    own: &[Model; 2],
    hold: Option<&Hold>,
    progress: bool,
) -> Vec<[SeedRun; 2]> {
    let bar = bar(cfg, progress);
    let nets = retrain_seeds(cfg, (data, validation), dataset_hash, hold, (&bar, None));
    let out = simulate_seeds(cfg, own, &nets, &bar);
    bar.finish_and_clear();
    out
}

/// The (seed, nominal) jobs of the study, in order: per seed, nominal then regularized.
fn jobs(cfg: &ProblemConfig) -> Vec<(u64, bool)> {
    let n = cfg.closed_loop.seeds.max(1) as u64;
    let base = cfg.training.seed;
    (0..n)
        .flat_map(|k| [(base + k, true), (base + k, false)])
        .collect()
}

/// The progress bar over the study's trainings and runs (hidden unless `progress`).
pub fn bar(cfg: &ProblemConfig, progress: bool) -> indicatif::ProgressBar {
    if !progress {
        return indicatif::ProgressBar::hidden();
    }
    let b = indicatif::ProgressBar::new(2 * jobs(cfg).len() as u64);
    b.set_style(
        indicatif::ProgressStyle::with_template(
            "{spinner} [      seeds] [{bar:30}] {pos}/{len} nets trained and simulated  ETA {eta}",
        )
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
        .progress_chars("=> "),
    );
    b
}

/// The study's first half, which needs only the dataset and the validation set (`data`):
/// per job, the net of that seed trained afresh — `None` for the first seed, whose nets are
/// the run's own. Once `stop` (if given) is set, the trainings not yet begun are skipped
/// (`None`): the caller has cancelled the study and discards the result.
pub fn retrain_seeds(
    cfg: &ProblemConfig,
    (data, validation): (&Dataset, &Dataset),
    dataset_hash: &str,
    hold: Option<&Hold>,
    (bar, stop): (
        &indicatif::ProgressBar,
        Option<&std::sync::atomic::AtomicBool>,
    ),
) -> Vec<Option<Model>> {
    let stopped = || stop.is_some_and(|s| s.load(std::sync::atomic::Ordering::SeqCst));
    let base = cfg.training.seed;
    let (set, vset) = (
        TrainSet::from_dataset(data),
        TrainSet::from_dataset(validation),
    );
    jobs(cfg)
        .par_iter()
        .map(|&(seed, nominal)| {
            let trained = (seed != base && !stopped()).then(|| {
                let mut st = cfg.training.clone();
                st.seed = seed;
                train(
                    &st,
                    &TrainOptions {
                        nominal,
                        progress: None,
                        hold: hold.cloned(),
                        keep_best: None,
                    },
                    &set,
                    &vset,
                    (&cfg.domain.lo, &cfg.domain.hi),
                    (&cfg.ocp.u_lo, &cfg.ocp.u_hi),
                    &data.header.problem_hash,
                    dataset_hash,
                )
            });
            bar.inc(1);
            trained
        })
        .collect()
}

/// The study's second half: every job's net ([`retrain_seeds`]'s, or `own` for the first
/// seed) simulated from the reference initial state.
pub fn simulate_seeds(
    cfg: &ProblemConfig,
    own: &[Model; 2],
    nets: &[Option<Model>],
    bar: &indicatif::ProgressBar,
) -> Vec<[SeedRun; 2]> {
    let x0 = initial_states(cfg).swap_remove(0);
    let s = SimSettings {
        steps: cfg.closed_loop.steps,
        noise: vec![],
        seed: 0,
        mass_mismatch: 0.0,
        mismatch_parameter: None,
        disturbance: Default::default(),
    };
    let jobs = jobs(cfg);
    let runs: Vec<SeedRun> = jobs
        .par_iter()
        .zip(nets)
        .map(|(&(seed, nominal), trained)| {
            let m = trained.as_ref().unwrap_or(&own[usize::from(!nominal)]);
            let mut law = MpcLaw::new(cfg);
            // No certificate for the extra seeds: the band check is off (ε = ∞) for all.
            let run = simulate(
                cfg,
                &mut law,
                &Controller::Net(&m.mlp, f64::INFINITY, None),
                &x0,
                &s,
            );
            bar.inc(1);
            SeedRun {
                seed,
                kind: if nominal { "nominal" } else { "regularized" }.into(),
                r2_validation: m.validation_stats.r2,
                eps_d: m.train_stats.max,
                run,
            }
        })
        .collect();
    let mut it = runs.into_iter();
    let mut out = Vec::new();
    while let (Some(a), Some(b)) = (it.next(), it.next()) {
        out.push([a, b]);
    }
    out
}
