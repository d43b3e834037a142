//! Checks of the `[ocp]` path and terminal constraints (tests only): a constraint that says
//! the same as a box gives the box's labels (linear and nonlinear forms), first-order
//! optimality recomputed from scratch with the constraint functions evaluated directly and
//! differentiated by finite differences, sensitivities against finite differences of the
//! solver where curved constraints are active, both QP backends agreeing, and the soft
//! fallback on the new rows.

use super::random_state;
use crate::mpc::law::{MpcLaw, SLACK_TOL};
use crate::mpc::sqp::SqpStatus;
use crate::problem::{ProblemConfig, QpSolverKind};
use crate::rng::uniform;
use nalgebra::{DMatrix, DVector};

/// The double integrator written as an ODE, the speed within ±0.3 either as boxes or as the
/// given constraints; from far away the optimal trajectory runs at the speed limit.
fn double_integrator(boxes: bool, constraints: &[&str]) -> ProblemConfig {
    let (x_lo, x_hi) = if boxes {
        ("[-5.0, -0.3]", "[5.0, 0.3]")
    } else {
        ("[-5.0, -inf]", "[5.0, inf]")
    };
    let list: Vec<String> = constraints.iter().map(|c| format!("{c:?}")).collect();
    let text = format!(
        r#"
name = "di_constraints"
[system]
kind = "ode"
states = ["position", "velocity"]
inputs = ["force"]
rhs = ["velocity", "force"]
[ocp]
ts = 0.1
horizon = 20
q = [1.0, 0.1]
r = [0.1]
p = [1.0, 0.1]
x_lo = {x_lo}
x_hi = {x_hi}
u_lo = [-1.0]
u_hi = [1.0]
constraints = [{}]
[domain]
lo = [-3.0, -0.3]
hi = [3.0, 0.3]
"#,
        list.join(", ")
    );
    ProblemConfig::from_toml_str(&text, "test").unwrap()
}

/// The pendulum as an ODE with a curved state constraint, a mixed state–input constraint
/// and a terminal region.
fn pendulum_curved() -> ProblemConfig {
    let text = r#"
name = "pendulum_curved"
[system]
kind = "ode"
states = ["theta", "omega"]
inputs = ["u"]
parameters = { m = 1.0, l = 1.0, g = 9.81 }
rhs = ["omega", "u/(m*l^2) - g/l*sin(theta + pi)"]
[ocp]
ts = 0.05
horizon = 20
q = [10.0, 1.0]
r = [0.1]
p = [10.0, 1.0]
x_lo = [-6.3, -inf]
x_hi = [6.3, inf]
u_lo = [-15.0]
u_hi = [15.0]
constraints = ["theta^2/4 + omega^2 <= 4", "omega*u <= 6"]
terminal_constraints = ["theta^2 + omega^2 <= 0.01"]
[domain]
lo = [-2.0, -1.5]
hi = [2.0, 1.5]
"#;
    ProblemConfig::from_toml_str(text, "test").unwrap()
}

/// Labels of two problems that describe the same feasible set agree; returns how many
/// states were compared and at how many a constraint row of `b` was active.
fn same_labels(a: &ProblemConfig, b: &ProblemConfig, n: u64) -> (usize, usize) {
    let (mut la, mut lb) = (MpcLaw::new(a), MpcLaw::new(b));
    let (mut compared, mut active) = (0, 0);
    for i in 0..n {
        let x = random_state(a, 5, i);
        let (ya, _) = la.solve(&x, None);
        let (yb, _) = lb.solve(&x, None);
        assert_eq!(ya.status, yb.status, "{x:?}");
        if ya.status != SqpStatus::Converged || ya.degeneracy.is_some() {
            continue;
        }
        let scale = ya.du_dx.iter().fold(1.0f64, |m, v| m.max(v.abs()));
        assert!(
            (ya.u[0] - yb.u[0]).abs() <= 1e-8,
            "{x:?}: u {} vs {}",
            ya.u[0],
            yb.u[0]
        );
        for (p, q) in ya.du_dx.iter().zip(&yb.du_dx) {
            assert!((p - q).abs() <= 1e-7 * scale, "{x:?}: du/dx {p} vs {q}");
        }
        assert!((ya.cost - yb.cost).abs() <= 1e-8 * (1.0 + ya.cost.abs()));
        compared += 1;
        let ocp = &lb.hard_solver().ocp;
        if yb
            .active
            .iter()
            .any(|&r| ocp.constraint_rows().contains(&r))
        {
            active += 1;
        }
    }
    (compared, active)
}

