//! Tests of `study::statistical_loop` (included from it with `#[path]`).

use super::*;

/// A controller of constant output.
struct Constant(f64);

impl TestedController for Constant {
    fn input(&self, _: &[f64]) -> Vec<f64> {
        vec![self.0]
    }
    fn describe(&self) -> String {
        format!("u = {}", self.0)
    }
}

/// The i-th start of stream `seed`, written out again.
fn start(cfg: &ProblemConfig, seed: u64, i: u64) -> Vec<f64> {
    (0..2)
        .map(|j| {
            let (lo, hi) = (cfg.domain.lo[j], cfg.domain.hi[j]);
            lo + (hi - lo) * uniform(seed, i, j as u64)
        })
        .collect()
}

/// The pendulum stepped by hand for `n` steps of `law` from `x`: (violated a bound by
/// more than 1e-6, the scaled distance of each state x_0..x_n to the origin).
fn by_hand(
    cfg: &ProblemConfig,
    law: &mut dyn FnMut(&[f64]) -> f64,
    mut x: Vec<f64>,
    n: usize,
) -> (bool, Vec<f64>) {
    let plant = Discrete::new(cfg.system.clone(), cfg.ocp.ts, cfg.ocp.rk4_substeps);
    let scale = cfg.ocp.x_scale_or_default(&cfg.domain.lo, &cfg.domain.hi);
    let dist = |x: &[f64]| (0..2).map(|j| x[j].abs() / scale[j]).fold(0.0, f64::max);
    let (mut bad, mut next, mut d) = (false, vec![0.0; 2], vec![dist(&x)]);
    for _ in 0..n {
        let (lo, hi) = (cfg.ocp.u_lo[0], cfg.ocp.u_hi[0]);
        let u = law(&x);
        let u = if u.is_finite() {
            u.clamp(lo, hi)
        } else {
            0.5 * (lo + hi)
        };
        plant.step(&x, &[u], &mut next);
        bad |= (0..2).any(|j| next[j] > cfg.ocp.x_hi[j] + 1e-6 || next[j] < cfg.ocp.x_lo[j] - 1e-6);
        x.copy_from_slice(&next);
        d.push(dist(&x));
    }
    (bad, d)
}

/// The run length: the configured steps unless the MPC settles slower, then 1.5 × its
/// slowest settling, capped at three times the configured steps.
#[test]
fn run_length_follows_the_slowest_settling() {
    assert_eq!(run_length(90, None), 90);
    assert_eq!(run_length(90, Some(20)), 90);
    assert_eq!(run_length(90, Some(61)), 92);
    assert_eq!(run_length(90, Some(100)), 150);
    assert_eq!(run_length(90, Some(260)), 270);
}

/// Counted against an independent count: every trajectory re-simulated here with the
/// plant stepped by hand, and the bound against the closed form of k = 0.
#[test]
fn counts_match_a_direct_simulation() {
    let mut cfg = ProblemConfig::default();
    cfg.closed_loop.steps = 20;
    for u in [0.0, 15.0] {
        let s = closed_loop_statistical(&cfg, &Constant(u), "model", 20, 7, 0.99);
        assert_eq!(s.seed, statistical_seed("model\0closed loop", 7));
        assert_eq!(s.user_seed, 7);
        assert_eq!(s.steps_configured, 20);
        assert!((20..=60).contains(&s.steps), "{}", s.steps);
        let mut k = 0;
        for i in 0..20u64 {
            let (bad, _) = by_hand(&cfg, &mut |_| u, start(&cfg, s.seed, i), s.steps);
            k += bad as u64;
        }
        assert_eq!(s.all.violating, k, "u = {u}");
        assert_eq!(s.all.trajectories, 20);
        assert!(s.feasible_starts.trajectories <= 20);
        assert!(s.feasible_starts.violating <= s.all.violating);
        if k == 0 {
            assert!((s.all.p_violation_upper - (1.0 - 0.01f64.powf(1.0 / 20.0))).abs() < 1e-12);
        }
    }
    // A constant full torque drives the pendulum's velocity out of its bound from
    // most states: the two inputs cannot both give no violations.
    let full = closed_loop_statistical(&cfg, &Constant(15.0), "model", 20, 7, 0.99);
    assert!(full.all.violating > 0, "{full:?}");
    // Another model: other initial states.
    let other = closed_loop_statistical(&cfg, &Constant(15.0), "other", 20, 7, 0.99);
    assert_ne!(other.seed, full.seed);
}

