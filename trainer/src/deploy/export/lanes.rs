//! κ_NN,f32 on [`LANES`] states at once ([`eval_f32_lanes`]): the device network of
//! [`super::allowance::eval_f32`] — projection onto the f32 box, the folded f32 layers
//! z_o = b_o + Σ_i w_oi·h_i summed in the core's order i = 0, 1, …, the device tanh — with
//! every operation applied to the lanes side by side. Each lane goes through exactly the
//! operations of the scalar evaluation in the same order (no fused multiply-add, no
//! reassociation), so each lane has the scalar result's bits; the loops over lanes let the
//! compiler use vector instructions, and the accurate tanh is the branch-free lane form
//! `learn::mlp::tanh32::tanh_lanes`, whose bits are `controller_core::activation::tanh_accurate`'s
//! (tested there). The fast tanh is applied lane by lane (`controller_core`'s own function).
//!
//! Used by the export's observed f32 differences (`allowance::sampled_max_diff`), whose
//! maximum is therefore the same number as with the scalar evaluation.

use super::{Folded, Tanh};
use crate::learn::mlp::tanh32::tanh_lanes;

/// States evaluated together.
pub const LANES: usize = 8;

/// One value per lane.
pub type Lane = [f32; LANES];

/// κ_NN,f32 (before the output clamp) of the `LANES` states `x[i][lane]` (input i of each
/// lane's state), into `bufs.0` (output o of each lane: `bufs.0[o][lane]`). The buffers are
/// reused: no allocation once they have grown.
pub fn eval_f32_lanes(
    folded: &Folded,
    (lo, hi): (&[f32], &[f32]),
    x: &[Lane],
    tanh: Tanh,
    bufs: &mut (Vec<Lane>, Vec<Lane>),
) {
    let (h, next) = bufs;
    h.clear();
    h.extend(x.iter().zip(lo.iter().zip(hi)).map(|(x, (l, u))| {
        let mut p = [0.0f32; LANES];
        for k in 0..LANES {
            // The scalar code's projection, lane by lane (a NaN stays NaN).
            p[k] = if x[k] < *l {
                *l
            } else if x[k] > *u {
                *u
            } else {
                x[k]
            };
        }
        p
    }));
    let n = folded.f32_layers.len();
    for (k, (n_in, _, w, b)) in folded.f32_layers.iter().enumerate() {
        next.clear();
        for (o, b) in b.iter().enumerate() {
            let mut acc = [*b; LANES];
            let row = &w[o * n_in..(o + 1) * n_in];
            for (wi, hi) in row.iter().zip(h.iter()) {
                for l in 0..LANES {
                    acc[l] += wi * hi[l];
                }
            }
            if k + 1 < n {
                acc = match tanh {
                    Tanh::Libm => tanh_lanes(&acc),
                    Tanh::Fast => acc.map(|v| tanh.eval(v)),
                };
            }
            next.push(acc);
        }
        std::mem::swap(h, next);
    }
}

#[cfg(test)]
mod tests {
    use super::super::{allowance::eval_f32, placeholder_pendulum};
    use super::*;

    /// Every lane has the bits of the scalar device evaluation, for both tanh, at states
    /// inside X, outside it (projected), at its corners and at non-finite inputs.
    #[test]
    fn lanes_have_the_scalar_bits() {
        let m = placeholder_pendulum();
        let folded = m.folded();
        let (lo, hi) = m.domain_f32();
        let mut states: Vec<[f32; 2]> = (0..4000u64)
            .map(|k| {
                let r = |i: u64| crate::rng::uniform(3, k, i) as f32;
                [-9.0 + 18.0 * r(0), -1.5 + 3.0 * r(1)]
            })
            .collect();
        states.extend([
            [lo[0], lo[1]],
            [hi[0], hi[1]],
            [f32::NAN, 0.0],
            [f32::INFINITY, f32::NEG_INFINITY],
        ]);
        for t in Tanh::ALL {
            let mut bufs = Default::default();
            for chunk in states.chunks(LANES) {
                let mut x = vec![[0.0f32; LANES]; 2];
                for (l, s) in chunk.iter().enumerate() {
                    x[0][l] = s[0];
                    x[1][l] = s[1];
                }
                eval_f32_lanes(&folded, (&lo, &hi), &x, t, &mut bufs);
                for (l, s) in chunk.iter().enumerate() {
                    let want = eval_f32(&folded, &lo, &hi, s, t);
                    assert_eq!(bufs.0.len(), want.len());
                    for (o, w) in want.iter().enumerate() {
                        assert_eq!(bufs.0[o][l].to_bits(), w.to_bits(), "{} at {s:?}", t.name());
                    }
                }
            }
        }
    }
}
