//! Check firmware: the controller's `evaluate` on the [`firmware_example::PROBES`] states
//! of [`firmware_example::probe_state`], one line `i,x1_bits,…,u1_bits,…,flags` each (each
//! x and u as the decimal of its f32 bit pattern), then exit 0. `tests/firmware_in_qemu.rs`
//! runs it on the Cortex-M4 (mps2-an386) and the Cortex-M0 (microbit) and compares every
//! line with the host. On the host it prints the same lines (the host's reference), see [`lines`].
#![cfg_attr(target_os = "none", no_std)]
#![cfg_attr(target_os = "none", no_main)]

#[cfg(target_os = "none")]
mod device {
    use cortex_m_rt::entry;
    use cortex_m_semihosting::{debug, hio};

    #[entry]
    fn main() -> ! {
        let mut ok = false;
        if let Ok(mut out) = hio::hstdout() {
            ok = true;
            super::lines(|b| ok &= out.write_all(b).is_ok());
        }
        debug::exit(if ok {
            debug::EXIT_SUCCESS
        } else {
            debug::EXIT_FAILURE
        });
        loop {}
    }

    #[panic_handler]
    fn panic(_: &core::panic::PanicInfo) -> ! {
        debug::exit(debug::EXIT_FAILURE);
        loop {}
    }
}

/// Hands the check's output to `write`, piece by piece: per probe state i the line
/// `i,x1_bits,…,x_NX_bits,u1_bits,…,u_NU_bits,flags`.
fn lines(mut write: impl FnMut(&[u8])) {
    use firmware_example::decimal::write_u32;
    use firmware_example::{evaluate, probe_state, PROBES};
    let mut t = [0u8; 24];
    for i in 0..PROBES {
        let x = probe_state(i);
        let o = evaluate(&x);
        let mut num = |v: u32, sep: &[u8]| {
            let l = write_u32(v, &mut t);
            write(t.get(..l).unwrap_or(&[]));
            write(sep);
        };
        num(i, b",");
        for v in x {
            num(v.to_bits(), b",");
        }
        for u in o.u {
            num(u.to_bits(), b",");
        }
        num(u32::from(o.flags.0), b"\n");
    }
}

/// On the host: the same lines on standard output (the reference the device is compared
/// with, for whatever controller `AMPC_WEIGHTS` named at build time).
#[cfg(not(target_os = "none"))]
fn main() {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    let mut ok = true;
    lines(|b| ok &= out.write_all(b).is_ok());
    if !ok || out.flush().is_err() {
        std::process::exit(1);
    }
}
