//! `ampc_safe_init`, `ampc_safe_init_with`, `ampc_safe_terminal_sequence`, `ampc_safe_step`:
//! the safety-augmented controller ([`controller_core::SafeController`]) behind raw pointers,
//! for the controller compiled in — the safe controller `trainer export --safe-rs` wrote for
//! `pendulum_ode` (default: `tests/fixtures/safe-controller/pendulum_ode_safe.rs`, its f32
//! plant, OCP, terminal ingredients and sequence network 2 → 16 → 20) or, with the cargo
//! feature `safe-planar-quadrotor`, for the planar quadrotor
//! (`planar_quadrotor_safe.rs`, 6 → 16 → 40; C side: define `AMPC_SAFE_PLANAR_QUADROTOR`
//! before including `ampc_safe.h`).
//!
//! ```text
//! struct ampc_safe { float sequence[AMPC_SAFE_N][AMPC_SAFE_NU]; float bound; uint8_t has_safe; };
//! uint8_t ampc_safe_init(struct ampc_safe *s);                         // no safe sequence yet
//! uint8_t ampc_safe_init_with(struct ampc_safe *s, const float x[AMPC_SAFE_NX],
//!                             const float sequence[AMPC_SAFE_N][AMPC_SAFE_NU]); // adopt if safe
//! uint8_t ampc_safe_terminal_sequence(const float x[AMPC_SAFE_NX],
//!                                     float sequence[AMPC_SAFE_N][AMPC_SAFE_NU]);
//! uint8_t ampc_safe_step(struct ampc_safe *s, const float x[AMPC_SAFE_NX], float u[AMPC_SAFE_NU]);
//! ```
//! The caller owns the controller's memory (`struct ampc_safe`, the last safe sequence and
//! the relaxed decrease's bound β, `SafeController::bound`): no
//! allocation, no static state. `ampc_safe_step` restores it, runs
//! [`controller_core::SafeController::step`] and writes it back; it returns the
//! [`SafeFlags`] bits. A sequence the caller altered is re-checked like any other
//! (`SafeController::restore`): it is applied only if it passes, else flagged
//! `SAFE_INFEASIBLE`. The network's candidate is clamped to the input box before the check
//! (`SafeController::step_with`; tested below). Initialisation (issue 41 §5): `ampc_safe_init` then steps (the first
//! candidate that passes the check becomes the safe sequence; flag `NO_SAFE` until then), or
//! `ampc_safe_init_with` an MPC solution at x₀ ([`SafeController::init_with`]: adopted only
//! if it passes the online check from x₀, as if applied at x₀; the caller applies its first
//! input at x₀). `ampc_safe_terminal_sequence` writes the terminal controller's rollout
//! Π_U(κ_f(x_k)) from x — a safe sequence when x lies well inside the terminal set.
//! Defined answers for bad input:
//! - `u` null: nothing read or written, returns `NULL_ARGUMENT`;
//! - `s` or `x` null: `u` = Π_U(u_ref) (the plant's reference input), `s` unchanged, returns
//!   `NULL_ARGUMENT | NON_FINITE_STATE`;
//! - a NaN or infinite state component: the controller's own answer (flag
//!   `NON_FINITE_STATE`; `u` finite, inside the input box);
//! - `ampc_safe_init_with`: a null argument returns `NULL_ARGUMENT`, a sequence that fails
//!   the check (NaN, outside the input box, a constraint or the terminal set violated)
//!   returns `SAFE_INFEASIBLE`; `s` is unchanged in both cases; 0 when adopted;
//! - `ampc_safe_terminal_sequence`: a null argument returns `NULL_ARGUMENT` (nothing
//!   written); a non-finite state returns `NON_FINITE_STATE` with the rollout written
//!   (inputs inside the box, not meaningful); 0 otherwise.

use controller_core::safe::{Plant, SafeFlags};

/// The compiled-in safe controller (module doc): the pendulum's.
#[cfg(not(feature = "safe-planar-quadrotor"))]
#[allow(missing_docs)]
mod compiled {
    controller_core::include_safe_controller!(
        "../../../tests/fixtures/safe-controller/pendulum_ode_safe.rs"
    );
}

