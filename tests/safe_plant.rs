//! The plant as `no_std` f32 Rust (issue 41 §3, the dynamics): the files
//! `deploy::plant_rs` writes for the cart-pole (built-in, through its expression form) and
//! the planar quadrotor (an `ode` expression plant) are committed under
//! `fixtures/safe-plant/` (regenerate with `AMPC_BLESS=1`), compiled into this test, and
//! compared with the trainer's f64 model `Discrete::step` on 10⁵ states and inputs drawn
//! uniformly from the domain X and the input box (f32-representable, so only the arithmetic
//! differs).
//!
//! The largest difference per state component, relative to the domain's half-width, is
//! printed and must stay below `REL_TOL`. **The online check's margin** (`safe::Margins`)
//! is derived from it as an *estimate*, not a bound: the measured maximum over these 10⁵
//! samples × a safety factor (10), in the units of the normalised constraints — sampled,
//! so states outside the sample (or accumulation over the horizon's N steps, which this
//! one-step test does not measure) are not covered by an argument.

use std::path::{Path, PathBuf};
use trainer::deploy::plant_rs::{plant_model, plant_rs};
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
        let src = plant_rs(&cfg.name, &model, cfg.ocp.ts, cfg.ocp.rk4_substeps);
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
