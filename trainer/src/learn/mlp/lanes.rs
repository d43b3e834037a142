//! The f32 lane engine of training ([`Lanes`]): the loss of [`Mlp`], its gradient and the
//! network's outputs and Jacobians, computed in f32 over groups of `L` = 8 samples at once
//! (one `[f32; 8]` per activation, tangent and gradient entry, so that every step of the
//! passes is a vector operation), with the forward, tangent and reverse passes fused per
//! group. The equations are those of the f64 passes (module `loss`):
//! ```text
//! z_j = b_j + W_j a_{j−1},  a_j = α(z_j),       Z_j = W_j T_{j−1},  T_j = diag(α′(z_j)) Z_j
//! ∂/∂z_j = α′ ∂/∂a_j + α″ Σ_k (∂/∂T_j)_k (Z_j)_k,   ∂/∂Z_j = α′ ∂/∂T_j
//! ∂/∂W_j += ∂/∂z_j a_{j−1}ᵀ + Σ_k (∂/∂Z_j)_k (T_{j−1})_kᵀ,  ∂/∂a_{j−1} = W_jᵀ ∂/∂z_j, ∂/∂T_{j−1} = W_jᵀ ∂/∂Z_j
//! ```
//! What is f32 and what is f64: the weights are rounded to f32 once per step (the master
//! copy and Adam stay f64 in `train`), the passes run in f32, the output errors and the
//! loss terms are formed in f64 from the f32 outputs, and the per-lane gradient
//! accumulators are flushed into the f64 gradient every [`FLUSH`] groups, lanes added in
//! order. The tanh is `controller_core`'s f32 tanh (`tanh_accurate`, ≤ 7.1·10⁻⁸ from the
//! true tanh), the one the deployed controller runs.
//!
//! Deterministic: one thread, a fixed order of every sum; the result depends only on the
//! inputs, not on the thread count or on whether the AVX or the portable (SSE2 on x86_64)
//! code runs: plain IEEE f32 operations, no fused multiply-add (tanh and ReLU entirely;
//! softplus calls the platform's `expf`/`log1pf`). Note that a sample's group depends on
//! its position in the batch.

use super::loss::{value_error, Batch, Grad, LossParts, LossWeights};
use super::{Activation, Mlp};

/// Samples per group (lanes of one vector).
pub const L: usize = 8;
/// Groups between flushes of the f32 gradient accumulators into the f64 gradient.
const FLUSH: usize = 64;

type V = [f32; L];

/// Reusable buffers of the lane engine and the f32 copy of the weights.
///
/// Values and tangents travel together as *jets*: unit c of layer j holds `Q = 1 + nx`
/// lane vectors at `h[j][c·Q ..]`, the value a_c first, then the tangents T_{c,k}
/// (`Q = 1` without the tangent pass). The reverse pass uses the same layout for
/// ∂loss/∂a, ∂loss/∂T.
#[derive(Debug, Clone, Default)]
pub struct Lanes {
    /// Widths `[nx, h₁, …, nu]` the buffers are sized for.
    widths: Vec<usize>,
    /// f32 weights (row-major out × inp), their transposes (inp × out) and biases.
    w: Vec<Vec<f32>>,
    wt: Vec<Vec<f32>>,
    b: Vec<Vec<f32>>,
    /// Jets of every layer (layer 0 the scaled input, layer m the raw output y, Y).
    h: Vec<Vec<V>>,
    /// Pre-activation tangents Z_j of the hidden layers (`[r·nx + k]`).
    zt: Vec<Vec<V>>,
    /// α′(z_j), α″(z_j) of the hidden layers.
    d: Vec<Vec<V>>,
    dd: Vec<Vec<V>>,
    /// Jets of ∂loss/∂(a, T) of the current layer and of the one below.
    g: Vec<V>,
    g2: Vec<V>,
    /// Accumulator jet of one unit.
    acc: Vec<V>,

    /// Per-lane gradient accumulators.
    gw: Vec<Vec<V>>,
    gb: Vec<Vec<V>>,
}

/// `acc[i] += w·v[i]` over the lanes.
#[inline(always)]
fn fma_lanes(acc: &mut V, w: f32, v: &V) {
    // Through locals: the compiler then sees whole-vector loads and stores.
    let (mut a, x) = (*acc, *v);
    for i in 0..L {
        a[i] += w * x[i];
    }
    *acc = a;
}

