//! Every error names the key, and the expression and column when it is in one; warnings.

use super::super::{compile, ErrorKind, SystemSpec};
use super::spec;

/// The oscillator of the contract; tests change one thing at a time.
fn base() -> SystemSpec {
    spec(
        &["pos", "vel"],
        &["force"],
        &[("k", 2.0), ("c", 0.3)],
        &["spring = k*pos + 0.5*pos^3"],
        &["vel", "force - spring - c*vel"],
    )
}

/// The message of compiling `s` (ODE), which must fail.
fn err(s: &SystemSpec) -> String {
    match compile(s, false) {
        Ok(_) => panic!("compiled: {s:?}"),
        Err(e) => e.to_string(),
    }
}

fn assert_has(msg: &str, parts: &[&str]) {
    for p in parts {
        assert!(msg.contains(p), "`{p}` not in: {msg}");
    }
}

fn with_rhs(rhs: &[&str]) -> SystemSpec {
    SystemSpec {
        rhs: Some(rhs.iter().map(|s| s.to_string()).collect()),
        ..base()
    }
}

fn with_defs(defs: &[&str]) -> SystemSpec {
    SystemSpec {
        definitions: defs.iter().map(|s| s.to_string()).collect(),
        ..base()
    }
}

#[test]
fn the_contract_example_compiles() {
    let m = compile(&base(), false).unwrap();
    assert_eq!((m.nx(), m.nu()), (2, 1));
    assert!(m.warnings().is_empty(), "{:?}", m.warnings());
}

#[test]
fn syntax_errors_name_key_text_and_column() {
    let m = err(&with_rhs(&["vel", "force - (spring"]));
    assert_has(
        &m,
        &[
            "system.rhs[1], column 16 of `force - (spring`",
            "expected `)`",
            "column 9",
        ],
    );
    let m = err(&with_rhs(&["vel", "force - * c"]));
    assert_has(
        &m,
        &[
            "system.rhs[1], column 9 of",
            "expected a number, name or `(`, found `*`",
        ],
    );
    let m = err(&with_rhs(&["vel", "force $ c"]));
    assert_has(
        &m,
        &["system.rhs[1], column 7 of", "unexpected character `$`"],
    );
    let m = err(&with_rhs(&["", "vel"]));
    assert_has(&m, &["system.rhs[0], column 1 of ``", "empty expression"]);
    let m = err(&with_rhs(&["vel)", "vel"]));
    assert_has(
        &m,
        &[
            "system.rhs[0], column 4 of `vel)`",
            "without a matching `(`",
        ],
    );
    let m = err(&with_rhs(&["vel vel", "vel"]));
    assert_has(
        &m,
        &[
            "system.rhs[0], column 5 of `vel vel`",
            "expected an operator",
        ],
    );
    let m = err(&with_rhs(&["sin", "vel"]));
    assert_has(
        &m,
        &["system.rhs[0], column 1 of `sin`", "`sin` is a function"],
    );
    let m = err(&with_rhs(&["1e+", "vel"]));
    assert_has(
        &m,
        &["system.rhs[0], column 1 of `1e+`", "malformed number"],
    );
    let m = err(&with_defs(&["spring k*pos"]));
    assert_has(
        &m,
        &[
            "system.definitions[0], column 8 of `spring k*pos`",
            "expected `=`",
        ],
    );
    let m = err(&with_defs(&["2 = pos"]));
    assert_has(
        &m,
        &[
            "system.definitions[0], column 1 of `2 = pos`",
            "expected `name = expression`",
        ],
    );
    let m = err(&with_defs(&["spring = "]));
    assert_has(
        &m,
        &[
            "system.definitions[0], column 10",
            "nothing after `spring =`",
        ],
    );
}

#[test]
fn unknown_names_and_functions() {
    let m = err(&with_rhs(&["vel", "force - sprng - c*vel"]));
    assert_has(
        &m,
        &[
            "system.rhs[1], column 9 of `force - sprng - c*vel`",
            "unknown name `sprng`",
            "states pos, vel; inputs force; parameters c, k; definitions spring",
        ],
    );
    let m = err(&with_rhs(&["vel", "force - sgn(vel)"]));
    assert_has(
        &m,
        &[
            "system.rhs[1], column 9 of",
            "unknown function `sgn`",
            "atan2",
        ],
    );
    let m = err(&with_rhs(&["vel", "force + atan2(vel)"]));
    assert_has(
        &m,
        &[
            "system.rhs[1], column 9 of",
            "`atan2` takes 2 arguments, got 1",
        ],
    );
    let m = err(&with_rhs(&["sin(pos, vel)", "vel"]));
    assert_has(
        &m,
        &[
            "system.rhs[0], column 1 of",
            "`sin` takes 1 argument, got 2",
        ],
    );
    let m = err(&with_rhs(&["max()", "vel"]));
    assert_has(
        &m,
        &[
            "system.rhs[0], column 1 of",
            "`max` takes 2 arguments, got 0",
        ],
    );
    let m = err(&with_rhs(&["k(pos)", "vel"]));
    assert_has(&m, &["system.rhs[0], column 1 of", "unknown function `k`"]);
}