/// A run that stays inside the constraints but ends far from the setpoint fails; the
/// run length and the MPC's count come from the MPC's own runs on the length draw. All
/// checked against hand-stepped simulations: the MPC's runs of 3 × 4 steps, their
/// settling steps, N = run_length(4, slowest), and every count at N.
#[test]
fn a_run_that_does_not_converge_fails() {
    let mut cfg = ProblemConfig::default();
    cfg.closed_loop.steps = 4;
    let s = closed_loop_statistical(&cfg, &Constant(0.0), "model", 30, 3, 0.99);
    // The MPC from the 30 starts of the length draw, 12 steps each.
    let length_seed = statistical_seed("model\0closed loop length", 3);
    let mut law = MpcLaw::new(&cfg);
    type HandRun = (bool, Vec<f64>);
    let mpc: Vec<(Vec<f64>, HandRun)> = (0..30u64)
        .map(|i| {
            let x0 = start(&cfg, length_seed, i);
            let r = by_hand(&cfg, &mut |x| law.solve(x, None).0.u[0], x0.clone(), 12);
            (x0, r)
        })
        .collect();
    let settle = |d: &[f64]| {
        (d[d.len() - 1] <= CONVERGE_TOL)
            .then(|| (0..d.len()).find(|&k| d[k..].iter().all(|v| *v <= CONVERGE_TOL)))
            .flatten()
    };
    let slowest = mpc.iter().filter_map(|(_, (_, d))| settle(d)).max();
    assert_eq!(s.mpc_slowest_settling, slowest);
    let n = run_length(4, slowest);
    assert_eq!(s.steps, n);
    // The MPC's failures at N (a violation within N steps, or far at step N).
    let mut mpc_failing = 0;
    let mut same = 0;
    for (x0, _) in &mpc {
        let (bad, d) = by_hand(&cfg, &mut |x| law.solve(x, None).0.u[0], x0.clone(), n);
        mpc_failing += u64::from(bad || d[n] > CONVERGE_TOL);
        let (bad, d) = by_hand(&cfg, &mut |_| 0.0, x0.clone(), n);
        same += u64::from(bad || d[n] > CONVERGE_TOL);
    }
    let m = s.mpc_failing.as_ref().unwrap();
    assert_eq!((m.trajectories, m.violating), (30, mpc_failing));
    assert_eq!(s.controller_failing_same, Some(same));
    // The tested starts, N steps of u = 0.
    let (mut failing, mut far) = (0, 0);
    for i in 0..30u64 {
        let (bad, d) = by_hand(&cfg, &mut |_| 0.0, start(&cfg, s.seed, i), n);
        far += u64::from(d[n] > CONVERGE_TOL);
        failing += u64::from(bad || d[n] > CONVERGE_TOL);
    }
    assert!(
        far > 0,
        "a few steps of u = 0 leave most starts far from the origin"
    );
    assert_eq!(s.not_converged, far);
    let f = s.failing.as_ref().unwrap();
    assert_eq!((f.trajectories, f.violating), (30, failing));
    assert!(f.violating > s.all.violating, "{s:?}");
    assert!(f.p_violation_upper >= s.all.p_violation_upper);
    let ff = s.failing_feasible.as_ref().unwrap();
    assert_eq!(ff.trajectories, s.feasible_starts.trajectories);
    assert!(ff.violating >= s.feasible_starts.violating);
    assert!(s.convergence.contains("within 0.05"), "{}", s.convergence);
}

/// A reference run stopped at rest ([`REST_TOL`]) is the full run where it matters: on
/// MPC runs of the pendulum from the length draw, each simulated for the whole cap, the
/// real states after the rest point stay within [`CONVERGE_TOL`] and violate nothing
/// more, so the settling step and the outcome at every length are the same. The starts
/// that come to rest save most of their steps.
#[test]
fn a_run_at_rest_is_the_full_run() {
    let cfg = ProblemConfig::default();
    let plant = Discrete::new(cfg.system.clone(), cfg.ocp.ts, cfg.ocp.rk4_substeps);
    let cap = LENGTH_CAP * cfg.closed_loop.steps;
    let seed = statistical_seed("model\0closed loop length", 3);
    let (mut rested, mut saved) = (0, 0);
    for i in 0..6u64 {
        let x0 = uniform_start(&cfg, seed, i);
        let run = |rest: Option<f64>| {
            let mut law = MpcLaw::new(&cfg);
            let mut along = crate::mpc::law::along::Along::default();
            let mut solves = 0;
            let t = trace_of(
                &cfg,
                &plant,
                &mut |x| {
                    solves += 1;
                    law.solve_next(x, &mut along).u
                },
                &x0,
                (cap, rest),
            );
            (t, solves)
        };
        let ((full, n_full), (short, n_short)) = (run(None), run(Some(REST_TOL)));
        assert_eq!(full.len(), short.len());
        assert_eq!(
            settling(&cfg, &x0, &full),
            settling(&cfg, &x0, &short),
            "{x0:?}"
        );
        for n in [1, cfg.closed_loop.steps, cap / 2, cap] {
            let (a, b) = (outcome(&cfg, &x0, &full, n), outcome(&cfg, &x0, &short, n));
            assert_eq!(fails(a), fails(b), "{x0:?} at {n}");
            assert_eq!(a.0, b.0, "{x0:?} at {n}");
        }
        if let Some(k) = short.iter().position(|r| r.1 <= REST_TOL) {
            rested += 1;
            saved += n_full - n_short;
            assert_eq!(n_short, k + 1);
            assert!(full[k..].iter().all(|r| r.1 <= CONVERGE_TOL), "{x0:?}");
        }
    }
    assert!(
        rested >= 3 && saved > cap,
        "{rested} at rest, {saved} solves saved"
    );
}

