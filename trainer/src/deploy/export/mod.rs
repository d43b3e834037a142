//! `export`: a trained network → `controller-core`'s generated Rust file and postcard blob,
//! with the certificate's f32 allowance.
//!
//! **Model.** [`ExportModel`] is a neutral description in physical units:
//! κ_NN,f64(x) = m_u + s_u ∘ (W_L tanh(… tanh(W_1 ((x − m_x) ⊘ s_x) + b_1) …) + b_L),
//! layers `w` stored out × in. The learning side converts its trained model into it.
//!
//! **Folding.** Both scalings are folded into the first and last layer (in f64):
//! W_1' = W_1 diag(1/s_x), b_1' = b_1 − W_1' m_x, W_L' = diag(s_u) W_L, b_L' = s_u ∘ b_L + m_u,
//! then rounded to f32 (nearest). The device runs `controller-core`'s `Dense::apply` (order:
//! bias, then `+ w·x` per input in order, no FMA) and its tanh.
//!
//! **f32 allowance** (the bound on |κ_NN,f32(x) − κ_NN,f64(x)| for x ∈ X), by forward error
//! analysis with interval arithmetic on sub-boxes B of X (u = 2⁻²⁴, γ_k = k u / (1 − k u)):
//! - input: x̂ = Π_X32(fl32(x)), |x̂_i − x_i| ≤ e_i = 2⁻²³ max|x_i| + 2⁻¹⁴⁹ (one ulp);
//! - affine layer, exact z = W' x + b' with x in the interval enclosure X_i (M_i = max |X_i|):
//!   |ẑ_o − z_o| ≤ |b̂_o − b'_o| + Σ_i (|ŵ_oi| e_i + |ŵ_oi − w'_oi| M_i)
//!   + γ_{n+1} (|b̂_o| + Σ_i |ŵ_oi| (M_i + e_i)) + n·2⁻¹⁴⁹ (products that underflow);
//! - tanh: |t(ẑ) − tanh(z)| ≤ δ_t + (1 − tanh²(m)) |ẑ − z|, m = min |ξ| over the interval
//!   of ẑ, δ_t the device tanh's exhaustively verified bound on the range of |ẑ|
//!   (`controller_core::activation`; piecewise in |ξ| for the fast tanh);
//!   enclosures of exact activations are tanh of the interval ends, widened by 10⁻¹⁵;
//! - the f64 reference itself rounds: the same analysis with u = 8·2⁻⁵³ (which covers the
//!   folding and the extra scaling operations) and δ_t = 10⁻¹⁵ is added.
//!
//! Interval ends and magnitudes are computed in f64 and widened (relative 10⁻¹²) to cover
//! their own rounding. The allowance is the maximum over sub-boxes and outputs; the report
//! puts it next to the largest difference seen on random states ([`sampled_max_diff`]).
//!
//! **Clamp band** `(U_d ⊕ [−ε, ε]) ∩ [act_lo, act_hi]`, ε = eps + allowance, rounded to f32
//! so that it contains U_d and lies within the actuator limits. **Domain** rounded inward to
//! f32 (the projected state is always in X).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use serde::Serialize;

/// Magic of the postcard blob.
pub const BLOB_MAGIC: [u8; 4] = *b"AMPC";
/// Blob format version (`controller_core::FORMAT_VERSION`).
pub const BLOB_VERSION: u16 = 1;
/// Number of random states behind [`ExportReport`]'s observed differences.
pub const SAMPLES: usize = 1_000_000;

/// `FAST_CLIP` of `controller_core::activation`.
const FAST_CLIP: f32 = 4.97;

/// `controller_core::activation::TANH_FAST_ERR_BINS` (checked equal in `tests/`).
pub const TANH_FAST_ERR_BINS: [(f64, f64); 10] = [
    (0.5, 4.0e-7),
    (1.0, 4.0e-7),
    (1.5, 4.0e-7),
    (2.0, 4.0e-7),
    (2.5, 5.0e-7),
    (3.0, 1.2e-6),
    (3.5, 4.6e-6),
    (4.0, 1.52e-5),
    (4.5, 4.25e-5),
    (f64::INFINITY, 1.0e-4),
];

/// One affine layer in f64: `w` is out × in.
#[derive(Clone, Debug, PartialEq, Serialize, serde::Deserialize)]
pub struct DenseF64 {
    /// Weights, one row per output.
    pub w: Vec<Vec<f64>>,
    /// Biases.
    pub b: Vec<f64>,
}

/// An affine scaling `physical = mean + scale ∘ normalised`.
#[derive(Clone, Debug, PartialEq, Serialize, serde::Deserialize)]
pub struct Scaling {
    /// Offset m.
    pub mean: Vec<f64>,
    /// Scale s (nonzero).
    pub scale: Vec<f64>,
}

impl Scaling {
    /// The identity scaling of dimension `n`.
    ///
    /// ```
    /// let s = trainer::deploy::export::Scaling::identity(2);
    /// assert_eq!(s.scale, vec![1.0, 1.0]);
    /// ```
    pub fn identity(n: usize) -> Self {
        Self {
            mean: vec![0.0; n],
            scale: vec![1.0; n],
        }
    }
}

/// A trained network and its certificate numbers, in physical units (see the module doc).
#[derive(Clone, Debug, PartialEq, Serialize, serde::Deserialize)]
pub struct ExportModel {
    /// Short name (problem), used in the generated file's doc.
    pub name: String,
    /// Layers, input to output; tanh between them, linear output.
    pub layers: Vec<DenseF64>,
    /// Input normalisation: x̃ = (x − mean) ⊘ scale.
    pub input: Scaling,
    /// Output un-normalisation: u = mean + scale ∘ ũ.
    pub output: Scaling,
    /// Lower corner of the certified domain X.
    pub domain_lo: Vec<f64>,
    /// Upper corner of X.
    pub domain_hi: Vec<f64>,
    /// Lower input bound U_d the MPC was solved with.
    pub u_lo: Vec<f64>,
    /// Upper input bound U_d.
    pub u_hi: Vec<f64>,
    /// Actuator lower limits (⊆-wise: U_d must lie within the actuator limits).
    pub actuator_lo: Vec<f64>,
    /// Actuator upper limits.
    pub actuator_hi: Vec<f64>,
    /// Input for non-finite states; `None` = centre of U_d.
    pub fallback: Option<Vec<f64>>,
    /// ε for the f64 network (learning side's certificate `eps`).
    pub eps: f64,
    /// ε_D.
    pub eps_d: f64,
    /// Sound upper bound on L_NN.
    pub l_nn: f64,
    /// How L_NN was bounded.
    pub l_nn_method: String,
    /// L_MPC.
    pub l_mpc: f64,
    /// Whether L_MPC is a sampled estimate.
    pub l_mpc_is_estimate: bool,
    /// Covering radius r of the data in X.
    pub covering_radius: f64,
    /// Content hash of the trained model (hex).
    pub hash: String,
    /// True for a stand-in network without a certificate.
    pub placeholder: bool,
}

