//! Unit tests of [`super::SafeController`] on the hand-written double integrator.
#![allow(clippy::indexing_slicing, clippy::unwrap_used)] // test code

use super::example::DoubleIntegrator as Di;
use super::*;
use crate::layer::Dense;

const N: usize = 10;
const M: Margins = Margins {
    stage: 1e-4,
    terminal: 1e-4,
};

/// No network: the tests pass candidates to `step_with`.
struct NoSource;

type Ctl = SafeController<Di, NoSource, 2, 1, N>;

fn ctl() -> Ctl {
    SafeController::new(Di, NoSource, M)
}

/// The saturated terminal controller simulated from `x`: u_k = Π_U(K x_k).
fn saturated_k(x: [f32; 2], delay: usize) -> [[f32; 1]; N] {
    let mut s = [[0.0; 1]; N];
    let mut xk = x;
    for (k, u) in s.iter_mut().enumerate() {
        if k >= delay {
            *u = Di.project_input(&Di.terminal_input(&xk));
        }
        xk = Di.step(&xk, u);
    }
    s
}

/// Four (`n`) full brakes u = −1, then the saturated κ_f, simulated from `x`.
fn brake_then_k(x: [f32; 2], n: usize) -> [[f32; 1]; N] {
    let mut v = [[-1.0]; N];
    let mut xn = x;
    for u in &v[..n] {
        xn = Di.step(&xn, u);
    }
    v[n..].copy_from_slice(&saturated_k(xn, 0)[..N - n]);
    v
}

#[test]
fn check_accepts_rest_and_rejects_each_kind_of_violation() {
    let c = ctl();
    assert_eq!(
        c.check(&[0.0, 0.0], &mut [[0.0]; N], false),
        Check {
            feasible: true,
            cost: 0.0
        }
    );
    // Input bound, exact: the saturated sequence passes, 1e-4 beyond the bound fails.
    let mut v = saturated_k([1.0, 0.0], 0);
    assert_eq!(v[0], [-1.0]);
    assert!(c.check(&[1.0, 0.0], &mut v, false).feasible);
    v[0] = [-1.0001];
    assert!(!c.check(&[1.0, 0.0], &mut v, false).feasible);
    // The state box binds from x_1 on (|v| > 2 at x_1), not at the measured x_0.
    assert!(!c.check(&[0.0, 2.1], &mut [[0.0]; N], false).feasible);
    let mut v = brake_then_k([-2.0, 2.1], 4);
    assert!(
        c.check(&[-2.0, 2.1], &mut v, false).feasible,
        "x_1 = (…, 1.6)"
    );
    // The margin: a velocity at x_1 2.5e-5 inside its bound passes without it, fails with it.
    let x = [-3.0, 1.99995];
    let loose = SafeController::<_, _, 2, 1, N>::new(
        Di,
        NoSource,
        Margins {
            stage: 0.0,
            terminal: 0.0,
        },
    );
    // u_0 = 0 keeps v = 1.99995 at x_1; four full brakes; then the saturated κ_f.
    let mut v = [[-1.0]; N];
    v[0] = [0.0];
    let mut x5 = x;
    for u in &v[..5] {
        x5 = Di.step(&x5, u);
    }
    v[5..].copy_from_slice(&saturated_k(x5, 0)[..N - 5]);
    assert!(loose.check(&x, &mut v, false).feasible);
    assert!(!c.check(&x, &mut v, false).feasible);
    // The cost is Σ ℓ + V_f along the simulated trajectory.
    let mut v = saturated_k([1.0, 0.0], 0);
    let r = c.check(&[1.0, 0.0], &mut v, false);
    assert!(r.feasible);
    let (mut x, mut j) = ([1.0f32, 0.0], 0.0f32);
    for u in &v {
        j += Di.stage_cost(&x, u);
        x = Di.step(&x, u);
    }
    assert_eq!(r.cost, j + Di.terminal_cost(&x));
}

