//! `activation`: tanh on the device, and the proven bound on its error.
//!
//! Two implementations, selected at build time:
//! - [`tanh_accurate`] (default): this crate's own f32 tanh, branch on `|x|`:
//!   - `|x| < 0.875`: `x + x·z·P(z)`, `z = x²`, `P` a degree-5 polynomial (near-minimax for
//!     the absolute error, fitted on `[0, 0.875]`, coefficients rounded to f32);
//!   - otherwise `sign(x)·(1 − 2/(e^{2a} + 1))`, `a = min(|x|, 10)`, with
//!     `e^{2a} = 2^k · p(r)`: `k = ⌊2a·log₂e + ½⌋`, `r = (2a − k·ln2_hi) − k·ln2_lo`
//!     (Cody–Waite, the first product and the difference are exact), `p(r) = 1 + r + r²·Q(r)`
//!     with `Q` of degree 4, and the scaling by `2^k` an integer add to the exponent bits.
//!
//!   About 15 f32 operations on either branch, one division, no table, no libm; odd by
//!   construction (the first branch is an odd expression, the second copies the sign bit).
//! - [`tanh_fast`] (feature `fast-tanh`): a (7, 6) rational, near-minimax for the absolute
//!   error on `[0, 8]`, in a scaled variable:
//!   `r = y (a₀ + a₁w + a₂w² + w³) / (b₀ + b₁w + b₂w² + w³)`, `w = y²`, `y = K·c(x)`, where
//!   `c(x) = ((x·2²⁸) as i32) as f32 · 2⁻²⁸` clips `x` to `[−FAST_CLIP, FAST_CLIP] = [−8, 8]`
//!   by the saturating float-to-integer conversion (one `vcvt` each way on the Cortex-M4, no
//!   compare or branch; NaN → 0; it truncates `|x| < 2⁻⁴` to a multiple of 2⁻²⁸), and the
//!   scale `K ≈ 0.026` makes both polynomials monic (the two multiplications by `K` and 2⁻²⁸
//!   are one, by the f32 constant `FAST_Y`). About 17 f32 instructions, one division; the
//!   result provably stays inside `(−1, 1)`, so it needs no clamp. Coefficients: a linear
//!   programme (minimise the largest absolute error on a grid of `[0, 8]`, with `r ≤ 1 − 10⁻⁶`),
//!   rounded to f32 (`controller-core/tools/fit_fast_tanh.py`); the bound below is not the
//!   fit's but the exhaustive check's.
//!
//! Error bounds: [`TANH_ACCURATE_MAX_ABS_ERR`] and [`TANH_FAST_MAX_ABS_ERR`] bound
//! `|t(x) − tanh(x)|` over **every** f32 input `x` (NaN excepted), where `tanh` is exact.
//! They are proven by exhaustion: the ignored test `exhaustive_error_bounds` evaluates both
//! functions on all 2³¹ non-negative f32 values (both are odd) against f64 `tanh` (error
//! < 2⁻⁵² relative, far below the margins) and checks the constants. `.ci/run` runs it in
//! release mode. Measured there: `tanh_accurate` max 7.07·10⁻⁸ absolute (at x ≈ 0.8734),
//! at most 1.19 ulp of the correctly rounded result; the constant is 1.2·10⁻⁷, libm's
//! `tanhf` bound, so certificates labelled `libm` hold for this function too;
//! `tanh_fast` max 3.22·10⁻⁶ (at x ≈ 7.63), bound 3.3·10⁻⁶.
//! The trainer depends on this module for the device arithmetic: its exporter evaluates
//! [`tanh_accurate`] and [`tanh_fast`] themselves and takes the error bounds and
//! [`TANH_FAST_ERR_BINS`] from here for the certificate's f32 allowance; its training engine
//! evaluates [`tanh_accurate`] on 8-sample lanes in a branch-free form built from the public
//! coefficients below ([`ACC_P`], [`ACC_Q`], …), checked bit for bit against [`tanh_accurate`].
//!
//! The certificate label of the default tanh stays `"libm"` (`CERTIFICATE_LIBM`,
//! `f32_allowance_libm`): a file-format name for "the default, accurate tanh", kept so that
//! exported controllers and reports keep working.

