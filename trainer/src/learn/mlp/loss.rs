//! The training loss of [`Mlp`] and its exact gradient with respect to the (scaled)
//! parameters, by reverse mode through the forward and tangent passes (hand-derived;
//! checked against central differences in the tests):
//! ```text
//! loss = λ₁/B Σ‖u_i − κ_i‖² + λ₂/B Σ_{i ∉ degenerate} ‖∂u_i/∂x − ∂κ_i/∂x‖²_F + λ₃ Σ_j ‖W̃_j‖²_F
//! ```
//! with `W̃_j` the weights in physical units (`W̃_1 = W_1 D`, `W̃_m = S W_m`). With a
//! clamp band ([`Batch::band`]) the terms of outputs that the deployed clamp matches
//! exactly are zero. A sequence net ([`Batch::seq`], outputs u₀, …, u_{N−1}) weighs output
//! r's value term by w_r and has the Jacobian term on its first `jac_rows` outputs (u₀)
//! only: `λ₁/B Σ Σ_r w_r (u_ir − κ_ir)² + λ₂/B Σ ‖∂u₀_i/∂x − ∂κ_i/∂x‖²_F + …`.

use super::kernels::{dot_block, WeightGrad};
use super::{Mlp, Workspace, BLOCK};
use serde::{Deserialize, Serialize};

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
    /// A sequence net's loss ([`SeqLoss`]); `None`: every output has weight 1 and a
    /// Jacobian target (the net of u₀ alone).
    pub seq: Option<SeqLoss<'a>>,
}

/// The loss of a sequence net: per-output value weights and the Jacobian on u₀ only.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SeqLoss<'a> {
    /// Outputs with a Jacobian target (the first ones, u₀): `du` holds `jac_rows × nx` per
    /// sample.
    pub jac_rows: usize,
    /// Value weight of each output (w_k repeated nu times for step k).
    pub weight: &'a [f64],
}

impl Batch<'_> {
    /// The outputs with a Jacobian target (all `nu` without [`Batch::seq`]).
    #[inline(always)]
    pub fn jac_rows(&self, nu: usize) -> usize {
        self.seq.map_or(nu, |s| s.jac_rows)
    }
    /// λ₁ times output r's value weight (λ₁ itself without [`Batch::seq`], the same bits).
    #[inline(always)]
    pub fn value_weight(&self, lam: f64, r: usize) -> f64 {
        self.seq.map_or(lam, |s| lam * s.weight[r])
    }
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

/// The value error of output r, `pred − target`, and whether the clamp to `band` matches
/// the label exactly ([`clamped_exact`]; the error is then 0).
#[inline]
pub(super) fn value_error(
    band: Option<(&[f64], &[f64])>,
    r: usize,
    pred: f64,
    target: f64,
) -> (f64, bool) {
    let exact = clamped_exact(band, r, pred, target);
    (if exact { 0.0 } else { pred - target }, exact)
}

impl Mlp {
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
        self.add_weight_term(lam, Some(&mut parts), grad);
        parts
    }

    /// Adds the weight term λ₃ Σ_j ‖W̃_j‖²_F on the physical weights (W̃_1 = W_1 D,
    /// W̃_m = S W_m) to `parts.weights` (if given) and, with `grad`, its gradient to
    /// `grad.w`.
    pub(super) fn add_weight_term(
        &self,
        lam: LossWeights,
        mut parts: Option<&mut LossParts>,
        mut grad: Option<&mut Grad>,
    ) {
        if lam.weights == 0.0 {
            return;
        }
        for (j, l) in self.layers.iter().enumerate() {
            for r in 0..l.out {
                for c in 0..l.inp {
                    let f = self.weight_scale(j, r, c);
                    let w = l.w[r * l.inp + c];
                    if let Some(parts) = parts.as_deref_mut() {
                        parts.weights += lam.weights * f * w * w;
                    }
                    if let Some(grad) = grad.as_deref_mut() {
                        grad.w[j][r * l.inp + c] += 2.0 * lam.weights * f * w;
                    }
                }
            }
        }
    }

    /// The factor f = r²c² of weight (j, r, c) in the weight term (r = s_r on the last
    /// layer, c = 1/h_c on the first, 1 elsewhere): ‖W̃_j‖²_F = Σ f·w².
    #[inline(always)]
    fn weight_scale(&self, j: usize, r: usize, c: usize) -> f64 {
        let rs = if j + 1 == self.layers.len() {
            self.out_half[r]
        } else {
            1.0
        };
        let cs = if j == 0 { 1.0 / self.in_half[c] } else { 1.0 };
        rs * rs * cs * cs
    }

    /// The weight term's gradient factors `(2λ₃)·f` per weight, row-major per layer, into
    /// `out`: adding factor·w to the gradient is [`Mlp::add_weight_term`]'s gradient, bit
    /// for bit (the same operations).
    pub(super) fn weight_grad_factors(&self, lam: LossWeights, out: &mut Vec<Vec<f64>>) {
        out.clear();
        for (j, l) in self.layers.iter().enumerate() {
            let mut v = Vec::with_capacity(l.w.len());
            for r in 0..l.out {
                for c in 0..l.inp {
                    v.push(2.0 * lam.weights * self.weight_scale(j, r, c));
                }
            }
            out.push(v);
        }
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
        let jr = batch.jac_rows(nu);
        let (y, yt) = (&ws.a[m], &ws.t[m]);
        for i in 0..nb {
            let gi = i0 + i;
            let use_jac = batch.use_jac[gi] && tangent;
            for r in 0..nu {
                let s = self.out_half[r];
                let pred = self.out_center[r] + s * y[r * nb + i];
                let (e, exact) = value_error(batch.band, r, pred, batch.u[gi * nu + r]);
                let lv = batch.value_weight(lam.value, r);
                parts.value += lv * inv_b * e * e;
                ws.ga[r * nb + i] = 2.0 * lv * inv_b * e * s;
                if !tangent {
                    continue;
                }
                for k in 0..nx {
                    let g = if use_jac && !exact && r < jr {
                        let e = s * yt[(r * nx + k) * nb + i] - batch.du[gi * jr * nx + r * nx + k];
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
