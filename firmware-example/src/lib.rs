//! The firmware's portable part: the pendulum plant, the control loop and a float printer.
//!
//! Plant (the paper's pendulum, x1 = θ − π, 0 = upright): ẋ1 = x2,
//! ẋ2 = u/(m l²) − (g/l) sin(x1 + π), m = l = 1, g = 9.81, integrated in f32 by one RK4
//! step per Ts = 0.05 s (`libm::sinf`, the same code on host and device). [`run`] drives
//! [`STEPS`] steps from (−π, 0) with `controller_core::evaluate` and hands each row to a
//! sink; the firmware prints them over semihosting, the host test collects them. No
//! `core::fmt` anywhere: [`decimal::write_f32`] prints floats with 9 significant digits,
//! which round-trip exactly to the same f32.
#![cfg_attr(not(test), no_std)]

pub mod decimal;
pub mod plant;

use controller_core::Flags;

/// Number of control steps of the upswing.
pub const STEPS: usize = 90;

/// One row of the trajectory: step, state, input applied, flags.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Row {
    /// Step index k.
    pub k: usize,
    /// State x_k.
    pub x: [f32; 2],
    /// Input u_k = controller(x_k) (also computed at the last row, not applied).
    pub u: f32,
    /// Controller flags at x_k.
    pub flags: Flags,
}

/// Runs the closed loop from (−π, 0) for [`STEPS`] steps, rows k = 0..=STEPS.
pub fn run(mut sink: impl FnMut(&Row)) {
    let mut x = [-core::f32::consts::PI, 0.0];
    for k in 0..=STEPS {
        let out = controller_core::evaluate(&x);
        let [u] = out.u;
        sink(&Row {
            k,
            x,
            u,
            flags: out.flags,
        });
        x = plant::rk4_step(x, u);
    }
}

/// Number of states of [`probe_state`].
pub const PROBES: u32 = 600;

/// The `i`-th state of the device-versus-host check (`evaluate-check` prints
/// `controller_core::evaluate` on each; `tests/firmware_in_qemu.rs` compares the bits with
/// the host): first 16 edge cases (zeros of both signs, NaN, ±inf, subnormals, huge values,
/// the corners of X and points just outside), then pseudo-random states (xorshift32, fixed
/// seed) uniform on X widened by 10 % of its width on each side, computed in f32.
pub fn probe_state(i: u32) -> [f32; 2] {
    let lo = controller_core::CERTIFICATE.domain_lo.map(|v| v as f32);
    let hi = controller_core::CERTIFICATE.domain_hi.map(|v| v as f32);
    let fixed = [
        [0.0, 0.0],
        [-0.0, -0.0],
        [f32::NAN, 0.0],
        [0.0, f32::INFINITY],
        [f32::NEG_INFINITY, 0.5],
        [1.0e-40, -1.0e-40],
        [1.0e30, -1.0e30],
        [-f32::MAX, f32::MAX],
        lo,
        hi,
        [lo[0], hi[1]],
        [hi[0], lo[1]],
        [lo[0] - 1.0, 0.0],
        [0.0, hi[1] + 1.0],
        [f32::MIN_POSITIVE, -f32::MIN_POSITIVE],
        [-1.0e-3, 2.0e-3],
    ];
    if let Some(x) = fixed.get(i as usize) {
        return *x;
    }
    let mut s = 0x9e37_79b9u32 ^ i.wrapping_mul(0x85eb_ca6b);
    let mut unit = || {
        s ^= s << 13;
        s ^= s >> 17;
        s ^= s << 5;
        (s >> 8) as f32 / (1u32 << 24) as f32
    };
    let mut x = [0.0f32; 2];
    for ((xi, l), h) in x.iter_mut().zip(lo).zip(hi) {
        *xi = l + (h - l) * (1.2 * unit() - 0.1);
    }
    x
}

/// CSV header of the firmware's output.
pub const HEADER: &str = "k,x1,x2,u,flags";

/// Formats a row as `k,x1,x2,u,flags\n` into `buf`; returns the number of bytes.
pub fn format_row(row: &Row, buf: &mut [u8; 96]) -> usize {
    let mut n = 0;
    let mut push = |bytes: &[u8]| {
        for &b in bytes {
            if let Some(slot) = buf.get_mut(n) {
                *slot = b;
                n += 1;
            }
        }
    };
    let mut tmp = [0u8; 24];
    let l = decimal::write_u32(row.k as u32, &mut tmp);
    push(tmp.get(..l).unwrap_or(&[]));
    for v in [row.x[0], row.x[1], row.u] {
        push(b",");
        let l = decimal::write_f32(v, &mut tmp);
        push(tmp.get(..l).unwrap_or(&[]));
    }
    push(b",");
    let l = decimal::write_u32(u32::from(row.flags.0), &mut tmp);
    push(tmp.get(..l).unwrap_or(&[]));
    push(b"\n");
    n
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_are_formatted_as_csv() {
        let mut buf = [0u8; 96];
        let r = Row {
            k: 7,
            x: [-std::f32::consts::PI, 0.5],
            u: 15.0,
            flags: Flags(5),
        };
        let n = format_row(&r, &mut buf);
        let s = std::str::from_utf8(&buf[..n]).unwrap();
        assert_eq!(s, "7,-3.14159274e0,5.00000000e-1,1.50000000e1,5\n");
    }

    #[test]
    fn probe_states_cover_edges_inside_and_outside() {
        let lo = controller_core::CERTIFICATE.domain_lo;
        let hi = controller_core::CERTIFICATE.domain_hi;
        let xs: Vec<[f32; 2]> = (0..PROBES).map(probe_state).collect();
        assert!(xs.iter().any(|x| x[0].is_nan()));
        let inside =
            |x: &[f32; 2]| (0..2).all(|i| f64::from(x[i]) >= lo[i] && f64::from(x[i]) <= hi[i]);
        let n_in = xs.iter().filter(|x| inside(x)).count();
        assert!(
            n_in > PROBES as usize / 2 && n_in < PROBES as usize - 50,
            "{n_in}"
        );
        assert_ne!(xs[100], xs[101]);
    }

    #[test]
    fn run_produces_91_rows_from_the_hanging_position() {
        let mut rows = Vec::new();
        run(|r| rows.push(*r));
        assert_eq!(rows.len(), STEPS + 1);
        assert_eq!(rows[0].x, [-core::f32::consts::PI, 0.0]);
        assert!(rows.iter().all(|r| r.u.is_finite() && r.u.abs() <= 15.0));
    }
}
