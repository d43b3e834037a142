//! Cross-checks of the MPC law against independent computations (tests only):
//! finite differences of the converged solver for ∂κ/∂x on all three systems, the
//! double integrator's piecewise-affine gain from its condensed QP on the active set,
//! first-order optimality recomputed from scratch (finite-difference gradients,
//! least-squares multipliers), and infeasibility proofs at the pendulum's corners.

use super::{load, random_state};
use crate::mpc::law::{MpcLaw, SLACK_TOL};
use crate::mpc::sqp::SqpStatus;
use crate::problem::ProblemConfig;
use nalgebra::{DMatrix, DVector};

/// Central differences of u0 of the converged solver agree with the KKT sensitivity to
/// 1e-5 (relative) wherever the active set does not change within ±h.
fn check_fd(cfg: &ProblemConfig, seed: u64, n: u64, min_checked: usize) {
    let mut law = MpcLaw::new(cfg);
    let nx = cfg.system.nx();
    let h = 1e-6;
    let mut checked = 0;
    for i in 0..n {
        let x = random_state(cfg, seed, i);
        let (l, _) = law.solve(&x, None);
        if l.status != SqpStatus::Converged || l.degeneracy.is_some() {
            continue;
        }
        let mut ok_all = true;
        let mut fds = vec![0.0; nx];
        for j in 0..nx {
            let (mut xp, mut xm) = (x.clone(), x.clone());
            xp[j] += h;
            xm[j] -= h;
            let (lp, _) = law.solve(&xp, None);
            let (lm, _) = law.solve(&xm, None);
            assert!(lp.status == SqpStatus::Converged && lm.status == SqpStatus::Converged);
            // One-sided differences disagree ⇒ the active set changes within ±h: a kink,
            // where no derivative exists; skip that state.
            let fwd = (lp.u[0] - l.u[0]) / h;
            let bwd = (l.u[0] - lm.u[0]) / h;
            if (fwd - bwd).abs() > 1e-3 * (1.0 + fwd.abs()) {
                ok_all = false;
                break;
            }
            fds[j] = (lp.u[0] - lm.u[0]) / (2.0 * h);
        }
        if !ok_all {
            continue;
        }
        let scale = fds
            .iter()
            .chain(&l.du_dx)
            .fold(1.0f64, |m, v| m.max(v.abs()));
        for j in 0..nx {
            assert!(
                (fds[j] - l.du_dx[j]).abs() <= 1e-5 * scale,
                "{} at {x:?}: du/dx{j} fd {} vs kkt {}",
                cfg.name,
                fds[j],
                l.du_dx[j]
            );
        }
        checked += 1;
    }
    assert!(
        checked >= min_checked,
        "{}: only {checked} states checked",
        cfg.name
    );
}

#[test]
fn sensitivity_matches_finite_differences_pendulum() {
    check_fd(&ProblemConfig::default(), 11, 40, 25);
}

#[test]
fn sensitivity_matches_finite_differences_cartpole() {
    check_fd(&load("cartpole.toml"), 12, 20, 10);
}

#[test]
fn sensitivity_matches_finite_differences_double_integrator() {
    check_fd(&load("double_integrator.toml"), 13, 40, 25);
}

