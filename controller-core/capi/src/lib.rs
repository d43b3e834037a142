//! `ampc-capi`: the C API of `controller-core` — `libampc_capi.a` and `include/ampc.h`.
//!
//! ```text
//! uint8_t ampc_evaluate(const float x[AMPC_NX], float u[AMPC_NU]);   // flags
//! extern const struct ampc_certificate ampc_linked_certificate;
//! uint8_t ampc_safe_step(struct ampc_safe *s, const float x[], float u[]);  // ampc_safe.h
//! ```
//! The safety-augmented controller (`ampc_safe_init`, `ampc_safe_step`, header
//! `include/ampc_safe.h`) is [`safe`].
//! `ampc_evaluate` is [`controller_core::demo::evaluate`] behind raw pointers: `u = κ_NN(Π_X(x))`
//! clamped to the band, the return value is [`Flags`]' bits, plus
//! [`FLAG_NULL_ARGUMENT`] for a null pointer (x null: u = fallback, flags NON_FINITE |
//! NULL_ARGUMENT; u null: nothing read or written, flags NULL_ARGUMENT). No allocation;
//! the only `unsafe` of the workspace's controller path is here, at the pointer boundary.
//!
//! The header `include/ampc.h` is written by `trainer export --c-header` for the compiled-in
//! network (its certificate values equal [`ampc_linked_certificate`]'s, which the C test
//! checks). On the bare-metal target the crate is `no_std` with its own panic handler (an
//! endless loop: no panic is reachable from `ampc_evaluate`, which `tests/c_api.rs` checks on
//! the C firmware's ELF); on a host it links std, whose handler it uses.
#![cfg_attr(target_os = "none", no_std)]
#![deny(missing_docs)]
#![deny(unsafe_op_in_unsafe_fn)]

use controller_core::{
    demo::{CERTIFICATE, NU, NX},
    Certificate, Flags, Guarantee,
};

/// Flag bit (C: `AMPC_FLAG_NULL_ARGUMENT`): `x` or `u` was a null pointer.
pub const FLAG_NULL_ARGUMENT: u8 = 0x80;

// The C flag values are controller-core's (the header's #defines are checked by the C test).
const _: () = assert!(
    Flags::OUT_OF_DOMAIN.0 == 1
        && Flags::NON_FINITE.0 == 2
        && Flags::CLAMPED.0 == 4
        && Flags::EXCLUDED.0 == 8
        && FLAG_NULL_ARGUMENT & 15 == 0
);

/// Capacity of [`AmpcCertificate::hash`] without the NUL (C: `AMPC_HASH_CAPACITY`).
pub const HASH_CAPACITY: usize = 64;

/// `struct ampc_certificate` of `ampc.h`: the certificate's numbers a C program needs.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AmpcCertificate {
    /// Total bound ε (learning side + f32 allowance of this build's tanh).
    pub eps: f64,
    /// Tier of the claim: `AMPC_GUARANTEE_*` = [`Guarantee`] as `u8`.
    pub guarantee: u8,
    /// 1 for the untrained placeholder network.
    pub placeholder: u8,
    /// 1 if built with `fast-tanh`.
    pub fast_tanh: u8,
    /// Lower corner of X.
    pub domain_lo: [f64; NX],
    /// Upper corner of X.
    pub domain_hi: [f64; NX],
    /// Lower end of the clamp band.
    pub clamp_lo: [f32; NU],
    /// Upper end of the clamp band.
    pub clamp_hi: [f32; NU],
    /// Model hash, NUL-terminated (C `char`: one byte).
    pub hash: [u8; HASH_CAPACITY + 1],
}

/// `s` NUL-padded into the C field; a longer hash does not compile.
// Evaluated at compile time only (the static's initialiser): an index out of bounds would be
// a compile error, never a run-time panic.
#[allow(clippy::indexing_slicing)]
const fn c_hash(s: &str) -> [u8; HASH_CAPACITY + 1] {
    let b = s.as_bytes();
    assert!(
        b.len() <= HASH_CAPACITY,
        "model hash longer than AMPC_HASH_CAPACITY"
    );
    let mut out = [0u8; HASH_CAPACITY + 1];
    let mut i = 0;
    while i < b.len() {
        out[i] = b[i];
        i += 1;
    }
    out
}

const fn c_certificate(c: &Certificate<NX, NU>) -> AmpcCertificate {
    AmpcCertificate {
        eps: c.eps,
        guarantee: c.guarantee as u8,
        placeholder: c.placeholder as u8,
        fast_tanh: controller_core::FAST_TANH as u8,
        domain_lo: c.domain_lo,
        domain_hi: c.domain_hi,
        clamp_lo: c.clamp_lo,
        clamp_hi: c.clamp_hi,
        hash: c_hash(c.hash),
    }
}

// The C enum values are controller-core's `Guarantee` discriminants.
const _: () = assert!(
    Guarantee::Sound as u8 == 0
        && Guarantee::Statistical as u8 == 1
        && Guarantee::Estimated as u8 == 2
);

/// The certificate of the compiled-in controller (C: `ampc_linked_certificate`).
#[no_mangle]
#[allow(non_upper_case_globals)]
pub static ampc_linked_certificate: AmpcCertificate = c_certificate(&CERTIFICATE);