#[test]
fn linear_constraint_gives_the_box_labels() {
    let boxed = double_integrator(true, &[]);
    let linear = double_integrator(false, &["velocity <= 0.3", "-0.3 <= velocity"]);
    let (compared, active) = same_labels(&boxed, &linear, 60);
    assert!(compared >= 40, "{compared}");
    assert!(active >= 5, "constraint active at only {active} states");
}

#[test]
fn nonlinear_constraint_gives_the_box_labels() {
    // |velocity| ≤ 0.3 written as a curved constraint: at the optimum the active
    // linearisation 2·velocity·Δvelocity = 0 fixes the velocity as the box does.
    let boxed = double_integrator(true, &[]);
    let curved = double_integrator(false, &["velocity^2 <= 0.09"]);
    let c = curved.constraint_set().unwrap().unwrap();
    assert!(!c.items[0].affine);
    let (compared, active) = same_labels(&boxed, &curved, 60);
    assert!(compared >= 40, "{compared}");
    assert!(active >= 5, "constraint active at only {active} states");
}

/// An inequality `f(z) ≤ 0` of the transcribed problem.
type Ineq = Box<dyn Fn(&[f64]) -> f64>;

/// Stationarity, feasibility and multiplier signs at the optimum, recomputed from the
/// problem functions only: objective, dynamics and g evaluated directly, all derivatives by
/// central differences, multipliers by least squares.
#[test]
fn curved_optimum_satisfies_first_order_conditions_independently() {
    let cfg = pendulum_curved();
    let cs = cfg.constraint_set().unwrap().unwrap();
    let mut law = MpcLaw::new(&cfg);
    let (nx, nu, n) = (2, 1, cfg.ocp.horizon);
    let mut checked_curved = 0;
    for i in 0..30 {
        let x = random_state(&cfg, 41, i);
        let (l, sol) = law.solve(&x, None);
        if l.status != SqpStatus::Converged {
            continue;
        }
        let z = sol.unwrap().z;
        let ocp = &law.hard_solver().ocp;
        // Every inequality as a function of z: the boxes, and g_i at its stages.
        let mut funcs: Vec<Ineq> = Vec::new();
        for k in 1..=n {
            let ix = k * (nx + nu);
            funcs.push(Box::new(move |z: &[f64]| z[ix] - 6.3));
            funcs.push(Box::new(move |z: &[f64]| -6.3 - z[ix]));
        }
        for k in 0..n {
            let iu = k * (nx + nu) + nx;
            funcs.push(Box::new(move |z: &[f64]| z[iu] - 15.0));
            funcs.push(Box::new(move |z: &[f64]| -15.0 - z[iu]));
        }
        let mut curved = Vec::new();
        for (ci, stages) in [(0, 1..n + 1), (1, 1..n), (2, n..n + 1)] {
            for k in stages {
                let cs = cs.clone();
                let off = k * (nx + nu);
                curved.push(funcs.len());
                funcs.push(Box::new(move |z: &[f64]| {
                    let u = if k < n { [z[off + nx]] } else { [0.0] };
                    let mut g = [0.0; 3];
                    cs.values(&z[off..off + nx], &u, &mut g);
                    g[ci]
                }));
            }
        }
        let nv = ocp.n_var;
        let h = 1e-6;
        let mut grad = DVector::zeros(nv);
        let mut jac = DMatrix::zeros(ocp.n_eq, nv);
        let (mut cp, mut cm) = (vec![0.0; ocp.n_eq], vec![0.0; ocp.n_eq]);
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
        for f in &funcs {
            assert!(f(&z) <= 1e-8, "{x:?}: constraint violated by {}", f(&z));
        }
        let active: Vec<usize> = (0..funcs.len()).filter(|&r| funcs[r](&z) > -1e-7).collect();
        let m = ocp.n_eq + active.len();
        let mut a = DMatrix::zeros(nv, m);
        a.view_mut((0, 0), (nv, ocp.n_eq))
            .copy_from(&jac.transpose());
        for (t, &r) in active.iter().enumerate() {
            for j in 0..nv {
                let (mut zp, mut zm) = (z.clone(), z.clone());
                zp[j] += h;
                zm[j] -= h;
                a[(j, ocp.n_eq + t)] = (funcs[r](&zp) - funcs[r](&zm)) / (2.0 * h);
            }
        }
        let mult = a.clone().svd(true, true).solve(&(-&grad), 1e-12).unwrap();
        let res = &grad + &a * &mult;
        let scale = grad.amax().max(1.0);
        assert!(
            res.amax() <= 1e-5 * scale,
            "{x:?}: stationarity {}",
            res.amax()
        );
        for t in 0..active.len() {
            assert!(
                mult[ocp.n_eq + t] >= -1e-5 * scale,
                "{x:?}: multiplier {}",
                mult[ocp.n_eq + t]
            );
        }
        if active.iter().any(|r| curved.contains(r)) {
            checked_curved += 1;
        }
    }
    assert!(
        checked_curved >= 10,
        "curved constraints active at only {checked_curved} optima"
    );
}