/// The compiled-in safe controller (module doc): the planar quadrotor's.
#[cfg(feature = "safe-planar-quadrotor")]
#[allow(missing_docs)]
mod compiled {
    controller_core::include_safe_controller!(
        "../../../tests/fixtures/safe-controller/planar_quadrotor_safe.rs"
    );
}

pub use compiled::safe::{N as SAFE_N, NU as SAFE_NU, NX as SAFE_NX};

/// The compiled-in controller's type and constant (`trainer export --safe-rs`).
pub use compiled::safe::{Controller as SafeControllerType, CONTROLLER as SAFE_CONTROLLER};

/// Flag bit (C: `AMPC_SAFE_FLAG_NULL_ARGUMENT`): `s`, `x` or `u` was a null pointer.
pub const SAFE_FLAG_NULL_ARGUMENT: u8 = 0x80;

// The C flag values are controller-core's (the header's #defines are checked by the C test).
const _: () = assert!(
    SafeFlags::CANDIDATE.0 == 1
        && SafeFlags::FALLBACK.0 == 2
        && SafeFlags::NO_SAFE.0 == 4
        && SafeFlags::INITIALISED.0 == 8
        && SafeFlags::SAFE_INFEASIBLE.0 == 16
        && SafeFlags::NON_FINITE_STATE.0 == 32
        && SafeFlags::NON_FINITE_CANDIDATE.0 == 64
);

/// `struct ampc_safe` of `ampc_safe.h`: the controller's memory, owned by the caller.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AmpcSafe {
    /// The sequence applied at the last step (valid when `has_safe` ≠ 0).
    pub sequence: [[f32; SAFE_NU]; SAFE_N],
    /// β of the relaxed decrease (`SafeController::bound`; −∞ when none).
    pub bound: f32,
    /// 0: no safe sequence yet; otherwise `sequence` is the last safe sequence.
    pub has_safe: u8,
}

/// Forgets the safe sequence (`has_safe = 0`); returns 0, or `SAFE_FLAG_NULL_ARGUMENT` for a
/// null `s`.
///
/// # Safety
/// `s` is null or points to one writable, aligned `struct ampc_safe`.
#[no_mangle]
pub unsafe extern "C" fn ampc_safe_init(s: *mut AmpcSafe) -> u8 {
    if s.is_null() {
        return SAFE_FLAG_NULL_ARGUMENT;
    }
    let fresh = AmpcSafe {
        sequence: [[0.0; SAFE_NU]; SAFE_N],
        bound: f32::NEG_INFINITY,
        has_safe: 0,
    };
    // SAFETY: s is non-null and points to one writable, aligned AmpcSafe (contract).
    unsafe { s.write(fresh) };
    0
}

/// Adopts `sequence` (e.g. the MPC's solution at `x`) as the safe sequence if it passes the
/// online check from `x` ([`controller_core::SafeController::init_with`]); returns 0 when
/// adopted, `SAFE_INFEASIBLE` when rejected, `SAFE_FLAG_NULL_ARGUMENT` for a null argument
/// (module doc). `s` changes only when the sequence is adopted.
///
/// # Safety
/// `s` is null or points to one writable, aligned `struct ampc_safe`; `x` is null or points
/// to `SAFE_NX` readable, initialised, aligned `f32`; `sequence` is null or points to
/// `SAFE_N × SAFE_NU` readable, initialised, aligned `f32` (row-major).
#[no_mangle]
pub unsafe extern "C" fn ampc_safe_init_with(
    s: *mut AmpcSafe,
    x: *const f32,
    sequence: *const f32,
) -> u8 {
    if s.is_null() || x.is_null() || sequence.is_null() {
        return SAFE_FLAG_NULL_ARGUMENT;
    }
    // SAFETY: non-null, and pointing to SAFE_NX and SAFE_N × SAFE_NU f32 (contract).
    let (state, seq) = unsafe {
        (
            x.cast::<[f32; SAFE_NX]>().read(),
            sequence.cast::<[[f32; SAFE_NU]; SAFE_N]>().read(),
        )
    };
    let mut ctl = SAFE_CONTROLLER;
    if ctl.init_with(&state, &seq).is_err() {
        return SafeFlags::SAFE_INFEASIBLE.0;
    }
    let Some(adopted) = ctl.safe_sequence().copied() else {
        return SafeFlags::SAFE_INFEASIBLE.0;
    };
    // SAFETY: s is non-null and points to one writable, aligned AmpcSafe (contract).
    unsafe {
        s.write(AmpcSafe {
            sequence: adopted,
            bound: ctl.bound(),
            has_safe: 1,
        })
    };
    0
}

