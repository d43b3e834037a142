//! The nominal terminal ingredients against a second method: closed-loop simulation of κ_f
//! from seeded points of X_f (another seed than the design's check, boundary and interior)
//! over the OCP's horizon — every state stays in X_f and in the state box, every input in
//! the box, and V_f decreases by at least ℓ at every step.

use super::*;
use crate::problem::ProblemConfig;

fn load(name: &str) -> ProblemConfig {
    let path =
        std::path::PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/")).join(name);
    ProblemConfig::load(&path).unwrap()
}

/// Simulates κ_f from 2000 seeded points for N steps; returns the number of steps checked.
fn simulate(cfg: &ProblemConfig, t: &NominalTerminal) -> usize {
    let nx = t.x_ref.len();
    let p = DMatrix::from_fn(nx, nx, |i, j| t.p[i][j]);
    let model = Discrete::new(cfg.system.clone(), cfg.ocp.ts, cfg.ocp.rk4_substeps);
    let (q, r) = (cfg.q(), cfg.r());
    let mut steps = 0;
    for x0 in set_points(&p, &t.x_ref, t.alpha.sqrt(), 2000, 0xc0ffee) {
        let mut x = x0;
        let mut xp = vec![0.0; nx];
        for _ in 0..cfg.ocp.horizon {
            let d: Vec<f64> = (0..nx).map(|i| x[i] - t.x_ref[i]).collect();
            let v = quad(&p, &d);
            assert!(
                v <= t.alpha * (1.0 + 1e-9),
                "{}: left X_f: {v} > {}",
                cfg.name,
                t.alpha
            );
            let u: Vec<f64> = (0..t.u_ref.len())
                .map(|j| t.u_ref[j] + (0..nx).map(|i| t.k[j][i] * d[i]).sum::<f64>())
                .collect();
            for (j, u) in u.iter().enumerate() {
                assert!(
                    cfg.ocp.u_lo[j] <= *u && *u <= cfg.ocp.u_hi[j],
                    "input {j}: {u}"
                );
            }
            for (i, x) in x.iter().enumerate() {
                assert!(
                    cfg.ocp.x_lo[i] <= *x && *x <= cfg.ocp.x_hi[i],
                    "state {i}: {x}"
                );
            }
            model.step(&x, &u, &mut xp);
            let dp: Vec<f64> = (0..nx).map(|i| xp[i] - t.x_ref[i]).collect();
            let (xs, us) = (cfg.ocp.x_ref_or_origin(nx), cfg.ocp.u_ref_or_zero(u.len()));
            let ex: Vec<f64> = (0..nx).map(|i| x[i] - xs[i]).collect();
            let eu: Vec<f64> = (0..u.len()).map(|j| u[j] - us[j]).collect();
            let ell = quad(&q, &ex) + quad(&r, &eu);
            assert!(
                quad(&p, &dp) - v <= -ell + 1e-12 * v.max(1.0),
                "{}: V_f({dp:?}) − V_f({d:?}) = {} > −ℓ = {}",
                cfg.name,
                quad(&p, &dp) - v,
                -ell
            );
            x.clone_from(&xp);
            steps += 1;
        }
    }
    steps
}

#[test]
fn cartpole_and_quadrotor_get_a_nominal_terminal_set_that_simulation_confirms() {
    for name in ["cartpole.toml", "planar_quadrotor.toml"] {
        let cfg = load(name);
        let t = nominal_terminal(&cfg, NOMINAL_SAMPLES)
            .unwrap_or_else(|| panic!("{name}: no nominal terminal set"));
        assert!(t.alpha > 0.0 && t.decrease_worst <= 0.0, "{name}: {t:?}");
        let steps = simulate(&cfg, &t);
        eprintln!(
            "{name}: P_f = {:?}, alpha = {:e}, c_max² = {:e}, worst = {:e}, {steps} simulated steps",
            t.cost,
            t.alpha,
            t.radius_max * t.radius_max,
            t.decrease_worst
        );
    }
}

#[test]
fn a_level_above_the_chosen_one_fails_the_decrease_or_the_boxes() {
    // The search is not vacuous: 1/0.8 of the chosen radius either leaves (i) or breaks (ii)
    // somewhere on the samples (the quadrotor: its level is below c_max², 1.03 vs 6.13).
    let cfg = load("planar_quadrotor.toml");
    let t = nominal_terminal(&cfg, NOMINAL_SAMPLES).unwrap();
    let nx = t.x_ref.len();
    let p = DMatrix::from_fn(nx, nx, |i, j| t.p[i][j]);
    let k = DMatrix::from_fn(t.u_ref.len(), nx, |i, j| t.k[i][j]);
    let c = t.alpha.sqrt() / 0.8;
    assert!(c <= t.radius_max, "{c} > {}", t.radius_max);
    let pts = set_points(&p, &t.x_ref, c, NOMINAL_SAMPLES, 0x7e4f);
    let (worst, ok) = check_points(&cfg, &p, &k, &pts);
    assert!(worst > 0.0 || !ok, "radius {c} would pass: {worst}");
}
