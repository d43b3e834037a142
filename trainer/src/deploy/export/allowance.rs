//! The f32 error analysis of an [`ExportModel`]: the device network [`eval_f32`], the sound
//! allowance [`f32_allowance`], the observed differences [`sampled_max_diff`] and the
//! rounding of bounds to f32 ([`f32_down`], [`f32_up`]).
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
//! their own rounding.
//!
//! **The norm.** ε is stated in the 2-norm over the outputs (‖κ − κ_NN‖₂ ≤ ε), so the
//! allowance added to it is a bound on ‖κ_NN,f32(x) − κ_NN,f64(x)‖₂: on each sub-box the
//! per-output bounds e_o give ‖·‖₂ ≤ √(Σ_o e_o²) ([`norm2_up`], rounded up), and the
//! allowance is the maximum of that over sub-boxes. A maximum over outputs (the ∞-norm)
//! would understate it by up to √nu; for nu = 1 the two are the same number. The
//! per-axis clamp band `U ⊕ [−(ε + a), ε + a]` stays sound with the 2-norm a (≥ every
//! output's bound). The observed differences ([`sampled_max_diff`]) are 2-norms too.
//! Both are stated in the certificate's norm ‖S_u⁻¹·‖₂ (`ExportModel::u_scale`): each
//! output's bound divided by s_u,o (rounded up), exactly the unscaled numbers when s_u = 1.

use super::boxes::{max_or_nan, Grid};
use super::lanes::{eval_f32_lanes, Lane, LANES};
use super::{DenseF64, ExportError, ExportModel, ExportReport, Folded, LayerF32, Tanh};

/// Number of random states behind [`ExportReport`]'s observed differences.
pub const SAMPLES: usize = 1 << 18;
/// Largest f32 ≤ v.
pub(super) fn f32_down(v: f64) -> f32 {
    let c = v as f32;
    if f64::from(c) > v {
        next_f32(c, false)
    } else {
        c
    }
}

/// Smallest f32 ≥ v.
pub(super) fn f32_up(v: f64) -> f32 {
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
    let mut bufs = (Vec::new(), Vec::new());
    eval_f32_in(folded, (lo, hi), x, tanh, &mut bufs);
    bufs.0
}

/// [`eval_f32`] into reused buffers: the result is left in `bufs.0` (the same operations in
/// the same order, so the same bits; no allocation once the buffers have grown).
fn eval_f32_in(
    folded: &Folded,
    (lo, hi): (&[f32], &[f32]),
    x: &[f32],
    tanh: Tanh,
    bufs: &mut (Vec<f32>, Vec<f32>),
) {
    let (h, next) = bufs;
    h.clear();
    h.extend(x.iter().zip(lo.iter().zip(hi)).map(|(x, (l, u))| {
        if x < l {
            *l
        } else if x > u {
            *u
        } else {
            *x
        }
    }));
    let n = folded.f32_layers.len();
    for (k, (n_in, _, w, b)) in folded.f32_layers.iter().enumerate() {
        next.clear();
        next.extend(b.iter().enumerate().map(|(o, b)| {
            let mut acc = *b;
            for i in 0..*n_in {
                acc += w[o * n_in + i] * h[i];
            }
            if k + 1 < n {
                tanh.eval(acc)
            } else {
                acc
            }
        }));
        std::mem::swap(h, next);
    }
}

/// [`ExportModel::eval_f64`] into reused buffers: the result is left in `bufs.0` (the same
/// operations in the same order, so the same bits).
fn eval_f64_in(model: &ExportModel, x: &[f64], bufs: &mut (Vec<f64>, Vec<f64>)) {
    let (h, next) = bufs;
    h.clear();
    h.extend(
        x.iter()
            .zip(model.input.mean.iter().zip(&model.input.scale))
            .map(|(x, (m, s))| (x - m) / s),
    );
    let n = model.layers.len();
    for (k, l) in model.layers.iter().enumerate() {
        next.clear();
        next.extend(l.w.iter().zip(&l.b).map(|(row, b)| {
            let z = row.iter().zip(h.iter()).fold(*b, |acc, (w, x)| acc + w * x);
            if k + 1 < n {
                z.tanh()
            } else {
                z
            }
        }));
        std::mem::swap(h, next);
    }
    for (y, (m, s)) in h
        .iter_mut()
        .zip(model.output.mean.iter().zip(&model.output.scale))
    {
        *y = m + s * *y;
    }
}

