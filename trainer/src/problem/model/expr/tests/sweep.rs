//! The derivative sweeps of `F` ([`Sweep`]) against the dual-number path of the same plant
//! (`ExprPlant::linearize` / `lagrangian_hessian`, an independent implementation of the same
//! derivatives): on smooth expressions covering every operation, through RK4 with one and
//! three sub-steps and as a discrete map, and on random expression trees.

use super::super::{compile, ErrorKind, Sweep, SystemSpec};
use super::props::{render, tree, SMOOTH};
use super::spec;
use crate::problem::model::{DiscretePlant, OdePlant};
use proptest::prelude::*;

/// A linearisation `(f, jx, ju)` into the given buffers.
type Lin<'a> = &'a dyn Fn(&mut [f64], &mut [f64], &mut [f64]);

/// `F`, `∂F/∂(x, u)` and `∇²(λᵀF)` of the sweep and of the dual numbers.
struct Both {
    sweep: [Vec<f64>; 4],
    dual: [Vec<f64>; 4],
}

fn both(spec: &SystemSpec, discrete: bool, substeps: usize, v: &[f64; 3], lam: &[f64; 2]) -> Both {
    let ts = 0.01;
    let (x, u) = (&v[..2], &v[2..]);
    let run = |lin: Lin, hes: &dyn Fn(&mut [f64])| {
        let (mut f, mut jx, mut ju, mut h) =
            (vec![0.0; 2], vec![0.0; 4], vec![0.0; 2], vec![0.0; 9]);
        lin(&mut f, &mut jx, &mut ju);
        hes(&mut h);
        [f, jx, ju, h]
    };
    let model = compile(spec, discrete).unwrap_or_else(|e| panic!("{e}"));
    let sweep: Sweep = model.sweep(ts, substeps);
    let s = run(&|f, jx, ju| sweep.linearize(x, u, f, jx, ju), &|h| {
        sweep.lagrangian_hessian(x, u, lam, h)
    });
    let d = if discrete {
        let p = DiscretePlant::try_from(spec.clone()).unwrap();
        run(
            &|f, jx, ju| p.linearize(ts, substeps, x, u, f, jx, ju),
            &|h| p.lagrangian_hessian(ts, substeps, x, u, lam, h),
        )
    } else {
        let p = OdePlant::try_from(spec.clone()).unwrap();
        run(
            &|f, jx, ju| p.linearize(ts, substeps, x, u, f, jx, ju),
            &|h| p.lagrangian_hessian(ts, substeps, x, u, lam, h),
        )
    };
    Both { sweep: s, dual: d }
}

/// The largest `|a − b| / (1 + max |·|)` over the entries (NaN where exactly one is finite).
fn worst(b: &Both) -> f64 {
    let mut w: f64 = 0.0;
    for (s, d) in b.sweep.iter().zip(&b.dual) {
        let scale = 1.0 + d.iter().chain(s.iter()).fold(0.0f64, |m, v| m.max(v.abs()));
        for (p, q) in s.iter().zip(d) {
            if p.is_finite() != q.is_finite() {
                return f64::NAN;
            }
            if p.is_finite() {
                w = w.max((p - q).abs() / scale);
            }
        }
    }
    w
}

fn smooth_spec(pair: &[&str; 2], discrete: bool) -> SystemSpec {
    let mut s = spec(
        &["x", "y"],
        &["z"],
        &[],
        &["d = x*y + z", "e = d^2 - sin(x)"],
        pair,
    );
    if discrete {
        s.next = s.rhs.take();
    }
    s
}

