//! `trainer run`: the whole pipeline of a problem file (`config`, default the embedded
//! pendulum) into `<out>/<name>/`, each stage skipped when its inputs are unchanged; with
//! a robust design (`--robust-eps` or `[robust] eps`) also the robust loop into
//! `<out>/<name>/robust/`. Stage lines go to stderr, the robust summary to stdout.

use anyhow::{Context, Result};
use std::io::IsTerminal;
use std::path::Path;
use std::path::PathBuf;
use trainer::pipeline::{RunOptions, Stage, StageReport, STAGES};
use trainer::problem::ProblemConfig;

/// The arguments of `trainer run` (their doc comments are the help text).
#[derive(clap::Args)]
pub(super) struct Args {
    /// Problem file (default: the embedded pendulum).
    config: Option<PathBuf>,
    /// Problem file, as a flag (the same as the positional argument).
    #[arg(long = "config", id = "config_flag", conflicts_with = "config")]
    config_flag: Option<PathBuf>,
    /// Root directory of runs; the run goes to `<out>/<name>/`.
    #[arg(long, default_value = "runs")]
    out: PathBuf,
    /// Redo a stage even if its inputs are unchanged (repeatable).
    #[arg(long, value_parser = stage_parser())]
    force: Vec<Stage>,
    /// No progress bars or stage lines.
    #[arg(long, short, conflicts_with = "verbose")]
    quiet: bool,
    /// Robust design for this input error ε (overrides `robust.eps`): tightened MPC,
    /// data, training, certificate and the robust closed-loop study in `<out>/<name>/robust/`.
    #[arg(long)]
    robust_eps: Option<f64>,
    /// Also list each stage's input hashes and output files.
    #[arg(long, short)]
    verbose: bool,
    /// Stop after this stage (a later `trainer run` resumes from there).
    #[arg(long, value_parser = stage_parser())]
    until: Option<Stage>,
}

impl Args {
    /// Runs the whole pipeline (and the robust loop when asked).
    pub(super) fn run(self) -> Result<()> {
        execute(
            self.config.or(self.config_flag).as_deref(),
            &self.out,
            &self.force,
            self.quiet,
            self.verbose,
            (self.robust_eps, self.until),
        )
    }
}

pub(super) fn execute(
    config: Option<&Path>,
    out: &Path,
    force: &[Stage],
    quiet: bool,
    verbose: bool,
    (robust_eps, until): (Option<f64>, Option<Stage>),
) -> Result<()> {
    let (mut cfg, text) = read_problem(config)?;
    if let Some(e) = robust_eps {
        cfg.robust.eps = e;
        cfg.validate().context("--robust-eps")?;
    }
    // The nominal pipeline never sees the robust settings (its files stay byte-identical).
    let robust = std::mem::take(&mut cfg.robust);
    let t = std::time::Instant::now();
    let opts = RunOptions {
        root: out.to_path_buf(),
        force: force.to_vec(),
        progress: !quiet && std::io::stderr().is_terminal(),
        on_stage: match (quiet, verbose) {
            (true, _) => None,
            (false, true) => Some(print_stage_verbose),
            (false, false) => Some(print_stage),
        },
        until,
    };
    trainer::pipeline::run(&cfg, &text, &opts)?;
    if !quiet {
        eprintln!(
            "run {} finished in {:.2} s -> {}",
            cfg.name,
            t.elapsed().as_secs_f64(),
            out.join(&cfg.name).display()
        );
    }
    if robust.enabled() && until.is_none() {
        cfg.robust = robust;
        robust_run(&cfg, &opts, out, quiet)?;
    }
    Ok(())
}

/// `--force`'s values: the stage names ([`Stage::name`]), listed in the help.
fn stage_parser() -> impl clap::builder::TypedValueParser<Value = Stage> {
    use clap::builder::TypedValueParser;
    clap::builder::PossibleValuesParser::new(STAGES).try_map(|s| s.parse::<Stage>())
}

/// The problem file and its text (the pipeline hashes the text), or the embedded pendulum.
fn read_problem(config: Option<&Path>) -> Result<(ProblemConfig, String)> {
    Ok(match config {
        Some(p) => {
            let text = std::fs::read_to_string(p)
                .with_context(|| format!("cannot read problem file {}", p.display()))?;
            (
                super::common::warn_plant(ProblemConfig::from_toml_str(
                    &text,
                    &p.display().to_string(),
                )?),
                text,
            )
        }
        None => (
            super::common::embedded_pendulum(),
            trainer::problem::PENDULUM_TOML.to_string(),
        ),
    })
}

/// One line per stage: name, done or skipped, seconds, summary.
fn print_stage(r: &StageReport) {
    if r.skipped {
        eprintln!(
            "[{:>11}] skipped  {}  (took {:.2} s when it ran)",
            r.stage, r.summary, r.seconds
        );
    } else {
        eprintln!(
            "[{:>11}] done    {:.2} s  {}",
            r.stage, r.seconds, r.summary
        );
    }
}

/// The stage line, then the stage's input hashes and output files.
fn print_stage_verbose(r: &StageReport) {
    print_stage(r);
    for (k, h) in &r.inputs {
        eprintln!("              input  {k} {}", &h[..h.len().min(16)]);
    }
    for o in &r.outputs {
        eprintln!("              output {o}");
    }
}

/// The robust design loop of `run --robust-eps` (or `[robust] eps`), with its summary.
fn robust_run(cfg: &ProblemConfig, opts: &RunOptions, out: &Path, quiet: bool) -> Result<()> {
    if !quiet {
        eprintln!(
            "robust design for ε = {} -> {}",
            cfg.robust.eps,
            out.join(&cfg.name).join("robust").display()
        );
    }
    let r = trainer::pipeline::robust::run(cfg, opts)?;
    let tb = &r.design.tube;
    println!(
        "robust design ε = {}: ρ = {:.4}, w̄ = {:.4e} ({:?}), tightening at N: x {:?}",
        tb.eps,
        tb.rho,
        tb.w,
        tb.bound,
        tb.x_margin
            .iter()
            .map(|m| m * tb.s[tb.s.len() - 1])
            .collect::<Vec<_>>()
    );
    for (k, v) in &r.summaries {
        println!(
            "  {k}: {} runs, {} violating ({:.3} % of steps, max {:.4}), max divergence {:.4}, \
             MPC infeasible steps {}, mean cost {:.2}",
            v.runs,
            v.runs_violating,
            v.violation_percent,
            v.max_violation,
            v.max_input_divergence,
            v.mpc_soft_steps,
            v.mean_cost
        );
    }
    println!(
        "  robust/nominal MPC cost: mean {:.4}, upswing {:.4}; upswing feasible: {}; study {:.1} s",
        r.cost_ratio_mean, r.cost_ratio_upswing, r.upswing_feasible, r.study_seconds
    );
    println!("{}", r.verdict_detail.message);
    if !quiet {
        eprintln!(
            "robust run -> {}",
            out.join(&cfg.name).join("robust").display()
        );
    }
    Ok(())
}
