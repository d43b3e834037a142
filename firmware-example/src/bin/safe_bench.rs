//! Measurement firmware for `controller_core::safe::SafeController::step_with` on the
//! generated pendulum (`pendulum_ode_safe.rs`, with the argument `pendulum`) or the
//! generated planar quadrotor (`tests/fixtures/safe-plant/planar_quadrotor_safe.rs`: f32 RK4,
//! constraints, costs, the nominal terminal ingredients and `MARGINS`), N = 20, on the
//! Cortex-M4 or the Cortex-M0 (QEMU; `tools/measure.sh safe`).
//!
//! Two kinds of entry points: the check alone (`ampc_safe_step`, `ampc_safe_step_pendulum`:
//! `step_with` a given candidate), and the whole controller with its sequence network
//! (`ampc_safe_step_net`, `ampc_safe_step_net_pendulum`: `step`, the network's candidate then
//! the check — the file `trainer export --safe-rs` writes,
//! `tests/fixtures/safe-controller/*_safe.rs`, compiled with
//! `controller_core::include_safe_controller!`; command-line word `net`). A safe sequence is adopted first
//! (`init_with` the terminal controller's sequence from a state of X_f), so every measured
//! step checks both the candidate and the shifted safe sequence over all N steps — the
//! check's work does not depend on the data (`SafeController::check`). Reads the number of
//! calls from the semihosting command line and prints
//! `calls=N stack_bytes=S flags_sum=… u_sum_bits=…`; instructions per step from the
//! instruction-counting plugin, (count(N = 1001) − count(N = 1))/1000.
#![cfg_attr(target_os = "none", no_std)]
#![cfg_attr(target_os = "none", no_main)]

#[cfg(target_os = "none")]
#[allow(dead_code, clippy::all)]
mod quad {
    include!(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../tests/fixtures/safe-plant/planar_quadrotor_safe.rs"
    ));
}

#[cfg(target_os = "none")]
#[allow(dead_code, clippy::all)]
mod pend {
    include!(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../tests/fixtures/safe-plant/pendulum_ode_safe.rs"
    ));
}

#[cfg(target_os = "none")]
mod quad_net {
    controller_core::include_safe_controller!(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../tests/fixtures/safe-controller/planar_quadrotor_safe.rs"
    ));
}

#[cfg(target_os = "none")]
mod pend_net {
    controller_core::include_safe_controller!(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../tests/fixtures/safe-controller/pendulum_ode_safe.rs"
    ));
}

#[cfg(target_os = "none")]
mod device {
    use super::{pend, pend_net, quad, quad_net};
    use controller_core::safe::{Plant, SafeController, SafeOutput};
    use core::hint::black_box;
    use cortex_m_rt::entry;
    use cortex_m_semihosting::{debug, hio, syscall};
    use firmware_example::decimal::write_u32;

    const N: usize = 20;
    type Ctl = SafeController<quad::SafePlant, (), 6, 2, N>;

    /// The measured entry point.
    #[no_mangle]
    #[inline(never)]
    pub fn ampc_safe_step(ctl: &mut Ctl, x: &[f32; 6], cand: &[[f32; 2]; N]) -> SafeOutput<2> {
        ctl.step_with(x, *cand)
    }

    type PendCtl = SafeController<pend::SafePlant, (), 2, 1, N>;

    /// The measured entry point of the quadrotor with its sequence network
    /// (`safe-bench net N`): the network's candidate, then the check.
    #[no_mangle]
    #[inline(never)]
    pub fn ampc_safe_step_net(ctl: &mut quad_net::safe::Controller, x: &[f32; 6]) -> SafeOutput<2> {
        ctl.step(x)
    }

    /// The measured entry point of the pendulum with its sequence network
    /// (`safe-bench pendulum net N`).
    #[no_mangle]
    #[inline(never)]
    pub fn ampc_safe_step_net_pendulum(
        ctl: &mut pend_net::safe::Controller,
        x: &[f32; 2],
    ) -> SafeOutput<1> {
        ctl.step(x)
    }

