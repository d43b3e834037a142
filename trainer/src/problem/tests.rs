//! Problem files: the shipped files parse and validate, errors name the key at fault,
//! the problem hash tracks the labels only.

use super::*;

const DIR: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/");

#[test]
fn shipped_configs_parse_and_validate() {
    for f in [
        "pendulum.toml",
        "cartpole.toml",
        "double_integrator.toml",
        "pendulum_robust.toml",
        "pendulum_ode.toml",
        "double_integrator_ode.toml",
    ] {
        let path = std::path::PathBuf::from(DIR).join(f);
        ProblemConfig::load(&path).unwrap_or_else(|e| panic!("{f}: {e}"));
    }
    let d = ProblemConfig::default();
    assert_eq!(d.name, "pendulum");
    assert_eq!(d, ProblemConfig::from_toml_str(PENDULUM_TOML, "x").unwrap());
    assert_eq!(d.ocp.horizon, 20);
    assert_eq!(d.sampling.counts, vec![35, 10]);
}

fn err_key(edit: impl Fn(&mut ProblemConfig)) -> String {
    let mut c = ProblemConfig::default();
    edit(&mut c);
    match c.validate() {
        Err(ConfigError::Invalid { key, .. }) => key,
        other => panic!("expected Invalid, got {other:?}"),
    }
}

#[test]
fn validation_names_the_key_at_fault() {
    assert_eq!(err_key(|c| c.ocp.horizon = 0), "ocp.horizon");
    // `validation_n = 0` used to be accepted and hung the plots stage on R² = NaN.
    for n in [0, 1] {
        assert_eq!(
            err_key(|c| c.training.validation_n = n),
            "training.validation_n"
        );
    }
    assert_eq!(
        err_key(|c| c.ocp.q = MatrixSpec::Diagonal(vec![1.0])),
        "ocp.q"
    );
    assert_eq!(
        err_key(|c| c.ocp.q = MatrixSpec::Diagonal(vec![1.0, -1.0])),
        "ocp.q"
    );
    assert_eq!(
        err_key(|c| c.ocp.p = MatrixSpec::Full(vec![vec![1.0, 2.0], vec![0.0, 1.0]])),
        "ocp.p"
    );
    assert_eq!(
        err_key(|c| c.ocp.r = MatrixSpec::Diagonal(vec![0.0])),
        "ocp.r"
    );
    assert_eq!(err_key(|c| c.ocp.x_lo[1] = 2.0), "ocp.x_lo[1]");
    assert_eq!(err_key(|c| c.ocp.u_hi[0] = f64::NAN), "ocp.u_hi[0]");
    assert_eq!(err_key(|c| c.ocp.ts = f64::NAN), "ocp.ts");
    assert_eq!(err_key(|c| c.domain.hi[0] = f64::INFINITY), "domain.hi[0]");
    assert_eq!(err_key(|c| c.domain.lo = vec![0.0]), "domain.lo");
    assert_eq!(err_key(|c| c.sampling.counts = vec![3]), "sampling.counts");
    assert_eq!(err_key(|c| c.refine.target_eps = 0.0), "refine.target_eps");
    assert_eq!(err_key(|c| c.refine.budget = 80), "refine.initial");
    assert_eq!(
        err_key(|c| c.refine.initial = vec![1, 3]),
        "refine.initial[0]"
    );
    assert_eq!(
        err_key(|c| c.refine.initial = vec![3, 9000]),
        "refine.initial[1]"
    );
    assert_eq!(err_key(|c| c.refine.safety = 0.5), "refine.safety");
    assert_eq!(
        err_key(|c| c.sampling.sampler = SamplerKind::Adaptive),
        "sampling.sampler"
    );
    assert_eq!(err_key(|c| c.solver.tol = 0.0), "solver.tol");
    assert_eq!(
        err_key(
            |c| c.system = System::Pendulum(crate::problem::model::Pendulum {
                m: -1.0,
                ..Default::default()
            })
        ),
        "system.m"
    );
}

#[test]
fn parse_errors_name_the_key() {
    let bad = PENDULUM_TOML.replace("horizon = 20", "horizon = \"twenty\"");
    let e = ProblemConfig::from_toml_str(&bad, "f.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("horizon") && e.contains("f.toml"), "{e}");
    let unknown = format!("{PENDULUM_TOML}\n[extra]\nfoo = 1\n");
    let e = ProblemConfig::from_toml_str(&unknown, "f.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("extra"), "{e}");
}

#[test]
fn problem_hash_tracks_labels_only() {
    let a = ProblemConfig::default();
    let mut b = a.clone();
    b.sampling.seed = 7;
    assert_eq!(a.problem_hash(), b.problem_hash());
    b.ocp.horizon = 21;
    assert_ne!(a.problem_hash(), b.problem_hash());
}