/// What can go wrong in an export.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// The model is inconsistent (the message names the field).
    #[error("invalid export model: {0}")]
    Invalid(String),
    /// Writing an output failed.
    #[error("cannot write {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
}

/// The device tanh implementations of `controller-core`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Tanh {
    /// libm's `tanhf` (default build).
    Libm,
    /// The clamped rational (`fast-tanh` feature).
    Fast,
}

impl Tanh {
    /// Both, in the order libm, fast.
    pub const ALL: [Tanh; 2] = [Tanh::Libm, Tanh::Fast];

    /// The f32 function as the device computes it (same code as `controller-core`).
    pub fn eval(self, x: f32) -> f32 {
        match self {
            Tanh::Libm => libm::tanhf(x),
            Tanh::Fast => {
                let x = if x > FAST_CLIP {
                    FAST_CLIP
                } else if x >= -FAST_CLIP {
                    x
                } else {
                    -FAST_CLIP
                };
                let x2 = x * x;
                let p = x * (135_135.0 + x2 * (17_325.0 + x2 * (378.0 + x2)));
                let q = 135_135.0 + x2 * (62_370.0 + x2 * (3_150.0 + x2 * 28.0));
                // q ≥ 135135 and x is finite, so r is never NaN.
                (p / q).clamp(-1.0, 1.0)
            }
        }
    }

    /// Bound on |t(x) − tanh(x)| over all f32 x (`controller_core::activation`'s constants,
    /// verified exhaustively there).
    pub fn max_abs_err(self) -> f64 {
        match self {
            Tanh::Libm => 1.2e-7,
            Tanh::Fast => 1.0e-4,
        }
    }

    /// Bound on |t(ξ) − tanh(ξ)| for `lo ≤ |ξ| ≤ hi` (the fast tanh's piecewise bound,
    /// `controller_core::activation::TANH_FAST_ERR_BINS`; libm's is uniform).
    pub fn max_abs_err_on(self, lo: f64, hi: f64) -> f64 {
        match self {
            Tanh::Libm => self.max_abs_err(),
            Tanh::Fast => {
                let mut prev = 0.0;
                let mut worst = 0.0f64;
                for (a, d) in TANH_FAST_ERR_BINS {
                    if hi >= prev && lo < a {
                        worst = worst.max(d);
                    }
                    prev = a;
                }
                worst
            }
        }
    }

    /// `"libm"` or `"fast"`.
    pub fn name(self) -> &'static str {
        match self {
            Tanh::Libm => "libm",
            Tanh::Fast => "fast",
        }
    }
}

/// The outcome of an export: allowances and observed differences, per tanh.
#[derive(Clone, Debug, PartialEq)]
pub struct ExportReport {
    /// Sound bound on |κ_NN,f32 − κ_NN,f64| over X, for [libm, fast].
    pub f32_allowance: [f64; 2],
    /// Largest difference seen on [`SAMPLES`] random states in X, for [libm, fast].
    pub f32_observed: [f64; 2],
    /// Number of random states.
    pub samples: usize,
    /// Sub-boxes of X in the interval analysis.
    pub boxes: usize,
}

/// One folded layer rounded to f32: `(inputs, outputs, w row-major, b)`.
pub type LayerF32 = (usize, usize, Vec<f32>, Vec<f32>);

/// The network with scalings folded in, in f64 and rounded to f32.
#[derive(Clone, Debug, PartialEq)]
pub struct Folded {
    /// Folded layers (f64).
    pub layers: Vec<DenseF64>,
    /// Folded weights rounded to f32: (w row-major, b) per layer, with dims (in, out).
    pub f32_layers: Vec<LayerF32>,
}

fn dims_ok(v: &[f64], n: usize, what: &str) -> Result<(), ExportError> {
    if v.len() != n {
        return Err(ExportError::Invalid(format!(
            "{what}: length {} (expected {n})",
            v.len()
        )));
    }
    if let Some(i) = v.iter().position(|x| !x.is_finite()) {
        return Err(ExportError::Invalid(format!("{what}[{i}] is not finite")));
    }
    Ok(())
}

impl ExportModel {
    /// State dimension.
    pub fn nx(&self) -> usize {
        self.layers
            .first()
            .and_then(|l| l.w.first())
            .map_or(0, Vec::len)
    }

    /// Input dimension.
    pub fn nu(&self) -> usize {
        self.layers.last().map_or(0, |l| l.b.len())
    }

