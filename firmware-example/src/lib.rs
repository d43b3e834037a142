//! The firmware's portable part: the controller it runs, the pendulum plant, the control
//! loop, the probe states and a float printer.
//!
//! The controller ([`controller`]) is the `trainer export` file named by the environment
//! variable `AMPC_WEIGHTS` at build time (any NX, NU; `build.rs` copies it), else
//! controller-core's compiled-in one (the paper's pendulum). Every binary but the closed
//! loop works for any controller: `evaluate-check` and `evaluate-bench` derive their states
//! from the certificate's X.
//!
//! Plant of the closed loop (the paper's pendulum, x1 = θ − π, 0 = upright): ẋ1 = x2,
//! ẋ2 = u/(m l²) − (g/l) sin(x1 + π), m = l = 1, g = 9.81, integrated in f32 by one RK4
//! step per Ts = 0.05 s (`libm::sinf`, the same code on host and device). [`run`] drives
//! [`STEPS`] steps from (−π, 0) with [`evaluate`] and hands each row to a sink; the
//! firmware prints them over semihosting, the host test collects them. It runs only with the
//! built-in pendulum controller ([`CLOSED_LOOP`]: no `AMPC_WEIGHTS`); another plant, or
//! another controller of the same sizes, needs its own f32 model in place of `plant.rs`.
//! No `core::fmt` anywhere: [`decimal::write_f32`] prints floats with 9 significant digits,
//! which round-trip exactly to the same f32.
#![cfg_attr(not(test), no_std)]

pub mod decimal;
pub mod plant;

/// The controller of this build: `AMPC_WEIGHTS`'s file, else controller-core's demo (the pendulum).
pub mod controller {
    controller_core::include_controller!(concat!(env!("OUT_DIR"), "/weights.rs"));
}

pub use controller::{evaluate, CERTIFICATE, CONTROLLER, NU, NX};

use controller_core::Flags;

/// Whether [`run`] simulates the closed loop: only with the built-in pendulum controller
/// (built without `AMPC_WEIGHTS`, whose plant `plant.rs` models), nx = 2, nu = 1.
pub const CLOSED_LOOP: bool = cfg!(ampc_pendulum) && NX == 2 && NU == 1;

/// Number of control steps of the upswing.
pub const STEPS: usize = 90;

/// One row of the trajectory: step, state, input applied, flags.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Row {
    /// Step index k.
    pub k: usize,
    /// State x_k.
    pub x: [f32; NX],
    /// Input u_k = controller(x_k) (also computed at the last row, not applied).
    pub u: [f32; NU],
    /// Controller flags at x_k.
    pub flags: Flags,
}

/// Runs the closed loop from (−π, 0) for [`STEPS`] steps, rows k = 0..=STEPS; returns
/// `false` without a row unless [`CLOSED_LOOP`] (the controller is not the built-in
/// pendulum's, whose plant this loop simulates).
pub fn run(mut sink: impl FnMut(&Row)) -> bool {
    if !CLOSED_LOOP {
        return false;
    }
    let mut x = [0.0f32; NX];
    if let Some(x1) = x.first_mut() {
        *x1 = -core::f32::consts::PI;
    }
    for k in 0..=STEPS {
        let out = evaluate(&x);
        sink(&Row {
            k,
            x,
            u: out.u,
            flags: out.flags,
        });
        let at = |v: &[f32], i: usize| v.get(i).copied().unwrap_or(0.0);
        let next = plant::rk4_step([at(&x, 0), at(&x, 1)], at(&out.u, 0));
        for (xi, n) in x.iter_mut().zip(next) {
            *xi = n;
        }
    }
    true
}

/// Number of states of [`probe_state`].
pub const PROBES: u32 = 600;

