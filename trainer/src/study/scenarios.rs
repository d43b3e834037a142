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
use crate::study::safety::{SafetyRun, SafetyStudy};
use rayon::prelude::*;
use std::collections::BTreeMap;

/// Closed-loop results keyed by controller name.
pub type ClosedLoop = BTreeMap<String, Vec<Run>>;

/// The whole of `closed_loop.json`: the runs keyed by controller name, and the safety study
/// (`[closed_loop] safety = true`) when it ran.
///
/// On disk (the issue 41 §6 contract, documented in docs/commands.md):
/// - **without the safety study** the file is exactly the map of runs (files written before
///   the safety study read unchanged, and are written byte for byte as before);
/// - **with it**, the top-level keys `safe`, `plain` and `mpc` are the safety study's nominal
///   runs from the same starts (lists of [`SafetyRun`]: `violation_steps`, `fallback_steps`,
///   `no_safe_steps`, `steps`, `cost`, `converged`, `diverged` when set), `safety` holds the
///   study's settings, summaries and mismatch groups (its nominal lists left out, they are
///   the top-level ones), and the ordinary study's MPC runs from the initial states move to
///   [`ORDINARY_MPC_KEY`]; every other key is unchanged.
///
/// In memory nothing moves: `runs["mpc"]` is the ordinary study's MPC runs and
/// `safety.nominal` the study's runs, whichever file they came from.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ClosedLoopFile {
    /// The safety study (`study::safety`).
    pub safety: Option<SafetyStudy>,
    /// The runs keyed by controller name.
    pub runs: ClosedLoop,
}

/// The key of the ordinary study's MPC runs (`runs["mpc"]` in memory) in a file with the
/// safety study, whose top-level `mpc` is the study's MPC runs.
pub const ORDINARY_MPC_KEY: &str = "mpc_nominal";

/// One top-level value of a file with the safety study.
#[derive(serde::Serialize)]
#[serde(untagged)]
enum Entry<'a> {
    Runs(&'a [Run]),
    Safety(&'a [SafetyRun]),
    Study(&'a SafetyStudy),
}

impl serde::Serialize for ClosedLoopFile {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let Some(study) = &self.safety else {
            return serde::Serialize::serialize(&self.runs, s);
        };
        let mut meta = study.clone();
        let g = &mut meta.nominal;
        for c in [&mut g.safe, &mut g.plain, &mut g.mpc] {
            c.runs = Vec::new();
        }
        let mut out: BTreeMap<&str, Entry> = BTreeMap::new();
        for (k, v) in &self.runs {
            let key = if k == "mpc" { ORDINARY_MPC_KEY } else { k };
            out.insert(key, Entry::Runs(v));
        }
        let n = &study.nominal;
        out.insert("safe", Entry::Safety(&n.safe.runs));
        out.insert("plain", Entry::Safety(&n.plain.runs));
        out.insert("mpc", Entry::Safety(&n.mpc.runs));
        out.insert("safety", Entry::Study(&meta));
        serde::Serialize::serialize(&out, s)
    }
}

impl<'de> serde::Deserialize<'de> for ClosedLoopFile {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        use serde::de::Error;
        let mut raw: BTreeMap<String, serde_json::Value> = serde::Deserialize::deserialize(d)?;
        let take = |raw: &mut BTreeMap<String, serde_json::Value>, k: &str| raw.remove(k);
        let safety = match take(&mut raw, "safety") {
            None => None,
            Some(v) => {
                let mut study: SafetyStudy = serde_json::from_value(v)
                    .map_err(|e| D::Error::custom(format!("key `safety`: {e}")))?;
                let g = &mut study.nominal;
                // A file of the first layout (the study's lists nested under `safety`, the
                // top level the ordinary runs alone) reads as it was written.
                let nested = [&g.safe, &g.plain, &g.mpc]
                    .iter()
                    .any(|c| !c.runs.is_empty());
                if !nested {
                    for (k, c) in [
                        ("safe", &mut g.safe),
                        ("plain", &mut g.plain),
                        ("mpc", &mut g.mpc),
                    ] {
                        if let Some(v) = take(&mut raw, k) {
                            c.runs = serde_json::from_value(v)
                                .map_err(|e| D::Error::custom(format!("key `{k}`: {e}")))?;
                        }
                    }
                    if let Some(v) = take(&mut raw, ORDINARY_MPC_KEY) {
                        raw.insert("mpc".into(), v);
                    }
                }
                Some(study)
            }
        };
        let mut runs = ClosedLoop::new();
        for (k, v) in raw {
            let r: Vec<Run> = serde_json::from_value(v)
                .map_err(|e| D::Error::custom(format!("key `{k}`: {e}")))?;
            runs.insert(k, r);
        }
        Ok(ClosedLoopFile { safety, runs })
    }
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
