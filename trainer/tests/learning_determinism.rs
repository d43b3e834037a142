//! Training is fully determined by (data, settings, seed), whatever the threads: the same
//! inputs give bit-identical model files, run twice and inside rayon pools of 1 and 2
//! threads (with the setpoint hold, which is part of training).
use trainer::certify::Model;
use trainer::learn::setpoint::Hold;
use trainer::learn::train::{label_random_states, train, TrainOptions, TrainSet};
use trainer::problem::ProblemConfig;

fn run(cfg: &ProblemConfig, set: &TrainSet, val: &TrainSet, nominal: bool) -> Model {
    train(
        &cfg.training,
        &TrainOptions {
            nominal,
            progress: None,
            hold: Some(Hold::solve(cfg).expect("κ at the origin")),
            keep_best: None,
        },
        set,
        val,
        (&cfg.domain.lo, &cfg.domain.hi),
        (&cfg.ocp.u_lo, &cfg.ocp.u_hi),
        "h",
        "d",
    )
}

#[test]
fn training_is_bit_identical_across_runs_and_thread_pools() {
    let mut cfg = ProblemConfig::default();
    cfg.training.epochs = 60;
    cfg.training.batch_size = 35;
    cfg.training.log_every = 7;
    // 100 labelled states (more than one 64-sample block of the batched kernels for the
    // full-set loss and error evaluations).
    let set = label_random_states(&cfg, 100, 3);
    let val = label_random_states(&cfg, 30, 4);
    assert!(set.len() > 64);
    for nominal in [false, true] {
        let a = run(&cfg, &set, &val, nominal).to_bytes();
        let b = run(&cfg, &set, &val, nominal).to_bytes();
        assert_eq!(a, b, "two runs differ (nominal = {nominal})");
        for threads in [1, 2] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let c = pool.install(|| run(&cfg, &set, &val, nominal).to_bytes());
            assert_eq!(a, c, "{threads}-thread pool differs (nominal = {nominal})");
        }
    }
}
