//! Where a closed-loop study's time goes: every run of `study::scenarios::closed_loop`
//! simulated on one thread and timed, then every state it visited solved again by
//! `MpcLaw::solve` (all starts, cold) and `MpcLaw::solve_single` (one start, cold), timed,
//! with the label's status and retry rung.
//!
//! Usage: `cargo run --release -p trainer --example closed_loop_profile -- CONFIG RUN_DIR
//! [JOB_FILTER]` (RUN_DIR: a finished `trainer run --out RUN_DIR` of CONFIG, for its
//! `model_nominal.bin` and `model_regularized.bin`; JOB_FILTER: only run names containing it).
//! Prints per run: wall ms per step, then per visited-state status: count, median and total
//! ms of the cold multi-start and single-start solves.
use std::collections::BTreeMap;
use std::time::Instant;
use trainer::certify::Model;
use trainer::mpc::law::MpcLaw;
use trainer::problem::{ProblemConfig, SamplerKind, SamplingSettings};
use trainer::study::closed_loop::{simulate, Controller, SimSettings};

/// The closed-loop study's initial states (`study::scenarios::initial_states`, crate-private;
/// the same rule for a problem file's plant): `closed_loop.x0` or the quarter point, then the
/// seeded random states.
fn initial_states(cfg: &ProblemConfig) -> Vec<Vec<f64>> {
    let (lo, hi) = (&cfg.domain.lo, &cfg.domain.hi);
    let first = cfg.closed_loop.x0.clone().unwrap_or_else(|| {
        lo.iter()
            .zip(hi)
            .map(|(l, h)| 0.5 * (l + h) + 0.25 * (l - h))
            .collect()
    });
    let s = SamplingSettings {
        sampler: SamplerKind::Random,
        n: cfg.closed_loop.random_initial_states,
        seed: 4242,
        counts: vec![],
    };
    let mut v = vec![first];
    if s.n > 0 {
        v.extend(trainer::data::sampling::Sampler::new(&s, &cfg.domain).points());
    }
    v
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let cfg = ProblemConfig::load(std::path::Path::new(&args[1])).expect("problem file");
    let dir = std::path::PathBuf::from(&args[2]);
    let filter = args.get(3).cloned().unwrap_or_default();
    let n = Model::load(&dir.join("model_nominal.bin")).expect("model_nominal.bin");
    let r = Model::load(&dir.join("model_regularized.bin")).expect("model_regularized.bin");
    let base = SimSettings {
        steps: cfg.closed_loop.steps,
        noise: vec![],
        seed: 0,
        mass_mismatch: 0.0,
        mismatch_parameter: None,
        disturbance: Default::default(),
    };
    let mut total_steps = 0usize;
    let mut total_ms = 0.0;
    // status -> (count, multi-start ms, single-start ms)
    let mut by_status: BTreeMap<String, (usize, f64, f64)> = BTreeMap::new();
    for (name, m) in [
        ("mpc", None),
        ("nominal", Some(&n)),
        ("regularized", Some(&r)),
    ] {
        for (i, x0) in initial_states(&cfg).iter().enumerate() {
            let job = format!("{name}#{i}");
            if !job.contains(&filter) {
                continue;
            }
            let ctrl = match m {
                None => Controller::Mpc,
                Some(m) => Controller::Net(&m.mlp, f64::INFINITY, None),
            };
            let mut law = MpcLaw::new(&cfg);
            let t = Instant::now();
            let run = simulate(&cfg, &mut law, &ctrl, x0, &base);
            let ms = t.elapsed().as_secs_f64() * 1e3;
            let steps = run.u.len().max(1);
            total_steps += steps;
            total_ms += ms;
            let mut line = BTreeMap::<String, usize>::new();
            for x in &run.x[..run.u.len()] {
                let mut fresh = MpcLaw::new(&cfg);
                let t = Instant::now();
                let (l, _) = fresh.solve(x, None);
                let multi = t.elapsed().as_secs_f64() * 1e3;
                let mut fresh = MpcLaw::new(&cfg);
                let t = Instant::now();
                let _ = fresh.solve_single(x, None);
                let single = t.elapsed().as_secs_f64() * 1e3;
                let key = format!(
                    "{}{}",
                    l.status.as_str(),
                    l.retry
                        .map(|r| format!("/{}", r.as_str()))
                        .unwrap_or_default()
                );
                *line.entry(key.clone()).or_default() += 1;
                let e = by_status.entry(key).or_default();
                e.0 += 1;
                e.1 += multi;
                e.2 += single;
            }
            println!(
                "{job}: {steps} steps, {:.2} ms/step ({:.0} ms), failures {}, soft {}, visited {line:?}",
                ms / steps as f64,
                ms,
                run.mpc_failures,
                run.mpc_soft_steps
            );
        }
    }
    println!(
        "all: {total_steps} steps, {:.2} ms/step in the loop",
        total_ms / total_steps.max(1) as f64
    );
    for (k, (c, m, s)) in by_status {
        println!(
            "  {k}: {c} states, cold multi-start {:.2} ms/state ({m:.0} ms), single {:.2} ms/state ({s:.0} ms)",
            m / c as f64,
            s / c as f64
        );
    }
}
