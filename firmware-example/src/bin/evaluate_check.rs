//! Check firmware: `controller_core::evaluate` on the [`firmware_example::PROBES`] states of
//! [`firmware_example::probe_state`], one line `i,u_bits,flags` each (u as the decimal of its
//! f32 bit pattern), then exit 0. `tests/firmware_in_qemu.rs` runs it on the Cortex-M4
//! (mps2-an386) and the Cortex-M0 (microbit) and compares every line with the host.
#![cfg_attr(target_os = "none", no_std)]
#![cfg_attr(target_os = "none", no_main)]

#[cfg(target_os = "none")]
mod device {
    use cortex_m_rt::entry;
    use cortex_m_semihosting::{debug, hio};
    use firmware_example::decimal::write_u32;
    use firmware_example::{probe_state, PROBES};

    #[entry]
    fn main() -> ! {
        let mut ok = false;
        if let Ok(mut out) = hio::hstdout() {
            ok = true;
            let mut t = [0u8; 24];
            for i in 0..PROBES {
                let o = controller_core::evaluate(&probe_state(i));
                for (k, v) in [i, o.u[0].to_bits(), u32::from(o.flags.0)]
                    .into_iter()
                    .enumerate()
                {
                    let l = write_u32(v, &mut t);
                    ok &= out.write_all(t.get(..l).unwrap_or(&[])).is_ok();
                    ok &= out.write_all(if k == 2 { b"\n" } else { b"," }).is_ok();
                }
            }
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

#[cfg(not(target_os = "none"))]
fn main() {
    println!("evaluate-check: device-versus-host check firmware (tests/firmware_in_qemu.rs)");
}
