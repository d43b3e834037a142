//! Benchmark of dataset generation: the paper's 35 × 10 pendulum grid, labels and
//! sensitivities, on all cores of rayon's default pool (file writes included: this is
//! exactly what `trainer sample` does).
use criterion::{criterion_group, criterion_main, Criterion};
use trainer::data::dataset::{generate, GenerateOptions};
use trainer::problem::ProblemConfig;

fn grid(c: &mut Criterion) {
    let cfg = ProblemConfig::default();
    let dir = std::env::temp_dir().join(format!("ampc-bench-{}", std::process::id()));
    let out = dir.join("grid.bin");
    let mut g = c.benchmark_group("dataset");
    g.sample_size(20);
    g.bench_function(
        format!("pendulum_grid_350_{}_threads", rayon::current_num_threads()),
        |b| b.iter(|| generate(&cfg, &out, &GenerateOptions::default()).map(|d| d.records.len())),
    );
    g.finish();
    let _ = std::fs::remove_dir_all(&dir);
}

criterion_group!(benches, grid);
criterion_main!(benches);