/// The setpoint offset: u = 0 holds the upright pendulum at the origin (offset at
/// rounding level: sin(0 + π) is 1.2e-16 in f64); a constant torque of 1 pushes it away
/// (the offset is the hand-stepped distance, above the tolerance): such a controller
/// cannot converge.
#[test]
fn the_setpoint_offset_is_the_run_from_x_ref() {
    let mut cfg = ProblemConfig::default();
    cfg.closed_loop.steps = 10;
    let held = closed_loop_statistical(&cfg, &Constant(0.0), "model", 2, 1, 0.99);
    let held_off = held.setpoint_offset.unwrap();
    assert!(held_off < 1e-12, "{held_off}");
    let pushed = closed_loop_statistical(&cfg, &Constant(1.0), "model", 2, 1, 0.99);
    let n = pushed.steps;
    let (_, d) = by_hand(&cfg, &mut |_| 1.0, vec![0.0, 0.0], n);
    let off = pushed.setpoint_offset.unwrap();
    assert!(off > CONVERGE_TOL, "{off}");
    assert!(
        (off - d[n]).abs() <= 1e-12 * d[n].max(1.0),
        "{off} vs {}",
        d[n]
    );
}

/// Where a run evaluated the controller, against the pendulum stepped by hand: the box of
/// x_0 … x_{n−1} and whether one of them lies outside X (a full torque from rest leaves X
/// as ω grows past 1; no torque at the origin stays there); the run counts and the box of
/// `closed_loop_statistical` are those of its runs.
#[test]
fn runs_that_leave_x_are_counted_with_their_reach() {
    let cfg = ProblemConfig::default();
    let plant = Discrete::new(cfg.system.clone(), cfg.ocp.ts, cfg.ocp.rk4_substeps);
    let n = 10;
    let mut lefts = Vec::new();
    for (u, x0) in [(15.0, [0.0, 0.0]), (0.0, [0.0, 0.0]), (-15.0, [1.0, 0.5])] {
        let (_, r) = trajectory_reach(&cfg, &plant, &Constant(u), &x0, n);
        let (mut x, mut next) = (x0.to_vec(), vec![0.0; 2]);
        let (mut lo, mut hi, mut left) = (x0.to_vec(), x0.to_vec(), false);
        for _ in 0..n {
            for j in 0..2 {
                lo[j] = lo[j].min(x[j]);
                hi[j] = hi[j].max(x[j]);
                left |= x[j] < cfg.domain.lo[j] || x[j] > cfg.domain.hi[j];
            }
            let u = u.clamp(cfg.ocp.u_lo[0], cfg.ocp.u_hi[0]);
            plant.step(&x, &[u], &mut next);
            x.copy_from_slice(&next);
        }
        assert_eq!((r.left, &r.lo, &r.hi), (left, &lo, &hi), "u = {u}");
        lefts.push(left);
    }
    assert_eq!(lefts, [true, false, true]);
    // The aggregate over the statistical runs.
    let mut cfg = ProblemConfig::default();
    cfg.closed_loop.steps = 20;
    let s = closed_loop_statistical(&cfg, &Constant(15.0), "model", 20, 7, 0.99);
    let (mut left, mut failing_left) = (0, 0);
    let mut reach: Option<Reach> = None;
    for i in 0..20u64 {
        let (r, w) = trajectory_reach(
            &cfg,
            &plant,
            &Constant(15.0),
            &start(&cfg, s.seed, i),
            s.steps,
        );
        left += u64::from(w.left);
        failing_left += u64::from(w.left && fails(r));
        reach = Some(reach.map_or(w.clone(), |a| a.join(&w)));
    }
    assert!(left > 0);
    assert_eq!(s.left_domain, Some(left));
    assert_eq!(s.failing_left_domain, Some(failing_left));
    let reach = reach.unwrap();
    assert_eq!(s.reach, Some((reach.lo, reach.hi)));
}
