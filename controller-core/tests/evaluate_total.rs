//! `evaluate` is total: for every bit pattern of the state, `u` is finite and inside the
//! certified clamp band, and the flags say what happened. 10⁴ cases in the normal run;
//! the ignored test runs 10⁶ (release, from `.ci/run`).
#![allow(clippy::indexing_slicing, clippy::unwrap_used)] // test code

use controller_core::{
    demo::{CERTIFICATE, CONTROLLER},
    Flags,
};
use proptest::prelude::*;
use proptest::test_runner::{Config, TestRunner};

fn check(bits: [u32; 2]) -> Result<(), TestCaseError> {
    let x = bits.map(f32::from_bits);
    let o = CONTROLLER.evaluate(&x);
    for j in 0..o.u.len() {
        prop_assert!(o.u[j].is_finite());
        prop_assert!(CERTIFICATE.clamp_lo[j] <= o.u[j] && o.u[j] <= CERTIFICATE.clamp_hi[j]);
        prop_assert!(CERTIFICATE.actuator_lo[j] <= f64::from(o.u[j]));
        prop_assert!(f64::from(o.u[j]) <= CERTIFICATE.actuator_hi[j]);
    }
    let finite = x.iter().all(|v| v.is_finite());
    prop_assert_eq!(o.flags.contains(Flags::NON_FINITE), !finite);
    if !finite {
        prop_assert_eq!(o.u, CERTIFICATE.fallback);
    } else {
        let inside = (0..2).all(|i| CONTROLLER.x_lo[i] <= x[i] && x[i] <= CONTROLLER.x_hi[i]);
        prop_assert_eq!(o.flags.contains(Flags::OUT_OF_DOMAIN), !inside);
    }
    Ok(())
}

/// Bit patterns: uniform u32 (mostly huge/tiny magnitudes, NaNs), plus states in and
/// near the domain, so every branch is exercised.
fn states() -> impl Strategy<Value = [u32; 2]> {
    prop_oneof![
        any::<[u32; 2]>(),
        (-8.0f32..8.0, -1.5f32..1.5).prop_map(|(a, b)| [a.to_bits(), b.to_bits()]),
    ]
}

fn run(cases: u32) {
    let mut runner = TestRunner::new(Config {
        cases,
        failure_persistence: None,
        ..Config::default()
    });
    runner.run(&states(), check).unwrap();
}

#[test]
fn evaluate_is_total_10k() {
    run(10_000);
}

#[test]
#[ignore = "10^6 cases; run in release by .ci/run"]
fn evaluate_is_total_1m() {
    run(1_000_000);
}

#[test]
fn special_values() {
    for v in [
        f32::NAN,
        f32::INFINITY,
        f32::NEG_INFINITY,
        -0.0,
        f32::MIN_POSITIVE,
        f32::MAX,
    ] {
        check([v.to_bits(), 0]).unwrap();
        check([0, v.to_bits()]).unwrap();
    }
}
