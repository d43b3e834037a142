//! The terminal region against simulation of the local feedback from seeded points on and
//! inside the boundary of the perturbed ball, its constraints against the tightened bounds,
//! and the cosine range against dense sampling.

use super::*;
use crate::problem::ProblemConfig;
use crate::robust::design;

fn load(name: &str, eps: f64) -> ProblemConfig {
    let path =
        std::path::PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/")).join(name);
    let mut c = ProblemConfig::load(&path).unwrap();
    c.robust.eps = eps;
    c.robust.terminal_constraint = true;
    c
}

/// Seeded points y with ‖y − x_r‖_P = r·t, t = 1 (the boundary) for half of them and
/// t uniform in [0, 1] for the others.
fn ball_points(p: &DMatrix<f64>, xr: &[f64], r: f64, n: u64) -> Vec<Vec<f64>> {
    let nx = xr.len();
    (0..n)
        .map(|k| {
            let d: Vec<f64> = (0..nx)
                .map(|i| 2.0 * uniform(11, k, i as u64) - 1.0)
                .collect();
            let t = if k % 2 == 0 { 1.0 } else { uniform(12, k, 0) };
            let s = r * t / p_norm(p, &d).max(1e-300);
            (0..nx).map(|i| xr[i] + s * d[i]).collect()
        })
        .collect()
}

/// The region's claims, checked by simulation: every state of the perturbed ball
/// ‖y − x_r‖_P ≤ c + m is mapped by F(y, κ_f(y)) into X_f (robust invariance, (c)); every
/// state of X_f satisfies the tightened state bounds at stage N and κ_f the tightened input
/// bounds ((a), (b)); trajectories of the local feedback from the boundary stay in X_f; the
/// rate ρ_f bounds the sampled one-step ratios.
fn check_by_simulation(cfg: &ProblemConfig) -> TerminalRegion {
    let d = design(cfg).unwrap();
    let t = d.terminal.clone().expect("a terminal region");
    let p = mat(&d.tube.p);
    let k = mat(&d.tube.k);
    let model = Discrete::new(cfg.system.clone(), cfg.ocp.ts, cfg.ocp.rk4_substeps);
    let n = cfg.ocp.horizon;
    let (xr, ur) = (&t.x_ref, &t.u_ref);
    let kappa = |x: &[f64]| -> Vec<f64> {
        (0..ur.len())
            .map(|j| {
                ur[j]
                    + (0..xr.len())
                        .map(|i| k[(j, i)] * (x[i] - xr[i]))
                        .sum::<f64>()
            })
            .collect()
    };
    let step = |x: &[f64]| {
        let mut f = vec![0.0; x.len()];
        model.step(x, &kappa(x), &mut f);
        f
    };
    let dist = |x: &[f64]| {
        let d: Vec<f64> = x.iter().zip(xr).map(|(a, b)| a - b).collect();
        p_norm(&p, &d)
    };
    let f_ref = step(xr);
    let mut worst_ratio = 0.0f64;
    for y in ball_points(&p, xr, t.radius + t.margin, 4000) {
        let fy = step(&y);
        assert!(
            dist(&fy) <= t.radius * (1.0 + 1e-12),
            "y {y:?} → {fy:?}: ‖·‖_P {} > c {}",
            dist(&fy),
            t.radius
        );
        let diff: Vec<f64> = fy.iter().zip(&f_ref).map(|(a, b)| a - b).collect();
        let dy = dist(&y);
        if dy > 0.0 {
            worst_ratio = worst_ratio.max(p_norm(&p, &diff) / dy);
        }
    }
    assert!(
        worst_ratio <= t.rho_local * (1.0 + 1e-9),
        "sampled rate {worst_ratio} above ρ_f {}",
        t.rho_local
    );
    let st = &d.stages;
    for x0 in ball_points(&p, xr, t.radius, 2000) {
        let mut x = x0.clone();
        for it in 0..40 {
            assert!(dist(&x) <= t.radius * (1.0 + 1e-9), "left X_f at step {it}");
            for i in 0..x.len() {
                assert!(
                    x[i] >= st.x_lo[n - 1][i] - 1e-12 && x[i] <= st.x_hi[n - 1][i] + 1e-12,
                    "x[{i}] = {} outside the stage-N bounds",
                    x[i]
                );
            }
            let u = kappa(&x);
            let sn = d.tube.s[n];
            for j in 0..u.len() {
                let shrink = d.tube.eps + d.tube.u_margin[j] * sn;
                assert!(
                    u[j] >= cfg.ocp.u_lo[j] + shrink - 1e-12
                        && u[j] <= cfg.ocp.u_hi[j] - shrink + 1e-12,
                    "u[{j}] = {} outside U_N",
                    u[j]
                );
            }
            x = step(&x);
        }
    }
    t
}