/// Widened up by a relative 10⁻¹² (and 10⁻³⁰⁰): covers the rounding of the interval ends
/// and magnitudes computed in f64.
fn widen(v: f64) -> f64 {
    v * (1.0 + 1e-12) + 1e-300
}

/// 2⁻¹⁴⁹, the smallest positive f32 (products that underflow).
const TINY: f64 = 1.401_298_464_324_817e-45;

/// The exact network's interval enclosures over a box (module doc): per layer k, its
/// input's interval `ins[k]` (the box for k = 0, then the tanh of the previous layer's)
/// and its pre-activation interval `pre[k]` (with the slack that covers the f64 sums). They
/// do not depend on the rounding analysed, so one enclosure serves the f32 and the f64
/// analysis of a box. The buffers are reused from box to box.
#[derive(Default)]
struct Enclosure {
    ins: Vec<(Vec<f64>, Vec<f64>)>,
    pre: Vec<(Vec<f64>, Vec<f64>)>,
}

impl Enclosure {
    /// The enclosures of `layers` over the box `[a, b]`.
    fn of(&mut self, layers: &[DenseF64], a: &[f64], b: &[f64]) {
        let n_layers = layers.len();
        self.ins.resize_with(n_layers, Default::default);
        self.pre.resize_with(n_layers, Default::default);
        set(&mut self.ins[0], a, b);
        for (k, l) in layers.iter().enumerate() {
            let (lo, hi) = &self.ins[k];
            let (zlo, zhi) = &mut self.pre[k];
            zlo.clear();
            zhi.clear();
            for (row, bias) in l.w.iter().zip(&l.b) {
                let (mut s_lo, mut s_hi, mut mag) = (*bias, *bias, bias.abs());
                for i in 0..lo.len() {
                    let w = row[i];
                    let (p, q) = (w * lo[i], w * hi[i]);
                    s_lo += p.min(q);
                    s_hi += p.max(q);
                    mag += w.abs() * lo[i].abs().max(hi[i].abs());
                }
                let slack = widen(mag) * 1e-13;
                zlo.push(s_lo - slack);
                zhi.push(s_hi + slack);
            }
            if k + 1 < n_layers {
                // The tanh layer's outputs: tanh of the interval ends.
                let (zlo, zhi) = &self.pre[k];
                let (nlo, nhi) = &mut self.ins[k + 1];
                nlo.clear();
                nhi.clear();
                nlo.extend(zlo.iter().map(|l0| (l0.tanh() - 1e-15).max(-1.0)));
                nhi.extend(zhi.iter().map(|h0| (h0.tanh() + 1e-15).min(1.0)));
            }
        }
    }
}

/// `dst = (a, b)` in place.
fn set(dst: &mut (Vec<f64>, Vec<f64>), a: &[f64], b: &[f64]) {
    dst.0.clear();
    dst.0.extend_from_slice(a);
    dst.1.clear();
    dst.1.extend_from_slice(b);
}

/// Interval bound on |computed − exact| of the folded network over the box of `enc` (its
/// [`Enclosure`]), for unit roundoff `u` and relative input error `input_rel`, rounded
/// weights `rounded` (or exact if `None`), tanh error `dt`, the per-output bounds divided by
/// `u_scale` (the norm's S_u). `bufs` are reused error buffers.
#[allow(clippy::too_many_arguments)]
fn box_error(
    layers: &[DenseF64],
    rounded: Option<&[LayerF32]>,
    enc: &Enclosure,
    (u, input_rel): (f64, f64),
    dt: &dyn Fn(f64, f64) -> f64,
    u_scale: &[f64],
    bufs: &mut (Vec<f64>, Vec<f64>),
) -> f64 {
    let (err, zerr) = bufs;
    let (lo, hi) = &enc.ins[0];
    err.clear();
    err.extend(
        lo.iter()
            .zip(hi)
            .map(|(l, h)| widen(input_rel * l.abs().max(h.abs()) + TINY)),
    );
    let n_layers = layers.len();
    for (k, l) in layers.iter().enumerate() {
        let (lo, hi) = &enc.ins[k];
        let n = lo.len();
        let gamma = (n as f64 + 1.0) * u / (1.0 - (n as f64 + 1.0) * u);
        zerr.clear();
        for (o, (row, bias)) in l.w.iter().zip(&l.b).enumerate() {
            // The weights as computed (rounded to f32, or exact), read in place.
            let wrow = rounded.map(|r| &r[k].2[o * n..(o + 1) * n]);
            let wr = |i: usize| wrow.map_or(row[i], |w| f64::from(w[i]));
            let br = rounded.map_or(*bias, |r| f64::from(r[k].3[o]));
            let mut e = widen((br - bias).abs());
            let mut rmag = br.abs();
            for i in 0..n {
                let w = row[i];
                let m = lo[i].abs().max(hi[i].abs());
                let wi = wr(i);
                e += wi.abs() * err[i] + (wi - w).abs() * m;
                rmag += wi.abs() * (m + err[i]);
            }
            zerr.push(widen(e + gamma * rmag + n as f64 * TINY));
        }
        if k + 1 < n_layers {
            // tanh layer
            let (zlo, zhi) = &enc.pre[k];
            for o in 0..zerr.len() {
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
            }
        }
        std::mem::swap(err, zerr);
    }
    norm2_up(&scaled_up(err, u_scale))
}

