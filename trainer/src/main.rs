//! The `trainer` command line: label states, generate and merge datasets.
//!
//! Exit codes: 0 success, 1 failure (the message names the file, state or setting at
//! fault), 2 usage error.

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand};
use rayon::prelude::*;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use trainer::certify::certificate::{certify, requirement, CertifyOptions};
use trainer::certify::Model;
use trainer::data::dataset::{self, Dataset, GenerateOptions, Shard};
use trainer::learn::train::{label_random_states, train, TrainOptions, TrainSet};
use trainer::mpc::law::MpcLaw;
use trainer::problem::ProblemConfig;

#[derive(Parser)]
#[command(
    name = "trainer",
    version,
    about = "Certified approximate MPC: solve, sample, merge, train, certify, eval"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// The whole pipeline: sample → validate → train (nominal + regularized) → certify →
    /// export → closed loop → seeds → plots → report (Markdown + HTML), each stage skipped
    /// when its inputs are unchanged.
    Run {
        /// Problem file (default: the embedded pendulum).
        config: Option<PathBuf>,
        /// Root directory of runs; the run goes to `<out>/<name>/`.
        #[arg(long, default_value = "runs")]
        out: PathBuf,
        /// Redo a stage even if its inputs are unchanged (repeatable).
        #[arg(long, value_parser = clap::builder::PossibleValuesParser::new(trainer::pipeline::STAGES))]
        force: Vec<String>,
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
    },
    /// Solve the OCP at the states of a CSV file (header x1,…,xn) and write u, ∂u/∂x, cost.
    Solve {
        /// Problem file (default: the embedded pendulum).
        #[arg(long)]
        config: Option<PathBuf>,
        /// Input CSV with header `x1,…,xn`.
        #[arg(long)]
        states: PathBuf,
        /// Output CSV: `x1..xn,u1..um,du1_dx1,…,dum_dxn,cost,status,iterations`.
        #[arg(long)]
        out: PathBuf,
    },
    /// Generate the labelled dataset of a problem's sampling plan (resumes if interrupted).
    Sample {
        /// Problem file (default: the embedded pendulum).
        #[arg(long)]
        config: Option<PathBuf>,
        /// Output dataset file (postcard); a CSV export is written beside it.
        #[arg(long)]
        out: PathBuf,
        /// Compute only shard K of N (`K/N`, 0 ≤ K < N).
        #[arg(long)]
        shard: Option<Shard>,
        /// No progress bar or summary.
        #[arg(long, short)]
        quiet: bool,
    },
    /// Train a network on a dataset (sensitivity-regularized by default).
    Train {
        /// Problem file (default: the embedded pendulum); its `[training]` table applies.
        #[arg(long)]
        config: Option<PathBuf>,
        /// Dataset file from `trainer sample`.
        #[arg(long)]
        data: PathBuf,
        /// Output model file.
        #[arg(long)]
        out: PathBuf,
        /// Nominal training (λ₂ = λ₃ = 0).
        #[arg(long)]
        nominal: bool,
        /// Override the seed of the initial weights and shuffling.
        #[arg(long)]
        seed: Option<u64>,
        /// A labelled validation dataset (e.g. a run's validation.bin); default: label
        /// `training.validation_n` random states now.
        #[arg(long)]
        validation: Option<PathBuf>,
        /// No progress or summary.
        #[arg(long, short)]
        quiet: bool,
    },
    /// Certify a trained model: ε = ε_D + (L_MPC + L_NN)·r with every term.
    Certify {
        /// Problem file (default: the embedded pendulum).
        #[arg(long)]
        config: Option<PathBuf>,
        /// Model file from `trainer train`.
        #[arg(long)]
        model: PathBuf,
        /// The dataset the model was trained on.
        #[arg(long)]
        data: PathBuf,
        /// Also report the data density a target ε requires.
        #[arg(long)]
        target_eps: Option<f64>,
        /// A proven Lipschitz constant of the MPC law (otherwise an estimate is used).
        #[arg(long)]
        l_mpc: Option<f64>,
        /// Print JSON (the certificate record) instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Evaluate a model at the states of a CSV file: outputs and Jacobians.
    Eval {
        /// Model file.
        #[arg(long)]
        model: PathBuf,
        /// Input CSV with header `x1,…,xn`.
        #[arg(long)]
        states: PathBuf,
        /// Output CSV `x1..xn,u1..um,du1_dx1,…,dum_dxn`.
        #[arg(long)]
        out: PathBuf,
    },
    /// The paper's Table I over seeds: nominal and regularized nets from the same initial
    /// weights, median [min, max] of R², ε_D and the Lipschitz bounds.
    Compare {
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
    },
    /// Export a trained model for controller-core: a generated Rust file and a postcard blob,
    /// with the certificate's f32 allowance.
    Export {
        /// Model file from `trainer train`.
        #[arg(long)]
        model: PathBuf,
        /// Certificate JSON (default: the one stored in the model by `trainer train`).
        #[arg(long)]
        certificate: Option<PathBuf>,
        /// Output Rust file.
        #[arg(long)]
        rust: PathBuf,
        /// Output postcard blob.
        #[arg(long)]
        postcard: PathBuf,
        /// Name used in the generated file (default: pendulum).
        #[arg(long, default_value = "pendulum")]
        name: String,
    },
    /// Adaptive refinement with local certificates: grow the data and the net until every
    /// cell of X has ε_C ≤ target (or the budget is spent); resumes from its checkpoint.
    Refine {
        /// Problem file (default: the embedded pendulum); its `[refine]` table applies.
        #[arg(long)]
        config: Option<PathBuf>,
        /// Target certified ε (overrides `refine.target_eps`).
        #[arg(long)]
        target_eps: Option<f64>,
        /// Budget of OCP solves (overrides `refine.budget`).
        #[arg(long)]
        budget: Option<usize>,
        /// Output directory (default: runs/<name>/refine).
        #[arg(long)]
        out: Option<PathBuf>,
        /// After refining, check the certificate at this many random states solved by the
        /// MPC (writes check.json).
        #[arg(long)]
        check: Option<usize>,
        /// Seed of the check's states.
        #[arg(long, default_value_t = 2024)]
        check_seed: u64,
        /// No progress lines.
        #[arg(long, short)]
        quiet: bool,
    },
    /// Merge shard files into one dataset, identical to an unsharded run.
    Merge {
        /// Output dataset file.
        out: PathBuf,
        /// Shard files.
        #[arg(required = true)]
        inputs: Vec<PathBuf>,
    },
}

