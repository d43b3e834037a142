//! Model-mismatch scenarios: the plant with one physical parameter scaled,
//! `p ↦ factor · p`, for the closed-loop study's robustness runs.

use super::{ExprPlant, System};

impl System {
    /// The plant with its mass scaled by `factor` (model mismatch in closed-loop studies):
    /// the pendulum's `m`, the cart-pole's `m_pole`, the double integrator's `mass`; for an
    /// expression or custom plant the parameter `mass`, else the parameter `m`. `None` when
    /// such a plant has neither parameter (or the scaled one does not compile or rebuild):
    /// it has no mass the study could perturb, and no mismatch runs are made for it.
    pub fn with_mass_scaled(&self, factor: f64) -> Option<System> {
        fn scaled<const D: bool>(p: &ExprPlant<D>, factor: f64) -> Option<ExprPlant<D>> {
            let params = &p.spec().parameters;
            let name = ["mass", "m"]
                .into_iter()
                .find(|n| params.contains_key(*n))?;
            p.with_parameter(name, params[name] * factor).ok()
        }
        let mut sys = self.clone();
        match &mut sys {
            System::Pendulum(p) => p.m *= factor,
            System::CartPole(p) => p.m_pole *= factor,
            System::DoubleIntegrator(p) => p.mass *= factor,
            System::Ode(p) => *p = scaled(p, factor)?,
            System::Discrete(p) => *p = scaled(p, factor)?,
            System::Custom(p) => *p = p.with_mass_scaled(factor)?,
        }
        Some(sys)
    }
    /// The names of the parameters [`with_parameter_scaled`](Self::with_parameter_scaled)
    /// can perturb: a built-in's fields, an expression plant's `parameters`, a custom
    /// plant's numeric parameters.
    pub fn parameter_names(&self) -> Vec<String> {
        let s = |v: &[&str]| v.iter().map(|t| t.to_string()).collect();
        match self {
            System::Pendulum(_) => s(&["m", "l", "g"]),
            System::CartPole(_) => s(&["m_cart", "m_pole", "l", "g"]),
            System::DoubleIntegrator(_) => s(&["mass"]),
            System::Ode(p) => p.spec().parameters.keys().cloned().collect(),
            System::Discrete(p) => p.spec().parameters.keys().cloned().collect(),
            System::Custom(p) => p.numeric_parameter_names(),
        }
    }
    /// The plant with its parameter `name` scaled by `factor` (a model-mismatch scenario);
    /// `None` when the plant has no such parameter or the scaled plant does not rebuild.
    pub fn with_parameter_scaled(&self, name: &str, factor: f64) -> Option<System> {
        fn scaled<const D: bool>(p: &ExprPlant<D>, name: &str, f: f64) -> Option<ExprPlant<D>> {
            let v = *p.spec().parameters.get(name)?;
            p.with_parameter(name, v * f).ok()
        }
        let mut sys = self.clone();
        match (&mut sys, name) {
            (System::Pendulum(p), "m") => p.m *= factor,
            (System::Pendulum(p), "l") => p.l *= factor,
            (System::Pendulum(p), "g") => p.g *= factor,
            (System::CartPole(p), "m_cart") => p.m_cart *= factor,
            (System::CartPole(p), "m_pole") => p.m_pole *= factor,
            (System::CartPole(p), "l") => p.l *= factor,
            (System::CartPole(p), "g") => p.g *= factor,
            (System::DoubleIntegrator(p), "mass") => p.mass *= factor,
            (System::Ode(p), _) => *p = scaled(p, name, factor)?,
            (System::Discrete(p), _) => *p = scaled(p, name, factor)?,
            (System::Custom(p), _) => *p = p.with_parameter_scaled(name, factor)?,
            _ => return None,
        }
        Some(sys)
    }
}