    /// Checks dimensions, finiteness and the boxes.
    pub fn validate(&self) -> Result<(), ExportError> {
        let inv = |m: String| Err(ExportError::Invalid(m));
        if self.layers.is_empty() {
            return inv("layers: empty".into());
        }
        let (nx, nu) = (self.nx(), self.nu());
        if nx == 0 || nu == 0 {
            return inv("layers: zero dimension".into());
        }
        let mut n_in = nx;
        for (k, l) in self.layers.iter().enumerate() {
            if l.w.len() != l.b.len() || l.w.is_empty() {
                return inv(format!(
                    "layers[{k}]: {} rows, {} biases",
                    l.w.len(),
                    l.b.len()
                ));
            }
            for (o, row) in l.w.iter().enumerate() {
                dims_ok(row, n_in, &format!("layers[{k}].w[{o}]"))?;
            }
            dims_ok(&l.b, l.b.len(), &format!("layers[{k}].b"))?;
            n_in = l.b.len();
        }
        dims_ok(&self.input.mean, nx, "input.mean")?;
        dims_ok(&self.input.scale, nx, "input.scale")?;
        dims_ok(&self.output.mean, nu, "output.mean")?;
        dims_ok(&self.output.scale, nu, "output.scale")?;
        if self
            .input
            .scale
            .iter()
            .chain(&self.output.scale)
            .any(|s| *s == 0.0)
        {
            return inv("scaling: zero scale".into());
        }
        for (v, n, w) in [
            (&self.domain_lo, nx, "domain_lo"),
            (&self.domain_hi, nx, "domain_hi"),
            (&self.u_lo, nu, "u_lo"),
            (&self.u_hi, nu, "u_hi"),
            (&self.actuator_lo, nu, "actuator_lo"),
            (&self.actuator_hi, nu, "actuator_hi"),
        ] {
            dims_ok(v, n, w)?;
        }
        for i in 0..nx {
            if self.domain_lo[i] > self.domain_hi[i] {
                return inv(format!("domain_lo[{i}] > domain_hi[{i}]"));
            }
        }
        for j in 0..nu {
            if !(self.actuator_lo[j] <= self.u_lo[j]
                && self.u_lo[j] <= self.u_hi[j]
                && self.u_hi[j] <= self.actuator_hi[j])
            {
                return inv(format!(
                    "u_{j}: need actuator_lo ≤ u_lo ≤ u_hi ≤ actuator_hi"
                ));
            }
        }
        if let Some(f) = &self.fallback {
            dims_ok(f, nu, "fallback")?;
            for j in 0..nu {
                if f[j] < self.actuator_lo[j] || f[j] > self.actuator_hi[j] {
                    return inv(format!("fallback[{j}] outside the actuator limits"));
                }
            }
        }
        for (v, w) in [
            (self.eps, "eps"),
            (self.eps_d, "eps_d"),
            (self.l_nn, "l_nn"),
            (self.l_mpc, "l_mpc"),
            (self.covering_radius, "covering_radius"),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return inv(format!("{w} must be finite and ≥ 0"));
            }
        }
        Ok(())
    }

    /// κ_NN,f64(x): the reference network, scalings applied explicitly.
    pub fn eval_f64(&self, x: &[f64]) -> Vec<f64> {
        let mut h: Vec<f64> = x
            .iter()
            .zip(self.input.mean.iter().zip(&self.input.scale))
            .map(|(x, (m, s))| (x - m) / s)
            .collect();
        let n = self.layers.len();
        for (k, l) in self.layers.iter().enumerate() {
            h =
                l.w.iter()
                    .zip(&l.b)
                    .map(|(row, b)| {
                        let z = row.iter().zip(&h).fold(*b, |acc, (w, x)| acc + w * x);
                        if k + 1 < n {
                            z.tanh()
                        } else {
                            z
                        }
                    })
                    .collect();
        }
        h.iter()
            .zip(self.output.mean.iter().zip(&self.output.scale))
            .map(|(y, (m, s))| m + s * y)
            .collect()
    }

    /// The folded network (module doc), in f64 and in f32.
    pub fn folded(&self) -> Folded {
        let mut layers = self.layers.clone();
        let first = &mut layers[0];
        for (row, b) in first.w.iter_mut().zip(first.b.iter_mut()) {
            for (i, w) in row.iter_mut().enumerate() {
                *w /= self.input.scale[i];
                *b -= *w * self.input.mean[i];
            }
        }
        let last = layers.last_mut().expect("validated: at least one layer");
        for (j, (row, b)) in last.w.iter_mut().zip(last.b.iter_mut()).enumerate() {
            let (m, s) = (self.output.mean[j], self.output.scale[j]);
            for w in row.iter_mut() {
                *w *= s;
            }
            *b = m + s * *b;
        }
        let f32_layers = layers
            .iter()
            .map(|l| {
                let w: Vec<f32> = l.w.iter().flatten().map(|v| *v as f32).collect();
                let b: Vec<f32> = l.b.iter().map(|v| *v as f32).collect();
                (l.w[0].len(), l.b.len(), w, b)
            })
            .collect();
        Folded { layers, f32_layers }
    }

    /// The certified box rounded inward to f32.
    pub fn domain_f32(&self) -> (Vec<f32>, Vec<f32>) {
        (
            self.domain_lo.iter().map(|v| f32_up(*v)).collect(),
            self.domain_hi.iter().map(|v| f32_down(*v)).collect(),
        )
    }

    /// Clamp band for a total ε (module doc), in f32.
    pub fn clamp_band(&self, eps: f64) -> (Vec<f32>, Vec<f32>) {
        let nu = self.nu();
        let mut lo = Vec::with_capacity(nu);
        let mut hi = Vec::with_capacity(nu);
        for j in 0..nu {
            let mut l = f32_down((self.u_lo[j] - eps).max(self.actuator_lo[j]));
            if f64::from(l) < self.actuator_lo[j] {
                l = f32_up(self.actuator_lo[j]);
            }
            let mut h = f32_up((self.u_hi[j] + eps).min(self.actuator_hi[j]));
            if f64::from(h) > self.actuator_hi[j] {
                h = f32_down(self.actuator_hi[j]);
            }
            lo.push(l);
            hi.push(h);
        }
        (lo, hi)
    }

    /// Fallback input in f32 (default: centre of U_d), inside `[lo, hi]`.
    pub fn fallback_f32(&self, lo: &[f32], hi: &[f32]) -> Vec<f32> {
        (0..self.nu())
            .map(|j| {
                let v = match &self.fallback {
                    Some(f) => f[j],
                    None => 0.5 * (self.u_lo[j] + self.u_hi[j]),
                };
                (v as f32).max(lo[j]).min(hi[j])
            })
            .collect()
    }
}

/// Largest f32 ≤ v.
fn f32_down(v: f64) -> f32 {
    let c = v as f32;
    if f64::from(c) > v {
        next_f32(c, false)
    } else {
        c
    }
}

/// Smallest f32 ≥ v.
fn f32_up(v: f64) -> f32 {
    let c = v as f32;
    if f64::from(c) < v {
        next_f32(c, true)
    } else {
        c
    }
}

