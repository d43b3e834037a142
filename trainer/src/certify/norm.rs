//! [`Norm`]: the scaled norm every bound of a certificate is stated in — a change of
//! variables
//!
//! ```text
//! z = S_x⁻¹ x,   v = S_u⁻¹ u,   S_x = diag(x_scale), S_u = diag(u_scale)
//! ε  bounds  ‖S_u⁻¹(κ(x) − κ_NN(x))‖₂,   states measured as ‖S_x⁻¹ Δx‖₂
//! κ̃_NN(z) = S_u⁻¹ κ_NN(S_x z)      (first layer W₁·S_x, last layer's rows ⊘ s_u)
//! per input, physical units:  |κ_j − κ_NN,j| ≤ s_u,j · ε        (|v_j| ≤ ‖v‖₂)
//! ```
//!
//! Theorem 1 in these variables is Theorem 1 of the scaled problem: ε_D, L_MPC, L_NN and
//! the covering radius are those of the scaled labels, the scaled net and the scaled points
//! over the scaled box S_x⁻¹X. The Lipschitz bounds (product of norms, LipSDP-Neuron, slope
//! vertices) bound sup ‖∂κ̃_NN/∂z‖₂ of whatever weights they are given for any activation
//! slope-restricted in [0, 1], so each covers the scaled net; the scaled net is built by
//! dividing the model's input and output normalisation by the scales
//! ([`Norm::scale_mlp`]), so its folded first and last layers are W₁ ⊘ (h_x ⊘ s_x) and
//! (h_u ⊘ s_u) ∘ W_L — computed in f64 like the unscaled folding (which is not rounded
//! outward either; the Lipschitz bounds treat the folded f64 weights as exact, as today).
//! The per-input bound is rounded up ([`Norm::per_input`]). With all scales 1 every
//! division is exact, so every number is the unscaled one bit for bit.

use crate::learn::mlp::Mlp;
use crate::learn::train::TrainSet;
use serde::{Deserialize, Serialize};
use std::borrow::Cow;

/// The scales of a certificate's norm (`"norm"` in `certificate.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Norm {
    /// S_x: one entry > 0 per state.
    pub x_scale: Vec<f64>,
    /// S_u: one entry > 0 per input.
    pub u_scale: Vec<f64>,
}

impl Norm {
    /// The unscaled norm (all scales 1): what certificates without `"norm"` were computed in.
    pub fn unscaled(nx: usize, nu: usize) -> Self {
        Norm {
            x_scale: vec![1.0; nx],
            u_scale: vec![1.0; nu],
        }
    }

    /// The norm of a problem: `[ocp] x_scale` and `u_scale`, by default the half-widths of
    /// the domain X and of U.
    pub fn of_problem(cfg: &crate::problem::ProblemConfig) -> Self {
        Norm {
            x_scale: cfg.ocp.x_scale_or_default(&cfg.domain.lo, &cfg.domain.hi),
            u_scale: cfg.ocp.u_scale_or_default(),
        }
    }

    /// Whether every scale is 1 (then every scaled quantity is the unscaled one).
    pub fn is_unit(&self) -> bool {
        self.x_scale.iter().chain(&self.u_scale).all(|s| *s == 1.0)
    }

    /// The scaled net κ̃_NN(z) = S_u⁻¹ κ_NN(S_x z) (module doc): the normalisation divided
    /// by the scales. Borrowed unchanged for the unit norm.
    pub fn scale_mlp<'a>(&self, mlp: &'a Mlp) -> Cow<'a, Mlp> {
        if self.is_unit() {
            return Cow::Borrowed(mlp);
        }
        let mut m = mlp.clone();
        for (v, s) in [
            (&mut m.in_center, &self.x_scale),
            (&mut m.in_half, &self.x_scale),
            (&mut m.out_center, &self.u_scale),
            (&mut m.out_half, &self.u_scale),
        ] {
            v.iter_mut().zip(s).for_each(|(a, s)| *a /= s);
        }
        Cow::Owned(m)
    }

    /// The labelled points in scaled variables: z_i = S_x⁻¹x_i, v_i = S_u⁻¹κ(x_i),
    /// ∂v/∂z = S_u⁻¹ (∂κ/∂x) S_x. Borrowed unchanged for the unit norm.
    pub fn scale_set<'a>(&self, set: &'a TrainSet) -> Cow<'a, TrainSet> {
        if self.is_unit() {
            return Cow::Borrowed(set);
        }
        let (nx, nu) = (set.nx, set.nu);
        let mut s = set.clone();
        for (k, x) in s.x.iter_mut().enumerate() {
            *x /= self.x_scale[k % nx];
        }
        for (k, u) in s.u.iter_mut().enumerate() {
            *u /= self.u_scale[k % nu];
        }
        for (k, d) in s.du.iter_mut().enumerate() {
            let (r, c) = ((k / nx) % nu, k % nx);
            *d = *d * self.x_scale[c] / self.u_scale[r];
        }
        Cow::Owned(s)
    }

    /// The box S_x⁻¹[lo, hi].
    pub fn scale_box(&self, lo: &[f64], hi: &[f64]) -> (Vec<f64>, Vec<f64>) {
        let f =
            |v: &[f64]| -> Vec<f64> { v.iter().zip(&self.x_scale).map(|(a, s)| a / s).collect() };
        (f(lo), f(hi))
    }

    /// A state difference in scaled units, ‖S_x⁻¹ Δx‖₂.
    pub fn state_distance(&self, a: &[f64], b: &[f64]) -> f64 {
        a.iter()
            .zip(b)
            .zip(&self.x_scale)
            .map(|((a, b), s)| ((a - b) / s).powi(2))
            .sum::<f64>()
            .sqrt()
    }

    /// An input difference in scaled units, ‖S_u⁻¹ Δu‖₂.
    pub fn input_norm(&self, d: &[f64]) -> f64 {
        if self.is_unit() {
            return d.iter().map(|e| e * e).sum::<f64>().sqrt();
        }
        d.iter()
            .zip(&self.u_scale)
            .map(|(e, s)| (e / s).powi(2))
            .sum::<f64>()
            .sqrt()
    }

    /// The physical per-input bounds of a scaled ε: s_u,j·ε, rounded up (exactly ε where
    /// s_u,j = 1). Sound because |v_j| ≤ ‖v‖₂ (and ≤ ‖v‖_∞).
    pub fn per_input(&self, eps: f64) -> Vec<f64> {
        self.u_scale.iter().map(|s| mul_up(*s, eps)).collect()
    }
}

