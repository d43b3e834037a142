//! `activation`: tanh on the device, and the proven bound on its error.
//!
//! Two implementations, selected at build time:
//! - [`tanh_libm`] (default): the pure-Rust `libm` port of musl's `tanhf` — the same code on
//!   the host and on the Cortex-M4.
//! - [`tanh_fast`] (feature `fast-tanh`): Lambert's continued fraction truncated to a
//!   (7, 6) rational, `r(x) = x (135135 + 17325 x² + 378 x⁴ + x⁶) / (135135 + 62370 x² +
//!   3150 x⁴ + 28 x⁶)`, evaluated on `x` clipped to `[−FAST_CLIP, FAST_CLIP]`: one division,
//!   no branch (the clip is two conditional moves; the result provably stays inside
//!   `(−1, 1)`, so it needs no clamp).
//!
//! Error bounds: [`TANH_LIBM_MAX_ABS_ERR`] and [`TANH_FAST_MAX_ABS_ERR`] bound
//! `|t(x) − tanh(x)|` over **every** f32 input `x` (NaN excepted), where `tanh` is exact.
//! They are proven by exhaustion: the ignored test `exhaustive_error_bounds` evaluates both
//! functions on all 2³¹ non-negative f32 values (both are odd) against f64 `tanh` (error
//! < 2⁻⁵² relative, far below the margins) and checks the constants. `.ci/run` runs it in
//! release mode. The trainer's exporter uses the same constants for the certificate's f32
//! allowance (the `tests/` crate checks that they agree).

/// `FAST_CLIP`: the fast tanh evaluates its rational on `x` clamped to ±4.97, where
/// `r(4.97) ≈ 1 − 6·10⁻⁷`.
pub const FAST_CLIP: f32 = 4.97;

/// Bound on `|tanh_libm(x) − tanh(x)|` for every f32 `x` (verified exhaustively).
pub const TANH_LIBM_MAX_ABS_ERR: f64 = 1.2e-7;

/// Bound on `|tanh_fast(x) − tanh(x)|` for every f32 `x` (verified exhaustively).
pub const TANH_FAST_MAX_ABS_ERR: f64 = 1.0e-4;

/// Piecewise bound for [`tanh_fast`]: entry `(a_k, δ_k)` bounds `|tanh_fast(x) − tanh(x)|`
/// by `δ_k` for `a_{k−1} ≤ |x| < a_k` (`a_{−1} = 0`, the last `a` is +∞). The rational is
/// accurate near 0 and loses accuracy towards the clip, so a network whose pre-activations
/// stay small gets a much smaller allowance than the uniform bound gives. Verified
/// exhaustively with the uniform bounds.
pub const TANH_FAST_ERR_BINS: [(f32, f64); 10] = [
    (0.5, 4.0e-7),
    (1.0, 4.0e-7),
    (1.5, 4.0e-7),
    (2.0, 4.0e-7),
    (2.5, 5.0e-7),
    (3.0, 1.2e-6),
    (3.5, 4.6e-6),
    (4.0, 1.52e-5),
    (4.5, 4.25e-5),
    (f32::INFINITY, 1.0e-4),
];

/// Name of the tanh this build uses (`"libm"` or `"fast"`).
pub const TANH_KIND: &str = if cfg!(feature = "fast-tanh") {
    "fast"
} else {
    "libm"
};

/// The error bound of the tanh this build uses.
pub const TANH_MAX_ABS_ERR: f64 = if cfg!(feature = "fast-tanh") {
    TANH_FAST_MAX_ABS_ERR
} else {
    TANH_LIBM_MAX_ABS_ERR
};

/// libm's `tanhf`.
#[inline]
#[cfg_attr(feature = "no-panic", no_panic::no_panic)]
pub fn tanh_libm(x: f32) -> f32 {
    libm::tanhf(x)
}

/// The clipped (7, 6) rational approximation (see the module doc). Odd, monotone on
/// the clipped range, finite for every input (NaN maps to `r(−FAST_CLIP)`).
///
/// No clamp of the result to `[−1, 1]`: on the clipped range the f32 rational never leaves
/// `(−1, 1)` (its largest value there is 0.9999995), checked on every f32 of
/// `[0, FAST_CLIP]` by the test `rational_stays_inside_unit_interval` (the rational is exactly
/// odd in f32, so that covers the negative half), so a clamp would never change a bit.
#[inline]
#[cfg_attr(feature = "no-panic", no_panic::no_panic)]
pub fn tanh_fast(x: f32) -> f32 {
    // Comparisons, not `f32::max`/`min` (a libcall on Cortex-M4) nor `clamp` (which would
    // propagate NaN). The first keeps `x ≥ −FAST_CLIP` and sends NaN to −FAST_CLIP, the
    // second is then a plain upper clip: the same as `if x > C { C } else if x >= −C { x }
    // else { −C }`, as two conditional moves without a branch.
    let x = if x >= -FAST_CLIP { x } else { -FAST_CLIP };
    let x = if x > FAST_CLIP { FAST_CLIP } else { x };
    rational(x)
}

