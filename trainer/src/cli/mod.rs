//! The `trainer` command line: the clap definitions of every subcommand (their doc
//! comments are the help text) and `dispatch`, which runs the chosen one.
//!
//! Each subcommand lives in its own file (`run`, `solve`, `sample`, `train`, `certify`,
//! `eval`, `compare`, `export`, `refine`, `merge`, `import`); `common` holds what they share.

mod certify;
mod common;
mod compare;
mod eval;
mod export;
mod import;
mod merge;
mod refine;
mod run;
mod sample;
mod solve;
mod train;

use anyhow::Result;
use certify::{ClosedLoopArgs, StatisticalArgs};
use clap::{Parser, Subcommand};
use std::path::{Path, PathBuf};
use trainer::data::dataset::csv_path;
use trainer::data::dataset::Shard;

#[derive(Parser)]
#[command(
    name = "trainer",
    version,
    about = "Certified approximate MPC: solve, sample, merge, train, certify, eval"
)]
pub(crate) struct Cli {
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
        /// Problem file, as a flag (the same as the positional argument).
        #[arg(long = "config", id = "config_flag", conflicts_with = "config")]
        config_flag: Option<PathBuf>,
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
        /// Model file from `trainer train`, or an ONNX file (detected by content).
        #[arg(long)]
        model: PathBuf,
        /// The dataset the model was trained on (for a net trained elsewhere: a dataset of
        /// this problem from `trainer sample`).
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
        #[command(flatten)]
        statistical: StatisticalArgs,
        #[command(flatten)]
        closed_loop: ClosedLoopArgs,
    },
    /// Evaluate a model at the states of a CSV file: outputs and Jacobians.
    Eval {
        /// Problem file: the model (and certificate) must be of this problem (default: the
        /// problem stored in the model).
        #[arg(long)]
        config: Option<PathBuf>,
        /// Model file, or an ONNX file (detected by content).
        #[arg(long)]
        model: PathBuf,
        /// Input CSV with header `x1,…,xn`.
        #[arg(long)]
        states: PathBuf,
        /// Output CSV: the controller's `x1..xn,u1..um,flags` (flags: 1 out of domain, 2 not
        /// finite, 4 clamped, 8 in a box the certificate excludes), or with --raw the bare
        /// network's
        /// `x1..xn,u1..um,du1_dx1,…,dum_dxn`.
        #[arg(long)]
        out: PathBuf,
        /// Certificate JSON whose domain and clamp band the controller uses (default: the
        /// one stored in the model).
        #[arg(long)]
        certificate: Option<PathBuf>,
        /// The bare f64 network and its Jacobian, without projection, clamp or f32.
        #[arg(long)]
        raw: bool,
        /// Read a certificate without a checksum (written before certificates were sealed):
        /// its numbers cannot be verified, so its tier is lowered to `estimated` (said on
        /// stderr and in the outputs). Without this flag such a file is refused.
        #[arg(long)]
        accept_unsealed: bool,
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
    /// Export a trained model for controller-core (a generated Rust file and a postcard blob,
    /// with the certificate's f32 allowance) and/or as an ONNX model with the certificate in
    /// its metadata.
    Export {
        /// Problem file: the model and the certificate must be of this problem (default: the
        /// problem stored in the model).
        #[arg(long)]
        config: Option<PathBuf>,
        /// Model file from `trainer train`, or an ONNX file (detected by content).
        #[arg(long)]
        model: PathBuf,
        /// Certificate JSON (default: the one stored in the model by `trainer train`).
        #[arg(long)]
        certificate: Option<PathBuf>,
        /// Output Rust file (with --postcard).
        #[arg(long)]
        rust: Option<PathBuf>,
        /// Output postcard blob (with --rust).
        #[arg(long)]
        postcard: Option<PathBuf>,
        /// Output ONNX file: the f32 network as the controller computes it (opset 13),
        /// certificate under `ampc.*` metadata keys.
        #[arg(long)]
        onnx: Option<PathBuf>,
        /// Name used in the generated files (default: the model's problem name), made a
        /// valid identifier (characters other than A–Z, a–z, 0–9, _ become _).
        #[arg(long)]
        name: Option<String>,
        /// Also write the C header of `controller-core/capi` for this network (`ampc.h`).
        #[arg(long)]
        c_header: Option<PathBuf>,
        /// Write a C library for this network into the folder DIR (created if missing):
        /// `ampc.h`, `ampc.c` (portable C99, bit-identical to the Rust controller), a
        /// `Makefile` and a `CMakeLists.txt` (see docs/deployment.md).
        #[arg(long, value_name = "DIR")]
        c_lib: Option<PathBuf>,
        /// Use the certificate's statistical level as ε (and so as the clamp band): the
        /// `"statistical"` block's `eps_at_p_target` of `--certificate` (from `trainer certify
        /// --statistical N --json`), tier `statistical`, instead of its certified ε.
        #[arg(long, requires = "certificate")]
        statistical_band: bool,
        /// Read a certificate without a checksum (written before certificates were sealed):
        /// its numbers cannot be verified, so its tier is lowered to `estimated` (said on
        /// stderr and in the outputs). Without this flag such a file is refused.
        #[arg(long)]
        accept_unsealed: bool,
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
        /// Labels for the first round: a dataset of this problem (e.g. from `trainer
        /// import`) whose records on the initial grid label those corners (no OCP solve).
        #[arg(long)]
        data: Option<PathBuf>,
        /// Keep the network of --model fixed: only split the cells (solving the MPC at their
        /// corners) until the target or the budget, and certify that network (no training).
        #[arg(long, requires = "model")]
        certify_only: bool,
        /// The network to certify with --certify-only: a model file or an ONNX file.
        #[arg(long, requires = "certify_only")]
        model: Option<PathBuf>,
        /// No progress lines.
        #[arg(long, short)]
        quiet: bool,
        #[command(flatten)]
        statistical: StatisticalArgs,
    },
    /// Import a labelled dataset from another solver's CSV: columns x1..xn (or the
    /// problem's state names), u1..um, optional du{j}_dx{i} and status, an optional leading
    /// index column (pandas' default); checked against the problem, a sample re-solved by
    /// ampc, stored as a dataset for train / certify.
    Import {
        /// The CSV file.
        #[arg(long)]
        csv: PathBuf,
        /// Problem file (default: the embedded pendulum).
        #[arg(long)]
        config: Option<PathBuf>,
        /// Output dataset file (default: the CSV's path with extension `.imported.bin`, so
        /// that importing a `dataset.csv` never replaces the `dataset.bin` beside it).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Rows re-solved by ampc's SQP to check the labels (0: none; all if fewer rows).
        #[arg(long, default_value_t = trainer::data::import::DEFAULT_RESOLVE)]
        resolve: usize,
        /// Seed of the re-solved sample.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Accept labels that disagree with ampc's re-solve (recorded in the dataset and
        /// the certificate, not an error).
        #[arg(long)]
        trust_labels: bool,
        /// No summary.
        #[arg(long, short)]
        quiet: bool,
    },
    /// Merge shard files into one dataset, identical to an unsharded run.
    Merge {
        /// Problem file: every shard must be labelled for this problem (default: the shards'
        /// own, which must agree).
        #[arg(long)]
        config: Option<PathBuf>,
        /// Output dataset file.
        out: PathBuf,
        /// Shard files.
        #[arg(required = true)]
        inputs: Vec<PathBuf>,
    },
}