#[test]
fn pendulum_region_is_proven_and_invariant_in_simulation() {
    let cfg = load("pendulum_robust_small.toml", 0.5);
    let t = check_by_simulation(&cfg);
    assert_eq!(t.check, TerminalCheck::Vertices);
    assert!(t.proven() && t.radius > 0.0 && t.rho_local < 1.0, "{t:?}");
    let d = design(&cfg).unwrap();
    assert_eq!(d.recursive_feasibility(), Feasibility::Proven);
}

#[test]
fn double_integrator_region_is_exact_and_invariant_in_simulation() {
    let cfg = load("double_integrator.toml", 0.1);
    let t = check_by_simulation(&cfg);
    assert_eq!(t.check, TerminalCheck::Exact);
    // (a)/(b) are tight at c_max or (c) shrank it.
    assert!(t.radius <= t.radius_max && t.radius > 0.0);
}

#[test]
fn expression_plant_is_only_sampled() {
    let cfg = load("double_integrator_ode.toml", 0.1);
    let d = design(&cfg).unwrap();
    if let Some(t) = &d.terminal {
        assert_eq!(t.check, TerminalCheck::Sampled);
        assert_eq!(d.recursive_feasibility(), Feasibility::Sampled);
        check_by_simulation(&cfg);
    } else {
        assert_eq!(d.recursive_feasibility(), Feasibility::Unknown);
    }
}

/// The region is the largest of its sequence: the next larger radius c/0.8 (if still
/// within the boxes) breaks (c) — so (c) is what decides, not an arbitrary shrink.
#[test]
fn larger_radius_breaks_a_condition() {
    let cfg = load("pendulum_robust_small.toml", 0.5);
    let d = design(&cfg).unwrap();
    let t = d.terminal.unwrap();
    let c = t.radius / 0.8;
    if c <= t.radius_max {
        let (rho, _) = local_rate(&cfg, &d.tube, c + t.margin);
        assert!(rho * (c + t.margin) + t.offset > c);
    } else {
        assert!((t.radius - t.radius_max).abs() <= 1e-12 * t.radius_max);
    }
}

#[test]
fn cos_range_against_dense_sampling() {
    for k in 0..200u64 {
        let a = -8.0 + 16.0 * uniform(5, k, 0);
        let b = a + 7.0 * uniform(5, k, 1);
        let (lo, hi) = cos_range(a, b);
        let (mut slo, mut shi) = (f64::INFINITY, f64::NEG_INFINITY);
        for i in 0..=20_000 {
            let c = (a + (b - a) * i as f64 / 20_000.0).cos();
            slo = slo.min(c);
            shi = shi.max(c);
        }
        assert!(lo <= slo + 1e-15 && hi >= shi - 1e-15, "[{a}, {b}]");
        assert!(slo - lo < 1e-6 && hi - shi < 1e-6, "[{a}, {b}]: not tight");
    }
}

/// The terminal constraint text is the quadratic form it stands for.
#[test]
fn constraint_text_names_the_states() {
    let cfg = load("pendulum_robust_small.toml", 0.5);
    let t = design(&cfg).unwrap().terminal.unwrap();
    assert!(t.constraint.contains("theta") && t.constraint.contains("omega"));
    assert!(t.constraint.ends_with(&format!("<= {}", t.alpha)));
    let rc = crate::robust::robust_config(&cfg, &design(&cfg).unwrap());
    assert_eq!(rc.ocp.terminal_constraints, vec![t.constraint.clone()]);
    // Not enforced: no constraint, recursive feasibility unknown.
    let mut off = cfg.clone();
    off.robust.terminal_constraint = false;
    let d = design(&off).unwrap();
    assert!(!d.terminal.as_ref().unwrap().enforced);
    assert_eq!(d.recursive_feasibility(), Feasibility::Unknown);
    assert!(crate::robust::robust_config(&off, &d)
        .ocp
        .terminal_constraints
        .is_empty());
}
