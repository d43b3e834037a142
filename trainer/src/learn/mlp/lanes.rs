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
//! inputs, not on the thread count or on whether the AVX(-2, -512) or the portable (SSE2 on x86_64)
//! code runs: plain IEEE f32 operations, no fused multiply-add (tanh and ReLU entirely;
//! softplus calls the platform's `expf`/`log1pf`). Note that a sample's group depends on
//! its position in the batch.

use super::loss::{value_error, Batch, Grad, LossParts, LossWeights};
#[cfg(target_arch = "x86_64")]
use super::{cpu_has_avx2, cpu_has_avx512};
use super::{Activation, Mlp};
use kernels::{dot_rows, outer_chunk};

mod eval;
mod kernels;

/// Samples per group (lanes of one vector).
pub const L: usize = 8;
/// Groups between flushes of the f32 gradient accumulators into the f64 gradient.
const FLUSH: usize = 64;

type V = [f32; L];

/// Lane-wise a + b.
#[inline(always)]
fn add(a: V, b: V) -> V {
    let mut r = a;
    for i in 0..L {
        r[i] = a[i] + b[i];
    }
    r
}

/// Lane-wise a·b.
#[inline(always)]
fn mul(a: V, b: V) -> V {
    let mut r = a;
    for i in 0..L {
        r[i] = a[i] * b[i];
    }
    r
}

/// Groups per chunk for jets of `q` vectors and layers up to `maxw` units: the groups of a
/// chunk go through each layer together (the kernels keep several groups' accumulators in
/// registers); fewer groups when a chunk's jets would not stay in the L1 cache. Always a
/// divisor of [`FLUSH`], so that the flushes fall where they would group by group.
fn chunk_groups(maxw: usize, q: usize) -> usize {
    match maxw * q {
        0..=64 => 8,
        65..=128 => 4,
        129..=256 => 2,
        _ => 1,
    }
}

/// Reusable buffers of the lane engine and the f32 copy of the weights.
///
/// Values and tangents travel together as *jets*: unit c of layer j (n units) in group g
/// of the current chunk holds `Q = 1 + nx` lane vectors at `h[j][(g·n + c)·Q ..]`, the
/// value a_c first, then the tangents T_{c,k} (`Q = 1` without the tangent pass). The
/// reverse pass uses the same layout for ∂loss/∂a, ∂loss/∂T.
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
    /// Pre-activation tangents Z_j of the hidden layers (`[(g·n + r)·nx + k]`).
    zt: Vec<Vec<V>>,
    /// α′(z_j), α″(z_j) of the hidden layers (`[g·n + r]`).
    d: Vec<Vec<V>>,
    dd: Vec<Vec<V>>,
    /// Jets of ∂loss/∂(a, T) of the current layer and of the one below.
    g: Vec<V>,
    g2: Vec<V>,
    /// Accumulator jet of one unit (kernels without a specialised jet size).
    acc: Vec<V>,

    /// Per-lane gradient accumulators.
    gw: Vec<Vec<V>>,
    gb: Vec<Vec<V>>,

    /// The weight term's gradient factors ([`Mlp::weight_grad_factors`]) and what they were
    /// formed for: the bits of λ₃ and of the input and output half-widths.
    wf: Vec<Vec<f64>>,
    wf_key: Vec<u64>,
}

/// (α(z), α′(z), α″(z)) over the lanes of `z`.
#[inline(always)]
fn activate(act: Activation, z: V) -> (V, V, V) {
    match act {
        Activation::Tanh => {
            let t = super::tanh32::tanh_lanes(&z);
            let (mut d, mut dd) = ([0.0; L], [0.0; L]);
            for i in 0..L {
                let s = 1.0 - t[i] * t[i];
                d[i] = s;
                dd[i] = -2.0 * t[i] * s;
            }
            (t, d, dd)
        }
        Activation::Softplus => {
            let (mut a, mut d, mut dd) = (z, [0.0; L], [0.0; L]);
            for i in 0..L {
                let s = 1.0 / (1.0 + (-z[i]).exp());
                a[i] = if z[i] > 30.0 {
                    z[i]
                } else {
                    z[i].exp().ln_1p()
                };
                d[i] = s;
                dd[i] = s * (1.0 - s);
            }
            (a, d, dd)
        }
        Activation::Relu => {
            let (mut a, mut d) = (z, [0.0; L]);
            for i in 0..L {
                let on = z[i] > 0.0;
                a[i] = if on { z[i] } else { 0.0 };
                d[i] = if on { 1.0 } else { 0.0 };
            }
            (a, d, [0.0; L])
        }
    }
}

