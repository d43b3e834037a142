//! The sequence network `[training] outputs = "sequence"`: one MLP with N·nu outputs that
//! predicts the MPC's whole optimal input sequence,
//!
//! ```text
//! κ_seq(x) = (u₀, u₁, …, u_{N−1}) ≈ (u₀*(x), …, u_{N−1}*(x)),   row-major N × nu,
//! L(θ) = λ₁/B Σ_i Σ_k w_k ‖u_k(x_i) − u_k*(x_i)‖² + λ₂/B Σ_i ‖∂u₀/∂x − ∂κ/∂x‖²_F + λ₃ Σ‖W̃‖²
//! ```
//!
//! (`w_k`: `[training] sequence_weights`, default all 1; the sensitivity term on u₀ only, as
//! the labels' ∂κ/∂x is u₀*'s). In the feedback form (`[training] sequence_form =
//! "feedback"`, [`Feedback`]) the targets of steps 1 … N−1 are offsets from the terminal
//! controller along the MPC's own predicted trajectory,
//!
//! ```text
//! c_k* = u_k* − κ_f(x_k*),  κ_f(x) = u_r + K(x − x_r),  x_0* = x, x_{k+1}* = F(x_k*, u_k*),
//! ```
//!
//! so that the device's realisation v_k = Π_U(κ_f(x̂_k) + c_k) (`controller_core::safe`)
//! reproduces u* exactly when the net is exact, and its errors pass through the loop closed
//! by K. u₀'s target is u₀* in both forms. The model's main network ([`TrainedModel::mlp`], the one
//! every later stage certifies, exports and simulates) is the **u₀ rows** of the sequence
//! net ([`first_rows`]: the last layer's first nu rows, biases and output scales — the same
//! operations, so the same bits, as the sequence net's first nu outputs); the sequence net
//! itself is [`TrainedModel::sequence`], stored in the model file's trailer
//! (`learn::model_file`), which checks on reading that its u₀ rows are exactly the main net.

use crate::data::dataset::Dataset;
use crate::learn::metrics::{errors, TrainSet};
use crate::learn::mlp::Mlp;
use crate::learn::setpoint::Hold;
use crate::learn::train::{train_from, TrainOptions, TrainedModel};
use crate::mpc::law::MpcLaw;
use crate::problem::model::Discrete;
use crate::problem::ProblemConfig;
use crate::robust::terminal_nominal::safe_terminal_gain;

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
    /// The feedback form needs a terminal controller and the problem has none.
    #[error(
        "problem `{0}`: training.sequence_form = \"feedback\" needs the safe controller's \
         terminal controller (the robust design's terminal region or the nominal terminal \
         ingredients, robust::terminal_nominal), and neither exists; set \
         training.sequence_form = \"open\""
    )]
    NoTerminal(String),
}

/// The terminal controller κ_f(x) = u_r + K(x − x_r) and the model F along which a
/// feedback-form net's targets are computed (module doc).
#[derive(Debug, Clone)]
pub struct Feedback {
    /// K (nu × nx): `robust::terminal_nominal::safe_terminal_gain`, the generated plant's.
    pub k: Vec<Vec<f64>>,
    /// x_r.
    pub x_ref: Vec<f64>,
    /// u_r.
    pub u_ref: Vec<f64>,
    /// F, the OCP's discretisation.
    pub model: Discrete,
}

impl Feedback {
    /// The feedback of `cfg` when its sequence net is in the feedback form; None for the
    /// open form.
    pub fn of(cfg: &ProblemConfig) -> Result<Option<Self>, SequenceError> {
        if cfg.training.sequence_form.is_open() {
            return Ok(None);
        }
        let k =
            safe_terminal_gain(cfg).ok_or_else(|| SequenceError::NoTerminal(cfg.name.clone()))?;
        let (nx, nu) = (cfg.system.nx(), cfg.system.nu());
        Ok(Some(Feedback {
            k,
            x_ref: cfg.ocp.x_ref_or_origin(nx),
            u_ref: cfg.ocp.u_ref_or_zero(nu),
            model: Discrete::new(cfg.system.clone(), cfg.ocp.ts, cfg.ocp.rk4_substeps),
        }))
    }

    /// κ_f(x).
    pub fn terminal_input(&self, x: &[f64]) -> Vec<f64> {
        self.u_ref
            .iter()
            .zip(&self.k)
            .map(|(u, row)| {
                u + row
                    .iter()
                    .zip(x.iter().zip(&self.x_ref))
                    .map(|(k, (x, r))| k * (x - r))
                    .sum::<f64>()
            })
            .collect()
    }