/// Condensed QP of the double integrator: X = Φx0 + ΓU; the gain ∂U/∂x0 on the active set
/// solves [2H G_Aᵀ; G_A 0] [∂U; ∂μ] = [−2F; E_A] — a computation that shares nothing
/// with the SQP/KKT code but the problem data.
#[test]
fn double_integrator_gain_matches_condensed_qp_on_active_set() {
    let cfg = load("double_integrator.toml");
    let (n, ts) = (cfg.ocp.horizon, cfg.ocp.ts);
    let m = match &cfg.system {
        crate::problem::model::System::DoubleIntegrator(d) => d.mass,
        _ => unreachable!(),
    };
    let a = DMatrix::from_row_slice(2, 2, &[1.0, ts, 0.0, 1.0]);
    let b = DMatrix::from_row_slice(2, 1, &[0.5 * ts * ts / m, ts / m]);
    // Φ (2N×2) and Γ (2N×N) for x_1..x_N.
    let mut phi = DMatrix::zeros(2 * n, 2);
    let mut gam = DMatrix::zeros(2 * n, n);
    let mut ak = DMatrix::identity(2, 2);
    for k in 0..n {
        ak = &a * &ak;
        phi.view_mut((2 * k, 0), (2, 2)).copy_from(&ak);
        for j in 0..=k {
            let mut p = DMatrix::identity(2, 2);
            for _ in 0..(k - j) {
                p = &a * &p;
            }
            gam.view_mut((2 * k, j), (2, 1)).copy_from(&(&p * &b));
        }
    }
    let (q, r, p) = (cfg.q(), cfg.r(), cfg.p());
    let mut qbar = DMatrix::zeros(2 * n, 2 * n);
    for k in 0..n {
        let w = if k + 1 == n { &p } else { &q };
        qbar.view_mut((2 * k, 2 * k), (2, 2)).copy_from(w);
    }
    let rbar = DMatrix::from_diagonal_element(n, n, r[(0, 0)]);
    let h = gam.transpose() * &qbar * &gam + rbar;
    let f = gam.transpose() * &qbar * &phi; // cost = UᵀHU + 2 x0ᵀFᵀU + …
    let mut law = MpcLaw::new(&cfg);
    let mut checked = 0;
    for i in 0..60 {
        let x = random_state(&cfg, 21, i);
        let (l, sol) = law.solve(&x, None);
        assert_eq!(l.status, SqpStatus::Converged, "{x:?}");
        if l.degeneracy.is_some() {
            continue;
        }
        let z = sol.unwrap().z;
        let ocp = &law.hard_solver().ocp;
        // Active constraints from the primal solution: (row of [Γ; −Γ; I; −I], rhs-gradient in x0).
        let mut ga: Vec<(DVector<f64>, DVector<f64>)> = Vec::new();
        for k in 0..n {
            let xk = ocp.ix(k + 1);
            for s in 0..2 {
                let v = z[xk + s];
                let row = gam.row(2 * k + s).transpose();
                let prow = phi.row(2 * k + s).transpose();
                if (v - cfg.ocp.x_hi[s]).abs() < 1e-7 {
                    ga.push((row.clone(), -prow.clone()));
                } else if (v - cfg.ocp.x_lo[s]).abs() < 1e-7 {
                    ga.push((-row, prow));
                }
            }
            let u = z[ocp.iu(k)];
            let e = DVector::from_fn(n, |j, _| if j == k { 1.0 } else { 0.0 });
            if (u - cfg.ocp.u_hi[0]).abs() < 1e-7 {
                ga.push((e, DVector::zeros(2)));
            } else if (u - cfg.ocp.u_lo[0]).abs() < 1e-7 {
                ga.push((-e, DVector::zeros(2)));
            }
        }
        let na = ga.len();
        let mut kk = DMatrix::zeros(n + na, n + na);
        kk.view_mut((0, 0), (n, n)).copy_from(&(2.0 * &h));
        let mut rhs = DMatrix::zeros(n + na, 2);
        rhs.view_mut((0, 0), (n, 2)).copy_from(&(-2.0 * &f));
        for (t, (g, e)) in ga.iter().enumerate() {
            for j in 0..n {
                kk[(n + t, j)] = g[j];
                kk[(j, n + t)] = g[j];
            }
            rhs[(n + t, 0)] = e[0];
            rhs[(n + t, 1)] = e[1];
        }
        let Some(sol) = kk.lu().solve(&rhs) else {
            continue; // LICQ fails on this active set (more active rows than freedom)
        };
        for j in 0..2 {
            assert!(
                (sol[(0, j)] - l.du_dx[j]).abs() <= 1e-7 * (1.0 + sol[(0, j)].abs()),
                "{x:?}: gain {j}: condensed {} vs kkt {}",
                sol[(0, j)],
                l.du_dx[j]
            );
        }
        checked += 1;
    }
    assert!(checked >= 40, "only {checked} states checked");
}

