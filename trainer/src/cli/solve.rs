//! `trainer solve`: solves the OCP of the problem file (`--config`) at every state of a
//! states CSV (`--states`, header `x1,…,xn`) and writes one CSV row per state (`--out`:
//! state, u, ∂u/∂x, cost, solver status, iterations).

use super::common::{
    csv_numbers, jacobian_header, load_config, opt, read_states, refuse_overwrite,
};
use anyhow::Result;
use rayon::prelude::*;
use std::path::{Path, PathBuf};
use trainer::mpc::law::MpcLaw;

/// The arguments of `trainer solve` (their doc comments are the help text).
#[derive(clap::Args)]
pub(super) struct Args {
    /// Problem file (default: the embedded pendulum).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Input CSV with header `x1,…,xn`.
    #[arg(long)]
    states: PathBuf,
    /// Output CSV: `x1..xn,u1..um,du1_dx1,…,dum_dxn,cost,status,iterations`.
    #[arg(long)]
    out: PathBuf,
}

impl Args {
    /// Solves the OCP at the states of `--states` into `--out`.
    pub(super) fn run(self) -> Result<()> {
        refuse_overwrite(&[&self.out], &[&self.states, opt(&self.config)])?;
        execute(self.config.as_deref(), &self.states, &self.out)
    }
}

pub(super) fn execute(config: Option<&Path>, states: &Path, out: &Path) -> Result<()> {
    let cfg = load_config(config)?;
    let (nx, nu) = (cfg.system.nx(), cfg.system.nu());
    let xs = read_states(states, nx, Some(&cfg))?;
    // Each state is solved from a cold start (and the other `solver.starts`): the answer
    // does not depend on the order.
    let labels: Vec<_> = xs
        .par_iter()
        .map_init(
            || MpcLaw::new(&cfg),
            |law, x| law.solve_starts(x, None, None).0,
        )
        .collect();
    let mut head = jacobian_header(nx, nu);
    head.extend(["cost", "status", "iterations"].map(String::from));
    let mut s = head.join(",");
    s.push('\n');
    for l in &labels {
        let nums = csv_numbers(l.x.iter().chain(&l.u).chain(&l.du_dx).chain([&l.cost]));
        s += &format!("{nums},{},{}\n", l.status.as_str(), l.info.iterations);
    }
    trainer::io::write_atomic(out, s.as_bytes())?;
    let bad = labels.iter().filter(|l| !l.status.is_labelled()).count();
    // Which rung of the solver's retry ladder labelled a state (not a CSV column: readers
    // of the format stay as they are).
    let mut retried = std::collections::BTreeMap::<&str, usize>::new();
    for r in labels.iter().filter_map(|l| l.retry) {
        *retried.entry(r.as_str()).or_default() += 1;
    }
    let retried: Vec<String> = retried.iter().map(|(k, n)| format!("{k} {n}")).collect();
    // Why states have no label (the label gate names the first non-finite quantity).
    let mut why = std::collections::BTreeMap::<String, usize>::new();
    let failed = labels
        .iter()
        .filter(|l| l.status == trainer::mpc::sqp::SqpStatus::NumericalFailure);
    for f in failed.filter_map(|l| l.failure()) {
        *why.entry(f.to_string()).or_default() += 1;
    }
    for (reason, n) in &why {
        eprintln!("{n} state(s) numerical_failure: {reason}");
    }
    eprintln!(
        "solved {} states ({} without a label{}) -> {}",
        labels.len(),
        bad,
        if retried.is_empty() {
            String::new()
        } else {
            format!("; after a retry: {}", retried.join(", "))
        },
        out.display()
    );
    Ok(())
}