    /// The targets (u₀*, c_1*, …, c_{N−1}*) of the sequence `seq` (row-major N × nu) from `x`.
    pub fn offsets(&self, x: &[f64], seq: &[f64], nu: usize) -> Vec<f64> {
        let mut out = seq.to_vec();
        let mut xk = x.to_vec();
        let mut next = vec![0.0; x.len()];
        for (k, u) in seq.chunks(nu.max(1)).enumerate() {
            if k >= 1 {
                for (o, kf) in out[k * nu..(k + 1) * nu]
                    .iter_mut()
                    .zip(self.terminal_input(&xk))
                {
                    *o -= kf;
                }
            }
            self.model.step(&xk, u, &mut next);
            std::mem::swap(&mut xk, &mut next);
        }
        out
    }

    /// The inputs u_0, u_1, … the device realises from the net's outputs `c` at `x` (f64,
    /// no projection onto U: for tests and diagnostics).
    pub fn realise(&self, x: &[f64], c: &[f64], nu: usize) -> Vec<f64> {
        let mut out = c.to_vec();
        let mut xk = x.to_vec();
        let mut next = vec![0.0; x.len()];
        for k in 0..c.len() / nu.max(1) {
            if k >= 1 {
                for (o, kf) in out[k * nu..(k + 1) * nu]
                    .iter_mut()
                    .zip(self.terminal_input(&xk))
                {
                    *o += kf;
                }
            }
            self.model.step(&xk, &out[k * nu..(k + 1) * nu], &mut next);
            std::mem::swap(&mut xk, &mut next);
        }
        out
    }
}

/// The labelled records of `d` in a sequence net's layout: targets u₀*, …, u_{N−1}* (N·nu
/// per point; with `feedback`, u₀*, c_1*, …, c_{N−1}*), Jacobian labels of u₀ (nu·nx per
/// point), value weights `w_k` repeated nu times. `origin` names the dataset in errors.
pub fn sequence_set(
    d: &Dataset,
    horizon: usize,
    step_weights: &[f64],
    feedback: Option<&Feedback>,
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
        .flat_map(|r| match feedback {
            Some(f) if r.seq.len() == n * nu => f.offsets(&r.x, &r.seq, nu),
            _ => r.seq.clone(),
        })
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
    let fb = Feedback::of(cfg)?;
    let set = sequence_set(data, n, &w, fb.as_ref(), origins.0)?;
    // A validation set without sequences still gives u₀'s figures below.
    let vset = sequence_set(validation, n, &w, fb.as_ref(), origins.1).unwrap_or_default();
    let (mut lo, mut hi) = tiled_range(&cfg.ocp.u_lo, &cfg.ocp.u_hi, n);
    if fb.is_some() {
        // The offsets' scale: u − κ_f spans about the width of U on either side of 0.
        let nu = cfg.system.nu();
        for j in nu..lo.len() {
            let w = hi[j] - lo[j];
            (lo[j], hi[j]) = (-w, w);
        }
    }
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
    if let Some(h) = &opts.hold {
        hold_sequence(cfg, fb.as_ref(), &h.x_ref, &mut m.mlp);
    }
    let first = first_rows(&m.mlp, nu);
    m.train_stats = errors(&first, &TrainSet::from_dataset(data)).1;
    m.validation_stats = errors(&first, &TrainSet::from_dataset(validation)).1;
    m.sequence = Some(std::mem::replace(&mut m.mlp, first));
    Ok(m)
}

/// The setpoint hold of the later steps (`learn::setpoint`, which holds u₀): the outputs
/// 1 … N−1 of `seq` at x_ref are set to their targets there — the MPC's own sequence at
/// x_ref (its offsets from κ_f in the feedback form, 0 when the MPC's plan at x_ref is
/// κ_f's). Near x_ref the online check compares costs that vanish like |x − x_ref|²; a net
/// whose later steps miss their targets at x_ref by a constant loses every comparison
/// there. u₀'s rows are left as the u₀ hold made them (the certified net's bits). Nothing
/// changes when the MPC gives no sequence at x_ref.
fn hold_sequence(cfg: &ProblemConfig, fb: Option<&Feedback>, x_ref: &[f64], seq: &mut Mlp) {
    let (n, nu) = (cfg.ocp.horizon, cfg.system.nu());
    let (label, _) = MpcLaw::new(cfg).solve(x_ref, None);
    if !label.status.is_labelled() || label.seq.len() != n * nu {
        return;
    }
    let target = match fb {
        Some(f) => f.offsets(x_ref, &label.seq, nu),
        None => label.seq,
    };
    let Some(last) = seq.layers.last() else {
        return;
    };
    let kept: Vec<f64> = last.b.iter().take(nu).copied().collect();
    Hold {
        x_ref: x_ref.to_vec(),
        u: target,
    }
    .apply(seq);
    if let Some(l) = seq.layers.last_mut() {
        l.b[..kept.len()].copy_from_slice(&kept);
    }
}

#[cfg(test)]
mod tests;
