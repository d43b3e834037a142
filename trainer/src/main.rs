//! The `trainer` command line: label states, generate and merge datasets.
//!
//! Exit codes: 0 success, 1 failure (the message names the file, state or setting at
//! fault), 2 usage error.

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand};
use rayon::prelude::*;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use trainer::config::ProblemConfig;
use trainer::dataset::{self, Dataset, GenerateOptions, Shard};
use trainer::mpc::MpcLaw;

#[derive(Parser)]
#[command(
    name = "trainer",
    version,
    about = "Certified approximate MPC: solve, sample, merge"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
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
    dataset::write_atomic(out, s.as_bytes())?;
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
    dataset::write_atomic(&dataset::csv_path(out), d.to_csv().as_bytes())?;
    eprintln!(
        "merged {} shards ({} records) -> {}",
        inputs.len(),
        d.records.len(),
        out.display()
    );
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
    };
    match res {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
