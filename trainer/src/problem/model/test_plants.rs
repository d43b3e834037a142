//! Expression plants for tests: a chain of masses between two walls, joined by hardening
//! springs `s(d) = k·d + kc·d³` and damped, with forces on some of the masses:
//! `ṗᵢ = vᵢ`, `m·v̇ᵢ = s(dᵢ₊₁) − s(dᵢ) − c·vᵢ (+ fⱼ)`, `dᵢ = pᵢ − pᵢ₋₁` (walls at 0).

use super::{OdePlant, System};

/// The `[system]` table of a chain of `n` masses (2n states) with forces on the masses
/// `forced` (0-based; one input each, named `f0`, `f1`, …).
pub(crate) fn chain_toml(n: usize, forced: &[usize]) -> String {
    let q = |v: Vec<String>| {
        v.iter()
            .map(|s| format!("\"{s}\""))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let states: Vec<String> = (0..n)
        .map(|i| format!("p{i}"))
        .chain((0..n).map(|i| format!("v{i}")))
        .collect();
    let inputs: Vec<String> = (0..forced.len()).map(|j| format!("f{j}")).collect();
    // Spring i joins mass i-1 (the left wall for i = 0) and mass i (the right wall for i = n).
    let defs: Vec<String> = (0..=n)
        .map(|i| {
            let d = match (i, i == n) {
                (0, _) => "p0".to_string(),
                (_, true) => format!("-p{}", n - 1),
                _ => format!("p{i} - p{}", i - 1),
            };
            format!("s{i} = k*({d}) + kc*({d})^3")
        })
        .collect();
    let rhs: Vec<String> = (0..n)
        .map(|i| format!("v{i}"))
        .chain((0..n).map(|i| {
            let f = forced
                .iter()
                .position(|&m| m == i)
                .map_or(String::new(), |j| format!(" + f{j}"));
            format!("(s{} - s{i} - c*v{i}{f})/m", i + 1)
        }))
        .collect();
    format!(
        "kind = \"ode\"\nstates = [{}]\ninputs = [{}]\nparameters = {{ k = 2.0, kc = 0.5, c = 0.2, m = 1.0 }}\ndefinitions = [{}]\nrhs = [{}]\n",
        q(states),
        q(inputs),
        q(defs),
        q(rhs)
    )
}

/// The chain of 6 masses with forces on masses 0, 2, 3, 5: 12 states, 4 inputs.
pub(crate) fn chain12() -> System {
    let spec: super::expr::SystemSpec =
        toml::from_str(&chain_toml(6, &[0, 2, 3, 5]).replace("kind = \"ode\"\n", ""))
            .unwrap_or_else(|e| panic!("{e}"));
    System::Ode(OdePlant::try_from(spec).unwrap_or_else(|e| panic!("{e}")))
}

/// A plant implemented in Rust for tests of [`CustomPlant`](super::CustomPlant): a damped
/// hardening oscillator driven through a saturating actuator, with a third state low-pass
/// filtering the position (3 states, 2 inputs):
/// `q̇ = v`, `v̇ = −k·q − kc·q³ − c·v + tanh(u₁) + u₂·cos(q)`, `ż = (q − z)/τ`.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub(crate) struct Oscillator {
    pub(crate) k: f64,
    pub(crate) kc: f64,
    pub(crate) c: f64,
    pub(crate) tau: f64,
}

impl Default for Oscillator {
    fn default() -> Self {
        Oscillator {
            k: 1.5,
            kc: 0.4,
            c: 0.2,
            tau: 0.7,
        }
    }
}

impl super::Dynamics for Oscillator {
    const NX: usize = 3;
    const NU: usize = 2;
    fn rhs<D: super::DualNum<Primitive = f64> + Copy>(&self, x: &[D], u: &[D], dx: &mut [D]) {
        let (q, v, z) = (x[0], x[1], x[2]);
        dx[0] = v;
        dx[1] = -(q * self.k) - q.powi(3) * self.kc - v * self.c + u[0].tanh() + u[1] * q.cos();
        dx[2] = (q - z) * (1.0 / self.tau);
    }
}

/// [`Oscillator`] as a custom plant.
pub(crate) fn oscillator() -> System {
    let p = super::CustomPlant::new("oscillator", "1", Oscillator::default())
        .and_then(|p| p.with_names(&["q", "v", "z"], &["drive", "tilt"]))
        .unwrap_or_else(|e| panic!("{e}"));
    System::Custom(p)
}