/// `acc += Σ_c w[c]·h_c` over units c whose jets (q vectors each) are consecutive in `h`.
/// Specialised for the jet sizes 1–5 and 7 (nx ≤ 4 and nx = 6, and every net without the
/// tangent pass) so that the accumulators stay in registers.
#[inline(always)]
fn dot_jets(w: &[f32], h: &[V], acc: &mut [V]) {
    match acc.len() {
        1 => dot_jets_q::<1>(w, h, acc),
        2 => dot_jets_q::<2>(w, h, acc),
        3 => dot_jets_q::<3>(w, h, acc),
        4 => dot_jets_q::<4>(w, h, acc),
        5 => dot_jets_q::<5>(w, h, acc),
        7 => dot_jets_q::<7>(w, h, acc),
        q => {
            for (&wc, hc) in w.iter().zip(h.chunks_exact(q)) {
                for (a, v) in acc.iter_mut().zip(hc) {
                    fma_lanes(a, wc, v);
                }
            }
        }
    }
}

#[inline(always)]
fn dot_jets_q<const Q: usize>(w: &[f32], h: &[V], acc: &mut [V]) {
    let mut a: [V; Q] = std::array::from_fn(|k| acc[k]);
    for (&wc, hc) in w.iter().zip(h.chunks_exact(Q)) {
        for (ak, hk) in a.iter_mut().zip(hc) {
            let x = *hk;
            for i in 0..L {
                ak[i] += wc * x[i];
            }
        }
    }
    acc.copy_from_slice(&a);
}

/// `gw[c] += Σ_q g[q]·h_c[q]` lane-wise for every unit c (jets of `g.len()` vectors
/// consecutive in `h`): one row of a weight gradient.
#[inline(always)]
fn outer_jets(g: &[V], h: &[V], gw: &mut [V]) {
    let q = g.len();
    for (acc, hc) in gw.iter_mut().zip(h.chunks_exact(q)) {
        let mut s = [0.0f32; L];
        for (a, b) in g.iter().zip(hc) {
            let (a, b) = (*a, *b);
            for i in 0..L {
                s[i] += a[i] * b[i];
            }
        }
        let mut t = *acc;
        for i in 0..L {
            t[i] += s[i];
        }
        *acc = t;
    }
}

/// α, α′, α″ over the lanes of `z` (in place: `z` becomes α(z)).
#[inline(always)]
fn activate(act: Activation, z: &mut V, d: &mut V, dd: &mut V) {
    match act {
        Activation::Tanh => {
            let t = super::tanh32::tanh_lanes(z);
            for i in 0..L {
                let s = 1.0 - t[i] * t[i];
                z[i] = t[i];
                d[i] = s;
                dd[i] = -2.0 * t[i] * s;
            }
        }
        Activation::Softplus => {
            for ((z, d), dd) in z.iter_mut().zip(d.iter_mut()).zip(dd.iter_mut()) {
                let s = 1.0 / (1.0 + (-*z).exp());
                *z = if *z > 30.0 { *z } else { z.exp().ln_1p() };
                *d = s;
                *dd = s * (1.0 - s);
            }
        }
        Activation::Relu => {
            for ((z, d), dd) in z.iter_mut().zip(d.iter_mut()).zip(dd.iter_mut()) {
                let on = *z > 0.0;
                *z = if on { *z } else { 0.0 };
                *d = if on { 1.0 } else { 0.0 };
                *dd = 0.0;
            }
        }
    }
}

