//! Profiling driver for the OCP solver: repeatedly solves the pendulum OCP (cold start +
//! sensitivity) at fixed states and prints per-state iteration counts and the mean time.
//! Usage: `cargo run --release -p trainer --example profile_solve -- [reps] [horizon] [qp]`
//! with `qp` = `structured` (default) or `clarabel`.
use std::time::Instant;
use trainer::mpc::law::MpcLaw;
use trainer::problem::ProblemConfig;

const STATES: [[f64; 2]; 6] = [
    [0.548207810803, 0.230770222963],
    [3.93666992824, -0.943360657709],
    [-std::f64::consts::PI, 0.0],
    [5.4672813214, -0.232644891476],
    [-4.07583167819, -0.222157152042],
    [1.72111132285, 0.7263578447],
];

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let reps: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(100);
    let horizon: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(20);
    let mut cfg = ProblemConfig::default();
    cfg.ocp.horizon = horizon;
    if args.get(3).map(String::as_str) == Some("clarabel") {
        cfg.solver.qp = trainer::mpc::qp::QpSolverKind::Clarabel;
    }
    let mut law = MpcLaw::new(&cfg);
    for x in STATES {
        let (l, _) = law.solve(&x, None);
        println!(
            "{x:?}: {:?} sqp+polish iters {} qp iters {} polished {}",
            l.status, l.info.iterations, l.info.qp_iterations, l.info.polished
        );
    }
    let t = Instant::now();
    for _ in 0..reps {
        for x in STATES {
            std::hint::black_box(law.solve(&x, None));
        }
    }
    let per = t.elapsed().as_secs_f64() / (reps * STATES.len()) as f64;
    println!(
        "mean {:.1} µs per solve (N = {horizon}, qp = {:?})",
        per * 1e6,
        cfg.solver.qp
    );
}
