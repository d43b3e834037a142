//! One epoch of training ([`Passes`]): the learning rate η_t of the schedule, the seeded
//! Fisher–Yates shuffle of the sample order, and Adam steps over its minibatches.
//!
//! ```text
//! η_t = η                                    (constant)
//! η_t = η·(0.01 + 0.99·½(1 + cos(π·t/T)))   (cosine, epoch t of T)
//! order: for i = n−1 … 1, swap(i, splitmix64(key ⊕ t≪32 ⊕ i) mod (i + 1))
//! ```
//! A minibatch's gradient is computed in f32 over 8-sample lanes reading the rows in place
//! ([`Lanes::grad`]) or in f64 on a copy of its rows ([`Mlp::loss_grad`]); Adam and the
//! master weights are f64 in both. Everything is determined by (weights, order, key): the
//! same inputs give bit-identical weights.

use crate::learn::adam::Adam;
use crate::learn::metrics::TrainSet;
use crate::learn::mlp::{Batch, Grad, Lanes, LossWeights, Mlp, Workspace};
use crate::problem::{Schedule, TrainSettings};
use crate::rng::{splitmix64, FastMod};

/// The learning rate of epoch `epoch` under `settings.schedule`.
pub(super) fn learning_rate(settings: &TrainSettings, epoch: usize) -> f64 {
    match settings.schedule {
        Schedule::Constant => settings.learning_rate,
        Schedule::Cosine => {
            let f = epoch as f64 / settings.epochs as f64;
            settings.learning_rate * (0.01 + 0.99 * 0.5 * (1.0 + (std::f64::consts::PI * f).cos()))
        }
    }
}

/// The seeded Fisher–Yates shuffle of epoch `epoch`, in place; `divisors[i]` divides by
/// `i + 1` (the remainders of `%`, without its divisions).
pub(super) fn shuffle(order: &mut [usize], divisors: &[FastMod], key: u64, epoch: usize) {
    for i in (1..order.len()).rev() {
        let r = splitmix64(key ^ ((epoch as u64) << 32) ^ i as u64);
        order.swap(i, divisors[i].of(r) as usize);
    }
}

/// The optimiser and the buffers of the minibatch passes.
pub(super) struct Passes {
    adam: Adam,
    grad: Grad,
    ws: Workspace,
    lanes: Lanes,
    /// f32 lane passes (`training.precision = "f32"`) instead of f64 ones.
    f32_passes: bool,
    /// The f64 passes' copy of a minibatch: states, targets, Jacobians, Jacobian flags.
    rows: (Vec<f64>, Vec<f64>, Vec<f64>, Vec<bool>),
}

impl Passes {
    /// Fresh Adam moments for `mlp`'s parameters.
    pub(super) fn new(mlp: &Mlp, f32_passes: bool) -> Self {
        let n_params = mlp.layers.iter().map(|l| l.w.len() + l.b.len()).sum();
        Passes {
            adam: Adam::new(n_params),
            grad: mlp.zero_grad(),
            ws: Workspace::default(),
            lanes: Lanes::default(),
            f32_passes,
            rows: Default::default(),
        }
    }

    /// One Adam step with learning rate `lr` per chunk of `bs` samples of `order`.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn epoch(
        &mut self,
        mlp: &mut Mlp,
        train: &TrainSet,
        set: &Batch,
        order: &[usize],
        bs: usize,
        lam: LossWeights,
        lr: f64,
    ) {
        let (nx, nu, jr) = (train.nx, train.nu, train.jac_rows());
        for chunk in order.chunks(bs) {
            if self.f32_passes {
                // The lanes read the minibatch's rows in place.
                self.lanes.grad(mlp, set, chunk, lam, &mut self.grad);
                adam_step(&mut self.adam, mlp, &self.grad, lr);
                continue;
            }
            let (bx, bu, bdu, bj) = &mut self.rows;
            bx.clear();
            bu.clear();
            bdu.clear();
            bj.clear();
            // Element by element: rows this short cost more as `memcpy` calls.
            for &i in chunk {
                bx.extend(train.x[i * nx..(i + 1) * nx].iter());
                bu.extend(train.u[i * nu..(i + 1) * nu].iter());
                bdu.extend(train.du[i * jr * nx..(i + 1) * jr * nx].iter());
                bj.push(train.use_jac[i]);
            }
            let batch = Batch {
                x: bx,
                u: bu,
                du: bdu,
                use_jac: bj,
                band: set.band,
                seq: set.seq,
            };
            mlp.loss_grad(&batch, lam, &mut self.grad, &mut self.ws);
            adam_step(&mut self.adam, mlp, &self.grad, lr);
        }
    }
}

/// One Adam step of `mlp`'s layers (in place) with the gradient `grad`; the moments are
/// flat, layer by layer, weights then biases.
fn adam_step(adam: &mut Adam, mlp: &mut Mlp, grad: &Grad, lr: f64) {
    let c = adam.begin_step();
    let params = mlp.layers.iter_mut().zip(grad.w.iter().zip(&grad.b));
    let params =
        params.flat_map(|(l, (gw, gb))| [(&mut l.w[..], &gw[..]), (&mut l.b[..], &gb[..])]);
    adam.update(params, lr, c);
}