/// The neighbouring finite f32 (up or down).
fn next_f32(c: f32, up: bool) -> f32 {
    if c == 0.0 {
        let tiny = f32::from_bits(1);
        return if up { tiny } else { -tiny };
    }
    let b = c.to_bits();
    let away = (c > 0.0) == up;
    f32::from_bits(if away { b + 1 } else { b - 1 })
}

/// κ_NN,f32(x) exactly as `controller-core` computes it, before the output clamp:
/// projection onto the f32 box, folded f32 layers in the core's order, device tanh.
pub fn eval_f32(folded: &Folded, lo: &[f32], hi: &[f32], x: &[f32], tanh: Tanh) -> Vec<f32> {
    let mut h: Vec<f32> = x
        .iter()
        .zip(lo.iter().zip(hi))
        .map(|(x, (l, u))| {
            if x < l {
                *l
            } else if x > u {
                *u
            } else {
                *x
            }
        })
        .collect();
    let n = folded.f32_layers.len();
    for (k, (n_in, _, w, b)) in folded.f32_layers.iter().enumerate() {
        h = b
            .iter()
            .enumerate()
            .map(|(o, b)| {
                let mut acc = *b;
                for i in 0..*n_in {
                    acc += w[o * n_in + i] * h[i];
                }
                if k + 1 < n {
                    tanh.eval(acc)
                } else {
                    acc
                }
            })
            .collect();
    }
    h
}

/// Interval bound on |computed − exact| of the folded network over the box `[a, b]`, for
/// unit roundoff `u`, rounded weights `wr` (or exact if `None`), tanh error `dt`.
fn box_error(
    layers: &[DenseF64],
    rounded: Option<&[LayerF32]>,
    a: &[f64],
    b: &[f64],
    u: f64,
    input_rel: f64,
    dt: &dyn Fn(f64, f64) -> f64,
) -> f64 {
    const TINY: f64 = 1.401_298_464_324_817e-45; // 2^-149
    let widen = |v: f64| v * (1.0 + 1e-12) + 1e-300;
    let mut lo: Vec<f64> = a.to_vec();
    let mut hi: Vec<f64> = b.to_vec();
    let mut err: Vec<f64> = lo
        .iter()
        .zip(&hi)
        .map(|(l, h)| widen(input_rel * l.abs().max(h.abs()) + TINY))
        .collect();
    let n_layers = layers.len();
    for (k, l) in layers.iter().enumerate() {
        let n = lo.len();
        let gamma = (n as f64 + 1.0) * u / (1.0 - (n as f64 + 1.0) * u);
        let mut zlo = Vec::with_capacity(l.b.len());
        let mut zhi = Vec::with_capacity(l.b.len());
        let mut zerr = Vec::with_capacity(l.b.len());
        for (o, (row, bias)) in l.w.iter().zip(&l.b).enumerate() {
            let (wr, br): (Vec<f64>, f64) = match rounded {
                Some(r) => (
                    r[k].2[o * n..(o + 1) * n]
                        .iter()
                        .map(|v| f64::from(*v))
                        .collect(),
                    f64::from(r[k].3[o]),
                ),
                None => (row.clone(), *bias),
            };
            // Exact enclosure of z_o.
            let (mut s_lo, mut s_hi, mut mag) = (*bias, *bias, bias.abs());
            let mut e = widen((br - bias).abs());
            let mut rmag = br.abs();
            for i in 0..n {
                let w = row[i];
                let (p, q) = (w * lo[i], w * hi[i]);
                s_lo += p.min(q);
                s_hi += p.max(q);
                let m = lo[i].abs().max(hi[i].abs());
                mag += w.abs() * m;
                e += wr[i].abs() * err[i] + (wr[i] - w).abs() * m;
                rmag += wr[i].abs() * (m + err[i]);
            }
            let slack = widen(mag) * 1e-13;
            zlo.push(s_lo - slack);
            zhi.push(s_hi + slack);
            zerr.push(widen(e + gamma * rmag + n as f64 * TINY));
        }
        if k + 1 < n_layers {
            // tanh layer
            for o in 0..zlo.len() {
                let (l0, h0, e) = (zlo[o], zhi[o], zerr[o]);
                let (cl, ch) = (l0 - e, h0 + e);
                let m = if cl <= 0.0 && ch >= 0.0 {
                    0.0
                } else {
                    cl.abs().min(ch.abs())
                };
                let t = m.tanh();
                let lip = (1.0 - t * t).min(1.0) * (1.0 + 1e-12);
                zerr[o] = widen(dt(m, cl.abs().max(ch.abs())) + lip * e);
                zlo[o] = (l0.tanh() - 1e-15).max(-1.0);
                zhi[o] = (h0.tanh() + 1e-15).min(1.0);
            }
        }
        lo = zlo;
        hi = zhi;
        err = zerr;
    }
    err.into_iter().fold(0.0, f64::max)
}

/// Per-axis number of sub-boxes: about 2¹⁶ boxes in all, at most 256 per axis.
fn splits(nx: usize) -> usize {
    let k = (65_536f64).powf(1.0 / nx as f64).floor() as usize;
    k.clamp(1, 256)
}

/// The sound f32 allowance over X for one tanh (module doc) and the number of sub-boxes.
pub fn f32_allowance(model: &ExportModel, tanh: Tanh) -> (f64, usize) {
    let folded = model.folded();
    let nx = model.nx();
    let k = splits(nx);
    let boxes = k.pow(nx as u32);
    let mut worst = 0.0f64;
    let mut idx = vec![0usize; nx];
    let mut a = vec![0.0; nx];
    let mut b = vec![0.0; nx];
    for _ in 0..boxes {
        for i in 0..nx {
            let (l, h) = (model.domain_lo[i], model.domain_hi[i]);
            let step = (h - l) / k as f64;
            a[i] = if idx[i] == 0 {
                l
            } else {
                l + step * idx[i] as f64
            };
            b[i] = if idx[i] + 1 == k {
                h
            } else {
                l + step * (idx[i] + 1) as f64
            };
            // Adjacent boxes share the computed end point, so the union covers X.
        }
        let e32 = box_error(
            &folded.layers,
            Some(&folded.f32_layers),
            &a,
            &b,
            2f64.powi(-24),
            2f64.powi(-23),
            &|lo, hi| tanh.max_abs_err_on(lo, hi),
        );
        let e64 = box_error(
            &model_unfolded_as_exact(&folded),
            None,
            &a,
            &b,
            8.0 * 2f64.powi(-53),
            8.0 * 2f64.powi(-53),
            &|_, _| 1e-15,
        );
        worst = worst.max(e32 + e64);
        for d in idx.iter_mut() {
            *d += 1;
            if *d < k {
                break;
            }
            *d = 0;
        }
    }
    (worst * (1.0 + 1e-9), boxes)
}

