//! The device tanh implementations of `controller-core` ([`Tanh`]): the default accurate
//! tanh (`controller_core::activation::tanh_accurate`: an odd polynomial for |x| < 0.875,
//! else `sign(x)·(1 − 2/(e^{2a} + 1))` with a Cody–Waite `exp`; label `"libm"`, the name of
//! the default tanh in certificates and reports since libm's `tanhf` was it) and the
//! fast tanh (`controller_core::activation::tanh_fast`, feature `fast-tanh`): a (7, 6)
//! rational in a scaled variable on `x` clipped to ±8 by a saturating float-to-integer
//! conversion,
//! ```text
//! y = ((x·2²⁸) as i32) as f32 · FAST_Y,  w = y²,  t = y (a₀ + a₁w + a₂w² + w³) / (b₀ + b₁w + b₂w² + w³),
//! ```
//! with the bounds on |t(ξ) − tanh(ξ)| verified exhaustively in `controller_core::activation`.
//! Both are copies, operation by operation, of the device code (`tests/export_roundtrip.rs`
//! checks them bit for bit).

/// `controller_core::activation`'s constants of `tanh_fast` (same names).
const FAST_FIX: f32 = 268_435_456.0;
const FAST_Y: f32 = 9.679_893e-11;
const FAST_A: [f32; 3] = [9.280_053e-5, 0.016_684_914, 0.435_023_87];
const FAST_B: [f32; 3] = [2.411_385_4e-6, 0.001_623_884_7, 0.107_925_8];

/// `controller_core::activation::TANH_FAST_ERR_BINS` (checked equal in `tests/`).
pub const TANH_FAST_ERR_BINS: [(f64, f64); 10] = [
    (0.5, 3.0e-6),
    (1.0, 2.8e-6),
    (1.5, 3.0e-6),
    (2.0, 3.1e-6),
    (2.5, 3.2e-6),
    (3.0, 2.3e-6),
    (3.5, 3.1e-6),
    (4.0, 2.9e-6),
    (4.5, 2.6e-6),
    (f64::INFINITY, 3.3e-6),
];
use crate::learn::mlp::tanh32::tanh_accurate;

/// The device tanh implementations of `controller-core`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Tanh {
    /// The default build's accurate tanh (`controller_core::activation::tanh_accurate`;
    /// libm's `tanhf` before, hence the name and the label `"libm"`).
    Libm,
    /// The clipped rational (`fast-tanh` feature).
    Fast,
}

impl Tanh {
    /// Both, in the order libm, fast.
    pub const ALL: [Tanh; 2] = [Tanh::Libm, Tanh::Fast];

    /// The f32 function as the device computes it (same code as `controller-core`).
    pub fn eval(self, x: f32) -> f32 {
        match self {
            Tanh::Libm => tanh_accurate(x),
            Tanh::Fast => {
                let y = ((x * FAST_FIX) as i32) as f32 * FAST_Y;
                let [a0, a1, a2] = FAST_A;
                let [b0, b1, b2] = FAST_B;
                let w = y * y;
                let p = y * (a0 + w * (a1 + w * (a2 + w)));
                let q = b0 + w * (b1 + w * (b2 + w));
                p / q
            }
        }
    }

    /// Bound on |t(x) − tanh(x)| over all f32 x (`controller_core::activation`'s constants,
    /// verified exhaustively there).
    pub fn max_abs_err(self) -> f64 {
        match self {
            Tanh::Libm => 1.2e-7,
            Tanh::Fast => 3.3e-6,
        }
    }

    /// Bound on |t(ξ) − tanh(ξ)| for `lo ≤ |ξ| ≤ hi` (the fast tanh's piecewise bound,
    /// `controller_core::activation::TANH_FAST_ERR_BINS`; the accurate one's is uniform).
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