#[test]
fn complete_writes_the_terminal_controller_into_the_last_entry() {
    let c = ctl();
    // At rest at p = 0.1 for N − 1 steps, then κ_f(x_{N−1}) = K (0.1, 0) = −0.4.
    let x0 = [0.1, 0.0];
    let mut v = [[0.0]; N];
    v[N - 1] = [f32::NAN];
    assert!(!c.check(&x0, &mut v.clone(), false).feasible);
    assert!(c.check(&x0, &mut v, true).feasible);
    assert_eq!(v[N - 1], [-0.4]);
}

#[test]
fn a_violating_candidate_falls_back_to_the_shifted_safe_sequence() {
    let mut c = ctl();
    let x0 = [1.0, 0.0];
    let safe = saturated_k(x0, 0);
    c.init_with(&x0, &safe).unwrap();
    let x1 = Di.step(&x0, &safe[0]);
    // Full throttle: |v| exceeds 2 after 4 steps.
    let o = c.step_with(&x1, [[1.0]; N]);
    assert_eq!(o.flags, SafeFlags::FALLBACK);
    assert_eq!(o.u, safe[1]);
    assert_eq!(o.candidate_cost, f32::INFINITY);
    assert!(o.safe_cost.is_finite());
    let stored = c.safe_sequence().unwrap();
    assert_eq!(stored[..N - 1], safe[1..]);
}

#[test]
fn a_better_feasible_candidate_is_used_a_worse_one_is_not() {
    let mut c = ctl();
    let x0 = [1.0, 0.0];
    let poor = saturated_k(x0, 2); // waits two steps, then brakes
    c.init_with(&x0, &poor).unwrap();
    let x1 = Di.step(&x0, &poor[0]);
    let good = saturated_k(x1, 0);
    let o = c.step_with(&x1, good);
    assert_eq!(o.flags, SafeFlags::CANDIDATE);
    assert!(o.candidate_cost < o.safe_cost, "{o:?}");
    assert_eq!(o.u, good[0]);
    // Next step: a feasible candidate that costs more than the shifted `good` is refused.
    let x2 = Di.step(&x1, &o.u);
    let worse = saturated_k(x2, 1);
    let o = c.step_with(&x2, worse);
    assert!(
        o.candidate_cost.is_finite() && o.candidate_cost > o.safe_cost,
        "{o:?}"
    );
    assert_eq!(o.flags, SafeFlags::FALLBACK);
    assert_eq!(o.u, good[1]);
}

#[test]
fn non_finite_inputs_have_defined_answers() {
    let mut c = ctl();
    // No safe sequence, NaN candidate: the reference input, NO_SAFE.
    let o = c.step_with(&[1.0, 0.0], [[f32::NAN]; N]);
    assert_eq!(o.u, [0.0]);
    assert_eq!(
        o.flags,
        SafeFlags::NO_SAFE.union(SafeFlags::NON_FINITE_CANDIDATE)
    );
    assert!(c.safe_sequence().is_none());
    // With a safe sequence: a NaN candidate falls back.
    let x0 = [1.0, 0.0];
    let safe = saturated_k(x0, 0);
    c.init_with(&x0, &safe).unwrap();
    let x1 = Di.step(&x0, &safe[0]);
    let mut cand = safe;
    cand[5] = [f32::INFINITY];
    let o = c.step_with(&x1, cand);
    assert_eq!(
        o.flags,
        SafeFlags::FALLBACK.union(SafeFlags::NON_FINITE_CANDIDATE)
    );
    assert_eq!(o.u, safe[1]);
    // A NaN state: every check fails; the shifted safe sequence is applied, flagged.
    let o = c.step_with(&[f32::NAN, 0.0], saturated_k([0.0, 0.0], 0));
    assert_eq!(
        o.flags,
        SafeFlags::FALLBACK
            .union(SafeFlags::SAFE_INFEASIBLE)
            .union(SafeFlags::NON_FINITE_STATE)
    );
    assert_eq!(o.u, safe[2]);
    assert!(c
        .safe_sequence()
        .unwrap()
        .as_flattened()
        .iter()
        .all(|v| v.is_finite()));
}