/// e_o / s_u,o rounded up (unchanged where s_u,o = 1 or no scale is given): a per-output
/// bound in the certificate's norm ‖S_u⁻¹·‖₂.
fn scaled_up(err: &[f64], u_scale: &[f64]) -> Vec<f64> {
    err.iter()
        .enumerate()
        .map(|(o, e)| match u_scale.get(o) {
            Some(s) if *s != 1.0 => {
                let q = e / s;
                q + q.abs() * f64::EPSILON
            }
            _ => *e,
        })
        .collect()
}

/// ‖v‖₂ rounded up (relative 4·10⁻¹⁶ covers the sum's and the root's rounding for the
/// short vectors of a network's outputs); for one element exactly |v₀|, so a one-output
/// network's numbers are those of the maximum over outputs. NaN in, NaN out.
pub(crate) fn norm2_up(v: &[f64]) -> f64 {
    match v {
        [] => 0.0,
        [a] => a.abs(),
        _ => {
            let s: f64 = v.iter().map(|e| e * e).sum();
            let n = s.sqrt();
            n + n * (v.len() as f64 + 2.0) * f64::EPSILON
        }
    }
}

/// Per-axis number of sub-boxes: about 2¹⁶ boxes in all, at most 256 per axis.
fn splits(nx: usize) -> usize {
    let k = (65_536f64).powf(1.0 / nx as f64).floor() as usize;
    k.clamp(1, 256)
}

/// The sound f32 allowance over X for one tanh (module doc) and the number of sub-boxes.
/// The sub-boxes are bounded in parallel; the maximum does not depend on the order, so the
/// result is the same for every thread count.
pub fn f32_allowance(model: &ExportModel, tanh: Tanh) -> (f64, usize) {
    let folded = model.folded();
    let key = allowance_key(model, &folded, tanh);
    let memo = ALLOWANCES.get_or_init(Default::default);
    if let Some(&hit) = memo.lock().ok().as_ref().and_then(|m| m.get(&key)) {
        return hit;
    }
    let r = f32_allowance_of(model, &folded, tanh);
    if let Ok(mut m) = memo.lock() {
        m.insert(key, r);
    }
    r
}

/// The allowances computed so far in this process, by [`allowance_key`]: a run computes
/// the same net's allowance in several stages (its certificate, the refinement's writes,
/// the statistical tier, the export), each a pure function of the key's inputs.
type AllowanceMemo = std::sync::Mutex<std::collections::HashMap<[u8; 32], (f64, usize)>>;
static ALLOWANCES: std::sync::OnceLock<AllowanceMemo> = std::sync::OnceLock::new();

/// SHA-256 of everything [`f32_allowance_of`] reads: the folded f64 and f32 layers, X, the
/// norm's S_u and the tanh.
fn allowance_key(model: &ExportModel, folded: &Folded, tanh: Tanh) -> [u8; 32] {
    use sha2::{Digest, Sha256};
    let mut h = Sha256::new();
    let mut f64s = |v: &[f64]| {
        h.update((v.len() as u64).to_le_bytes());
        for x in v {
            h.update(x.to_bits().to_le_bytes());
        }
    };
    for l in &folded.layers {
        for row in &l.w {
            f64s(row);
        }
        f64s(&l.b);
    }
    f64s(&model.domain_lo);
    f64s(&model.domain_hi);
    f64s(&model.u_scale);
    for (n_in, n_out, w, b) in &folded.f32_layers {
        h.update((*n_in as u64).to_le_bytes());
        h.update((*n_out as u64).to_le_bytes());
        for x in w.iter().chain(b) {
            h.update(x.to_bits().to_le_bytes());
        }
    }
    h.update([tanh as u8]);
    h.finalize().into()
}