/// The activation of a hidden layer over a chunk, in place on the jets `h` (q vectors per
/// unit u, (z, Z) in, (a, T) out): `a = α(z)`, `T = α′(z)·Z`, keeping α′, α″ and Z for the
/// reverse pass. The tanh runs on four units at a time (32 lanes: independent chains).
#[inline(always)]
fn activate_chunk(act: Activation, h: &mut [V], d: &mut [V], dd: &mut [V], zt: &mut [V], q: usize) {
    let n = h.len() / q;
    let mut u0 = 0;
    // Z saved and T formed in one loop (a separate copy of a few vectors is a `memcpy` call).
    let finish = |h: &mut [V], zt: &mut [V], u: usize, a: V, dv: V| {
        let hu = &mut h[u * q..(u + 1) * q];
        hu[0] = a;
        for (t, z) in hu[1..]
            .iter_mut()
            .zip(&mut zt[u * (q - 1)..(u + 1) * (q - 1)])
        {
            *z = *t;
            *t = mul(dv, *t);
        }
    };
    if act == Activation::Tanh {
        const B: usize = 4;
        while u0 + B <= n {
            let mut z = [0.0f32; B * L];
            for (b, zb) in z.as_chunks_mut::<L>().0.iter_mut().enumerate() {
                *zb = h[(u0 + b) * q];
            }
            let t = super::tanh32::tanh_lanes(&z);
            for (b, &tb) in t.as_chunks::<L>().0.iter().enumerate() {
                let u = u0 + b;
                let (mut dv, mut ddv) = ([0.0; L], [0.0; L]);
                for i in 0..L {
                    let s = 1.0 - tb[i] * tb[i];
                    dv[i] = s;
                    ddv[i] = -2.0 * tb[i] * s;
                }
                (d[u], dd[u]) = (dv, ddv);
                finish(h, zt, u, tb, dv);
            }
            u0 += B;
        }
    }
    for u in u0..n {
        let (a, dv, ddv) = activate(act, h[u * q]);
        (d[u], dd[u]) = (dv, ddv);
        finish(h, zt, u, a, dv);
    }
}

/// ∂/∂a, ∂/∂T → ∂/∂z, ∂/∂Z of a hidden layer over a chunk, in place on the jets `g` (q
/// vectors per unit u): `∂/∂z = α′·∂/∂a + α″·Σ_k (∂/∂T)_k Z_k`, `∂/∂Z = α′·∂/∂T`.
#[inline(always)]
fn activation_back(g: &mut [V], d: &[V], dd: &[V], zt: &[V], q: usize) {
    match q {
        1 => act_back_q::<1>(g, d, dd, zt),
        2 => act_back_q::<2>(g, d, dd, zt),
        3 => act_back_q::<3>(g, d, dd, zt),
        4 => act_back_q::<4>(g, d, dd, zt),
        5 => act_back_q::<5>(g, d, dd, zt),
        7 => act_back_q::<7>(g, d, dd, zt),
        _ => {
            for (u, gr) in g.chunks_exact_mut(q).enumerate() {
                let (dv, ddv) = (d[u], dd[u]);
                let z = &zt[u * (q - 1)..(u + 1) * (q - 1)];
                let mut acc = [0.0f32; L];
                for (gk, &zk) in gr[1..].iter_mut().zip(z) {
                    acc = add(acc, mul(*gk, zk));
                    *gk = mul(*gk, dv);
                }
                gr[0] = add(mul(dv, gr[0]), mul(ddv, acc));
            }
        }
    }
}

