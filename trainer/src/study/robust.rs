//! The robust closed-loop study (Corollary 1, checked by simulation): the robust-design net
//! and the robust MPC under input errors |e| ≤ ε from feasible Monte Carlo states, with the
//! true (untightened) constraints; [`RunSummary`] aggregates the runs.

use crate::certify::Model;
use crate::mpc::law::MpcLaw;
use crate::mpc::sqp::SqpStatus;
use crate::problem::ProblemConfig;
use crate::rng::uniform;
use crate::study::closed_loop::{simulate, Controller, Disturbance, Run, SimSettings};
use crate::study::scenarios::{initial_states, ClosedLoop};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Aggregate of a set of closed-loop runs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunSummary {
    /// Number of runs.
    pub runs: usize,
    /// Runs with at least one violating step.
    pub runs_violating: usize,
    /// Violating steps over all runs.
    pub violation_steps: usize,
    /// Share of violating steps in %.
    pub violation_percent: f64,
    /// Largest violation.
    pub max_violation: f64,
    /// Largest input divergence from the MPC along the trajectories.
    pub max_input_divergence: f64,
    /// Steps where the robust MPC was infeasible at the visited state.
    pub mpc_soft_steps: usize,
    /// Mean closed-loop cost.
    pub mean_cost: f64,
}

/// Summarises runs.
pub fn summarize(runs: &[Run]) -> RunSummary {
    let steps: usize = runs.iter().map(|r| r.steps).sum();
    let vs: usize = runs.iter().map(|r| r.violation_steps).sum();
    RunSummary {
        runs: runs.len(),
        runs_violating: runs.iter().filter(|r| r.violation_steps > 0).count(),
        violation_steps: vs,
        violation_percent: 100.0 * vs as f64 / steps.max(1) as f64,
        max_violation: runs.iter().map(|r| r.max_violation).fold(0.0, f64::max),
        max_input_divergence: runs
            .iter()
            .map(|r| r.max_input_divergence)
            .fold(0.0, f64::max),
        mpc_soft_steps: runs.iter().map(|r| r.mpc_soft_steps).sum(),
        mean_cost: runs.iter().map(|r| r.cost).sum::<f64>() / runs.len().max(1) as f64,
    }
}

/// Seeded uniform states of X at which the robust MPC (`rcfg`) is feasible (its hard
/// problem converges), `n` of them, in draw order.
pub fn feasible_states(rcfg: &ProblemConfig, n: usize, seed: u64) -> Vec<Vec<f64>> {
    let nx = rcfg.system.nx();
    let mut out = Vec::new();
    let mut next = 0u64;
    while out.len() < n && next < 200 * (n as u64 + 10) {
        let batch: Vec<Vec<f64>> = (next..next + 256)
            .map(|m| {
                (0..nx)
                    .map(|i| {
                        let (l, h) = (rcfg.domain.lo[i], rcfg.domain.hi[i]);
                        l + (h - l) * uniform(seed ^ 0xfea5, m, i as u64)
                    })
                    .collect()
            })
            .collect();
        next += 256;
        let ok: Vec<bool> = batch
            .par_iter()
            .map_init(
                || MpcLaw::new(rcfg),
                |law, x| law.solve(x, None).0.status == SqpStatus::Converged,
            )
            .collect();
        for (x, f) in batch.into_iter().zip(ok) {
            if f && out.len() < n {
                out.push(x);
            }
        }
    }
    out
}

/// The box the feasible set of the tightened MPC is searched in beyond X: per axis the hull
/// of X and the OCP's state bounds, an unbounded side taking X's width again.
pub fn search_box(rcfg: &ProblemConfig) -> (Vec<f64>, Vec<f64>) {
    let (lo, hi) = (&rcfg.domain.lo, &rcfg.domain.hi);
    let o = &rcfg.ocp;
    (0..lo.len())
        .map(|i| {
            let w = hi[i] - lo[i];
            let a = o.x_lo.get(i).copied().unwrap_or(f64::NEG_INFINITY);
            let b = o.x_hi.get(i).copied().unwrap_or(f64::INFINITY);
            (
                if a.is_finite() {
                    a.min(lo[i])
                } else {
                    lo[i] - w
                },
                if b.is_finite() {
                    b.max(hi[i])
                } else {
                    hi[i] + w
                },
            )
        })
        .unzip()
}