#[test]
fn before_a_safe_sequence_the_candidate_is_projected_then_adopted_when_feasible() {
    let mut c = ctl();
    let o = c.step_with(&[1.0, 0.0], [[5.0]; N]);
    assert_eq!((o.u, o.flags), ([1.0], SafeFlags::NO_SAFE));
    let x = [1.0, 0.0];
    let good = saturated_k(x, 0);
    let o = c.step_with(&x, good);
    assert_eq!(o.flags, SafeFlags::CANDIDATE.union(SafeFlags::INITIALISED));
    assert_eq!(c.safe_sequence(), Some(&good));
    c.reset();
    assert!(c.safe_sequence().is_none());
}

#[test]
fn init_with_rejects_an_infeasible_sequence_and_changes_nothing() {
    let mut c = ctl();
    assert_eq!(
        c.init_with(&[1.0, 0.0], &[[1.0]; N]),
        Err(InitRejected::Infeasible)
    );
    assert!(c.safe_sequence().is_none());
    let s = saturated_k([1.0, 0.0], 0);
    assert!(c.init_with(&[1.0, 0.0], &s).unwrap() > 0.0);
    assert_eq!(
        c.init_with(&[1.0, 0.0], &[[1.0]; N]),
        Err(InitRejected::Infeasible)
    );
    assert_eq!(c.safe_sequence(), Some(&s));
}

#[test]
fn validate_rejects_negative_or_non_finite_margins() {
    assert_eq!(ctl().validate(), Ok(()));
    for (stage, terminal) in [(-1e-3, 0.0), (0.0, f32::NAN), (f32::INFINITY, 0.0)] {
        let c = SafeController::<_, _, 2, 1, N>::new(Di, NoSource, Margins { stage, terminal });
        assert_eq!(c.validate(), Err(InvalidMargins::NotFiniteNonNegative));
    }
}

#[test]
fn sequence_net_reshapes_step_major_and_pads_with_nan() {
    let net = SequenceNet(Dense::<2, 4>::new(
        [[1.0, 0.0], [0.0, 1.0], [1.0, 1.0], [2.0, 0.0]],
        [0.0; 4],
    ));
    let s: [[f32; 2]; 2] = net.sequence(&[1.0, 3.0]);
    assert_eq!(s, [[1.0, 3.0], [4.0, 2.0]]);
    let short = SequenceNet(Dense::<2, 3>::new(
        [[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]],
        [0.0; 3],
    ));
    let s: [[f32; 2]; 2] = short.sequence(&[1.0, 3.0]);
    assert_eq!(s[..1], [[1.0, 3.0]]);
    assert_eq!(s[1][0], 4.0);
    assert!(s[1][1].is_nan());
}

#[test]
fn step_uses_the_controllers_own_source() {
    // A linear "network" u_k = −x_0 − x_1 for every k: from rest it proposes zeros.
    let net = SequenceNet(Dense::<2, N>::new([[-1.0, -1.0]; N], [0.0; N]));
    let mut c = SafeController::<_, _, 2, 1, N>::new(Di, net, M);
    let o = c.step(&[0.0, 0.0]);
    assert_eq!(o.flags, SafeFlags::CANDIDATE.union(SafeFlags::INITIALISED));
    assert_eq!((o.u, o.candidate_cost), ([0.0], 0.0));
}

#[test]
fn restore_puts_back_a_sequence_and_a_corrupt_one_is_flagged_not_applied_silently() {
    let x0 = [1.0, 0.0];
    let safe = saturated_k(x0, 0);
    let x1 = Di.step(&x0, &safe[0]);
    // Kept outside and put back: the same step as an uninterrupted controller.
    let mut a = ctl();
    a.init_with(&x0, &safe).unwrap();
    let kept = a.safe_sequence().copied();
    let mut b = ctl();
    b.restore(kept);
    assert_eq!(a.step_with(&x1, [[1.0]; N]), b.step_with(&x1, [[1.0]; N]));
    assert_eq!(a.safe_sequence(), b.safe_sequence());
    // A corrupt sequence (NaN) fails its check: flagged, and the output stays in the box.
    let mut c = ctl();
    c.restore(Some([[f32::NAN]; N]));
    let o = c.step_with(&x1, [[1.0]; N]);
    assert!(
        o.flags.contains(SafeFlags::SAFE_INFEASIBLE),
        "{:?}",
        o.flags
    );
    assert!(o.u[0].is_finite() && o.u[0].abs() <= Di::U_MAX);
    c.restore(None);
    assert_eq!(c.safe_sequence(), None);
}

