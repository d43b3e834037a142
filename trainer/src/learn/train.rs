//! Training: Adam on minibatches of the sensitivity-regularized loss (the paper's
//! eq. (fullloss)), the epoch loop with its training curve, and the model file (the
//! figures themselves: module `metrics`).
//!
//! ```text
//! loss(Θ) = λ₁·MSE + λ₂·mean‖∂κ/∂x − ∂κ_NN/∂x‖²_F + λ₃·Σ_j‖W̃_j‖²_F          (mlp module)
//! Adam:  m ← β₁m + (1−β₁)g,  v ← β₂v + (1−β₂)g²,  Θ ← Θ − η_t·m̂/(√v̂ + 1e-8)
//! ```
//! The nominal net is the same procedure with (λ₁, 0, 0). The updates run on one thread
//! (the training curve may be computed on a second one from snapshots of the weights) and
//! are fully determined by (dataset, settings, seed): same inputs → bit-identical weights. The
//! passes run in f32 over 8-sample lanes (`training.precision = "f32"`, the default,
//! [`Lanes`]) or in f64 ([`Mlp::loss_grad`]); Adam and the master weights are f64 in both,
//! and the final statistics are f64 evaluations of the f64 net.
//! Points without a label are excluded; degenerate points keep their value term and drop
//! the Jacobian term. Metrics: ε_D = max_i ‖κ(x_i) − κ_NN(x_i)‖ over the training set
//! (eq. (explespd)) with the error distribution, and R² on MPC-labelled random states.

use crate::learn::epoch::{learning_rate, shuffle, Passes};
use crate::learn::metrics::CurvePoint;
pub use crate::learn::metrics::{errors, EpochLog, ErrorStats, KeepBest, TrainSet};
use crate::learn::mlp::{Batch, Lanes, LossWeights, Mlp};
use crate::learn::setpoint::Hold;
use crate::problem::{Precision, TrainSettings};
use crate::rng::{splitmix64, FastMod};
use serde::{Deserialize, Serialize};

/// Model file format version.
pub const MODEL_VERSION: u32 = 3;
/// Magic bytes of a model file.
pub const MODEL_MAGIC: [u8; 8] = *b"AMPCMODL";

/// Which loss a model was trained with.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Kind {
    /// λ₂ = λ₃ = 0.
    Nominal,
    /// The sensitivity-regularized loss.
    Regularized,
    /// Trained elsewhere and imported (an ONNX file): `lambda`, `settings` and the
    /// statistics are placeholders.
    Imported,
}

/// A trained model file: the network, how it was made and how it did, and a slot `C` for
/// what a later stage attaches to it (the certificate: `certify::Model` is
/// `TrainedModel<Certificate>`; this stage never fills it).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainedModel<C> {
    /// Must equal [`MODEL_MAGIC`].
    pub magic: [u8; 8],
    /// Must equal [`MODEL_VERSION`].
    pub version: u32,
    /// The network.
    pub mlp: Mlp,
    /// Nominal or regularized.
    pub kind: Kind,
    /// Loss weights used.
    pub lambda: LossWeights,
    /// Settings used (`hold_setpoint`: whether the setpoint hold was applied; stored in
    /// format 3's layout, see `learn::stored_settings`).
    #[serde(with = "crate::learn::stored_settings")]
    pub settings: TrainSettings,
    /// Problem hash of the dataset's labels.
    pub problem_hash: String,
    /// SHA-256 of the dataset file's bytes.
    pub dataset_hash: String,
    /// Epochs actually run (early stop may end sooner).
    pub epochs_run: usize,
    /// Errors on the training set.
    pub train_stats: ErrorStats,
    /// Errors on the validation set.
    pub validation_stats: ErrorStats,
    /// Training curve.
    pub history: Vec<EpochLog>,
    /// What a later stage attached (the certificate, which `trainer certify` recomputes);
    /// `None` after training.
    pub certificate: Option<C>,
    /// For a network imported from a file of another format (ONNX): the SHA-256 (hex) of
    /// that file's bytes, which is then the [`TrainedModel::content_hash`] a certificate
    /// binds. Not stored in the model file (`None` after loading one).
    #[serde(skip)]
    pub source_hash: Option<String>,
    /// The problem file (TOML) of the labels, kept in the model file's trailer
    /// ([`crate::learn::model_file`]); `None` in older files and ONNX imports.
    #[serde(skip)]
    pub problem_toml: Option<String>,
    /// A sequence net's full network (N·nu outputs, `crate::learn::sequence`), whose u₀ rows
    /// are exactly [`TrainedModel::mlp`]; kept in the model file's trailer; `None` for a net
    /// of u₀ alone.
    #[serde(skip)]
    pub sequence: Option<Mlp>,
}

