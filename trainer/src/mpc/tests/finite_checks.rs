//! The label gate on plants whose arithmetic is not finite (tests only): the paper's
//! pendulum written as an ODE with a term that gives NaN or ±∞ on part or all of X (`log` of
//! a negative number, `u/0`, a parameter 0 in a denominator, `sqrt` and a fractional power of
//! a negative number, `0·sqrt(ω)`). Each must give no label (`numerical_failure`) where the
//! arithmetic is not finite — never a `converged` label with 0 iterations, which is what a
//! residual folded with `f64::max` (which drops a NaN, so a NaN residual reads as 0) gives.

use crate::mpc::finite::{Failure, Quantity};
use crate::mpc::law::MpcLaw;
use crate::mpc::sqp::{KktResidual, SqpStatus};
use crate::problem::ProblemConfig;

/// `configs/pendulum_ode.toml` with `rhs[1]` (and the parameters) replaced, a shorter
/// horizon (speed).
pub(crate) fn pendulum_with(rhs1: &str, parameters: &str) -> ProblemConfig {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/pendulum_ode.toml");
    let text = std::fs::read_to_string(path).unwrap();
    let old_rhs = r#"rhs = ["omega", "u/(m*l^2) - g/l*sin(theta + pi)"]"#;
    let old_par = "parameters = { m = 1.0, l = 1.0, g = 9.81 }";
    assert!(
        text.contains(old_rhs) && text.contains(old_par),
        "pendulum_ode.toml changed"
    );
    let text = text
        .replace(old_rhs, &format!(r#"rhs = ["omega", "{rhs1}"]"#))
        .replace(old_par, &format!("parameters = {{ {parameters} }}"))
        .replace("horizon = 20", "horizon = 8");
    ProblemConfig::from_toml_str(&text, "test").unwrap_or_else(|e| panic!("{rhs1}: {e}"))
}

const BASE: &str = "u/(m*l^2) - g/l*sin(theta + pi)";
const PARAMS: &str = "m = 1.0, l = 1.0, g = 9.81";

/// Every variant of the issue: no state of the grid gets a label, and the failure names a
/// non-finite quantity.
#[test]
fn plants_non_finite_everywhere_give_no_label() {
    let variants = [
        (format!("{BASE} + log(theta - 100)"), PARAMS.to_string()),
        ("u/0 - g/l*sin(theta + pi)".to_string(), PARAMS.to_string()),
        (BASE.to_string(), "m = 0.0, l = 1.0, g = 9.81".to_string()),
        (format!("{BASE} + sqrt(theta - 7)"), PARAMS.to_string()),
        (format!("{BASE} + (theta - 7)^0.5"), PARAMS.to_string()),
    ];
    for (rhs, par) in &variants {
        let cfg = pendulum_with(rhs, par);
        let mut law = MpcLaw::new(&cfg);
        for x in [[0.0, 0.0], [-3.0, 0.5], [1.0, -1.0]] {
            let (l, sol) = law.solve(&x, None);
            assert_eq!(
                l.status,
                SqpStatus::NumericalFailure,
                "{rhs} / {par} at {x:?}: {l:?}"
            );
            assert!(sol.is_none());
            assert!(l.u.iter().all(|v| v.is_nan()), "{l:?}");
            assert!(
                matches!(l.failure(), Some(Failure::NonFinite(_))),
                "{rhs} at {x:?}: {:?}",
                l.failure()
            );
        }
    }
    // The first non-finite quantity of `log(theta − 100)` is the plant's equations.
    let cfg = pendulum_with(&format!("{BASE} + log(theta - 100)"), PARAMS);
    let (l, _) = MpcLaw::new(&cfg).solve(&[0.5, 0.0], None);
    assert_eq!(l.failure(), Some(Failure::NonFinite(Quantity::Equations)));
}

/// `… + 0·sqrt(omega)`: NaN where ω < 0 (and an infinite derivative at ω = 0), finite
/// elsewhere. Every state whose prediction meets the NaN is `numerical_failure`; every label
/// rests on finite numbers along its whole predicted trajectory (re-evaluated here).
#[test]
fn a_plant_non_finite_on_part_of_x_labels_only_its_finite_part() {
    let cfg = pendulum_with(&format!("{BASE} + 0*sqrt(omega)"), PARAMS);
    let model =
        crate::problem::model::Discrete::new(cfg.system.clone(), cfg.ocp.ts, cfg.ocp.rk4_substeps);
    let mut law = MpcLaw::new(&cfg);
    let (mut failed, mut labelled) = (0, 0);
    for i in 0..6 {
        for j in 0..5 {
            let x = [-3.0 + 1.2 * i as f64, -1.0 + 0.5 * j as f64];
            let (l, sol) = law.solve(&x, None);
            if x[1] < 0.0 {
                // F(x_s, ·) is NaN whatever the input: no label is possible.
                assert_eq!(l.status, SqpStatus::NumericalFailure, "{x:?}: {l:?}");
            }
            if !l.status.is_labelled() {
                failed += 1;
                continue;
            }
            labelled += 1;
            assert!(l.u.iter().chain(&l.du_dx).all(|v| v.is_finite()), "{l:?}");
            let z = sol.expect("a hard label returns its solution").z;
            let ocp = &law.hard_solver().ocp;
            let (nx, nu) = (2, 1);
            let (mut f, mut jx, mut ju) = (vec![0.0; nx], vec![0.0; nx * nx], vec![0.0; nx]);
            for k in 0..ocp.horizon {
                let (xk, uk) = (&z[ocp.ix(k)..][..nx], &z[ocp.iu(k)..][..nu]);
                model.linearize(xk, uk, &mut f, &mut jx, &mut ju);
                assert!(
                    f.iter().chain(&jx).chain(&ju).all(|v| v.is_finite()),
                    "{x:?}: stage {k} at {xk:?}, {uk:?}: F {f:?} ∂F {jx:?} {ju:?}"
                );
            }
        }
    }
    assert!(
        failed >= 12 && labelled >= 1,
        "{failed} failed, {labelled} labelled"
    );
}

/// The KKT residual's largest part keeps a NaN (read as ∞), where `f64::max` dropped it.
#[test]
fn a_nan_part_makes_the_residual_infinite() {
    let r = KktResidual {
        stationarity: f64::NAN,
        primal: 1e-12,
        dual: 0.0,
        complementarity: 0.0,
    };
    assert_eq!(r.max(), f64::INFINITY);
    let r = KktResidual {
        stationarity: 0.0,
        complementarity: f64::NAN,
        ..r
    };
    assert_eq!(r.max(), f64::INFINITY);
}

/// A finite plant's labels pass the gate untouched (the pendulum's first states).
#[test]
fn finite_plants_are_labelled_as_before() {
    let cfg = ProblemConfig::default();
    let mut law = MpcLaw::new(&cfg);
    for x in [[0.0, 0.0], [-3.0, 0.5], [1.0, -1.0], [6.0, 1.0]] {
        let (l, _) = law.solve(&x, None);
        assert_eq!(l.status, SqpStatus::Converged, "{x:?}");
        assert_eq!(l.failure(), None);
    }
}
