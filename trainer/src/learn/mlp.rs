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

pub use crate::problem::Activation;
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

/// Gradient with the same shapes as the layers.
#[derive(Debug, Clone, PartialEq)]
pub struct Grad {
    /// ∂loss/∂W_j, row-major.
    pub w: Vec<Vec<f64>>,
    /// ∂loss/∂b_j.
    pub b: Vec<Vec<f64>>,
}

/// Loss weights (λ₁, λ₂, λ₃).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LossWeights {
    /// λ₁: value (MSE) term.
    pub value: f64,
    /// λ₂: Jacobian term.
    pub jacobian: f64,
    /// λ₃: weight term.
    pub weights: f64,
}

/// Loss value split into its terms (each already multiplied by its λ).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct LossParts {
    /// λ₁ · MSE.
    pub value: f64,
    /// λ₂ · mean Jacobian mismatch.
    pub jacobian: f64,
    /// λ₃ · Σ‖W̃‖²_F.
    pub weights: f64,
}

impl LossParts {
    /// Sum of the terms.
    pub fn total(&self) -> f64 {
        self.value + self.jacobian + self.weights
    }
}

/// A batch of training targets, borrowed from the dataset.
pub struct Batch<'a> {
    /// States, row-major B × nx.
    pub x: &'a [f64],
    /// Targets κ, row-major B × nu.
    pub u: &'a [f64],
    /// Target Jacobians, row-major B × (nu·nx), each row-major nu × nx.
    pub du: &'a [f64],
    /// Whether sample i's Jacobian term is used (false at degenerate points).
    pub use_jac: &'a [bool],
    /// Saturation-aware loss: the deployed output is clamped to this band (lo, hi per
    /// output). A label on a bound of the band (within [`SAT_TOL`]) with a prediction at or
    /// beyond that bound is matched exactly after the clamp, so its value and Jacobian terms
    /// are zero. `None`: the plain loss.
    pub band: Option<(&'a [f64], &'a [f64])>,
}

/// Labels within this of a band bound count as saturated (see [`Batch::band`]).
pub const SAT_TOL: f64 = 1e-6;

/// Whether output r of a sample is matched exactly after the clamp to `band`: the label
/// `target` sits on a bound and the prediction `pred` is at or beyond it.
#[inline]
pub fn clamped_exact(band: Option<(&[f64], &[f64])>, r: usize, pred: f64, target: f64) -> bool {
    match band {
        None => false,
        Some((lo, hi)) => {
            (target >= hi[r] - SAT_TOL && pred >= hi[r])
                || (target <= lo[r] + SAT_TOL && pred <= lo[r])
        }
    }
}

/// Samples per block of the batched passes (a minibatch is processed in blocks of this
/// many samples, in order, so that the buffers stay small and in cache).
const BLOCK: usize = 64;

/// Samples per register-blocked group in [`dot_block`].
const LANES: usize = 8;

/// `dst[i] = init + Σ_c w[c]·src[c·stride + i]` for `i < dst.len()`, summed over c in
/// order (the per-sample order), with the accumulators of `LANES` samples in registers.
#[inline(always)]
fn dot_block(w: &[f64], src: &[f64], stride: usize, init: f64, dst: &mut [f64]) {
    let nb = dst.len();
    let full = nb / LANES * LANES;
    let (head, tail) = dst.split_at_mut(full);
    for (g, out) in head.chunks_exact_mut(LANES).enumerate() {
        let i0 = g * LANES;
        let mut acc = [init; LANES];
        for (c, &wc) in w.iter().enumerate() {
            let s: &[f64; LANES] = src[c * stride + i0..c * stride + i0 + LANES]
                .try_into()
                .expect("LANES elements");
            for (a, &v) in acc.iter_mut().zip(s) {
                *a += wc * v;
            }
        }
        out.copy_from_slice(&acc);
    }
    for (q, out) in tail.iter_mut().enumerate() {
        let i = full + q;
        let mut acc = init;
        for (c, &wc) in w.iter().enumerate() {
            acc += wc * src[c * stride + i];
        }
        *out = acc;
    }
}

/// One row of a layer's weight gradient over a block: `gw[c] += Σ_i (ga_i a_{i,c} +
/// Σ_k gt_{k,i} T_{i,k,c})`, each sample's term formed as in the per-sample formula and
/// added in sample order, for a group of `W` columns whose accumulators stay in registers.
struct WeightGrad<'a> {
    /// ∂loss/∂z_r over the block (nb).
    gar: &'a [f64],
    /// ∂loss/∂Z_{r,k} over the block (nx × nb), empty without tangents.
    gtr: &'a [f64],
    /// Sample-major inputs (nb × inp).
    at: &'a [f64],
    /// Sample-major input tangents (nb × nx × inp).
    tt: &'a [f64],
    inp: usize,
    nx: usize,
}

