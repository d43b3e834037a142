//! `ampc_safe_init`, `ampc_safe_step`: the safety-augmented controller
//! ([`controller_core::SafeController`]) behind raw pointers, for the controller compiled in:
//! the safe controller of `pendulum_ode` (`trainer export --safe-rs`,
//! `tests/fixtures/safe-controller/pendulum_ode_safe.rs`: its f32 plant, OCP, terminal
//! ingredients and sequence network 2 → 16 → 20).
//!
//! ```text
//! struct ampc_safe { float sequence[AMPC_SAFE_N][AMPC_SAFE_NU]; uint8_t has_safe; };
//! uint8_t ampc_safe_init(struct ampc_safe *s);                         // no safe sequence yet
//! uint8_t ampc_safe_step(struct ampc_safe *s, const float x[AMPC_SAFE_NX], float u[AMPC_SAFE_NU]);
//! ```
//! The caller owns the controller's memory (`struct ampc_safe`, the last safe sequence): no
//! allocation, no static state. `ampc_safe_step` restores it, runs
//! [`controller_core::SafeController::step`] and writes it back; it returns the
//! [`SafeFlags`] bits. A sequence the caller altered is re-checked like any other
//! (`SafeController::restore`): it is applied only if it passes, else flagged
//! `SAFE_INFEASIBLE`. Defined answers for bad input:
//! - `u` null: nothing read or written, returns `NULL_ARGUMENT`;
//! - `s` or `x` null: `u` = Π_U(u_ref) (the plant's reference input), `s` unchanged, returns
//!   `NULL_ARGUMENT | NON_FINITE_STATE`;
//! - a NaN or infinite state component: the controller's own answer (flag
//!   `NON_FINITE_STATE`; `u` finite, inside the input box).

use controller_core::safe::{Plant, SafeFlags};

/// The compiled-in safe controller (module doc).
#[allow(missing_docs)]
mod pendulum {
    controller_core::include_safe_controller!(
        "../../../tests/fixtures/safe-controller/pendulum_ode_safe.rs"
    );
}

pub use pendulum::safe::{N as SAFE_N, NU as SAFE_NU, NX as SAFE_NX};

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
        has_safe: 0,
    };
    // SAFETY: s is non-null and points to one writable, aligned AmpcSafe (contract).
    unsafe { s.write(fresh) };
    0
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
    let mut ctl = pendulum::safe::CONTROLLER;
    if s.is_null() || x.is_null() {
        let u_ref = ctl.plant.project_input(&[f32::NAN; SAFE_NU]);
        // SAFETY: u is non-null and points to SAFE_NU writable, aligned f32 (contract).
        unsafe { u.cast::<[f32; SAFE_NU]>().write(u_ref) };
        return SAFE_FLAG_NULL_ARGUMENT | SafeFlags::NON_FINITE_STATE.0;
    }
    // SAFETY: s and x are non-null and point to one AmpcSafe and SAFE_NX f32 (contract).
    let (memory, state) = unsafe { (s.read(), x.cast::<[f32; SAFE_NX]>().read()) };
    ctl.restore((memory.has_safe != 0).then_some(memory.sequence));
    let out = ctl.step(&state);
    let after = match ctl.safe_sequence() {
        Some(q) => AmpcSafe {
            sequence: *q,
            has_safe: 1,
        },
        None => AmpcSafe {
            sequence: [[0.0; SAFE_NU]; SAFE_N],
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

    /// Through the pointers, a run of steps is the Rust controller's, bit for bit.
    #[test]
    fn steps_through_pointers_are_the_core() {
        let mut mem = AmpcSafe {
            sequence: [[9.0; SAFE_NU]; SAFE_N],
            has_safe: 7,
        };
        // SAFETY: a live AmpcSafe.
        assert_eq!(unsafe { ampc_safe_init(&mut mem) }, 0);
        assert_eq!(mem.has_safe, 0);
        let mut ctl = pendulum::safe::CONTROLLER;
        let p = ctl.plant;
        let mut x = [0.4f32, -0.3];
        for _ in 0..60 {
            let want = ctl.step(&x);
            let mut u = [5.0f32; SAFE_NU];
            // SAFETY: live, aligned arrays of the right lengths.
            let f = unsafe { ampc_safe_step(&mut mem, x.as_ptr(), u.as_mut_ptr()) };
            assert_eq!(u.map(f32::to_bits), want.u.map(f32::to_bits));
            assert_eq!(f, want.flags.0);
            assert_eq!(mem.has_safe != 0, ctl.safe_sequence().is_some());
            x = p.step(&x, &u);
        }
        assert!(mem.has_safe == 1);
    }

    #[test]
    fn null_pointers_and_nan_states_give_the_documented_answers() {
        let mut mem = AmpcSafe {
            sequence: [[0.0; SAFE_NU]; SAFE_N],
            has_safe: 0,
        };
        let x = [0.1f32, 0.0];
        let mut u = [5.0f32; SAFE_NU];
        // SAFETY: null u is allowed.
        let f = unsafe { ampc_safe_step(&mut mem, x.as_ptr(), core::ptr::null_mut()) };
        assert_eq!(f, SAFE_FLAG_NULL_ARGUMENT);
        let u_ref = pendulum::safe::plant::U_REF;
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
        let nan = [f32::NAN, 0.0];
        // SAFETY: live arrays.
        let f = unsafe { ampc_safe_step(&mut mem, nan.as_ptr(), u.as_mut_ptr()) };
        assert!(SafeFlags(f).contains(SafeFlags::NON_FINITE_STATE));
        assert!(u[0].is_finite());
        let (lo, hi) = (
            pendulum::safe::plant::U_LO[0],
            pendulum::safe::plant::U_HI[0],
        );
        assert!(lo <= u[0] && u[0] <= hi);
    }
}