    /// `n` steps of `f` over four states (flags sum, u bits sum).
    fn steps<const NX: usize, const NU: usize>(
        n: u32,
        states: &[[f32; NX]; 4],
        mut f: impl FnMut(&[f32; NX]) -> SafeOutput<NU>,
    ) -> (u32, u32) {
        let (mut acc, mut fl) = (0u32, 0u32);
        for i in 0..n {
            let x = states.get((i % 4) as usize).copied().unwrap_or([0.0; NX]);
            let o = black_box(f(black_box(&x)));
            acc = o.u.iter().fold(acc, |a, u| a.wrapping_add(u.to_bits()));
            fl = fl.wrapping_add(u32::from(o.flags.0));
        }
        (fl, acc)
    }

    /// The pendulum with its network: (init, flags sum, u bits sum) over n steps.
    fn pendulum_net(n: u32) -> (bool, u32, u32) {
        let p = pend::SafePlant;
        let x0 = [0.1f32, -0.1];
        let mut x = x0;
        let seq: [[f32; 1]; N] = core::array::from_fn(|_| {
            let u = p.project_input(&p.terminal_input(&x));
            x = p.step(&x, &u);
            u
        });
        let mut ctl = pend_net::safe::CONTROLLER;
        let init_ok = ctl.init_with(&x0, &seq).is_ok();
        let states: [[f32; 2]; 4] = [x0, [0.05, 0.1], [-0.1, 0.05], [0.02, -0.02]];
        let (fl, acc) = steps(n, &states, |x| ampc_safe_step_net_pendulum(&mut ctl, x));
        (init_ok, fl, acc)
    }

    /// The quadrotor with its network: (init, flags sum, u bits sum) over n steps.
    fn quadrotor_net(n: u32) -> (bool, u32, u32) {
        let x0 = [0.05f32, -0.05, 0.02, 0.0, 0.05, 0.0];
        let seq = kappa_sequence(&x0);
        let mut ctl = quad_net::safe::CONTROLLER;
        let init_ok = ctl.init_with(&x0, &seq).is_ok();
        let (fl, acc) = steps(n, &QUAD_STATES, |x| ampc_safe_step_net(&mut ctl, x));
        (init_ok, fl, acc)
    }

    /// The quadrotor's measurement states.
    const QUAD_STATES: [[f32; 6]; 4] = [
        [0.05, -0.05, 0.02, 0.0, 0.05, 0.0],
        [0.04, -0.04, 0.015, 0.01, 0.04, 0.0],
        [-0.05, 0.05, -0.02, 0.0, -0.05, 0.01],
        [0.02, 0.01, 0.0, -0.01, 0.0, 0.0],
    ];