#[test]
fn definitions_are_read_in_order() {
    let m = err(&with_defs(&["a = b + 1", "b = pos", "spring = a"]));
    assert_has(
        &m,
        &[
            "system.definitions[0], column 5 of `a = b + 1`",
            "definition `b` is used before it is defined (in system.definitions[1])",
        ],
    );
    let m = err(&with_defs(&["spring = 1 + spring"]));
    assert_has(
        &m,
        &[
            "system.definitions[0], column 14",
            "`spring` is used before",
        ],
    );
    // A name unknown in a definition lists only the earlier definitions.
    let m = err(&with_defs(&["a = pos", "b = zz", "spring = a + b"]));
    assert_has(
        &m,
        &[
            "system.definitions[1], column 5",
            "unknown name `zz`",
            "definitions a;",
        ],
    );
}

#[test]
fn names_given_twice_or_reserved() {
    let m = err(&SystemSpec {
        states: vec!["pos".into(), "pos".into()],
        ..base()
    });
    assert_has(
        &m,
        &[
            "system.states[1]",
            "name `pos` is already a state (`system.states[0]`)",
        ],
    );
    let m = err(&SystemSpec {
        inputs: vec!["vel".into()],
        ..base()
    });
    assert_has(
        &m,
        &[
            "system.inputs[0]",
            "`vel` is already a state (`system.states[1]`)",
        ],
    );
    let mut s = base();
    s.parameters.insert("force".into(), 1.0);
    assert_has(
        &err(&s),
        &[
            "system.parameters.force",
            "already an input (`system.inputs[0]`)",
        ],
    );
    let m = err(&with_defs(&["c = 2", "spring = pos"]));
    assert_has(
        &m,
        &[
            "system.definitions[0], column 1 of `c = 2`",
            "already a parameter (`system.parameters.c`)",
        ],
    );
    let m = err(&with_defs(&["spring = pos", "  spring = vel"]));
    assert_has(
        &m,
        &[
            "system.definitions[1], column 3",
            "already a definition (`system.definitions[0]`)",
        ],
    );
    let m = err(&with_defs(&["pi = 3.14", "spring = pos"]));
    assert_has(
        &m,
        &[
            "system.definitions[0], column 1",
            "`pi` is already the constant π",
        ],
    );
    let m = err(&SystemSpec {
        states: vec!["pi".into(), "vel".into()],
        ..base()
    });
    assert_has(&m, &["system.states[0]", "`pi` is already the constant π"]);
    let mut s = base();
    s.parameters.insert("exp".into(), 1.0);
    assert_has(
        &err(&s),
        &["system.parameters.exp", "`exp` is already a function"],
    );
    let m = err(&with_defs(&["sqrt = pos", "spring = pos"]));
    assert_has(
        &m,
        &[
            "system.definitions[0], column 1",
            "`sqrt` is already a function",
        ],
    );
    let m = err(&SystemSpec {
        inputs: vec!["f orce".into()],
        ..base()
    });
    assert_has(&m, &["system.inputs[0]", "`f orce` is not a valid name"]);
}

#[test]
fn one_equation_per_state() {
    let m = err(&with_rhs(&["vel"]));
    assert_has(
        &m,
        &[
            "system.rhs:",
            "2 states but 1 equation:",
            "no equation for `vel`",
        ],
    );
    let m = err(&with_rhs(&["vel", "force", "pos"]));
    assert_has(
        &m,
        &[
            "system.rhs[2], column 1 of `pos`",
            "3 equations for 2 states",
        ],
    );
    let mut s = base();
    s.next = s.rhs.take();
    s.next.as_mut().map(|v| v.pop());
    let m = compile(&s, true).unwrap_err().to_string();
    assert_has(&m, &["system.next:", "no equation for `vel`"]);
}

