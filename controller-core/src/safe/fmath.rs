//! `fmath`: sin and cos in f32 arithmetic only, for the generated plants of the online check
//! (`trainer`'s `deploy::plant_rs`). `libm`'s `sinf`/`cosf` reduce the argument in f64,
//! which a Cortex-M4's single-precision FPU runs in software (about 1,000 instructions per
//! call); these take a few dozen.
//!
//! ```text
//! j = ⌊|x|·4/π⌋ rounded up to even,  r = ((|x| − j·DP1) − j·DP2) − j·DP3   (|r| ≤ π/4,
//!     DP1 + DP2 + DP3 = π/4 in three parts, exact products for j < 2^13)
//! sin r ≈ r + r³(s₀ + r²(s₁ + r²s₂)),   cos r ≈ 1 − r²/2 + r⁴(c₀ + r²(c₁ + r²c₂))
//! ```
//! and the octant j mod 8 picks the polynomial and the sign (Cephes `sinf`/`cosf`,
//! S. L. Moshier). Valid for |x| ≤ [`MAX_ARG`]; beyond it, and for a non-finite x, the result
//! is NaN (which the online check treats as infeasible). The error against the exact sin/cos
//! is measured by this module's tests (a few 1e-8 for |x| ≤ 100), not proven; the online
//! check's margin is measured on the generated code that calls these functions.

/// The largest |x| accepted (larger arguments give NaN).
pub const MAX_ARG: f32 = 8192.0;

const FOPI: f32 = 1.273_239_5; // 4/π
const DP1: f32 = 0.785_156_25;
const DP2: f32 = 2.418_756_5e-4;
const DP3: f32 = 3.774_895e-8;

/// The reduced argument r and the octant j (module doc); None outside the valid range.
#[inline]
fn reduce(x: f32) -> Option<(f32, u32)> {
    let a = if x < 0.0 { -x } else { x };
    if a.is_nan() || a > MAX_ARG {
        return None;
    }
    let mut j = (a * FOPI) as u32;
    let mut y = j as f32;
    if j & 1 == 1 {
        j += 1;
        y += 1.0;
    }
    Some((((a - y * DP1) - y * DP2) - y * DP3, j & 7))
}

#[inline]
fn sin_poly(r: f32) -> f32 {
    let z = r * r;
    ((-1.951_529_6e-4 * z + 8.332_161e-3) * z - 1.666_665_5e-1) * z * r + r
}

#[inline]
fn cos_poly(r: f32) -> f32 {
    let z = r * r;
    ((2.443_315_7e-5 * z - 1.388_731_6e-3) * z + 4.166_664_6e-2) * z * z - 0.5 * z + 1.0
}

/// sin x in f32 (module doc); NaN for |x| > [`MAX_ARG`] or a non-finite x.
#[inline]
pub fn sin(x: f32) -> f32 {
    let Some((r, mut j)) = reduce(x) else {
        return f32::NAN;
    };
    let mut neg = x < 0.0;
    if j > 3 {
        neg = !neg;
        j -= 4;
    }
    let y = if j == 1 || j == 2 {
        cos_poly(r)
    } else {
        sin_poly(r)
    };
    if neg {
        -y
    } else {
        y
    }
}

/// cos x in f32 (module doc); NaN for |x| > [`MAX_ARG`] or a non-finite x.
#[inline]
pub fn cos(x: f32) -> f32 {
    let Some((r, mut j)) = reduce(x) else {
        return f32::NAN;
    };
    let mut neg = false;
    if j > 3 {
        neg = !neg;
        j -= 4;
    }
    if j > 1 {
        neg = !neg;
    }
    let y = if j == 1 || j == 2 {
        sin_poly(r)
    } else {
        cos_poly(r)
    };
    if neg {
        -y
    } else {
        y
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Largest |sin − sin64|, |cos − cos64| over n points of [−w, w].
    fn worst(w: f64, n: usize) -> (f64, f64) {
        let (mut es, mut ec) = (0.0f64, 0.0f64);
        for i in 0..=n {
            let x = (-w + 2.0 * w * i as f64 / n as f64) as f32;
            let xd = f64::from(x);
            es = es.max((f64::from(sin(x)) - xd.sin()).abs());
            ec = ec.max((f64::from(cos(x)) - xd.cos()).abs());
        }
        (es, ec)
    }

    #[test]
    fn close_to_the_exact_functions() {
        let (s, c) = worst(4.0, 1_000_000);
        assert!(s < 1.2e-7 && c < 1.2e-7, "|x| ≤ 4: {s:e} {c:e}");
        let (s, c) = worst(100.0, 1_000_000);
        assert!(s < 2e-7 && c < 2e-7, "|x| ≤ 100: {s:e} {c:e}");
        let (s, c) = worst(8192.0, 1_000_000);
        assert!(s < 1e-5 && c < 1e-5, "|x| ≤ 8192: {s:e} {c:e}");
    }

    #[test]
    fn exact_at_zero_odd_even_and_nan_outside() {
        assert_eq!(sin(0.0), 0.0);
        assert_eq!(cos(0.0), 1.0);
        for x in [0.3f32, 1.7, 2.9, 5.5, 100.25] {
            assert_eq!(sin(-x), -sin(x));
            assert_eq!(cos(-x), cos(x));
        }
        for x in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 8192.5, -1e30] {
            assert!(sin(x).is_nan() && cos(x).is_nan(), "{x}");
        }
    }
}
