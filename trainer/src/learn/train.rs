//! Training: Adam on minibatches of the sensitivity-regularized loss (the paper's
//! eq. (fullloss)), validation metrics, the training curve and the model file.
//!
//! ```text
//! loss(Θ) = λ₁·MSE + λ₂·mean‖∂κ/∂x − ∂κ_NN/∂x‖²_F + λ₃·Σ_j‖W̃_j‖²_F          (mlp module)
//! Adam:  m ← β₁m + (1−β₁)g,  v ← β₂v + (1−β₂)g²,  Θ ← Θ − η_t·m̂/(√v̂ + 1e-8)
//! ```
//! The nominal net is the same procedure with (λ₁, 0, 0). Training is single-threaded and
//! fully determined by (dataset, settings, seed): same inputs → bit-identical weights. The
//! passes run in f32 over 8-sample lanes (`training.precision = "f32"`, the default,
//! [`Lanes`]) or in f64 ([`Mlp::loss_grad`]); Adam and the master weights are f64 in both,
//! and the final statistics are f64 evaluations of the f64 net.
//! Points without a label are excluded; degenerate points keep their value term and drop
//! the Jacobian term. Metrics: ε_D = max_i ‖κ(x_i) − κ_NN(x_i)‖ over the training set
//! (eq. (explespd)) with the error distribution, and R² on MPC-labelled random states.

use crate::data::dataset::Dataset;
use crate::learn::adam::Adam;
use crate::learn::mlp::{Batch, Grad, Lanes, LossParts, LossWeights, Mlp, Workspace};
use crate::learn::setpoint::Hold;
use crate::problem::{Precision, Schedule, TrainSettings};
use crate::rng::splitmix64;
use serde::{Deserialize, Serialize};

/// Model file format version.
pub const MODEL_VERSION: u32 = 3;
/// Magic bytes of a model file.
pub const MODEL_MAGIC: [u8; 8] = *b"AMPCMODL";

/// Labelled points in training layout.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TrainSet {
    /// State dimension.
    pub nx: usize,
    /// Input dimension.
    pub nu: usize,
    /// States, row-major.
    pub x: Vec<f64>,
    /// Labels κ, row-major.
    pub u: Vec<f64>,
    /// Label Jacobians, row-major (nu × nx each).
    pub du: Vec<f64>,
    /// Whether the Jacobian label is usable (not degenerate).
    pub use_jac: Vec<bool>,
}

impl TrainSet {
    /// The labelled records of a dataset (hard and soft labels; unlabelled ones dropped).
    pub fn from_dataset(d: &Dataset) -> Self {
        let (nx, nu) = (d.header.nx as usize, d.header.nu as usize);
        let mut s = TrainSet {
            nx,
            nu,
            ..Default::default()
        };
        for r in d.records.iter().filter(|r| r.is_labelled()) {
            s.x.extend(&r.x);
            s.u.extend(&r.u);
            s.du.extend(&r.du_dx);
            s.use_jac
                .push(r.degeneracy.is_none() && r.du_dx.iter().all(|v| v.is_finite()));
        }
        s
    }
    /// Number of points.
    pub fn len(&self) -> usize {
        self.use_jac.len()
    }
    /// Whether there are no points.
    pub fn is_empty(&self) -> bool {
        self.use_jac.is_empty()
    }
}

/// Error statistics of κ_NN against labels.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct ErrorStats {
    /// Number of points.
    pub n: usize,
    /// max ‖κ − κ_NN‖ (ε_D on the training set).
    pub max: f64,
    /// Median.
    pub median: f64,
    /// 90th percentile.
    pub p90: f64,
    /// 99th percentile.
    pub p99: f64,
    /// Mean.
    pub mean: f64,
    /// R² = 1 − SS_res/SS_tot over all outputs.
    pub r2: f64,
    /// Max ‖∂κ/∂x − ∂κ_NN/∂x‖_F over points with a usable Jacobian label.
    pub max_jac_err: f64,
}

/// Errors of the network on a set, sorted ascending (for box plots), and statistics.
pub fn errors(mlp: &Mlp, set: &TrainSet) -> (Vec<f64>, ErrorStats) {
    errors_impl(mlp, set, true)
}

/// [`errors`]; without `with_jac` the Jacobians are not computed (`max_jac_err` = 0).
fn errors_impl(mlp: &Mlp, set: &TrainSet, with_jac: bool) -> (Vec<f64>, ErrorStats) {
    let (nx, nu) = (set.nx, set.nu);
    let mut ws = Workspace::default();
    // All outputs and Jacobians at once (batched; the same values as point by point).
    let (mut u_all, mut j_all) = (vec![0.0; set.len() * nu], vec![0.0; set.len() * nu * nx]);
    mlp.eval_batch(
        &set.x,
        &mut u_all,
        with_jac.then_some(&mut j_all[..]),
        &mut ws,
    );
    error_stats(set, &u_all, &j_all, with_jac, true)
}

