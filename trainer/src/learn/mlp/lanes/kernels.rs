//! The register-blocked kernels of the lane engine over a *chunk* of groups (the jets of
//! every group of a chunk side by side, group g's unit c at `(g·n + c)·q`):
//! - [`dot_chunk`]: `acc_g = init + Σ_c w[c]·h_{g,c}` for every group g of the chunk (a jet
//!   of `q` lane vectors each; `init` on the value only), summed over c in order, with the
//!   accumulators of several groups in registers so that every weight is broadcast once per
//!   block and the groups' chains run side by side; [`dot_rows`] runs it for every row of
//!   a layer, two rows at a time (each jet vector loaded once for both);
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
fn dot_chunk(
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

/// [`dot_chunk`] for every row r of the row-major `w` (rows of length `n`) with `init`
/// `bias[r]` (0 without `bias`): two rows at a time where the jet size has a kernel, so that
/// every jet vector loaded serves both rows. Each accumulator's terms are those of
/// [`dot_chunk`] in the same order: the same bits.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(super) fn dot_rows(
    w: &[f32],
    n: usize,
    bias: Option<&[f32]>,
    h: &[V],
    sg: usize,
    ng: usize,
    q: usize,
    scratch: &mut [V],
    dst: &mut [V],
    so: usize,
) {
    debug_assert!(
        n > 0 && w.len().is_multiple_of(n),
        "rows of length {n} in {}",
        w.len()
    );
    let rows = w.len() / n.max(1);
    let init = |r: usize| bias.map_or(0.0, |b| b[r]);
    let mut r = 0;
    while r + 2 <= rows {
        let pair = [&w[r * n..(r + 1) * n], &w[(r + 1) * n..(r + 2) * n]];
        let i2 = [init(r), init(r + 1)];
        match q {
            1 => pair_blocks::<1, 4>(pair, h, sg, ng, i2, dst, so, r),
            2 => pair_blocks::<2, 2>(pair, h, sg, ng, i2, dst, so, r),
            3 => pair_blocks::<3, 2>(pair, h, sg, ng, i2, dst, so, r),
            _ => break,
        }
        r += 2;
    }
    for r in r..rows {
        dot_chunk(
            &w[r * n..(r + 1) * n],
            h,
            sg,
            ng,
            q,
            init(r),
            scratch,
            dst,
            so,
            r,
        );
    }
}

/// Rows r, r + 1 of [`dot_rows`] for jets of `Q` vectors, `G` groups per register block
/// (the rest one by one).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn pair_blocks<const Q: usize, const G: usize>(
    w: [&[f32]; 2],
    h: &[V],
    sg: usize,
    ng: usize,
    init: [f32; 2],
    dst: &mut [V],
    so: usize,
    r: usize,
) {
    let mut store = |a: &[[[V; Q]; 2]], g0: usize| {
        for (g, ag) in a.iter().enumerate() {
            for (k, ak) in ag.iter().enumerate() {
                let o = (g0 + g) * so + (r + k) * Q;
                let d: &mut [V; Q] = (&mut dst[o..o + Q]).try_into().expect("Q vectors");
                *d = *ak;
            }
        }
    };
    let mut g0 = 0;
    while g0 + G <= ng {
        store(&pair_block::<Q, G>(w, h, sg, g0, init), g0);
        g0 += G;
    }
    while g0 < ng {
        store(&pair_block::<Q, 1>(w, h, sg, g0, init), g0);
        g0 += 1;
    }
}

#[inline(always)]
fn pair_block<const Q: usize, const G: usize>(
    w: [&[f32]; 2],
    h: &[V],
    sg: usize,
    g0: usize,
    init: [f32; 2],
) -> [[[V; Q]; 2]; G] {
    let n = w[0].len();
    let (w0, w1) = (w[0], &w[1][..n]);
    let mut hs: [&[[V; Q]]; G] = [&[]; G];
    for (g, hg) in hs.iter_mut().enumerate() {
        *hg = &h[(g0 + g) * sg..(g0 + g) * sg + n * Q].as_chunks::<Q>().0[..n];
    }
    let mut a = [[[[0.0f32; L]; Q]; 2]; G];
    for ag in a.iter_mut() {
        ag[0][0] = [init[0]; L];
        ag[1][0] = [init[1]; L];
    }
    for c in 0..n {
        let (wa, wb) = (w0[c], w1[c]);
        for (ag, hg) in a.iter_mut().zip(&hs) {
            let hc: &[V; Q] = &hg[c];
            for k in 0..Q {
                let x = hc[k];
                for i in 0..L {
                    ag[0][k][i] += wa * x[i];
                    ag[1][k][i] += wb * x[i];
                }
            }
        }
    }
    a
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

#[cfg(test)]
mod tests {
    use super::*;

    /// `dot_rows` (two rows at a time) gives the bits of `dot_chunk` row by row, for every
    /// jet size, odd and even row counts, with and without biases, and chunks of 1–9 groups.
    #[test]
    fn dot_rows_is_dot_chunk_row_by_row() {
        let mut s = 0x1234_5678_9ABC_DEF0u64;
        let mut next = || {
            s = crate::rng::splitmix64(s);
            (s >> 40) as f32 / (1u64 << 24) as f32 * 4.0 - 2.0
        };
        for q in [1, 2, 3, 4, 6] {
            for (rows, n) in [(1, 3), (2, 2), (5, 10), (10, 10), (7, 1)] {
                for ng in [1, 2, 3, 5, 9] {
                    let w: Vec<f32> = (0..rows * n).map(|_| next()).collect();
                    let bias: Vec<f32> = (0..rows).map(|_| next()).collect();
                    let h: Vec<V> = (0..ng * n * q)
                        .map(|_| std::array::from_fn(|_| next()))
                        .collect();
                    let mut scratch = vec![[0.0; L]; q];
                    for b in [Some(&bias[..]), None] {
                        let so = rows * q;
                        let (mut a, mut e) = (vec![[0.0; L]; ng * so], vec![[0.0; L]; ng * so]);
                        dot_rows(&w, n, b, &h, n * q, ng, q, &mut scratch, &mut a, so);
                        for r in 0..rows {
                            let init = b.map_or(0.0, |b| b[r]);
                            let wr = &w[r * n..(r + 1) * n];
                            dot_chunk(wr, &h, n * q, ng, q, init, &mut scratch, &mut e, so, r);
                        }
                        let bits = |v: &[V]| -> Vec<u32> {
                            v.iter().flatten().map(|x| x.to_bits()).collect()
                        };
                        assert_eq!(bits(&a), bits(&e), "q {q} rows {rows} n {n} ng {ng}");
                    }
                }
            }
        }
    }
}
