//! Tests of the setpoint (`ocp.x_ref`, `ocp.u_ref`) in the OCP: the objective
//! Σ (x_k − x_ref)ᵀQ(x_k − x_ref) + (u_k − u_ref)ᵀR(u_k − u_ref) + (x_N − x_ref)ᵀP(x_N − x_ref)
//! and its gradient against central differences, the default (no setpoint) equal to
//! xᵀQx + uᵀRu bit for bit, and the law at an equilibrium (x_ref, u_ref): u₀ = u_ref, cost 0.

use crate::mpc::law::MpcLaw;
use crate::mpc::ocp::Ocp;
use crate::mpc::sqp::SqpStatus;
use crate::problem::ProblemConfig;

/// A damped spring with a constant force: ẋ = (vel, force − k·pos − c·vel). Its equilibria
/// are (pos, 0) with force = k·pos, exactly in f64 for pos = 0.5, k = 2 (force 1): then
/// f(x_ref, u_ref) = 0 exactly and so is every RK4 stage.
fn spring(x_ref: Option<&str>, u_ref: Option<&str>) -> ProblemConfig {
    let refs = x_ref.map_or(String::new(), |v| format!("x_ref = {v}\n"))
        + &u_ref.map_or(String::new(), |v| format!("u_ref = {v}\n"));
    let text = format!(
        r#"
name = "spring"
[system]
kind = "ode"
states = ["pos", "vel"]
inputs = ["force"]
parameters = {{ k = 2.0, c = 0.3 }}
rhs = ["vel", "force - k*pos - c*vel"]
[ocp]
ts = 0.1
horizon = 15
q = [[4.0, 0.5], [0.5, 1.0]]
r = [0.2]
p = [8.0, 2.0]
{refs}x_lo = [-2.0, -1.5]
x_hi = [2.0, 1.5]
u_lo = [-3.0]
u_hi = [3.0]
[domain]
lo = [-1.0, -1.0]
hi = [1.0, 1.0]
"#
    );
    ProblemConfig::from_toml_str(&text, "spring").unwrap()
}

/// The spring with a setpoint that is no equilibrium (a moving state): a problem file
/// refuses it ([`crate::problem::setpoint`]); the OCP's cost is still defined for it, and
/// the tests of the cost's algebra use it to exercise every term.
fn spring_moving() -> ProblemConfig {
    let mut cfg = spring(Some("[0.5, 0.0]"), Some("[1.0]"));
    cfg.ocp.x_ref = Some(vec![0.5, -0.25]);
    cfg
}

fn rand_z(ocp: &Ocp, seed: u64) -> Vec<f64> {
    (0..ocp.n_var)
        .map(|i| 2.0 * crate::rng::uniform(seed, 3, i as u64) - 1.0)
        .collect()
}

#[test]
fn gradient_with_a_setpoint_matches_central_differences() {
    let cfg = spring_moving();
    for soft in [false, true] {
        let ocp = Ocp::new(&cfg, soft);
        assert_eq!(
            (ocp.x_ref.as_slice(), ocp.u_ref.as_slice()),
            (&[0.5, -0.25][..], &[1.0][..])
        );
        for seed in 0..5 {
            let z = rand_z(&ocp, seed);
            let mut g = vec![0.0; ocp.n_var];
            ocp.gradient(&z, &mut g);
            for j in 0..ocp.n_var {
                let h = 1e-6;
                let (mut zp, mut zm) = (z.clone(), z.clone());
                zp[j] += h;
                zm[j] -= h;
                let fd = (ocp.objective(&zp) - ocp.objective(&zm)) / (2.0 * h);
                // Central differences of a quadratic are exact up to rounding of f/h.
                let tol = 1e-7 * (1.0 + ocp.objective(&z).abs());
                assert!(
                    (fd - g[j]).abs() <= tol,
                    "soft {soft} z[{j}]: {fd} vs {}",
                    g[j]
                );
            }
        }
    }
}