/// The outputs of the network on a set in f32 ([`Lanes`]) and their [`curve_stats`]: the
/// training curve's validation figure under `precision = "f32"`.
fn curve_stats_lanes(lanes: &mut Lanes, mlp: &Mlp, set: &TrainSet) -> ErrorStats {
    let mut u_all = vec![0.0; set.len() * set.nu];
    lanes.eval_batch(mlp, &set.x, &mut u_all, None);
    curve_stats(set, &u_all)
}

/// The figures of the training curve from the outputs `u_all` (n × nu) on `set`: the
/// [`error_stats`] without Jacobians and without sorting the errors, so that only `n`,
/// `max` and `r2` are filled (the bits of those fields of [`error_stats`]); the quantiles
/// and the mean are NaN.
fn curve_stats(set: &TrainSet, u_all: &[f64]) -> ErrorStats {
    error_stats(set, u_all, &[], false, false).1
}

/// Error statistics of the outputs `u_all` (n × nu) and, `with_jac`, the Jacobians `j_all`
/// (n × nu·nx) against `set`. Without `sorted` the errors are returned in the set's order
/// and only `n`, `max`, `r2` and `max_jac_err` are computed (the rest NaN).
fn error_stats(
    set: &TrainSet,
    u_all: &[f64],
    j_all: &[f64],
    with_jac: bool,
    sorted: bool,
) -> (Vec<f64>, ErrorStats) {
    let (nx, nu) = (set.nx, set.nu);
    let mut errs = Vec::with_capacity(set.len());
    let (mut ss_res, mut max_jac) = (0.0, 0.0f64);
    let mut mean_u = vec![0.0; nu];
    for i in 0..set.len() {
        for r in 0..nu {
            mean_u[r] += set.u[i * nu + r] / set.len().max(1) as f64;
        }
    }
    let mut ss_tot = 0.0;
    for i in 0..set.len() {
        let u = &u_all[i * nu..(i + 1) * nu];
        let mut e2 = 0.0;
        for r in 0..nu {
            let e = u[r] - set.u[i * nu + r];
            e2 += e * e;
            ss_tot += (set.u[i * nu + r] - mean_u[r]).powi(2);
        }
        ss_res += e2;
        errs.push(e2.sqrt());
        if with_jac && set.use_jac[i] {
            let j = &j_all[i * nu * nx..(i + 1) * nu * nx];
            let je: f64 = (0..nu * nx)
                .map(|k| (j[k] - set.du[i * nu * nx + k]).powi(2))
                .sum();
            max_jac = max_jac.max(je.sqrt());
        }
    }
    if sorted {
        errs.sort_by(f64::total_cmp);
    }
    let q = |p: f64| -> f64 {
        if errs.is_empty() || !sorted {
            return f64::NAN;
        }
        let k = ((errs.len() - 1) as f64 * p).round() as usize;
        errs[k]
    };
    // The last of the sorted errors: the greatest in `total_cmp`'s order.
    let max = errs.iter().copied().max_by(f64::total_cmp);
    let stats = ErrorStats {
        n: errs.len(),
        max: max.unwrap_or(f64::NAN),
        median: q(0.5),
        p90: q(0.9),
        p99: q(0.99),
        mean: if sorted {
            errs.iter().sum::<f64>() / errs.len().max(1) as f64
        } else {
            f64::NAN
        },
        r2: if ss_tot > 0.0 {
            1.0 - ss_res / ss_tot
        } else {
            f64::NAN
        },
        max_jac_err: max_jac,
    };
    (errs, stats)
}

/// One point of the training curve.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct EpochLog {
    /// Epoch (1-based, after the epoch's updates).
    pub epoch: usize,
    /// Loss terms on the whole training set.
    pub loss: LossParts,
    /// ε_D on the training set.
    pub eps_d: f64,
    /// R² on the validation set (NaN without one).
    pub r2_validation: f64,
}

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
}

