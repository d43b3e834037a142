//! The multilayer perceptron κ_NN = ζ_m ∘ α ∘ … ∘ α ∘ ζ₁ and its exact derivatives.
//!
//! Layers `z_j = W_j a_{j−1} + b_j`, hidden activations `a_j = α(z_j)` (tanh by default;
//! softplus and ReLU optional), linear output. Inputs and outputs are scaled so that the
//! trained parameters see X as [−1, 1]ⁿ and U as [−1, 1]ᵐ:
//! ```text
//! a_0 = D (x − c),   D = diag(1/h),  c, h = centre and half-width of X
//! u   = o + S y,     S = diag(s),    o, s = centre and half-width of the output range
//! ```
//! The input Jacobian is an explicit forward (tangent) computation,
//! `T_0 = D`, `T_j = diag(α′(z_j)) W_j T_{j−1}`, `∂κ_NN/∂x = S W_m T_{m−1}`,
//! and [`Mlp::loss_grad`] differentiates the training loss through both passes in reverse
//! mode (hand-derived; checked against central differences in the tests):
//! ```text
//! loss = λ₁/B Σ‖u_i − κ_i‖² + λ₂/B Σ_{i ∉ degenerate} ‖∂u_i/∂x − ∂κ_i/∂x‖²_F + λ₃ Σ_j ‖W̃_j‖²_F
//! ```
//! with `W̃_j` the weights in physical units (the scalings folded in: `W̃_1 = W_1 D`,
//! `W̃_m = S W_m`), so that λ₃ penalises what the paper penalises on its unscaled network.
//! The weight norm is the Frobenius norm.
//!
//! This file holds the network ([`Mlp`], [`Layer`]), its constructor and scaling, the
//! buffers of the batched passes ([`Workspace`]) and the forward pass; the other passes
//! have their own files:
//! - `tangent`: the tangent pass `T_j` (the input Jacobian);
//! - `loss`: the training loss, its reverse pass and the gradient ([`Batch`], [`Grad`]);
//! - `kernels`: the register-blocked dot products the batched passes share;
//! - `lanes`: the f32 engine of training ([`Lanes`]): the same loss and gradient over groups
//!   of 8 samples in f32 vector lanes;
//! - `tanh32`: the deployed controller's f32 tanh on lanes, branch-free, from
//!   `controller_core::activation`'s coefficients;
//! - `tests`: gradients and Jacobians against central differences, the batched kernels
//!   against the per-sample reference bit for bit.

mod kernels;
mod lanes;
mod loss;
mod tangent;
pub(crate) mod tanh32;
#[cfg(test)]
mod tests;

pub use crate::problem::Activation;
use kernels::dot_block;
/// Whether the CPU has AVX and AVX2 (each checked: one detected feature is not taken to
/// imply another).
#[cfg(target_arch = "x86_64")]
pub(crate) fn cpu_has_avx2() -> bool {
    std::arch::is_x86_feature_detected!("avx") && std::arch::is_x86_feature_detected!("avx2")
}

/// Whether the CPU has AVX, AVX2, AVX-512F and AVX-512VL (each checked).
#[cfg(target_arch = "x86_64")]
pub(crate) fn cpu_has_avx512() -> bool {
    cpu_has_avx2()
        && std::arch::is_x86_feature_detected!("avx512f")
        && std::arch::is_x86_feature_detected!("avx512vl")
}

pub use lanes::Lanes;
pub use loss::{clamped_exact, Batch, Grad, LossParts, LossWeights, SeqLoss, SAT_TOL};
use serde::{Deserialize, Serialize};

impl Activation {
    /// (α(z), α′(z), α″(z)).
    #[inline]
    pub fn eval(self, z: f64) -> (f64, f64, f64) {
        match self {
            Activation::Tanh => {
                let t = z.tanh();
                let d = 1.0 - t * t;
                (t, d, -2.0 * t * d)
            }
            Activation::Softplus => {
                let s = 1.0 / (1.0 + (-z).exp());
                let v = if z > 30.0 { z } else { z.exp().ln_1p() };
                (v, s, s * (1.0 - s))
            }
            Activation::Relu => {
                if z > 0.0 {
                    (z, 1.0, 0.0)
                } else {
                    (0.0, 0.0, 0.0)
                }
            }
        }
    }
}