/// Writes the terminal controller's rollout from `x`: v_k = Π_U(κ_f(x_k)), x_{k+1} = the
/// f32 plant's step (module doc for the return values).
///
/// # Safety
/// `x` is null or points to `SAFE_NX` readable, initialised, aligned `f32`; `sequence` is
/// null or points to `SAFE_N × SAFE_NU` writable, aligned `f32` (row-major).
#[no_mangle]
pub unsafe extern "C" fn ampc_safe_terminal_sequence(x: *const f32, sequence: *mut f32) -> u8 {
    if x.is_null() || sequence.is_null() {
        return SAFE_FLAG_NULL_ARGUMENT;
    }
    // SAFETY: x is non-null and points to SAFE_NX f32 (contract).
    let x0 = unsafe { x.cast::<[f32; SAFE_NX]>().read() };
    let p = SAFE_CONTROLLER.plant;
    let mut xk = x0;
    let seq: [[f32; SAFE_NU]; SAFE_N] = core::array::from_fn(|_| {
        let u = p.project_input(&p.terminal_input(&xk));
        xk = p.step(&xk, &u);
        u
    });
    // SAFETY: sequence is non-null and points to SAFE_N × SAFE_NU writable f32 (contract).
    unsafe { sequence.cast::<[[f32; SAFE_NU]; SAFE_N]>().write(seq) };
    if x0.iter().all(|v| v.is_finite()) {
        0
    } else {
        SafeFlags::NON_FINITE_STATE.0
    }
}

