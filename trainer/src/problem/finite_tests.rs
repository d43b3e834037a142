//! Issue 38 §1, §4: every number of a problem file is finite where infinity means nothing,
//! sizes have documented limits, and an expression error's first line names the key and the
//! problem.

use super::*;

const ODE: &str = include_str!("../../../configs/pendulum_ode.toml");

fn invalid_in(text: &str) -> (String, String) {
    match ProblemConfig::from_toml_str(text, "p.toml") {
        Err(ConfigError::Invalid { key, reason, .. }) => (key, reason),
        other => panic!("expected Invalid, got {other:?}"),
    }
}

/// `u_lo = [-inf]` passed validation and `train` panicked later in an SVD ("Singular value
/// was NaN"); state bounds may still be ±inf (no bound).
#[test]
fn input_bounds_must_be_finite_state_bounds_may_be_infinite() {
    let text = PENDULUM_TOML.replacen("u_lo = [-15.0]", "u_lo = [-inf]", 1);
    assert_ne!(text, PENDULUM_TOML);
    let (key, reason) = invalid_in(&text);
    assert_eq!(key, "ocp.u_lo[0]");
    assert!(
        reason.contains("-inf") && reason.contains("finite"),
        "{reason}"
    );
    let text = PENDULUM_TOML.replacen("u_hi = [15.0]", "u_hi = [inf]", 1);
    assert_eq!(invalid_in(&text).0, "ocp.u_hi[0]");
    let mut c = ProblemConfig::default();
    c.ocp.x_lo[1] = f64::NEG_INFINITY;
    c.ocp.x_hi[1] = f64::INFINITY;
    c.validate().unwrap();
}

/// `ocp.horizon = 1e8` (2 GB before any output), `rk4_substeps = 1e10` (a hang),
/// `hidden = [100000000]` (an abort on allocation): each is refused at validation, naming the
/// key, the limit and the value.
#[test]
fn sizes_beyond_the_documented_limits_are_refused() {
    for (from, to, key, value) in [
        (
            "horizon = 20",
            "horizon = 100000000",
            "ocp.horizon",
            "100000000",
        ),
        (
            "rk4_substeps = 1",
            "rk4_substeps = 10000000000",
            "ocp.rk4_substeps",
            "10000000000",
        ),
    ] {
        let text = ODE.replacen(from, to, 1);
        assert_ne!(text, ODE);
        let t = std::time::Instant::now();
        let (k, reason) = invalid_in(&text);
        assert!(t.elapsed().as_secs_f64() < 1.0);
        assert_eq!(k, key);
        assert!(
            reason.contains(value) && reason.contains("10000"),
            "{reason}"
        );
    }
    let text = format!("{ODE}\n[training]\nhidden = [100000000]\n");
    let (k, reason) = invalid_in(&text);
    assert_eq!(k, "training.hidden[0]");
    assert!(
        reason.contains("4096") && reason.contains("100000000"),
        "{reason}"
    );
    let text = format!(
        "{ODE}\n[training]\nhidden = [{}]\n",
        vec!["4"; 65].join(", ")
    );
    assert_eq!(invalid_in(&text).0, "training.hidden");
    let mut c = ProblemConfig::default();
    c.refine.training.hidden = vec![5000];
    assert!(
        matches!(c.validate(), Err(ConfigError::Invalid { key, .. }) if key == "refine.training.hidden[0]")
    );
    c.refine.training.hidden = vec![8];
    c.refine.training.lambda[1] = f64::INFINITY;
    assert!(
        matches!(c.validate(), Err(ConfigError::Invalid { key, .. }) if key == "refine.training.lambda[1]")
    );
}

/// The first line of an expression error names the key and the problem; where it sits in
/// the file follows (it does not open with "TOML parse error at line 6").
#[test]
fn an_expression_error_opens_with_the_key_and_the_problem() {
    let text = ODE.replacen("g/l*sin(theta + pi)", "g/l*sin(thetaa + pi)", 1);
    assert_ne!(text, ODE);
    let e = ProblemConfig::from_toml_str(&text, "p.toml")
        .unwrap_err()
        .to_string();
    let first = e.lines().next().unwrap();
    assert!(
        first.contains("system.rhs[1]") && first.contains("unknown name `thetaa`"),
        "{e}"
    );
    assert!(
        first.starts_with("problem file p.toml: system.rhs[1]"),
        "{e}"
    );
    assert!(e.contains("line "), "the place in the file follows: {e}");
    // A TOML syntax error keeps its message and place.
    let e = ProblemConfig::from_toml_str("name = ", "q.toml")
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("problem file q.toml: ") && e.contains("line 1"),
        "{e}"
    );
}

/// A flat sum of 999 terms in a problem file is accepted (depth is nesting, not length).
#[test]
fn a_long_flat_sum_is_accepted_in_a_problem_file() {
    for n in [999, 1500] {
        let sum = vec!["0.001*omega"; n].join(" + ");
        let text = ODE.replacen(r#"rhs = ["omega","#, &format!(r#"rhs = ["{sum}","#), 1);
        assert_ne!(text, ODE);
        ProblemConfig::from_toml_str(&text, "p.toml").unwrap_or_else(|e| panic!("{n}: {e}"));
    }
}