/// [`f32_allowance`] computed (not looked up): the maximum of the per-box bound
/// ([`box_bound`]) over the grid of [`splits`] boxes per axis, pruned through coarse boxes
/// ([`Grid::max_of`]).
fn f32_allowance_of(model: &ExportModel, folded: &Folded, tanh: Tanh) -> (f64, usize) {
    let exact = model_unfolded_as_exact(folded);
    let grid = Grid::new(&model.domain_lo, &model.domain_hi, splits(model.nx()));
    let worst = grid.max_of(Scratch::default, |sc, a, b| {
        box_bound((model, folded, &exact), tanh, sc, a, b)
    });
    (worst * (1.0 + 1e-9), grid.boxes())
}

/// A box's enclosure and error buffers, reused from box to box.
type Scratch = (Enclosure, (Vec<f64>, Vec<f64>));

/// The allowance's bound on the box `[a, b]`: the f32 analysis plus the f64 reference's
/// own (module doc), on one enclosure (the exact layers are the same).
fn box_bound(
    (model, folded, exact): (&ExportModel, &Folded, &[DenseF64]),
    tanh: Tanh,
    (enc, bufs): &mut Scratch,
    a: &[f64],
    b: &[f64],
) -> f64 {
    enc.of(&folded.layers, a, b);
    let e32 = box_error(
        &folded.layers,
        Some(&folded.f32_layers),
        enc,
        (2f64.powi(-24), 2f64.powi(-23)),
        &|lo, hi| tanh.max_abs_err_on(lo, hi),
        &model.u_scale,
        bufs,
    );
    let e64 = box_error(
        exact,
        None,
        enc,
        (8.0 * 2f64.powi(-53), 8.0 * 2f64.powi(-53)),
        &|_, _| 1e-15,
        &model.u_scale,
        bufs,
    );
    e32 + e64
}

/// [`f32_allowance_of`] without the pruning: the maximum over every box.
#[cfg(test)]
fn f32_allowance_every_box(model: &ExportModel, tanh: Tanh) -> f64 {
    let folded = model.folded();
    let exact = model_unfolded_as_exact(&folded);
    let grid = Grid::new(&model.domain_lo, &model.domain_hi, splits(model.nx()));
    let (mut a, mut b) = (vec![0.0; model.nx()], vec![0.0; model.nx()]);
    let mut sc = Scratch::default();
    let mut worst = 0.0f64;
    for n in 0..grid.boxes() {
        grid.fine_box(n, &mut a, &mut b);
        let e = box_bound((model, &folded, &exact), tanh, &mut sc, &a, &b);
        worst = max_or_nan(worst, e);
    }
    worst * (1.0 + 1e-9)
}

fn model_unfolded_as_exact(folded: &Folded) -> Vec<DenseF64> {
    folded.layers.clone()
}

/// Largest ‖κ_NN,f32(x) − κ_NN,f64(x)‖₂ (over outputs; |·| for one output) on `n` uniform
/// random states in X
/// (deterministic xorshift stream from `seed`). The states are drawn in order, chunk by
/// chunk, and each chunk is evaluated in parallel: the maximum is the same for every
/// thread count.
pub fn sampled_max_diff(model: &ExportModel, tanh: Tanh, n: usize, seed: u64) -> f64 {
    sampled_max_diffs(model, &[tanh], n, seed)[0]
}