/// The `i`-th state of the device-versus-host check (`evaluate-check` prints [`evaluate`]
/// on each; `tests/firmware_in_qemu.rs` compares the bits with the host): first 16 edge
/// cases (zeros of both signs, NaN, ±inf, subnormals, huge values, the corners of X and
/// points just outside, each spread over the components), then pseudo-random states
/// (xorshift32, fixed seed) uniform on X widened by 10 % of its width on each side,
/// computed in f32. For nx = 2 the edge cases are the pairs listed in the code; for nx = 1,
/// states 16–21 are edge cases too (the pairs' second values).
pub fn probe_state(i: u32) -> [f32; NX] {
    let lo = CERTIFICATE.domain_lo.map(|v| v as f32);
    let hi = CERTIFICATE.domain_hi.map(|v| v as f32);
    // Edge case i: (first component, the others), alternating over the components.
    let pick = |a: f32, b: f32| -> [f32; NX] {
        let mut x = [b; NX];
        for (k, v) in x.iter_mut().enumerate() {
            if k % 2 == 0 {
                *v = a;
            }
        }
        x
    };
    let mixed = |a: &[f32; NX], b: &[f32; NX]| -> [f32; NX] {
        let mut x = *a;
        for (k, v) in x.iter_mut().enumerate() {
            if k % 2 == 1 {
                *v = b.get(k).copied().unwrap_or(0.0);
            }
        }
        x
    };
    let mut out_lo = [0.0f32; NX];
    let mut out_hi = [0.0f32; NX];
    if let Some(v) = out_lo.first_mut() {
        *v = lo.first().copied().unwrap_or(0.0) - 1.0;
    }
    if let Some(v) = out_hi.last_mut() {
        *v = hi.last().copied().unwrap_or(0.0) + 1.0;
    }
    let fixed = match i {
        0 => Some(pick(0.0, 0.0)),
        1 => Some(pick(-0.0, -0.0)),
        2 => Some(pick(f32::NAN, 0.0)),
        3 => Some(pick(0.0, f32::INFINITY)),
        4 => Some(pick(f32::NEG_INFINITY, 0.5)),
        5 => Some(pick(1.0e-40, -1.0e-40)),
        6 => Some(pick(1.0e30, -1.0e30)),
        7 => Some(pick(-f32::MAX, f32::MAX)),
        8 => Some(lo),
        9 => Some(hi),
        10 => Some(mixed(&lo, &hi)),
        11 => Some(mixed(&hi, &lo)),
        12 => Some(out_lo),
        13 => Some(out_hi),
        14 => Some(pick(f32::MIN_POSITIVE, -f32::MIN_POSITIVE)),
        15 => Some(pick(-1.0e-3, 2.0e-3)),
        // With one component `pick` keeps only its first value: the second ones here.
        16..=21 if NX == 1 => [
            f32::INFINITY,
            0.5,
            -1.0e-40,
            -1.0e30,
            f32::MAX,
            -f32::MIN_POSITIVE,
        ]
        .get(i as usize - 16)
        .map(|&v| [v; NX]),
        _ => None,
    };
    if let Some(x) = fixed {
        return x;
    }
    let mut s = 0x9e37_79b9u32 ^ i.wrapping_mul(0x85eb_ca6b);
    let mut unit = || {
        s ^= s << 13;
        s ^= s >> 17;
        s ^= s << 5;
        (s >> 8) as f32 / (1u32 << 24) as f32
    };
    let mut x = [0.0f32; NX];
    for ((xi, l), h) in x.iter_mut().zip(lo).zip(hi) {
        *xi = l + (h - l) * (1.2 * unit() - 0.1);
    }
    x
}