/// Seeded uniform states of the [`search_box`] outside X (at most `n` draws) at which the
/// tightened MPC is feasible: the feasible set reaches beyond the certified domain there,
/// where ε does not hold (the controller projects onto X). Empty when the box is X.
pub fn feasible_outside_domain(rcfg: &ProblemConfig, n: usize, seed: u64) -> Vec<Vec<f64>> {
    let (blo, bhi) = search_box(rcfg);
    let (lo, hi) = (&rcfg.domain.lo, &rcfg.domain.hi);
    if blo.iter().zip(lo).all(|(a, b)| a >= b) && bhi.iter().zip(hi).all(|(a, b)| a <= b) {
        return Vec::new();
    }
    let nx = lo.len();
    let outside: Vec<Vec<f64>> = (0..n as u64)
        .map(|m| {
            (0..nx)
                .map(|i| blo[i] + (bhi[i] - blo[i]) * uniform(seed ^ 0x0b5d, m, i as u64))
                .collect::<Vec<f64>>()
        })
        .filter(|x| (0..nx).any(|i| x[i] < lo[i] || x[i] > hi[i]))
        .collect();
    let ok: Vec<bool> = outside
        .par_iter()
        .map_init(
            || MpcLaw::new(rcfg),
            |law, x| law.solve(x, None).0.status == SqpStatus::Converged,
        )
        .collect();
    outside
        .into_iter()
        .zip(ok)
        .filter_map(|(x, f)| f.then_some(x))
        .collect()
}

/// The disturbances of the robust-MPC runs, with their `closed_loop.json` keys.
pub fn disturbances(eps: f64) -> Vec<(&'static str, Disturbance)> {
    vec![
        ("robust_mpc_bang+", Disturbance::BangBang { eps, period: 0 }),
        (
            "robust_mpc_bang-",
            Disturbance::BangBang {
                eps: -eps,
                period: 0,
            },
        ),
        (
            "robust_mpc_bang_alt",
            Disturbance::BangBang { eps, period: 5 },
        ),
        ("robust_mpc_adversarial", Disturbance::Adversarial { eps }),
        ("robust_mpc_random", Disturbance::Random { eps }),
    ]
}