/// First-order optimality from scratch: gradients of f and c by central differences of
/// the objective/constraint functions, the active set from the primal point only,
/// multipliers by least squares; stationarity, sign and feasibility are then checked.
#[test]
fn optimum_satisfies_first_order_conditions_independently() {
    let cfg = ProblemConfig::default();
    let mut law = MpcLaw::new(&cfg);
    for i in 0..15 {
        let x = random_state(&cfg, 31, i);
        let (l, sol) = law.solve(&x, None);
        if l.status != SqpStatus::Converged {
            continue;
        }
        let z = sol.unwrap().z;
        let ocp = &law.hard_solver().ocp;
        let nv = ocp.n_var;
        let h = 1e-6;
        let mut grad = DVector::zeros(nv);
        let mut jac = DMatrix::zeros(ocp.n_eq, nv);
        let mut cp = vec![0.0; ocp.n_eq];
        let mut cm = vec![0.0; ocp.n_eq];
        for j in 0..nv {
            let (mut zp, mut zm) = (z.clone(), z.clone());
            zp[j] += h;
            zm[j] -= h;
            grad[j] = (ocp.objective(&zp) - ocp.objective(&zm)) / (2.0 * h);
            ocp.constraint_values(&zp, &x, &mut cp);
            ocp.constraint_values(&zm, &x, &mut cm);
            for r in 0..ocp.n_eq {
                jac[(r, j)] = (cp[r] - cm[r]) / (2.0 * h);
            }
        }
        let mut c = vec![0.0; ocp.n_eq];
        ocp.constraint_values(&z, &x, &mut c);
        assert!(
            c.iter().all(|v| v.abs() < 1e-8),
            "{x:?}: infeasible dynamics"
        );
        let active: Vec<usize> = (0..ocp.rows.len())
            .filter(|&r| ocp.rows[r].slack(&z) < 1e-8)
            .collect();
        for row in &ocp.rows {
            assert!(row.slack(&z) > -1e-9, "{x:?}: bound violated");
        }
        // Solve min ‖grad + Jᵀλ + G_Aᵀν‖ in the least-squares sense.
        let m = ocp.n_eq + active.len();
        let mut a = DMatrix::zeros(nv, m);
        a.view_mut((0, 0), (nv, ocp.n_eq))
            .copy_from(&jac.transpose());
        for (t, &r) in active.iter().enumerate() {
            let row = &ocp.rows[r];
            for k in 0..row.len {
                a[(row.idx[k], ocp.n_eq + t)] = row.coef[k];
            }
        }
        let svd = a.clone().svd(true, true);
        let mult = svd.solve(&(-&grad), 1e-12).unwrap();
        let res = &grad + &a * &mult;
        let scale = grad.amax().max(1.0);
        assert!(
            res.amax() <= 1e-5 * scale,
            "{x:?}: stationarity residual {}",
            res.amax()
        );
        for t in 0..active.len() {
            assert!(
                mult[ocp.n_eq + t] >= -1e-5 * scale,
                "{x:?}: negative multiplier {}",
                mult[ocp.n_eq + t]
            );
        }
    }
}