/// One step of the safe controller (module doc); returns the flag bits.
///
/// # Safety
/// `s` is null or points to one readable and writable, aligned `struct ampc_safe`; `x` is
/// null or points to `SAFE_NX` readable, initialised, aligned `f32`; `u` is null or points
/// to `SAFE_NU` writable, aligned `f32`. All reads happen before the writes.
#[no_mangle]
pub unsafe extern "C" fn ampc_safe_step(s: *mut AmpcSafe, x: *const f32, u: *mut f32) -> u8 {
    if u.is_null() {
        return SAFE_FLAG_NULL_ARGUMENT;
    }
    let mut ctl = compiled::safe::CONTROLLER;
    if s.is_null() || x.is_null() {
        let u_ref = ctl.plant.project_input(&[f32::NAN; SAFE_NU]);
        // SAFETY: u is non-null and points to SAFE_NU writable, aligned f32 (contract).
        unsafe { u.cast::<[f32; SAFE_NU]>().write(u_ref) };
        return SAFE_FLAG_NULL_ARGUMENT | SafeFlags::NON_FINITE_STATE.0;
    }
    // SAFETY: s and x are non-null and point to one AmpcSafe and SAFE_NX f32 (contract).
    let (memory, state) = unsafe { (s.read(), x.cast::<[f32; SAFE_NX]>().read()) };
    ctl.restore_with_bound(
        (memory.has_safe != 0).then_some(memory.sequence),
        memory.bound,
    );
    let out = ctl.step(&state);
    let after = match ctl.safe_sequence() {
        Some(q) => AmpcSafe {
            sequence: *q,
            bound: ctl.bound(),
            has_safe: 1,
        },
        None => AmpcSafe {
            sequence: [[0.0; SAFE_NU]; SAFE_N],
            bound: f32::NEG_INFINITY,
            has_safe: 0,
        },
    };
    // SAFETY: as above; everything was read before these writes.
    unsafe {
        s.write(after);
        u.cast::<[f32; SAFE_NU]>().write(out.u);
    }
    out.flags.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use controller_core::safe::{CandidateForm, SequenceSource};

    /// A start away from the set point (the pendulum's, or the quadrotor's).
    #[cfg(not(feature = "safe-planar-quadrotor"))]
    const X0: [f32; SAFE_NX] = [0.4, -0.3];
    #[cfg(feature = "safe-planar-quadrotor")]
    const X0: [f32; SAFE_NX] = [0.1, -0.1, 0.04, 0.0, 0.1, 0.0];

    fn fresh() -> AmpcSafe {
        AmpcSafe {
            sequence: [[0.0; SAFE_NU]; SAFE_N],
            bound: f32::NEG_INFINITY,
            has_safe: 0,
        }
    }

    /// Through the pointers, a run of steps is the Rust controller's, bit for bit.
    #[test]
    fn steps_through_pointers_are_the_core() {
        let mut mem = AmpcSafe {
            sequence: [[9.0; SAFE_NU]; SAFE_N],
            bound: 3.0,
            has_safe: 7,
        };
        // SAFETY: a live AmpcSafe.
        assert_eq!(unsafe { ampc_safe_init(&mut mem) }, 0);
        assert_eq!(mem.has_safe, 0);
        assert_eq!(mem.bound, f32::NEG_INFINITY);
        let mut ctl = SAFE_CONTROLLER;
        let p = ctl.plant;
        let mut x = X0;
        for _ in 0..60 {
            let want = ctl.step(&x);
            let mut u = [5.0f32; SAFE_NU];
            // SAFETY: live, aligned arrays of the right lengths.
            let f = unsafe { ampc_safe_step(&mut mem, x.as_ptr(), u.as_mut_ptr()) };
            assert_eq!(u.map(f32::to_bits), want.u.map(f32::to_bits));
            assert_eq!(f, want.flags.0);
            assert_eq!(mem.has_safe != 0, ctl.safe_sequence().is_some());
            assert_eq!(mem.bound.to_bits(), ctl.bound().to_bits());
            x = p.step(&x, &u);
        }
        // The pendulum's net finds a safe sequence by itself from X0; the quadrotor's small
        // net (6 → 16 → 40) does not, near hover either: it is initialised with
        // `ampc_safe_init_with` (next test, and the C firmware).
        #[cfg(not(feature = "safe-planar-quadrotor"))]
        assert!(mem.has_safe == 1);
    }

    /// `ampc_safe_init_with` is `init_with`: the terminal rollout near the set point is
    /// adopted and the following steps equal the core's; a NaN or out-of-box sequence is
    /// rejected with `s` untouched; `ampc_safe_terminal_sequence` is the rollout.
    #[test]
    fn init_with_adopts_what_the_core_adopts() {
        let x: [f32; SAFE_NX] = core::array::from_fn(|i| X0[i] * 0.1);
        let mut seq = [[f32::NAN; SAFE_NU]; SAFE_N];
        // SAFETY: live arrays of the right lengths.
        let f = unsafe { ampc_safe_terminal_sequence(x.as_ptr(), seq.as_mut_ptr().cast()) };
        assert_eq!(f, 0);
        let p = SAFE_CONTROLLER.plant;
        let mut xk = x;
        for v in &seq {
            let want = p.project_input(&p.terminal_input(&xk));
            assert_eq!(v.map(f32::to_bits), want.map(f32::to_bits));
            xk = p.step(&xk, v);
        }
        let mut ctl = SAFE_CONTROLLER;
        assert!(
            ctl.init_with(&x, &seq).is_ok(),
            "rollout near x_ref not safe"
        );
        let mut mem = fresh();
        // SAFETY: live arrays.
        assert_eq!(
            unsafe { ampc_safe_init_with(&mut mem, x.as_ptr(), seq.as_ptr().cast()) },
            0
        );
        assert_eq!(mem.has_safe, 1);
        assert_eq!(Some(&mem.sequence), ctl.safe_sequence());
        let mut xs = p.step(&x, &seq[0]);
        for _ in 0..20 {
            let want = ctl.step(&xs);
            let mut u = [0.0f32; SAFE_NU];
            // SAFETY: live arrays.
            let f = unsafe { ampc_safe_step(&mut mem, xs.as_ptr(), u.as_mut_ptr()) };
            assert_eq!(
                (f, u.map(f32::to_bits)),
                (want.flags.0, want.u.map(f32::to_bits))
            );
            assert!(!SafeFlags(f).contains(SafeFlags::NO_SAFE));
            xs = p.step(&xs, &u);
        }
        // Rejections leave the memory as it was.
        let before = mem;
        let mut bad = seq;
        bad[3][0] = f32::NAN;
        let mut far = seq;
        far[0][0] = 1e9;
        for b in [bad, far] {
            // SAFETY: live arrays.
            let f = unsafe { ampc_safe_init_with(&mut mem, x.as_ptr(), b.as_ptr().cast()) };
            assert_eq!(f, SafeFlags::SAFE_INFEASIBLE.0);
            assert_eq!(mem, before);
        }
        let null = core::ptr::null::<f32>();
        // SAFETY: null arguments are allowed.
        unsafe {
            assert_eq!(
                ampc_safe_init_with(&mut mem, null, seq.as_ptr().cast()),
                SAFE_FLAG_NULL_ARGUMENT
            );
            assert_eq!(
                ampc_safe_init_with(&mut mem, x.as_ptr(), null),
                SAFE_FLAG_NULL_ARGUMENT
            );
            assert_eq!(
                ampc_safe_init_with(core::ptr::null_mut(), x.as_ptr(), seq.as_ptr().cast()),
                SAFE_FLAG_NULL_ARGUMENT
            );
            assert_eq!(
                ampc_safe_terminal_sequence(null, seq.as_mut_ptr().cast()),
                SAFE_FLAG_NULL_ARGUMENT
            );
            assert_eq!(
                ampc_safe_terminal_sequence(x.as_ptr(), core::ptr::null_mut()),
                SAFE_FLAG_NULL_ARGUMENT
            );
        }
        assert_eq!(mem, before);
        let mut nan = x;
        nan[0] = f32::NAN;
        // SAFETY: live arrays.
        let f = unsafe { ampc_safe_terminal_sequence(nan.as_ptr(), seq.as_mut_ptr().cast()) };
        assert_eq!(f, SafeFlags::NON_FINITE_STATE.0);
        assert!(seq.as_flattened().iter().all(|v| v.is_finite()));
    }

    /// The sequence the controller checks for the finite candidate `raw` at `x`: Π_U of each
    /// entry (open form), or Π_U(c_0) then Π_U(κ_f(x̂_k) + c_k) along the plant's simulation
    /// (feedback form; `controller_core::safe`).
    fn realised(x: &[f32; SAFE_NX], raw: &[[f32; SAFE_NU]; SAFE_N]) -> [[f32; SAFE_NU]; SAFE_N] {
        let ctl = SAFE_CONTROLLER;
        let p = ctl.plant;
        if ctl.form == CandidateForm::Open {
            return raw.map(|u| p.project_input(&u));
        }
        let mut xk = *x;
        core::array::from_fn(|k| {
            let v = if k == 0 {
                p.project_input(&raw[0])
            } else {
                let kf = p.terminal_input(&xk);
                p.project_input(&core::array::from_fn(|j| raw[k][j] + kf[j]))
            };
            xk = p.step(&xk, &v);
            v
        })
    }

    /// `ampc_safe_step` clamps the network's candidate to U before the check: over a grid of
    /// X (fresh memory, so a candidate that passes becomes the safe sequence), the step
    /// accepts (`CANDIDATE`) exactly when the clamped candidate passes the check, and stores
    /// it clamped (realised, in the feedback form); every accepted raw candidate outside U is counted as rescued by the
    /// projection (its unclamped check fails). The committed fixture nets give no such state
    /// (0 rescued; the discriminating test is controller-core's
    /// `a_candidate_slightly_outside_u_is_clamped_then_checked`, the same `step_with`).
    #[test]
    fn the_candidate_is_clamped_to_u_before_the_check() {
        let ctl = SAFE_CONTROLLER;
        let (lo, hi) = (compiled::safe::plant::U_LO, compiled::safe::plant::U_HI);
        let (mut rescued, mut accepted) = (0, 0);
        for i in 0..=120 {
            for j in 0..=40 {
                let x: [f32; SAFE_NX] = core::array::from_fn(|k| {
                    let t = if k == 0 {
                        i as f32 / 120.0
                    } else {
                        j as f32 / 40.0
                    };
                    let (a, b) = (
                        compiled::safe::plant::X_LO[k],
                        compiled::safe::plant::X_HI[k],
                    );
                    a + (b - a) * t
                });
                let raw = ctl.source.sequence(&x);
                let clamped = realised(&x, &raw);
                let mut mem = fresh();
                let mut u = [0.0f32; SAFE_NU];
                // SAFETY: live, aligned arrays of the right lengths.
                let f = SafeFlags(unsafe { ampc_safe_step(&mut mem, x.as_ptr(), u.as_mut_ptr()) });
                let passes = ctl.check(&x, &mut clamped.clone(), false).feasible;
                assert_eq!(f.contains(SafeFlags::CANDIDATE), passes, "x = {x:?}");
                if !passes {
                    continue;
                }
                accepted += 1;
                assert_eq!(mem.sequence, clamped);
                // The entries that are inputs before the check (all, or c_0 in the feedback
                // form, whose offsets are projected after κ_f is added).
                let inputs = if ctl.form == CandidateForm::Feedback {
                    1
                } else {
                    SAFE_N
                };
                let outside = raw[..inputs]
                    .iter()
                    .any(|v| (0..SAFE_NU).any(|k| v[k] < lo[k] || v[k] > hi[k]));
                if outside {
                    assert!(!ctl.check(&x, &mut raw.clone(), false).feasible);
                    rescued += 1;
                }
            }
        }
        // The quadrotor's small net may find no safe sequence by itself on this grid.
        assert!(
            accepted > 0 || cfg!(feature = "safe-planar-quadrotor"),
            "{rescued} rescued of {accepted}"
        );
    }

    #[test]
    fn null_pointers_and_nan_states_give_the_documented_answers() {
        let mut mem = fresh();
        let x: [f32; SAFE_NX] = core::array::from_fn(|i| if i == 0 { 0.1 } else { 0.0 });
        let mut u = [5.0f32; SAFE_NU];
        // SAFETY: null u is allowed.
        let f = unsafe { ampc_safe_step(&mut mem, x.as_ptr(), core::ptr::null_mut()) };
        assert_eq!(f, SAFE_FLAG_NULL_ARGUMENT);
        let u_ref = compiled::safe::plant::U_REF;
        for (s, xp) in [
            (core::ptr::null_mut(), x.as_ptr()),
            (&mut mem as *mut AmpcSafe, core::ptr::null()),
        ] {
            u = [5.0; SAFE_NU];
            // SAFETY: null s or x is allowed; the others are live.
            let f = unsafe { ampc_safe_step(s, xp, u.as_mut_ptr()) };
            assert_eq!(f, SAFE_FLAG_NULL_ARGUMENT | SafeFlags::NON_FINITE_STATE.0);
            assert_eq!(u, u_ref);
        }
        assert_eq!(mem.has_safe, 0);
        // SAFETY: null s is allowed.
        assert_eq!(
            unsafe { ampc_safe_init(core::ptr::null_mut()) },
            SAFE_FLAG_NULL_ARGUMENT
        );
        let mut nan = x;
        nan[0] = f32::NAN;
        // SAFETY: live arrays.
        let f = unsafe { ampc_safe_step(&mut mem, nan.as_ptr(), u.as_mut_ptr()) };
        assert!(SafeFlags(f).contains(SafeFlags::NON_FINITE_STATE));
        let (lo, hi) = (compiled::safe::plant::U_LO, compiled::safe::plant::U_HI);
        for i in 0..SAFE_NU {
            assert!(u[i].is_finite());
            assert!(lo[i] <= u[i] && u[i] <= hi[i]);
        }
    }
}
