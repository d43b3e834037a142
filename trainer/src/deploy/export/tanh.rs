//! The device tanh implementations of `controller-core` ([`Tanh`]): libm's `tanhf` and
//! the clamped rational
//! ```text
//! t(x) = x (135135 + 17325 x² + 378 x⁴ + x⁶) / (135135 + 62370 x² + 3150 x⁴ + 28 x⁶),  |x| ≤ 4.97
//! ```
//! with the bounds on |t(ξ) − tanh(ξ)| verified exhaustively in `controller_core::activation`.

/// `FAST_CLIP` of `controller_core::activation`.
const FAST_CLIP: f32 = 4.97;

/// `controller_core::activation::TANH_FAST_ERR_BINS` (checked equal in `tests/`).
pub const TANH_FAST_ERR_BINS: [(f64, f64); 10] = [
    (0.5, 4.0e-7),
    (1.0, 4.0e-7),
    (1.5, 4.0e-7),
    (2.0, 4.0e-7),
    (2.5, 5.0e-7),
    (3.0, 1.2e-6),
    (3.5, 4.6e-6),
    (4.0, 1.52e-5),
    (4.5, 4.25e-5),
    (f64::INFINITY, 1.0e-4),
];
/// The device tanh implementations of `controller-core`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Tanh {
    /// libm's `tanhf` (default build).
    Libm,
    /// The clamped rational (`fast-tanh` feature).
    Fast,
}

impl Tanh {
    /// Both, in the order libm, fast.
    pub const ALL: [Tanh; 2] = [Tanh::Libm, Tanh::Fast];

    /// The f32 function as the device computes it (same code as `controller-core`).
    pub fn eval(self, x: f32) -> f32 {
        match self {
            Tanh::Libm => libm::tanhf(x),
            Tanh::Fast => {
                let x = if x > FAST_CLIP {
                    FAST_CLIP
                } else if x >= -FAST_CLIP {
                    x
                } else {
                    -FAST_CLIP
                };
                let x2 = x * x;
                let p = x * (135_135.0 + x2 * (17_325.0 + x2 * (378.0 + x2)));
                let q = 135_135.0 + x2 * (62_370.0 + x2 * (3_150.0 + x2 * 28.0));
                // q ≥ 135135 and x is finite, so r is never NaN.
                (p / q).clamp(-1.0, 1.0)
            }
        }
    }

    /// Bound on |t(x) − tanh(x)| over all f32 x (`controller_core::activation`'s constants,
    /// verified exhaustively there).
    pub fn max_abs_err(self) -> f64 {
        match self {
            Tanh::Libm => 1.2e-7,
            Tanh::Fast => 1.0e-4,
        }
    }

    /// Bound on |t(ξ) − tanh(ξ)| for `lo ≤ |ξ| ≤ hi` (the fast tanh's piecewise bound,
    /// `controller_core::activation::TANH_FAST_ERR_BINS`; libm's is uniform).
    pub fn max_abs_err_on(self, lo: f64, hi: f64) -> f64 {
        match self {
            Tanh::Libm => self.max_abs_err(),
            Tanh::Fast => {
                let mut prev = 0.0;
                let mut worst = 0.0f64;
                for (a, d) in TANH_FAST_ERR_BINS {
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
