//! Profiling driver for the OCP solver: cold start + sensitivity at fixed states, with
//! per-state iteration counts, status counts and the time per solve.
//!
//! Usage: `cargo run --release -p trainer --example profile_solve -- [reps] [horizon] [qp]
//! [config] [n]` with `qp` = `structured` (default) or `clarabel`. Without `config` (or with
//! `-`) it solves six fixed states of the default pendulum; with a problem file it solves
//! `n` (default 100) uniform random states of the file's domain (seed 1), and prints the
//! status counts, SQP/QP iteration statistics and the median and mean time per solve.
//! A sixth argument names a CSV file to write the labels to (x, status, iterations, cost,
//! u, ∂u/∂x; `{:e}` round-trip precision), to compare two builds state by state.
use std::time::Instant;
use trainer::mpc::law::MpcLaw;
use trainer::problem::{ProblemConfig, SamplerKind, SamplingSettings};

const STATES: [[f64; 2]; 6] = [
    [0.548207810803, 0.230770222963],
    [3.93666992824, -0.943360657709],
    [-std::f64::consts::PI, 0.0],
    [5.4672813214, -0.232644891476],
    [-4.07583167819, -0.222157152042],
    [1.72111132285, 0.7263578447],
];

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let reps: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(100);
    let horizon: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(20);
    let config = args.get(4).filter(|s| s.as_str() != "-");
    let mut cfg = match config {
        Some(path) => ProblemConfig::load(std::path::Path::new(path)).expect("problem file"),
        None => ProblemConfig::default(),
    };
    cfg.ocp.horizon = horizon;
    if args.get(3).map(String::as_str) == Some("clarabel") {
        cfg.solver.qp = trainer::mpc::qp::QpSolverKind::Clarabel;
    }
    let states: Vec<Vec<f64>> = match config {
        Some(_) => {
            let n = args.get(5).and_then(|s| s.parse().ok()).unwrap_or(100);
            let s = SamplingSettings {
                sampler: SamplerKind::Random,
                n,
                seed: 1,
                counts: vec![],
            };
            trainer::data::sampling::Sampler::new(&s, &cfg.domain).points()
        }
        None => STATES.iter().map(|x| x.to_vec()).collect(),
    };
    let verbose = config.is_none();
    let mut law = MpcLaw::new(&cfg);
    let mut iters = Vec::new();
    let mut statuses = std::collections::BTreeMap::new();
    let (mut qp_iters, mut polished) = (0usize, 0usize);
    let mut csv = String::new();
    for x in &states {
        let (l, _) = law.solve(x, None);
        let nums = |v: &[f64]| {
            v.iter()
                .map(|a| format!("{a:e}"))
                .collect::<Vec<_>>()
                .join(",")
        };
        csv += &format!(
            "{},{},{},{:e},{},{}\n",
            nums(x),
            l.status.as_str(),
            l.info.iterations,
            l.cost,
            nums(&l.u),
            nums(&l.du_dx)
        );
        if verbose {
            println!(
                "{x:?}: {:?} sqp+polish iters {} qp iters {} polished {}",
                l.status, l.info.iterations, l.info.qp_iterations, l.info.polished
            );
        }
        *statuses.entry(l.status.as_str()).or_insert(0usize) += 1;
        iters.push(l.info.iterations as f64);
        qp_iters += l.info.qp_iterations;
        polished += l.info.polished as usize;
    }
    if let Some(path) = args.get(6) {
        std::fs::write(path, csv).expect("label file");
    }
    let n = states.len() as f64;
    let mean_it = iters.iter().sum::<f64>() / n;
    let max_it = iters.iter().fold(0.0f64, |m, v| m.max(*v));
    println!(
        "{} states: status {statuses:?}; iterations mean {mean_it:.2} median {} max {max_it}; \
         QP iterations mean {:.1}; polished {polished}",
        states.len(),
        median(&mut iters),
        qp_iters as f64 / n
    );
    let mut per_state = Vec::new();
    let t_all = Instant::now();
    for x in &states {
        let t = Instant::now();
        for _ in 0..reps {
            std::hint::black_box(law.solve(x, None));
        }
        per_state.push(t.elapsed().as_secs_f64() / reps as f64);
    }
    let mean = t_all.elapsed().as_secs_f64() / (reps as f64 * n);
    println!(
        "median {:.1} µs, mean {:.1} µs per solve + sensitivity (N = {horizon}, qp = {:?}, \
         {reps} reps)",
        median(&mut per_state) * 1e6,
        mean * 1e6,
        cfg.solver.qp
    );
}