#[test]
fn rhs_for_an_ode_next_for_a_discrete_system() {
    let m = compile(&base(), true).unwrap_err().to_string();
    assert_has(&m, &["system.rhs:", "`rhs` (dx/dt) is for kind = \"ode\""]);
    let mut s = base();
    s.next = s.rhs.take();
    let m = err(&s);
    assert_has(&m, &["system.next:", "is for kind = \"discrete\""]);
    assert!(compile(&s, true).is_ok());
    s.rhs = s.next.clone();
    assert_has(&err(&s), &["system.next:", "is for kind = \"discrete\""]);
    assert_has(
        &compile(&s, true).unwrap_err().to_string(),
        &["system.rhs:", "is for kind = \"ode\""],
    );
    let s = SystemSpec {
        rhs: None,
        ..base()
    };
    assert_has(&err(&s), &["system.rhs:", "missing: an ODE needs `rhs`"]);
    assert_has(
        &compile(&s, true).unwrap_err().to_string(),
        &["system.next:", "missing"],
    );
}

#[test]
fn parameters_must_be_finite_and_constant_parts_too() {
    for v in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        let mut s = base();
        s.parameters.insert("k".into(), v);
        let e = compile(&s, false).unwrap_err();
        assert_eq!(e.key, "system.parameters.k");
        assert!(matches!(e.kind, ErrorKind::NonFiniteParameter { .. }));
        assert_has(&e.to_string(), &["parameter `k` must be finite"]);
    }
    let m = err(&with_rhs(&["vel", "force + log(k - 2)"]));
    assert_has(
        &m,
        &[
            "system.rhs[1], column 9 of `force + log(k - 2)`",
            "depends on no state or input and evaluates to -inf",
        ],
    );
    let m = err(&with_rhs(&["vel", "force + 1/(c - 0.3)"]));
    assert_has(&m, &["system.rhs[1], column 9", "evaluates to inf"]);
    let m = err(&with_defs(&["spring = sqrt(-k)*pos"]));
    assert_has(
        &m,
        &["system.definitions[0], column 10", "evaluates to NaN"],
    );
}

#[test]
fn states_empty_and_unknown_units() {
    let s = SystemSpec {
        states: vec![],
        rhs: Some(vec![]),
        ..base()
    };
    let e = compile(&s, false).unwrap_err();
    assert_eq!(
        e.to_string(),
        "system.states: a system needs at least one state"
    );
    assert_eq!(e.reason(), "a system needs at least one state");
    let mut s = base();
    s.units.insert("pos".into(), "m".into());
    s.units.insert("spring".into(), "N".into());
    assert_eq!(compile(&s, false).unwrap().unit("pos"), Some("m"));
    s.units.insert("speed".into(), "m/s".into());
    assert_has(
        &err(&s),
        &["system.units.speed", "`speed`, which is no state"],
    );
}

#[test]
fn reason_is_the_message_without_the_key() {
    let e = compile(&with_rhs(&["vel", "force - sprng"]), false).unwrap_err();
    assert_eq!(e.key, "system.rhs[1]");
    assert_eq!(e.at, Some(("force - sprng".to_string(), 9)));
    assert!(e
        .reason()
        .starts_with("column 9 of `force - sprng`: unknown name `sprng`"));
    assert_eq!(format!("{}, {}", e.key, e.reason()), e.to_string());
    let e = compile(&with_rhs(&["vel"]), false).unwrap_err();
    assert_eq!(format!("{}: {}", e.key, e.reason()), e.to_string());
}

#[test]
fn warnings_name_non_smooth_functions_and_unused_names() {
    let mut s = with_rhs(&["vel", "force - spring - c*abs(vel)*vel"]);
    s.definitions.push("sat = max(min(force, 1), -1)".into());
    s.parameters.insert("unused".into(), 1.0);
    let m = compile(&s, false).unwrap();
    let w = m.warnings().join("\n");
    assert_has(
        &w,
        &[
            "system.rhs[1], column 20 of `force - spring - c*abs(vel)*vel`: `abs` is not smooth: sensitivities are one-sided at their kinks",
            "system.definitions[1], column 7 of `sat = max(min(force, 1), -1)`: `max` is not smooth",
            "system.definitions[1], column 11",
            "system.definitions[1]: definition `sat` is never used",
            "system.parameters.unused: parameter `unused` is never used",
        ],
    );
    assert_eq!(m.warnings().len(), 5, "{w}");
}
