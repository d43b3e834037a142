//! The sequence network `[training] outputs = "sequence"`: one MLP with N·nu outputs that
//! predicts the MPC's whole optimal input sequence,
//!
//! ```text
//! κ_seq(x) = (u₀, u₁, …, u_{N−1}) ≈ (u₀*(x), …, u_{N−1}*(x)),   row-major N × nu,
//! L(θ) = λ₁/B Σ_i Σ_k w_k ‖u_k(x_i) − u_k*(x_i)‖² + λ₂/B Σ_i ‖∂u₀/∂x − ∂κ/∂x‖²_F + λ₃ Σ‖W̃‖²
//! ```
//!
//! (`w_k`: `[training] sequence_weights`, default all 1; the sensitivity term on u₀ only, as
//! the labels' ∂κ/∂x is u₀*'s). The model's main network ([`TrainedModel::mlp`], the one
//! every later stage certifies, exports and simulates) is the **u₀ rows** of the sequence
//! net ([`first_rows`]: the last layer's first nu rows, biases and output scales — the same
//! operations, so the same bits, as the sequence net's first nu outputs); the sequence net
//! itself is [`TrainedModel::sequence`], stored in the model file's trailer
//! (`learn::model_file`), which checks on reading that its u₀ rows are exactly the main net.

use crate::data::dataset::Dataset;
use crate::learn::metrics::{errors, TrainSet};
use crate::learn::mlp::Mlp;
use crate::learn::train::{train_from, TrainOptions, TrainedModel};
use crate::problem::ProblemConfig;

/// A dataset cannot train a sequence net.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SequenceError {
    /// The dataset keeps no sequences (made before format 5 or without
    /// `outputs = "sequence"`).
    #[error(
        "{0}: the dataset keeps no input sequences (format {1}); label it again with \
         [training] outputs = \"sequence\""
    )]
    NoSequences(String, u32),
    /// The kept sequences have another horizon than the problem's.
    #[error("{0}: the dataset's sequences have N = {1} steps, the problem's ocp.horizon is {2}")]
    Horizon(String, usize, usize),
}

/// The labelled records of `d` in a sequence net's layout: targets u₀*, …, u_{N−1}* (N·nu
/// per point), Jacobian labels of u₀ (nu·nx per point), value weights `w_k` repeated nu
/// times. `origin` names the dataset in errors.
pub fn sequence_set(
    d: &Dataset,
    horizon: usize,
    step_weights: &[f64],
    origin: &str,
) -> Result<TrainSet, SequenceError> {
    let n = d
        .sequence_horizon()
        .ok_or_else(|| SequenceError::NoSequences(origin.to_string(), d.version))?;
    if n != horizon {
        return Err(SequenceError::Horizon(origin.to_string(), n, horizon));
    }
    let mut s = TrainSet::from_dataset(d);
    let nu = s.nu;
    s.nu = n * nu;
    s.u = d
        .records
        .iter()
        .filter(|r| r.is_labelled())
        .flat_map(|r| r.seq.iter().copied())
        .collect();
    if s.u.len() != s.len() * s.nu {
        // A labelled record without its sequence (an imported or refined one).
        return Err(SequenceError::NoSequences(origin.to_string(), d.version));
    }
    s.row_weight = step_weights
        .iter()
        .flat_map(|w| std::iter::repeat_n(*w, nu))
        .collect();
    Ok(s)
}

/// The net of the first `nu` outputs of `seq`: the last layer's first `nu` rows and biases
/// and the first `nu` output centres and half-widths (every other layer shared).
pub fn first_rows(seq: &Mlp, nu: usize) -> Mlp {
    let mut m = seq.clone();
    if let Some(l) = m.layers.last_mut() {
        let nu = nu.min(l.out);
        l.w.truncate(nu * l.inp);
        l.b.truncate(nu);
        l.out = nu;
    }
    m.out_center.truncate(nu);
    m.out_half.truncate(nu);
    m
}

/// The input range of a sequence net's outputs: U repeated over the N steps.
pub fn tiled_range(lo: &[f64], hi: &[f64], horizon: usize) -> (Vec<f64>, Vec<f64>) {
    (lo.repeat(horizon), hi.repeat(horizon))
}

/// Trains the sequence net of `cfg` on `data` (statistics on `validation`) and returns the
/// model whose main net is its u₀ rows ([`first_rows`]; the setpoint hold is folded into
/// those rows' biases, so both nets agree) with [`TrainedModel::sequence`] set. The training
/// curve's ε_D and R² are over all N·nu outputs; the model's `train_stats` and
/// `validation_stats` are the u₀ net's, as for a net of u₀ alone.
#[allow(clippy::too_many_arguments)]
pub fn train_sequence<C>(
    cfg: &ProblemConfig,
    opts: &TrainOptions,
    data: &Dataset,
    validation: &Dataset,
    origins: (&str, &str),
    problem_hash: &str,
    dataset_hash: &str,
) -> Result<TrainedModel<C>, SequenceError> {
    let n = cfg.ocp.horizon;
    let w = cfg.training.step_weights(n);
    let set = sequence_set(data, n, &w, origins.0)?;
    // A validation set without sequences still gives u₀'s figures below.
    let vset = sequence_set(validation, n, &w, origins.1).unwrap_or_default();
    let (lo, hi) = tiled_range(&cfg.ocp.u_lo, &cfg.ocp.u_hi, n);
    let mut m: TrainedModel<C> = train_from(
        None,
        &cfg.training,
        opts,
        &set,
        &vset,
        (&cfg.domain.lo, &cfg.domain.hi),
        (&lo, &hi),
        problem_hash,
        dataset_hash,
    );
    let nu = cfg.system.nu();
    let first = first_rows(&m.mlp, nu);
    m.train_stats = errors(&first, &TrainSet::from_dataset(data)).1;
    m.validation_stats = errors(&first, &TrainSet::from_dataset(validation)).1;
    m.sequence = Some(std::mem::replace(&mut m.mlp, first));
    Ok(m)
}

#[cfg(test)]
mod tests;
