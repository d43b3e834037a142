//! The sets a network is measured on and what is measured: [`TrainSet`] (labelled points
//! in training layout), [`ErrorStats`], the training curve's [`EpochLog`] and the score
//! by which a training run keeps its best checkpoint ([`KeepBest`]).
//!
//! ```text
//! e_i = ‖κ(x_i) − κ_NN(x_i)‖,   ε_D = max_i e_i   (eq. (explespd)),   R² = 1 − SS_res/SS_tot
//! keep-best score = Σ_i max(0, ‖clamp(κ_NN(x_i)) − κ(x_i)‖ − θ)
//! ```
//! [`errors`] is the f64 evaluation every reported figure comes from; the training curve
//! ([`CurvePoint`]) takes ε_D and the validation R² from the pass the precision selects,
//! without sorting, and may be computed on a second thread from a snapshot of the weights
//! (the same bits: every figure is a function of the weights alone).

use crate::data::dataset::Dataset;
use crate::learn::mlp::{Batch, Lanes, LossParts, LossWeights, Mlp, Workspace};
use serde::{Deserialize, Serialize};

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
    /// A sequence net's value weight per output (empty: the net of u₀, all 1); its
    /// Jacobian labels are then those of u₀ alone (`du` holds [`TrainSet::jac_rows`] × nx
    /// per point, `crate::learn::sequence`).
    pub row_weight: Vec<f64>,
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
    /// The outputs with a Jacobian label (`nu`, or a sequence net's u₀ rows).
    pub fn jac_rows(&self) -> usize {
        match self.len() * self.nx {
            0 => self.nu,
            n => self.du.len() / n,
        }
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
pub(super) fn errors_impl(mlp: &Mlp, set: &TrainSet, with_jac: bool) -> (Vec<f64>, ErrorStats) {
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
    let (nx, nu, jr) = (set.nx, set.nu, set.jac_rows());
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
            // (A sequence net's Jacobian labels are u₀'s: its first jr rows.)
            let j = &j_all[i * nu * nx..(i + 1) * nu * nx];
            let je: f64 = (0..jr * nx)
                .map(|k| (j[k] - set.du[i * jr * nx + k]).powi(2))
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

/// Which weights a training run returns when it keeps its best checkpoint: among the
/// starting weights and the weights after every `every` epochs (and after the last), the
/// ones with the smallest total excess Σᵢ max(0, eᵢ − θ) of the errors eᵢ = ‖clamp(κ_NN(xᵢ))
/// − κᵢ‖ over the threshold θ (`threshold`) on the first `points` training points — each
/// output clamped to `[lo, hi]` first, as the controller clamps. With θ the level of
/// corner error at which a refinement retrains, the score counts how far the fit misses
/// where splitting cells cannot help. The errors are measured by the f32 lanes (a
/// selection, not a reported figure); ties keep the earlier checkpoint, so a warm start
/// never returns a net with a larger excess on the data than the net it started from.
#[derive(Debug, Clone, PartialEq)]
pub struct KeepBest {
    /// Checkpoint period in epochs (at least 1).
    pub every: usize,
    /// Lower output bounds.
    pub lo: Vec<f64>,
    /// Upper output bounds.
    pub hi: Vec<f64>,
    /// Leading points of the training set measured (later ones may repeat them).
    pub points: usize,
    /// Error threshold θ (≥ 0).
    pub threshold: f64,
    /// The norm's S_u: errors are ‖S_u⁻¹(·)‖₂ (empty: unscaled).
    pub u_scale: Vec<f64>,
}

impl KeepBest {
    /// The total excess of `mlp`'s clamped errors over the threshold on the first
    /// `self.points` points of `set` (NaN errors count as infinite).
    pub(super) fn score(
        &self,
        lanes: &mut Lanes,
        u: &mut Vec<f64>,
        mlp: &Mlp,
        set: &TrainSet,
    ) -> f64 {
        let (nx, nu) = (set.nx, set.nu);
        let n = self.points.min(set.len());
        u.resize(n * nu, 0.0);
        lanes.eval_batch(mlp, &set.x[..n * nx], u, None);
        let mut excess = 0.0;
        for (i, ui) in u.chunks_exact(nu.max(1)).enumerate().take(n) {
            let e2: f64 = (0..nu)
                .map(|r| {
                    let s = self.u_scale.get(r).copied().unwrap_or(1.0);
                    ((ui[r].clamp(self.lo[r], self.hi[r]) - set.u[i * nu + r]) / s).powi(2)
                })
                .sum();
            let e = e2.sqrt();
            excess += if e.is_nan() {
                f64::INFINITY
            } else {
                (e - self.threshold).max(0.0)
            };
        }
        excess
    }
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

/// The buffers of one computer of training-curve points (reused from point to point).
#[derive(Default)]
pub(super) struct CurvePoint {
    lanes: Lanes,
    ws: Workspace,
    u_curve: Vec<f64>,
}

impl CurvePoint {
    /// The curve's point after `epoch` for the weights `mlp`: the loss on the training set
    /// `set` (= `train`), ε_D there and R² on `validation` (NaN when it is empty); under
    /// `f32` from the f32 lanes (the loss pass gives the outputs too; no Jacobians, no
    /// sorting), else from the f64 passes. Also returns the training-set statistics.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn compute(
        &mut self,
        mlp: &Mlp,
        epoch: usize,
        set: &Batch,
        train: &TrainSet,
        validation: &TrainSet,
        lam: LossWeights,
        f32_passes: bool,
    ) -> (EpochLog, ErrorStats) {
        let (loss, st, r2v) = if f32_passes {
            self.u_curve.resize(train.len() * train.nu, 0.0);
            (
                self.lanes.loss_outputs(mlp, set, lam, &mut self.u_curve),
                curve_stats(train, &self.u_curve),
                curve_stats_lanes(&mut self.lanes, mlp, validation).r2,
            )
        } else {
            (
                mlp.loss(set, lam, &mut self.ws),
                errors(mlp, train).1,
                errors_impl(mlp, validation, false).1.r2,
            )
        };
        let r2_validation = if validation.is_empty() { f64::NAN } else { r2v };
        let log = EpochLog {
            epoch,
            loss,
            eps_d: st.max,
            r2_validation,
        };
        (log, st)
    }
}
