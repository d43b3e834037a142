//! Tests of the closed-loop simulation (`super`): where each constraint is checked, runs
//! that diverge, the stop box, a network's plain-solve reference, the MPC's swing-up.

use super::*;

/// Each kind of constraint is checked where the OCP places it: states only at x_{k+1},
/// inputs only at u_k, both at (x_k, u_k) from k = 1, terminal never; boxes as before.
#[test]
fn step_violation_places_each_constraint() {
    let mut cfg = ProblemConfig::default();
    cfg.ocp.constraints = vec![
        "omega <= 0.5".into(),
        "u <= 2".into(),
        "theta + u <= 1".into(),
    ];
    cfg.ocp.terminal_constraints = vec!["theta^2 <= 0.01".into()];
    cfg.validate().unwrap();
    let cs = cfg.constraint_set().unwrap();
    let v = |k: usize, x: [f64; 2], u: f64, next: [f64; 2]| {
        step_violation(&cfg, cs.as_ref(), k, &x, &[u], &next)
    };
    let ok = [0.0, 0.0];
    assert_eq!(v(3, ok, 0.0, ok), 0.0);
    // ω only counts at the next state; the measured state is not constrained.
    assert_eq!(v(3, [0.0, 0.9], 0.0, ok), 0.0);
    assert!((v(3, ok, 0.0, [0.0, 0.9]) - 0.4).abs() < 1e-12);
    // input-only at every step, including the first.
    assert!((v(0, ok, 2.5, ok) - 0.5).abs() < 1e-12);
    // mixed: θ_k + u_k ≤ 1 from k = 1 on.
    assert_eq!(v(0, [0.8, 0.0], 1.0, ok), 0.0);
    assert!((v(1, [0.8, 0.0], 1.0, ok) - 0.8).abs() < 1e-12);
    // the terminal region is not a closed-loop constraint; boxes still are.
    assert_eq!(v(5, ok, 0.0, [0.5, 0.0]), 0.0);
    assert!((v(5, ok, 0.0, [7.0, 0.0]) - (7.0 - 2.0 * std::f64::consts::PI)).abs() < 1e-12);
}

/// A plant that turns NaN along the trajectory (`0·sqrt(θ − 1)`, the state falling below
/// θ = 1) ends the run at that step with a defined status: every recorded number finite,
/// no NaN (or `null`) in the JSON, the step counted as violating, never settled. Before,
/// the run carried NaN to its end and `step_violation` read a NaN state as no violation.
#[test]
fn a_non_finite_state_ends_the_run_with_a_status() {
    let cfg = crate::mpc::tests::finite_checks::pendulum_with(
        "u/(m*l^2) - g/l*sin(theta + pi) + 0*sqrt(theta - 1)",
        "m = 1.0, l = 1.0, g = 9.81",
    );
    let nan = [f64::NAN, 0.0];
    assert_eq!(
        step_violation(&cfg, None, 3, &[0.0, 0.0], &[0.0], &nan),
        f64::INFINITY
    );
    let mut law = MpcLaw::new(&cfg);
    let s = SimSettings {
        steps: 30,
        noise: vec![],
        seed: 0,
        mass_mismatch: 0.0,
        mismatch_parameter: None,
        disturbance: Disturbance::None,
    };
    let r = simulate(&cfg, &mut law, &Controller::Mpc, &[1.2, -1.0], &s);
    let stop = r.stopped.clone().expect("the run stops at the NaN state");
    assert!(stop.step < 30 && r.steps == stop.step, "{stop:?}");
    assert_eq!(r.x.len(), stop.step + 1);
    assert_eq!(r.u.len(), stop.step);
    assert!(r.violation_steps >= 1);
    assert_eq!(r.settling_step, None);
    let nums = r.x.iter().flatten().chain(r.u.iter().flatten());
    assert!(nums.chain(&r.final_offset).all(|v| v.is_finite()), "{r:?}");
    assert!(r.cost.is_finite() && r.max_violation.is_finite());
    // (serde_json writes a NaN or ∞ as `null`; `settling_step` is the only optional.)
    let mut v = serde_json::to_value(&r).unwrap();
    v.as_object_mut().unwrap().remove("settling_step");
    let json = v.to_string();
    assert!(!json.contains("null") && !json.contains("NaN,"), "{json}");
}