/// `u = controller(x)`; returns the flag bits (see the crate doc for null pointers).
///
/// # Safety
/// `x` is null or points to `NX` readable, initialised, 4-byte-aligned `f32`; `u` is null
/// or points to `NU` writable, 4-byte-aligned `f32` (a C `float[]`). `x` is read completely
/// before `u` is written, so the two may overlap.
#[no_mangle]
pub unsafe extern "C" fn ampc_evaluate(x: *const f32, u: *mut f32) -> u8 {
    if u.is_null() {
        return FLAG_NULL_ARGUMENT;
    }
    let out = if x.is_null() {
        controller_core::Output {
            u: CERTIFICATE.fallback,
            flags: Flags::NON_FINITE,
        }
    } else {
        // SAFETY: x is non-null and, by the caller's contract, points to NX readable,
        // initialised, aligned f32 — exactly one `[f32; NX]` (same size and alignment).
        let state = unsafe { x.cast::<[f32; NX]>().read() };
        controller_core::demo::evaluate(&state)
    };
    // SAFETY: u is non-null and, by the caller's contract, points to NU writable, aligned
    // f32 — one `[f32; NU]`; x has been read completely above.
    unsafe { u.cast::<[f32; NU]>().write(out.u) };
    if x.is_null() {
        out.flags.0 | FLAG_NULL_ARGUMENT
    } else {
        out.flags.0
    }
}

/// One RK4 step of firmware-example's pendulum (`x ← rk4_step(x, u)`), for the C firmware
/// test only (feature `pendulum-plant`); null `x`: nothing happens.
///
/// # Safety
/// `x` is null or points to 2 readable and writable, aligned `f32`.
#[cfg(feature = "pendulum-plant")]
#[no_mangle]
pub unsafe extern "C" fn ampc_example_pendulum_step(x: *mut f32, u: f32) {
    if x.is_null() {
        return;
    }
    let p = x.cast::<[f32; 2]>();
    // SAFETY: x is non-null and points to 2 readable, writable, aligned f32 (contract).
    unsafe { p.write(plant::rk4_step(p.read(), u)) };
}

pub mod safe;

/// The Rust firmware's plant, compiled from its very source file (no dependency on the
/// firmware crate, whose Cortex-M runtime must not end up in the static library).
#[cfg(feature = "pendulum-plant")]
#[path = "../../../firmware-example/src/plant.rs"]
mod plant;

#[cfg(all(target_os = "none", not(test)))]
#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    // Unreachable from `ampc_evaluate` (checked on the ELF); a defined end if it ever were.
    loop {
        core::hint::spin_loop();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn evaluate_through_pointers_is_the_core() {
        for x in [[-3.0f32, 0.0], [0.1, -0.2], [9.0, 0.0], [f32::NAN, 0.0]] {
            let mut u = [7.0f32; NU];
            // SAFETY: both arrays are live, aligned and of the right length.
            let flags = unsafe { ampc_evaluate(x.as_ptr(), u.as_mut_ptr()) };
            let want = controller_core::demo::evaluate(&x);
            assert_eq!(u.map(f32::to_bits), want.u.map(f32::to_bits));
            assert_eq!(flags, want.flags.0);
        }
    }

    #[test]
    fn null_pointers_give_the_documented_answer() {
        let mut u = [7.0f32; NU];
        // SAFETY: null x is allowed; u is a live array.
        let f = unsafe { ampc_evaluate(core::ptr::null(), u.as_mut_ptr()) };
        assert_eq!(f, Flags::NON_FINITE.0 | FLAG_NULL_ARGUMENT);
        assert_eq!(u, CERTIFICATE.fallback);
        let x = [0.0f32; NX];
        // SAFETY: null u is allowed.
        let f = unsafe { ampc_evaluate(x.as_ptr(), core::ptr::null_mut()) };
        assert_eq!(f, FLAG_NULL_ARGUMENT);
        // SAFETY: both null.
        assert_eq!(
            unsafe { ampc_evaluate(core::ptr::null(), core::ptr::null_mut()) },
            FLAG_NULL_ARGUMENT
        );
    }

    #[test]
    fn overlapping_x_and_u_read_x_first() {
        let mut buf = [0.3f32, -0.1];
        let want = controller_core::demo::evaluate(&[0.3, -0.1]);
        let p = buf.as_mut_ptr();
        // SAFETY: buf holds NX = 2 ≥ NU floats; x is read before u is written.
        let f = unsafe { ampc_evaluate(p, p) };
        assert_eq!((buf[0].to_bits(), f), (want.u[0].to_bits(), want.flags.0));
    }

    #[test]
    fn linked_certificate_is_the_core_certificate() {
        let c = &ampc_linked_certificate;
        assert_eq!(c.eps.to_bits(), CERTIFICATE.eps.to_bits());
        assert_eq!(c.guarantee, CERTIFICATE.guarantee as u8);
        assert_eq!(
            (c.domain_lo, c.domain_hi),
            (CERTIFICATE.domain_lo, CERTIFICATE.domain_hi)
        );
        assert_eq!(
            (c.clamp_lo, c.clamp_hi),
            (CERTIFICATE.clamp_lo, CERTIFICATE.clamp_hi)
        );
        let n = c
            .hash
            .iter()
            .position(|b| *b == 0)
            .unwrap_or(HASH_CAPACITY + 1);
        assert_eq!(&c.hash[..n], CERTIFICATE.hash.as_bytes());
    }
}