/// `FAST_CLIP`: the fast tanh evaluates its rational on `x` clipped to ±8 (where
/// `1 − tanh 8 ≈ 2.3·10⁻⁷`); the clip is the saturation of `(x·2²⁸) as i32` at ±2³¹.
pub const FAST_CLIP: f32 = 8.0;
/// `2²⁸ = 2³¹ / FAST_CLIP`: the fixed-point scale of the fast tanh's clip.
pub const FAST_FIX: f32 = 268_435_456.0;
/// `K·2⁻²⁸` rounded to f32 (`K = 0.025984265`): fixed-point integer → the scaled variable `y`.
pub const FAST_Y: f32 = 9.679_893e-11;
/// `a₀, a₁, a₂` of the fast tanh's numerator `y (a₀ + a₁w + a₂w² + w³)`.
pub const FAST_A: [f32; 3] = [9.280_053e-5, 0.016_684_914, 0.435_023_87];
/// `b₀, b₁, b₂` of its denominator `b₀ + b₁w + b₂w² + w³`.
pub const FAST_B: [f32; 3] = [2.411_385_4e-6, 0.001_623_884_7, 0.107_925_8];

/// Bound on `|tanh_accurate(x) − tanh(x)|` for every f32 `x` (verified exhaustively; the
/// largest error seen is 7.07·10⁻⁸, see the module doc).
pub const TANH_ACCURATE_MAX_ABS_ERR: f64 = 1.2e-7;

/// Bound on `|tanh_fast(x) − tanh(x)|` for every f32 `x` (verified exhaustively; the
/// largest error seen is 3.22·10⁻⁶, at x ≈ 7.63).
pub const TANH_FAST_MAX_ABS_ERR: f64 = 3.3e-6;

/// Piecewise bound for [`tanh_fast`]: entry `(a_k, δ_k)` bounds `|tanh_fast(x) − tanh(x)|`
/// by `δ_k` for `a_{k−1} ≤ |x| < a_k` (`a_{−1} = 0`, the last `a` is +∞). The near-minimax
/// rational's error is nearly level on `[0, 8]`, so the bins differ little (2.3–3.3·10⁻⁶).
/// Verified exhaustively with the uniform bounds (each bin is the largest error seen,
/// rounded up).
pub const TANH_FAST_ERR_BINS: [(f32, f64); 10] = [
    (0.5, 3.0e-6),
    (1.0, 2.8e-6),
    (1.5, 3.0e-6),
    (2.0, 3.1e-6),
    (2.5, 3.2e-6),
    (3.0, 2.3e-6),
    (3.5, 3.1e-6),
    (4.0, 2.9e-6),
    (4.5, 2.6e-6),
    (f32::INFINITY, 3.3e-6),
];

/// Certificate label of the tanh this build uses (`"libm"`: the default [`tanh_accurate`],
/// see the module doc; or `"fast"`).
pub const TANH_KIND: &str = if cfg!(feature = "fast-tanh") {
    "fast"
} else {
    "libm"
};

/// The error bound of the tanh this build uses.
pub const TANH_MAX_ABS_ERR: f64 = if cfg!(feature = "fast-tanh") {
    TANH_FAST_MAX_ABS_ERR
} else {
    TANH_ACCURATE_MAX_ABS_ERR
};