fn model_unfolded_as_exact(folded: &Folded) -> Vec<DenseF64> {
    folded.layers.clone()
}

/// Largest |κ_NN,f32(x) − κ_NN,f64(x)| (over outputs) on `n` uniform random states in X
/// (deterministic xorshift stream from `seed`).
pub fn sampled_max_diff(model: &ExportModel, tanh: Tanh, n: usize, seed: u64) -> f64 {
    let folded = model.folded();
    let (lo, hi) = model.domain_f32();
    let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    let mut next = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    let nx = model.nx();
    let mut worst = 0.0f64;
    let mut x = vec![0.0; nx];
    for _ in 0..n {
        for i in 0..nx {
            x[i] = model.domain_lo[i] + next() * (model.domain_hi[i] - model.domain_lo[i]);
        }
        let x32: Vec<f32> = x.iter().map(|v| *v as f32).collect();
        let y32 = eval_f32(&folded, &lo, &hi, &x32, tanh);
        let y64 = model.eval_f64(&x);
        for (a, b) in y32.iter().zip(&y64) {
            worst = worst.max((f64::from(*a) - b).abs());
        }
    }
    worst
}

/// Computes the allowances (sound) and observed differences ([`SAMPLES`] states) for both
/// tanh implementations.
pub fn certify_f32(model: &ExportModel) -> Result<ExportReport, ExportError> {
    model.validate()?;
    let mut report = ExportReport {
        f32_allowance: [0.0; 2],
        f32_observed: [0.0; 2],
        samples: SAMPLES,
        boxes: 0,
    };
    for (k, t) in Tanh::ALL.iter().enumerate() {
        let (a, boxes) = f32_allowance(model, *t);
        report.f32_allowance[k] = a;
        report.boxes = boxes;
        report.f32_observed[k] = sampled_max_diff(model, *t, SAMPLES, 1 + k as u64);
    }
    Ok(report)
}

// ---------------------------------------------------------------------------------------
// Rendering

/// Width rustfmt formats to.
const WIDTH: usize = 100;

/// Shortest round-trip text of an f32 (Rust's `Debug`, always with `.` or exponent).
fn lit32(v: f32) -> String {
    format!("{v:?}")
}

/// Shortest round-trip text of an f64.
fn lit64(v: f64) -> String {
    format!("{v:?}")
}

/// An array literal laid out as rustfmt does: on one line if it fits, else one item per
/// line (or filled lines when every item is at most 10 characters).
fn array(items: &[String], indent: usize, used: usize, tail: usize) -> String {
    let one = format!("[{}]", items.join(", "));
    if !one.contains('\n') && used + one.len() + tail <= WIDTH {
        return one;
    }
    let pad = " ".repeat(indent + 4);
    let mut s = String::from("[\n");
    if items.len() > 1 && items.iter().all(|i| i.len() <= 10 && !i.contains('\n')) {
        let mut line = String::new();
        for it in items {
            if !line.is_empty() && indent + 4 + line.len() + 1 + it.len() + 1 > WIDTH {
                let _ = writeln!(s, "{pad}{line}");
                line.clear();
            }
            if !line.is_empty() {
                line.push(' ');
            }
            line.push_str(it);
            line.push(',');
        }
        let _ = writeln!(s, "{pad}{line}");
    } else {
        for it in items {
            let _ = writeln!(s, "{pad}{it},");
        }
    }
    s.push_str(&" ".repeat(indent));
    s.push(']');
    s
}

/// `pub const NAME: TY = VALUE;` with rustfmt's line breaking for array values.
fn const_array(out: &mut String, doc: &str, vis: &str, name: &str, ty: &str, items: &[String]) {
    let head = format!("{vis}const {name}: {ty} = ");
    let _ = writeln!(out, "/// {doc}");
    let _ = writeln!(out, "{head}{};", array(items, 0, head.len(), 1));
}

fn certificate_literal(
    model: &ExportModel,
    tanh: Tanh,
    report: &ExportReport,
    k: usize,
) -> Vec<(String, String)> {
    let eps_total = model.eps + report.f32_allowance[k];
    let (clo, chi) = model.clamp_band(eps_total);
    let fb = model.fallback_f32(&clo, &chi);
    let v64 = |v: &[f64]| v.iter().map(|x| lit64(*x)).collect::<Vec<_>>();
    let v32 = |v: &[f32]| v.iter().map(|x| lit32(*x)).collect::<Vec<_>>();
    let arr = |name: &str, items: Vec<String>| {
        let used = 4 + name.len() + 2;
        (name.to_string(), array(&items, 4, used, 1))
    };
    vec![
        ("eps".into(), lit64(eps_total)),
        ("eps_nn".into(), lit64(model.eps)),
        ("eps_d".into(), lit64(model.eps_d)),
        ("l_nn".into(), lit64(model.l_nn)),
        ("l_nn_method".into(), format!("{:?}", model.l_nn_method)),
        ("l_mpc".into(), lit64(model.l_mpc)),
        (
            "l_mpc_is_estimate".into(),
            model.l_mpc_is_estimate.to_string(),
        ),
        ("covering_radius".into(), lit64(model.covering_radius)),
        ("f32_allowance".into(), lit64(report.f32_allowance[k])),
        ("f32_observed".into(), lit64(report.f32_observed[k])),
        ("tanh".into(), format!("{:?}", tanh.name())),
        ("tanh_max_abs_err".into(), lit64(tanh.max_abs_err())),
        arr("domain_lo", v64(&model.domain_lo)),
        arr("domain_hi", v64(&model.domain_hi)),
        arr("u_lo", v64(&model.u_lo)),
        arr("u_hi", v64(&model.u_hi)),
        arr("actuator_lo", v64(&model.actuator_lo)),
        arr("actuator_hi", v64(&model.actuator_hi)),
        arr("clamp_lo", v32(&clo)),
        arr("clamp_hi", v32(&chi)),
        arr("fallback", v32(&fb)),
        ("hash".into(), format!("{:?}", model.hash)),
        ("placeholder".into(), model.placeholder.to_string()),
    ]
}