#[inline(always)]
fn act_back_q<const Q: usize>(g: &mut [V], d: &[V], dd: &[V], zt: &[V]) {
    for (u, gr) in g.chunks_exact_mut(Q).enumerate() {
        let (dv, ddv) = (d[u], dd[u]);
        let mut jet: [V; Q] = (&*gr).try_into().expect("Q vectors");
        let z = &zt[u * (Q - 1)..(u + 1) * (Q - 1)];
        let mut acc = [0.0f32; L];
        for k in 1..Q {
            acc = add(acc, mul(jet[k], z[k - 1]));
            jet[k] = mul(jet[k], dv);
        }
        jet[0] = add(mul(dv, jet[0]), mul(ddv, acc));
        gr.copy_from_slice(&jet);
    }
}

/// What one call of the engine computes besides the passes: the minibatch as rows of the
/// batch given (`None`: the whole batch in order), the gradient, the loss terms, and the
/// outputs κ_NN of the samples (B × nu).
struct Job<'a> {
    rows: Option<&'a [usize]>,
    grad: Option<&'a mut Grad>,
    with_loss: bool,
    outputs: Option<&'a mut [f64]>,
}

impl Default for Job<'_> {
    fn default() -> Self {
        Job {
            rows: None,
            grad: None,
            with_loss: true,
            outputs: None,
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
            let maxw = widths.iter().copied().max().unwrap_or(0);
            // Vectors per unit of a chunk, for both jet sizes in use.
            let f = (chunk_groups(maxw, 1)).max(chunk_groups(maxw, q) * q);
            let per = |f: usize| -> Vec<Vec<V>> {
                widths.iter().map(|&n| vec![[0.0; L]; n * f]).collect()
            };
            self.h = per(f);
            self.zt = per(f);
            self.d = per(8);
            self.dd = per(8);
            self.g = vec![[0.0; L]; maxw * f];
            self.g2 = vec![[0.0; L]; maxw * f];
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
            self.wf.clear();
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

    /// Forward (and, with `q = 1 + nx`, tangent) pass of one chunk of `ng` groups: samples
    /// `i0 … i0 + nb − 1` (`nb ≤ ng·L`; sample i0 + s in lane s mod L of group s / L) are the
    /// rows `rows[i]` of the row-major states `x` (with `rows = None`, row i); the other
    /// lanes get the centre of X (their results are unused).
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn pass(
        &mut self,
        mlp: &Mlp,
        x: &[f64],
        rows: Option<&[usize]>,
        i0: usize,
        nb: usize,
        q: usize,
        ng: usize,
    ) {
        let nx = mlp.nx();
        let m = mlp.layers.len();
        for (g, h0g) in self.h[0][..ng * nx * q]
            .chunks_exact_mut(nx * q)
            .enumerate()
        {
            for (c, h0) in h0g.chunks_exact_mut(q).enumerate() {
                let (cc, hw) = (mlp.in_center[c], mlp.in_half[c]);
                for (i, v) in h0[0].iter_mut().enumerate() {
                    let s = g * L + i;
                    *v = if s < nb {
                        let row = rows.map_or(i0 + s, |r| r[i0 + s]);
                        ((x[row * nx + c] - cc) / hw) as f32
                    } else {
                        0.0
                    };
                }
                // T_0 = D.
                for (k, t) in h0[1..].iter_mut().enumerate() {
                    *t = [if c == k { (1.0 / hw) as f32 } else { 0.0 }; L];
                }
            }
        }
        let act = mlp.activation;
        for j in 0..m {
            let (inp, out) = (mlp.layers[j].inp, mlp.layers[j].out);
            let hidden = j + 1 < m;
            let (w, b) = (&self.w[j], &self.b[j]);
            let (hlo, hhi) = self.h.split_at_mut(j + 1);
            let (hp, hn) = (&hlo[j][..ng * inp * q], &mut hhi[0][..ng * out * q]);
            let (d, dd, zt) = (&mut self.d[j + 1], &mut self.dd[j + 1], &mut self.zt[j + 1]);
            dot_rows(
                w,
                inp,
                Some(b),
                hp,
                inp * q,
                ng,
                q,
                &mut self.acc,
                hn,
                out * q,
            );
            if hidden {
                activate_chunk(act, hn, d, dd, zt, q);
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
        let job = Job {
            grad,
            ..Job::default()
        };
        self.dispatch(mlp, batch, lam, job)
    }

    /// The loss of `batch` (no gradient) and the network's outputs κ_NN at its states into
    /// `u` (B × nu, row-major): the bits of [`Lanes::loss_grad`]'s loss and of
    /// [`Lanes::eval_batch`]'s outputs, in one pass.
    pub fn loss_outputs(
        &mut self,
        mlp: &Mlp,
        batch: &Batch,
        lam: LossWeights,
        u: &mut [f64],
    ) -> LossParts {
        let job = Job {
            outputs: Some(u),
            ..Job::default()
        };
        self.dispatch(mlp, batch, lam, job)
    }

    /// The gradient into `grad` (overwritten) of the loss of the minibatch made of the rows
    /// `rows` of `set` (sample i is row `rows[i]`), without the loss terms themselves: a
    /// training step's work, with no copy of the minibatch. The bits of
    /// [`Lanes::loss_grad`]'s gradient on those rows gathered into a batch.
    pub fn grad(
        &mut self,
        mlp: &Mlp,
        set: &Batch,
        rows: &[usize],
        lam: LossWeights,
        grad: &mut Grad,
    ) {
        let job = Job {
            rows: Some(rows),
            grad: Some(grad),
            with_loss: false,
            outputs: None,
        };
        self.dispatch(mlp, set, lam, job);
    }

    fn dispatch(&mut self, mlp: &Mlp, batch: &Batch, lam: LossWeights, job: Job) -> LossParts {
        self.load(mlp);
        #[cfg(target_arch = "x86_64")]
        if cpu_has_avx512() {
            // SAFETY: the CPU has AVX, AVX2, AVX-512F and AVX-512VL (`cpu_has_avx512`), the
            // features this `#[target_feature]` function enables.
            return unsafe { self.loss_grad_avx512(mlp, batch, lam, job) };
        }
        #[cfg(target_arch = "x86_64")]
        if cpu_has_avx2() {
            // SAFETY: the CPU has AVX and AVX2 (`cpu_has_avx2`), the one requirement of
            // calling a `#[target_feature(enable = "avx,avx2")]` function.
            return unsafe { self.loss_grad_avx2(mlp, batch, lam, job) };
        }
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx") {
            // SAFETY: the CPU has AVX (checked just above), the one requirement of calling
            // a `#[target_feature(enable = "avx")]` function.
            return unsafe { self.loss_grad_avx(mlp, batch, lam, job) };
        }
        self.loss_grad_impl(mlp, batch, lam, job)
    }

    /// [`Lanes::loss_grad_impl`] compiled with AVX: 8 f32 lanes per instruction instead of
    /// 4. The same IEEE operations in the same order (AVX, not FMA: no fused multiply-add),
    /// so the same bits as the SSE2 build.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    fn loss_grad_avx(&mut self, mlp: &Mlp, batch: &Batch, lam: LossWeights, job: Job) -> LossParts {
        self.loss_grad_impl(mlp, batch, lam, job)
    }

    /// [`Lanes::loss_grad_impl`] compiled with AVX2 as well: the tanh's exponent arithmetic
    /// (integer operations on the f32 bits) on 8 lanes too. Integer operations are exact,
    /// the float ones those of the AVX build: the same bits.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx,avx2")]
    fn loss_grad_avx2(
        &mut self,
        mlp: &Mlp,
        batch: &Batch,
        lam: LossWeights,
        job: Job,
    ) -> LossParts {
        self.loss_grad_impl(mlp, batch, lam, job)
    }

    /// [`Lanes::loss_grad_impl`] compiled with AVX-512F/VL as well: the same 8-lane
    /// operations (no fused multiply-add), with 32 vector registers instead of 16 (fewer
    /// spills). The same IEEE operations in the same order: the same bits.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx,avx2,avx512f,avx512vl")]
    fn loss_grad_avx512(
        &mut self,
        mlp: &Mlp,
        batch: &Batch,
        lam: LossWeights,
        job: Job,
    ) -> LossParts {
        self.loss_grad_impl(mlp, batch, lam, job)
    }

    #[inline(always)]
    fn loss_grad_impl(
        &mut self,
        mlp: &Mlp,
        batch: &Batch,
        lam: LossWeights,
        job: Job,
    ) -> LossParts {
        let Job {
            rows,
            mut grad,
            with_loss,
            mut outputs,
        } = job;
        let (nx, nu, m) = (mlp.nx(), mlp.nu(), mlp.layers.len());
        let jr = batch.jac_rows(nu);
        let bsz = rows.map_or(batch.use_jac.len(), <[usize]>::len);
        let inv_b = 1.0 / bsz.max(1) as f64;
        let tangent = lam.jacobian != 0.0;
        let q = if tangent { 1 + nx } else { 1 };
        if let Some(g) = grad.as_deref_mut() {
            for (gw, gb) in g.w.iter_mut().zip(g.b.iter_mut()) {
                gw.fill(0.0);
                gb.fill(0.0);
            }
        }
        // The lane accumulators are zero here: `load` allocates them zeroed and every
        // call with a gradient ends with a flush, which zeroes them.
        let mut parts = LossParts::default();
        let mut groups = 0;
        let maxw = self.widths.iter().copied().max().unwrap_or(0);
        let span = chunk_groups(maxw, q) * L;
        for i0 in (0..bsz).step_by(span) {
            let nb = span.min(bsz - i0);
            let ng = nb.div_ceil(L);
            self.pass(mlp, batch.x, rows, i0, nb, q, ng);
            // Output errors in f64 from the f32 outputs; padding lanes get zero gradients.
            self.g[..ng * nu * q].fill([0.0; L]);
            let y = &self.h[m];
            for s in 0..nb {
                let (o, i) = ((s / L) * nu * q, s % L);
                let gi = rows.map_or(i0 + s, |r| r[i0 + s]);
                let use_jac = tangent && batch.use_jac[gi];
                for r in 0..nu {
                    let sc = mlp.out_half[r];
                    let pred = mlp.out_center[r] + sc * f64::from(y[o + r * q][i]);
                    if let Some(u) = outputs.as_deref_mut() {
                        u[(i0 + s) * nu + r] = pred;
                    }
                    let (e, exact) = value_error(batch.band, r, pred, batch.u[gi * nu + r]);
                    let lv = batch.value_weight(lam.value, r);
                    if with_loss {
                        parts.value += lv * inv_b * e * e;
                    }
                    self.g[o + r * q][i] = (2.0 * lv * inv_b * e * sc) as f32;
                    if !use_jac || exact || r >= jr {
                        continue;
                    }
                    for k in 0..nx {
                        let yk = f64::from(y[o + r * q + 1 + k][i]);
                        let e = sc * yk - batch.du[gi * jr * nx + r * nx + k];
                        if with_loss {
                            parts.jacobian += lam.jacobian * inv_b * e * e;
                        }
                        self.g[o + r * q + 1 + k][i] = (2.0 * lam.jacobian * inv_b * e * sc) as f32;
                    }
                }
            }
            if let Some(g) = grad.as_deref_mut() {
                self.backward(mlp, q, ng);
                groups += ng;
                if groups % FLUSH == 0 {
                    self.flush(g);
                }
            }
        }
        if let Some(g) = grad.as_deref_mut() {
            self.flush(g);
        }
        // Weight term on the physical weights, in f64 (as the f64 path); a step's gradient
        // alone from the cached factors (the same bits).
        match grad {
            Some(g) if !with_loss && lam.weights != 0.0 => self.add_weight_grad(mlp, lam, g),
            grad => mlp.add_weight_term(lam, with_loss.then_some(&mut parts), grad),
        }
        parts
    }

    /// The gradient of the weight term added to `g`: factor·w per weight, the factors formed
    /// once per λ₃ and scaling ([`Mlp::add_weight_term`]'s gradient bit for bit).
    #[inline(always)]
    fn add_weight_grad(&mut self, mlp: &Mlp, lam: LossWeights, g: &mut Grad) {
        let key = || {
            let halves = mlp.in_half.iter().chain(&mlp.out_half);
            std::iter::once(lam.weights.to_bits()).chain(halves.map(|v| v.to_bits()))
        };
        if self.wf.len() != mlp.layers.len() || !key().eq(self.wf_key.iter().copied()) {
            mlp.weight_grad_factors(lam, &mut self.wf);
            self.wf_key.clear();
            self.wf_key.extend(key());
        }
        for ((gw, f), l) in g.w.iter_mut().zip(&self.wf).zip(&mlp.layers) {
            for ((d, &f), &w) in gw.iter_mut().zip(f).zip(&l.w) {
                *d += f * w;
            }
        }
    }

    /// Adds the lane accumulators into `g` and zeroes them: entry e gets
    /// `d_e + (((−0 + l₀) + l₁) + … + l₇)` in f64, the lanes in order (`Iterator::sum`'s
    /// operations), four entries at a time.
    #[inline(always)]
    fn flush(&mut self, g: &mut Grad) {
        const E: usize = 4;
        for (acc, dst) in self
            .gw
            .iter_mut()
            .chain(self.gb.iter_mut())
            .zip(g.w.iter_mut().chain(g.b.iter_mut()))
        {
            let mut a4 = acc.chunks_exact_mut(E);
            let mut d4 = dst.chunks_exact_mut(E);
            for (v, d) in (&mut a4).zip(&mut d4) {
                let v: &mut [V; E] = v.try_into().expect("E entries");
                let mut s = [-0.0f64; E];
                for i in 0..L {
                    for e in 0..E {
                        s[e] += f64::from(v[e][i]);
                    }
                }
                for e in 0..E {
                    d[e] += s[e];
                }
                *v = [[0.0; L]; E];
            }
            for (v, d) in a4.into_remainder().iter_mut().zip(d4.into_remainder()) {
                let mut s = -0.0f64;
                for x in *v {
                    s += f64::from(x);
                }
                *d += s;
                *v = [0.0; L];
            }
        }
    }

    /// Reverse pass of one chunk of `ng` groups from the output jets in `g` (∂/∂y, ∂/∂Y)
    /// into the lane accumulators.
    #[inline(always)]
    fn backward(&mut self, mlp: &Mlp, q: usize, ng: usize) {
        let m = mlp.layers.len();
        for j in (0..m).rev() {
            let (inp, out) = (mlp.layers[j].inp, mlp.layers[j].out);
            let (so, si) = (out * q, inp * q);
            let g = &mut self.g[..ng * so];
            if j + 1 < m {
                // ∂/∂a, ∂/∂T of layer j + 1 → ∂/∂z, ∂/∂Z (unit u = g·out + r of the chunk).
                activation_back(g, &self.d[j + 1], &self.dd[j + 1], &self.zt[j + 1], q);
            }
            // ∂/∂W[r, c] += Σ_q g_r[q]·h_c[q] (value and tangent terms), ∂/∂b[r] += g_r[0],
            // group after group.
            let hp = &self.h[j][..ng * si];
            for (r, (gwr, gb)) in self.gw[j]
                .chunks_exact_mut(inp)
                .zip(self.gb[j].iter_mut())
                .enumerate()
            {
                for gg in g.chunks_exact(so) {
                    let g0 = gg[r * q];
                    for i in 0..L {
                        gb[i] += g0[i];
                    }
                }
                outer_chunk(g, so, r, hp, si, ng, q, gwr);
            }
            if j > 0 {
                // ∂/∂(a, T)_{j−1} = Wᵀ ∂/∂(z, Z)_j.
                let g2 = &mut self.g2[..ng * si];
                dot_rows(&self.wt[j], out, None, g, so, ng, q, &mut self.acc, g2, si);
                std::mem::swap(&mut self.g, &mut self.g2);
            }
        }
    }
}

#[cfg(test)]
mod tests;
