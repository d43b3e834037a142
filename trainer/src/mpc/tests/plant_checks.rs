//! Cross-checks of the MPC law on plants written as expressions (tests only): the paper's
//! pendulum and the double integrator as `kind = "ode"` give the labels (u, ∂u/∂x) of the
//! built-in plants, and a 12-state, 4-input nonlinear mass chain solves to convergence with
//! KKT sensitivities equal to central finite differences of the converged solver.

use super::load;
use crate::mpc::law::MpcLaw;
use crate::mpc::sqp::SqpStatus;
use crate::problem::model::test_plants::chain_toml;
use crate::problem::ProblemConfig;
use crate::rng::uniform;

/// Every 12th point of the problem's `sampling.counts` grid (30 of the pendulum's 350).
fn grid_states(cfg: &ProblemConfig, every: usize) -> Vec<Vec<f64>> {
    let c = &cfg.sampling.counts;
    let total: usize = c.iter().product();
    (0..total)
        .step_by(every)
        .map(|mut k| {
            (0..c.len())
                .map(|j| {
                    let (lo, hi) = (cfg.domain.lo[j], cfg.domain.hi[j]);
                    let i = k % c[j];
                    k /= c[j];
                    lo + (hi - lo) * i as f64 / (c[j] - 1) as f64
                })
                .collect()
        })
        .collect()
}

fn same_labels(builtin: &str, ode: &str, every: usize, min_states: usize) {
    let (a, b) = (load(builtin), load(ode));
    assert_ne!(a.system, b.system);
    let (mut la, mut lb) = (MpcLaw::new(&a), MpcLaw::new(&b));
    let states = grid_states(&a, every);
    assert!(states.len() >= min_states, "{}", states.len());
    for x in &states {
        let ((ka, _), (kb, _)) = (la.solve(x, None), lb.solve(x, None));
        assert_eq!(ka.status, kb.status, "{ode} at {x:?}");
        for (p, q) in ka.u.iter().zip(&kb.u).chain(ka.du_dx.iter().zip(&kb.du_dx)) {
            assert!(
                (p - q).abs() <= 1e-12 || (p.is_nan() && q.is_nan()),
                "{ode} at {x:?}: {p} vs {q} ({ka:?} vs {kb:?})"
            );
        }
    }
}

#[test]
fn pendulum_ode_labels_equal_the_built_in_pendulum() {
    same_labels("pendulum.toml", "pendulum_ode.toml", 12, 30);
}

#[test]
fn double_integrator_ode_labels_equal_the_built_in() {
    same_labels(
        "double_integrator.toml",
        "double_integrator_ode.toml",
        7,
        30,
    );
}

/// A 12-state, 4-input problem: the chain of 6 masses of `test_plants`.
fn chain_problem() -> ProblemConfig {
    let n = 12;
    let v = |x: f64, k: usize| format!("[{}]", vec![format!("{x:?}"); k].join(", "));
    let text = format!(
        "name = \"chain\"\n[system]\n{}\n[ocp]\nts = 0.1\nhorizon = 10\nrk4_substeps = 1\nq = {}\nr = {}\np = {}\nx_lo = {}\nx_hi = {}\nu_lo = {}\nu_hi = {}\n[domain]\nlo = {}\nhi = {}\n[sampling]\nsampler = \"random\"\nn = 10\n",
        chain_toml(6, &[0, 2, 3, 5]),
        v(1.0, n),
        v(0.1, 4),
        v(5.0, n),
        v(-3.0, n),
        v(3.0, n),
        v(-2.0, 4),
        v(2.0, 4),
        v(-0.8, n),
        v(0.8, n),
    );
    ProblemConfig::from_toml_str(&text, "chain").unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn twelve_state_chain_converges_with_finite_difference_sensitivities() {
    let cfg = chain_problem();
    let (nx, nu) = (cfg.system.nx(), cfg.system.nu());
    assert_eq!((nx, nu), (12, 4));
    let mut law = MpcLaw::new(&cfg);
    let h = 1e-6;
    let mut checked = 0;
    for i in 0..4u64 {
        let x: Vec<f64> = (0..nx)
            .map(|j| {
                let (lo, hi) = (cfg.domain.lo[j], cfg.domain.hi[j]);
                lo + (hi - lo) * uniform(99, i, j as u64)
            })
            .collect();
        let (l, _) = law.solve(&x, None);
        assert_eq!(l.status, SqpStatus::Converged, "at {x:?}");
        if l.degeneracy.is_some() {
            continue;
        }
        let mut fd = vec![0.0; nu * nx];
        let mut kink = false;
        for j in 0..nx {
            let (mut xp, mut xm) = (x.clone(), x.clone());
            xp[j] += h;
            xm[j] -= h;
            let ((lp, _), (lm, _)) = (law.solve(&xp, None), law.solve(&xm, None));
            assert!(lp.status == SqpStatus::Converged && lm.status == SqpStatus::Converged);
            for r in 0..nu {
                let (fwd, bwd) = ((lp.u[r] - l.u[r]) / h, (l.u[r] - lm.u[r]) / h);
                kink |= (fwd - bwd).abs() > 1e-3 * (1.0 + fwd.abs());
                fd[r * nx + j] = (lp.u[r] - lm.u[r]) / (2.0 * h);
            }
        }
        if kink {
            continue;
        }
        let scale = fd
            .iter()
            .chain(&l.du_dx)
            .fold(1.0f64, |m, v| m.max(v.abs()));
        for (k, (a, b)) in fd.iter().zip(&l.du_dx).enumerate() {
            assert!(
                (a - b).abs() <= 1e-5 * scale,
                "at {x:?}: du{}/dx{}: fd {a} vs kkt {b}",
                k / nx,
                k % nx
            );
        }
        checked += 1;
    }
    assert!(checked >= 3, "only {checked} states checked");
}
