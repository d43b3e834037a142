//! Measurement firmware for `controller_core::demo::evaluate` on the Cortex-M4 or the Cortex-M0 (QEMU;
//! `tools/measure.sh`).
//!
//! Reads the number of calls N from the semihosting command line
//! (`-semihosting-config enable=on,target=native,arg=evaluate-bench,arg=N`, default 1),
//! evaluates N states (cycling through the 8 states of `firmware_example::bench_state`, in
//! X), and prints
//! `calls=N stack_bytes=S u_sum_bits=…`. S is the stack used by one call, by stack painting:
//! 4 KiB below the current stack pointer are filled with a pattern, `ampc_evaluate` is
//! called, and the deepest overwritten word gives the depth. Executed instructions per
//! call come from an instruction-counting TCG plugin: (count(N = 1001) − count(N = 1))/1000
//! (see BENCHMARKS.md). `ampc_evaluate` is the non-inlined, unmangled entry point whose
//! call graph the QEMU test checks for panic paths.
#![cfg_attr(target_os = "none", no_std)]
#![cfg_attr(target_os = "none", no_main)]

#[cfg(target_os = "none")]
mod device {
    use controller_core::{Controller, Output};
    use core::hint::black_box;
    use cortex_m_rt::entry;
    use cortex_m_semihosting::{debug, hio, syscall};
    use firmware_example::bench_state;
    use firmware_example::controller::{weights::Net, NU, NX};
    use firmware_example::decimal::write_u32;

    /// The controller as a named static (weights in flash), so its size shows in `nm`.
    #[no_mangle]
    pub static AMPC_CONTROLLER: Controller<NX, NU, Net> = firmware_example::CONTROLLER;

    /// The measured entry point.
    #[no_mangle]
    #[inline(never)]
    pub fn ampc_evaluate(x: &[f32; NX]) -> Output<NU> {
        AMPC_CONTROLLER.evaluate(x)
    }

    const PAINT: u32 = 0xDEAD_BEEF;
    const DEPTH: usize = 1024; // words

    fn calls() -> u32 {
        let mut buf = [0u8; 64];
        // SAFETY: GET_CMDLINE writes at most `buf.len()` bytes into `buf`.
        let r = unsafe { syscall!(GET_CMDLINE, buf.as_mut_ptr(), buf.len()) };
        if r != 0 {
            return 1;
        }
        // "evaluate-bench N": the number after the last space.
        let end = buf.iter().position(|b| *b == 0).unwrap_or(buf.len());
        let line = buf.get(..end).unwrap_or(&[]);
        let start = line.iter().rposition(|b| *b == b' ').map_or(0, |p| p + 1);
        let mut n: u32 = 0;
        for b in line.get(start..).unwrap_or(&[]) {
            if b.is_ascii_digit() {
                n = n.saturating_mul(10).saturating_add(u32::from(b - b'0'));
            }
        }
        n.max(1)
    }

    #[inline(never)]
    fn stack_use() -> usize {
        let sp = cortex_m::register::msp::read() as usize;
        let top = (sp - 64) & !3;
        let bottom = top - 4 * DEPTH;
        // SAFETY: the 4 KiB below the stack pointer are unused stack (4 MiB of RAM).
        unsafe {
            for a in (bottom..top).step_by(4) {
                core::ptr::write_volatile(a as *mut u32, PAINT);
            }
        }
        black_box(ampc_evaluate(black_box(&bench_state(0))));
        let mut lowest = top;
        for a in (bottom..top).step_by(4) {
            // SAFETY: same region as above.
            if unsafe { core::ptr::read_volatile(a as *const u32) } != PAINT {
                lowest = a;
                break;
            }
        }
        sp - lowest
    }

    #[entry]
    fn main() -> ! {
        let n = calls();
        let stack = stack_use();
        let states: [[f32; NX]; 8] = core::array::from_fn(bench_state);
        let mut acc = 0u32;
        for i in 0..n {
            let x = states[(i % 8) as usize];
            let o = black_box(ampc_evaluate(black_box(&x)));
            acc = o.u.iter().fold(acc, |a, u| a.wrapping_add(u.to_bits()));
        }
        let mut ok = false;
        if let Ok(mut out) = hio::hstdout() {
            let mut t = [0u8; 24];
            ok = true;
            for (label, v) in [
                ("calls=", n),
                (" stack_bytes=", stack as u32),
                (" u_sum_bits=", acc),
            ] {
                let l = write_u32(v, &mut t);
                ok &= out.write_all(label.as_bytes()).is_ok();
                ok &= out.write_all(&t[..l]).is_ok();
            }
            ok &= out.write_all(b"\n").is_ok();
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
    println!("evaluate-bench: Cortex-M4 measurement firmware (see BENCHMARKS.md)");
}
