//! Benchmarks of the OCP solver: one cold-start solve + sensitivity of the pendulum at the
//! 20 IPOPT test states, growth with the horizon N, and with the state dimension.
// The states are copied verbatim from the IPOPT reference table (−3.14159265359 included).
#![allow(clippy::approx_constant)]
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use trainer::mpc::law::MpcLaw;
use trainer::problem::ProblemConfig;

/// The 20 IPOPT reference states (x1, x2).
const STATES: [[f64; 2]; 20] = [
    [1.72111132285, 0.7263578447],
    [-2.89294547519, 0.0829224404982],
    [-5.76829682002, -0.400576218925],
    [-6.07549291375, -0.154625557605],
    [3.93666992824, -0.943360657709],
    [5.18683955722, -0.751433447001],
    [1.34002467904, 0.341248829387],
    [2.88393884005, 0.294379023149],
    [0.548207810803, 0.230770222963],
    [5.4672813214, -0.232644891476],
    [3.96913282095, 0.994419871578],
    [-6.24877229911, 0.961670677552],
    [4.49127459876, 0.371083968961],
    [-5.86113652059, 0.300918552536],
    [2.88593545344, 0.376893461142],
    [-4.07583167819, -0.222157152042],
    [-3.14159265359, 0.0],
    [0.0, 0.0],
    [2.0, 1.0],
    [-6.0, -1.0],
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
            b.iter(|| law.solve(&STATES[8], None))
        });
    }
    g.finish();
}

/// Mean time per cold solve + sensitivity over 16 seeded random states of each problem's
/// domain: pendulum (nx = 2) against cart-pole (nx = 4), both N = 20.
fn state_dimension(c: &mut Criterion) {
    let mut g = c.benchmark_group("state_dimension_16_random_states");
    for name in ["pendulum", "cartpole"] {
        let cfg = if name == "pendulum" {
            ProblemConfig::default()
        } else {
            let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/cartpole.toml");
            ProblemConfig::load(std::path::Path::new(path)).expect("cartpole config")
        };
        let s = trainer::problem::SamplingSettings {
            sampler: trainer::problem::SamplerKind::Random,
            n: 16,
            seed: 1,
            counts: vec![],
        };
        let pts = trainer::data::sampling::Sampler::new(&s, &cfg.domain).points();
        let mut law = MpcLaw::new(&cfg);
        g.bench_function(name, |b| {
            b.iter(|| pts.iter().map(|x| law.solve(x, None).0.u[0]).sum::<f64>())
        });
    }
    g.finish();
}

criterion_group!(benches, solve_cold, horizon, state_dimension);
criterion_main!(benches);