/// [`sampled_max_diff`] of several device tanh on the same `n` states (the stream of
/// `seed`): the f64 reference net — most of the cost, a glibc `tanh` per hidden unit — is
/// evaluated once per state for all of them. Entry k is exactly
/// `sampled_max_diff(model, tanhs[k], n, seed)`.
pub fn sampled_max_diffs(model: &ExportModel, tanhs: &[Tanh], n: usize, seed: u64) -> Vec<f64> {
    use rayon::prelude::*;
    const CHUNK: usize = 1 << 14;
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
    let mut worst = vec![0.0f64; tanhs.len()];
    let mut xs = vec![0.0; CHUNK * nx.max(1)];
    let mut done = 0;
    while done < n {
        let m = CHUNK.min(n - done);
        for x in xs[..m * nx].chunks_exact_mut(nx.max(1)) {
            for (i, v) in x.iter_mut().enumerate() {
                *v = model.domain_lo[i] + next() * (model.domain_hi[i] - model.domain_lo[i]);
            }
        }
        // Scratch per worker (no allocation per state): the lanes' inputs in f32, the f32
        // lane buffers, each tanh's f32 outputs, the f64 layer buffers, the difference. The
        // f32 net runs on `LANES` states at once (`lanes`: each lane has the scalar
        // evaluation's bits).
        type Scratch = (
            Vec<Lane>,
            (Vec<Lane>, Vec<Lane>),
            Vec<Vec<Lane>>,
            (Vec<f64>, Vec<f64>),
            Vec<f64>,
        );
        let w = xs[..m * nx]
            .par_chunks(nx.max(1) * LANES)
            .map_init(Scratch::default, |(x32, b32, y32, b64, d), group| {
                let states = group.len() / nx.max(1);
                x32.clear();
                x32.extend((0..nx).map(|i| {
                    let mut v = [0.0f32; LANES];
                    for (l, s) in group.chunks_exact(nx.max(1)).enumerate() {
                        v[l] = s[i] as f32;
                    }
                    v
                }));
                y32.resize_with(tanhs.len(), Vec::new);
                for (t, y) in tanhs.iter().zip(y32.iter_mut()) {
                    eval_f32_lanes(&folded, (&lo, &hi), x32, *t, b32);
                    y.clear();
                    y.extend_from_slice(&b32.0);
                }
                let mut worst = vec![0.0f64; tanhs.len()];
                for (l, x) in group.chunks_exact(nx.max(1)).enumerate().take(states) {
                    eval_f64_in(model, x, b64);
                    for (w, y) in worst.iter_mut().zip(y32.iter()) {
                        d.clear();
                        d.extend(
                            y.iter()
                                .zip(&b64.0)
                                .enumerate()
                                .map(|(o, (a, b))| (f64::from(a[l]) - b) / model.u_scale_of(o)),
                        );
                        *w = max_or_nan(*w, norm2_sampled(d));
                    }
                }
                worst
            })
            .reduce(
                || vec![0.0; tanhs.len()],
                |a, b| a.iter().zip(&b).map(|(x, y)| max_or_nan(*x, *y)).collect(),
            );
        for (a, b) in worst.iter_mut().zip(&w) {
            *a = max_or_nan(*a, *b);
        }
        done += m;
    }
    worst
}

/// ‖d‖₂ of an observed difference (plain f64; |d₀| for one output; NaN propagates so that a
/// non-finite output is never hidden by a maximum).
fn norm2_sampled(d: &[f64]) -> f64 {
    match d {
        [a] => a.abs(),
        _ => d.iter().map(|e| e * e).sum::<f64>().sqrt(),
    }
}