    /// Prints `prefix` then `calls=`, `init=`, `flags_sum=`, `u_sum_bits=` and exits.
    fn report(prefix: &str, n: u32, (init_ok, fl, acc): (bool, u32, u32)) -> ! {
        let mut ok = init_ok;
        if let Ok(mut out) = hio::hstdout() {
            let mut t = [0u8; 24];
            ok &= out.write_all(prefix.as_bytes()).is_ok();
            for (label, v) in [
                ("calls=", n),
                (" init=", u32::from(init_ok)),
                (" flags_sum=", fl),
                (" u_sum_bits=", acc),
            ] {
                let l = write_u32(v, &mut t);
                ok &= out.write_all(label.as_bytes()).is_ok();
                ok &= out.write_all(t.get(..l).unwrap_or(&[])).is_ok();
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

    /// The measured entry point of the pendulum (`safe-bench pendulum N`).
    #[no_mangle]
    #[inline(never)]
    pub fn ampc_safe_step_pendulum(
        ctl: &mut PendCtl,
        x: &[f32; 2],
        cand: &[[f32; 1]; N],
    ) -> SafeOutput<1> {
        ctl.step_with(x, *cand)
    }

    /// The pendulum's measurement: (init, flags sum, u bits sum) over n steps.
    fn pendulum(n: u32) -> (bool, u32, u32) {
        let p = pend::SafePlant;
        let x0 = [0.1f32, -0.1];
        let mut x = x0;
        let seq: [[f32; 1]; N] = core::array::from_fn(|_| {
            let u = p.project_input(&p.terminal_input(&x));
            x = p.step(&x, &u);
            u
        });
        let mut ctl: PendCtl = SafeController::new(pend::SafePlant, (), pend::MARGINS);
        let init_ok = ctl.init_with(&x0, &seq).is_ok();
        let states: [[f32; 2]; 4] = [x0, [0.05, 0.1], [-0.1, 0.05], [0.02, -0.02]];
        let (mut acc, mut fl) = (0u32, 0u32);
        for i in 0..n {
            let x = states[(i % 4) as usize];
            let o = black_box(ampc_safe_step_pendulum(
                &mut ctl,
                black_box(&x),
                black_box(&seq),
            ));
            acc = o.u.iter().fold(acc, |a, u| a.wrapping_add(u.to_bits()));
            fl = fl.wrapping_add(u32::from(o.flags.0));
        }
        (init_ok, fl, acc)
    }

    /// Whether the command line holds the word `word`.
    fn wants(word: &[u8]) -> bool {
        let mut buf = [0u8; 64];
        // SAFETY: GET_CMDLINE writes at most `buf.len()` bytes into `buf`.
        let r = unsafe { syscall!(GET_CMDLINE, buf.as_mut_ptr(), buf.len()) };
        r == 0 && buf.windows(word.len()).any(|w| w == word)
    }

    /// The terminal controller's sequence from `x`.
    fn kappa_sequence(x: &[f32; 6]) -> [[f32; 2]; N] {
        let p = quad::SafePlant;
        let mut x = *x;
        core::array::from_fn(|_| {
            let u = p.project_input(&p.terminal_input(&x));
            x = p.step(&x, &u);
            u
        })
    }

    fn calls() -> u32 {
        let mut buf = [0u8; 64];
        // SAFETY: GET_CMDLINE writes at most `buf.len()` bytes into `buf`.
        let r = unsafe { syscall!(GET_CMDLINE, buf.as_mut_ptr(), buf.len()) };
        if r != 0 {
            return 1;
        }
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

    const PAINT: u32 = 0xDEAD_BEEF;
    const DEPTH: usize = 2048; // words

    #[inline(never)]
    fn stack_use(ctl: &mut Ctl, x: &[f32; 6], cand: &[[f32; 2]; N]) -> usize {
        let sp = cortex_m::register::msp::read() as usize;
        let top = (sp - 64) & !3;
        let bottom = top - 4 * DEPTH;
        // SAFETY: the 8 KiB below the stack pointer are unused stack.
        unsafe {
            for a in (bottom..top).step_by(4) {
                core::ptr::write_volatile(a as *mut u32, PAINT);
            }
        }
        black_box(ampc_safe_step(
            black_box(ctl),
            black_box(x),
            black_box(cand),
        ));
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
        match (wants(b"pendulum"), wants(b" net")) {
            (true, true) => report("pendulum net ", n, pendulum_net(n)),
            (false, true) => report("net ", n, quadrotor_net(n)),
            _ => {}
        }
        if wants(b"pendulum") {
            let (init_ok, fl, acc) = pendulum(n);
            let mut ok = init_ok;
            if let Ok(mut out) = hio::hstdout() {
                let mut t = [0u8; 24];
                for (label, v) in [
                    ("pendulum calls=", n),
                    (" init=", u32::from(init_ok)),
                    (" flags_sum=", fl),
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
        }
        let x0 = [0.05f32, -0.05, 0.02, 0.0, 0.05, 0.0];
        let seq = kappa_sequence(&x0);
        let mut ctl: Ctl = SafeController::new(quad::SafePlant, (), quad::MARGINS);
        let init_ok = ctl.init_with(&x0, &seq).is_ok();
        let states: [[f32; 6]; 4] = [
            x0,
            [0.04, -0.04, 0.015, 0.01, 0.04, 0.0],
            [-0.05, 0.05, -0.02, 0.0, -0.05, 0.01],
            [0.02, 0.01, 0.0, -0.01, 0.0, 0.0],
        ];
        let stack = stack_use(&mut ctl, &x0, &seq);
        let (mut acc, mut fl) = (0u32, 0u32);
        for i in 0..n {
            let x = states[(i % 4) as usize];
            let o = black_box(ampc_safe_step(&mut ctl, black_box(&x), black_box(&seq)));
            acc = o.u.iter().fold(acc, |a, u| a.wrapping_add(u.to_bits()));
            fl = fl.wrapping_add(u32::from(o.flags.0));
        }
        let mut ok = init_ok;
        if let Ok(mut out) = hio::hstdout() {
            let mut t = [0u8; 24];
            for (label, v) in [
                ("calls=", n),
                (" stack_bytes=", stack as u32),
                (" init=", u32::from(init_ok)),
                (" flags_sum=", fl),
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
    println!("safe-bench: SafeController measurement firmware (see BENCHMARKS.md)");
}