/// One affine layer: `w` row-major (out × inp), bias `b`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Layer {
    /// Input width.
    pub inp: usize,
    /// Output width.
    pub out: usize,
    /// Weights, row-major out × inp.
    pub w: Vec<f64>,
    /// Bias.
    pub b: Vec<f64>,
}

/// The network with its input and output scaling.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Mlp {
    /// Layers, input to output.
    pub layers: Vec<Layer>,
    /// Hidden activation.
    pub activation: Activation,
    /// Input centre c.
    pub in_center: Vec<f64>,
    /// Input half-width h.
    pub in_half: Vec<f64>,
    /// Output centre o.
    pub out_center: Vec<f64>,
    /// Output half-width s.
    pub out_half: Vec<f64>,
}

/// Samples per block of the batched passes (a minibatch is processed in blocks of this
/// many samples, in order, so that the buffers stay small and in cache).
const BLOCK: usize = 64;

/// Reusable buffers of the batched passes. For a block of `nb` samples, layer j's
/// activations are stored feature-major (`a_j[c·nb + i]`, n_j × nb, the sample index
/// contiguous so that the loops over the block vectorise) and its tangents as
/// `t_j[(c·nx + k)·nb + i]` ((n_j·nx) × nb).
#[derive(Debug, Clone, Default)]
pub struct Workspace {
    /// Widths `[nx, h₁, …, nu]` the buffers are sized for.
    widths: Vec<usize>,
    /// Activations a_j (a_m = raw output y).
    a: Vec<Vec<f64>>,
    /// Tangents T_j (T_m = Y).
    t: Vec<Vec<f64>>,
    /// Pre-activation tangents W_j T_{j−1} of the hidden layers.
    zt: Vec<Vec<f64>>,
    /// α′(z_j).
    dz: Vec<Vec<f64>>,
    /// α″(z_j).
    ddz: Vec<Vec<f64>>,
    /// Sample-major copy of a layer's input activations (`at[i·n + c]`).
    at: Vec<f64>,
    /// Sample-major copy of a layer's input tangents (`tt[(i·nx + k)·n + c]`).
    tt: Vec<f64>,
    /// ∂loss/∂a (then ∂/∂z) of the current layer, n × nb.
    ga: Vec<f64>,
    /// ∂loss/∂T (then ∂/∂Z) of the current layer, (n·nx) × nb.
    gt: Vec<f64>,
    ga2: Vec<f64>,
    gt2: Vec<f64>,
    /// Per-sample scratch (nb).
    acc: Vec<f64>,
    /// A column of a weight matrix (max width).
    wcol: Vec<f64>,
}

impl Mlp {
    /// A network of widths `[nx, h₁, …, nu]` with seeded Glorot-uniform weights and zero
    /// biases; scaling from the input box `[lo, hi]` and output box `[u_lo, u_hi]`.
    pub fn new(
        widths: &[usize],
        activation: Activation,
        seed: u64,
        lo: &[f64],
        hi: &[f64],
        u_lo: &[f64],
        u_hi: &[f64],
    ) -> Self {
        let mut layers = Vec::new();
        for (j, w) in widths.windows(2).enumerate() {
            let (inp, out) = (w[0], w[1]);
            let lim = (6.0 / (inp + out) as f64).sqrt();
            let ws = (0..inp * out)
                .map(|k| lim * (2.0 * crate::rng::uniform(seed, j as u64, k as u64) - 1.0))
                .collect();
            layers.push(Layer {
                inp,
                out,
                w: ws,
                b: vec![0.0; out],
            });
        }
        let half = |l: &[f64], h: &[f64]| {
            l.iter()
                .zip(h)
                .map(|(a, b)| 0.5 * (b - a))
                .collect::<Vec<_>>()
        };
        let mid = |l: &[f64], h: &[f64]| {
            l.iter()
                .zip(h)
                .map(|(a, b)| 0.5 * (a + b))
                .collect::<Vec<_>>()
        };
        Mlp {
            layers,
            activation,
            in_center: mid(lo, hi),
            in_half: half(lo, hi),
            out_center: mid(u_lo, u_hi),
            out_half: half(u_lo, u_hi),
        }
    }