/// Runs the subcommand of `cli`.
pub(crate) fn dispatch(cli: Cli) -> Result<()> {
    match cli.cmd {
        Cmd::Run {
            config,
            config_flag,
            out,
            force,
            quiet,
            verbose,
            robust_eps,
        } => run::execute(
            config.or(config_flag).as_deref(),
            &out,
            &force,
            quiet,
            verbose,
            robust_eps,
        ),
        Cmd::Solve {
            config,
            states,
            out,
        } => {
            common::refuse_overwrite(&[&out], &[&states, opt(&config)])?;
            solve::execute(config.as_deref(), &states, &out)
        }
        Cmd::Sample {
            config,
            out,
            shard,
            quiet,
        } => {
            let csv = csv_path(&out);
            common::refuse_overwrite(&[&out, &csv], &[opt(&config)])?;
            sample::execute(config.as_deref(), &out, shard, quiet)
        }
        Cmd::Train {
            config,
            data,
            out,
            nominal,
            seed,
            validation,
            quiet,
        } => {
            common::refuse_overwrite(&[&out], &[&data, opt(&config), opt(&validation)])?;
            train::execute(
                config.as_deref(),
                &data,
                &out,
                nominal,
                seed,
                validation.as_deref(),
                quiet,
            )
        }
        Cmd::Certify {
            config,
            model,
            data,
            target_eps,
            l_mpc,
            json,
            statistical,
            closed_loop,
        } => {
            let stat = statistical.options(model.with_extension("statistical.bin"))?;
            certify::execute(
                config.as_deref(),
                &model,
                &data,
                target_eps,
                l_mpc,
                json,
                certify::Tiers {
                    statistical: stat.as_ref(),
                    closed_loop: closed_loop.options()?,
                },
            )
        }
        Cmd::Eval {
            config,
            model,
            states,
            out,
            certificate,
            raw,
            accept_unsealed,
        } => {
            common::refuse_overwrite(&[&out], &[&model, &states, opt(&certificate), opt(&config)])?;
            let inputs = eval::Inputs {
                config: config.as_deref(),
                model: &model,
                states: &states,
                certificate: certificate.as_deref(),
                accept_unsealed,
            };
            eval::execute(&inputs, &out, raw)
        }
        Cmd::Compare {
            config,
            data,
            seeds,
            json,
        } => {
            common::refuse_overwrite(&[opt(&json)], &[&data, opt(&config)])?;
            compare::execute(config.as_deref(), &data, seeds, json.as_deref())
        }
        Cmd::Export {
            config,
            model,
            certificate,
            rust,
            postcard,
            onnx,
            name,
            c_header,
            c_lib,
            statistical_band,
            accept_unsealed,
        } => {
            common::refuse_overwrite(
                &[opt(&rust), opt(&postcard), opt(&onnx), opt(&c_header)],
                &[&model, opt(&certificate), opt(&config)],
            )?;
            let out = export::Outputs {
                rust: rust.as_deref(),
                postcard: postcard.as_deref(),
                onnx: onnx.as_deref(),
                c_header: c_header.as_deref(),
                c_lib: c_lib.as_deref(),
            };
            export::execute(
                config.as_deref(),
                &model,
                certificate.as_deref(),
                &out,
                name.as_deref(),
                (statistical_band, accept_unsealed),
            )
        }
        Cmd::Refine {
            config,
            target_eps,
            budget,
            out,
            check,
            check_seed,
            data,
            certify_only: _,
            model,
            quiet,
            statistical,
        } => refine::execute(
            config.as_deref(),
            target_eps,
            budget,
            out.as_deref(),
            (check.map(|n| (n, check_seed)), &statistical),
            data.as_deref(),
            model.as_deref(),
            quiet,
        ),
        Cmd::Import {
            csv,
            config,
            out,
            resolve,
            seed,
            trust_labels,
            quiet,
        } => {
            let out = out.unwrap_or_else(|| csv.with_extension("imported.bin"));
            common::refuse_overwrite(&[&out], &[&csv, opt(&config)])?;
            let opts = trainer::data::import::ImportOptions {
                resolve,
                seed,
                trust_labels,
            };
            import::execute(config.as_deref(), &csv, &out, &opts, quiet)
        }
        Cmd::Merge {
            config,
            out,
            inputs,
        } => {
            let csv = csv_path(&out);
            let mut ins: Vec<&Path> = inputs.iter().map(PathBuf::as_path).collect();
            ins.push(opt(&config));
            common::refuse_overwrite(&[&out, &csv], &ins)?;
            merge::execute(config.as_deref(), &out, &inputs)
        }
    }
}

/// An optional path as a path (the empty path, which names no file, when absent).
fn opt(p: &Option<PathBuf>) -> &Path {
    p.as_deref().unwrap_or(Path::new(""))
}
