//! The device tanh implementations of `controller-core` ([`Tanh`]): which one a certificate
//! or a clamp band is for, its f32 function and its error bound — all taken from
//! `controller_core::activation`, the one copy of the device arithmetic.
//!
//! - [`Tanh::Libm`]: the default accurate tanh (`controller_core::activation::tanh_accurate`:
//!   an odd polynomial for |x| < 0.875, else `sign(x)·(1 − 2/(e^{2a} + 1))` with a
//!   Cody–Waite `exp`), max error 1.2·10⁻⁷ over every f32. Its label in certificates,
//!   generated files and reports is `"libm"` (a file-format name).
//! - [`Tanh::Fast`]: the `fast-tanh` feature's (7, 6) rational on `x` clipped to ±8
//!   (`controller_core::activation::tanh_fast`), max error 3.3·10⁻⁶, with the piecewise bound
//!   `controller_core::activation::TANH_FAST_ERR_BINS` over |x|.
//!
//! Both functions exist in every build of `controller-core` (the feature only picks which one
//! `activation::tanh` calls), so the exporter evaluates both whatever features are unified.

use controller_core::activation::{
    tanh_accurate, tanh_fast, TANH_ACCURATE_MAX_ABS_ERR, TANH_FAST_ERR_BINS, TANH_FAST_MAX_ABS_ERR,
};

/// The device tanh implementations of `controller-core`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Tanh {
    /// The default build's accurate tanh (`controller_core::activation::tanh_accurate`;
    /// label `"libm"`).
    Libm,
    /// The clipped rational (`fast-tanh` feature, `controller_core::activation::tanh_fast`).
    Fast,
}

impl Tanh {
    /// Both, in the order libm, fast.
    pub const ALL: [Tanh; 2] = [Tanh::Libm, Tanh::Fast];

    /// The f32 function the device computes (`controller_core::activation`'s own code).
    pub fn eval(self, x: f32) -> f32 {
        match self {
            Tanh::Libm => tanh_accurate(x),
            Tanh::Fast => tanh_fast(x),
        }
    }

    /// Bound on |t(x) − tanh(x)| over all f32 x (`controller_core::activation`'s constants,
    /// verified exhaustively there).
    pub fn max_abs_err(self) -> f64 {
        match self {
            Tanh::Libm => TANH_ACCURATE_MAX_ABS_ERR,
            Tanh::Fast => TANH_FAST_MAX_ABS_ERR,
        }
    }

    /// Bound on |t(ξ) − tanh(ξ)| for `lo ≤ |ξ| ≤ hi`: the largest bin of
    /// `controller_core::activation::TANH_FAST_ERR_BINS` that meets `[lo, hi]` for the fast
    /// tanh; the accurate one's bound is uniform.
    pub fn max_abs_err_on(self, lo: f64, hi: f64) -> f64 {
        match self {
            Tanh::Libm => self.max_abs_err(),
            Tanh::Fast => {
                let mut prev = 0.0;
                let mut worst = 0.0f64;
                for (a, d) in TANH_FAST_ERR_BINS {
                    let a = f64::from(a);
                    if hi >= prev && lo < a {
                        worst = worst.max(d);
                    }
                    prev = a;
                }
                worst
            }
        }
    }

    /// `"libm"` or `"fast"`.
    pub fn name(self) -> &'static str {
        match self {
            Tanh::Libm => "libm",
            Tanh::Fast => "fast",
        }
    }
}
