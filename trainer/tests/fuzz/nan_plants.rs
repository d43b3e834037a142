//! Expression plants with random NaN/∞-producing terms, through the library
//! (no CLI): the paper's pendulum as an ODE with one of `log(θ − c)`, `sqrt(θ − c)`,
//! `(θ − c)^p` (p fractional), `0·sqrt(ω − c)`, `asin(θ/c)`, `u/0`, or the mass parameter 0
//! in the input's denominator, c drawn inside X so that each plant is non-finite on part (or
//! all) of X and on the grid's first state.
//!
//! Properties:
//! - every state where F(x_s, ·) is not finite for any input is `numerical_failure`;
//! - every label rests on finite numbers: u, ∂κ/∂x, and F with its Jacobians at every stage
//!   of the returned solution, re-evaluated here;
//! - no finite ε: `certify` of the plant's grid dataset is refused by the label gate
//!   (`MismatchError::Labels`), whatever the model.

use super::runner;
use proptest::prelude::*;
use proptest::test_runner::TestCaseError;
use std::sync::OnceLock;
use trainer::certify::certificate::{certify, CertifyOptions, MismatchError};
use trainer::certify::Model;
use trainer::data::dataset::{generate, GenerateOptions};
use trainer::mpc::law::MpcLaw;
use trainer::problem::model::Discrete;
use trainer::problem::ProblemConfig;

const BASE: &str = "u/(m*l^2) - g/l*sin(theta + pi)";

/// One bad term (`kind`), with `c` in (−1, 1) scaling a point inside X.
fn plant(kind: u8, c: f64, p: f64) -> (String, String) {
    let par = "m = 1.0, l = 1.0, g = 9.81".to_string();
    let th = 6.0 * c; // θ ∈ [−2π, 2π]
    let om = 0.9 * c; // ω ∈ [−1, 1]
    let rhs = match kind {
        0 => format!("{BASE} + log(theta - ({th}))"),
        1 => format!("{BASE} + sqrt(theta - ({th}))"),
        2 => format!("{BASE} + (theta - ({th}))^{p}"),
        3 => format!("{BASE} + 0*sqrt(omega - ({om}))"),
        4 => format!("{BASE} + asin(theta/{})", 0.5 + 5.0 * c.abs()),
        5 => "u/0 - g/l*sin(theta + pi)".to_string(),
        _ => return (BASE.to_string(), "m = 0.0, l = 1.0, g = 9.81".to_string()),
    };
    (rhs, par)
}

