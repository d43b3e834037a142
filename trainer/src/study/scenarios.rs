//! The closed-loop study of a run (`closed_loop.json`): the MPC and both nets from every
//! initial state x₀ (nominal plant), then noise and model-mismatch runs from the first:
//! x_{t+1} = F(x_t, κ(x_t + n_t)) with one of F's parameters scaled by 1 ± its relative
//! change (`closed_loop.mismatch`, else the paper's mass ± `mass_mismatch` for a plant
//! with a mass; [`ClosedLoopSettings::mismatch_scenarios`](crate::problem::ClosedLoopSettings::mismatch_scenarios)).

use crate::certify::certificate::Certificate;
use crate::certify::Model;
use crate::data::sampling::Sampler;
use crate::mpc::law::MpcLaw;
use crate::problem::{ProblemConfig, SamplerKind, SamplingSettings};
use crate::study::closed_loop::{simulate, Controller, Run, SimSettings};
use rayon::prelude::*;
use std::collections::BTreeMap;

/// Closed-loop results keyed by controller name.
pub type ClosedLoop = BTreeMap<String, Vec<Run>>;

/// The whole of `closed_loop.json`: the runs keyed by controller name, and the safety study
/// (`[closed_loop] safety = true`) under the key `safety` when it ran. A file without it is
/// exactly the map of runs (files written before the safety study read unchanged, and the
/// study's absence writes them byte for byte as before).
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ClosedLoopFile {
    /// The safety study (`study::safety`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub safety: Option<crate::study::safety::SafetyStudy>,
    /// The runs keyed by controller name.
    #[serde(flatten)]
    pub runs: ClosedLoop,
}

/// Initial states of the closed-loop study: `closed_loop.x0` (default: the paper's
/// (−π, 0) for the pendulum, a quarter of the way from the domain's centre to its lower
/// corner otherwise), then `closed_loop.random_initial_states` seeded random states of X.
pub fn initial_states(cfg: &ProblemConfig) -> Vec<Vec<f64>> {
    let first = cfg
        .closed_loop
        .x0
        .clone()
        .unwrap_or_else(|| match cfg.system {
            crate::problem::model::System::Pendulum(_) => vec![-std::f64::consts::PI, 0.0],
            _ => cfg
                .domain
                .lo
                .iter()
                .zip(&cfg.domain.hi)
                .map(|(l, h)| 0.5 * (l + h) + 0.25 * (l - h))
                .collect(),
        });
    let s = SamplingSettings {
        sampler: SamplerKind::Random,
        n: cfg.closed_loop.random_initial_states,
        seed: 4242,
        counts: vec![],
    };
    let mut v = vec![first];
    if s.n > 0 {
        v.extend(Sampler::new(&s, &cfg.domain).points());
    }
    v
}

/// The closed-loop study: MPC and both nets from every initial state (nominal plant, no
/// noise), then robustness runs from the first state: uniform measurement noise
/// (`noise_fraction` of the domain's half-width, `noise_runs` seeds) and each mismatch
/// scenario with both signs. Keys: `mpc`, `nominal`, `regularized`, and `<name>_noise`,
/// `<name>_<tag>+`, `<name>_<tag>-` (tag `mass` for the mass scenario, else the parameter).
pub fn closed_loop(cfg: &ProblemConfig, nominal: &Model, regularized: &Model) -> ClosedLoop {
    let st = &cfg.closed_loop;
    let base = SimSettings {
        steps: st.steps,
        noise: vec![],
        seed: 0,
        mass_mismatch: 0.0,
        mismatch_parameter: None,
        disturbance: Default::default(),
    };
    let x0s = initial_states(cfg);
    let eps = |m: &Model| {
        m.certificate
            .as_ref()
            // The band's half-width in physical units: the largest per-input bound (ε
            // itself for the unscaled norm).
            .map_or(f64::INFINITY, |c: &Certificate| {
                c.eps_per_input().into_iter().fold(0.0, f64::max)
            })
    };
    let nets: [(&str, Option<&Model>); 3] = [
        ("mpc", None),
        ("nominal", Some(nominal)),
        ("regularized", Some(regularized)),
    ];
    let noise: Vec<f64> = cfg
        .domain
        .lo
        .iter()
        .zip(&cfg.domain.hi)
        .map(|(l, h)| st.noise_fraction * 0.5 * (h - l))
        .collect();
    let mut jobs: Vec<(String, Option<&Model>, Vec<f64>, SimSettings)> = Vec::new();
    for (name, m) in nets {
        for x0 in &x0s {
            jobs.push((name.to_string(), m, x0.clone(), base.clone()));
        }
        for seed in 0..st.noise_runs as u64 {
            let s = SimSettings {
                noise: noise.clone(),
                seed,
                ..base.clone()
            };
            jobs.push((format!("{name}_noise"), m, x0s[0].clone(), s));
        }
        // An expression plant without a parameter `mass` or `m` has no mass to perturb.
        let has_mass = cfg.system.with_mass_scaled(1.0).is_some();
        for sc in st.mismatch_scenarios(has_mass) {
            for (sign, mm) in [("+", sc.relative), ("-", -sc.relative)] {
                let s = SimSettings {
                    mass_mismatch: mm,
                    mismatch_parameter: sc.parameter.clone(),
                    ..base.clone()
                };
                jobs.push((format!("{name}_{}{sign}", sc.tag), m, x0s[0].clone(), s));
            }
        }
    }
    let runs: Vec<(String, Run)> = jobs
        .par_iter()
        .map_init(
            || MpcLaw::new(cfg),
            |law, (name, m, x0, s)| {
                let ctrl = match m {
                    None => Controller::Mpc,
                    Some(m) => Controller::Net(&m.mlp, eps(m), None),
                };
                (name.clone(), simulate(cfg, law, &ctrl, x0, s))
            },
        )
        .collect();
    let mut out = ClosedLoop::new();
    for (k, r) in runs {
        out.entry(k).or_default().push(r);
    }
    out
}