/// The candidate is clamped to U before the check: a good sequence pushed 1e-4 beyond the
/// input bound (what a network fitted to saturated MPC inputs outputs) fails the check as it
/// is, but is clamped, passes and is applied and stored clamped; a sequence whose clamped
/// version still violates (full throttle beyond the bound) is rejected as before.
#[test]
fn a_candidate_slightly_outside_u_is_clamped_then_checked() {
    let mut c = ctl();
    let x0 = [1.0, 0.0];
    let poor = saturated_k(x0, 2);
    c.init_with(&x0, &poor).unwrap();
    let x1 = Di.step(&x0, &poor[0]);
    let good = saturated_k(x1, 0);
    assert_eq!(good[0], [-1.0], "the good sequence starts on the bound");
    let mut over = good;
    for u in over.iter_mut().filter(|u| u[0] <= -1.0) {
        u[0] = -1.0001;
    }
    assert!(
        !c.check(&x1, &mut over.clone(), false).feasible,
        "unclamped: fails"
    );
    let o = c.step_with(&x1, over);
    assert_eq!(o.flags, SafeFlags::CANDIDATE, "{o:?}");
    assert_eq!(o.u, [-1.0]);
    assert_eq!(c.safe_sequence(), Some(&good), "stored clamped");
    // Clamped to +1 for all N steps the velocity leaves |v| ≤ 2: still rejected.
    let x2 = Di.step(&x1, &o.u);
    let o = c.step_with(&x2, [[1.5]; N]);
    assert_eq!(o.flags, SafeFlags::FALLBACK, "{o:?}");
    assert_eq!(o.candidate_cost, f32::INFINITY);
    assert_eq!(o.u, good[1]);
}

fn feedback_ctl() -> Ctl {
    ctl().with_form(CandidateForm::Feedback)
}

#[test]
fn a_feedback_candidate_of_zero_offsets_is_the_saturated_terminal_controller() {
    // v_0 = c_0, then v_k = Π_U(κ_f(x̂_k) + 0): the rollout of saturated_k after one step.
    let x0 = [1.0, 0.0];
    let mut c = feedback_ctl();
    let mut cand = [[0.0]; N];
    cand[0] = [-1.0];
    let o = c.step_with(&x0, cand);
    assert_eq!(o.flags, SafeFlags::CANDIDATE.union(SafeFlags::INITIALISED));
    assert_eq!(o.u, [-1.0]);
    let want = saturated_k(x0, 0);
    assert_eq!(want[0], [-1.0]);
    // The stored sequence is the realised one, not the offsets.
    assert_eq!(c.safe_sequence(), Some(&want));
    // The same candidate in the open form is "brake once, then coast": a different sequence.
    let mut open = ctl();
    open.step_with(&x0, cand);
    assert_ne!(open.safe_sequence(), Some(&want));
}

#[test]
fn feedback_offsets_are_projected_after_the_terminal_controller_is_added() {
    // From x = 0, κ_f = 0 along rest: offsets of ±5 are clamped to ±1 after adding κ_f, and
    // the realised sequence (inside U) is what is checked and stored.
    let c = feedback_ctl();
    let x0 = [0.0, 0.0];
    let mut v = [[0.0]; N];
    v[1] = [5.0];
    let mut realised = v;
    let r = c.check_as(&x0, &mut realised, false, true);
    assert_eq!(realised[1], [1.0], "Π_U(κ_f(x̂_1) + 5) = Π_U(0 + 5)");
    let mut x = x0;
    let mut expect = [[0.0f32]; N];
    for (k, u) in expect.iter_mut().enumerate() {
        if k >= 1 {
            *u = Di.project_input(&[Di.terminal_input(&x)[0] + v[k][0]]);
        }
        x = Di.step(&x, u);
    }
    assert_eq!(realised, expect);
    assert_eq!(r, c.check(&x0, &mut expect.clone(), false));
    // An offset only the open form would clamp: the step does not clamp c_k (k ≥ 1) first.
    let mut c = feedback_ctl();
    let o = c.step_with(&x0, v);
    assert!(o.flags.contains(SafeFlags::CANDIDATE), "{:?}", o.flags);
    assert_eq!(c.safe_sequence(), Some(&expect));
}