/// Options of a training run.
#[derive(Debug, Clone)]
pub struct TrainOptions {
    /// Nominal (λ₂ = λ₃ = 0) instead of regularized.
    pub nominal: bool,
    /// Called after each logged epoch (progress reporting).
    pub progress: Option<fn(usize, usize)>,
    /// The setpoint to hold exactly ([`Hold`]: x_ref and κ(x_ref)), when
    /// `training.hold_setpoint` is on: applied to the trained net before its final
    /// statistics. The model records `settings.hold_setpoint` = whether it was applied.
    pub hold: Option<Hold>,
    /// Return the checkpoint (the start included) with the smallest excess of clamped
    /// errors over a threshold instead of the last weights ([`KeepBest`]; the warm-started
    /// retrainings of a refinement). `None`: the last weights.
    pub keep_best: Option<KeepBest>,
}

/// Trains a network on `train` from its seeded initial weights; `validation` gives R².
/// `u_range` is the output range used for scaling (the input bounds U_d).
#[allow(clippy::too_many_arguments)]
pub fn train<C>(
    settings: &TrainSettings,
    opts: &TrainOptions,
    train: &TrainSet,
    validation: &TrainSet,
    domain: (&[f64], &[f64]),
    u_range: (&[f64], &[f64]),
    problem_hash: &str,
    dataset_hash: &str,
) -> TrainedModel<C> {
    train_from(
        None,
        settings,
        opts,
        train,
        validation,
        domain,
        u_range,
        problem_hash,
        dataset_hash,
    )
}