/// The generated Rust file `controller-core/src/generated/weights.rs`.
pub fn render_rust(model: &ExportModel, report: &ExportReport) -> String {
    let folded = model.folded();
    let (nx, nu) = (model.nx(), model.nu());
    let sizes: Vec<usize> = std::iter::once(nx)
        .chain(model.layers.iter().map(|l| l.b.len()))
        .collect();
    let mut o = String::new();
    o.push_str("// @generated by trainer export — do not edit\n");
    if model.placeholder {
        let _ = writeln!(
            o,
            "//! PLACEHOLDER weights for `{}`: a deterministic stand-in network, NOT the trained",
            model.name
        );
        o.push_str(
            "//! controller and NOT certified (eps_nn = 0; only the f32 allowance is computed).\n\
             //! It exists so that the embedded side can be built and tested before training;\n\
             //! `trainer export` replaces it with the trained network.\n",
        );
    } else {
        let _ = writeln!(
            o,
            "//! Weights and certificates of the `{}` controller.",
            model.name
        );
    }
    let arch: Vec<String> = sizes.iter().map(usize::to_string).collect();
    let _ = writeln!(
        o,
        "//!\n//! Architecture {} (tanh hidden layers, linear output), input and output scalings\n\
         //! folded into the first and last layer (physical units in and out). Model hash:\n\
         //! `{}`.",
        arch.join("-"),
        model.hash
    );
    let _ = writeln!(
        o,
        "//!\n//! f32 allowance (sound bound on |κ_NN,f32 − κ_NN,f64| over X, {} sub-boxes) vs the\n\
         //! largest difference on {} random states: libm tanh {:.3e} vs {:.3e}; fast tanh\n\
         //! {:.3e} vs {:.3e}.",
        report.boxes,
        report.samples,
        report.f32_allowance[0],
        report.f32_observed[0],
        report.f32_allowance[1],
        report.f32_observed[1]
    );
    o.push_str(
        "#![allow(\n    clippy::approx_constant,\n    clippy::excessive_precision,\n    \
         clippy::unreadable_literal\n)]\n\n",
    );
    o.push_str("use crate::certificate::Certificate;\nuse crate::layer::Dense;\n");
    if model.layers.len() > 1 {
        o.push_str("use crate::mlp::Hidden;\n");
    }
    o.push('\n');
    let _ = writeln!(o, "/// State dimension.\npub const NX: usize = {nx};");
    let _ = writeln!(o, "/// Input dimension.\npub const NU: usize = {nu};");
    // Network type
    let n = model.layers.len();
    let mut ty = format!("Dense<{}, {}>", sizes[n - 1], sizes[n]);
    for k in (0..n - 1).rev() {
        ty = format!("Hidden<{}, {}, {ty}>", sizes[k], sizes[k + 1]);
    }
    let _ = writeln!(
        o,
        "/// The network type: {}.\npub type Net = {ty};\n",
        sizes
            .iter()
            .enumerate()
            .map(|(k, s)| if k == 0 || k == n {
                s.to_string()
            } else {
                format!("{s} (tanh)")
            })
            .collect::<Vec<_>>()
            .join(" → ")
    );
    for (k, (n_in, n_out, w, b)) in folded.f32_layers.iter().enumerate() {
        let items = |r: &[f32]| r.iter().map(|v| lit32(*v)).collect::<Vec<_>>();
        let rows: Vec<String> = w.chunks(*n_in).map(|r| array(&items(r), 4, 4, 1)).collect();
        let name = format!("W{}", k + 1);
        let doc = format!("Layer {} weights ({n_in} → {n_out}, out × in).", k + 1);
        let ty = format!("[[f32; {n_in}]; {n_out}]");
        let head = format!("const {name}: {ty} = ");
        if *n_out == 1 && head.len() + rows[0].len() + 3 > WIDTH {
            // rustfmt writes a lone multi-line row as `[[ … ]]`.
            let _ = writeln!(o, "/// {doc}\n{head}[{}];", array(&items(w), 0, WIDTH, 0));
        } else {
            const_array(&mut o, &doc, "", &name, &ty, &rows);
        }
        let bs: Vec<String> = b.iter().map(|v| lit32(*v)).collect();
        const_array(
            &mut o,
            &format!("Layer {} biases.", k + 1),
            "",
            &format!("B{}", k + 1),
            &format!("[f32; {n_out}]"),
            &bs,
        );
    }
    // NET expression
    let mut expr = format!("Dense::new(W{n}, B{n})");
    for k in (1..n).rev() {
        expr = format!("Hidden::new(Dense::new(W{k}, B{k}), {expr})");
    }
    let _ = writeln!(o, "/// The network, physical units in and out.");
    let line = format!("pub const NET: Net = {expr};");
    if line.len() <= WIDTH {
        let _ = writeln!(o, "{line}");
    } else {
        o.push_str(&nested_call("pub const NET: Net = ", &expr));
    }
    let (lo, hi) = model.domain_f32();
    let v32 = |v: &[f32]| v.iter().map(|x| lit32(*x)).collect::<Vec<_>>();
    o.push('\n');
    const_array(
        &mut o,
        "Lower corner of X in f32 (rounded inward).",
        "pub ",
        "X_LO",
        &format!("[f32; {nx}]"),
        &v32(&lo),
    );
    const_array(
        &mut o,
        "Upper corner of X in f32 (rounded inward).",
        "pub ",
        "X_HI",
        &format!("[f32; {nx}]"),
        &v32(&hi),
    );
    for (k, t) in Tanh::ALL.iter().enumerate() {
        let _ = writeln!(
            o,
            "\n/// The certificate for the {} tanh.\npub const CERTIFICATE_{}: Certificate<{nx}, {nu}> = Certificate {{",
            t.name(),
            t.name().to_uppercase()
        );
        for (f, v) in certificate_literal(model, *t, report, k) {
            let _ = writeln!(o, "    {f}: {v},");
        }
        o.push_str("};\n");
    }
    o
}