    /// Input dimension.
    pub fn nx(&self) -> usize {
        self.layers.first().map_or(0, |l| l.inp)
    }
    /// Output dimension.
    pub fn nu(&self) -> usize {
        self.layers.last().map_or(0, |l| l.out)
    }
    /// Layer widths `[nx, h₁, …, nu]`.
    pub fn widths(&self) -> Vec<usize> {
        let mut w = vec![self.nx()];
        w.extend(self.layers.iter().map(|l| l.out));
        w
    }

    /// The weights in physical units: `W̃_1 = W_1 D`, `W̃_m = S W_m` (both for m = 1),
    /// row-major, and the biases of the affine map from x to u (`b̃_1 = b_1 − W_1 D c`,
    /// `b̃_m = o + S b_m`).
    pub fn physical_layers(&self) -> Vec<Layer> {
        let m = self.layers.len();
        let mut out = self.layers.clone();
        for (j, l) in out.iter_mut().enumerate() {
            if j == 0 {
                for r in 0..l.out {
                    let mut shift = 0.0;
                    for c in 0..l.inp {
                        l.w[r * l.inp + c] /= self.in_half[c];
                        shift += l.w[r * l.inp + c] * self.in_center[c];
                    }
                    l.b[r] -= shift;
                }
            }
            if j + 1 == m {
                for r in 0..l.out {
                    for c in 0..l.inp {
                        l.w[r * l.inp + c] *= self.out_half[r];
                    }
                    l.b[r] = self.out_center[r] + self.out_half[r] * l.b[r];
                }
            }
        }
        out
    }

    fn ensure(&self, ws: &mut Workspace) {
        let same = ws.widths.len() == self.layers.len() + 1
            && ws.widths[0] == self.nx()
            && self
                .layers
                .iter()
                .zip(&ws.widths[1..])
                .all(|(l, &n)| l.out == n);
        if same {
            return;
        }
        let w = self.widths();
        let nx = self.nx();
        let maxw = w.iter().copied().max().unwrap_or(0);
        let per = |f: usize| -> Vec<Vec<f64>> { w.iter().map(|&n| vec![0.0; n * f]).collect() };
        ws.a = per(BLOCK);
        ws.dz = per(BLOCK);
        ws.ddz = per(BLOCK);
        ws.t = per(nx * BLOCK);
        ws.zt = per(nx * BLOCK);
        ws.at = vec![0.0; maxw * BLOCK];
        ws.tt = vec![0.0; maxw * nx * BLOCK];
        ws.ga = vec![0.0; maxw * BLOCK];
        ws.ga2 = vec![0.0; maxw * BLOCK];
        ws.gt = vec![0.0; maxw * nx * BLOCK];
        ws.gt2 = vec![0.0; maxw * nx * BLOCK];
        ws.acc = vec![0.0; BLOCK];
        ws.wcol = vec![0.0; maxw];
        ws.widths = w;
    }

    /// Forward (and, if `tangent`, tangent) pass for a block of `nb ≤ BLOCK` states
    /// (`x` row-major nb × nx); leaves activations, slopes and tangents in `ws`.
    ///
    /// Every sum is accumulated in the same order as the per-sample formulas in the module
    /// doc (bias first, then the inputs in order), so the results do not depend on `nb`.
    fn pass_block(&self, x: &[f64], nb: usize, tangent: bool, ws: &mut Workspace) {
        let nx = self.nx();
        let a0 = &mut ws.a[0][..nx * nb];
        for (c, ac) in a0.chunks_exact_mut(nb).enumerate() {
            let (cc, h) = (self.in_center[c], self.in_half[c]);
            for (v, xi) in ac.iter_mut().zip(x.chunks_exact(nx)) {
                *v = (xi[c] - cc) / h;
            }
        }
        if tangent {
            self.tangent_input(nb, ws);
        }
        for j in 0..self.layers.len() {
            self.forward_layer(j, nb, ws);
            if tangent {
                self.tangent_layer(j, nb, ws);
            }
        }
    }