proptest! {
    #![proptest_config(ProptestConfig {
        rng_seed: proptest::test_runner::RngSeed::Fixed(0x616d_7063),
        ..ProptestConfig::with_cases(64)
    })]
    /// Every operation, smooth region: F, ∂F and ∇²λᵀF agree with the dual path's to 1e-12.
    #[test]
    fn sweeps_equal_the_dual_numbers_on_every_operation(
        x in 0.5f64..1.5,
        y in 0.5f64..1.5,
        z in 0.2f64..0.8,
        l0 in -2.0f64..2.0,
        l1 in -2.0f64..2.0,
    ) {
        for pair in &SMOOTH {
            for (discrete, substeps) in [(true, 1), (false, 1), (false, 3)] {
                let b = both(&smooth_spec(pair, discrete), discrete, substeps, &[x, y, z], &[l0, l1]);
                let w = worst(&b);
                prop_assert!(w <= 1e-12, "{pair:?} discrete {discrete} substeps {substeps}: {w:e}\nsweep {:?}\ndual {:?}", b.sweep, b.dual);
            }
        }
    }

    /// Random expression trees (every operation, kinks, poles), as a discrete map: where both
    /// are finite, the sweep and the dual numbers agree to 1e-9 relative (rounding of
    /// different but exact formulas, amplified by cancellation in deep trees). Entries where
    /// only one side is finite are not compared: the two differ on purpose there (the dual
    /// numbers' tanh is sinh/cosh, NaN beyond |x| ≈ 710; their powers and quotients round
    /// through other intermediates).
    #[test]
    fn sweeps_equal_the_dual_numbers_on_random_trees(
        a in tree(),
        b in tree(),
        v in prop::array::uniform3(-2.5f64..2.5),
        lam in prop::array::uniform2(-2.0f64..2.0),
    ) {
        let mut d = spec(&["x", "y"], &["z"], &[], &[], &[&render(&a), &render(&b)]);
        d.next = d.rhs.take();
        match compile(&d, true) {
            Ok(_) => {}
            Err(e) if matches!(e.kind, ErrorKind::NonFiniteConstant { .. }) => return Ok(()),
            Err(e) => return Err(TestCaseError::fail(format!("{e}"))),
        }
        let r = both(&d, true, 1, &v, &lam);
        let mut worst_entry: f64 = 0.0;
        for (sv, dv) in r.sweep.iter().zip(&r.dual) {
            for (p, q) in sv.iter().zip(dv) {
                if p.is_finite() && q.is_finite() {
                    worst_entry = worst_entry.max((p - q).abs() / (1.0 + p.abs().max(q.abs())));
                }
            }
        }
        prop_assert!(worst_entry <= 1e-9, "{:?}: {worst_entry:e}\nsweep {:?}\ndual {:?}", [render(&a), render(&b)], r.sweep, r.dual);
        // F itself is the f64 tape's value, bit for bit (the sweep computes it with the same
        // functions; the dual path's tanh and powers round differently, so not compared here).
        let model = compile(&d, true).unwrap();
        let mut f = [0.0; 2];
        model.eval(&v[..2], &v[2..], &mut f, &mut Vec::new());
        for k in 0..2 {
            let p = r.sweep[0][k];
            prop_assert!(p.to_bits() == f[k].to_bits() || (p.is_nan() && f[k].is_nan()), "F[{k}] {p} vs {}", f[k]);
        }
    }
}

/// `abs` at ±0: the derivative's sign follows the sign bit of the argument, as in the dual
/// numbers (+1 at +0.0, −1 at −0.0), through both sweeps.
#[test]
fn abs_at_signed_zero_follows_the_dual_numbers() {
    for (z, sign) in [(0.0, 1.0), (-0.0, -1.0)] {
        let mut d = spec(
            &["x", "y"],
            &["z"],
            &[],
            &[],
            &["abs(z)*x + y", "abs(z)^2 + abs(x)"],
        );
        d.next = d.rhs.take();
        let b = both(&d, true, 1, &[0.5, 1.0, z], &[1.0, 1.0]);
        assert_eq!(worst(&b), 0.0, "z {z}: {:?} vs {:?}", b.sweep, b.dual);
        // ∂F₀/∂z = sign · x.
        assert_eq!(b.sweep[2][0], sign * 0.5, "z {z}");
    }
}