/// `|x|` below which [`tanh_accurate`] evaluates its odd polynomial.
pub const ACC_CUT: f32 = 0.875;
/// `P(z)` of [`tanh_accurate`]'s first branch, constant term first.
pub const ACC_P: [f32; 6] = [
    -0.333_331_76,
    0.133_299_98,
    -0.053_710_45,
    0.020_895_608,
    -0.006_869_007_4,
    0.001_314_905,
];
/// `Q(r)` of [`tanh_accurate`]'s `e^r = 1 + r + r²·Q(r)`, constant term first.
pub const ACC_Q: [f32; 5] = [
    0.499_999_94,
    0.166_665_21,
    0.041_668_39,
    0.008_368_71,
    0.001_381_461_3,
];
/// Inputs are clipped to `|x| ≤ ACC_CLIP` (then `1 − tanh < 5·10⁻⁹`).
pub const ACC_CLIP: f32 = 10.0;
/// log₂ e in f32.
pub const LOG2E: f32 = core::f32::consts::LOG2_E;
/// ln 2 rounded to 16 significant bits: `k·LN2_HI` is exact for `k < 2⁸`.
pub const LN2_HI: f32 = 0.693_145_75;
/// `ln 2 − LN2_HI`, rounded to f32.
pub const LN2_LO: f32 = 1.428_606_8e-6;

/// This crate's tanh (see the module doc): max error 7.07·10⁻⁸ absolute, 1.19 ulp, over
/// every f32. Odd (`t(−x) = −t(x)`; `t(−0) = +0`); finite for every input (±inf → ±t(10) = ±1, NaN → ±t(10)).
///
/// The operation order is the one the exporter's f32 model (`trainer::deploy::export`)
/// mirrors.
#[inline]
#[cfg_attr(feature = "no-panic", no_panic::no_panic)]
pub fn tanh_accurate(x: f32) -> f32 {
    let a = f32::from_bits(x.to_bits() & 0x7fff_ffff);
    if a < ACC_CUT {
        let z = x * x;
        let [p0, p1, p2, p3, p4, p5] = ACC_P;
        let p = p0 + z * (p1 + z * (p2 + z * (p3 + z * (p4 + z * p5))));
        return x + x * (z * p);
    }
    // NaN fails `a < ACC_CLIP` too and becomes ACC_CLIP.
    let a = if a < ACC_CLIP { a } else { ACC_CLIP };
    let y = a + a;
    // y ∈ [1.75, 20]: k ∈ [3, 29], no saturation; the conversion truncates, so + ½ rounds.
    let k = (y * LOG2E + 0.5) as i32;
    let kf = k as f32;
    let r = (y - kf * LN2_HI) - kf * LN2_LO;
    let [q0, q1, q2, q3, q4] = ACC_Q;
    let q = q0 + r * (q1 + r * (q2 + r * (q3 + r * q4)));
    let p = 1.0 + (r + r * (r * q));
    // p ∈ [0.7, 1.5] and k ≤ 29: adding k to the exponent field stays a normal number.
    let e = f32::from_bits(p.to_bits().wrapping_add((k as u32) << 23));
    let t = 1.0 - 2.0 / (e + 1.0);
    f32::from_bits(t.to_bits() | (x.to_bits() & 0x8000_0000))
}

/// The clipped (7, 6) rational approximation (see the module doc). Exactly odd
/// (`t(−x) = −t(x)`, the truncation and the saturation are symmetric), finite for every input
/// (±inf → ±t(8), NaN → 0).
///
/// No clamp of the result to `[−1, 1]`: on every f32 of `[0, FAST_CLIP]` (which reaches
/// every value the clip produces, up to sign) the result stays in `[0, 1)` (its largest value
/// is 0.9999992), checked by the test `rational_stays_inside_unit_interval`, so a clamp would
/// never change a bit.
#[inline]
#[cfg_attr(feature = "no-panic", no_panic::no_panic)]
pub fn tanh_fast(x: f32) -> f32 {
    // `as i32` saturates (and sends NaN to 0): the clip without compares, `f32::min`/`max`
    // (a libcall on the Cortex-M4) or a branch. `x·2²⁸` is exact (power of two).
    let y = ((x * FAST_FIX) as i32) as f32 * FAST_Y;
    rational(y)
}