/// Computes the allowances (sound) and observed differences (the same [`SAMPLES`] states)
/// for both tanh implementations.
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
    }
    // Both tanh on the same states (the stream of seed 1): one f64 reference per state.
    let seen = sampled_max_diffs(model, &Tanh::ALL, SAMPLES, 1);
    report.f32_observed.copy_from_slice(&seen);
    super::range::check_report(model, &report)?;
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::super::{placeholder_pendulum, Scaling, Tanh};
    use super::*;

    /// The placeholder pendulum with its output row duplicated: two outputs that are the same
    /// function, so the f32 error vector is (d, d) with ‖·‖₂ = √2·|d|.
    fn two_equal_outputs() -> ExportModel {
        let mut m = placeholder_pendulum();
        let last = m.layers.last_mut().unwrap();
        last.w.push(last.w[0].clone());
        last.b.push(last.b[0]);
        m.output = Scaling {
            mean: vec![0.0; 2],
            scale: vec![15.0; 2],
        };
        for v in [
            &mut m.u_lo,
            &mut m.u_hi,
            &mut m.actuator_lo,
            &mut m.actuator_hi,
        ] {
            v.push(v[0]);
        }
        m
    }

    /// ε is a 2-norm over the outputs: the allowance of two equal outputs is √2 times the
    /// one-output allowance (each output's analysis is the same), not the maximum over outputs
    /// (which would equal the one-output figure).
    #[test]
    fn allowance_of_two_equal_outputs_is_sqrt2_times_one() {
        let one = placeholder_pendulum();
        let two = two_equal_outputs();
        for t in Tanh::ALL {
            let (a1, _) = f32_allowance(&one, t);
            let (a2, _) = f32_allowance(&two, t);
            let want = std::f64::consts::SQRT_2 * a1;
            assert!(
                a2 >= want * (1.0 - 1e-12) && a2 <= want * (1.0 + 1e-9),
                "{}: two outputs {a2:e}, √2 · one output {want:e}",
                t.name()
            );
        }
    }

    /// The 2-norm allowance covers the 2-norm of the f32-vs-f64 difference on random states,
    /// computed here from the two evaluations (not by `sampled_max_diff`).
    #[test]
    fn allowance_covers_the_observed_two_norm_difference() {
        let m = two_equal_outputs();
        let folded = m.folded();
        let (lo, hi) = m.domain_f32();
        for t in Tanh::ALL {
            let (a, _) = f32_allowance(&m, t);
            let mut worst = 0.0f64;
            for k in 0..20_000u64 {
                let x: Vec<f64> = (0..2)
                    .map(|i| {
                        let r = crate::rng::uniform(11, k, i as u64);
                        m.domain_lo[i] + r * (m.domain_hi[i] - m.domain_lo[i])
                    })
                    .collect();
                let x32: Vec<f32> = x.iter().map(|v| *v as f32).collect();
                let y32 = eval_f32(&folded, &lo, &hi, &x32, t);
                let y64 = m.eval_f64(&x);
                let s: f64 = (0..2).map(|o| (f64::from(y32[o]) - y64[o]).powi(2)).sum();
                worst = worst.max(s.sqrt());
            }
            assert!(worst > 0.0 && a >= worst, "{}: {a:e} < {worst:e}", t.name());
            let seen = sampled_max_diff(&m, t, 20_000, 5);
            assert!(a >= seen, "{}: {a:e} < {seen:e}", t.name());
        }
    }

    /// Both tanh on one stream of states give, each, exactly the maximum of a scalar
    /// recomputation on that stream (the xorshift stream re-implemented here, the scalar
    /// `eval_f32` and `eval_f64`): sharing the f64 reference changes no bit.
    #[test]
    fn shared_reference_is_each_tanh_own_maximum() {
        let m = two_equal_outputs();
        let folded = m.folded();
        let (lo, hi) = m.domain_f32();
        let (n, seed) = (3_001, 9u64);
        let both = sampled_max_diffs(&m, &Tanh::ALL, n, seed);
        for (k, t) in Tanh::ALL.iter().enumerate() {
            let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
            let mut worst = 0.0f64;
            for _ in 0..n {
                let x: Vec<f64> = (0..2)
                    .map(|i| {
                        s ^= s << 13;
                        s ^= s >> 7;
                        s ^= s << 17;
                        let r = (s >> 11) as f64 / (1u64 << 53) as f64;
                        m.domain_lo[i] + r * (m.domain_hi[i] - m.domain_lo[i])
                    })
                    .collect();
                let x32: Vec<f32> = x.iter().map(|v| *v as f32).collect();
                let y32 = eval_f32(&folded, &lo, &hi, &x32, *t);
                let y64 = m.eval_f64(&x);
                let e = |o: usize| (f64::from(y32[o]) - y64[o]) / m.u_scale_of(o);
                let d: f64 = (0..2).map(|o| e(o) * e(o)).sum();
                worst = worst.max(d.sqrt());
            }
            assert!(worst > 0.0, "{}", t.name());
            assert_eq!(both[k], worst, "{}", t.name());
            assert_eq!(both[k], sampled_max_diff(&m, *t, n, seed), "{}", t.name());
        }
    }

    /// The allowance pruned through coarse boxes is the maximum over every box, bit for bit,
    /// for one and two outputs, both tanh, and a net whose weights are perturbed (so its
    /// largest box is somewhere else).
    #[test]
    fn pruned_allowance_is_the_maximum_over_every_box() {
        let mut bent = placeholder_pendulum();
        for (k, l) in bent.layers.iter_mut().enumerate() {
            for (o, row) in l.w.iter_mut().enumerate() {
                for (i, w) in row.iter_mut().enumerate() {
                    *w *= 1.0 + 0.3 * crate::rng::uniform(7, (k * 1000 + o) as u64, i as u64);
                }
            }
        }
        for m in [placeholder_pendulum(), two_equal_outputs(), bent] {
            for t in Tanh::ALL {
                let folded = m.folded();
                let (pruned, _) = f32_allowance_of(&m, &folded, t);
                assert_eq!(pruned, f32_allowance_every_box(&m, t), "{}", t.name());
            }
        }
    }

    #[test]
    fn norms_keep_nan_and_one_output() {
        assert_eq!(norm2_up(&[-3.0]), 3.0);
        assert!(norm2_up(&[3.0, 4.0]) >= 5.0);
        assert!(max_or_nan(1.0, f64::NAN).is_nan());
        assert!(norm2_up(&[f64::NAN, 1.0]).is_nan());
    }
}
