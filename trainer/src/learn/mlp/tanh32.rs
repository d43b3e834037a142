//! The f32 tanh of `controller-core` (`controller_core::activation::tanh_accurate`), the one
//! the deployed controller runs, mirrored operation by operation:
//! ```text
//! |x| < 0.875:  t = x + x·(z·P(z)),  z = x²                         (odd polynomial)
//! otherwise:    t = sign(x)·(1 − 2/(e + 1)),  e = e^{2a},  a = min(|x|, 10)
//!               e = 2^k·(1 + r + r²Q(r)),  k = ⌊2a·log₂e + ½⌋,  r = 2a − k·ln 2 (Cody–Waite)
//! ```
//! (max |t − tanh| = 7.07·10⁻⁸ over every f32, verified exhaustively in controller-core).
//! Written without branches — both formulas are evaluated and one is selected, which gives
//! the same bits as the device's branching code — so that a loop over lanes vectorises:
//! the training engine (`lanes`) and the exporter's model of the device both use it.

/// `controller_core::activation`'s constants of `tanh_accurate` (same names).
const ACC_CUT: f32 = 0.875;
const ACC_P: [f32; 6] = [
    -0.333_331_76,
    0.133_299_98,
    -0.053_710_45,
    0.020_895_608,
    -0.006_869_007_4,
    0.001_314_905,
];
const ACC_Q: [f32; 5] = [
    0.499_999_94,
    0.166_665_21,
    0.041_668_39,
    0.008_368_71,
    0.001_381_461_3,
];
const ACC_CLIP: f32 = 10.0;
const LOG2E: f32 = core::f32::consts::LOG2_E;
const LN2_HI: f32 = 0.693_145_75;
const LN2_LO: f32 = 1.428_606_8e-6;
/// 2²³: `v + MAGIC − MAGIC` rounds `v ∈ [0, 2²²)` to the nearest integer.
const MAGIC: f32 = 8_388_608.0;

/// `controller_core::activation::tanh_accurate`: the same f32 operations, the same bits.
#[inline(always)]
pub fn tanh_accurate(x: f32) -> f32 {
    let a = f32::from_bits(x.to_bits() & 0x7fff_ffff);
    // The polynomial branch.
    let z = x * x;
    let [p0, p1, p2, p3, p4, p5] = ACC_P;
    let p = p0 + z * (p1 + z * (p2 + z * (p3 + z * (p4 + z * p5))));
    let small = x + x * (z * p);
    // The exponential branch (NaN fails `a < ACC_CLIP` and becomes ACC_CLIP).
    let c = if a < ACC_CLIP { a } else { ACC_CLIP };
    let y = c + c;
    // y ∈ [0, 20]: v ∈ [0.5, 29.4]; the device truncates v to k (`as i32`), i.e. takes
    // ⌊v⌋. Here without a float-to-integer conversion (which does not vectorise): rounding
    // by the magic number 2²³ (exact for v < 2²²), one down where it rounded up, and k read
    // off the bits of k + 2²³ (0x4b00_0000 + k).
    let v = y * LOG2E + 0.5;
    let nearest = (v + MAGIC) - MAGIC;
    let kf = if nearest > v { nearest - 1.0 } else { nearest };
    let k = (kf + MAGIC).to_bits().wrapping_sub(MAGIC.to_bits());
    let r = (y - kf * LN2_HI) - kf * LN2_LO;
    let [q0, q1, q2, q3, q4] = ACC_Q;
    let q = q0 + r * (q1 + r * (q2 + r * (q3 + r * q4)));
    let e1 = 1.0 + (r + r * (r * q));
    let e = f32::from_bits(e1.to_bits().wrapping_add(k << 23));
    let t = 1.0 - 2.0 / (e + 1.0);
    let big = f32::from_bits(t.to_bits() | (x.to_bits() & 0x8000_0000));
    if a < ACC_CUT {
        small
    } else {
        big
    }
}

/// [`tanh_accurate`] on `N` lanes, written as one loop per operation (each a vector
/// instruction or two) so that the compiler vectorises it: the same operations, the same
/// bits as `tanh_accurate` lane by lane.
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

    /// The lane form gives the bits of the scalar form (which `tests/export_roundtrip.rs`
    /// compares with controller-core's), on every 4099th bit pattern, ±inf and NaN.
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