/// `r(x)` of the module doc, unclipped: Horner in `x²`, one division. The operation order is
/// the one the exporter's f32 model (`trainer::export`) mirrors.
#[inline(always)]
fn rational(x: f32) -> f32 {
    let x2 = x * x;
    let p = x * (135_135.0 + x2 * (17_325.0 + x2 * (378.0 + x2)));
    let q = 135_135.0 + x2 * (62_370.0 + x2 * (3_150.0 + x2 * 28.0));
    // q ≥ 135135 and x is finite, so r is never NaN.
    p / q
}

/// The tanh of this build: [`tanh_libm`], or [`tanh_fast`] with the `fast-tanh` feature.
#[inline]
pub fn tanh(x: f32) -> f32 {
    if cfg!(feature = "fast-tanh") {
        tanh_fast(x)
    } else {
        tanh_libm(x)
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
            for f in [tanh_libm as fn(f32) -> f32, tanh_fast] {
                assert_eq!(f(-x), -f(x));
                assert!(f(x).abs() <= 1.0);
            }
            assert!(err(tanh_libm, x) <= TANH_LIBM_MAX_ABS_ERR);
            assert!(err(tanh_fast, x) <= TANH_FAST_MAX_ABS_ERR);
        }
        assert_eq!(tanh_fast(f32::INFINITY), tanh_fast(FAST_CLIP));
        assert!(tanh_fast(f32::NAN).is_finite());
    }

    /// Why `tanh_fast` needs no output clamp: every f32 of `[0, FAST_CLIP]` gives a rational
    /// in `[0, 1)` (and `r(−x) = −r(x)` exactly). About 10⁹ divisions: a few seconds.
    #[test]
    fn rational_stays_inside_unit_interval() {
        let mut max = 0.0f32;
        for bits in 0..=FAST_CLIP.to_bits() {
            let x = f32::from_bits(bits);
            let r = rational(x);
            assert!((0.0..1.0).contains(&r), "r({x:e}) = {r:e}");
            max = max.max(r);
            if bits % 65_537 == 0 {
                assert_eq!(rational(-x).to_bits(), (-r).to_bits());
            }
        }
        assert!(max < 1.0);
    }

    /// The proof of the two bounds: every non-negative f32 (both functions are odd, which
    /// the grid test and the code's symmetry show; the negative half is checked too on a
    /// stride). Runs in release mode from `.ci/run` (~1 min).
    #[test]
    #[ignore = "exhaustive over 2^31 inputs; run in release by .ci/run"]
    fn exhaustive_error_bounds() {
        let mut max = [0.0f64; 2];
        let mut at = [0.0f32; 2];
        let mut bins = [0.0f64; TANH_FAST_ERR_BINS.len()];
        let mut bin = 0;
        for bits in 0u32..0x7f80_0000 {
            let x = f32::from_bits(bits);
            let t = f64::from(x).tanh();
            for (k, f) in [tanh_libm as fn(f32) -> f32, tanh_fast].iter().enumerate() {
                let e = (f64::from(f(x)) - t).abs();
                if e > max[k] {
                    max[k] = e;
                    at[k] = x;
                }
            }
            while let Some((a, _)) = TANH_FAST_ERR_BINS.get(bin) {
                if x < *a {
                    break;
                }
                bin += 1;
            }
            let e = (f64::from(tanh_fast(x)) - t).abs();
            bins[bin] = bins[bin].max(e);
            if bits % 4099 == 0 {
                assert_eq!(tanh_libm(-x), -tanh_libm(x));
                assert_eq!(tanh_fast(-x), -tanh_fast(x));
            }
        }
        assert_eq!(tanh_libm(f32::INFINITY), 1.0);
        println!("max |tanh_libm − tanh| = {:e} at x = {:e}", max[0], at[0]);
        println!("max |tanh_fast − tanh| = {:e} at x = {:e}", max[1], at[1]);
        for ((a, bound), seen) in TANH_FAST_ERR_BINS.iter().zip(bins) {
            println!("fast tanh, |x| < {a}: max error {seen:e} (bound {bound:e})");
            assert!(seen <= *bound, "|x| < {a}: {seen:e} > {bound:e}");
        }
        assert!(max[0] <= TANH_LIBM_MAX_ABS_ERR, "{}", max[0]);
        assert!(max[1] <= TANH_FAST_MAX_ABS_ERR, "{}", max[1]);
    }
}