/// [`train`], started from the weights of `init` (a warm start, e.g. after new data
/// arrived) instead of the seeded initial weights. `init` must have the settings' layer
/// widths; its input/output scaling is kept.
#[allow(clippy::too_many_arguments)]
pub fn train_from<C>(
    init: Option<Mlp>,
    settings: &TrainSettings,
    opts: &TrainOptions,
    train: &TrainSet,
    validation: &TrainSet,
    domain: (&[f64], &[f64]),
    u_range: (&[f64], &[f64]),
    problem_hash: &str,
    dataset_hash: &str,
) -> TrainedModel<C> {
    let mut mlp = initial_mlp(init, settings, train, domain, u_range);
    let lam = loss_weights(settings, opts.nominal);
    let band = settings.saturation_aware.then_some(u_range);
    let n = train.len();
    let bs = settings.batch_size.min(n.max(1));
    let f32_passes = settings.precision == Precision::F32;
    let mut passes = Passes::new(&mlp, f32_passes);
    let mut order: Vec<usize> = (0..n).collect();
    // The shuffle's divisors 1…n (the remainders of `%`, without its divisions).
    let divisors: Vec<FastMod> = (1..=n as u64).map(FastMod::new).collect();
    let shuffle_key = splitmix64(settings.seed ^ 0xA5A5);
    let mut history = Vec::new();
    let mut epochs_run = 0;
    let set = Batch {
        x: &train.x,
        u: &train.u,
        du: &train.du,
        use_jac: &train.use_jac,
        band,
        seq: (!train.row_weight.is_empty()).then(|| crate::learn::mlp::SeqLoss {
            jac_rows: train.jac_rows(),
            weight: &train.row_weight,
        }),
    };
    let mut curve = CurvePoint::default();
    // The best checkpoint so far (`opts.keep_best`): its score and weights.
    let (mut kb_lanes, mut kb_u) = (Lanes::default(), Vec::new());
    let mut best = opts.keep_best.as_ref().map(|kb| {
        let s = kb.score(&mut kb_lanes, &mut kb_u, &mlp, train);
        (s, mlp.clone())
    });
    // Without an early stop nothing in the loop reads the curve: its points are computed on
    // a second thread from snapshots of the weights (the same bits), beside the next epochs.
    // With one (or when no thread can be started) they are computed in place.
    std::thread::scope(|scope| {
        let (snapshots, worker) = if settings.target_eps_d.is_none() {
            // At most a few snapshots wait: if the curve falls behind (a large validation
            // set, a short `log_every`), the loop waits for it instead of piling up copies.
            let (tx, rx) = std::sync::mpsc::sync_channel::<(usize, Mlp)>(4);
            let (set, lam) = (&set, lam);
            let spawned = std::thread::Builder::new()
                .name("training curve".into())
                .spawn_scoped(scope, move || {
                    let mut c = CurvePoint::default();
                    rx.iter()
                        .map(|(e, m)| c.compute(&m, e, set, train, validation, lam, f32_passes).0)
                        .collect::<Vec<EpochLog>>()
                });
            match spawned {
                Ok(h) => (Some(tx), Some(h)),
                Err(_) => (None, None),
            }
        } else {
            (None, None)
        };
        for epoch in 0..settings.epochs {
            shuffle(&mut order, &divisors, shuffle_key, epoch);
            let lr = learning_rate(settings, epoch);
            passes.epoch(&mut mlp, train, &set, &order, bs, lam, lr);
            epochs_run = epoch + 1;
            let last = epoch + 1 == settings.epochs;
            if let (Some(kb), Some((s, m))) = (&opts.keep_best, &mut best) {
                if (epoch + 1) % kb.every.max(1) == 0 || last {
                    let now = kb.score(&mut kb_lanes, &mut kb_u, &mlp, train);
                    if now.total_cmp(s).is_lt() {
                        *s = now;
                        m.clone_from(&mlp);
                    }
                }
            }
            if (epoch + 1) % settings.log_every == 0 || last {
                let mut stop = false;
                if let Some(tx) = &snapshots {
                    // A failed send means the worker is gone (it panicked): stop training
                    // now; its join below reports the panic.
                    if tx.send((epoch + 1, mlp.clone())).is_err() {
                        break;
                    }
                } else {
                    let (log, st) =
                        curve.compute(&mlp, epoch + 1, &set, train, validation, lam, f32_passes);
                    history.push(log);
                    // Under f32 the stop is confirmed by the f64 ε_D the model reports.
                    stop = settings.target_eps_d.is_some_and(|t| {
                        st.max <= t && (!f32_passes || errors(&mlp, train).1.max <= t)
                    });
                }
                if let Some(p) = opts.progress {
                    p(epoch + 1, settings.epochs);
                }
                if stop {
                    break;
                }
            }
        }
        drop(snapshots);
        if let Some(h) = worker {
            match h.join() {
                Ok(points) => history = points,
                Err(panic) => std::panic::resume_unwind(panic),
            }
        }
    });
    if let Some((_, m)) = best {
        mlp = m;
    }
    if let Some(h) = &opts.hold {
        h.apply(&mut mlp);
    }
    let mut settings = settings.clone();
    settings.hold_setpoint = opts.hold.is_some();
    let (_, train_stats) = errors(&mlp, train);
    let (_, validation_stats) = errors(&mlp, validation);
    TrainedModel {
        magic: MODEL_MAGIC,
        version: MODEL_VERSION,
        mlp,
        kind: if opts.nominal {
            Kind::Nominal
        } else {
            Kind::Regularized
        },
        lambda: lam,
        settings,
        problem_hash: problem_hash.to_string(),
        dataset_hash: dataset_hash.to_string(),
        epochs_run,
        train_stats,
        validation_stats,
        history,
        certificate: None,
        source_hash: None,
        problem_toml: None,
        sequence: None,
    }
}