    /// One layer of the forward pass over a block: `z = b + W a` from `ws.a[j]` (summed over
    /// the inputs in order) into `ws.a[j + 1]`, then, for a hidden layer, `α(z)` in place
    /// and the slopes α′(z), α″(z) into `ws.dz[j + 1]`, `ws.ddz[j + 1]`.
    fn forward_layer(&self, j: usize, nb: usize, ws: &mut Workspace) {
        let l = &self.layers[j];
        let (inp, out) = (l.inp, l.out);
        let (alo, ahi) = ws.a.split_at_mut(j + 1);
        let ap = &alo[j][..inp * nb];
        let an = &mut ahi[0][..out * nb];
        // z = b + W a, accumulated over the inputs in order.
        for ((row, &b), zr) in l.w.chunks_exact(inp).zip(&l.b).zip(an.chunks_exact_mut(nb)) {
            dot_block(row, ap, nb, b, zr);
        }
        if j + 1 < self.layers.len() {
            let act = self.activation;
            let dz = &mut ws.dz[j + 1][..out * nb];
            let ddz = &mut ws.ddz[j + 1][..out * nb];
            for ((z, d), dd) in an.iter_mut().zip(dz.iter_mut()).zip(ddz.iter_mut()) {
                let (v, dv, ddv) = act.eval(*z);
                *z = v;
                *d = dv;
                *dd = ddv;
            }
        }
    }

    /// κ_NN(x) into `u` and ∂κ_NN/∂x (row-major nu × nx) into `jac`.
    pub fn eval(&self, x: &[f64], u: &mut [f64], jac: &mut [f64], ws: &mut Workspace) {
        self.eval_batch(x, u, Some(jac), ws);
    }

    /// κ_NN at the states `x` (row-major n × nx) into `u` (n × nu) and, if given, the
    /// Jacobians ∂κ_NN/∂x into `jac` (n × nu·nx, each row-major nu × nx). The same values,
    /// bit for bit, as [`Mlp::eval`] point by point, computed block-wise.
    pub fn eval_batch(
        &self,
        x: &[f64],
        u: &mut [f64],
        mut jac: Option<&mut [f64]>,
        ws: &mut Workspace,
    ) {
        self.ensure(ws);
        let (nx, nu, m) = (self.nx(), self.nu(), self.layers.len());
        let n = x.len() / nx.max(1);
        let mut i0 = 0;
        while i0 < n {
            let nb = BLOCK.min(n - i0);
            self.pass_block(&x[i0 * nx..(i0 + nb) * nx], nb, jac.is_some(), ws);
            for r in 0..nu {
                let (o, s) = (self.out_center[r], self.out_half[r]);
                let y = &ws.a[m][r * nb..(r + 1) * nb];
                for (i, &yi) in y.iter().enumerate() {
                    u[(i0 + i) * nu + r] = o + s * yi;
                }
                if let Some(jac) = jac.as_deref_mut() {
                    for k in 0..nx {
                        let tk = &ws.t[m][(r * nx + k) * nb..(r * nx + k + 1) * nb];
                        for (i, &t) in tk.iter().enumerate() {
                            jac[(i0 + i) * nu * nx + r * nx + k] = s * t;
                        }
                    }
                }
            }
            i0 += nb;
        }
    }

    /// κ_NN(x) only (allocating convenience; the thread's workspace).
    pub fn predict(&self, x: &[f64]) -> Vec<f64> {
        let mut u = vec![0.0; self.nu()];
        with_workspace(|ws| self.eval_batch(x, &mut u, None, ws));
        u
    }
}

/// `f` with this thread's [`Workspace`] (a fresh one if it is in use further up the stack):
/// for single evaluations, where a fresh workspace's zero-filled block buffers (tens of
/// KiB) cost more than the pass. A workspace's contents never change a result.
pub fn with_workspace<R>(f: impl FnOnce(&mut Workspace) -> R) -> R {
    thread_local! {
        static WS: std::cell::RefCell<Workspace> = std::cell::RefCell::new(Workspace::default());
    }
    WS.with(|ws| match ws.try_borrow_mut() {
        Ok(mut ws) => f(&mut ws),
        Err(_) => f(&mut Workspace::default()),
    })
}
