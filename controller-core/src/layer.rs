//! `layer`: one affine layer `y = W x + b` in f32, dimensions in the type.
//!
//! `Dense<I, O>` stores `W` row-major as `[[f32; I]; O]` (output × input) and `b` as
//! `[f32; O]`. The operation order is fixed and is part of the certificate: for each
//! output `o`, `acc = b[o]`, then `acc = acc + W[o][i] * x[i]` for `i = 0, 1, …, I-1`,
//! each product and each sum rounded to f32 separately (Rust never contracts them into
//! a fused multiply-add). The trainer's forward error analysis (`trainer::export`)
//! assumes exactly this order.

/// An affine layer with `I` inputs and `O` outputs: `y = W x + b`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Dense<const I: usize, const O: usize> {
    /// Weights, one row per output (`w[o][i]`).
    pub w: [[f32; I]; O],
    /// Biases, one per output.
    pub b: [f32; O],
}

impl<const I: usize, const O: usize> Dense<I, O> {
    /// A layer from its weight rows and biases.
    ///
    /// ```
    /// use controller_core::layer::Dense;
    /// const L: Dense<2, 1> = Dense::new([[1.0, -2.0]], [0.5]);
    /// assert_eq!(L.apply(&[3.0, 1.0]), [1.5]);
    /// ```
    pub const fn new(w: [[f32; I]; O], b: [f32; O]) -> Self {
        Self { w, b }
    }

    /// `W x + b`, in the documented operation order.
    #[inline]
    #[cfg_attr(feature = "no-panic", no_panic::no_panic)]
    pub fn apply(&self, x: &[f32; I]) -> [f32; O] {
        let mut y = self.b;
        for (acc, row) in y.iter_mut().zip(self.w.iter()) {
            for (w, xi) in row.iter().zip(x.iter()) {
                *acc += *w * *xi;
            }
        }
        y
    }

    /// Number of parameters (`O·I + O`).
    pub const PARAMS: usize = O * I + O;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn apply_matches_hand_computation() {
        let l = Dense::new([[1.0, 2.0], [-1.0, 0.5]], [0.25, -3.0]);
        assert_eq!(l.apply(&[2.0, -1.0]), [0.25, -5.5]);
        assert_eq!(Dense::<2, 2>::PARAMS, 6);
    }

    #[test]
    fn order_is_bias_first_then_inputs_in_order() {
        // 1e8 + 1 − 1e8 in f32 depends on the order: bias first gives (1e8 + 1) = 1e8,
        // then − 1e8 = 0; any other order could give 1.
        let l = Dense::new([[1.0, -1.0]], [1.0e8]);
        assert_eq!(l.apply(&[1.0, 1.0e8]), [0.0]);
    }
}
