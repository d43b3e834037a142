//! The paper's inverted pendulum: ẋ₁ = x₂, ẋ₂ = u/(m l²) − (g/l)·sin(x₁ + π).
//!
//! `x₁ = θ − π` is the angle from the upright position (rad), `x₂` its rate (rad/s),
//! `u` the torque (N·m). The upright pendulum is the origin.

use super::Dynamics;
use num_dual::DualNum;
use serde::{Deserialize, Serialize};

/// Pendulum parameters (defaults: the paper's m = 1 kg, l = 1 m, g = 9.81 m/s²).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Pendulum {
    /// Mass in kg (default 1).
    pub m: f64,
    /// Length in m (default 1).
    pub l: f64,
    /// Gravity in m/s² (default 9.81).
    pub g: f64,
}

impl Default for Pendulum {
    fn default() -> Self {
        Pendulum {
            m: 1.0,
            l: 1.0,
            g: 9.81,
        }
    }
}

impl Dynamics for Pendulum {
    const NX: usize = 2;
    const NU: usize = 1;
    fn rhs<D: DualNum<Primitive = f64> + Copy>(&self, x: &[D], u: &[D], dx: &mut [D]) {
        dx[0] = x[1];
        dx[1] = u[0] * (1.0 / (self.m * self.l * self.l))
            - (x[0] + std::f64::consts::PI).sin() * (self.g / self.l);
    }
}
