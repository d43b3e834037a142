//! The plant as `no_std` f32 Rust (issue 41 §3, the dynamics): the files
//! `deploy::plant_rs` writes for the cart-pole (built-in, through its expression form) and
//! the planar quadrotor (an `ode` expression plant) are committed under
//! `fixtures/safe-plant/` (regenerate with `AMPC_BLESS=1`), compiled into this test, and
//! compared with the trainer's f64 model `Discrete::step` on 10⁵ states and inputs drawn
//! uniformly from the domain X and the input box (f32-representable, so only the arithmetic
//! differs).
//!
//! The largest difference per state component, relative to the domain's half-width, is
//! printed and must stay below `REL_TOL`. This is the one-step difference; **the online
//! check's margin** (`safe::Margins`, the generated `MARGINS`) comes from the N-step
//! difference over 10⁵ trajectories × 10, marked *estimated* (`deploy::plant_rs_margin`;
//! checked against the compiled code on other trajectories in `safe_plant_loop`).
//!
//! The OCP's part (`ocp_rs`: ℓ, V_f, Π_U, the normalised state-box violation) is compared
//! with the same formulas in f64 on the same kind of samples (inputs drawn from twice the
//! box, so that the projection clamps): Π_U exactly, the others to a relative 1e-5.

use std::path::{Path, PathBuf};
use trainer::deploy::plant_rs::{ocp_rs, plant_model, plant_rs};
use trainer::problem::model::Discrete;
use trainer::problem::ProblemConfig;

#[allow(dead_code)] // TS: the generated file's documentation of itself
mod cartpole {
    include!("fixtures/safe-plant/cartpole.rs");
}
#[allow(dead_code)]
mod quadrotor {
    include!("fixtures/safe-plant/planar_quadrotor.rs");
}

/// Largest accepted one-step difference |F_f32 − F_f64|_i / half-width_i.
const REL_TOL: f64 = 1e-5;
const SAMPLES: usize = 100_000;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn config(name: &str) -> ProblemConfig {
    ProblemConfig::load(&root().join("configs").join(format!("{name}.toml"))).unwrap()
}

#[test]
fn generated_sources_are_the_committed_fixtures() {
    for (name, file) in [
        ("cartpole", "cartpole.rs"),
        ("planar_quadrotor", "planar_quadrotor.rs"),
    ] {
        let cfg = config(name);
        let model = plant_model(&cfg.system).unwrap();
        let src = plant_rs(&cfg.name, &model, cfg.ocp.ts, cfg.ocp.rk4_substeps)
            + "\n"
            + &ocp_rs(&cfg).unwrap();
        let path = root().join("tests/fixtures/safe-plant").join(file);
        if std::env::var_os("AMPC_BLESS").is_some() {
            std::fs::write(&path, &src).unwrap();
        }
        let committed = std::fs::read_to_string(&path).unwrap();
        assert!(
            committed == src,
            "{} is not what deploy::plant_rs writes for configs/{name}.toml: rerun with AMPC_BLESS=1",
            path.display()
        );
    }
}

/// xorshift64 → uniform [0, 1).
fn uniform(s: &mut u64) -> f64 {
    *s ^= *s << 13;
    *s ^= *s >> 7;
    *s ^= *s << 17;
    (*s >> 11) as f64 / (1u64 << 53) as f64
}

/// Max over the samples of |F_f32 − F_f64|_i / half-width_i, per component.
fn max_rel_diff<const NX: usize, const NU: usize>(
    name: &str,
    step: fn(&[f32; NX], &[f32; NU]) -> [f32; NX],
) -> Vec<f64> {
    let cfg = config(name);
    let f64_model = Discrete::new(cfg.system.clone(), cfg.ocp.ts, cfg.ocp.rk4_substeps);
    let (lo, hi) = (&cfg.domain.lo, &cfg.domain.hi);
    let (ulo, uhi) = (&cfg.ocp.u_lo, &cfg.ocp.u_hi);
    let mut seed = 0x5AFE_0041_u64 ^ NX as u64;
    let mut worst = vec![0.0f64; NX];
    let mut out = vec![0.0f64; NX];
    for _ in 0..SAMPLES {
        let x: [f32; NX] =
            std::array::from_fn(|i| (lo[i] + (hi[i] - lo[i]) * uniform(&mut seed)) as f32);
        let u: [f32; NU] =
            std::array::from_fn(|j| (ulo[j] + (uhi[j] - ulo[j]) * uniform(&mut seed)) as f32);
        let xd: Vec<f64> = x.iter().map(|&v| f64::from(v)).collect();
        let ud: Vec<f64> = u.iter().map(|&v| f64::from(v)).collect();
        f64_model.step(&xd, &ud, &mut out);
        let y = step(&x, &u);
        for i in 0..NX {
            let half = 0.5 * (hi[i] - lo[i]);
            let d = (f64::from(y[i]) - out[i]).abs() / half;
            assert!(
                d.is_finite(),
                "{name}: non-finite difference at x={x:?} u={u:?}"
            );
            worst[i] = worst[i].max(d);
        }
    }
    worst
}