/// `r(y)` of the module doc: Horner in `w = y²`, both polynomials monic, one division. The
/// operation order is the one the exporter's f32 model (`trainer::deploy::export`) mirrors.
#[inline(always)]
fn rational(y: f32) -> f32 {
    let [a0, a1, a2] = FAST_A;
    let [b0, b1, b2] = FAST_B;
    let w = y * y;
    let p = y * (a0 + w * (a1 + w * (a2 + w)));
    let q = b0 + w * (b1 + w * (b2 + w));
    // q ≥ b0 > 0 and y is finite, so r is never NaN.
    p / q
}

/// The tanh of this build: [`tanh_accurate`], or [`tanh_fast`] with the `fast-tanh` feature.
#[inline]
pub fn tanh(x: f32) -> f32 {
    if cfg!(feature = "fast-tanh") {
        tanh_fast(x)
    } else {
        tanh_accurate(x)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn err(f: fn(f32) -> f32, x: f32) -> f64 {
        (f64::from(f(x)) - f64::from(x).tanh()).abs()
    }

    #[test]
    fn both_are_odd_and_accurate_on_a_grid() {
        for k in -20_000..=20_000 {
            let x = k as f32 * 1e-3;
            for f in [tanh_accurate as fn(f32) -> f32, tanh_fast] {
                assert_eq!(f(-x), -f(x));
                assert!(f(x).abs() <= 1.0);
            }
            assert!(err(tanh_accurate, x) <= TANH_ACCURATE_MAX_ABS_ERR);
            assert!(err(tanh_fast, x) <= TANH_FAST_MAX_ABS_ERR);
        }
        assert_eq!(tanh_fast(f32::INFINITY), tanh_fast(FAST_CLIP));
        assert_eq!(tanh_fast(f32::NEG_INFINITY), -tanh_fast(FAST_CLIP));
        assert_ne!(tanh_fast(FAST_CLIP), tanh_fast(7.9));
        assert_eq!(tanh_fast(f32::NAN), 0.0);
        assert_eq!(tanh_accurate(f32::INFINITY), 1.0);
        assert_eq!(tanh_accurate(f32::NEG_INFINITY), -1.0);
        assert!(tanh_accurate(f32::NAN).is_finite());
    }

    /// The fast counterpart of the exhaustive proof (debug build, < 1 s): every 997th f32
    /// bit pattern below 10.5 (subnormals to the clip, both branches, ~1.1·10⁶ inputs) plus
    /// the 2·10⁴ f32 on each side of the branch point `ACC_CUT` and of `ACC_CLIP`; checks the
    /// bound, |t| ≤ 1, oddness, and monotonicity on the dense neighbourhoods.
    #[test]
    fn accurate_tanh_bound_on_a_dense_sample() {
        let mut worst = 0.0f64;
        let mut check = |x: f32| {
            let t = tanh_accurate(x);
            let e = err(tanh_accurate, x);
            assert!(e <= TANH_ACCURATE_MAX_ABS_ERR, "x = {x:e}: error {e:e}");
            assert!(t.abs() <= 1.0);
            assert_eq!(tanh_accurate(-x), -t, "x = {x:e}");
            worst = worst.max(e);
            t
        };
        for bits in (0..10.5f32.to_bits()).step_by(997) {
            check(f32::from_bits(bits));
        }
        for centre in [ACC_CUT, ACC_CLIP] {
            let mut prev = f32::NEG_INFINITY;
            for bits in centre.to_bits() - 20_000..centre.to_bits() + 20_000 {
                let t = check(f32::from_bits(bits));
                assert!(t >= prev, "not monotone at {:e}", f32::from_bits(bits));
                prev = t;
            }
        }
        // Not vacuous: the sample reaches the errors the exhaustive test reports.
        assert!(worst > 0.5 * TANH_ACCURATE_MAX_ABS_ERR / 2.0, "{worst:e}");
    }

    /// Why `tanh_fast` needs no output clamp: every f32 of `[0, FAST_CLIP]` gives a result
    /// in `[0, 1)`. The clip's outputs for these inputs are all its non-negative outputs
    /// (inputs above 8 give the same as 8, NaN the same as 0), and `t(−x) = −t(x)` exactly
    /// (checked on a stride), so that covers every input. About 10⁹ divisions: a few seconds.
    #[test]
    fn rational_stays_inside_unit_interval() {
        let mut max = 0.0f32;
        for bits in 0..=FAST_CLIP.to_bits() {
            let x = f32::from_bits(bits);
            let r = tanh_fast(x);
            assert!((0.0..1.0).contains(&r), "t({x:e}) = {r:e}");
            max = max.max(r);
            if bits % 65_537 == 1 {
                // `==`: a tiny x truncates to +0 on both sides.
                assert_eq!(tanh_fast(-x), -r);
            }
        }
        assert!(max < 1.0);
        assert_eq!(tanh_fast(9.0e30), tanh_fast(FAST_CLIP));
        assert_eq!(rational(0.0), 0.0);
    }

    /// The proof of the two bounds: every non-negative f32 (both functions are odd, which
    /// the grid test and the code's symmetry show; the negative half is checked too on a
    /// stride). Runs in release mode from `.ci/run` (~1 min of CPU; prints the accurate
    /// tanh's largest error in ulp of the correctly rounded result too).
    #[test]
    #[ignore = "exhaustive over 2^31 inputs; run in release by .ci/run"]
    fn exhaustive_error_bounds() {
        let mut max = [0.0f64; 2];
        let mut at = [0.0f32; 2];
        let mut bins = [0.0f64; TANH_FAST_ERR_BINS.len()];
        let mut bin = 0;
        let mut max_ulp = 0.0f64;
        for bits in 0u32..0x7f80_0000 {
            let x = f32::from_bits(bits);
            let t = f64::from(x).tanh();
            // ulp of the binade of t: lo ≤ t < next(lo) for the f32 lo below t.
            let r = t as f32;
            let lo = if f64::from(r) > t {
                f32::from_bits(r.to_bits() - 1)
            } else {
                r
            };
            let ulp = f64::from(f32::from_bits(lo.to_bits() + 1) - lo);
            let e = [tanh_accurate(x), tanh_fast(x)].map(|y| (f64::from(y) - t).abs());
            max_ulp = max_ulp.max(e[0] / ulp);
            for ((m, a), ek) in max.iter_mut().zip(at.iter_mut()).zip(e) {
                if ek > *m {
                    *m = ek;
                    *a = x;
                }
            }
            while let Some((a, _)) = TANH_FAST_ERR_BINS.get(bin) {
                if x < *a {
                    break;
                }
                bin += 1;
            }
            bins[bin] = bins[bin].max(e[1]);
            if bits % 4099 == 0 {
                assert_eq!(tanh_accurate(-x), -tanh_accurate(x));
                assert_eq!(tanh_fast(-x), -tanh_fast(x));
            }
        }
        assert_eq!(tanh_accurate(f32::INFINITY), 1.0);
        println!(
            "max |tanh_accurate − tanh| = {:e} at x = {:e}, {max_ulp:.3} ulp",
            max[0], at[0]
        );
        println!("max |tanh_fast − tanh| = {:e} at x = {:e}", max[1], at[1]);
        for ((a, bound), seen) in TANH_FAST_ERR_BINS.iter().zip(bins) {
            println!("fast tanh, |x| < {a}: max error {seen:e} (bound {bound:e})");
            assert!(seen <= *bound, "|x| < {a}: {seen:e} > {bound:e}");
        }
        assert!(max[0] <= TANH_ACCURATE_MAX_ABS_ERR, "{}", max[0]);
        assert!(max[1] <= TANH_FAST_MAX_ABS_ERR, "{}", max[1]);
    }
}