impl Lanes {
    /// Sizes the buffers for `mlp` (once per shape) and rounds its weights to f32.
    fn load(&mut self, mlp: &Mlp) {
        let same = self.widths.len() == mlp.layers.len() + 1
            && self.widths[0] == mlp.nx()
            && mlp
                .layers
                .iter()
                .zip(&self.widths[1..])
                .all(|(l, &n)| l.out == n);
        if !same {
            let widths = mlp.widths();
            let q = 1 + mlp.nx();
            let per = |f: usize| -> Vec<Vec<V>> {
                widths.iter().map(|&n| vec![[0.0; L]; n * f]).collect()
            };
            let maxw = widths.iter().copied().max().unwrap_or(0);
            self.h = per(q);
            self.zt = per(q - 1);
            self.d = per(1);
            self.dd = per(1);
            self.g = vec![[0.0; L]; maxw * q];
            self.g2 = vec![[0.0; L]; maxw * q];
            self.acc = vec![[0.0; L]; q];
            self.gw = mlp
                .layers
                .iter()
                .map(|l| vec![[0.0; L]; l.w.len()])
                .collect();
            self.gb = mlp
                .layers
                .iter()
                .map(|l| vec![[0.0; L]; l.b.len()])
                .collect();
            self.w = mlp.layers.iter().map(|l| vec![0.0; l.w.len()]).collect();
            self.wt = self.w.clone();
            self.b = mlp.layers.iter().map(|l| vec![0.0; l.b.len()]).collect();
            self.widths = widths;
        }
        for (l, ((w, wt), b)) in mlp.layers.iter().zip(
            self.w
                .iter_mut()
                .zip(self.wt.iter_mut())
                .zip(self.b.iter_mut()),
        ) {
            for (d, &s) in w.iter_mut().zip(&l.w) {
                *d = s as f32;
            }
            for (r, row) in w.chunks_exact(l.inp).enumerate() {
                for (c, &v) in row.iter().enumerate() {
                    wt[c * l.out + r] = v;
                }
            }
            for (d, &s) in b.iter_mut().zip(&l.b) {
                *d = s as f32;
            }
        }
    }

    /// Forward (and, with `q = 1 + nx`, tangent) pass of one group: `x` holds `nb ≤ L`
    /// states (row-major); the other lanes get the centre of X (their results are unused).
    #[inline(always)]
    fn pass(&mut self, mlp: &Mlp, x: &[f64], nb: usize, q: usize) {
        let nx = mlp.nx();
        let m = mlp.layers.len();
        for (c, h0) in self.h[0][..nx * q].chunks_exact_mut(q).enumerate() {
            let (cc, hw) = (mlp.in_center[c], mlp.in_half[c]);
            for (i, v) in h0[0].iter_mut().enumerate() {
                *v = if i < nb {
                    ((x[i * nx + c] - cc) / hw) as f32
                } else {
                    0.0
                };
            }
            // T_0 = D.
            for (k, t) in h0[1..].iter_mut().enumerate() {
                *t = [if c == k { (1.0 / hw) as f32 } else { 0.0 }; L];
            }
        }
        for j in 0..m {
            let (inp, out) = (mlp.layers[j].inp, mlp.layers[j].out);
            let hidden = j + 1 < m;
            let (w, b) = (&self.w[j], &self.b[j]);
            let (hlo, hhi) = self.h.split_at_mut(j + 1);
            let (hp, hn) = (&hlo[j][..inp * q], &mut hhi[0][..out * q]);
            let acc = &mut self.acc[..q];
            for (r, (hr, wr)) in hn.chunks_exact_mut(q).zip(w.chunks_exact(inp)).enumerate() {
                acc.fill([0.0; L]);
                acc[0] = [b[r]; L];
                dot_jets(wr, hp, acc);
                if hidden {
                    let (d, dd) = (&mut self.d[j + 1][r], &mut self.dd[j + 1][r]);
                    hr[0] = acc[0];
                    activate(mlp.activation, &mut hr[0], d, dd);
                    let zt = &mut self.zt[j + 1][r * (q - 1)..(r + 1) * (q - 1)];
                    for ((t, z), a) in hr[1..].iter_mut().zip(zt.iter_mut()).zip(&acc[1..]) {
                        *z = *a;
                        for i in 0..L {
                            t[i] = d[i] * a[i];
                        }
                    }
                } else {
                    hr.copy_from_slice(acc);
                }
            }
        }
    }

