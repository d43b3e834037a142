//! [`Statistical`]: the dimension-free, probabilistic tier of a certificate.
//!
//! **The function tested** is the deployed controller κ̂ — the state rounded to f32 and
//! projected onto the f32 domain X, the folded f32 network with the device tanh, the clamp
//! band U ⊕ [−(ε + a), ε + a] (a: the f32 allowance) — exactly as `controller-core`
//! evaluates it. It is given as a [`TestedController`]: the device model lives in `deploy`
//! (`deploy::export::Device`), which `certify` may not import, so the caller (the CLI, which
//! may use every stage) passes `deploy::export::Deployed`; this module owns the statistic,
//! not the evaluation. The statement names the function ([`Statistical::function`]). A
//! narrower band (an exported statistical level, `export --statistical-band`) never
//! increases the error: κ ∈ U and clamping to a box containing κ moves no output away
//! from it.
//!
//! **The states** are n i.i.d. uniform states of X drawn from the seed
//! [`statistical_seed`]`(model hash, user seed)`: fresh for every model tested (a retrained
//! or refined net gets new states, never the ones it was selected on), reproducible for the
//! same model. They are never training states: a drawn state equal to one of the dataset's
//! states refuses the whole draw ([`StatisticalError::TrainingState`]; with a continuous
//! uniform draw this means the streams coincide, and another `--statistical-seed` fixes it).
//!
//! From n such states with k exceedances of ε (‖κ(x) − κ̂(x)‖₂ > ε), the Clopper–Pearson
//! upper bound p̄ on p = P(‖κ − κ̂‖ > ε) at confidence 1 − β is the p̄ solving
//!
//!   P(Bin(n, p̄) ≤ k) = Σ_{i ≤ k} C(n, i) p̄ⁱ (1 − p̄)^{n−i} = β     (p̄ = 1 for k = n),
//!
//! i.e. the 1 − β quantile of Beta(k + 1, n − k); for k = 0 it is 1 − β^{1/n}. With
//! probability at least 1 − β over the draw of the states, p ≤ p̄ (Hertneck et al. 2018
//! use this form). It rests on the states being i.i.d. uniform on X and on the MPC labels
//! being κ (a state the MPC leaves unlabelled counts as an exceedance), not on Lipschitz
//! constants or cells — hence it scales to any dimension.
//!
//! **Infeasible regions.** Where the MPC has no solution there is no κ to approximate, so
//! the statement that means something is conditional ([`GivenLabelled`]): of the n states,
//! the n_L the MPC labels are — given n_L — i.i.d. uniform on the labelled part X_L of X, so
//! k_L exceedances among them give P(‖κ − κ̂‖ > ε | x ∈ X_L) ≤ p̄(n_L, k_L) at the same
//! confidence. The share of X left unlabelled gets its own bound ([`UnlabelledShare`]):
//! u unlabelled states of n give P(x ∉ X_L) ≤ p̄(n, u). The unconditional bound above
//! (an unlabelled state an exceedance) is kept: it is the conjunction's worst case.
//!
//! **Feasible, not merely labelled.** A state labelled by the soft problem (`soft`: the
//! hard OCP has no solution, the exact-penalty problem's optimum is the label) is labelled
//! but not MPC-feasible. The statement the pipeline exports is conditional on the
//! hard-feasible part X_F ⊆ X_L (status `converged`, the same test as the closed loop's
//! feasible starts): [`Statistical::given_feasible`] counts the n_F hard-feasible states
//! and their k_F exceedances, P(‖κ − κ̂‖ > ε | x ∈ X_F) ≤ p̄(n_F, k_F), and
//! [`Statistical::infeasible_share`] bounds P(x ∉ X_F) ≤ p̄(n, n − n_F) with the box of the
//! states outside X_F. The soft states' errors are reported apart
//! ([`Statistical::soft_labelled`]): the soft law near a runaway region is a penalty
//! optimum a regression net is not asked to match, and no bound rests on it.
//!
//! [`eps_for_probability`] turns it around: the smallest observed-error level ε_p such that
//! the bound for ε_p is ≤ a target p (the (k*+1)-th largest error, k* the largest count
//! whose bound is ≤ p).

