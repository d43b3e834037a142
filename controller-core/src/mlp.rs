//! `mlp`: the network κ_NN as a chain of layers whose sizes are checked by the compiler.
//!
//! κ_NN(x) = W_L · tanh(W_{L-1} · … tanh(W_1 x + b_1) … + b_{L-1}) + b_L.
//! `Hidden<I, H, Next>` is one tanh layer `R^I → R^H` followed by `Next: Network<H>`;
//! the last layer is a plain [`Dense`] (linear output). A `Next` whose input size is not
//! `H` does not implement `Network<H>`, so a mismatched chain is a type error
//! (`tests/compile_fail/`). The activation is [`crate::activation::tanh`] (the core's accurate tanh,
//! or the rational approximation with the `fast-tanh` feature).
//!
//! ```
//! use controller_core::layer::Dense;
//! use controller_core::mlp::{Hidden, Network};
//! // 2 → 3 (tanh) → 1
//! const NET: Hidden<2, 3, Dense<3, 1>> = Hidden::new(
//!     Dense::new([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]], [0.0; 3]),
//!     Dense::new([[1.0, 1.0, -1.0]], [0.0]),
//! );
//! assert_eq!(NET.forward(&[0.0, 0.0]), [0.0]);
//! ```

use crate::activation::tanh;
use crate::layer::Dense;

/// Callback of [`Network::for_each_layer`]: `(inputs, outputs, w row-major, b)`.
pub type LayerVisitor<'a> = dyn FnMut(usize, usize, &[f32], &[f32]) + 'a;

/// A network taking `[f32; I]`.
pub trait Network<const I: usize> {
    /// The output array, `[f32; O]`.
    type Output;
    /// Forward pass.
    fn forward(&self, x: &[f32; I]) -> Self::Output;
    /// Visits every layer's parameters, input to output: `(inputs, outputs, w row-major, b)`.
    /// Used to compare two networks parameter by parameter.
    fn for_each_layer(&self, f: &mut LayerVisitor<'_>);
}

impl<const I: usize, const O: usize> Network<I> for Dense<I, O> {
    type Output = [f32; O];
    #[inline]
    fn forward(&self, x: &[f32; I]) -> [f32; O] {
        self.apply(x)
    }
    fn for_each_layer(&self, f: &mut LayerVisitor<'_>) {
        f(I, O, self.w.as_flattened(), &self.b);
    }
}

/// A tanh layer `R^I → R^H` followed by the rest of the network.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hidden<const I: usize, const H: usize, N: Network<H>> {
    /// The affine part of this layer.
    pub layer: Dense<I, H>,
    /// The layers after the activation.
    pub next: N,
}

impl<const I: usize, const H: usize, N: Network<H>> Hidden<I, H, N> {
    /// `next ∘ tanh ∘ layer`.
    ///
    /// ```
    /// use controller_core::layer::Dense;
    /// use controller_core::mlp::Hidden;
    /// let net = Hidden::new(Dense::<1, 2>::new([[1.0], [2.0]], [0.0; 2]), Dense::<2, 1>::new([[1.0, 1.0]], [0.0]));
    /// assert_eq!(net.layer.b, [0.0, 0.0]);
    /// ```
    pub const fn new(layer: Dense<I, H>, next: N) -> Self {
        Self { layer, next }
    }
}

impl<const I: usize, const H: usize, N: Network<H>> Network<I> for Hidden<I, H, N> {
    type Output = N::Output;
    #[inline]
    fn forward(&self, x: &[f32; I]) -> N::Output {
        let mut h = self.layer.apply(x);
        for v in h.iter_mut() {
            *v = tanh(*v);
        }
        self.next.forward(&h)
    }
    fn for_each_layer(&self, f: &mut LayerVisitor<'_>) {
        self.layer.for_each_layer(f);
        self.next.for_each_layer(f);
    }
}

/// A reference to a network is the network (so a controller can hold `&'static Net`: the
/// weights stay in flash instead of being copied with the controller).
impl<const I: usize, N: Network<I> + ?Sized> Network<I> for &N {
    type Output = N::Output;
    #[inline]
    fn forward(&self, x: &[f32; I]) -> N::Output {
        (**self).forward(x)
    }
    fn for_each_layer(&self, f: &mut LayerVisitor<'_>) {
        (**self).for_each_layer(f);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn forward_applies_tanh_between_layers_only() {
        let net = Hidden::new(
            Dense::<1, 1>::new([[1.0]], [0.0]),
            Dense::<1, 1>::new([[2.0]], [1.0]),
        );
        assert_eq!(net.forward(&[0.5]), [2.0 * tanh(0.5) + 1.0]);
    }

    #[test]
    fn a_reference_to_a_network_computes_the_same() {
        let net = Hidden::new(
            Dense::<1, 2>::new([[1.5], [-0.25]], [0.1, 0.0]),
            Dense::<2, 1>::new([[2.0, 3.0]], [1.0]),
        );
        let r: &Hidden<1, 2, Dense<2, 1>> = &net;
        for x in [-2.0f32, 0.0, 0.3, 7.0] {
            assert_eq!(Network::forward(&r, &[x]), net.forward(&[x]));
        }
        let mut n = 0;
        Network::for_each_layer(&r, &mut |_, _, _, _| n += 1);
        assert_eq!(n, 2);
    }

    #[test]
    fn for_each_layer_visits_in_order() {
        let net = Hidden::new(
            Dense::<2, 3>::new([[0.0; 2]; 3], [0.0; 3]),
            Dense::<3, 1>::new([[0.0; 3]], [0.0]),
        );
        let mut dims = [(0, 0); 2];
        let mut k = 0;
        net.for_each_layer(&mut |i, o, w, b| {
            assert_eq!((w.len(), b.len()), (i * o, o));
            if let Some(d) = dims.get_mut(k) {
                *d = (i, o);
            }
            k += 1;
        });
        assert_eq!((k, dims), (2, [(2, 3), (3, 1)]));
    }
}
