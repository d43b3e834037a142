//! The grammar: precedence, associativity, numbers, functions, `pi`; garbage never panics.

use super::super::compile;
use super::super::parse::{parse_definition, parse_expr, AstKind, BinOp};
use super::{one, spec, value_at};
use proptest::prelude::*;
use std::f64::consts::PI;

fn c(text: &str) -> f64 {
    value_at(text, 0.0, 0.0)
}

#[test]
fn precedence_and_associativity() {
    assert_eq!(c("2^3^2"), 512.0);
    assert_eq!(c("(2^3)^2"), 64.0);
    assert_eq!(c("-2^2"), -4.0);
    assert_eq!(c("(-2)^2"), 4.0);
    assert_eq!(c("1-2-3"), -4.0);
    assert_eq!(c("8/4/2"), 1.0);
    assert_eq!(c("2*3^2"), 18.0);
    assert_eq!(c("1+2*3"), 7.0);
    assert_eq!(c("(1+2)*3"), 9.0);
    assert_eq!(c("2^-1"), 0.5);
    assert_eq!(c("2^-1^2"), 0.5); // 2^(-(1^2))
    assert_eq!(c("--3"), 3.0);
    assert_eq!(c("2*-3"), -6.0);
    assert_eq!(c("1 - -1"), 2.0);
    assert_eq!(c("-2^-2"), -0.25);
    assert_eq!(c("12/3*2"), 8.0);
    assert_eq!(c("2-3+4"), 3.0);
    // With a variable (not folded): the tape follows the same rules.
    assert_eq!(value_at("-x^2", 3.0, 0.0), -9.0);
    assert_eq!(value_at("x^u^2", 2.0, 3.0), 512.0);
    assert_eq!(value_at("x - u - 1", 1.0, 2.0), -2.0);
    assert_eq!(value_at("x / u / 2", 8.0, 4.0), 1.0);
    assert_eq!(value_at("x^-2", 2.0, 0.0), 0.25);
    assert_eq!(value_at("-x^u", 2.0, 2.0), -4.0);
}

#[test]
fn the_tree_has_the_expected_shape() {
    // `-x^2` is Neg(Pow(x, 2)); `a-b` is Sub(a, b); `a-b+c` is the chain a, (−, b), (+, c)
    // (evaluated as (a − b) + c); `a^b^c` is Pow(a, Pow(b, c)).
    let e = parse_expr("-x^2").unwrap();
    let AstKind::Neg(inner) = e.kind else {
        panic!("{e:?}")
    };
    assert!(matches!(inner.kind, AstKind::Bin(BinOp::Pow, _, _)));
    let e = parse_expr("a-b").unwrap();
    assert!(matches!(e.kind, AstKind::Bin(BinOp::Sub, _, _)), "{e:?}");
    let e = parse_expr("a-b+c*d/f").unwrap();
    let AstKind::Chain(first, rest) = e.kind else {
        panic!("{e:?}")
    };
    assert!(matches!(first.kind, AstKind::Name(_)));
    let ops: Vec<BinOp> = rest.iter().map(|(op, _)| *op).collect();
    assert_eq!(ops, [BinOp::Sub, BinOp::Add]);
    assert!(matches!(rest[1].1.kind, AstKind::Chain(_, ref r) if r.len() == 2));
    let e = parse_expr("a^b^c").unwrap();
    let AstKind::Bin(BinOp::Pow, l, r) = e.kind else {
        panic!("{e:?}")
    };
    assert!(matches!(l.kind, AstKind::Name(_)));
    assert!(matches!(r.kind, AstKind::Bin(BinOp::Pow, _, _)));
    // Columns are 1-based character positions.
    let e = parse_expr("  θθ").unwrap_err();
    assert_eq!(e.0, 3);
    let (name, col, _) = parse_definition("  spring = k*x").unwrap();
    assert_eq!((name.as_str(), col), ("spring", 3));
}

#[test]
fn numbers() {
    assert_eq!(c("1e-3"), 1e-3);
    assert_eq!(c(".5"), 0.5);
    assert_eq!(c("2."), 2.0);
    assert_eq!(c("1.5E+2"), 150.0);
    assert_eq!(c("0.25e1"), 2.5);
    assert_eq!(c("007"), 7.0);
    assert!(one("1e").is_err());
    assert!(one(".").is_err());
    assert!(one("1.2.3").is_err());
    assert!(one("1e999").is_err());
    assert!(one("2x").is_err());
}