/// ∂κ/∂x against central differences of the solver where curved constraints are active:
/// a missing curvature term ν∇²g in the KKT matrix would show here.
#[test]
fn curved_sensitivity_matches_finite_differences() {
    let cfg = pendulum_curved();
    let mut law = MpcLaw::new(&cfg);
    let h = 1e-6;
    let mut checked = 0;
    for i in 0..40 {
        let x = random_state(&cfg, 43, i);
        let (l, _) = law.solve(&x, None);
        if l.status != SqpStatus::Converged || l.degeneracy.is_some() {
            continue;
        }
        let ocp = &law.hard_solver().ocp;
        let curved_active = l
            .active
            .iter()
            .any(|&r| ocp.nonlinear_rows().any(|q| q == r));
        let mut fd = [0.0; 2];
        let mut smooth = true;
        for j in 0..2 {
            let (mut xp, mut xm) = (x.clone(), x.clone());
            xp[j] += h;
            xm[j] -= h;
            let (lp, _) = law.solve(&xp, None);
            let (lm, _) = law.solve(&xm, None);
            let (fwd, bwd) = ((lp.u[0] - l.u[0]) / h, (l.u[0] - lm.u[0]) / h);
            if lp.status != SqpStatus::Converged
                || lm.status != SqpStatus::Converged
                || (fwd - bwd).abs() > 1e-3 * (1.0 + fwd.abs())
            {
                smooth = false;
                break;
            }
            fd[j] = (lp.u[0] - lm.u[0]) / (2.0 * h);
        }
        if !smooth || !curved_active {
            continue;
        }
        let scale = fd
            .iter()
            .chain(&l.du_dx)
            .fold(1.0f64, |m, v| m.max(v.abs()));
        for j in 0..2 {
            assert!(
                (fd[j] - l.du_dx[j]).abs() <= 1e-5 * scale,
                "{x:?}: du/dx{j} fd {} vs kkt {}",
                fd[j],
                l.du_dx[j]
            );
        }
        checked += 1;
    }
    assert!(
        checked >= 8,
        "only {checked} states with active curved constraints checked"
    );
}

#[test]
fn both_qp_backends_agree_with_constraints() {
    let cfg = pendulum_curved();
    let mut other = cfg.clone();
    other.solver.qp = QpSolverKind::Clarabel;
    let (mut a, mut b) = (MpcLaw::new(&cfg), MpcLaw::new(&other));
    let mut compared = 0;
    for i in 0..20 {
        let x = random_state(&cfg, 47, i);
        let (la, _) = a.solve(&x, None);
        let (lb, _) = b.solve(&x, None);
        assert_eq!(la.status, lb.status, "{x:?}");
        if !la.status.is_labelled() {
            continue;
        }
        assert!(
            (la.u[0] - lb.u[0]).abs() <= 1e-6 * (1.0 + la.u[0].abs()),
            "{x:?}"
        );
        assert!(
            (la.cost - lb.cost).abs() <= 1e-6 * (1.0 + la.cost.abs()),
            "{x:?}"
        );
        compared += 1;
    }
    assert!(compared >= 15, "{compared}");
}

