//! Probe of the f32 training engine: times `Lanes::loss_grad` on consecutive minibatches
//! of 35 of a dataset for a given model (the work of one Adam step without the update),
//! best of 15 repetitions of 2,000 calls, and prints a hash of the bits of every gradient
//! and loss of the first repetition, so that two builds can be compared for identical
//! results as well as for time.
//!
//! `cargo run --release -p trainer --example lanes_probe -- DATA.bin MODEL.bin [--loss-only | --grad-only]`
//! (`--loss-only`: the forward passes and the loss, no gradient; `--grad-only`: the
//! gradient without the loss terms, the minibatch read as rows of the set, as in a
//! training step; its row list is built inside the timed loop).
use std::path::Path;
use std::time::Instant;
use trainer::certify::Model;
use trainer::data::dataset::Dataset;
use trainer::learn::mlp::{Batch, Lanes, LossWeights};
use trainer::learn::train::TrainSet;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        eprintln!("usage: lanes_probe DATA.bin MODEL.bin [--loss-only | --grad-only]");
        std::process::exit(2);
    }
    let d = Dataset::load(Path::new(&args[1])).unwrap_or_else(|e| panic!("{e}"));
    let model = Model::load(Path::new(&args[2])).unwrap_or_else(|e| panic!("{e}"));
    let loss_only = args.iter().any(|a| a == "--loss-only");
    let grad_only = args.iter().any(|a| a == "--grad-only");
    let set = TrainSet::from_dataset(&d);
    let mlp = model.mlp;
    let (nx, nu) = (set.nx, set.nu);
    // The default training settings' λ.
    let lam = LossWeights {
        value: 1.0,
        jacobian: 3.0,
        weights: 0.05,
    };
    let bs = 35;
    let batches = set.use_jac.len() / bs;
    assert!(batches > 0, "fewer than {bs} samples in {}", args[1]);
    let mut lanes = Lanes::default();
    let mut g = mlp.zero_grad();
    let mut hash: u64 = 0;
    let mut best = f64::INFINITY;
    for rep in 0..15 {
        let t = Instant::now();
        for k in 0..2000 {
            let i = (k % batches) * bs;
            let batch = Batch {
                x: &set.x[i * nx..(i + bs) * nx],
                u: &set.u[i * nu..(i + bs) * nu],
                du: &set.du[i * nu * nx..(i + bs) * nu * nx],
                use_jac: &set.use_jac[i..i + bs],
                band: None,
                seq: None,
            };
            let p = if grad_only {
                let all = Batch {
                    x: &set.x,
                    u: &set.u,
                    du: &set.du,
                    use_jac: &set.use_jac,
                    band: None,
                    seq: None,
                };
                let rows: Vec<usize> = (i..i + bs).collect();
                lanes.grad(&mlp, &all, &rows, lam, &mut g);
                Default::default()
            } else {
                lanes.loss_grad(&mlp, &batch, lam, (!loss_only).then_some(&mut g))
            };
            if rep == 0 {
                let grads = g.w.iter().chain(&g.b).flatten();
                for v in grads.chain([&p.value, &p.jacobian]) {
                    hash = hash.rotate_left(5) ^ v.to_bits();
                }
            }
        }
        best = best.min(t.elapsed().as_secs_f64() / 2000.0);
    }
    println!(
        "{:.3} µs per loss_grad of {bs} ({}); bits hash {hash:016x}",
        best * 1e6,
        if loss_only {
            "loss only"
        } else if grad_only {
            "gradient only"
        } else {
            "loss and gradient"
        }
    );
}