/// The `s`-th of the 8 states `evaluate-bench` cycles through: for the built-in pendulum
/// ([`CLOSED_LOOP`]) the 8 states of the recorded measurements, else a Latin hypercube in X
/// (component k of state s at the centre of stratum (s·(2k + 3)) mod 8 of [lo_k, hi_k];
/// components k and k + 4 share their strata).
pub fn bench_state(s: usize) -> [f32; NX] {
    const PENDULUM: [[f32; 2]; 8] = [
        [-3.1, 0.0],
        [-2.0, 0.5],
        [-1.0, -0.8],
        [-0.2, 0.3],
        [0.1, -0.1],
        [1.5, 0.9],
        [2.5, -0.4],
        [5.0, 0.7],
    ];
    let mut x = [0.0f32; NX];
    if CLOSED_LOOP {
        if let Some(p) = PENDULUM.get(s % 8) {
            for (xi, v) in x.iter_mut().zip(p) {
                *xi = *v;
            }
        }
        return x;
    }
    for (k, xi) in x.iter_mut().enumerate() {
        let (l, h) = (CERTIFICATE.domain_lo[k], CERTIFICATE.domain_hi[k]);
        let stratum = ((s % 8) * (2 * k + 3)) % 8;
        *xi = (l + (h - l) * (stratum as f64 + 0.5) / 8.0) as f32;
    }
    x
}

/// CSV header of the closed loop's output (the pendulum's: nx = 2, nu = 1).
pub const HEADER: &str = "k,x1,x2,u,flags";

/// Bytes of a formatted row: the index (≤ 10 digits), NX + NU floats of at most 16 bytes
/// each after a comma, the flags (≤ 3 digits) after a comma, the newline.
pub const ROW_BYTES: usize = 16 + 17 * (NX + NU);

/// Formats a row as `k,x1,…,u1,…,flags\n` into `buf` (for the pendulum `k,x1,x2,u,flags`);
/// returns the number of bytes.
pub fn format_row(row: &Row, buf: &mut [u8; ROW_BYTES]) -> usize {
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
    for v in row.x.iter().chain(&row.u).copied() {
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
    #[cfg(ampc_pendulum)]
    fn rows_are_formatted_as_csv() {
        let mut buf = [0u8; ROW_BYTES];
        let r = Row {
            k: 7,
            x: [-std::f32::consts::PI, 0.5],
            u: [15.0],
            flags: Flags(5),
        };
        let n = format_row(&r, &mut buf);
        let s = std::str::from_utf8(&buf[..n]).unwrap();
        assert_eq!(s, "7,-3.14159274e0,5.00000000e-1,1.50000000e1,5\n");
    }

    #[test]
    fn probe_states_cover_edges_inside_and_outside() {
        let lo = CERTIFICATE.domain_lo;
        let hi = CERTIFICATE.domain_hi;
        let xs: Vec<[f32; NX]> = (0..PROBES).map(probe_state).collect();
        assert!(xs.iter().any(|x| x[0].is_nan()));
        let inside =
            |x: &[f32; NX]| (0..NX).all(|i| f64::from(x[i]) >= lo[i] && f64::from(x[i]) <= hi[i]);
        let n_in = xs.iter().filter(|x| inside(x)).count();
        assert!(
            n_in > PROBES as usize / 2 && n_in < PROBES as usize - 50,
            "{n_in}"
        );
        assert_ne!(xs[100], xs[101]);
        assert_eq!(xs[8].map(f64::from), lo.map(|v| f64::from(v as f32)));
    }

    #[test]
    fn bench_states_lie_in_x() {
        let (lo, hi) = (CERTIFICATE.domain_lo, CERTIFICATE.domain_hi);
        for s in 0..8 {
            let x = bench_state(s);
            assert!((0..NX).all(|k| f64::from(x[k]) >= lo[k] && f64::from(x[k]) <= hi[k]));
        }
        assert_ne!(bench_state(0), bench_state(1));
    }

    #[test]
    #[cfg(ampc_pendulum)]
    fn run_produces_91_rows_from_the_hanging_position() {
        let mut rows = Vec::new();
        assert!(run(|r| rows.push(*r)));
        assert_eq!(rows.len(), STEPS + 1);
        assert_eq!(rows[0].x, [-core::f32::consts::PI, 0.0]);
        assert!(rows
            .iter()
            .all(|r| r.u[0].is_finite() && r.u[0].abs() <= 15.0));
    }
}
