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
    fn run_produces_91_rows_from_the_hanging_position() {
        let mut rows = Vec::new();
        run(|r| rows.push(*r));
        assert_eq!(rows.len(), STEPS + 1);
        assert_eq!(rows[0].x, [-core::f32::consts::PI, 0.0]);
        assert!(rows.iter().all(|r| r.u.is_finite() && r.u.abs() <= 15.0));
    }
}
