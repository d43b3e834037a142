//! Firmware example: the paper's pendulum upswing in closed loop on a Cortex-M4 (`cargo
//! firmware`, QEMU mps2-an386) or a Cortex-M0/M0+ (`cargo firmware-m0`, QEMU microbit).
//!
//! Runs [`firmware_example::run`] (RK4 plant in f32 + the controller, 90 steps from
//! (−π, 0)) and prints `k,x1,x2,u,flags` rows over semihosting, then exits with status 0
//! (1 on a panic or a semihosting write error). Another controller (built with
//! `AMPC_WEIGHTS`) gets one line `# closed loop skipped …` instead of the header and the rows
//! (its plant has no f32 model here). Build and run in QEMU: `cargo firmware`. On the host this
//! binary only prints a hint.
#![cfg_attr(target_os = "none", no_std)]
#![cfg_attr(target_os = "none", no_main)]

#[cfg(target_os = "none")]
mod device {
    use cortex_m_rt::entry;
    use cortex_m_semihosting::{debug, hio};
    use firmware_example::{format_row, run, CLOSED_LOOP, HEADER, ROW_BYTES};

    #[entry]
    fn main() -> ! {
        let mut ok = false;
        if let Ok(mut out) = hio::hstdout() {
            ok = !CLOSED_LOOP
                || (out.write_all(HEADER.as_bytes()).is_ok() && out.write_all(b"\n").is_ok());
            let mut buf = [0u8; ROW_BYTES];
            let ran = run(|row| {
                let n = format_row(row, &mut buf);
                ok &= out.write_all(buf.get(..n).unwrap_or(&[])).is_ok();
            });
            if !ran {
                ok &= out
                    .write_all(
                        b"# closed loop skipped: the controller is not the built-in \
                          pendulum's (AMPC_WEIGHTS), and src/plant.rs models only that plant; \
                          evaluate-check and evaluate-bench run any controller\n",
                    )
                    .is_ok();
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
    println!("firmware-example: run it on the Cortex-M4 (QEMU) with `cargo firmware`");
}