#[test]
fn f32_plants_match_the_f64_model_on_1e5_states() {
    let cases: [(&str, Vec<f64>); 2] = [
        ("cartpole", max_rel_diff::<4, 1>("cartpole", cartpole::step)),
        (
            "planar_quadrotor",
            max_rel_diff::<6, 2>("planar_quadrotor", quadrotor::step),
        ),
    ];
    for (name, worst) in &cases {
        let max = worst.iter().cloned().fold(0.0, f64::max);
        let per: Vec<String> = worst.iter().map(|d| format!("{d:.3e}")).collect();
        eprintln!(
            "{name}: max |F_f32 − F_f64|_i / half-width_i per state [{}]; max {max:.3e}",
            per.join(", ")
        );
        assert!(
            max <= REL_TOL,
            "{name}: one-step f32 difference {max:e} > {REL_TOL:e}"
        );
        assert!(
            max > 0.0,
            "{name}: no difference at all: the comparison is not running f32"
        );
    }
}

/// The generated `(stage_cost, terminal_cost, project_input, state_box_violation)`.
type OcpFns<const NX: usize, const NU: usize> = (
    fn(&[f32; NX], &[f32; NU]) -> f32,
    fn(&[f32; NX]) -> f32,
    fn(&[f32; NU]) -> [f32; NU],
    fn(&[f32; NX]) -> f32,
);

/// ℓ, V_f, Π_U and g_X of the generated file against f64 formulas from the problem file.
fn check_ocp<const NX: usize, const NU: usize>(name: &str, f: OcpFns<NX, NU>) {
    let (stage_cost, terminal_cost, project_input, state_box_violation) = f;
    let cfg = config(name);
    let ocp = &cfg.ocp;
    let (qm, rm, pm) = (
        ocp.q.to_dmatrix().unwrap(),
        ocp.r.to_dmatrix().unwrap(),
        ocp.p.to_dmatrix().unwrap(),
    );
    let (q, r, p) = (
        |i: usize, j: usize| qm[(i, j)],
        |i: usize, j: usize| rm[(i, j)],
        |i: usize, j: usize| pm[(i, j)],
    );
    let (xr, ur) = (ocp.x_ref_or_origin(NX), ocp.u_ref_or_zero(NU));
    let scale = ocp.x_scale_or_default(&cfg.domain.lo, &cfg.domain.hi);
    fn quad(w: &dyn Fn(usize, usize) -> f64, d: &[f64]) -> f64 {
        (0..d.len())
            .map(|i| d[i] * (0..d.len()).map(|j| w(i, j) * d[j]).sum::<f64>())
            .sum()
    }
    let (lo, hi) = (&cfg.domain.lo, &cfg.domain.hi);
    let mut seed = 0x0C9_0041_u64 ^ NX as u64;
    let close = |a: f32, b: f64| (f64::from(a) - b).abs() <= 1e-5 * (1.0 + b.abs());
    for _ in 0..SAMPLES {
        let x: [f32; NX] = std::array::from_fn(|i| {
            let w = hi[i] - lo[i];
            (lo[i] - 0.5 * w + 2.0 * w * uniform(&mut seed)) as f32
        });
        let u: [f32; NU] = std::array::from_fn(|j| {
            let (l, h) = (ocp.u_lo[j], ocp.u_hi[j]);
            (l - 0.5 * (h - l) + 2.0 * (h - l) * uniform(&mut seed)) as f32
        });
        let dx: Vec<f64> = (0..NX).map(|i| f64::from(x[i]) - xr[i]).collect();
        let du: Vec<f64> = (0..NU).map(|j| f64::from(u[j]) - ur[j]).collect();
        let l = quad(&q, &dx) + quad(&r, &du);
        assert!(close(stage_cost(&x, &u), l), "{name}: ℓ at x={x:?} u={u:?}");
        assert!(
            close(terminal_cost(&x), quad(&p, &dx)),
            "{name}: V_f at {x:?}"
        );
        let pu = project_input(&u);
        for j in 0..NU {
            let want = f64::from(u[j]).clamp(ocp.u_lo[j], ocp.u_hi[j]) as f32;
            assert_eq!(pu[j], want, "{name}: Π_U at {u:?}");
        }
        let g = (0..NX)
            .flat_map(|i| {
                let xi = f64::from(x[i]);
                [(ocp.x_lo[i] - xi) / scale[i], (xi - ocp.x_hi[i]) / scale[i]]
            })
            .filter(|v| v.is_finite())
            .fold(f64::NEG_INFINITY, f64::max);
        let got = state_box_violation(&x);
        assert!(
            (g.is_infinite() && got == f32::NEG_INFINITY) || close(got, g),
            "{name}: g_X at {x:?}: {got} vs {g}"
        );
    }
    assert_eq!(project_input(&[f32::NAN; NU]).map(f64::from).to_vec(), ur);
    assert!(state_box_violation(&[f32::NAN; NX]).is_nan());
}

#[test]
fn ocp_functions_match_the_f64_formulas_on_1e5_points() {
    use cartpole as c;
    use quadrotor as q;
    check_ocp::<4, 1>(
        "cartpole",
        (
            c::stage_cost,
            c::terminal_cost,
            c::project_input,
            c::state_box_violation,
        ),
    );
    check_ocp::<6, 2>(
        "planar_quadrotor",
        (
            q::stage_cost,
            q::terminal_cost,
            q::project_input,
            q::state_box_violation,
        ),
    );
}