fn flatten(mlp: &Mlp) -> Vec<f64> {
    mlp.layers
        .iter()
        .flat_map(|l| l.w.iter().chain(&l.b).copied())
        .collect()
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

/// One Adam step of `mlp`'s layers (in place) with the gradient `grad`; the moments are
/// flat in the order of `flatten`.
fn adam_step(adam: &mut Adam, mlp: &mut Mlp, grad: &Grad, lr: f64) {
    let c = adam.begin_step();
    let params = mlp.layers.iter_mut().zip(grad.w.iter().zip(&grad.b));
    let params =
        params.flat_map(|(l, (gw, gb))| [(&mut l.w[..], &gw[..]), (&mut l.b[..], &gb[..])]);
    adam.update(params, lr, c);
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
    let mut widths = vec![train.nx];
    widths.extend(&settings.hidden);
    widths.push(train.nu);
    let mut mlp = match init {
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
    };
    let lam = if opts.nominal {
        LossWeights {
            value: settings.lambda[0],
            jacobian: 0.0,
            weights: 0.0,
        }
    } else {
        LossWeights {
            value: settings.lambda[0],
            jacobian: settings.lambda[1],
            weights: settings.lambda[2],
        }
    };
    let band = settings.saturation_aware.then_some(u_range);
    let (nx, nu) = (train.nx, train.nu);
    let n = train.len();
    let bs = settings.batch_size.min(n.max(1));
    let n_params = flatten(&mlp).len();
    let mut adam = Adam::new(n_params);
    let mut grad = mlp.zero_grad();
    let mut ws = Workspace::default();
    let mut lanes = Lanes::default();
    let f32_passes = settings.precision == Precision::F32;
    let (mut bx, mut bu, mut bdu, mut bj) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut order: Vec<usize> = (0..n).collect();
    let mut history = Vec::new();
    let mut epochs_run = 0;
    let mut u_curve = vec![0.0; n * nu];
    let set = Batch {
        x: &train.x,
        u: &train.u,
        du: &train.du,
        use_jac: &train.use_jac,
        band,
    };
    for epoch in 0..settings.epochs {
        let lr = match settings.schedule {
            Schedule::Constant => settings.learning_rate,
            Schedule::Cosine => {
                let f = epoch as f64 / settings.epochs as f64;
                settings.learning_rate
                    * (0.01 + 0.99 * 0.5 * (1.0 + (std::f64::consts::PI * f).cos()))
            }
        };
        // Seeded Fisher–Yates shuffle.
        for i in (1..n).rev() {
            let r =
                splitmix64(splitmix64(settings.seed ^ 0xA5A5) ^ ((epoch as u64) << 32) ^ i as u64);
            order.swap(i, (r % (i as u64 + 1)) as usize);
        }
        for chunk in order.chunks(bs) {
            if f32_passes {
                // The lanes read the minibatch's rows in place.
                lanes.grad(&mlp, &set, chunk, lam, &mut grad);
                adam_step(&mut adam, &mut mlp, &grad, lr);
                continue;
            }
            bx.clear();
            bu.clear();
            bdu.clear();
            bj.clear();
            // Element by element: rows this short cost more as `memcpy` calls.
            for &i in chunk {
                bx.extend(train.x[i * nx..(i + 1) * nx].iter());
                bu.extend(train.u[i * nu..(i + 1) * nu].iter());
                bdu.extend(train.du[i * nu * nx..(i + 1) * nu * nx].iter());
                bj.push(train.use_jac[i]);
            }
            let batch = Batch {
                x: &bx,
                u: &bu,
                du: &bdu,
                use_jac: &bj,
                band,
            };
            mlp.loss_grad(&batch, lam, &mut grad, &mut ws);
            adam_step(&mut adam, &mut mlp, &grad, lr);
        }
        epochs_run = epoch + 1;
        let last = epoch + 1 == settings.epochs;
        if (epoch + 1) % settings.log_every == 0 || last {
            let (loss, st, r2v) = if f32_passes {
                (
                    // The loss pass gives the outputs too; the curve records ε_D and
                    // the validation R² only: no Jacobians, no sorting.
                    lanes.loss_outputs(&mlp, &set, lam, &mut u_curve),
                    curve_stats(train, &u_curve),
                    curve_stats_lanes(&mut lanes, &mlp, validation).r2,
                )
            } else {
                (
                    mlp.loss(&set, lam, &mut ws),
                    errors(&mlp, train).1,
                    errors_impl(&mlp, validation, false).1.r2,
                )
            };
            let r2v = if validation.is_empty() { f64::NAN } else { r2v };
            history.push(EpochLog {
                epoch: epoch + 1,
                loss,
                eps_d: st.max,
                r2_validation: r2v,
            });
            if let Some(p) = opts.progress {
                p(epoch + 1, settings.epochs);
            }
            // Under f32 the stop is confirmed by the f64 ε_D the model reports.
            if settings
                .target_eps_d
                .is_some_and(|t| st.max <= t && (!f32_passes || errors(&mlp, train).1.max <= t))
            {
                break;
            }
        }
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
        // One flipped byte anywhere is an error (it used to evaluate to other u silently).
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