/// The starting weights: `init` when it has the settings' layer widths, else the seeded
/// initial weights scaled to the domain and the output range.
fn initial_mlp(
    init: Option<Mlp>,
    settings: &TrainSettings,
    train: &TrainSet,
    domain: (&[f64], &[f64]),
    u_range: (&[f64], &[f64]),
) -> Mlp {
    let mut widths = vec![train.nx];
    widths.extend(&settings.hidden);
    widths.push(train.nu);
    match init {
        Some(m) if m.widths() == widths => m,
        _ => Mlp::new(
            &widths,
            settings.activation,
            settings.seed,
            domain.0,
            domain.1,
            u_range.0,
            u_range.1,
        ),
    }
}

/// The loss weights (λ₁, λ₂, λ₃) of `settings.lambda`; nominal: (λ₁, 0, 0).
fn loss_weights(settings: &TrainSettings, nominal: bool) -> LossWeights {
    let [value, jacobian, weights] = settings.lambda;
    if nominal {
        LossWeights {
            value,
            jacobian: 0.0,
            weights: 0.0,
        }
    } else {
        LossWeights {
            value,
            jacobian,
            weights,
        }
    }
}

/// Labels `n` uniformly random states of X (seeded) with the MPC, in parallel, each from a
/// cold start (so the result does not depend on the thread count). Unlabelled states are
/// dropped.
pub fn label_random_states(cfg: &crate::problem::ProblemConfig, n: usize, seed: u64) -> TrainSet {
    use rayon::prelude::*;
    let s = crate::problem::SamplingSettings {
        sampler: crate::problem::SamplerKind::Random,
        n,
        seed,
        counts: vec![],
    };
    let sampler = crate::data::sampling::Sampler::new(&s, &cfg.domain);
    let pts = sampler.points();
    let labels: Vec<crate::mpc::law::Label> = pts
        .par_iter()
        .map_init(
            || crate::mpc::law::MpcLaw::new(cfg),
            |law, x| law.solve(x, None).0,
        )
        .collect();
    let (nx, nu) = (cfg.system.nx(), cfg.system.nu());
    let mut set = TrainSet {
        nx,
        nu,
        ..Default::default()
    };
    for l in labels.into_iter().filter(|l| l.status.is_labelled()) {
        set.x.extend(&l.x);
        set.u.extend(&l.u);
        set.du.extend(&l.du_dx);
        set.use_jac.push(l.degeneracy.is_none());
    }
    set
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::dataset::Dataset;
    use crate::problem::ProblemConfig;
    use proptest::prelude::*;
    use std::path::Path;

    fn setup(epochs: usize) -> (ProblemConfig, TrainSet, TrainSet) {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../configs/double_integrator.toml"
        );
        let mut cfg = ProblemConfig::load(Path::new(path)).unwrap();
        cfg.sampling.counts = vec![9, 5];
        cfg.training.epochs = epochs;
        cfg.training.batch_size = 9;
        cfg.training.log_every = 5;
        let sampler = crate::data::sampling::Sampler::new(&cfg.sampling, &cfg.domain);
        let mut law = crate::mpc::law::MpcLaw::new(&cfg);
        let recs = crate::data::dataset::label_chunk(&mut law, &sampler, 0, sampler.len(), true);
        let d = Dataset {
            magic: crate::data::dataset::MAGIC,
            version: crate::data::dataset::FORMAT_VERSION,
            header: crate::data::dataset::Header {
                problem: cfg.name.clone(),
                problem_hash: cfg.problem_hash(),
                config_toml: String::new(),
                nx: 2,
                nu: 1,
                sampling: cfg.sampling.clone(),
                total: recs.len() as u64,
                shard: None,
                chunk: crate::data::dataset::CHUNK as u32,
            },
            records: recs,
            labels: None,
            disagree: Vec::new(),
        };
        let set = TrainSet::from_dataset(&d);
        let val = label_random_states(&cfg, 40, 1);
        (cfg, set, val)
    }

    fn run(cfg: &ProblemConfig, set: &TrainSet, val: &TrainSet, nominal: bool) -> TrainedModel<()> {
        train(
            &cfg.training,
            &TrainOptions {
                nominal,
                progress: None,
                hold: None,
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
    fn training_is_deterministic_and_learns() {
        let (cfg, set, val) = setup(600);
        let a = run(&cfg, &set, &val, false);
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let b = pool.install(|| run(&cfg, &set, &val, false));
        assert_eq!(
            a.to_bytes(),
            b.to_bytes(),
            "same seed and data must give bit-identical models"
        );
        let first = a.history.first().unwrap().loss.total();
        let last = a.history.last().unwrap().loss.total();
        assert!(last < 0.5 * first, "loss {first} -> {last}");
        assert!(a.validation_stats.r2 > 0.95, "R² {}", a.validation_stats.r2);
        let mut other = cfg.clone();
        other.training.seed = 1;
        assert_ne!(run(&other, &set, &val, false).mlp, a.mlp);
        // Nominal and regularized start from the same initial weights.
        let mut zero = cfg.clone();
        zero.training.epochs = 1;
        zero.training.learning_rate = 1e-300;
        let (n0, r0) = (run(&zero, &set, &val, true), run(&zero, &set, &val, false));
        for (a, b) in n0.mlp.layers.iter().zip(&r0.mlp.layers) {
            for (x, y) in a.w.iter().chain(&a.b).zip(b.w.iter().chain(&b.b)) {
                assert!(
                    (x - y).abs() < 1e-250,
                    "initial parameters differ: {x} vs {y}"
                );
            }
        }
    }

    #[test]
    fn early_stop_on_target_eps_d() {
        let (mut cfg, set, val) = setup(500);
        cfg.training.target_eps_d = Some(1e6);
        let m = run(&cfg, &set, &val, false);
        assert_eq!(m.epochs_run, cfg.training.log_every);
        assert_eq!(m.history.len(), 1);
    }

    /// A warm start that keeps its best checkpoint never returns a net whose clamped errors
    /// exceed the threshold by more than its starting net's (a learning rate large enough
    /// to wreck the fit: the last weights are worse, the kept ones are not), and the score
    /// is the f64 excess of the clamped errors to f32 accuracy.
    #[test]
    fn keep_best_never_returns_a_worse_fit_than_its_start() {
        let (mut cfg, set, val) = setup(300);
        let start = run(&cfg, &set, &val, false).mlp;
        let (lo, hi) = (cfg.ocp.u_lo.clone(), cfg.ocp.u_hi.clone());
        let excess = |m: &Mlp, th: f64| -> f64 {
            let mut ws = crate::learn::mlp::Workspace::default();
            let mut u = vec![0.0; set.len() * set.nu];
            m.eval_batch(&set.x, &mut u, None, &mut ws);
            (0..set.len())
                .map(|i| {
                    let e: f64 = (0..set.nu)
                        .map(|r| {
                            (u[i * set.nu + r].clamp(lo[r], hi[r]) - set.u[i * set.nu + r]).powi(2)
                        })
                        .sum();
                    (e.sqrt() - th).max(0.0)
                })
                .sum()
        };
        cfg.training.epochs = 20;
        cfg.training.learning_rate = 0.5;
        let warm = |keep: Option<KeepBest>| -> Mlp {
            train_from::<()>(
                Some(start.clone()),
                &cfg.training,
                &TrainOptions {
                    nominal: false,
                    progress: None,
                    hold: None,
                    keep_best: keep,
                },
                &set,
                &val,
                (&cfg.domain.lo, &cfg.domain.hi),
                (&lo, &hi),
                "h",
                "d",
            )
            .mlp
        };
        for th in [0.0, 0.05] {
            let kb = KeepBest {
                every: 3,
                lo: lo.clone(),
                hi: hi.clone(),
                points: set.len(),
                threshold: th,
                u_scale: Vec::new(),
            };
            let (mut lanes, mut u) = (Lanes::default(), Vec::new());
            let (f32_score, f64_score) = (
                kb.score(&mut lanes, &mut u, &start, &set),
                excess(&start, th),
            );
            assert!(
                (f32_score - f64_score).abs() <= 1e-4 * (1.0 + f64_score) * set.len() as f64,
                "{f32_score} vs {f64_score}"
            );
            let last = warm(None);
            let kept = warm(Some(kb));
            assert!(
                excess(&last, th) > excess(&start, th),
                "the wrecked run is not worse: the test tests nothing"
            );
            assert!(
                excess(&kept, th) <= excess(&start, th) * (1.0 + 1e-4) + 1e-6,
                "θ {th}"
            );
        }
    }

    /// The curve computed on its own thread (no early stop) is the curve computed in place
    /// (an early stop that never fires), point for point, in both precisions, with a
    /// snapshot every epoch (more than the channel holds: the loop waits for the curve).
    #[test]
    fn the_curve_on_its_thread_is_the_curve_in_place() {
        for precision in [Precision::F32, Precision::F64] {
            let (mut cfg, set, val) = setup(40);
            cfg.training.precision = precision;
            cfg.training.log_every = 1;
            let a = run(&cfg, &set, &val, false);
            cfg.training.target_eps_d = Some(0.0);
            let b = run(&cfg, &set, &val, false);
            assert_eq!(b.epochs_run, 40, "{precision:?}");
            assert_eq!(a.history.len(), 40, "{precision:?}");
            let bits = |m: &TrainedModel<()>| -> Vec<u64> {
                m.history
                    .iter()
                    .flat_map(|h| {
                        let l = h.loss;
                        [
                            h.epoch as f64,
                            l.value,
                            l.jacobian,
                            l.weights,
                            h.eps_d,
                            h.r2_validation,
                        ]
                    })
                    .map(f64::to_bits)
                    .collect()
            };
            assert_eq!(bits(&a), bits(&b), "{precision:?}");
            assert_eq!(a.mlp, b.mlp, "{precision:?}");
        }
    }

    #[test]
    fn model_file_round_trip_and_corruption() {
        let (cfg, set, val) = setup(5);
        let m = run(&cfg, &set, &val, true);
        let bytes = m.to_bytes();
        assert_eq!(TrainedModel::<()>::from_bytes(&bytes, "m").unwrap(), m);
        assert!(
            TrainedModel::<()>::from_bytes(&bytes[..bytes.len() - 3], "m.bin")
                .unwrap_err()
                .to_string()
                .contains("m.bin")
        );
        // One flipped byte anywhere is an error (never a model that evaluates to other u).
        for i in 0..bytes.len() {
            let mut b = bytes.clone();
            b[i] ^= 0x04;
            assert!(
                TrainedModel::<()>::from_bytes(&b, "m.bin").is_err(),
                "byte {i}"
            );
        }
        let mut bad = m.clone();
        bad.mlp.layers[1].w.pop();
        assert!(TrainedModel::<()>::from_bytes(&bad.to_bytes(), "m")
            .unwrap_err()
            .to_string()
            .contains("shapes"));
        // The stored problem: round trip; a file without it (older builds) keeps its bytes.
        let mut with = m.clone();
        with.problem_toml = Some(cfg.to_toml_string().unwrap());
        let wb = with.to_bytes();
        assert_eq!(TrainedModel::<()>::from_bytes(&wb, "m").unwrap(), with);
        assert_eq!(&wb[..bytes.len() - 32], &bytes[..bytes.len() - 32]);
        // An older build (postcard ignores the trailer) reads the same model.
        let old: TrainedModel<()> = postcard::from_bytes(crate::io::unseal(&wb).unwrap()).unwrap();
        assert_eq!(old, m);
    }

    proptest! {
        #![proptest_config(ProptestConfig {
        rng_seed: proptest::test_runner::RngSeed::Fixed(0x616d_7063),
        ..ProptestConfig::with_cases(200)
    })]
        #[test]
        fn model_decoder_never_panics(bytes in proptest::collection::vec(any::<u8>(), 0..600), keep_magic in any::<bool>()) {
            let mut b = bytes;
            if keep_magic && b.len() >= 8 {
                b[..8].copy_from_slice(&MODEL_MAGIC);
            }
            let _ = TrainedModel::<()>::from_bytes(&b, "fuzz");
        }
    }
}
