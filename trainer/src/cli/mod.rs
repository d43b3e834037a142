//! The `trainer` command line: the subcommands ([`Cmd`], whose doc comments are their help
//! text) and `dispatch`, which runs the chosen one.
//!
//! Each subcommand lives in its own file (`run`, `solve`, `sample`, `train`, `certify`,
//! `eval`, `compare`, `export`, `refine`, `merge`, `import`): its arguments as an `Args`
//! struct (`#[derive(clap::Args)]`, the flags' doc comments are their help text) with its
//! own `run()`; `common` holds what they share.

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
use clap::{Parser, Subcommand};

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

/// The subcommands, each with its arguments.
#[derive(Subcommand)]
enum Cmd {
    /// The whole pipeline: sample → validate → train (nominal + regularized) → certify →
    /// refine → statistical → export → closed loop → seeds → plots → report (Markdown +
    /// HTML), each stage skipped when its inputs are unchanged.
    Run(run::Args),
    /// Solve the OCP at the states of a CSV file (header x1,…,xn) and write u, ∂u/∂x, cost.
    Solve(solve::Args),
    /// Generate the labelled dataset of a problem's sampling plan (resumes if interrupted).
    Sample(sample::Args),
    /// Train a network on a dataset (sensitivity-regularized by default).
    Train(train::Args),
    /// Certify a trained model: ε = ε_D + (L_MPC + L_NN)·r with every term.
    Certify(certify::Args),
    /// Evaluate a model at the states of a CSV file: outputs and Jacobians.
    Eval(eval::Args),
    /// The paper's Table I over seeds: nominal and regularized nets from the same initial
    /// weights, median [min, max] of R², ε_D and the Lipschitz bounds.
    Compare(compare::Args),
    /// Export a trained model for controller-core (a generated Rust file and a postcard blob,
    /// with the certificate's f32 allowance) and/or as an ONNX model with the certificate in
    /// its metadata.
    Export(export::Args),
    /// Adaptive refinement with local certificates: grow the data and the net until every
    /// cell of X has ε_C ≤ target (or the budget is spent); resumes from its checkpoint.
    Refine(refine::Args),
    /// Import a labelled dataset from another solver's CSV: columns x1..xn (or the
    /// problem's state names), u1..um, optional du{j}_dx{i} and status, an optional leading
    /// index column (pandas' default); checked against the problem, a sample re-solved by
    /// ampc, stored as a dataset for train / certify.
    Import(import::Args),
    /// Merge shard files into one dataset, identical to an unsharded run.
    Merge(merge::Args),
}

/// Runs the subcommand of `cli`.
pub(crate) fn dispatch(cli: Cli) -> Result<()> {
    match cli.cmd {
        Cmd::Run(a) => a.run(),
        Cmd::Solve(a) => a.run(),
        Cmd::Sample(a) => a.run(),
        Cmd::Train(a) => a.run(),
        Cmd::Certify(a) => a.run(),
        Cmd::Eval(a) => a.run(),
        Cmd::Compare(a) => a.run(),
        Cmd::Export(a) => a.run(),
        Cmd::Refine(a) => a.run(),
        Cmd::Import(a) => a.run(),
        Cmd::Merge(a) => a.run(),
    }
}