fn config(rhs: &str, par: &str) -> ProblemConfig {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/pendulum_ode.toml");
    let text = std::fs::read_to_string(path).unwrap();
    let text = text
        .replace(
            r#"rhs = ["omega", "u/(m*l^2) - g/l*sin(theta + pi)"]"#,
            &format!(r#"rhs = ["omega", "{rhs}"]"#),
        )
        .replace(
            "parameters = { m = 1.0, l = 1.0, g = 9.81 }",
            &format!("parameters = {{ {par} }}"),
        )
        .replace("horizon = 20", "horizon = 6")
        .replace("counts = [35, 10]", "counts = [4, 3]");
    ProblemConfig::from_toml_str(&text, "nan plant").unwrap_or_else(|e| panic!("{rhs}: {e}"))
}

/// A small model of the right dimensions (2 → 1) with no problem hash (so that only the
/// label gate can stop `certify`): trained once on the finite pendulum.
fn model() -> &'static Model {
    static M: OnceLock<Model> = OnceLock::new();
    M.get_or_init(|| {
        let cfg = config(BASE, "m = 1.0, l = 1.0, g = 9.81");
        let dir = std::env::temp_dir().join(format!("ampc-nan-fuzz-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let d = generate(&cfg, &dir.join("finite.bin"), &GenerateOptions::default()).unwrap();
        let set = trainer::learn::train::TrainSet::from_dataset(&d);
        let mut settings = cfg.training.clone();
        settings.hidden = vec![4];
        settings.epochs = 20;
        let opts = trainer::learn::train::TrainOptions {
            nominal: false,
            progress: None,
            hold: None,
            keep_best: None,
        };
        let (lo, hi) = (&cfg.domain.lo, &cfg.domain.hi);
        let (ulo, uhi) = (&cfg.ocp.u_lo, &cfg.ocp.u_hi);
        let _ = std::fs::remove_dir_all(&dir);
        trainer::learn::train::train(&settings, &opts, &set, &set, (lo, hi), (ulo, uhi), "", "")
    })
}

fn check(kind: u8, c: f64, p: f64) -> Result<(), TestCaseError> {
    let (rhs, par) = plant(kind, c, p);
    let cfg = config(&rhs, &par);
    let f = Discrete::new(cfg.system.clone(), cfg.ocp.ts, cfg.ocp.rk4_substeps);
    let (nx, nu) = (2, 1);
    let (mut fx, mut jx, mut ju) = (vec![0.0; nx], vec![0.0; nx * nx], vec![0.0; nx * nu]);
    let mut finite_at = |x: &[f64], u: &[f64]| {
        f.linearize(x, u, &mut fx, &mut jx, &mut ju);
        fx.iter().chain(&jx).chain(&ju).all(|v| v.is_finite())
    };
    let mut law = MpcLaw::new(&cfg);
    let dir = std::env::temp_dir().join(format!("ampc-nan-fuzz-{}-{kind}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("d.bin");
    let data = generate(&cfg, &out, &GenerateOptions::default());
    let _ = std::fs::remove_dir_all(&dir);
    let data = data.map_err(|e| TestCaseError::fail(format!("{rhs}: {e}")))?;
    let mut failed = 0;
    for r in &data.records {
        let (l, sol) = law.solve(&r.x, None);
        let (lo, hi) = (cfg.ocp.u_lo[0], cfg.ocp.u_hi[0]);
        let nowhere = [lo, 0.0, hi].iter().all(|u| !finite_at(&r.x, &[*u]));
        for l_status in [l.status, r.status] {
            if nowhere && l_status != trainer::mpc::sqp::SqpStatus::NumericalFailure {
                return Err(TestCaseError::fail(format!(
                    "{rhs} at {:?}: F is not finite there, status {l_status:?}",
                    r.x
                )));
            }
        }
        if r.status == trainer::mpc::sqp::SqpStatus::NumericalFailure {
            failed += 1;
        }
        if r.is_labelled() && !r.u.iter().chain(&r.du_dx).all(|v| v.is_finite()) {
            return Err(TestCaseError::fail(format!("{rhs}: label {r:?}")));
        }
        if let Some(z) = sol.map(|s| s.z) {
            let ocp = &law.hard_solver().ocp;
            for k in 0..ocp.horizon {
                let (xk, uk) = (&z[ocp.ix(k)..][..nx], &z[ocp.iu(k)..][..nu]);
                if !finite_at(xk, uk) {
                    return Err(TestCaseError::fail(format!(
                        "{rhs} at {:?}: labelled ({:?}) but F is not finite at stage {k}",
                        r.x, l.status
                    )));
                }
            }
        }
    }
    if failed == 0 {
        return Err(TestCaseError::fail(format!(
            "{rhs}: the first grid state is non-finite, yet no numerical_failure"
        )));
    }
    match certify(model(), &data, &cfg, &CertifyOptions::default()) {
        Err(MismatchError::Labels(_)) => Ok(()),
        Err(e) => Err(TestCaseError::fail(format!(
            "{rhs}: refused for another reason: {e}"
        ))),
        Ok(c) => Err(TestCaseError::fail(format!(
            "{rhs}: a certificate ε = {} from a non-finite model",
            c.eps
        ))),
    }
}

/// `cases` random plants.
pub fn nan_plants(cases: u32) {
    runner(cases)
        .run(
            &(
                0u8..7,
                -0.9f64..0.9,
                prop::sample::select(vec![0.5, 1.5, 0.25, 2.5]),
            ),
            |(k, c, p)| check(k, c, p),
        )
        .unwrap();
}