/// From θ = 1.9, ω = 1.4 the path constraint θ²/4 + ω² ≤ 1 cannot hold at x₁ whatever the
/// input (checked on a grid of inputs: x₁'s angle is ≈ 1.97 and its rate ≥ 1.1): the hard
/// problem is infeasible, the soft one labels the state with a positive slack.
#[test]
fn infeasible_constraint_gets_a_soft_label() {
    let mut cfg = pendulum_curved();
    cfg.ocp.constraints[0] = "theta^2/4 + omega^2 <= 1".into();
    cfg.validate().unwrap();
    let x = [1.9, 1.4];
    // Premise: g(x₁) > 0 for every admissible input.
    let model = crate::problem::model::Discrete::new(cfg.system.clone(), cfg.ocp.ts, 1);
    for t in 0..=300 {
        let u = -15.0 + 0.1 * t as f64;
        let mut next = [0.0; 2];
        model.step(&x, &[u], &mut next);
        let g = next[0] * next[0] / 4.0 + next[1] * next[1] - 1.0;
        assert!(g > 0.1, "premise at u = {u}: {next:?}");
    }
    let (l, _) = MpcLaw::new(&cfg).solve(&x, None);
    assert_eq!(l.status, SqpStatus::Soft);
    assert!(l.max_slack > SLACK_TOL && l.u[0].is_finite());
    assert!(l.du_dx.iter().all(|v| v.is_finite()));
    let mut off = cfg.clone();
    off.solver.soft_fallback = false;
    let (l, _) = MpcLaw::new(&off).solve(&x, None);
    assert_eq!(l.status, SqpStatus::Infeasible);
}

/// A hard-infeasible state of the unseen ball-and-beam (`tests/reference/ball_beam_unseen.toml`:
/// nonlinear and mixed path constraints, 2 RK4 sub-steps; IPOPT reports
/// `Infeasible_Problem_Detected` here): the soft problem's multipliers reach the slack weight
/// (~1e4); with the blockwise Hessian rule (which drops their curvature λᵀ∇²F) the soft
/// SQP crawls to its iteration limit and the whole retry ladder fails (2 s, no label).
/// The plain solve must label it: soft, a positive slack, the KKT residual within `tol`, in
/// a few dozen iterations.
#[test]
fn infeasible_ball_beam_state_gets_a_soft_label_without_the_ladder() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../tests/reference/ball_beam_unseen.toml"
    );
    let cfg = ProblemConfig::load(std::path::Path::new(path)).unwrap();
    let x = [
        -2.814682050982047e-1,
        -3.9515341285287253e-1,
        3.054357250458669e-1,
        3.6172018218196256e-1,
    ];
    let (l, _) = MpcLaw::new(&cfg).solve(&x, None);
    assert_eq!(l.status, SqpStatus::Soft, "{:?}", l.info);
    assert_eq!(l.retry, None);
    assert!(l.max_slack > SLACK_TOL, "{}", l.max_slack);
    assert!(l.info.kkt.max() <= cfg.solver.tol, "{:?}", l.info.kkt);
    assert!(l.info.iterations <= 40, "{:?}", l.info);
    assert!(l.u.iter().chain(&l.du_dx).all(|v| v.is_finite()));
}

/// A hard-infeasible state of the Gymnasium cart-pole with a curved speed–force constraint and
/// a terminal region (`tests/reference/cartpole_public_nl.toml`): the soft SQP's full steps
/// were rejected by the ℓ₁ merit under a penalty μ ≈ 2·10⁵ (the Maratos effect; steps of
/// 1/16–1/128 to the iteration limit, then the ladder failed too). With the second-order
/// correction the plain solve gives it a soft label.
#[test]
fn maratos_state_gets_a_soft_label_with_the_second_order_correction() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../tests/reference/cartpole_public_nl.toml"
    );
    let cfg = ProblemConfig::load(std::path::Path::new(path)).unwrap();
    let x = [
        -1.2199507514152268,
        1.4509271241882833,
        0.0934950945540256,
        0.7091021636711219,
    ];
    let (l, _) = MpcLaw::new(&cfg).solve(&x, None);
    assert_eq!(l.status, SqpStatus::Soft, "{:?}", l.info);
    assert_eq!(l.retry, None);
    assert!(l.max_slack > SLACK_TOL, "{}", l.max_slack);
    assert!(l.info.kkt.max() <= cfg.solver.tol, "{:?}", l.info.kkt);
    assert!(l.u.iter().chain(&l.du_dx).all(|v| v.is_finite()));
}