/// The robust closed-loop study. Keys: `robust` (the robust-design net from the upswing
/// state, then from every Monte Carlo state; same per-run format as the other keys),
/// `nominal_net` (if given: the nominal design's net from the same states, its divergence
/// measured against the nominal MPC), `robust_mpc` (the robust MPC, no disturbance),
/// `robust_mpc_<disturbance>` (the robust MPC with the applied input κ(x) + e, |e| ≤ ε),
/// `nominal_mpc` (the untightened MPC, for the cost degradation). The MPC runs use the
/// upswing state and the first `disturbed_states` Monte Carlo states. Violations are
/// always measured against the true (untightened) constraints.
pub fn study(
    cfg: &ProblemConfig,
    rcfg: &ProblemConfig,
    net: (&Model, f64),
    nominal_net: Option<(&Model, f64)>,
    mc_states: &[Vec<f64>],
) -> ClosedLoop {
    let eps = cfg.robust.eps;
    let base = SimSettings {
        steps: cfg.closed_loop.steps,
        noise: vec![],
        seed: 0,
        mass_mismatch: 0.0,
        mismatch_parameter: None,
        disturbance: Disturbance::None,
    };
    let up = initial_states(cfg)[0].clone();
    let mut net_x0 = vec![up.clone()];
    net_x0.extend(mc_states.iter().cloned());
    let mut mpc_x0 = vec![up];
    mpc_x0.extend(mc_states.iter().take(cfg.robust.disturbed_states).cloned());
    type Job<'a> = (
        String,
        bool,
        Option<(&'a Model, f64)>,
        Vec<f64>,
        SimSettings,
    );
    // (key, robust law?, net, x0, settings)
    let mut jobs: Vec<Job> = Vec::new();
    for x0 in &net_x0 {
        jobs.push(("robust".into(), true, Some(net), x0.clone(), base.clone()));
        if let Some(nn) = nominal_net {
            jobs.push((
                "nominal_net".into(),
                false,
                Some(nn),
                x0.clone(),
                base.clone(),
            ));
        }
    }
    for (i, x0) in mpc_x0.iter().enumerate() {
        jobs.push(("robust_mpc".into(), true, None, x0.clone(), base.clone()));
        jobs.push(("nominal_mpc".into(), false, None, x0.clone(), base.clone()));
        for (key, d) in disturbances(eps) {
            let s = SimSettings {
                disturbance: d,
                seed: i as u64,
                ..base.clone()
            };
            jobs.push((key.into(), true, None, x0.clone(), s));
        }
    }
    let runs: Vec<(String, Run)> = jobs
        .par_iter()
        .map_init(
            || (MpcLaw::new(rcfg), MpcLaw::new(cfg)),
            |(rlaw, nlaw), (key, robust, m, x0, s)| {
                let law = if *robust { rlaw } else { nlaw };
                let ctrl = match m {
                    Some((m, e)) => Controller::Net(
                        &m.mlp,
                        *e,
                        m.certificate
                            .as_ref()
                            .map(|c| (&c.clamp_lo[..], &c.clamp_hi[..])),
                    ),
                    None => Controller::Mpc,
                };
                (key.clone(), simulate(rcfg, law, &ctrl, x0, s))
            },
        )
        .collect();
    let mut out = ClosedLoop::new();
    for (k, r) in runs {
        out.entry(k).or_default().push(r);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::problem::model::Discrete;
    use crate::problem::RobustMethod;
    use crate::robust::*;

    fn load(name: &str) -> ProblemConfig {
        let path = std::path::PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/"))
            .join(name);
        ProblemConfig::load(&path).unwrap()
    }

    fn pendulum(eps: f64) -> ProblemConfig {
        let mut c = ProblemConfig::default();
        c.robust.eps = eps;
        c
    }

    fn di(eps: f64) -> ProblemConfig {
        let mut c = load("double_integrator.toml");
        c.robust.eps = eps;
        c
    }

    #[test]
    fn pendulum_design_is_a_contraction_and_leaves_the_upswing_feasible() {
        let cfg = pendulum(0.5);
        let d = design(&cfg).unwrap();
        let t = &d.tube;
        eprintln!(
            "ρ {:.5} w̄ {:.4e} K {:?} scale {:?} s_N {:.4} σ {:?} τ {:?}",
            t.rho, t.w, t.k, t.lqr_r_scale, t.s[20], t.x_margin, t.u_margin
        );
        assert_eq!(t.bound, JacobianBound::Vertices);
        assert!(t.rho < 1.0, "ρ = {}", t.rho);
        assert!(
            d.stages.x_hi.iter().all(|x| x[1] > 0.3),
            "{:?}",
            d.stages.x_hi
        );
        // The Lipschitz tightening is hopeless here.
        let mut lip = cfg.clone();
        lip.robust.method = RobustMethod::Lipschitz;
        let e = design(&lip).unwrap_err();
        eprintln!("lipschitz: {e}");
        assert!(matches!(e, RobustError::Infeasible { .. }));
        // The robust MPC swings up from (−π, 0) under adversarial input errors |e| ≤ ε.
        let rcfg = robust_config(&cfg, &d);
        let mut law = MpcLaw::new(&rcfg);
        let up = [-std::f64::consts::PI, 0.0];
        assert_eq!(law.solve(&up, None).0.status, SqpStatus::Converged);
        for (key, dist) in disturbances(0.5) {
            let s = SimSettings {
                steps: 90,
                noise: vec![],
                seed: 1,
                mass_mismatch: 0.0,
                mismatch_parameter: None,
                disturbance: dist,
            };
            let r = simulate(&rcfg, &mut law, &Controller::Mpc, &up, &s);
            eprintln!(
                "{key}: viol {} max {:.3e} soft {} cost {:.2} last {:?}",
                r.violation_steps,
                r.max_violation,
                r.mpc_soft_steps,
                r.cost,
                r.x.last()
            );
            assert_eq!(r.violation_steps, 0, "{key}");
            assert_eq!(r.mpc_soft_steps, 0, "{key}");
            assert_eq!(r.mpc_failures, 0, "{key}");
        }
    }

    /// ∂κ/∂x of the tightened OCP against central differences, at states where a
    /// tightened (stage-dependent) bound is active; and the solution against the
    /// reference QP solver (clarabel).
    #[test]
    fn tightened_ocp_sensitivities_match_finite_differences_and_clarabel() {
        let cfg = pendulum(0.5);
        let d = design(&cfg).unwrap();
        let rcfg = robust_config(&cfg, &d);
        let mut law = MpcLaw::new(&rcfg);
        let mut reference = rcfg.clone();
        reference.solver.qp = crate::mpc::qp::QpSolverKind::Clarabel;
        let mut ref_law = MpcLaw::new(&reference);
        let ocp = crate::mpc::ocp::Ocp::new(&rcfg, false);
        // States along the robust upswing (x₂ rides its tightened bound).
        let s = SimSettings {
            steps: 40,
            noise: vec![],
            seed: 0,
            mass_mismatch: 0.0,
            mismatch_parameter: None,
            disturbance: Disturbance::None,
        };
        let run = simulate(
            &rcfg,
            &mut law,
            &Controller::Mpc,
            &[-std::f64::consts::PI, 0.0],
            &s,
        );
        let h = 1e-6;
        let (mut checked, mut with_tight_active) = (0, 0);
        for x in run.x.iter().step_by(3) {
            let (l, sol) = law.solve(x, None);
            assert_eq!(l.status, SqpStatus::Converged);
            let (lr, _) = ref_law.solve(x, None);
            assert!(
                (l.u[0] - lr.u[0]).abs() < 1e-6,
                "{x:?}: {} vs {}",
                l.u[0],
                lr.u[0]
            );
            assert!((l.cost - lr.cost).abs() < 1e-6 * l.cost.max(1.0));
            if l.degeneracy.is_some() {
                continue;
            }
            let z = sol.unwrap().z;
            let tight_active = (1..=rcfg.ocp.horizon).any(|k| {
                let (lo, hi) = rcfg.ocp.x_bounds(k);
                (0..2).any(|i| {
                    let v = z[ocp.ix(k) + i];
                    ((v - hi[i]).abs() < 1e-7 && hi[i] < cfg.ocp.x_hi[i])
                        || ((v - lo[i]).abs() < 1e-7 && lo[i] > cfg.ocp.x_lo[i])
                })
            });
            let mut ok = true;
            let mut fd = [0.0; 2];
            for j in 0..2 {
                let (mut xp, mut xm) = (x.clone(), x.clone());
                xp[j] += h;
                xm[j] -= h;
                let up = law.solve(&xp, None).0.u[0];
                let um = law.solve(&xm, None).0.u[0];
                let (fwd, bwd) = ((up - l.u[0]) / h, (l.u[0] - um) / h);
                if (fwd - bwd).abs() > 1e-3 * (1.0 + fwd.abs()) {
                    ok = false; // a kink within ±h
                }
                fd[j] = (up - um) / (2.0 * h);
            }
            if !ok {
                continue;
            }
            for j in 0..2 {
                assert!(
                    (fd[j] - l.du_dx[j]).abs() <= 1e-4 * (1.0 + fd[j].abs()),
                    "{x:?}: ∂u/∂x{j} {} vs FD {}",
                    l.du_dx[j],
                    fd[j]
                );
            }
            checked += 1;
            if tight_active {
                with_tight_active += 1;
            }
        }
        eprintln!("checked {checked}, with a tightened bound active {with_tight_active}");
        assert!(checked >= 5 && with_tight_active >= 2);
    }

    fn mpc_monte_carlo(cfg: &ProblemConfig, states: usize, steps: usize) {
        let d = design(cfg).unwrap();
        let rcfg = robust_config(cfg, &d);
        let xs = feasible_states(&rcfg, states, 3);
        assert_eq!(xs.len(), states);
        let mut jobs = Vec::new();
        for (i, x) in xs.iter().enumerate() {
            for (key, dist) in disturbances(cfg.robust.eps) {
                jobs.push((key, i as u64, x.clone(), dist));
            }
        }
        let bad: Vec<String> = jobs
            .par_iter()
            .map_init(
                || MpcLaw::new(&rcfg),
                |law, (key, seed, x, dist)| {
                    let s = SimSettings {
                        steps,
                        noise: vec![],
                        seed: *seed,
                        mass_mismatch: 0.0,
                        mismatch_parameter: None,
                        disturbance: *dist,
                    };
                    let r = simulate(&rcfg, law, &Controller::Mpc, x, &s);
                    (r.violation_steps + r.mpc_soft_steps + r.mpc_failures > 0).then(|| {
                        format!(
                            "{key} from {x:?}: {} violations (max {:.3e}), {} infeasible, {} failed",
                            r.violation_steps, r.max_violation, r.mpc_soft_steps, r.mpc_failures
                        )
                    })
                },
            )
            .flatten()
            .collect();
        assert!(
            bad.is_empty(),
            "{} bad runs: {:?}",
            bad.len(),
            &bad[..bad.len().min(5)]
        );
    }

    #[test]
    fn double_integrator_monte_carlo_has_no_violations() {
        mpc_monte_carlo(&di(0.1), 100, 60);
    }

    #[test]
    fn pendulum_monte_carlo_has_no_violations() {
        mpc_monte_carlo(&pendulum(0.5), 16, 90);
    }

    #[test]
    fn adversarial_disturbance_pushes_towards_the_nearest_bound() {
        let cfg = ProblemConfig::default();
        let model = Discrete::new(cfg.system.clone(), cfg.ocp.ts, 1);
        let d = Disturbance::Adversarial { eps: 0.5 };
        // x₂ near its upper bound 1: push up (∂x₂⁺/∂u > 0), so e = +ε.
        assert_eq!(d.at(&model, &cfg, 0, 0, &[0.0, 0.95], &[0.0]), vec![0.5]);
        // x₂ near −1: e = −ε.
        assert_eq!(d.at(&model, &cfg, 0, 0, &[0.0, -0.95], &[0.0]), vec![-0.5]);
        // x₁ near 2π with x₂ = 0: the x₁ bound is the nearest: e = +ε.
        assert_eq!(d.at(&model, &cfg, 0, 0, &[6.2, 0.0], &[0.0]), vec![0.5]);
        let b = Disturbance::BangBang {
            eps: 0.5,
            period: 2,
        };
        let seq: Vec<f64> = (0..6)
            .map(|k| b.at(&model, &cfg, k, 0, &[0.0, 0.0], &[0.0])[0])
            .collect();
        assert_eq!(seq, vec![0.5, 0.5, -0.5, -0.5, 0.5, 0.5]);
        let r = Disturbance::Random { eps: 0.5 };
        assert!((0..100).all(|k| r.at(&model, &cfg, k, 3, &[0.0, 0.0], &[0.0])[0].abs() <= 0.5));
    }
}
