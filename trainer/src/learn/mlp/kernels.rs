//! The register-blocked kernels of the batched passes: the dot products over a block of
//! samples ([`dot_block`], `dst[i] = init + Σ_c w[c]·src[c·stride + i]`) and the rows of a
//! layer's weight gradient ([`WeightGrad`], `gw[c] += Σ_i (ga_i a_{i,c} + Σ_k gt_{k,i} T_{i,k,c})`),
//! each summed in the per-sample order, so that the batched passes reproduce the
//! per-sample formulas bit for bit.

/// Samples per register-blocked group in [`dot_block`].
const LANES: usize = 8;

/// `dst[i] = init + Σ_c w[c]·src[c·stride + i]` for `i < dst.len()`, summed over c in
/// order (the per-sample order), with the accumulators of `LANES` samples in registers.
#[inline(always)]
pub(super) fn dot_block(w: &[f64], src: &[f64], stride: usize, init: f64, dst: &mut [f64]) {
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
pub(super) struct WeightGrad<'a> {
    /// ∂loss/∂z_r over the block (nb).
    pub(super) gar: &'a [f64],
    /// ∂loss/∂Z_{r,k} over the block (nx × nb), empty without tangents.
    pub(super) gtr: &'a [f64],
    /// Sample-major inputs (nb × inp).
    pub(super) at: &'a [f64],
    /// Sample-major input tangents (nb × nx × inp).
    pub(super) tt: &'a [f64],
    pub(super) inp: usize,
    pub(super) nx: usize,
}

impl WeightGrad<'_> {
    /// Columns `c0..c0 + W` of the row; returns `c0 + W`.
    #[inline(always)]
    pub(super) fn chunk<const W: usize>(&self, c0: usize, gw: &mut [f64]) -> usize {
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