/// The stop box is the hull of X and the finite state bounds widened by ten widths of
/// X, checked on numbers worked by hand: an infinite bound leaves X's side alone.
#[test]
fn stop_box_widens_the_hull_by_ten_widths() {
    let mut cfg = ProblemConfig::default();
    cfg.domain.lo = vec![-1.0, 0.5];
    cfg.domain.hi = vec![3.0, 1.5];
    cfg.ocp.x_lo = vec![-2.0, f64::NEG_INFINITY];
    cfg.ocp.x_hi = vec![2.0, 4.0];
    let (lo, hi) = stop_box(&cfg);
    // axis 1: hull [−2, 3], width of X 4 → [−42, 43]; axis 2: hull [0.5, 4], width 1.
    assert_eq!(lo, vec![-42.0, -9.5]);
    assert_eq!(hi, vec![43.0, 14.0]);
}

/// A network's run solves its divergence reference without the retry ladder and gives
/// the law its budget back: every divergence is ‖κ_plain(x) − κ_NN(x)‖ of a plain solve
/// (worked again here with a law of budget 0 on the recorded states), and an MPC run
/// with the same law afterwards is the run of a fresh law.
#[test]
fn a_network_run_uses_the_plain_solve_and_restores_the_budget() {
    use crate::learn::mlp::Activation;
    let cfg = ProblemConfig::default();
    let (lo, hi) = (&cfg.domain.lo, &cfg.domain.hi);
    let (ulo, uhi) = (&cfg.ocp.u_lo, &cfg.ocp.u_hi);
    let net = Mlp::new(&[2, 8, 1], Activation::Tanh, 5, lo, hi, ulo, uhi);
    let s = SimSettings {
        steps: 12,
        noise: vec![],
        seed: 0,
        mass_mismatch: 0.0,
        mismatch_parameter: None,
        disturbance: Disturbance::None,
    };
    let budget = cfg.solver.retry_budget;
    assert!(budget > 0);
    let mut law = MpcLaw::new(&cfg);
    let x0 = [1.0, 0.3];
    let r = simulate(&cfg, &mut law, &Controller::Net(&net, 1e9, None), &x0, &s);
    assert_eq!(law.set_retry_budget(budget), budget);
    let mut plain = MpcLaw::new(&crate::mpc::law::ladder::counting_problem(&cfg));
    let mut along = Along::default();
    assert_eq!(r.divergence.len(), r.u.len());
    for (k, d) in r.divergence.iter().enumerate() {
        let kappa = plain.solve_next(&r.x[k], &mut along).u;
        let want = (kappa[0] - net.predict(&r.x[k])[0]).abs();
        assert!(
            (d - want).abs() <= 1e-9 * want.max(1.0),
            "step {k}: {d} vs {want}"
        );
    }
    let after = simulate(&cfg, &mut law, &Controller::Mpc, &x0, &s);
    let fresh = simulate(&cfg, &mut MpcLaw::new(&cfg), &Controller::Mpc, &x0, &s);
    assert_eq!(after.u, fresh.u);
}

#[test]
fn mpc_swings_the_pendulum_up_and_respects_bounds() {
    let cfg = ProblemConfig::default();
    let mut law = MpcLaw::new(&cfg);
    let s = SimSettings {
        steps: 90,
        noise: vec![],
        seed: 0,
        mass_mismatch: 0.0,
        mismatch_parameter: None,
        disturbance: Disturbance::None,
    };
    let r = simulate(
        &cfg,
        &mut law,
        &Controller::Mpc,
        &[-std::f64::consts::PI, 0.0],
        &s,
    );
    assert_eq!(r.x.len(), 91);
    assert_eq!(r.mpc_failures, 0);
    assert_eq!(r.violation_steps, 0, "max violation {}", r.max_violation);
    let last = r.x.last().unwrap();
    assert!(last[0].abs() < 0.05 && last[1].abs() < 0.05, "{last:?}");
    assert!(r.settling_step.is_some());
    // The recorded cost is the sum of stage costs of the recorded trajectory.
    let c: f64 = (0..90)
        .map(|k| 10.0 * r.x[k][0].powi(2) + r.x[k][1].powi(2) + 0.1 * r.u[k][0].powi(2))
        .sum();
    assert!((c - r.cost).abs() < 1e-9 * c);
}