/// Formats `head` + a nested `Hidden::new(a, Hidden::new(b, c))` call the way rustfmt
/// breaks it: arguments one per line, recursively, when the call does not fit.
fn nested_call(head: &str, expr: &str) -> String {
    fn split_args(inner: &str) -> Vec<String> {
        let mut args = Vec::new();
        let mut depth = 0;
        let mut cur = String::new();
        for c in inner.chars() {
            match c {
                '(' => depth += 1,
                ')' => depth -= 1,
                ',' if depth == 0 => {
                    args.push(cur.trim().to_string());
                    cur.clear();
                    continue;
                }
                _ => {}
            }
            cur.push(c);
        }
        args.push(cur.trim().to_string());
        args
    }
    fn fmt(expr: &str, indent: usize, used: usize, tail: usize) -> String {
        if used + expr.len() + tail <= WIDTH {
            return expr.to_string();
        }
        let open = expr.find('(').unwrap_or(expr.len());
        let name = &expr[..open];
        let inner = &expr[open + 1..expr.len() - 1];
        let pad = " ".repeat(indent + 4);
        let mut s = format!("{name}(\n");
        for a in split_args(inner) {
            let f = fmt(&a, indent + 4, indent + 4, 1);
            let _ = writeln!(s, "{pad}{f},");
        }
        s.push_str(&" ".repeat(indent));
        s.push(')');
        s
    }
    format!("{head}{};\n", fmt(expr, 0, head.len(), 1))
}

/// The blob's body (see `controller_core::blob`), serialised with postcard.
#[derive(Serialize)]
struct BlobBody<'a> {
    magic: [u8; 4],
    version: u16,
    nx: u32,
    nu: u32,
    x_lo: Vec<f32>,
    x_hi: Vec<f32>,
    clamp_lo_libm: Vec<f32>,
    clamp_hi_libm: Vec<f32>,
    clamp_lo_fast: Vec<f32>,
    clamp_hi_fast: Vec<f32>,
    fallback: Vec<f32>,
    layers: Vec<BlobLayer>,
    hash: &'a str,
}

#[derive(Serialize)]
struct BlobLayer {
    n_in: u32,
    n_out: u32,
    w: Vec<f32>,
    b: Vec<f32>,
}

/// CRC-32 (IEEE), as `controller_core::blob::crc32`.
pub fn crc32(data: &[u8]) -> u32 {
    let mut crc = 0xFFFF_FFFFu32;
    for &byte in data {
        crc ^= u32::from(byte);
        for _ in 0..8 {
            let mask = (crc & 1).wrapping_neg();
            crc = (crc >> 1) ^ (0xEDB8_8320 & mask);
        }
    }
    !crc
}

/// The postcard blob: `postcard(body) ++ crc32(body).to_le_bytes()`.
pub fn render_postcard(model: &ExportModel, report: &ExportReport) -> Vec<u8> {
    let folded = model.folded();
    let (x_lo, x_hi) = model.domain_f32();
    let (lo_l, hi_l) = model.clamp_band(model.eps + report.f32_allowance[0]);
    let (lo_f, hi_f) = model.clamp_band(model.eps + report.f32_allowance[1]);
    // The fallback is the same for both bands (it lies in U_d ⊆ both bands).
    let fallback = model.fallback_f32(&lo_l, &hi_l);
    let body = BlobBody {
        magic: BLOB_MAGIC,
        version: BLOB_VERSION,
        nx: model.nx() as u32,
        nu: model.nu() as u32,
        x_lo,
        x_hi,
        clamp_lo_libm: lo_l,
        clamp_hi_libm: hi_l,
        clamp_lo_fast: lo_f,
        clamp_hi_fast: hi_f,
        fallback,
        layers: folded
            .f32_layers
            .iter()
            .map(|(i, o, w, b)| BlobLayer {
                n_in: *i as u32,
                n_out: *o as u32,
                w: w.clone(),
                b: b.clone(),
            })
            .collect(),
        hash: &model.hash,
    };
    let mut bytes = postcard::to_stdvec(&body).expect("postcard serialises plain data");
    let c = crc32(&bytes);
    bytes.extend_from_slice(&c.to_le_bytes());
    bytes
}

fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), ExportError> {
    let io = |source| ExportError::Io {
        path: path.to_path_buf(),
        source,
    };
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".tmp");
    let tmp = PathBuf::from(tmp);
    std::fs::write(&tmp, bytes).map_err(io)?;
    std::fs::rename(&tmp, path).map_err(io)
}

/// Validates `model`, computes the f32 allowances, writes the Rust file and the blob
/// (each atomically: temporary file + rename) and returns the report.
pub fn export_files(
    model: &ExportModel,
    rust_out: &Path,
    postcard_out: &Path,
) -> Result<ExportReport, ExportError> {
    let report = certify_f32(model)?;
    write_atomic(rust_out, render_rust(model, &report).as_bytes())?;
    write_atomic(postcard_out, &render_postcard(model, &report))?;
    Ok(report)
}