#[test]
fn a_non_finite_feedback_offset_fails_the_check() {
    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        let mut c = feedback_ctl();
        let mut cand = [[0.0]; N];
        cand[3] = [bad];
        let o = c.step_with(&[0.1, 0.0], cand);
        assert!(o.flags.contains(SafeFlags::NON_FINITE_CANDIDATE));
        assert!(o.flags.contains(SafeFlags::NO_SAFE), "{:?}", o.flags);
        assert_eq!(o.candidate_cost, f32::INFINITY);
        assert!(c.safe_sequence().is_none());
    }
}

#[test]
fn the_relaxed_decrease_accepts_a_candidate_within_its_bound_and_only_then() {
    let x0 = [1.0, 0.0];
    let safe = saturated_k(x0, 0);
    let x1 = Di.step(&x0, &safe[0]);
    let strict_c = ctl();
    let mut sh: [[f32; 1]; N] = core::array::from_fn(|k| safe.get(k + 1).copied().unwrap_or([0.0]));
    let j_s = strict_c.check(&x1, &mut sh, true);
    // The safe candidate with a small wiggle near its end: feasible, costlier.
    let mut late = sh;
    late[N - 3][0] += 0.05;
    late[N - 2][0] -= 0.05;
    let j_late = strict_c.check(&x1, &mut late.clone(), false);
    assert!(j_late.feasible && j_s.feasible);
    assert!(
        j_late.cost > j_s.cost,
        "the test needs a costlier candidate: {} vs {}",
        j_late.cost,
        j_s.cost
    );
    for (sigma, accepted) in [(None, false), (Some(1.0), false), (Some(0.05), true)] {
        let mut c = ctl();
        if let Some(s) = sigma {
            c = c.with_decrease(s);
        }
        let j0 = c.init_with(&x0, &safe).unwrap();
        let l0 = Di.stage_cost(&x0, &safe[0]);
        match sigma {
            Some(s) => assert_eq!(c.bound(), j0 - s * l0),
            None => assert_eq!(c.bound(), f32::NEG_INFINITY),
        }
        let within = j_late.cost <= c.bound();
        assert_eq!(
            within,
            accepted,
            "σ {sigma:?}: J(c) {} β {}",
            j_late.cost,
            c.bound()
        );
        let o = c.step_with(&x1, late);
        let want = if accepted {
            SafeFlags::CANDIDATE
        } else {
            SafeFlags::FALLBACK
        };
        assert_eq!(o.flags, want, "σ {sigma:?}");
        // β after the step: the applied sequence's cost minus σ·ℓ at x1.
        let (j, v0) = if accepted {
            (j_late.cost, late[0])
        } else {
            (j_s.cost, sh[0])
        };
        match sigma {
            Some(s) => assert_eq!(c.bound(), j - s * Di.stage_cost(&x1, &v0)),
            None => assert_eq!(c.bound(), f32::NEG_INFINITY),
        }
        // restore forgets β; restore_with_bound keeps it; reset forgets it.
        let (q, b) = (c.safe_sequence().copied(), c.bound());
        c.restore(q);
        assert_eq!(c.bound(), f32::NEG_INFINITY);
        c.restore_with_bound(q, b);
        assert_eq!(c.bound().to_bits(), b.to_bits());
        c.reset();
        assert_eq!(c.bound(), f32::NEG_INFINITY);
    }
}

#[test]
fn validate_checks_the_relaxed_decrease() {
    assert!(ctl().with_decrease(0.5).validate().is_ok());
    assert!(ctl().with_decrease(1.0).validate().is_ok());
    for bad in [0.0, -0.1, 1.01, f32::NAN, f32::INFINITY] {
        assert_eq!(
            ctl().with_decrease(bad).validate(),
            Err(InvalidMargins::Decrease),
            "{bad}"
        );
    }
}