impl WeightGrad<'_> {
    /// Columns `c0..c0 + W` of the row; returns `c0 + W`.
    #[inline(always)]
    fn chunk<const W: usize>(&self, c0: usize, gw: &mut [f64]) -> usize {
        let (inp, nx, nb) = (self.inp, self.nx, self.gar.len());
        let mut acc: [f64; W] = gw[c0..c0 + W].try_into().expect("W columns");
        for (i, &s0) in self.gar.iter().enumerate() {
            let a: &[f64; W] = self.at[i * inp + c0..i * inp + c0 + W]
                .try_into()
                .expect("W columns");
            let mut g = [0.0; W];
            for (g, &a) in g.iter_mut().zip(a) {
                *g = s0 * a;
            }
            if !self.gtr.is_empty() {
                for k in 0..nx {
                    let sk = self.gtr[k * nb + i];
                    let o = (i * nx + k) * inp + c0;
                    let t: &[f64; W] = self.tt[o..o + W].try_into().expect("W columns");
                    for (g, &t) in g.iter_mut().zip(t) {
                        *g += sk * t;
                    }
                }
            }
            for (a, &g) in acc.iter_mut().zip(&g) {
                *a += g;
            }
        }
        gw[c0..c0 + W].copy_from_slice(&acc);
        c0 + W
    }
}

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
        let m = self.layers.len();
        let act = self.activation;
        {
            let a0 = &mut ws.a[0][..nx * nb];
            for (c, ac) in a0.chunks_exact_mut(nb).enumerate() {
                let (cc, h) = (self.in_center[c], self.in_half[c]);
                for (v, xi) in ac.iter_mut().zip(x.chunks_exact(nx)) {
                    *v = (xi[c] - cc) / h;
                }
            }
            if tangent {
                let t0 = &mut ws.t[0][..nx * nx * nb];
                for (ck, tc) in t0.chunks_exact_mut(nb).enumerate() {
                    let (c, k) = (ck / nx, ck % nx);
                    tc.fill(if c == k { 1.0 / self.in_half[c] } else { 0.0 });
                }
            }
        }
        for (j, l) in self.layers.iter().enumerate() {
            let hidden = j + 1 < m;
            let (inp, out) = (l.inp, l.out);
            let (alo, ahi) = ws.a.split_at_mut(j + 1);
            let ap = &alo[j][..inp * nb];
            let an = &mut ahi[0][..out * nb];
            // z = b + W a, accumulated over the inputs in order.
            for ((row, &b), zr) in l.w.chunks_exact(inp).zip(&l.b).zip(an.chunks_exact_mut(nb)) {
                dot_block(row, ap, nb, b, zr);
            }
            if tangent {
                // Z = W T_{j−1} (into zt for hidden layers, straight into T_m for the output).
                let (tlo, thi) = ws.t.split_at_mut(j + 1);
                let tp = &tlo[j][..inp * nx * nb];
                let dst = if hidden {
                    &mut ws.zt[j + 1][..out * nx * nb]
                } else {
                    &mut thi[0][..out * nx * nb]
                };
                for (row, zr) in l.w.chunks_exact(inp).zip(dst.chunks_exact_mut(nx * nb)) {
                    for (k, s) in zr.chunks_exact_mut(nb).enumerate() {
                        dot_block(row, &tp[k * nb..], nx * nb, 0.0, s);
                    }
                }
            }
            if hidden {
                let dz = &mut ws.dz[j + 1][..out * nb];
                let ddz = &mut ws.ddz[j + 1][..out * nb];
                for ((z, d), dd) in an.iter_mut().zip(dz.iter_mut()).zip(ddz.iter_mut()) {
                    let (v, dv, ddv) = act.eval(*z);
                    *z = v;
                    *d = dv;
                    *dd = ddv;
                }
                if tangent {
                    let zt = &ws.zt[j + 1][..out * nx * nb];
                    let tn = &mut ws.t[j + 1][..out * nx * nb];
                    for ((tr, zr), dr) in tn
                        .chunks_exact_mut(nx * nb)
                        .zip(zt.chunks_exact(nx * nb))
                        .zip(dz.chunks_exact(nb))
                    {
                        for (tk, zk) in tr.chunks_exact_mut(nb).zip(zr.chunks_exact(nb)) {
                            for ((t, &z), &d) in tk.iter_mut().zip(zk).zip(dr) {
                                *t = d * z;
                            }
                        }
                    }
                }
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

    /// κ_NN(x) only (allocating convenience).
    pub fn predict(&self, x: &[f64]) -> Vec<f64> {
        let mut ws = Workspace::default();
        let mut u = vec![0.0; self.nu()];
        self.eval_batch(x, &mut u, None, &mut ws);
        u
    }

    /// The weight term Σ_j ‖W̃_j‖²_F (physical units).
    pub fn weight_norm2(&self) -> f64 {
        self.physical_layers()
            .iter()
            .map(|l| l.w.iter().map(|v| v * v).sum::<f64>())
            .sum()
    }

    /// Loss of a batch and its exact gradient with respect to the (scaled) parameters.
    ///
    /// Batched over blocks of samples; every sum (loss terms, gradient entries) is
    /// accumulated over the samples in batch order, as in the per-sample formulation, so
    /// the result does not depend on the block size. With λ₂ = 0 the tangent pass is
    /// skipped (its contributions are exact zeros).
    pub fn loss_grad(
        &self,
        batch: &Batch,
        lam: LossWeights,
        grad: &mut Grad,
        ws: &mut Workspace,
    ) -> LossParts {
        self.loss_impl(batch, lam, Some(grad), ws)
    }

    /// The loss of a batch only (forward and tangent passes, no gradient): the same
    /// value, bit for bit, as [`Mlp::loss_grad`] returns.
    pub fn loss(&self, batch: &Batch, lam: LossWeights, ws: &mut Workspace) -> LossParts {
        self.loss_impl(batch, lam, None, ws)
    }

    fn loss_impl(
        &self,
        batch: &Batch,
        lam: LossWeights,
        mut grad: Option<&mut Grad>,
        ws: &mut Workspace,
    ) -> LossParts {
        self.ensure(ws);
        let nx = self.nx();
        let bsz = batch.use_jac.len();
        if let Some(grad) = grad.as_deref_mut() {
            for (gw, gb) in grad.w.iter_mut().zip(grad.b.iter_mut()) {
                gw.fill(0.0);
                gb.fill(0.0);
            }
        }
        let inv_b = 1.0 / bsz.max(1) as f64;
        let tangent = lam.jacobian != 0.0;
        let mut parts = LossParts::default();
        let mut i0 = 0;
        while i0 < bsz {
            let nb = BLOCK.min(bsz - i0);
            self.pass_block(&batch.x[i0 * nx..(i0 + nb) * nx], nb, tangent, ws);
            self.output_grad(batch, i0, nb, lam, inv_b, tangent, &mut parts, ws);
            if let Some(grad) = grad.as_deref_mut() {
                self.backward_block(nb, tangent, grad, ws);
            }
            i0 += nb;
        }
        // Weight term on the physical weights: ‖W̃‖² with W̃_1 = W_1 D, W̃_m = S W_m.
        if lam.weights != 0.0 {
            let m = self.layers.len();
            for (j, l) in self.layers.iter().enumerate() {
                for r in 0..l.out {
                    let rs = if j + 1 == m { self.out_half[r] } else { 1.0 };
                    for c in 0..l.inp {
                        let cs = if j == 0 { 1.0 / self.in_half[c] } else { 1.0 };
                        let f = rs * rs * cs * cs;
                        let w = l.w[r * l.inp + c];
                        parts.weights += lam.weights * f * w * w;
                        if let Some(grad) = grad.as_deref_mut() {
                            grad.w[j][r * l.inp + c] += 2.0 * lam.weights * f * w;
                        }
                    }
                }
            }
        }
        parts
    }

    /// Loss terms of a block (accumulated into `parts` sample by sample) and the output
    /// gradients ∂loss/∂y, ∂loss/∂Y into `ws.ga`, `ws.gt`.
    #[allow(clippy::too_many_arguments)]
    fn output_grad(
        &self,
        batch: &Batch,
        i0: usize,
        nb: usize,
        lam: LossWeights,
        inv_b: f64,
        tangent: bool,
        parts: &mut LossParts,
        ws: &mut Workspace,
    ) {
        let (nx, nu, m) = (self.nx(), self.nu(), self.layers.len());
        let (y, yt) = (&ws.a[m], &ws.t[m]);
        for i in 0..nb {
            let gi = i0 + i;
            let use_jac = batch.use_jac[gi] && tangent;
            for r in 0..nu {
                let s = self.out_half[r];
                let pred = self.out_center[r] + s * y[r * nb + i];
                let exact = clamped_exact(batch.band, r, pred, batch.u[gi * nu + r]);
                let e = if exact {
                    0.0
                } else {
                    pred - batch.u[gi * nu + r]
                };
                parts.value += lam.value * inv_b * e * e;
                ws.ga[r * nb + i] = 2.0 * lam.value * inv_b * e * s;
                if !tangent {
                    continue;
                }
                for k in 0..nx {
                    let g = if use_jac && !exact {
                        let e = s * yt[(r * nx + k) * nb + i] - batch.du[gi * nu * nx + r * nx + k];
                        parts.jacobian += lam.jacobian * inv_b * e * e;
                        2.0 * lam.jacobian * inv_b * e * s
                    } else {
                        0.0
                    };
                    ws.gt[(r * nx + k) * nb + i] = g;
                }
            }
        }
    }

    /// Reverse pass of a block through all layers, adding ∂loss/∂W_j, ∂loss/∂b_j to
    /// `grad` sample by sample. `ws.ga`, `ws.gt` hold ∂/∂z_j, ∂/∂Z_j of the current layer
    /// (for the output layer z = y, Z = Y).
    fn backward_block(&self, nb: usize, tangent: bool, grad: &mut Grad, ws: &mut Workspace) {
        let (nx, m) = (self.nx(), self.layers.len());
        for j in (0..m).rev() {
            let l = &self.layers[j];
            let (inp, out) = (l.inp, l.out);
            if j + 1 < m {
                // ga, gt hold ∂/∂a_{j+1}, ∂/∂T_{j+1}: convert to ∂/∂z, ∂/∂Z.
                let d = &ws.dz[j + 1][..out * nb];
                let dd = &ws.ddz[j + 1][..out * nb];
                let ga = &mut ws.ga[..out * nb];
                if tangent {
                    let zt = &ws.zt[j + 1][..out * nx * nb];
                    let gt = &mut ws.gt[..out * nx * nb];
                    let acc = &mut ws.acc[..nb];
                    for ((((gar, dr), ddr), gtr), ztr) in ga
                        .chunks_exact_mut(nb)
                        .zip(d.chunks_exact(nb))
                        .zip(dd.chunks_exact(nb))
                        .zip(gt.chunks_exact_mut(nx * nb))
                        .zip(zt.chunks_exact(nx * nb))
                    {
                        acc.fill(0.0);
                        for (gk, zk) in gtr.chunks_exact_mut(nb).zip(ztr.chunks_exact(nb)) {
                            for (((a, g), &z), &dv) in
                                acc.iter_mut().zip(gk.iter_mut()).zip(zk).zip(dr)
                            {
                                *a += *g * z;
                                *g *= dv;
                            }
                        }
                        for (((g, &dv), &ddv), &a) in
                            gar.iter_mut().zip(dr).zip(ddr).zip(acc.iter())
                        {
                            *g = dv * *g + ddv * a;
                        }
                    }
                } else {
                    // Without tangents the Jacobian contribution is an exact zero.
                    for ((g, &dv), &ddv) in ga.iter_mut().zip(d).zip(dd) {
                        *g = dv * *g + ddv * 0.0;
                    }
                }
            }
            // Sample-major copies of the layer's inputs (gathered, written contiguously).
            {
                let ap = &ws.a[j][..inp * nb];
                for (i, dst) in ws.at[..inp * nb].chunks_exact_mut(inp).enumerate() {
                    for (d, &a) in dst.iter_mut().zip(ap[i..].iter().step_by(nb)) {
                        *d = a;
                    }
                }
                if tangent {
                    let tp = &ws.t[j][..inp * nx * nb];
                    let tt = &mut ws.tt[..inp * nx * nb];
                    for (ik, dst) in tt.chunks_exact_mut(inp).enumerate() {
                        let (i, k) = (ik / nx, ik % nx);
                        let src = tp[k * nb + i..].iter().step_by(nx * nb);
                        for (d, &t) in dst.iter_mut().zip(src) {
                            *d = t;
                        }
                    }
                }
            }
            // ∂/∂W_j[r, c] += ga_r a_c + Σ_k gt_{r,k} T_{c,k}, sample by sample.
            let at = &ws.at[..inp * nb];
            let tt = &ws.tt[..inp * nx * nb];
            let ga = &ws.ga[..out * nb];
            let gt = &ws.gt[..out * nx * nb];
            for (r, ((gwr, gbr), gar)) in grad.w[j]
                .chunks_exact_mut(inp)
                .zip(grad.b[j].iter_mut())
                .zip(ga.chunks_exact(nb))
                .enumerate()
            {
                for &s0 in gar {
                    *gbr += s0;
                }
                let gtr = if tangent {
                    &gt[r * nx * nb..(r + 1) * nx * nb]
                } else {
                    &[]
                };
                let wg = WeightGrad {
                    gar,
                    gtr,
                    at,
                    tt,
                    inp,
                    nx,
                };
                let mut c0 = 0;
                while c0 < inp {
                    c0 = match inp - c0 {
                        8.. => wg.chunk::<8>(c0, gwr),
                        4.. => wg.chunk::<4>(c0, gwr),
                        2.. => wg.chunk::<2>(c0, gwr),
                        _ => wg.chunk::<1>(c0, gwr),
                    };
                }
            }
            if j > 0 {
                // ∂/∂a_j = W_jᵀ ga, ∂/∂T_j = W_jᵀ gt, summed over the outputs in order.
                let ga2 = &mut ws.ga2[..inp * nb];
                let wcol = &mut ws.wcol[..out];
                for (c, dst) in ga2.chunks_exact_mut(nb).enumerate() {
                    for (v, row) in wcol.iter_mut().zip(l.w.chunks_exact(inp)) {
                        *v = row[c];
                    }
                    dot_block(wcol, ga, nb, 0.0, dst);
                    if tangent {
                        let gt2 = &mut ws.gt2[c * nx * nb..(c + 1) * nx * nb];
                        for (k, dst) in gt2.chunks_exact_mut(nb).enumerate() {
                            dot_block(wcol, &gt[k * nb..], nx * nb, 0.0, dst);
                        }
                    }
                }
                std::mem::swap(&mut ws.ga, &mut ws.ga2);
                std::mem::swap(&mut ws.gt, &mut ws.gt2);
            }
        }
    }

    /// A zero gradient of matching shapes.
    pub fn zero_grad(&self) -> Grad {
        Grad {
            w: self.layers.iter().map(|l| vec![0.0; l.w.len()]).collect(),
            b: self.layers.iter().map(|l| vec![0.0; l.b.len()]).collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn net(seed: u64, act: Activation, widths: &[usize]) -> Mlp {
        let nx = widths[0];
        let nu = *widths.last().unwrap();
        let lo: Vec<f64> = (0..nx).map(|i| -1.0 - i as f64).collect();
        let hi: Vec<f64> = (0..nx).map(|i| 2.0 + 0.5 * i as f64).collect();
        let mut m = Mlp::new(widths, act, seed, &lo, &hi, &vec![-3.0; nu], &vec![5.0; nu]);
        for (j, l) in m.layers.iter_mut().enumerate() {
            for (k, b) in l.b.iter_mut().enumerate() {
                *b = 0.3 * (2.0 * crate::rng::uniform(seed + 99, j as u64, k as u64) - 1.0);
            }
        }
        m
    }

    fn data(
        seed: u64,
        nx: usize,
        nu: usize,
        b: usize,
    ) -> (Vec<f64>, Vec<f64>, Vec<f64>, Vec<bool>) {
        let r = |a: u64, k: usize| 4.0 * crate::rng::uniform(seed, a, k as u64) - 2.0;
        let x = (0..b * nx).map(|k| r(1, k)).collect();
        let u = (0..b * nu).map(|k| r(2, k)).collect();
        let du = (0..b * nu * nx).map(|k| 3.0 * r(3, k)).collect();
        let use_jac = (0..b).map(|i| i % 3 != 1).collect();
        (x, u, du, use_jac)
    }

    /// Central differences of the loss against the hand-derived gradient, term by term.
    fn check_grad(act: Activation, widths: &[usize], seed: u64) {
        check_grad_band(act, widths, seed, false);
        check_grad_band(act, widths, seed, true);
    }

    /// With `saturated`, the labels are clamped to a band (about half of them land on a
    /// bound) and the saturation-aware loss is used.
    fn check_grad_band(act: Activation, widths: &[usize], seed: u64, saturated: bool) {
        let m = net(seed, act, widths);
        let (nx, nu) = (m.nx(), m.nu());
        let (x, mut u, du, uj) = data(seed, nx, nu, 16);
        let (blo, bhi) = (vec![-0.3; nu], vec![0.3; nu]);
        if saturated {
            for v in u.iter_mut() {
                *v = v.clamp(-0.3, 0.3);
            }
            // The test must see both cases: clamped-exact samples and ordinary ones.
            let mut ws = Workspace::default();
            let (mut p, mut jac) = (vec![0.0; nu], vec![0.0; nu * nx]);
            let mut exact = 0;
            for i in 0..16 {
                m.eval(&x[i * nx..(i + 1) * nx], &mut p, &mut jac, &mut ws);
                for r in 0..nu {
                    exact += clamped_exact(Some((&blo, &bhi)), r, p[r], u[i * nu + r]) as usize;
                }
            }
            assert!(
                exact > 0 && exact < 16 * nu,
                "{exact} of {} clamped-exact",
                16 * nu
            );
        }
        let batch = Batch {
            x: &x,
            u: &u,
            du: &du,
            use_jac: &uj,
            band: saturated.then_some((&blo[..], &bhi[..])),
        };
        for lam in [
            LossWeights {
                value: 1.0,
                jacobian: 0.0,
                weights: 0.0,
            },
            LossWeights {
                value: 0.0,
                jacobian: 1.0,
                weights: 0.0,
            },
            LossWeights {
                value: 0.0,
                jacobian: 0.0,
                weights: 1.0,
            },
            LossWeights {
                value: 1.0,
                jacobian: 3.0,
                weights: 0.05,
            },
        ] {
            let mut ws = Workspace::default();
            let mut g = m.zero_grad();
            m.loss_grad(&batch, lam, &mut g, &mut ws);
            let h = 1e-6;
            for j in 0..m.layers.len() {
                for k in 0..m.layers[j].w.len() + m.layers[j].b.len() {
                    let nw = m.layers[j].w.len();
                    let f = |d: f64| {
                        let mut p = m.clone();
                        if k < nw {
                            p.layers[j].w[k] += d;
                        } else {
                            p.layers[j].b[k - nw] += d;
                        }
                        let mut g2 = p.zero_grad();
                        p.loss_grad(&batch, lam, &mut g2, &mut Workspace::default())
                            .total()
                    };
                    let fd = (f(h) - f(-h)) / (2.0 * h);
                    let an = if k < nw { g.w[j][k] } else { g.b[j][k - nw] };
                    assert!(
                        (fd - an).abs() <= 1e-6 * (1.0 + an.abs()),
                        "{act:?} {widths:?} {lam:?} layer {j} param {k}: fd {fd} analytic {an}"
                    );
                }
            }
        }
    }

    #[test]
    fn gradients_match_finite_differences() {
        check_grad(Activation::Tanh, &[2, 10, 10, 1], 1);
        check_grad(Activation::Tanh, &[3, 4, 2], 2);
        check_grad(Activation::Tanh, &[2, 1], 3);
        check_grad(Activation::Softplus, &[2, 5, 4, 2], 4);
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(32))]
        #[test]
        fn jacobian_matches_finite_differences(seed in 0u64..1000, x in proptest::collection::vec(-3.0f64..3.0, 3)) {
            for act in [Activation::Tanh, Activation::Softplus] {
                let m = net(seed, act, &[3, 6, 5, 2]);
                let mut ws = Workspace::default();
                let (mut u, mut j) = (vec![0.0; 2], vec![0.0; 6]);
                m.eval(&x, &mut u, &mut j, &mut ws);
                for k in 0..3 {
                    let (mut xp, mut xm) = (x.clone(), x.clone());
                    xp[k] += 1e-6;
                    xm[k] -= 1e-6;
                    let (up, um) = (m.predict(&xp), m.predict(&xm));
                    for r in 0..2 {
                        let fd = (up[r] - um[r]) / 2e-6;
                        prop_assert!((fd - j[r * 3 + k]).abs() <= 1e-6 * (1.0 + fd.abs()));
                    }
                }
            }
        }
    }

    /// The original per-sample kernels (one state at a time, scalar loops), kept as the
    /// reference the batched kernels must reproduce bit for bit.
    mod reference {
        use super::super::*;

        #[derive(Default)]
        pub struct Ws {
            a: Vec<Vec<f64>>,
            dz: Vec<Vec<f64>>,
            ddz: Vec<Vec<f64>>,
            t: Vec<Vec<f64>>,
            zt: Vec<Vec<f64>>,
            ga: Vec<f64>,
            gt: Vec<f64>,
            ga2: Vec<f64>,
            gt2: Vec<f64>,
        }

        fn ensure(mlp: &Mlp, ws: &mut Ws) {
            let nx = mlp.nx();
            let w = mlp.widths();
            ws.a = w.iter().map(|&n| vec![0.0; n]).collect();
            ws.dz = w.iter().map(|&n| vec![0.0; n]).collect();
            ws.ddz = w.iter().map(|&n| vec![0.0; n]).collect();
            ws.t = w.iter().map(|&n| vec![0.0; n * nx]).collect();
            ws.zt = w.iter().map(|&n| vec![0.0; n * nx]).collect();
            let maxw = w.into_iter().max().unwrap_or(0);
            ws.ga = vec![0.0; maxw];
            ws.ga2 = vec![0.0; maxw];
            ws.gt = vec![0.0; maxw * nx];
            ws.gt2 = vec![0.0; maxw * nx];
        }

        fn pass(mlp: &Mlp, x: &[f64], ws: &mut Ws) {
            let nx = mlp.nx();
            let m = mlp.layers.len();
            for i in 0..nx {
                ws.a[0][i] = (x[i] - mlp.in_center[i]) / mlp.in_half[i];
                for k in 0..nx {
                    ws.t[0][i * nx + k] = if i == k { 1.0 / mlp.in_half[i] } else { 0.0 };
                }
            }
            for (j, l) in mlp.layers.iter().enumerate() {
                let (prev, rest) = ws.a.split_at_mut(j + 1);
                let (tprev, trest) = ws.t.split_at_mut(j + 1);
                let (ap, an) = (&prev[j], &mut rest[0]);
                let (tp, tn) = (&tprev[j], &mut trest[0]);
                let zt = &mut ws.zt[j + 1];
                for r in 0..l.out {
                    let row = &l.w[r * l.inp..(r + 1) * l.inp];
                    let mut z = l.b[r];
                    for c in 0..l.inp {
                        z += row[c] * ap[c];
                    }
                    for k in 0..nx {
                        let mut s = 0.0;
                        for c in 0..l.inp {
                            s += row[c] * tp[c * nx + k];
                        }
                        zt[r * nx + k] = s;
                    }
                    if j + 1 < m {
                        let (v, d, dd) = mlp.activation.eval(z);
                        an[r] = v;
                        ws.dz[j + 1][r] = d;
                        ws.ddz[j + 1][r] = dd;
                        for k in 0..nx {
                            tn[r * nx + k] = d * zt[r * nx + k];
                        }
                    } else {
                        an[r] = z;
                        for k in 0..nx {
                            tn[r * nx + k] = zt[r * nx + k];
                        }
                    }
                }
            }
        }

        pub fn eval(mlp: &Mlp, x: &[f64], u: &mut [f64], jac: &mut [f64]) {
            let mut ws = Ws::default();
            ensure(mlp, &mut ws);
            pass(mlp, x, &mut ws);
            let (nx, m) = (mlp.nx(), mlp.layers.len());
            for r in 0..mlp.nu() {
                u[r] = mlp.out_center[r] + mlp.out_half[r] * ws.a[m][r];
                for k in 0..nx {
                    jac[r * nx + k] = mlp.out_half[r] * ws.t[m][r * nx + k];
                }
            }
        }

        pub fn loss_grad(mlp: &Mlp, batch: &Batch, lam: LossWeights, grad: &mut Grad) -> LossParts {
            let mut ws = Ws::default();
            ensure(mlp, &mut ws);
            let (nx, nu, m) = (mlp.nx(), mlp.nu(), mlp.layers.len());
            let bsz = batch.use_jac.len();
            for (gw, gb) in grad.w.iter_mut().zip(grad.b.iter_mut()) {
                gw.fill(0.0);
                gb.fill(0.0);
            }
            let inv_b = 1.0 / bsz.max(1) as f64;
            let mut parts = LossParts::default();
            for i in 0..bsz {
                let x = &batch.x[i * nx..(i + 1) * nx];
                pass(mlp, x, &mut ws);
                let use_jac = batch.use_jac[i] && lam.jacobian != 0.0;
                for r in 0..nu {
                    let s = mlp.out_half[r];
                    let pred = mlp.out_center[r] + s * ws.a[m][r];
                    let exact = super::clamped_exact(batch.band, r, pred, batch.u[i * nu + r]);
                    let e = if exact {
                        0.0
                    } else {
                        pred - batch.u[i * nu + r]
                    };
                    parts.value += lam.value * inv_b * e * e;
                    ws.ga[r] = 2.0 * lam.value * inv_b * e * s;
                    for k in 0..nx {
                        let g = if use_jac && !exact {
                            let e = s * ws.t[m][r * nx + k] - batch.du[i * nu * nx + r * nx + k];
                            parts.jacobian += lam.jacobian * inv_b * e * e;
                            2.0 * lam.jacobian * inv_b * e * s
                        } else {
                            0.0
                        };
                        ws.gt[r * nx + k] = g;
                    }
                }
                for j in (0..m).rev() {
                    let l = &mlp.layers[j];
                    if j + 1 < m {
                        let (d, dd, zt) = (&ws.dz[j + 1], &ws.ddz[j + 1], &ws.zt[j + 1]);
                        for r in 0..l.out {
                            let mut acc = 0.0;
                            for k in 0..nx {
                                acc += ws.gt[r * nx + k] * zt[r * nx + k];
                                ws.gt[r * nx + k] *= d[r];
                            }
                            ws.ga[r] = d[r] * ws.ga[r] + dd[r] * acc;
                        }
                    }
                    let (ap, tp) = (&ws.a[j], &ws.t[j]);
                    let gw = &mut grad.w[j];
                    for r in 0..l.out {
                        grad.b[j][r] += ws.ga[r];
                        for c in 0..l.inp {
                            let mut g = ws.ga[r] * ap[c];
                            for k in 0..nx {
                                g += ws.gt[r * nx + k] * tp[c * nx + k];
                            }
                            gw[r * l.inp + c] += g;
                        }
                    }
                    if j > 0 {
                        for c in 0..l.inp {
                            let mut g = 0.0;
                            for r in 0..l.out {
                                g += l.w[r * l.inp + c] * ws.ga[r];
                            }
                            ws.ga2[c] = g;
                            for k in 0..nx {
                                let mut g = 0.0;
                                for r in 0..l.out {
                                    g += l.w[r * l.inp + c] * ws.gt[r * nx + k];
                                }
                                ws.gt2[c * nx + k] = g;
                            }
                        }
                        std::mem::swap(&mut ws.ga, &mut ws.ga2);
                        std::mem::swap(&mut ws.gt, &mut ws.gt2);
                    }
                }
            }
            if lam.weights != 0.0 {
                for (j, l) in mlp.layers.iter().enumerate() {
                    for r in 0..l.out {
                        let rs = if j + 1 == m { mlp.out_half[r] } else { 1.0 };
                        for c in 0..l.inp {
                            let cs = if j == 0 { 1.0 / mlp.in_half[c] } else { 1.0 };
                            let f = rs * rs * cs * cs;
                            let w = l.w[r * l.inp + c];
                            parts.weights += lam.weights * f * w * w;
                            grad.w[j][r * l.inp + c] += 2.0 * lam.weights * f * w;
                        }
                    }
                }
            }
            parts
        }
    }

    fn bits(v: &[f64]) -> Vec<u64> {
        v.iter().map(|x| x.to_bits()).collect()
    }

    /// The batched kernels reproduce the per-sample reference bit for bit: loss terms,
    /// gradients, values and Jacobians, for batch sizes across the block boundary, all
    /// activations, with and without the Jacobian term.
    #[test]
    fn batched_kernels_match_the_per_sample_reference_bitwise() {
        let cases: [(Activation, &[usize]); 5] = [
            (Activation::Tanh, &[2, 10, 10, 1]),
            (Activation::Tanh, &[3, 4, 2]),
            (Activation::Tanh, &[2, 1]),
            (Activation::Softplus, &[2, 5, 4, 2]),
            (Activation::Relu, &[4, 7, 3, 5, 2]),
        ];
        for (ci, (act, widths)) in cases.into_iter().enumerate() {
            let m = net(10 + ci as u64, act, widths);
            let (nx, nu) = (m.nx(), m.nu());
            let mut ws = Workspace::default();
            for b in [1usize, 7, 35, 64, 65, 200] {
                let (x, mut u, du, uj) = data(ci as u64 + 3 * b as u64, nx, nu, b);
                let (blo, bhi) = (vec![-0.5; nu], vec![0.5; nu]);
                let banded = b % 2 == 1;
                if banded {
                    u.iter_mut().for_each(|v| *v = v.clamp(-0.5, 0.5));
                }
                let batch = Batch {
                    x: &x,
                    u: &u,
                    du: &du,
                    use_jac: &uj,
                    band: banded.then_some((&blo[..], &bhi[..])),
                };
                for lam in [
                    LossWeights {
                        value: 1.0,
                        jacobian: 3.0,
                        weights: 0.05,
                    },
                    LossWeights {
                        value: 1.0,
                        jacobian: 0.0,
                        weights: 0.0,
                    },
                ] {
                    let (mut g1, mut g2) = (m.zero_grad(), m.zero_grad());
                    let p1 = m.loss_grad(&batch, lam, &mut g1, &mut ws);
                    let p2 = reference::loss_grad(&m, &batch, lam, &mut g2);
                    let p3 = m.loss(&batch, lam, &mut ws);
                    for (q, r) in [(p1, p2), (p3, p2)] {
                        assert_eq!(
                            bits(&[q.value, q.jacobian, q.weights]),
                            bits(&[r.value, r.jacobian, r.weights]),
                            "{widths:?} b={b} {lam:?}"
                        );
                    }
                    for j in 0..m.layers.len() {
                        assert_eq!(bits(&g1.w[j]), bits(&g2.w[j]), "{widths:?} b={b} W{j}");
                        assert_eq!(bits(&g1.b[j]), bits(&g2.b[j]), "{widths:?} b={b} b{j}");
                    }
                }
                let (mut u1, mut j1) = (vec![0.0; b * nu], vec![0.0; b * nu * nx]);
                m.eval_batch(&x, &mut u1, Some(&mut j1), &mut ws);
                let mut u3 = vec![0.0; b * nu];
                m.eval_batch(&x, &mut u3, None, &mut ws);
                assert_eq!(bits(&u1), bits(&u3));
                for i in 0..b {
                    let (mut u2, mut j2) = (vec![0.0; nu], vec![0.0; nu * nx]);
                    reference::eval(&m, &x[i * nx..(i + 1) * nx], &mut u2, &mut j2);
                    assert_eq!(bits(&u1[i * nu..(i + 1) * nu]), bits(&u2));
                    assert_eq!(bits(&j1[i * nu * nx..(i + 1) * nu * nx]), bits(&j2));
                    let (mut u4, mut j4) = (vec![0.0; nu], vec![0.0; nu * nx]);
                    m.eval(&x[i * nx..(i + 1) * nx], &mut u4, &mut j4, &mut ws);
                    assert_eq!(bits(&u4), bits(&u2));
                    assert_eq!(bits(&j4), bits(&j2));
                }
            }
        }
    }

    #[test]
    fn physical_layers_compute_the_same_function() {
        let m = net(5, Activation::Tanh, &[2, 7, 3]);
        let phys = m.physical_layers();
        let x = [0.7, -1.3];
        let mut a = x.to_vec();
        for (j, l) in phys.iter().enumerate() {
            let mut z = l.b.clone();
            for r in 0..l.out {
                for c in 0..l.inp {
                    z[r] += l.w[r * l.inp + c] * a[c];
                }
            }
            a = if j + 1 < phys.len() {
                z.iter().map(|v| v.tanh()).collect()
            } else {
                z
            };
        }
        let u = m.predict(&x);
        for r in 0..3 {
            assert!((u[r] - a[r]).abs() < 1e-12);
        }
    }
}
