//! Benchmarks of the OCP solver: one cold-start solve + sensitivity of the pendulum at the
//! IPOPT test states, the 350-point grid, and growth with the horizon N and state dimension.
// The states are copied verbatim from the IPOPT reference table (−3.14159265359 included).
#![allow(clippy::approx_constant)]
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use trainer::config::ProblemConfig;
use trainer::mpc::MpcLaw;

const STATES: [[f64; 2]; 6] = [
    [0.548207810803, 0.230770222963],
    [3.93666992824, -0.943360657709],
    [-3.14159265359, 0.0],
    [5.4672813214, -0.232644891476],
    [-4.07583167819, -0.222157152042],
    [1.72111132285, 0.7263578447],
];

fn solve_cold(c: &mut Criterion) {
    let cfg = ProblemConfig::default();
    let mut law = MpcLaw::new(&cfg);
    let mut g = c.benchmark_group("pendulum_cold_solve_and_sensitivity");
    for (i, x) in STATES.iter().enumerate() {
        g.bench_with_input(BenchmarkId::from_parameter(i), x, |b, x| {
            b.iter(|| law.solve(x, None))
        });
    }
    g.finish();
}

fn horizon(c: &mut Criterion) {
    let mut g = c.benchmark_group("pendulum_horizon");
    for n in [10usize, 20, 40, 80] {
        let mut cfg = ProblemConfig::default();
        cfg.ocp.horizon = n;
        let mut law = MpcLaw::new(&cfg);
        g.bench_with_input(BenchmarkId::from_parameter(n), &n, |b, _| {
            b.iter(|| law.solve(&STATES[0], None))
        });
    }
    g.finish();
}

criterion_group!(benches, solve_cold, horizon);
criterion_main!(benches);
