//! A cart-pole: a pole hinged on a cart driven by a horizontal force.
//!
//! State `x = (p, θ, ṗ, θ̇)`: cart position (m), pole angle from upright (rad), their rates;
//! input `u = F` (N). Frictionless rigid-body equations with the pole's mass spread along
//! its length (half-length `l`):
//!
//! ```text
//! θ̈ = (g sinθ − cosθ · (F + m_p l θ̇² sinθ)/(m_c + m_p)) / (l (4/3 − m_p cos²θ/(m_c + m_p)))
//! p̈ = (F + m_p l (θ̇² sinθ − θ̈ cosθ)) / (m_c + m_p)
//! ```
//!
//! Default parameters (m_c = 1 kg, m_p = 0.1 kg, l = 0.5 m) are the classic benchmark's;
//! with |F| ≤ 20 N (configs/cartpole.toml) the pole can be swung up within a 2 m track.

use super::expr::SystemSpec;
use super::Dynamics;
use num_dual::DualNum;
use serde::{Deserialize, Serialize};

/// Cart-pole parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CartPole {
    /// Cart mass in kg (default 1).
    pub m_cart: f64,
    /// Pole mass in kg (default 0.1).
    pub m_pole: f64,
    /// Pole half-length in m (default 0.5).
    pub l: f64,
    /// Gravity in m/s² (default 9.81).
    pub g: f64,
}

impl Default for CartPole {
    fn default() -> Self {
        CartPole {
            m_cart: 1.0,
            m_pole: 0.1,
            l: 0.5,
            g: 9.81,
        }
    }
}

impl Dynamics for CartPole {
    const NX: usize = 4;
    const NU: usize = 1;
    fn rhs<D: DualNum<Primitive = f64> + Copy>(&self, x: &[D], u: &[D], dx: &mut [D]) {
        let mt = self.m_cart + self.m_pole;
        let (s, c) = (x[1].sin(), x[1].cos());
        let w2 = x[3] * x[3];
        let temp = (u[0] + w2 * s * (self.m_pole * self.l)) * (1.0 / mt);
        let den = (c * c * (-self.m_pole / mt) + 4.0 / 3.0) * self.l;
        let th_dd = (s * self.g - c * temp) / den;
        let p_dd = temp - th_dd * c * (self.m_pole * self.l / mt);
        dx[0] = x[2];
        dx[1] = x[3];
        dx[2] = p_dd;
        dx[3] = th_dd;
    }
}

impl CartPole {
    /// [`Dynamics::rhs`] written as expressions, operation for operation and with its
    /// constant factors precomputed the same way, so that the compiled tape computes `rhs`'s
    /// bits: the form in which [`Discrete`](super::Discrete) differentiates the cart-pole
    /// by sweeps (`expr::Sweep`).
    /// The cart-pole as an expression plant (the same equations, term for term).
    pub fn expressions(&self) -> SystemSpec {
        let mt = self.m_cart + self.m_pole;
        let s = |v: &[&str]| v.iter().map(|t| t.to_string()).collect::<Vec<_>>();
        SystemSpec {
            states: s(&["p", "th", "v", "om"]),
            inputs: s(&["f"]),
            parameters: [
                ("mpl", self.m_pole * self.l),
                ("inv_mt", 1.0 / mt),
                ("neg_mp_mt", -self.m_pole / mt),
                ("four_thirds", 4.0 / 3.0),
                ("l", self.l),
                ("g", self.g),
                ("mpl_mt", self.m_pole * self.l / mt),
            ]
            .into_iter()
            .map(|(k, v)| (k.to_string(), v))
            .collect(),
            definitions: s(&[
                "sn = sin(th)",
                "cs = cos(th)",
                "w2 = om*om",
                "temp = (f + w2*sn*mpl)*inv_mt",
                "den = (cs*cs*neg_mp_mt + four_thirds)*l",
                "th_dd = (sn*g - cs*temp)/den",
                "p_dd = temp - th_dd*cs*mpl_mt",
            ]),
            rhs: Some(s(&["v", "om", "p_dd", "th_dd"])),
            next: None,
            units: Default::default(),
            time_unit: None,
        }
    }
}
