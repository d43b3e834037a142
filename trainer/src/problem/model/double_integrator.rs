//! A linear double integrator: ẋ₁ = x₂, ẋ₂ = u / mass (position, velocity, force).
//!
//! RK4 is exact for this system (A² = 0), so the discrete model is the exact
//! zero-order-hold discretisation and the MPC is a convex QP: a useful exact check.

use super::Dynamics;
use num_dual::DualNum;
use serde::{Deserialize, Serialize};

/// Double-integrator parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DoubleIntegrator {
    /// Mass in kg (default 1).
    pub mass: f64,
}

impl Default for DoubleIntegrator {
    fn default() -> Self {
        DoubleIntegrator { mass: 1.0 }
    }
}

impl Dynamics for DoubleIntegrator {
    const NX: usize = 2;
    const NU: usize = 1;
    fn rhs<D: DualNum<Primitive = f64> + Copy>(&self, x: &[D], u: &[D], dx: &mut [D]) {
        dx[0] = x[1];
        dx[1] = u[0] * (1.0 / self.mass);
    }
}