    /// The loss of `batch` and, with `grad`, its gradient (the f64 gradient is overwritten).
    /// The same loss as [`Mlp::loss_grad`] up to f32 rounding of the passes.
    pub fn loss_grad(
        &mut self,
        mlp: &Mlp,
        batch: &Batch,
        lam: LossWeights,
        grad: Option<&mut Grad>,
    ) -> LossParts {
        self.load(mlp);
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx") {
            // SAFETY: the CPU has AVX (checked just above), the one requirement of calling
            // a `#[target_feature(enable = "avx")]` function.
            return unsafe { self.loss_grad_avx(mlp, batch, lam, grad) };
        }
        self.loss_grad_impl(mlp, batch, lam, grad)
    }

    /// [`Lanes::loss_grad_impl`] compiled with AVX: 8 f32 lanes per instruction instead of
    /// 4. The same IEEE operations in the same order (AVX, not FMA: no fused multiply-add),
    /// so the same bits as the SSE2 build.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    fn loss_grad_avx(
        &mut self,
        mlp: &Mlp,
        batch: &Batch,
        lam: LossWeights,
        grad: Option<&mut Grad>,
    ) -> LossParts {
        self.loss_grad_impl(mlp, batch, lam, grad)
    }

    #[inline(always)]
    fn loss_grad_impl(
        &mut self,
        mlp: &Mlp,
        batch: &Batch,
        lam: LossWeights,
        mut grad: Option<&mut Grad>,
    ) -> LossParts {
        let (nx, nu, m) = (mlp.nx(), mlp.nu(), mlp.layers.len());
        let bsz = batch.use_jac.len();
        let inv_b = 1.0 / bsz.max(1) as f64;
        let tangent = lam.jacobian != 0.0;
        let q = if tangent { 1 + nx } else { 1 };
        if let Some(g) = grad.as_deref_mut() {
            for (gw, gb) in g.w.iter_mut().zip(g.b.iter_mut()) {
                gw.fill(0.0);
                gb.fill(0.0);
            }
        }
        self.zero_acc();
        let mut parts = LossParts::default();
        let mut groups = 0;
        for i0 in (0..bsz).step_by(L) {
            let nb = L.min(bsz - i0);
            self.pass(mlp, &batch.x[i0 * nx..(i0 + nb) * nx], nb, q);
            // Output errors in f64 from the f32 outputs; padding lanes get zero gradients.
            self.g[..nu * q].fill([0.0; L]);
            let y = &self.h[m];
            for i in 0..nb {
                let gi = i0 + i;
                let use_jac = tangent && batch.use_jac[gi];
                for r in 0..nu {
                    let s = mlp.out_half[r];
                    let pred = mlp.out_center[r] + s * f64::from(y[r * q][i]);
                    let (e, exact) = value_error(batch.band, r, pred, batch.u[gi * nu + r]);
                    parts.value += lam.value * inv_b * e * e;
                    self.g[r * q][i] = (2.0 * lam.value * inv_b * e * s) as f32;
                    if !use_jac || exact {
                        continue;
                    }
                    for k in 0..nx {
                        let yk = f64::from(y[r * q + 1 + k][i]);
                        let e = s * yk - batch.du[gi * nu * nx + r * nx + k];
                        parts.jacobian += lam.jacobian * inv_b * e * e;
                        self.g[r * q + 1 + k][i] = (2.0 * lam.jacobian * inv_b * e * s) as f32;
                    }
                }
            }
            if let Some(g) = grad.as_deref_mut() {
                self.backward(mlp, q);
                groups += 1;
                if groups % FLUSH == 0 {
                    self.flush(g);
                }
            }
        }
        if let Some(g) = grad.as_deref_mut() {
            self.flush(g);
        }
        // Weight term on the physical weights, in f64 (as the f64 path).
        mlp.add_weight_term(lam, &mut parts, grad);
        parts
    }

    fn zero_acc(&mut self) {
        for v in self.gw.iter_mut().chain(self.gb.iter_mut()) {
            v.fill([0.0; L]);
        }
    }

    /// Adds the lane accumulators into `g` (lanes in order) and zeroes them.
    fn flush(&mut self, g: &mut Grad) {
        for (acc, dst) in self
            .gw
            .iter()
            .chain(&self.gb)
            .zip(g.w.iter_mut().chain(g.b.iter_mut()))
        {
            for (v, d) in acc.iter().zip(dst.iter_mut()) {
                *d += v.iter().map(|&x| f64::from(x)).sum::<f64>();
            }
        }
        self.zero_acc();
    }

    /// Reverse pass of one group from the output jets in `g` (∂/∂y, ∂/∂Y) into the lane
    /// accumulators.
    #[inline(always)]
    fn backward(&mut self, mlp: &Mlp, q: usize) {
        let m = mlp.layers.len();
        for j in (0..m).rev() {
            let (inp, out) = (mlp.layers[j].inp, mlp.layers[j].out);
            let g = &mut self.g[..out * q];
            if j + 1 < m {
                // ∂/∂a, ∂/∂T of layer j + 1 → ∂/∂z, ∂/∂Z.
                let (d, dd) = (&self.d[j + 1], &self.dd[j + 1]);
                for (r, gr) in g.chunks_exact_mut(q).enumerate() {
                    let (d, dd) = (&d[r], &dd[r]);
                    let zt = &self.zt[j + 1][r * (q - 1)..(r + 1) * (q - 1)];
                    let mut acc = [0.0f32; L];
                    for (gk, z) in gr[1..].iter_mut().zip(zt) {
                        for i in 0..L {
                            acc[i] += gk[i] * z[i];
                            gk[i] *= d[i];
                        }
                    }
                    let g0 = &mut gr[0];
                    for i in 0..L {
                        g0[i] = d[i] * g0[i] + dd[i] * acc[i];
                    }
                }
            }
            // ∂/∂W[r, c] += Σ_q g_r[q]·h_c[q] (value and tangent terms), ∂/∂b[r] += g_r[0].
            let hp = &self.h[j][..inp * q];
            for ((gr, gwr), gb) in g
                .chunks_exact(q)
                .zip(self.gw[j].chunks_exact_mut(inp))
                .zip(self.gb[j].iter_mut())
            {
                for i in 0..L {
                    gb[i] += gr[0][i];
                }
                outer_jets(gr, hp, gwr);
            }
            if j > 0 {
                // ∂/∂(a, T)_{j−1} = Wᵀ ∂/∂(z, Z)_j.
                let g2 = &mut self.g2[..inp * q];
                for (g2c, wc) in g2.chunks_exact_mut(q).zip(self.wt[j].chunks_exact(out)) {
                    g2c.fill([0.0; L]);
                    dot_jets(wc, g, g2c);
                }
                std::mem::swap(&mut self.g, &mut self.g2);
            }
        }
    }

    /// κ_NN at the states `x` (row-major n × nx) into `u` (n × nu) and, if given, the
    /// Jacobians into `jac` (n × nu·nx), computed in f32 (the outputs of
    /// [`Mlp::eval_batch`] up to f32 rounding).
    pub fn eval_batch(&mut self, mlp: &Mlp, x: &[f64], u: &mut [f64], jac: Option<&mut [f64]>) {
        self.load(mlp);
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx") {
            // SAFETY: the CPU has AVX (checked just above), see `loss_grad`.
            return unsafe { self.eval_batch_avx(mlp, x, u, jac) };
        }
        self.eval_batch_impl(mlp, x, u, jac)
    }

    /// [`Lanes::eval_batch_impl`] compiled with AVX (the same bits, see `loss_grad_avx`).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    fn eval_batch_avx(&mut self, mlp: &Mlp, x: &[f64], u: &mut [f64], jac: Option<&mut [f64]>) {
        self.eval_batch_impl(mlp, x, u, jac)
    }

    #[inline(always)]
    fn eval_batch_impl(
        &mut self,
        mlp: &Mlp,
        x: &[f64],
        u: &mut [f64],
        mut jac: Option<&mut [f64]>,
    ) {
        let (nx, nu, m) = (mlp.nx(), mlp.nu(), mlp.layers.len());
        let n = x.len() / nx.max(1);
        for i0 in (0..n).step_by(L) {
            let nb = L.min(n - i0);
            let q = if jac.is_some() { 1 + nx } else { 1 };
            self.pass(mlp, &x[i0 * nx..(i0 + nb) * nx], nb, q);
            let y = &self.h[m];
            for i in 0..nb {
                for r in 0..nu {
                    let s = mlp.out_half[r];
                    u[(i0 + i) * nu + r] = mlp.out_center[r] + s * f64::from(y[r * q][i]);
                    if let Some(jac) = jac.as_deref_mut() {
                        for k in 0..nx {
                            jac[(i0 + i) * nu * nx + r * nx + k] =
                                s * f64::from(y[r * q + 1 + k][i]);
                        }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests;
