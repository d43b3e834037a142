//! `trainer compare`: the paper's Table I over seeds. For each seed trains a nominal and a
//! regularized net on `--data` from the same initial weights and certifies both; prints a
//! Markdown table of median [min, max] to stdout and, with `--json`, writes the per-seed
//! results there.

use super::common::{med_range, opt, problem_for_data, refuse_overwrite, sha256_file};
use anyhow::{bail, Context, Result};
use rayon::prelude::*;
use std::path::{Path, PathBuf};
use trainer::certify::certificate::{certify, CertifyOptions};
use trainer::data::dataset::Dataset;
use trainer::learn::setpoint::Hold;
use trainer::learn::train::{label_random_states, train, TrainOptions, TrainSet};
use trainer::problem::ProblemConfig;

/// One row of the seed comparison.
#[derive(serde::Serialize)]
struct SeedResult {
    seed: u64,
    kind: &'static str,
    r2_validation: f64,
    eps_d: f64,
    median_error: f64,
    l_nn: f64,
    l_nn_lipsdp: f64,
    l_nn_naive: f64,
    l_nn_lower: f64,
    eps: f64,
}

/// What every seed's training shares: the problem, the dataset and its file hash, the
/// training and validation sets.
struct Shared<'a> {
    cfg: &'a ProblemConfig,
    d: &'a Dataset,
    dhash: &'a str,
    set: &'a TrainSet,
    val: &'a TrainSet,
    hold: Option<&'a Hold>,
}

/// The arguments of `trainer compare` (their doc comments are the help text).
#[derive(clap::Args)]
pub(super) struct Args {
    /// Problem file (default: the embedded pendulum).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Dataset file.
    #[arg(long)]
    data: PathBuf,
    /// Number of seeds (0..seeds).
    #[arg(long, default_value_t = 10)]
    seeds: u64,
    /// Write the per-seed results as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
}

impl Args {
    /// Trains and certifies both nets over the seeds and prints the table.
    pub(super) fn run(self) -> Result<()> {
        refuse_overwrite(&[opt(&self.json)], &[&self.data, opt(&self.config)])?;
        execute(
            self.config.as_deref(),
            &self.data,
            self.seeds,
            self.json.as_deref(),
        )
    }
}

pub(super) fn execute(
    config: Option<&Path>,
    data: &Path,
    seeds: u64,
    json: Option<&Path>,
) -> Result<()> {
    let d = Dataset::load(data)?;
    let cfg = problem_for_data(config, data, &d)?;
    if d.header.problem_hash != cfg.problem_hash() {
        bail!(
            "{} was labelled for another problem than the config's {}",
            data.display(),
            cfg.name
        );
    }
    if seeds == 0 {
        bail!("--seeds must be at least 1");
    }
    let set = TrainSet::from_dataset(&d);
    let val = label_random_states(
        &cfg,
        cfg.training.validation_n,
        cfg.training.validation_seed,
    );
    let dhash = sha256_file(data)?;
    let hold = Hold::if_enabled(&cfg, cfg.training.hold_setpoint)?;
    let shared = Shared {
        cfg: &cfg,
        d: &d,
        dhash: &dhash,
        set: &set,
        val: &val,
        hold: hold.as_ref(),
    };
    let jobs: Vec<(u64, bool)> = (0..seeds).flat_map(|s| [(s, true), (s, false)]).collect();
    let results: Vec<SeedResult> = jobs
        .par_iter()
        .map(|&(seed, nominal)| train_seed(&shared, seed, nominal))
        .collect::<Result<_, _>>()
        .with_context(|| format!("cannot certify the nets trained on {}", data.display()))?;
    print_table(&results);
    println!(
        "median [min, max] over seeds 0..{}; {} labelled training points, {} validation states",
        seeds,
        set.len(),
        val.len()
    );
    if let Some(p) = json {
        trainer::io::write_atomic(p, serde_json::to_string_pretty(&results)?.as_bytes())?;
    }
    Ok(())
}

/// Trains the nominal or the regularized net of one seed and certifies it.
fn train_seed(
    shared: &Shared,
    seed: u64,
    nominal: bool,
) -> Result<SeedResult, trainer::certify::certificate::MismatchError> {
    let Shared {
        cfg,
        d,
        dhash,
        set,
        val,
        hold,
    } = *shared;
    let mut st = cfg.training.clone();
    st.seed = seed;
    let m = train(
        &st,
        &TrainOptions {
            nominal,
            progress: None,
            hold: hold.cloned(),
            keep_best: None,
        },
        set,
        val,
        (&cfg.domain.lo, &cfg.domain.hi),
        (&cfg.ocp.u_lo, &cfg.ocp.u_hi),
        &d.header.problem_hash,
        dhash,
    );
    let c = certify(
        &m,
        d,
        cfg,
        &CertifyOptions {
            extra: Some(val.clone()),
            ..Default::default()
        },
    )?;
    Ok(SeedResult {
        seed,
        kind: if nominal { "nominal" } else { "regularized" },
        r2_validation: m.validation_stats.r2,
        eps_d: c.eps_d,
        median_error: m.train_stats.median,
        l_nn: c.l_nn,
        l_nn_lipsdp: c.l_nn_lipsdp,
        l_nn_naive: c.l_nn_naive,
        l_nn_lower: c.l_nn_lower,
        eps: c.eps,
    })
}

/// The Markdown table: one row per kind of net (median [min, max] over the seeds) beside
/// the paper's values.
fn print_table(results: &[SeedResult]) {
    println!("| net | validation R² | ε_D | L_NN (tightest sound) | LipSDP | naive | sampled lower | ε (Thm 1) | paper: R², ε_D, L |");
    println!("|---|---|---|---|---|---|---|---|---|");
    for (kind, paper) in [
        ("nominal", "0.985, 3.231, 384.01"),
        ("regularized", "0.992, 1.823, 207.66"),
    ] {
        let rs: Vec<&SeedResult> = results.iter().filter(|r| r.kind == kind).collect();
        let col =
            |f: fn(&SeedResult) -> f64| med_range(&rs.iter().map(|r| f(r)).collect::<Vec<_>>());
        println!(
            "| {kind} | {} | {} | {} | {} | {} | {} | {} | {paper} |",
            col(|r| r.r2_validation),
            col(|r| r.eps_d),
            col(|r| r.l_nn),
            col(|r| r.l_nn_lipsdp),
            col(|r| r.l_nn_naive),
            col(|r| r.l_nn_lower),
            col(|r| r.eps),
        );
    }
}