/// PLACEHOLDER pendulum network (2-10-10-1) until the trained one exists: deterministic
/// pseudo-random weights (xorshift, seed 0x5EED, uniform in ±1.5/√fan_in), normalisation by
/// the domain's half-widths, output scale 15 N·m. Not trained and not certified: the
/// certificate numbers are zero and `placeholder = true`.
pub fn placeholder_pendulum() -> ExportModel {
    let mut s: u64 = 0x5EED;
    let mut next = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    let sizes = [2usize, 10, 10, 1];
    let layers = sizes
        .windows(2)
        .map(|d| {
            let g = 1.5 / (d[0] as f64).sqrt();
            DenseF64 {
                w: (0..d[1])
                    .map(|_| (0..d[0]).map(|_| g * next()).collect())
                    .collect(),
                b: (0..d[1]).map(|_| 0.1 * next()).collect(),
            }
        })
        .collect();
    let tau = std::f64::consts::TAU;
    ExportModel {
        name: "pendulum".into(),
        layers,
        input: Scaling {
            mean: vec![0.0, 0.0],
            scale: vec![tau, 1.0],
        },
        output: Scaling {
            mean: vec![0.0],
            scale: vec![15.0],
        },
        domain_lo: vec![-tau, -1.0],
        domain_hi: vec![tau, 1.0],
        u_lo: vec![-15.0],
        u_hi: vec![15.0],
        actuator_lo: vec![-15.0],
        actuator_hi: vec![15.0],
        fallback: None,
        eps: 0.0,
        eps_d: 0.0,
        l_nn: 0.0,
        l_nn_method: "placeholder (untrained network, no certificate)".into(),
        l_mpc: 0.0,
        l_mpc_is_estimate: true,
        covering_radius: 0.0,
        hash: "placeholder-2-10-10-1-seed-5eed".into(),
        placeholder: true,
    }
}

impl ExportModel {
    /// The export description of a trained tanh network and its certificate (physical
    /// units; the actuator limits are the data's input bounds U_d unless given).
    pub fn from_trained(
        name: &str,
        model: &crate::certify::Model,
        cert: &crate::certify::certificate::Certificate,
    ) -> Result<Self, ExportError> {
        let m = &model.mlp;
        if m.activation != crate::learn::mlp::Activation::Tanh {
            return Err(ExportError::Invalid(format!(
                "activation {:?}: the device supports tanh only",
                m.activation
            )));
        }
        let layers = m
            .layers
            .iter()
            .map(|l| DenseF64 {
                w: (0..l.out)
                    .map(|r| l.w[r * l.inp..(r + 1) * l.inp].to_vec())
                    .collect(),
                b: l.b.clone(),
            })
            .collect();
        Ok(ExportModel {
            name: name.to_string(),
            layers,
            input: Scaling {
                mean: m.in_center.clone(),
                scale: m.in_half.clone(),
            },
            output: Scaling {
                mean: m.out_center.clone(),
                scale: m.out_half.clone(),
            },
            domain_lo: cert.domain_lo.clone(),
            domain_hi: cert.domain_hi.clone(),
            u_lo: cert.u_lo.clone(),
            u_hi: cert.u_hi.clone(),
            actuator_lo: cert.u_lo.clone(),
            actuator_hi: cert.u_hi.clone(),
            fallback: None,
            eps: cert.eps,
            eps_d: cert.eps_d,
            l_nn: cert.l_nn,
            l_nn_method: format!("{:?}", cert.l_nn_method),
            l_mpc: cert.l_mpc,
            l_mpc_is_estimate: cert.l_mpc_is_estimate,
            covering_radius: cert.covering_radius,
            hash: cert.hash.clone(),
            placeholder: false,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn folding_preserves_the_function() {
        let m = placeholder_pendulum();
        let f = m.folded();
        for x in [[0.3, -0.2], [-6.0, 1.0], [2.0, 0.5]] {
            // folded network in f64
            let mut h = x.to_vec();
            for (k, l) in f.layers.iter().enumerate() {
                h =
                    l.w.iter()
                        .zip(&l.b)
                        .map(|(r, b)| {
                            let z = r.iter().zip(&h).fold(*b, |a, (w, x)| a + w * x);
                            if k + 1 < f.layers.len() {
                                z.tanh()
                            } else {
                                z
                            }
                        })
                        .collect();
            }
            assert!((h[0] - m.eval_f64(&x)[0]).abs() < 1e-12);
        }
    }

    #[test]
    fn allowance_is_sound_on_a_million_states_and_not_vacuous() {
        let m = placeholder_pendulum();
        for t in Tanh::ALL {
            let (bound, _) = f32_allowance(&m, t);
            let seen = sampled_max_diff(&m, t, SAMPLES, 7);
            println!("{}: bound {bound:e}, observed {seen:e}", t.name());
            assert!(
                bound >= seen,
                "{}: bound {bound} < observed {seen}",
                t.name()
            );
            assert!(seen > 0.0);
            // tight enough to be useful: within three orders of magnitude of what is seen
            assert!(bound < 1e3 * seen.max(1e-7), "{bound} vs {seen}");
        }
    }

    #[test]
    fn allowance_grows_with_a_worse_tanh_and_weights() {
        let m = placeholder_pendulum();
        let (a, _) = f32_allowance(&m, Tanh::Libm);
        let (b, _) = f32_allowance(&m, Tanh::Fast);
        assert!(b > a);
        let mut big = m.clone();
        big.output.scale = vec![150.0];
        assert!(f32_allowance(&big, Tanh::Libm).0 > a);
    }

    #[test]
    fn band_contains_u_d_and_stays_in_actuator_limits() {
        let mut m = placeholder_pendulum();
        m.actuator_lo = vec![-20.0];
        m.actuator_hi = vec![16.0];
        let (lo, hi) = m.clamp_band(1.3);
        assert!(f64::from(lo[0]) <= -16.3 && f64::from(lo[0]) > -16.31);
        assert_eq!(hi[0], 16.0);
        m.u_lo = vec![-0.1];
        let (lo, _) = m.clamp_band(1e-9);
        assert!(f64::from(lo[0]) <= -0.1 - 1e-9);
        let (dlo, dhi) = m.domain_f32();
        assert!(f64::from(dlo[0]) >= m.domain_lo[0] && f64::from(dhi[0]) <= m.domain_hi[0]);
    }

    #[test]
    fn validate_names_the_field() {
        let mut m = placeholder_pendulum();
        m.layers[1].w[3].pop();
        let e = m.validate().unwrap_err().to_string();
        assert!(e.contains("layers[1].w[3]"), "{e}");
        let mut m = placeholder_pendulum();
        m.u_hi = vec![20.0];
        assert!(m.validate().unwrap_err().to_string().contains("u_0"));
    }

    #[test]
    fn array_layout_rules() {
        let s: Vec<String> = (0..3).map(|i| format!("{i}.5")).collect();
        assert_eq!(array(&s, 0, 10, 1), "[0.5, 1.5, 2.5]");
    }
}
