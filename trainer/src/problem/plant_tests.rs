//! Problem files with plants written as expressions (`kind = "ode"` / `"discrete"`): they
//! round-trip through TOML with the same hash, compile errors are problem-file errors naming
//! the key and the column, sizes are checked, warnings are exposed, the mass is found.

use super::model::System;
use super::*;

const DIR: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/");

fn load(f: &str) -> ProblemConfig {
    ProblemConfig::load(&std::path::PathBuf::from(DIR).join(f)).unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn expression_plants_round_trip_with_the_same_hash() {
    for f in ["pendulum_ode.toml", "double_integrator_ode.toml"] {
        let cfg = load(f);
        assert!(matches!(cfg.system, System::Ode(_)), "{f}");
        assert_eq!((cfg.system.nx(), cfg.system.nu()), (2, 1));
        let text = toml::to_string(&cfg).unwrap();
        let back = ProblemConfig::from_toml_str(&text, "round trip").unwrap();
        assert_eq!(back, cfg, "{text}");
        assert_eq!(back.problem_hash(), cfg.problem_hash());
        assert!(text.contains("kind = \"ode\""), "{text}");
    }
    // A change of the plant changes the hash.
    let a = load("pendulum_ode.toml");
    let text = std::fs::read_to_string(std::path::PathBuf::from(DIR).join("pendulum_ode.toml"))
        .unwrap()
        .replace("g = 9.81", "g = 9.8");
    let b = ProblemConfig::from_toml_str(&text, "x").unwrap();
    assert_ne!(a.problem_hash(), b.problem_hash());
    assert_ne!(a.problem_hash(), ProblemConfig::default().problem_hash());
}

const DISCRETE: &str = r#"
name = "leaky"
[system]
kind = "discrete"
states = ["a", "b"]
inputs = ["u"]
parameters = { k = 0.9 }
next = ["k*a + 0.1*b", "b + 0.1*u - 0.01*sin(a)"]
[ocp]
ts = 0.1
horizon = 5
q = [1.0, 1.0]
r = [1.0]
p = [1.0, 1.0]
x_lo = [-5.0, -5.0]
x_hi = [5.0, 5.0]
u_lo = [-1.0]
u_hi = [1.0]
[domain]
lo = [-1.0, -1.0]
hi = [1.0, 1.0]
"#;

#[test]
fn discrete_plants_are_read_and_stepped_without_rk4() {
    let cfg = ProblemConfig::from_toml_str(DISCRETE, "d.toml").unwrap();
    assert_eq!(cfg.system.name(), "discrete");
    let model = super::model::Discrete::new(cfg.system.clone(), 0.1, 3);
    let mut out = [0.0; 2];
    model.step(&[0.5, -0.2], &[0.7], &mut out);
    assert_eq!(out[0], 0.9 * 0.5 + 0.1 * -0.2);
    assert_eq!(out[1], -0.2 + 0.1 * 0.7 - 0.01 * 0.5f64.sin());
    let text = toml::to_string(&cfg).unwrap();
    assert_eq!(ProblemConfig::from_toml_str(&text, "x").unwrap(), cfg);
}

#[test]
fn compile_errors_name_the_key_and_column() {
    let bad = DISCRETE.replace("b + 0.1*u", "b + 0.1*uu");
    let e = ProblemConfig::from_toml_str(&bad, "d.toml")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("d.toml") && e.contains("system.next[1]") && e.contains("column 9"),
        "{e}"
    );
    assert!(e.contains("unknown name `uu`"), "{e}");
    let bad = DISCRETE.replace("next = ", "rhs = ");
    let e = ProblemConfig::from_toml_str(&bad, "d.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("system."), "{e}");
}

#[test]
fn sizes_are_checked_and_warnings_exposed() {
    let no_input = DISCRETE
        .replace("inputs = [\"u\"]", "inputs = []")
        .replace("0.1*u", "0.1");
    match ProblemConfig::from_toml_str(&no_input, "d.toml") {
        Err(ConfigError::Invalid { key, .. }) => assert_eq!(key, "system.inputs"),
        other => panic!("{other:?}"),
    }
    let names: Vec<String> = (0..16).map(|i| format!("\"s{i}\"")).collect();
    let eqs: Vec<String> = (0..16).map(|i| format!("\"-s{i} + u\"")).collect();
    let big = DISCRETE
        .replace("[\"a\", \"b\"]", &format!("[{}]", names.join(", ")))
        .replace(
            "[\"k*a + 0.1*b\", \"b + 0.1*u - 0.01*sin(a)\"]",
            &format!("[{}]", eqs.join(", ")),
        );
    match ProblemConfig::from_toml_str(&big, "d.toml") {
        Err(ConfigError::Invalid { key, .. }) => assert_eq!(key, "system.states"),
        other => panic!("{other:?}"),
    }
    assert!(load("pendulum_ode.toml").system.warnings().is_empty());
    let kinky = DISCRETE.replace("0.01*sin(a)", "0.01*abs(a)");
    let cfg = ProblemConfig::from_toml_str(&kinky, "d.toml").unwrap();
    assert!(!cfg.system.warnings().is_empty());
}

#[test]
fn mass_is_the_parameter_mass_or_m() {
    let pend = load("pendulum_ode.toml").system;
    let heavy = pend.with_mass_scaled(1.5).unwrap();
    assert_ne!(heavy, pend);
    match &heavy {
        System::Ode(p) => assert_eq!(p.spec().parameters["m"], 1.5),
        other => panic!("{other:?}"),
    }
    let di = load("double_integrator_ode.toml").system;
    match di.with_mass_scaled(2.0).unwrap() {
        System::Ode(p) => assert_eq!(p.spec().parameters["mass"], 2.0),
        other => panic!("{other:?}"),
    }
    let d = ProblemConfig::from_toml_str(DISCRETE, "d.toml").unwrap();
    assert!(d.system.with_mass_scaled(2.0).is_none());
}

#[test]
fn default_refine_grid_fits_the_budget_for_many_states() {
    let r = RefineSettings::default();
    assert_eq!(r.initial_counts(2), vec![9; 2]);
    assert_eq!(r.initial_counts(4), vec![9; 4]);
    assert_eq!(r.initial_counts(5), vec![8; 5]);
    assert_eq!(r.initial_counts(12), vec![2; 12]);
    assert!(r.validate(12).is_ok());
}
