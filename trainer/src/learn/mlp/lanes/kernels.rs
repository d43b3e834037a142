//! The register-blocked kernels of the lane engine over a *chunk* of groups (the jets of
//! every group of a chunk side by side, group g's unit c at `(g·n + c)·q`):
//! - [`dot_chunk`]: `acc_g = init + Σ_c w[c]·h_{g,c}` for every group g of the chunk (a jet
//!   of `q` lane vectors each; `init` on the value only), summed over c in order, with the
//!   accumulators of several groups in registers so that every weight is broadcast once per
//!   block and the groups' chains run side by side;
//! - [`outer_chunk`]: one row of a weight gradient, `gw[c] += Σ_g Σ_k g_{g,k}·h_{g,c,k}`,
//!   the groups' terms added in group order with the accumulators in registers.
//!
//! Every lane's operations are those of one group processed alone, in the same order, so
//! the results do not depend on how groups are blocked (same bits as one group at a time).

use super::{add, mul, L, V};

/// Writes `dst[g·so + r·q + k] = [k = 0]·init + Σ_c w[c]·h[g·sg + c·q + k]` for each group
/// `g < ng`, summed over c in order (`0 + …` first). `scratch` (≥ q vectors) holds the
/// accumulators of the jet sizes without a specialised kernel.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(super) fn dot_chunk(
    w: &[f32],
    h: &[V],
    sg: usize,
    ng: usize,
    q: usize,
    init: f32,
    scratch: &mut [V],
    dst: &mut [V],
    so: usize,
    r: usize,
) {
    match q {
        1 => dot_blocks::<1, 8>(w, h, sg, ng, init, dst, so, r),
        2 => dot_blocks::<2, 4>(w, h, sg, ng, init, dst, so, r),
        3 => dot_blocks::<3, 4>(w, h, sg, ng, init, dst, so, r),
        4 => dot_blocks::<4, 2>(w, h, sg, ng, init, dst, so, r),
        5 => dot_blocks::<5, 2>(w, h, sg, ng, init, dst, so, r),
        7 => dot_blocks::<7, 2>(w, h, sg, ng, init, dst, so, r),
        _ => {
            let acc = &mut scratch[..q];
            for g in 0..ng {
                acc.fill([0.0; L]);
                acc[0] = [init; L];
                let hg = &h[g * sg..g * sg + w.len() * q];
                for (&wc, hc) in w.iter().zip(hg.chunks_exact(q)) {
                    for (a, x) in acc.iter_mut().zip(hc) {
                        let (mut t, x) = (*a, *x);
                        for i in 0..L {
                            t[i] += wc * x[i];
                        }
                        *a = t;
                    }
                }
                dst[g * so + r * q..g * so + r * q + q].copy_from_slice(acc);
            }
        }
    }
}

/// [`dot_chunk`] for jets of `Q` vectors, `G` groups per register block (the rest one by
/// one).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn dot_blocks<const Q: usize, const G: usize>(
    w: &[f32],
    h: &[V],
    sg: usize,
    ng: usize,
    init: f32,
    dst: &mut [V],
    so: usize,
    r: usize,
) {
    let mut g0 = 0;
    while g0 + G <= ng {
        let a = dot_block::<Q, G>(w, h, sg, g0, init);
        for (g, ag) in a.iter().enumerate() {
            let o = (g0 + g) * so + r * Q;
            let d: &mut [V; Q] = (&mut dst[o..o + Q]).try_into().expect("Q vectors");
            *d = *ag;
        }
        g0 += G;
    }
    while g0 < ng {
        let a = dot_block::<Q, 1>(w, h, sg, g0, init);
        let o = g0 * so + r * Q;
        let d: &mut [V; Q] = (&mut dst[o..o + Q]).try_into().expect("Q vectors");
        *d = a[0];
        g0 += 1;
    }
}