/// At x = (2π, 1) no input can keep x1(1) ≤ 2π (x1 after one step is increasing in u, and
/// even u = u_lo overshoots): the hard OCP is infeasible. The solver must detect it, label
/// the state softly (default) or leave it unlabelled (fallback off).
#[test]
fn pendulum_corner_infeasibility_is_detected() {
    let cfg = ProblemConfig::default();
    let two_pi = 2.0 * std::f64::consts::PI;
    for xs in [[two_pi, 1.0], [-two_pi, -1.0], [two_pi, 0.6]] {
        let model = crate::problem::model::Discrete::new(cfg.system.clone(), cfg.ocp.ts, 1);
        let mut next = [0.0; 2];
        let u_best = if xs[1] > 0.0 {
            cfg.ocp.u_lo[0]
        } else {
            cfg.ocp.u_hi[0]
        };
        model.step(&xs, &[u_best], &mut next);
        assert!(next[0].abs() > two_pi, "premise: {xs:?} is infeasible");
        let (l, _) = MpcLaw::new(&cfg).solve(&xs, None);
        assert_eq!(l.status, SqpStatus::Soft, "{xs:?}");
        assert!(
            l.max_slack > SLACK_TOL && l.u[0].is_finite() && l.du_dx.iter().all(|v| v.is_finite())
        );
        let mut off = cfg.clone();
        off.solver.soft_fallback = false;
        let (l, _) = MpcLaw::new(&off).solve(&xs, None);
        assert_eq!(l.status, SqpStatus::Infeasible, "{xs:?}");
        assert!(l.u[0].is_nan());
    }
    // A feasible state next to the corner stays a hard optimum.
    let (l, _) = MpcLaw::new(&cfg).solve(&[two_pi - 0.2, 0.3], None);
    assert_eq!(l.status, SqpStatus::Converged);
}

#[test]
fn non_finite_state_is_a_status_not_a_panic() {
    let cfg = ProblemConfig::default();
    let mut law = MpcLaw::new(&cfg);
    for xs in [[f64::NAN, 0.0], [0.0, f64::INFINITY]] {
        let (l, s) = law.solve(&xs, None);
        assert_eq!(l.status, SqpStatus::NumericalFailure);
        assert!(s.is_none());
    }
    // Far outside X (but finite): still a defined status, no panic.
    let (l, _) = law.solve(&[100.0, -50.0], None);
    assert!(matches!(
        l.status,
        SqpStatus::Soft
            | SqpStatus::Converged
            | SqpStatus::MaxIterations
            | SqpStatus::NumericalFailure
    ));
}

#[test]
fn cartpole_converges_on_its_domain() {
    let cfg = load("cartpole.toml");
    let mut law = MpcLaw::new(&cfg);
    for i in 0..30 {
        let x = random_state(&cfg, 41, i);
        let (l, _) = law.solve(&x, None);
        assert_eq!(l.status, SqpStatus::Converged, "{x:?}: {:?}", l.info);
    }
}

/// On the boundary between saturated and unsaturated u0 the input bound is weakly active
/// (u0 at its bound with a zero multiplier): found by bisection along a line, the state
/// must be flagged `WeaklyActive`, while states on either side are plain derivatives.
#[test]
fn weakly_active_bound_is_flagged_degenerate() {
    use crate::mpc::sensitivity::Degeneracy;
    let cfg = load("double_integrator.toml");
    let mut law = MpcLaw::new(&cfg);
    let u_hi = cfg.ocp.u_hi[0];
    let at = |law: &mut MpcLaw, t: f64| law.solve(&[-3.0 * t, 0.0], None).0;
    let (mut a, mut b) = (0.0, 1.0); // u0(a) < u_hi, u0(b) = u_hi
    assert!(at(&mut law, a).u[0] < u_hi - 1e-3);
    assert!((at(&mut law, b).u[0] - u_hi).abs() < 1e-8);
    for _ in 0..60 {
        let m = 0.5 * (a + b);
        // Labels are accurate to ~1e-10 (tol 1e-8 on the scaled KKT residual).
        if at(&mut law, m).u[0] >= u_hi - 1e-8 {
            b = m;
        } else {
            a = m;
        }
    }
    let l = at(&mut law, b);
    assert_eq!(l.status, SqpStatus::Converged);
    assert!(
        matches!(l.degeneracy, Some(Degeneracy::WeaklyActive(_))),
        "{:?} u {}",
        l.degeneracy,
        l.u[0]
    );
    assert_eq!(at(&mut law, 0.5 * b).degeneracy, None);
    assert_eq!(at(&mut law, (1.5 * b).min(1.0)).degeneracy, None);
}