fn load_config(path: &Option<PathBuf>) -> Result<ProblemConfig> {
    Ok(match path {
        Some(p) => ProblemConfig::load(p)?,
        None => ProblemConfig::default(),
    })
}

/// Reads a states CSV: header `x1,…,xn`, one finite state per row.
fn read_states(path: &Path, nx: usize) -> Result<Vec<Vec<f64>>> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read states file {}", path.display()))?;
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty());
    let (_, header) = lines.next().with_context(|| {
        format!(
            "{}: empty file (expected a header x1,…,x{nx})",
            path.display()
        )
    })?;
    let cols: Vec<&str> = header.split(',').map(str::trim).collect();
    let expected: Vec<String> = (1..=nx).map(|i| format!("x{i}")).collect();
    if cols != expected {
        bail!(
            "{}:1: header must be `{}` for this problem ({} states), got `{}`",
            path.display(),
            expected.join(","),
            nx,
            header.trim()
        );
    }
    let mut out = Vec::new();
    for (ln, line) in lines {
        let vals: Vec<&str> = line.split(',').map(str::trim).collect();
        if vals.len() != nx {
            bail!(
                "{}:{}: expected {nx} columns, got {}",
                path.display(),
                ln + 1,
                vals.len()
            );
        }
        let mut x = Vec::with_capacity(nx);
        for (i, v) in vals.iter().enumerate() {
            let f: f64 = v.parse().with_context(|| {
                format!(
                    "{}:{}: x{} = `{v}` is not a number",
                    path.display(),
                    ln + 1,
                    i + 1
                )
            })?;
            if !f.is_finite() {
                bail!(
                    "{}:{}: x{} = {v} is not finite",
                    path.display(),
                    ln + 1,
                    i + 1
                );
            }
            x.push(f);
        }
        out.push(x);
    }
    Ok(out)
}

