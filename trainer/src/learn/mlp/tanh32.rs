//! The f32 tanh of `controller-core` (`controller_core::activation::tanh_accurate`, the one
//! the deployed controller runs) on `N` lanes at once, from the core's own coefficients
//! (`controller_core::activation::{ACC_P, ACC_Q, …}`):
//! ```text
//! |x| < 0.875:  t = x + x·(z·P(z)),  z = x²                         (odd polynomial)
//! otherwise:    t = sign(x)·(1 − 2/(e + 1)),  e = e^{2a},  a = min(|x|, 10)
//!               e = 2^k·(1 + r + r²Q(r)),  k = ⌊2a·log₂e + ½⌋,  r = 2a − k·ln 2 (Cody–Waite)
//! ```
//! (max |t − tanh| = 7.07·10⁻⁸ over every f32, verified exhaustively in controller-core).
//! Written without branches — both formulas are evaluated and one is selected, and ⌊·⌋ is
//! taken without a float-to-integer conversion — which gives the bits of the device's
//! branching code lane by lane and lets the loops vectorise: the training engine (`lanes`)
//! uses it. The contract: `tanh_lanes(x)[i]` has the bits of
//! `controller_core::activation::tanh_accurate(x[i])` for every f32 (tested below).

use controller_core::activation::{ACC_CLIP, ACC_CUT, ACC_P, ACC_Q, LN2_HI, LN2_LO, LOG2E};

/// 2²³: `v + MAGIC − MAGIC` rounds `v ∈ [0, 2²²)` to the nearest integer.
const MAGIC: f32 = 8_388_608.0;

/// `controller_core::activation::tanh_accurate` on `N` lanes, written as one loop per
/// operation (each a vector instruction or two) so that the compiler vectorises it: the
/// same operations, the same bits lane by lane.
#[inline(always)]
pub fn tanh_lanes<const N: usize>(x: &[f32; N]) -> [f32; N] {
    // One plain loop per operation (not `array::from_fn`, which the compiler may leave as
    // a call per element).
    macro_rules! map {
        (&|$i:ident| $e:expr) => {{
            let mut r = [0.0f32; N];
            for $i in 0..N {
                r[$i] = $e;
            }
            r
        }};
    }
    let a = map!(&|i| f32::from_bits(x[i].to_bits() & 0x7fff_ffff));
    let [p0, p1, p2, p3, p4, p5] = ACC_P;
    let z = map!(&|i| x[i] * x[i]);
    let p = map!(&|i| p0 + z[i] * (p1 + z[i] * (p2 + z[i] * (p3 + z[i] * (p4 + z[i] * p5)))));
    let small = map!(&|i| x[i] + x[i] * (z[i] * p[i]));
    let y = map!(&|i| {
        let c = if a[i] < ACC_CLIP { a[i] } else { ACC_CLIP };
        c + c
    });
    let v = map!(&|i| y[i] * LOG2E + 0.5);
    let nearest = map!(&|i| (v[i] + MAGIC) - MAGIC);
    let kf = map!(&|i| {
        if nearest[i] > v[i] {
            nearest[i] - 1.0
        } else {
            nearest[i]
        }
    });
    let r = map!(&|i| (y[i] - kf[i] * LN2_HI) - kf[i] * LN2_LO);
    let [q0, q1, q2, q3, q4] = ACC_Q;
    let e1 = map!(&|i| {
        let r = r[i];
        let q = q0 + r * (q1 + r * (q2 + r * (q3 + r * q4)));
        1.0 + (r + r * (r * q))
    });
    let e = map!(&|i| {
        let k = (kf[i] + MAGIC).to_bits().wrapping_sub(MAGIC.to_bits());
        f32::from_bits(e1[i].to_bits().wrapping_add(k << 23))
    });
    let t = map!(&|i| 1.0 - 2.0 / (e[i] + 1.0));
    map!(&|i| {
        let big = f32::from_bits(t[i].to_bits() | (x[i].to_bits() & 0x8000_0000));
        if a[i] < ACC_CUT {
            small[i]
        } else {
            big
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use controller_core::activation::tanh_accurate;

    /// The lane form gives the bits of controller-core's scalar tanh, on every 4099th bit
    /// pattern, ±inf, NaN, ±0 and a grid of [−12.5, 12.5].
    #[test]
    fn lanes_equal_the_scalar_tanh_bit_for_bit() {
        let xs: Vec<f32> = (0..=u32::MAX)
            .step_by(4099)
            .chain([0x7f80_0000, 0xff80_0000, 0x7fc0_0000, 0, 0x8000_0000])
            .map(f32::from_bits)
            .chain((-5000..5000).map(|k| k as f32 * 2.5e-3))
            .collect();
        for chunk in xs.chunks(8) {
            let mut v = [0.0f32; 8];
            v[..chunk.len()].copy_from_slice(chunk);
            let t = tanh_lanes(&v);
            for (x, t) in v.iter().zip(t) {
                assert_eq!(t.to_bits(), tanh_accurate(*x).to_bits(), "x = {x:e}");
            }
        }
    }
}