/// s·ε rounded up: the f64 product plus one relative rounding (exact for s = 1).
pub fn mul_up(s: f64, eps: f64) -> f64 {
    if s == 1.0 {
        return eps;
    }
    let p = s * eps;
    p + p.abs() * f64::EPSILON
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learn::mlp::Activation;

    /// A random tanh net 2 → 6 → 5 → 2 with a normalisation of mixed magnitudes.
    fn net(seed: u64) -> Mlp {
        Mlp::new(
            &[2, 6, 5, 2],
            Activation::Tanh,
            seed,
            &[0.0, 330.0],
            &[1.0, 370.0],
            &[280.0, -0.1],
            &[320.0, 0.1],
        )
    }

    /// The scaled net is S_u⁻¹ κ_NN(S_x z), and every sound Lipschitz bound of it is at
    /// least the largest scaled slope ‖S_u⁻¹ Δκ_NN‖₂ / ‖S_x⁻¹ Δx‖₂ sampled between random
    /// nearby pairs of states (an upper bound never below a sampled value). The unscaled
    /// bound does not cover the scaled slope here (the test fails if the scaling is skipped).
    #[test]
    fn scaled_lipschitz_bounds_cover_sampled_scaled_slopes() {
        use crate::certify::lipschitz::{lipsdp_bound, naive_bound, vertex_bound};
        // Scales that stretch the net's slopes (scaled slope ≫ unscaled Lipschitz bound).
        let norm = Norm {
            x_scale: vec![5.0, 200.0],
            u_scale: vec![2.0, 0.01],
        };
        for seed in 1..4u64 {
            let m = net(seed);
            let s = norm.scale_mlp(&m);
            let x = [0.3, 345.0];
            let z = [x[0] / norm.x_scale[0], x[1] / norm.x_scale[1]];
            let (u, v) = (m.predict(&x), s.predict(&z));
            for j in 0..2 {
                assert!((v[j] - u[j] / norm.u_scale[j]).abs() < 1e-9 * (1.0 + v[j].abs()));
            }
            let bounds = [
                naive_bound(&s),
                lipsdp_bound(&s),
                vertex_bound(&s, 22).unwrap(),
            ];
            let mut slope = 0.0f64;
            for k in 0..4000u64 {
                let a: Vec<f64> = (0..2)
                    .map(|i| {
                        m.in_center[i]
                            + m.in_half[i] * (2.0 * crate::rng::uniform(seed, k, i as u64) - 1.0)
                    })
                    .collect();
                let b: Vec<f64> = (0..2)
                    .map(|i| {
                        a[i] + 1e-4
                            * norm.x_scale[i]
                            * (crate::rng::uniform(seed + 9, k, i as u64) - 0.5)
                    })
                    .collect();
                let (ua, ub) = (m.predict(&a), m.predict(&b));
                let du: Vec<f64> = ua.iter().zip(&ub).map(|(p, q)| p - q).collect();
                let q = norm.input_norm(&du) / norm.state_distance(&a, &b);
                slope = slope.max(q);
            }
            for l in bounds {
                assert!(
                    l >= slope,
                    "bound {l} below the sampled scaled slope {slope}"
                );
            }
            assert!(
                naive_bound(&m) < slope,
                "the test must tell scaled from unscaled bounds"
            );
        }
    }

    #[test]
    fn the_unit_norm_changes_nothing_and_per_input_rounds_up() {
        let m = net(1);
        let n = Norm::unscaled(2, 2);
        assert!(matches!(n.scale_mlp(&m), Cow::Borrowed(_)));
        assert_eq!(n.per_input(0.3), vec![0.3, 0.3]);
        let s = Norm {
            x_scale: vec![1.0, 1.0],
            u_scale: vec![3.0, 0.1],
        };
        let p = s.per_input(0.7);
        assert!(p[0] >= 2.1 && p[1] >= 0.07);
        assert!(p[0] <= 2.1 * (1.0 + 1e-15));
    }
}