fn solve(config: &Option<PathBuf>, states: &Path, out: &Path) -> Result<()> {
    let cfg = load_config(config)?;
    let (nx, nu) = (cfg.system.nx(), cfg.system.nu());
    let xs = read_states(states, nx)?;
    // Each state is solved from a cold start: the answer does not depend on the order.
    let labels: Vec<_> = xs
        .par_iter()
        .map_init(|| MpcLaw::new(&cfg), |law, x| law.solve(x, None).0)
        .collect();
    let mut s = String::new();
    let mut head: Vec<String> = (1..=nx).map(|i| format!("x{i}")).collect();
    head.extend((1..=nu).map(|j| format!("u{j}")));
    for j in 1..=nu {
        head.extend((1..=nx).map(|i| format!("du{j}_dx{i}")));
    }
    head.extend(["cost", "status", "iterations"].map(String::from));
    s += &head.join(",");
    s.push('\n');
    for l in &labels {
        let nums: Vec<String> =
            l.x.iter()
                .chain(&l.u)
                .chain(&l.du_dx)
                .chain([&l.cost])
                .map(|v| format!("{v:?}"))
                .collect();
        s += &format!(
            "{},{},{}\n",
            nums.join(","),
            l.status.as_str(),
            l.info.iterations
        );
    }
    trainer::io::write_atomic(out, s.as_bytes())?;
    let bad = labels.iter().filter(|l| !l.status.is_labelled()).count();
    eprintln!(
        "solved {} states ({} without a label) -> {}",
        labels.len(),
        bad,
        out.display()
    );
    Ok(())
}

fn sample(config: &Option<PathBuf>, out: &Path, shard: Option<Shard>, quiet: bool) -> Result<()> {
    let cfg = load_config(config)?;
    let t = std::time::Instant::now();
    let opts = GenerateOptions {
        shard,
        progress: !quiet && std::io::stderr().is_terminal(),
    };
    let d = dataset::generate(&cfg, out, &opts)?;
    if !quiet {
        let c = d.counts();
        eprintln!(
            "{}: {} states{} in {:.2} s: {} converged, {} soft, {} infeasible, {} failed, {} degenerate -> {} (+ {})",
            cfg.name,
            c.total,
            shard.map(|s| format!(" (shard {}/{})", s.index, s.count)).unwrap_or_default(),
            t.elapsed().as_secs_f64(),
            c.converged,
            c.soft,
            c.infeasible,
            c.failed,
            c.degenerate,
            out.display(),
            dataset::csv_path(out).display()
        );
    }
    Ok(())
}

