//! Host nanoseconds per `evaluate` of the compiled-in controller (f32, this build's tanh).

use criterion::{criterion_group, criterion_main, Criterion};
use std::hint::black_box;

fn evaluate(c: &mut Criterion) {
    let name = format!("evaluate_{}", controller_core::activation::TANH_KIND);
    let states = [[-3.0f32, 0.0], [0.5, -0.3], [2.0, 0.9], [-6.0, 0.1]];
    let mut cycle = states.iter().cycle();
    c.bench_function(&name, |b| {
        b.iter(|| {
            let x = cycle.next().unwrap_or(&[0.0, 0.0]);
            controller_core::demo::evaluate(black_box(x))
        })
    });
}

criterion_group!(benches, evaluate);
criterion_main!(benches);