/// `shift_for_correction` moves each nonlinear row's right-hand side by the remainder
/// `g(z + d) − g(z) − ∇g(z)ᵀd` (g evaluated directly, ∇g by central differences) and
/// `restore_rhs` undoes it; affine rows do not move.
#[test]
fn correction_shift_is_the_linearisation_remainder() {
    let cfg = pendulum_curved();
    let mut ocp = crate::mpc::ocp::Ocp::new(&cfg, true);
    let n = ocp.n_var;
    let z: Vec<f64> = (0..n)
        .map(|i| 0.3 * uniform(5, i as u64, 0) - 0.1)
        .collect();
    let d: Vec<f64> = (0..n)
        .map(|i| 0.2 * uniform(6, i as u64, 0) - 0.1)
        .collect();
    ocp.relinearize(&z);
    let before: Vec<f64> = ocp.rows.iter().map(|r| r.rhs).collect();
    let saved = ocp.shift_for_correction(&z, &d);
    let nl: Vec<usize> = ocp.nonlinear_rows().collect();
    assert!(!nl.is_empty());
    // g_r(w) = −(slack of row r at w after relinearising at w, without its slack entry):
    // read through a clone relinearised at w.
    let g_of = |w: &[f64], r: usize| {
        let mut o = crate::mpc::ocp::Ocp::new(&cfg, true);
        o.relinearize(w);
        let row = o.rows[r];
        let s: f64 = (0..row.len)
            .filter(|&j| row.idx[j] >= o.is())
            .map(|j| row.coef[j] * w[row.idx[j]])
            .sum();
        -(row.rhs - (row.dot(w) - s))
    };
    let zd: Vec<f64> = z.iter().zip(&d).map(|(a, b)| a + b).collect();
    let mut largest = 0.0f64;
    for (r, row) in ocp.rows.iter().enumerate() {
        if !nl.contains(&r) {
            assert_eq!(row.rhs, before[r], "affine row {r} moved");
            continue;
        }
        // ∇g(z)ᵀd by a central difference along d.
        let h = 1e-6;
        let zp: Vec<f64> = z.iter().zip(&d).map(|(a, b)| a + h * b).collect();
        let zm: Vec<f64> = z.iter().zip(&d).map(|(a, b)| a - h * b).collect();
        let lin = (g_of(&zp, r) - g_of(&zm, r)) / (2.0 * h);
        let rem = g_of(&zd, r) - g_of(&z, r) - lin;
        let moved = before[r] - row.rhs;
        largest = largest.max(rem.abs());
        assert!(
            (moved - rem).abs() <= 1e-7 * (1.0 + rem.abs()),
            "row {r}: {moved} vs {rem}"
        );
    }
    assert!(
        largest > 1e-5,
        "the remainders are all ≈ 0 ({largest}): no check"
    );
    ocp.restore_rhs(&saved);
    assert!(ocp.rows.iter().zip(&before).all(|(r, b)| r.rhs == *b));
}

/// The robust design's margins reach the OCP: the row of an affine mixed constraint at
/// stage 1 has b − margin (`robust` computes the margins, `mpc` builds the rows from them).
#[test]
fn robust_margins_reach_the_ocp_rows() {
    let cfg = crate::robust::tests::di_mixed_constraints();
    let d = crate::robust::design(&cfg).unwrap();
    let rc = crate::robust::robust_config(&cfg, &d);
    let ocp = crate::mpc::ocp::Ocp::new(&rc, false);
    let rhs: Vec<f64> = ocp
        .constraint_rows()
        .iter()
        .map(|&r| ocp.rows[r].rhs)
        .collect();
    let want = 2.0 - d.stages.margins[1][1];
    assert!(
        rhs.iter().any(|h| (h - want).abs() < 1e-12),
        "no row with rhs {want}: {rhs:?}"
    );
}