fn merge(out: &Path, inputs: &[PathBuf]) -> Result<()> {
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

fn export_cmd(
    model: &Path,
    certificate: Option<&Path>,
    rust: &Path,
    postcard: &Path,
    name: &str,
) -> Result<()> {
    let m = Model::load(model)?;
    let cert: trainer::certify::certificate::Certificate = match certificate {
        Some(p) => serde_json::from_str(
            &std::fs::read_to_string(p).with_context(|| format!("cannot read {}", p.display()))?,
        )
        .with_context(|| format!("{}: not a certificate", p.display()))?,
        None => m.certificate.clone().with_context(|| {
            format!(
                "{} holds no certificate: pass --certificate",
                model.display()
            )
        })?,
    };
    if cert.hash != m.content_hash() {
        bail!(
            "the certificate is about another network (hash {}), not {}",
            cert.hash,
            model.display()
        );
    }
    let em = trainer::deploy::export::ExportModel::from_trained(name, &m, &cert)?;
    let r = trainer::deploy::export::export_files(&em, rust, postcard)?;
    eprintln!(
        "exported {} -> {} + {} | f32 allowance (sound) {:.3e}, largest difference on {} random states {:.3e} | certified ε {:.4} + {:.3e}",
        model.display(),
        rust.display(),
        postcard.display(),
        r.f32_allowance[0],
        r.samples,
        r.f32_observed[0],
        cert.eps,
        r.f32_allowance[0]
    );
    Ok(())
}

fn print_stage(r: &trainer::pipeline::StageReport) {
    eprintln!(
        "[{:>11}] {} {:.2} s  {}",
        r.stage,
        if r.skipped { "skipped" } else { "done   " },
        r.seconds,
        r.summary
    );
}

fn print_stage_verbose(r: &trainer::pipeline::StageReport) {
    print_stage(r);
    for (k, h) in &r.inputs {
        eprintln!("              input  {k} {}", &h[..h.len().min(16)]);
    }
    for o in &r.outputs {
        eprintln!("              output {o}");
    }
}

fn run_cmd(
    config: &Option<PathBuf>,
    out: &Path,
    force: &[String],
    quiet: bool,
    verbose: bool,
    robust_eps: Option<f64>,
) -> Result<()> {
    let (mut cfg, text) = match config {
        Some(p) => {
            let text = std::fs::read_to_string(p)
                .with_context(|| format!("cannot read problem file {}", p.display()))?;
            (
                ProblemConfig::from_toml_str(&text, &p.display().to_string())?,
                text,
            )
        }
        None => (
            ProblemConfig::default(),
            trainer::problem::PENDULUM_TOML.to_string(),
        ),
    };
    if let Some(e) = robust_eps {
        cfg.robust.eps = e;
        cfg.validate().context("--robust-eps")?;
    }
    // The nominal pipeline never sees the robust settings (its files stay byte-identical).
    let robust = std::mem::take(&mut cfg.robust);
    let t = std::time::Instant::now();
    let opts = trainer::pipeline::RunOptions {
        root: out.to_path_buf(),
        force: force.to_vec(),
        progress: !quiet && std::io::stderr().is_terminal(),
        on_stage: match (quiet, verbose) {
            (true, _) => None,
            (false, true) => Some(print_stage_verbose),
            (false, false) => Some(print_stage),
        },
        until: None,
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
    if robust.enabled() {
        cfg.robust = robust;
        robust_run(&cfg, &opts, out, quiet)?;
    }
    Ok(())
}

/// The robust design loop of `run --robust-eps` (or `[robust] eps`), with its summary.
fn robust_run(
    cfg: &ProblemConfig,
    opts: &trainer::pipeline::RunOptions,
    out: &Path,
    quiet: bool,
) -> Result<()> {
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
    println!("{}", r.verdict.message);
    if !quiet {
        eprintln!(
            "robust run -> {}",
            out.join(&cfg.name).join("robust").display()
        );
    }
    Ok(())
}

fn sha256_file(path: &Path) -> Result<String> {
    use sha2::{Digest, Sha256};
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    Ok(trainer::io::hex(&Sha256::digest(&bytes)))
}

fn train_cmd(
    config: &Option<PathBuf>,
    data: &Path,
    out: &Path,
    nominal: bool,
    seed: Option<u64>,
    validation: Option<&Path>,
    quiet: bool,
) -> Result<()> {
    let mut cfg = load_config(config)?;
    if let Some(s) = seed {
        cfg.training.seed = s;
    }
    let d = Dataset::load(data)?;
    if d.header.problem_hash != cfg.problem_hash() {
        bail!(
            "{} was labelled for another problem (hash {}…) than the config's {} ({}…)",
            data.display(),
            &d.header.problem_hash[..12.min(d.header.problem_hash.len())],
            cfg.name,
            &cfg.problem_hash()[..12]
        );
    }
    let set = TrainSet::from_dataset(&d);
    if set.is_empty() {
        bail!("{}: no labelled points to train on", data.display());
    }
    let t0 = std::time::Instant::now();
    let val = match validation {
        Some(p) => {
            let v = Dataset::load(p)?;
            if v.header.problem_hash != d.header.problem_hash {
                bail!(
                    "{} was labelled for another problem than {}",
                    p.display(),
                    data.display()
                );
            }
            TrainSet::from_dataset(&v)
        }
        None => label_random_states(
            &cfg,
            cfg.training.validation_n,
            cfg.training.validation_seed,
        ),
    };
    let t_val = t0.elapsed().as_secs_f64();
    let t1 = std::time::Instant::now();
    let opts = TrainOptions {
        nominal,
        progress: None,
    };
    let mut model = train(
        &cfg.training,
        &opts,
        &set,
        &val,
        (&cfg.domain.lo, &cfg.domain.hi),
        (&cfg.ocp.u_lo, &cfg.ocp.u_hi),
        &d.header.problem_hash,
        &sha256_file(data)?,
    );
    let t_train = t1.elapsed().as_secs_f64();
    let cert = certify(
        &model,
        &d,
        &cfg,
        &CertifyOptions {
            extra: Some(val),
            ..Default::default()
        },
    );
    model.certificate = Some(cert.clone());
    model.save(out)?;
    if !quiet {
        eprintln!(
            "{} net {:?}: {} epochs in {:.3} s (validation labels {:.3} s) | train ε_D {:.4}, median {:.4} | validation R² {:.5}, max err {:.4} | L_NN {:.2} ({:?}), naive {:.2}, lower {:.2} | ε {:.3} -> {}",
            if nominal { "nominal" } else { "regularized" },
            model.mlp.widths(),
            model.epochs_run,
            t_train,
            t_val,
            model.train_stats.max,
            model.train_stats.median,
            model.validation_stats.r2,
            model.validation_stats.max,
            cert.l_nn,
            cert.l_nn_method,
            cert.l_nn_naive,
            cert.l_nn_lower,
            cert.eps,
            out.display()
        );
    }
    Ok(())
}

#[allow(clippy::too_many_arguments)]
fn refine_cmd(
    config: &Option<PathBuf>,
    target_eps: Option<f64>,
    budget: Option<usize>,
    out: &Option<PathBuf>,
    check: Option<usize>,
    check_seed: u64,
    quiet: bool,
) -> Result<()> {
    use trainer::certify::refine;
    let mut cfg = load_config(config)?;
    // A robust design (`[robust] eps > 0`): refine the data of the tightened MPC, with the
    // design ε as the default target (Corollary 1 needs certified ε ≤ design ε).
    let mut robust_note = None;
    if cfg.robust.enabled() {
        let design = trainer::robust::design(&cfg)?;
        let eps = cfg.robust.eps;
        let mut rcfg = trainer::robust::robust_config(&cfg, &design);
        if !cfg.name.ends_with("robust") {
            rcfg.name = format!("{}_robust", cfg.name);
        } else {
            rcfg.name = cfg.name.clone();
        }
        if target_eps.is_none() {
            rcfg.refine.target_eps = eps;
        }
        robust_note = Some(eps);
        cfg = rcfg;
    }
    if let Some(e) = target_eps {
        cfg.refine.target_eps = e;
    }
    if let Some(b) = budget {
        cfg.refine.budget = b;
    }
    cfg.refine
        .validate(cfg.system.nx())
        .context("invalid --target-eps / --budget")?;
    let rs = cfg.refine.clone();
    let dir = out
        .clone()
        .unwrap_or_else(|| Path::new("runs").join(&cfg.name).join("refine"));
    std::fs::create_dir_all(&dir)
        .with_context(|| format!("cannot create output directory {}", dir.display()))?;
    let t0 = std::time::Instant::now();
    fn line(l: &refine::RoundLog, budget: usize) {
        eprintln!(
            "round {:>2}: cells {}/{} ok, certified ε {:.4} (corner max {:.4}), {} second-order, \
             solves {}/{budget}, {:.1} s",
            l.round, l.cells_ok, l.cells, l.eps, l.eps_d, l.second_order, l.solves, l.seconds
        );
    }
    let opts = refine::RefineOptions {
        on_round: (!quiet).then_some(line as fn(&refine::RoundLog, usize)),
    };
    let checkpoint = dir.join("refine_state.bin");
    let r = refine::refine(&cfg, &rs, Some(&checkpoint), &opts)?;
    let cert = refine::write_outputs(&cfg, &rs, &r, &dir)?;
    if cfg.system.nx() >= 2 {
        let fig = trainer::study::plots::eps_map(
            &cfg,
            &refine::cell_views(&cfg, &rs, &r.state),
            rs.target_eps,
        )?;
        let png = trainer::study::plots::to_png(fig.name, &fig.svg, cfg.plots.png_scale as f32)?;
        trainer::io::write_atomic(&dir.join("eps_map.svg"), fig.svg.as_bytes())?;
        trainer::io::write_atomic(&dir.join("eps_map.png"), &png)?;
    }
    if !quiet {
        let l = &cert.local;
        println!(
            "{}: certified ε {:.4} (target {}{}) with {} solves, {} cells ({} second-order), \
             max corner error {:.4}; global Theorem 1 grid for this ε: {}; {:.1} s -> {}",
            cfg.name,
            cert.base.eps,
            rs.target_eps,
            if l.met { ", met" } else { ", NOT met" },
            l.solves,
            l.cells,
            l.cells_second_order,
            cert.base.eps_d,
            match (l.global_grid_solves, l.sparsification) {
                (Some(g), Some(s)) => format!("{g:.3e} solves ({s:.0}× more)"),
                _ => "none suffices (ε ≤ ε_D)".into(),
            },
            t0.elapsed().as_secs_f64(),
            dir.display()
        );
    }
    if let Some(n) = check {
        let c = refine::check(&cfg, &rs, &r, n, check_seed);
        trainer::io::write_atomic(&dir.join("check.json"), refine::pretty(&c).as_bytes())?;
        if !quiet {
            println!(
                "check at {} random states ({} labelled): max observed {:.4} vs certified {:.4} \
                 (ratio {:.2}); over ε: {}, over own cell's ε_C: {} (max ratio {:.3}); \
                 slope estimate misses {}/{} (max excess {:.3}); {:.1} s",
                c.states,
                c.labelled,
                c.max_observed,
                c.certified,
                c.ratio,
                c.over_eps,
                c.over_cell,
                c.max_cell_ratio,
                c.slope_misses,
                c.slope_checks,
                c.max_slope_excess,
                c.seconds
            );
        }
        if c.over_eps > 0 || c.over_cell > 0 {
            bail!(
                "certificate check failed: {} states above ε, {} above their cell's ε_C (see {})",
                c.over_eps,
                c.over_cell,
                dir.join("check.json").display()
            );
        }
    }
    if let Some(design) = robust_note {
        let v = trainer::robust::verdict(design, cert.base.eps);
        if !quiet {
            println!("robust design: {}", v.message);
        }
    }
    if !r.met {
        bail!(
            "target ε {} not met within {} solves / {} rounds: certified ε {:.4} (outputs in {})",
            rs.target_eps,
            rs.budget,
            rs.max_rounds,
            cert.base.eps,
            dir.display()
        );
    }
    Ok(())
}

fn certify_cmd(
    config: &Option<PathBuf>,
    model: &Path,
    data: &Path,
    target: Option<f64>,
    l_mpc: Option<f64>,
    json: bool,
) -> Result<()> {
    let cfg = load_config(config)?;
    let m = Model::load(model)?;
    let d = Dataset::load(data)?;
    if let Some(v) = l_mpc {
        if !(v.is_finite() && v >= 0.0) {
            bail!("--l-mpc must be a finite number ≥ 0, got {v}");
        }
    }
    if let Some(e) = target {
        if !(e.is_finite() && e > 0.0) {
            bail!("--target-eps must be a finite number > 0, got {e}");
        }
    }
    let c = certify(
        &m,
        &d,
        &cfg,
        &CertifyOptions {
            l_mpc,
            ..Default::default()
        },
    );
    let req =
        target.map(|e| requirement(e, c.eps_d, c.l_mpc, c.l_nn, &cfg.domain.lo, &cfg.domain.hi));
    if json {
        let mut v = serde_json::to_value(&c)?;
        if let (Some(r), Some(o)) = (req, v.as_object_mut()) {
            o.insert("requirement".into(), serde_json::to_value(r)?);
        }
        println!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(());
    }
    println!(
        "certificate of {} on {} ({} labelled points)",
        model.display(),
        data.display(),
        c.n_points
    );
    println!(
        "  eps_D            {:.6}   (max ‖κ − κ_NN‖ over the data)",
        c.eps_d
    );
    println!(
        "  L_NN             {:.4}   ({:?}, sound)",
        c.l_nn, c.l_nn_method
    );
    println!("    naive          {:.4}", c.l_nn_naive);
    println!("    LipSDP-Neuron  {:.4}", c.l_nn_lipsdp);
    if let Some(v) = c.l_nn_vertex {
        println!("    slope vertices {v:.4}");
    }
    println!("    sampled lower  {:.4}", c.l_nn_lower);
    println!("  L_MPC            {:.4}   ({})", c.l_mpc, c.l_mpc_method);
    println!(
        "  covering radius  {:.6}   ({})",
        c.covering_radius, c.covering_method
    );
    println!(
        "  eps              {:.6}   = eps_D + (L_MPC + L_NN)·r{}",
        c.eps,
        if c.l_mpc_is_estimate {
            "  [L_MPC is an estimate]"
        } else {
            ""
        }
    );
    if let Some(r) = req {
        match (r.delta, r.spacing, r.solves) {
            (Some(dl), Some(h), Some(n)) => println!(
                "  target eps {}: covering radius δ ≤ {:.6}, e.g. a grid with spacing {:.6} per axis: {:.0} OCP solves",
                r.target_eps, dl, h, n
            ),
            _ => println!("  target eps {} ≤ eps_D {:.6}: no data density can certify it with this network", r.target_eps, c.eps_d),
        }
    }
    Ok(())
}

fn eval_cmd(model: &Path, states: &Path, out: &Path) -> Result<()> {
    let m = Model::load(model)?;
    let (nx, nu) = (m.mlp.nx(), m.mlp.nu());
    let xs = read_states(states, nx)?;
    let mut head: Vec<String> = (1..=nx).map(|i| format!("x{i}")).collect();
    head.extend((1..=nu).map(|j| format!("u{j}")));
    for j in 1..=nu {
        head.extend((1..=nx).map(|i| format!("du{j}_dx{i}")));
    }
    let mut s = head.join(",");
    s.push('\n');
    let mut ws = trainer::learn::mlp::Workspace::default();
    let (mut u, mut jac) = (vec![0.0; nu], vec![0.0; nu * nx]);
    for x in &xs {
        m.mlp.eval(x, &mut u, &mut jac, &mut ws);
        let nums: Vec<String> = x
            .iter()
            .chain(&u)
            .chain(&jac)
            .map(|v| format!("{v:?}"))
            .collect();
        s += &nums.join(",");
        s.push('\n');
    }
    trainer::io::write_atomic(out, s.as_bytes())?;
    Ok(())
}

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

fn med_range(v: &[f64]) -> String {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let med = if s.is_empty() {
        f64::NAN
    } else if s.len() % 2 == 1 {
        s[s.len() / 2]
    } else {
        0.5 * (s[s.len() / 2 - 1] + s[s.len() / 2])
    };
    format!(
        "{} [{}, {}]",
        fmt_num(med),
        fmt_num(s.first().copied().unwrap_or(f64::NAN)),
        fmt_num(s.last().copied().unwrap_or(f64::NAN))
    )
}

fn fmt_num(v: f64) -> String {
    if v.abs() >= 100.0 {
        format!("{v:.1}")
    } else if v.abs() >= 0.9 && v.abs() < 1.0 {
        format!("{v:.4}")
    } else {
        format!("{v:.3}")
    }
}

fn compare_cmd(
    config: &Option<PathBuf>,
    data: &Path,
    seeds: u64,
    json: Option<&Path>,
) -> Result<()> {
    let cfg = load_config(config)?;
    let d = Dataset::load(data)?;
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
    let jobs: Vec<(u64, bool)> = (0..seeds).flat_map(|s| [(s, true), (s, false)]).collect();
    let results: Vec<SeedResult> = jobs
        .par_iter()
        .map(|&(seed, nominal)| {
            let mut st = cfg.training.clone();
            st.seed = seed;
            let m = train(
                &st,
                &TrainOptions {
                    nominal,
                    progress: None,
                },
                &set,
                &val,
                (&cfg.domain.lo, &cfg.domain.hi),
                (&cfg.ocp.u_lo, &cfg.ocp.u_hi),
                &d.header.problem_hash,
                &dhash,
            );
            let c = certify(
                &m,
                &d,
                &cfg,
                &CertifyOptions {
                    extra: Some(val.clone()),
                    ..Default::default()
                },
            );
            SeedResult {
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
            }
        })
        .collect();
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

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    let res = match &cli.cmd {
        Cmd::Solve {
            config,
            states,
            out,
        } => solve(config, states, out),
        Cmd::Sample {
            config,
            out,
            shard,
            quiet,
        } => sample(config, out, *shard, *quiet),
        Cmd::Merge { out, inputs } => merge(out, inputs),
        Cmd::Refine {
            config,
            target_eps,
            budget,
            out,
            check,
            check_seed,
            quiet,
        } => refine_cmd(
            config,
            *target_eps,
            *budget,
            out,
            *check,
            *check_seed,
            *quiet,
        ),
        Cmd::Export {
            model,
            certificate,
            rust,
            postcard,
            name,
        } => export_cmd(model, certificate.as_deref(), rust, postcard, name),
        Cmd::Run {
            config,
            out,
            force,
            quiet,
            verbose,
            robust_eps,
        } => run_cmd(config, out, force, *quiet, *verbose, *robust_eps),
        Cmd::Train {
            config,
            data,
            out,
            nominal,
            seed,
            validation,
            quiet,
        } => train_cmd(
            config,
            data,
            out,
            *nominal,
            *seed,
            validation.as_deref(),
            *quiet,
        ),
        Cmd::Certify {
            config,
            model,
            data,
            target_eps,
            l_mpc,
            json,
        } => certify_cmd(config, model, data, *target_eps, *l_mpc, *json),
        Cmd::Eval { model, states, out } => eval_cmd(model, states, out),
        Cmd::Compare {
            config,
            data,
            seeds,
            json,
        } => compare_cmd(config, data, *seeds, json.as_deref()),
    };
    match res {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
