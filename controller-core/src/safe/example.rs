//! `example`: a hand-written [`Plant`] — the double integrator with a deadbeat terminal
//! controller — for the documentation, the tests and instruction counts.
//!
//! ```text
//! x = (p, v),  ṗ = v, v̇ = u,  h = 0.5 s:   F(x, u) = (p + h v + h²/2 u, v + h u)
//!   (exact; RK4 with one sub-step gives the same map)
//! constraints: |p| ≤ 4, |v| ≤ 2 on x_1 … x_N (g_k(x, u) = max(|p|/4 − 1, |v|/2 − 1) for k ≥ 1;
//!   at k = 0 only "x finite"), |u| ≤ 1 (Π_U: clamp)
//! g_N(x) = xᵀPx/α − 1 (the terminal set, inside the state box)
//! ℓ(x, u) = p² + v² + u²,  V_f(x) = xᵀ P x,  κ_f(x) = K x,  K = (−4, −3)
//! A_K = A + B K is nilpotent (A_K² = 0), P = M + A_Kᵀ M A_K with M = I + KᵀK:
//!   A_Kᵀ P A_K − P = −M   (V_f decreases by at least ℓ(x, κ_f(x)), exactly)
//! P = [[37.25, 17.0625], [17.0625, 11.265625]]   (exact in f32)
//! α = 1.2 < 1/(K P⁻¹ Kᵀ) = 1.2124…: on {xᵀPx ≤ α}, |Kx| ≤ 1 and the state box holds
//!   (16/(P⁻¹)₁₁ = 182.5, 4/(P⁻¹)₂₂ = 13.8), and the set is invariant under κ_f.
//! ```
//! The terminal ingredients here are proven by hand (the equations above); generated
//! plants carry the tier of the trainer's terminal design.

use super::Plant;

/// The double integrator of the module doc (reference state and input 0).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DoubleIntegrator;

impl DoubleIntegrator {
    /// Sampling period h (s).
    pub const H: f32 = 0.5;
    /// Terminal gain K.
    pub const K: [f32; 2] = [-4.0, -3.0];
    /// Terminal weight P.
    pub const P: [[f32; 2]; 2] = [[37.25, 17.0625], [17.0625, 11.265625]];
    /// Terminal level α.
    pub const ALPHA: f32 = 1.2;
    /// State bounds |p| ≤ P_MAX, |v| ≤ V_MAX.
    pub const P_MAX: f32 = 4.0;
    /// Velocity bound.
    pub const V_MAX: f32 = 2.0;
    /// Input bound |u| ≤ U_MAX.
    pub const U_MAX: f32 = 1.0;
}

/// max of two values, NaN if either is (f32::max would drop a NaN).
fn nan_max(a: f32, b: f32) -> f32 {
    if a.is_nan() || b.is_nan() {
        f32::NAN
    } else if a > b {
        a
    } else {
        b
    }
}

impl Plant<2, 1> for DoubleIntegrator {
    fn step(&self, x: &[f32; 2], u: &[f32; 1]) -> [f32; 2] {
        let [p, v] = *x;
        let [u] = *u;
        let h = Self::H;
        [p + h * v + 0.5 * h * h * u, v + h * u]
    }

    fn stage_violation(&self, k: usize, x: &[f32; 2], _u: &[f32; 1]) -> f32 {
        if k == 0 {
            // x_0 is the measured state: no state constraint (the OCP's rule).
            return if x.iter().all(|v| v.is_finite()) {
                -1.0
            } else {
                f32::NAN
            };
        }
        let [p, v] = *x;
        nan_max(p.abs() / Self::P_MAX - 1.0, v.abs() / Self::V_MAX - 1.0)
    }

    fn terminal_violation(&self, x: &[f32; 2]) -> f32 {
        // The terminal set lies inside the state box (module doc): it is the only check.
        self.terminal_cost(x) / Self::ALPHA - 1.0
    }

    fn terminal_input(&self, x: &[f32; 2]) -> [f32; 1] {
        [Self::K[0] * x[0] + Self::K[1] * x[1]]
    }

    fn project_input(&self, u: &[f32; 1]) -> [f32; 1] {
        let [u] = *u;
        [if u.is_nan() {
            0.0
        } else {
            u.clamp(-Self::U_MAX, Self::U_MAX)
        }]
    }

    fn stage_cost(&self, x: &[f32; 2], u: &[f32; 1]) -> f32 {
        x[0] * x[0] + x[1] * x[1] + u[0] * u[0]
    }

    fn terminal_cost(&self, x: &[f32; 2]) -> f32 {
        let [[a, b], [_, d]] = Self::P;
        let [p, v] = *x;
        a * p * p + 2.0 * b * p * v + d * v * v
    }
}