#[test]
fn functions_and_pi() {
    assert_eq!(c("pi"), PI);
    assert_eq!(c("2*pi"), 2.0 * PI);
    assert_eq!(c("sin(pi/2)"), 1.0);
    assert_eq!(c("cos(0)"), 1.0);
    assert_eq!(c("tan(0.5)"), 0.5f64.tan());
    assert_eq!(c("asin(0.5)"), 0.5f64.asin());
    assert_eq!(c("acos(0.5)"), 0.5f64.acos());
    assert_eq!(c("atan(2)"), 2f64.atan());
    assert_eq!(c("atan2(1, -1)"), 1f64.atan2(-1.0));
    assert_eq!(c("exp(1)"), 1f64.exp());
    assert_eq!(c("log(10)"), 10f64.ln());
    assert_eq!(c("sqrt(2)"), 2f64.sqrt());
    assert_eq!(c("sinh(1)"), 1f64.sinh());
    assert_eq!(c("cosh(1)"), 1f64.cosh());
    assert_eq!(c("tanh(1)"), 1f64.tanh());
    assert_eq!(c("abs(-3)"), 3.0);
    assert_eq!(c("min(2, -3)"), -3.0);
    assert_eq!(c("max(2, -3)"), 2.0);
    assert_eq!(c("max(min(1,2), 3*sin(0))"), 1.0);
    assert_eq!(c("-sin(pi/2)^2"), -1.0);
    assert_eq!(c("2^0.5"), 2f64.sqrt());
    assert_eq!(c("2^1.5"), 2f64.powf(1.5));
    assert_eq!(value_at("atan2(x, u)", 1.0, 2.0), 1f64.atan2(2.0));
    assert_eq!(value_at("min(x, u) + max(x, u)", 1.0, 2.0), 3.0);
    assert_eq!(value_at("abs(x)", -2.0, 0.0), 2.0);
    assert_eq!(value_at("x^0", 5.0, 0.0), 1.0);
    assert_eq!(value_at("x^1", 5.0, 0.0), 5.0);
    assert_eq!(value_at("x^3", 2.0, 0.0), 8.0);
    assert_eq!(value_at("2^x", 3.0, 0.0), 8.0);
}

/// Strings over the language's characters (and some others): compile returns, never panics.
fn garbage() -> impl Strategy<Value = String> {
    let pieces = prop::sample::select(vec![
        "x", "u", "pi", "sin", "atan2", "min", "(", ")", ",", "+", "-", "*", "/", "^", "=", "1",
        "2.5", ".", "e", "E", "1e", "9e999", " ", "θ", "#", "k", "q", "_",
    ]);
    prop::collection::vec(pieces, 0..24).prop_map(|v| v.concat())
}

proptest! {
    #![proptest_config(ProptestConfig {
        rng_seed: proptest::test_runner::RngSeed::Fixed(0x616d_7063),
        ..ProptestConfig::with_cases(512)
    })]
    #[test]
    fn garbage_never_panics(a in garbage(), b in ".{0,30}", d in garbage()) {
        for text in [&a, &b] {
            let s = spec(&["x"], &["u"], &[("k", 2.0)], &[d.as_str()], &[text.as_str()]);
            if let Ok(m) = compile(&s, false) {
                let mut out = [0.0];
                m.eval(&[0.3], &[0.7], &mut out, &mut Vec::new());
            }
            let _ = compile(&spec(&["x"], &["u"], &[], &[], &[text.as_str()]), false);
            let _ = parse_definition(text);
        }
    }
}

#[test]
fn deep_nesting_is_an_error_not_a_stack_overflow() {
    let deep = format!("{}x{}", "(".repeat(100_000), ")".repeat(100_000));
    assert!(one(&deep)
        .unwrap_err()
        .to_string()
        .contains("nested too deeply"));
    // The length of a flat sum is no nesting: 999 and 100 000 terms are one level deep
    // (a parser that counted each term as a level would refuse more than 1 000).
    let sum = vec!["x"; 999].join(" + ");
    assert_eq!(value_at(&sum, 1.0, 0.0), 999.0);
    let long = vec!["x"; 100_000].join("+");
    assert_eq!(value_at(&long, 1.0, 0.0), 100_000.0);
    let products = vec!["x*u/u"; 2_000].join("-");
    assert_eq!(value_at(&products, 1.0, 3.0), -1998.0);
    let minus = format!("{}x", "-".repeat(100_000));
    assert!(one(&minus).is_err());
    let pow = vec!["x"; 100_000].join("^");
    assert!(one(&pow).is_err());
    // 150 levels are fine.
    let ok = format!("{}x{}", "(".repeat(150), ")".repeat(150));
    assert_eq!(value_at(&ok, 2.0, 0.0), 2.0);
}