#[inline(always)]
fn dot_block<const Q: usize, const G: usize>(
    w: &[f32],
    h: &[V],
    sg: usize,
    g0: usize,
    init: f32,
) -> [[V; Q]; G] {
    let n = w.len();
    // Each group's jets as n arrays of Q vectors (the bounds checked once, here).
    let mut hs: [&[[V; Q]]; G] = [&[]; G];
    for (g, hg) in hs.iter_mut().enumerate() {
        *hg = &h[(g0 + g) * sg..(g0 + g) * sg + n * Q].as_chunks::<Q>().0[..n];
    }
    let mut a = [[[0.0f32; L]; Q]; G];
    for ag in a.iter_mut() {
        ag[0] = [init; L];
    }
    for (c, &wc) in w.iter().enumerate() {
        for (ag, hg) in a.iter_mut().zip(&hs) {
            let hc: &[V; Q] = &hg[c];
            for (ak, hk) in ag.iter_mut().zip(hc) {
                let x = *hk;
                for i in 0..L {
                    ak[i] += wc * x[i];
                }
            }
        }
    }
    a
}

/// One row r of a layer's weight gradient over a chunk: for every column c,
/// `gw[c] += s_0; gw[c] += s_1; …` with `s_g = ((0 + gr_{g,0}·h_{g,c,0}) + gr_{g,1}·h_{g,c,1}) + …`,
/// where group g's row jet is `g_all[g·sgo + r·q ..][..q]` and its input jets
/// `h[g·sgi + c·q ..][..q]`.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(super) fn outer_chunk(
    g_all: &[V],
    sgo: usize,
    r: usize,
    h: &[V],
    sgi: usize,
    ng: usize,
    q: usize,
    gw: &mut [V],
) {
    match q {
        1 => outer_blocks::<1>(g_all, sgo, r, h, sgi, ng, gw),
        2 => outer_blocks::<2>(g_all, sgo, r, h, sgi, ng, gw),
        3 => outer_blocks::<3>(g_all, sgo, r, h, sgi, ng, gw),
        4 => outer_blocks::<4>(g_all, sgo, r, h, sgi, ng, gw),
        5 => outer_blocks::<5>(g_all, sgo, r, h, sgi, ng, gw),
        7 => outer_blocks::<7>(g_all, sgo, r, h, sgi, ng, gw),
        _ => {
            for (c, acc) in gw.iter_mut().enumerate() {
                let mut t = *acc;
                for g in 0..ng {
                    let gr = &g_all[g * sgo + r * q..g * sgo + r * q + q];
                    let hc = &h[g * sgi + c * q..g * sgi + c * q + q];
                    let mut s = [0.0f32; L];
                    for (a, b) in gr.iter().zip(hc) {
                        let (a, b) = (*a, *b);
                        for i in 0..L {
                            s[i] += a[i] * b[i];
                        }
                    }
                    for i in 0..L {
                        t[i] += s[i];
                    }
                }
                *acc = t;
            }
        }
    }
}

/// [`outer_chunk`] for jets of `Q` vectors: column after column, the column's accumulator
/// in a register while the groups' terms are added in order.
#[inline(always)]
fn outer_blocks<const Q: usize>(
    g_all: &[V],
    sgo: usize,
    r: usize,
    h: &[V],
    sgi: usize,
    ng: usize,
    gw: &mut [V],
) {
    for (c, acc) in gw.iter_mut().enumerate() {
        let mut t = *acc;
        // Group by group through whole chunks, so that the bounds checks are loop-invariant.
        for (gg, hg) in g_all.chunks_exact(sgo).zip(h.chunks_exact(sgi)).take(ng) {
            let gr: [V; Q] = gg[r * Q..r * Q + Q].try_into().expect("Q vectors");
            let hc: [V; Q] = hg[c * Q..c * Q + Q].try_into().expect("Q vectors");
            // `0 + g₀h₀` of the one-group formula without the `0 +`: it can only change
            // the sign of a zero, which the f64 gradient (+0 plus the lanes) never sees.
            let mut s = mul(gr[0], hc[0]);
            for k in 1..Q {
                s = add(s, mul(gr[k], hc[k]));
            }
            t = add(t, s);
        }
        *acc = t;
    }
}