use crate::data::dataset::{self, Dataset, DatasetError, GenerateOptions, Record};
use crate::mpc::sqp::SqpStatus;
use crate::problem::{ProblemConfig, SamplerKind, SamplingSettings};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The statistical tier of a certificate (`"statistical"` in `certificate.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Statistical {
    /// n: i.i.d. uniform states of X drawn (seeded).
    pub samples: u64,
    /// k: states whose error exceeds ε (unlabelled states included).
    pub exceedances: u64,
    /// 1 − β.
    pub confidence: f64,
    /// Clopper–Pearson upper bound on P(‖κ − κ̂‖₂ > ε) at that confidence (κ̂: `function`).
    pub p_exceed_upper: f64,
    /// The ε the exceedances are counted against.
    pub eps: f64,
    /// States the MPC left without a label (counted as exceedances).
    pub unlabelled: u64,
    /// Largest observed error over the labelled states.
    pub max_error: f64,
    /// Seed of the states (`crate::rng::uniform` streams): [`statistical_seed`] of
    /// `model_hash` and `user_seed`.
    pub seed: u64,
    /// The seed given by the user (`--statistical-seed`), mixed into `seed`.
    #[serde(default)]
    pub user_seed: u64,
    /// Content hash of the model tested (the states are drawn from it).
    #[serde(default)]
    pub model_hash: String,
    /// The function whose errors were counted, in words (module doc).
    #[serde(default)]
    pub function: String,
    /// The smallest ε whose bound at this confidence is ≤ `p_target` (None when n is too
    /// small for `p_target`; +∞ is written `"inf"`, see [`inf`]).
    #[serde(with = "inf::option")]
    pub eps_at_p_target: Option<f64>,
    /// The probability target of `eps_at_p_target`.
    pub p_target: f64,
    /// What the bound rests on, in words.
    pub rests_on: String,
    /// States drawn inside the cells excluded from the certified domain
    /// (`refine.exclude_infeasible`) and dropped: the n states above are uniform on X minus
    /// those cells.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub excluded_states: u64,
    /// The norm the errors are measured in (the certificate's, `[ocp] x_scale`,
    /// `u_scale`): errors are ‖S_u⁻¹(κ − κ̂)‖₂. Absent in older files: unscaled.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub norm: Option<crate::certify::norm::Norm>,
    /// `eps` per input in physical units (s_u,j·eps, rounded up). Empty in older files.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub epsilon_per_input: Vec<f64>,
    /// `eps_at_p_target` per input in physical units. Absent in older files.
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        with = "inf::option_vec"
    )]
    pub eps_at_p_target_per_input: Option<Vec<f64>>,
    /// The bound conditional on the states the MPC labels (module doc; absent in files
    /// written before it existed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub given_labelled: Option<GivenLabelled>,
    /// The bound on the share of X the MPC leaves unlabelled (module doc; absent in files
    /// written before it existed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unlabelled_share: Option<UnlabelledShare>,
    /// The bound conditional on the states where the MPC's hard OCP is feasible (module
    /// doc: soft labels excluded; absent in files written before it existed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub given_feasible: Option<GivenLabelled>,
    /// The bound on the share of X where the MPC's hard OCP has no solution (unlabelled or
    /// soft-labelled states; absent in files written before it existed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub infeasible_share: Option<UnlabelledShare>,
    /// The soft-labelled states and the controller's largest error there (module doc; no
    /// bound rests on them). Absent when there are none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub soft_labelled: Option<SoftLabelled>,
}

/// The states labelled by the soft problem only (the hard OCP infeasible) and the
/// controller's largest error against those labels, in the certificate's norm.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SoftLabelled {
    /// States labelled by the soft problem.
    pub states: u64,
    /// Largest error there (+∞ for a non-finite output).
    #[serde(with = "inf::value")]
    pub max_error: f64,
}

impl Statistical {
    /// This block stated in `norm` (errors already measured in it): the norm and the
    /// per-input physical levels of `eps` and `eps_at_p_target`.
    pub fn in_norm(mut self, norm: crate::certify::norm::Norm) -> Self {
        self.epsilon_per_input = norm.per_input(self.eps);
        self.eps_at_p_target_per_input = self.eps_at_p_target.map(|e| norm.per_input(e));
        self.norm = Some(norm);
        self
    }
}

/// P(‖κ − κ̂‖ > ε | the MPC labels x) ≤ `p_exceed_upper`: the Clopper–Pearson bound from the
/// n_L labelled states alone (given n_L they are i.i.d. uniform on the labelled part of X);
/// unlabelled states are not exceedances here, they are counted in [`UnlabelledShare`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GivenLabelled {
    /// n_L: states the MPC labelled.
    pub samples: u64,
    /// k_L: labelled states whose error exceeds ε (a non-finite output included).
    pub exceedances: u64,
    /// Clopper–Pearson upper bound p̄(n_L, k_L) at the block's confidence.
    pub p_exceed_upper: f64,
    /// The smallest ε whose conditional bound is ≤ `p_target` (None when n_L is too small;
    /// +∞ is written `"inf"`).
    #[serde(with = "inf::option")]
    pub eps_at_p_target: Option<f64>,
}

/// P(the MPC leaves x unlabelled) ≤ `p_upper` for x uniform on X (minus excluded boxes):
/// the Clopper–Pearson bound from u unlabelled states among n, at the block's confidence —
/// the share of X where the MPC has no solution (or its solver found none).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct UnlabelledShare {
    /// u: unlabelled states.
    pub unlabelled: u64,
    /// n: all states.
    pub samples: u64,
    /// Clopper–Pearson upper bound p̄(n, u).
    pub p_upper: f64,
    /// The smallest box holding every unlabelled state (lower, upper corner; None if u = 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bounding_box: Option<(Vec<f64>, Vec<f64>)>,
}

pub use crate::data::unlabelled::bounding_box;
pub use clopper::{clopper_pearson_upper, draw_for_labelled, eps_for_probability};

fn is_zero(v: &u64) -> bool {
    *v == 0
}

/// The statistical tier from per-sample errors: NaN for a state the MPC left unlabelled,
/// +∞ for a labelled state where the controller's output is not finite (an exceedance).
pub fn from_errors(
    errors: &[f64],
    eps: f64,
    confidence: f64,
    seed: u64,
    p_target: f64,
) -> Statistical {
    let bad = |e: &f64| !e.is_finite();
    let unlabelled = errors.iter().filter(|e| e.is_nan()).count() as u64;
    let exceedances = errors.iter().filter(|e| bad(e) || **e > eps).count() as u64;
    let n = errors.len() as u64;
    let labelled: Vec<f64> = errors.iter().copied().filter(|e| !e.is_nan()).collect();
    let n_l = labelled.len() as u64;
    let k_l = labelled.iter().filter(|e| bad(e) || **e > eps).count() as u64;
    let given_labelled = GivenLabelled {
        samples: n_l,
        exceedances: k_l,
        p_exceed_upper: clopper_pearson_upper(n_l, k_l, confidence),
        eps_at_p_target: eps_for_probability(&labelled, p_target, confidence),
    };
    let unlabelled_share = UnlabelledShare {
        unlabelled,
        samples: n,
        p_upper: clopper_pearson_upper(n, unlabelled, confidence),
        bounding_box: None,
    };
    Statistical {
        samples: n,
        exceedances,
        confidence,
        p_exceed_upper: clopper_pearson_upper(n, exceedances, confidence),
        eps,
        unlabelled,
        max_error: errors
            .iter()
            .filter(|e| !bad(e))
            .fold(0.0f64, |m, e| m.max(*e)),
        seed,
        user_seed: seed,
        model_hash: String::new(),
        function: String::new(),
        eps_at_p_target: eps_for_probability(errors, p_target, confidence),
        p_target,
        rests_on: "i.i.d. uniform states of X labelled by the MPC (an unlabelled state counts \
                   as an exceedance); Clopper–Pearson bound, no Lipschitz or cell assumption"
            .into(),
        excluded_states: 0,
        norm: None,
        epsilon_per_input: Vec::new(),
        eps_at_p_target_per_input: None,
        given_labelled: Some(given_labelled),
        unlabelled_share: Some(unlabelled_share),
        given_feasible: None,
        infeasible_share: None,
        soft_labelled: None,
    }
}

impl Statistical {
    /// Adds the bound given hard-feasible states, the share of X outside them and the
    /// soft-labelled states' errors (module doc). `errors` are those of [`from_errors`];
    /// `feasible[i]`: whether state i's hard OCP has a solution (a feasible state is
    /// labelled; a labelled state that is not feasible is soft-labelled).
    pub fn with_feasibility(mut self, errors: &[f64], feasible: &[bool]) -> Self {
        let bad = |e: &f64| !e.is_finite();
        let hard: Vec<f64> = errors
            .iter()
            .zip(feasible)
            .filter(|(_, f)| **f)
            .map(|(e, _)| if e.is_nan() { f64::INFINITY } else { *e })
            .collect();
        let (n, n_f) = (errors.len() as u64, hard.len() as u64);
        let k_f = hard.iter().filter(|e| bad(e) || **e > self.eps).count() as u64;
        self.given_feasible = Some(GivenLabelled {
            samples: n_f,
            exceedances: k_f,
            p_exceed_upper: clopper_pearson_upper(n_f, k_f, self.confidence),
            eps_at_p_target: eps_for_probability(&hard, self.p_target, self.confidence),
        });
        self.infeasible_share = Some(UnlabelledShare {
            unlabelled: n - n_f,
            samples: n,
            p_upper: clopper_pearson_upper(n, n - n_f, self.confidence),
            bounding_box: None,
        });
        // Labelled (not NaN) but not hard-feasible: the soft labels.
        let soft: Vec<f64> = errors
            .iter()
            .zip(feasible)
            .filter(|(e, f)| !**f && !e.is_nan())
            .map(|(e, _)| *e)
            .collect();
        self.soft_labelled = (!soft.is_empty()).then(|| SoftLabelled {
            states: soft.len() as u64,
            max_error: soft.iter().fold(0.0f64, |m, e| {
                m.max(if bad(e) { f64::INFINITY } else { *e })
            }),
        });
        self
    }
}

/// Whether `x` lies in one of the closed `boxes` (lower corner, upper corner): the test of
/// the excluded boxes of a certificate (`refine.exclude_infeasible`) on the trainer's side.
pub fn in_any_box(x: &[f64], boxes: &[(Vec<f64>, Vec<f64>)]) -> bool {
    boxes.iter().any(|(lo, hi)| {
        x.iter()
            .zip(lo.iter().zip(hi))
            .all(|(v, (l, h))| l <= v && v <= h)
    })
}

/// Default user seed of the statistical states (mixed with the model's hash by
/// [`statistical_seed`]).
pub const DEFAULT_SEED: u64 = 0x5354_4154;

/// The seed of the statistical states of the model with content hash `model_hash`: the first
/// 8 bytes (little-endian) of SHA-256("ampc statistical states\0" ‖ model_hash ‖ "\0" ‖
/// user_seed as 8 little-endian bytes). A different model gets different states.
pub fn statistical_seed(model_hash: &str, user_seed: u64) -> u64 {
    use sha2::{Digest, Sha256};
    let d = Sha256::new()
        .chain_update(b"ampc statistical states\0")
        .chain_update(model_hash.as_bytes())
        .chain_update(b"\0")
        .chain_update(user_seed.to_le_bytes())
        .finalize();
    let mut b = [0u8; 8];
    b.copy_from_slice(&d[..8]);
    u64::from_le_bytes(b)
}

/// The function the statistical tier tests: the deployed controller (module doc).
pub trait TestedController: Sync {
    /// The input the controller applies at the state `x` (physical units; a non-finite
    /// component counts as an exceedance).
    fn input(&self, x: &[f64]) -> Vec<f64>;
    /// What the function is, in words (stored in [`Statistical::function`]).
    fn describe(&self) -> String;
}

/// Errors of the statistical tier.
#[derive(Debug, thiserror::Error)]
pub enum StatisticalError {
    /// Labelling or reading the states' dataset.
    #[error(transparent)]
    Dataset(#[from] DatasetError),
    /// A drawn state is one of the training states (module doc).
    #[error(
        "statistical state {index} = {state:?} (seed {seed}) is a state of the training \
         dataset: the bound must be computed on fresh states; pass another \
         --statistical-seed"
    )]
    TrainingState {
        /// Index of the drawn state.
        index: usize,
        /// The state.
        state: Vec<f64>,
        /// The seed of the draw.
        seed: u64,
    },
}

/// Settings of a statistical certificate (`--statistical N`, `--confidence`, …).
#[derive(Debug, Clone, PartialEq)]
pub struct StatisticalOptions {
    /// n: number of i.i.d. uniform states.
    pub samples: usize,
    /// 1 − β (default 0.99).
    pub confidence: f64,
    /// Seed of the states (default [`DEFAULT_SEED`]).
    pub seed: u64,
    /// Target probability for `eps_at_p_target` (default 1e-3).
    pub p_target: f64,
    /// Show the labelling's progress bar.
    pub progress: bool,
    /// Boxes excluded from the certified domain (lower, upper corner; a local certificate's
    /// `local.excluded.boxes`): states drawn inside one are dropped, so the bound is about
    /// the uniform distribution on X minus them.
    pub excluded: Vec<(Vec<f64>, Vec<f64>)>,
}

impl Default for StatisticalOptions {
    fn default() -> Self {
        StatisticalOptions {
            samples: 0,
            confidence: 0.99,
            seed: DEFAULT_SEED,
            p_target: 1e-3,
            progress: false,
            excluded: Vec::new(),
        }
    }
}

impl StatisticalOptions {
    /// Checks the numbers; the message names the flag.
    pub fn validate(&self) -> Result<(), String> {
        if self.samples == 0 {
            return Err("--statistical must be at least 1 state".into());
        }
        if !(self.confidence > 0.0 && self.confidence < 1.0) {
            return Err(format!(
                "--confidence must lie in (0, 1), got {}",
                self.confidence
            ));
        }
        if !(self.p_target > 0.0 && self.p_target < 1.0) {
            return Err(format!(
                "--p-target must lie in (0, 1), got {}",
                self.p_target
            ));
        }
        Ok(())
    }
}

/// The labelling problem of the statistical states: `cfg` with `n` uniform random states
/// (from the seed `seed`, [`statistical_seed`]) and cold starts, so that each label depends
/// on its own state only, and no retry ladder
/// ([`counting_problem`](crate::mpc::law::ladder::counting_problem)).
pub fn sampling_problem(
    cfg: &ProblemConfig,
    opts: &StatisticalOptions,
    seed: u64,
) -> ProblemConfig {
    // (The tier counts the states the MPC leaves unlabelled: no retry ladder.)
    let mut c = crate::mpc::law::ladder::counting_problem(cfg);
    c.sampling = SamplingSettings {
        sampler: SamplerKind::Random,
        counts: c.sampling.counts.clone(),
        n: opts.samples,
        seed,
    };
    c.solver.warm_start = false;
    c
}

/// Labels shard `shard` of the statistical states of the model with content hash
/// `model_hash` into `store`: the records of that shard exactly as the unsharded labelling
/// computes them (each state and label a function of its index alone), so `trainer merge`
/// of all M shards gives the very file [`certify_statistically`] writes and reuses. No
/// bound is computed from a shard.
pub fn label_shard(
    cfg: &ProblemConfig,
    model_hash: &str,
    store: &Path,
    opts: &StatisticalOptions,
    shard: dataset::Shard,
) -> Result<Dataset, StatisticalError> {
    let sc = sampling_problem(cfg, opts, statistical_seed(model_hash, opts.seed));
    Ok(dataset::generate(
        &sc,
        store,
        &GenerateOptions {
            shard: Some(shard),
            progress: opts.progress,
        },
    )?)
}

/// The model tested and the data it was trained on, for [`certify_statistically`].
pub struct Tested<'a> {
    /// The deployed controller (module doc).
    pub controller: &'a dyn TestedController,
    /// Content hash of the model (seeds the states).
    pub model_hash: &'a str,
    /// The training states (row by row): no statistical state may equal one.
    pub training: &'a [Vec<f64>],
}

/// Refuses the draw when a drawn state equals a training state (bit for bit).
fn check_fresh<'a>(
    drawn: impl IntoIterator<Item = &'a [f64]>,
    training: &[Vec<f64>],
    seed: u64,
) -> Result<(), StatisticalError> {
    let key = |x: &[f64]| x.iter().map(|v| v.to_bits()).collect::<Vec<u64>>();
    let train: std::collections::HashSet<Vec<u64>> = training.iter().map(|x| key(x)).collect();
    for (index, x) in drawn.into_iter().enumerate() {
        if train.contains(&key(x)) {
            return Err(StatisticalError::TrainingState {
                index,
                state: x.to_vec(),
                seed,
            });
        }
    }
    Ok(())
}

/// Labels (or reuses) the statistical states in `store` (a dataset file: resumable through
/// its checkpoint, reused when complete and of the same plan — hence the same model — and
/// problem), refuses them if one is a training state, and counts the exceedances of `eps`
/// by the deployed controller `tested.controller` (module doc).
pub fn certify_statistically(
    cfg: &ProblemConfig,
    tested: &Tested<'_>,
    eps: f64,
    store: &Path,
    opts: &StatisticalOptions,
) -> Result<Statistical, StatisticalError> {
    let seed = statistical_seed(tested.model_hash, opts.seed);
    let sc = sampling_problem(cfg, opts, seed);
    let reusable = |d: &Dataset| {
        d.header.problem_hash == sc.problem_hash()
            && d.header.sampling == sc.sampling
            && d.header.shard.is_none()
            && d.records.len() == opts.samples
    };
    let data = match Dataset::load(store) {
        Ok(d) if reusable(&d) => d,
        _ => dataset::generate(
            &sc,
            store,
            &GenerateOptions {
                shard: None,
                progress: opts.progress,
            },
        )?,
    };
    check_fresh(
        data.records.iter().map(|r| r.x.as_slice()),
        tested.training,
        seed,
    )?;
    let inside = |x: &[f64]| in_any_box(x, &opts.excluded);
    // Errors in the certificate's norm ‖S_u⁻¹(κ − κ̂)‖₂ (crate::certify::norm).
    let norm = crate::certify::norm::Norm::of_problem(cfg);
    let dropped = data.records.iter().filter(|r| inside(&r.x)).count() as u64;
    let errors: Vec<f64> = data
        .records
        .iter()
        .filter(|r| !inside(&r.x))
        .map(|r| {
            if !r.is_labelled() || r.u.iter().any(|v| !v.is_finite()) {
                // Unlabelled: no κ to compare with (NaN, counted apart by `from_errors`).
                return f64::NAN;
            }
            let u = tested.controller.input(&r.x);
            let e = if u.len() == r.u.len() {
                let d: Vec<f64> = r.u.iter().zip(&u).map(|(k, v)| k - v).collect();
                norm.input_norm(&d)
            } else {
                f64::INFINITY
            };
            // A non-finite output counts as an exceedance.
            if e.is_finite() {
                e
            } else {
                f64::INFINITY
            }
        })
        .collect();
    // Hard-feasible: the hard OCP converged (the closed loop's test of a feasible start).
    let kept: Vec<_> = data.records.iter().filter(|r| !inside(&r.x)).collect();
    let unlabelled = |r: &&Record| !r.is_labelled() || r.u.iter().any(|v| !v.is_finite());
    let feasible: Vec<bool> = kept
        .iter()
        .map(|r| r.status == SqpStatus::Converged && !unlabelled(r))
        .collect();
    let mut s = from_errors(&errors, eps, opts.confidence, seed, opts.p_target)
        .with_feasibility(&errors, &feasible)
        .in_norm(norm);
    if let Some(share) = s.unlabelled_share.as_mut() {
        share.bounding_box = bounding_box(
            kept.iter()
                .filter(|r| unlabelled(r))
                .map(|r| r.x.as_slice()),
        );
    }
    if let Some(share) = s.infeasible_share.as_mut() {
        share.bounding_box = bounding_box(
            kept.iter()
                .zip(&feasible)
                .filter(|(_, f)| !**f)
                .map(|(r, _)| r.x.as_slice()),
        );
    }
    s.user_seed = opts.seed;
    s.model_hash = tested.model_hash.to_string();
    s.function = tested.controller.describe();
    let domain = if dropped > 0 {
        s.excluded_states = dropped;
        format!(
            "i.i.d. uniform states of X minus the {} excluded boxes ({dropped} of the {} \
             states drawn fell inside them and were dropped; the rest are uniform on the \
             certified domain)",
            opts.excluded.len(),
            data.records.len()
        )
    } else {
        "i.i.d. uniform states of X".to_string()
    };
    s.rests_on = format!(
        "{domain}, drawn from the model's hash (none is a training state), labelled by the MPC \
         (an unlabelled state counts as an exceedance here; `given_labelled` bounds the \
         error on the labelled states alone, `unlabelled_share` the share left unlabelled; \
         `given_feasible` on the states where the hard OCP is feasible, soft labels \
         excluded, `infeasible_share` the share where it is not); \
         the errors are those of {}; Clopper–Pearson bound, no Lipschitz or cell assumption",
        s.function
    );
    Ok(s)
}

mod clopper;
pub mod inf;
#[cfg(test)]
mod tests;