#[test]
fn objective_is_the_setpoint_deviation_cost() {
    let plain = Ocp::new(&spring(None, None), false);
    let with = Ocp::new(&spring_moving(), false);
    let z = rand_z(&plain, 11);
    // Without a setpoint: Σ xᵀQx + uᵀRu + x_NᵀPx_N, written out.
    let q = |x: &[f64]| 4.0 * x[0] * x[0] + 2.0 * 0.5 * x[0] * x[1] + x[1] * x[1];
    let p = |x: &[f64]| 8.0 * x[0] * x[0] + 2.0 * x[1] * x[1];
    let direct = |xr: [f64; 2], ur: f64| -> f64 {
        let mut f = 0.0;
        for k in 0..15 {
            let (ix, iu) = (plain.ix(k), plain.iu(k));
            f += q(&[z[ix] - xr[0], z[ix + 1] - xr[1]]) + 0.2 * (z[iu] - ur).powi(2);
        }
        let ix = plain.ix(15);
        f + p(&[z[ix] - xr[0], z[ix + 1] - xr[1]])
    };
    let (a, b) = (plain.objective(&z), direct([0.0, 0.0], 0.0));
    assert!((a - b).abs() <= 1e-12 * b, "{a} vs {b}");
    let (a, b) = (with.objective(&z), direct([0.5, -0.25], 1.0));
    assert!((a - b).abs() <= 1e-12 * b, "{a} vs {b}");
    // The origin stated explicitly is the default, bit for bit (v − 0 = v).
    let zero = Ocp::new(&spring(Some("[0.0, 0.0]"), Some("[0.0]")), false);
    assert_eq!(zero.objective(&z).to_bits(), plain.objective(&z).to_bits());
    let (mut g0, mut g1) = (vec![0.0; z.len()], vec![0.0; z.len()]);
    zero.gradient(&z, &mut g0);
    plain.gradient(&z, &mut g1);
    assert_eq!(g0, g1);
}

#[test]
fn law_at_an_equilibrium_setpoint_is_its_input_at_zero_cost() {
    let cfg = spring(Some("[0.5, 0.0]"), Some("[1.0]"));
    let mut law = MpcLaw::new(&cfg);
    let (l, _) = law.solve(&[0.5, 0.0], None);
    assert_eq!(l.status, SqpStatus::Converged);
    // (x_ref, u_ref) held over the horizon is feasible with zero cost, the global minimum
    // of a nonnegative objective; the solver's tolerance is the only slack.
    assert!((l.u[0] - 1.0).abs() <= 1e-9, "u0 = {}", l.u[0]);
    assert!(l.cost.abs() <= 1e-15, "cost {}", l.cost);
    // Without u_ref, the problem file computes the input that holds x_ref from the model
    // (force = k·pos = 1), and the law applies it at zero cost.
    let derived = spring(Some("[0.5, 0.0]"), None);
    assert!((derived.ocp.u_ref_or_zero(1)[0] - 1.0).abs() <= 1e-12);
    let mut other = MpcLaw::new(&derived);
    let (l0, _) = other.solve(&[0.5, 0.0], None);
    assert!((l0.u[0] - 1.0).abs() <= 1e-9, "u0 = {}", l0.u[0]);
    assert!(l0.cost.abs() <= 1e-15, "cost {}", l0.cost);
    // From elsewhere, the MPC's closed loop goes to the setpoint, not to the origin.
    let model = crate::problem::model::Discrete::new(cfg.system.clone(), cfg.ocp.ts, 1);
    let mut x = vec![-0.5, 0.5];
    for _ in 0..150 {
        let (l, _) = law.solve(&x, None);
        assert!(l.status.is_labelled(), "{x:?}: {:?}", l.status);
        let mut next = vec![0.0; 2];
        model.step(&x, &l.u, &mut next);
        x = next;
    }
    assert!((x[0] - 0.5).abs() < 1e-6 && x[1].abs() < 1e-6, "{x:?}");
}

/// States within 1e-10…1e-4 of a nonzero setpoint: the cost there is far below the
/// rounding of the constraint residuals (ε·|x_ref|), where a merit line search without a
/// floor rejects every step (`NumericalFailure`); the SQP's rounding floor lets it converge.
#[test]
fn law_converges_arbitrarily_close_to_a_nonzero_setpoint() {
    let cfg = spring(Some("[0.5, 0.0]"), Some("[1.0]"));
    let mut law = MpcLaw::new(&cfg);
    for k in 0..7 {
        let d = 10f64.powi(-10 + k);
        for x in [[0.5 - d, -2.7 * d], [0.5 + d, 0.0], [0.5, d]] {
            let (l, _) = law.solve(&x, None);
            assert_eq!(l.status, SqpStatus::Converged, "{x:?}: {:?}", l.info);
            // κ is Lipschitz near the setpoint, κ(x_ref) = u_ref: |κ(x) − u_ref| = O(d).
            assert!((l.u[0] - 1.0).abs() <= 1e3 * d, "{x:?}: u0 = {}", l.u[0]);
        }
    }
}
