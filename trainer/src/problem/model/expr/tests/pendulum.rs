//! The paper's pendulum in the expression syntax against `Pendulum::rhs`; CSE; the TOML
//! contract (inside a `kind`-tagged enum, round trip); no allocation per call; timing.

use super::super::super::{Dynamics, Pendulum};
use super::super::{compile, ExprModel, SystemSpec};
use super::spec;
use serde::{Deserialize, Serialize};

/// How the caller will embed the spec: `[system] kind = "ode" | "discrete"`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
enum Sys {
    Ode(SystemSpec),
    Discrete(SystemSpec),
}

#[derive(Debug, Serialize, Deserialize)]
struct File {
    system: Sys,
}

const PENDULUM: &str = r#"
[system]
kind = "ode"
states = ["theta", "omega"]
inputs = ["u"]
parameters = { m = 1.0, l = 1.0, g = 9.81 }
rhs = ["omega", "u/(m*l^2) - g/l*sin(theta + pi)"]
units = { theta = "rad", omega = "rad/s", u = "N*m" }
"#;

fn load(text: &str) -> ExprModel {
    let file: File = toml::from_str(text).unwrap_or_else(|e| panic!("{e}"));
    match &file.system {
        Sys::Ode(s) => compile(s, false),
        Sys::Discrete(s) => compile(s, true),
    }
    .unwrap_or_else(|e| panic!("{e}"))
}

/// splitmix64 → uniform in [lo, hi).
struct Rng(u64);
impl Rng {
    fn next(&mut self, lo: f64, hi: f64) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        lo + (hi - lo) * ((z >> 11) as f64 / (1u64 << 53) as f64)
    }
}

#[test]
fn pendulum_is_bit_identical_to_the_built_in_model() {
    let m = load(PENDULUM);
    assert_eq!((m.nx(), m.nu()), (2, 1));
    assert_eq!(m.state_names(), ["theta", "omega"]);
    assert_eq!(m.unit("omega"), Some("rad/s"));
    assert!(m.warnings().is_empty(), "{:?}", m.warnings());
    let p = Pendulum::default();
    let mut rng = Rng(7);
    let mut scratch = Vec::new();
    for _ in 0..1000 {
        let x = [rng.next(-10.0, 10.0), rng.next(-20.0, 20.0)];
        let u = [rng.next(-50.0, 50.0)];
        let (mut a, mut b) = ([0.0; 2], [0.0; 2]);
        m.eval(&x, &u, &mut a, &mut scratch);
        p.rhs(&x, &u, &mut b);
        assert_eq!(a.map(f64::to_bits), b.map(f64::to_bits), "x {x:?} u {u:?}");
    }
    // The tape: theta + π, sin, × 9.81, u − …; ω and u/(m l²) = u are read directly.
    assert_eq!(m.n_instructions(), 4, "{m}");
}

#[test]
fn pendulum_with_other_parameters_agrees_to_rounding() {
    // u/(m*l^2) divides once where Pendulum::rhs multiplies by 1/(m l²): the bits may differ
    // by the rounding of that one operation.
    let p = Pendulum {
        m: 0.3,
        l: 0.7,
        g: 9.81,
    };
    let s = spec(
        &["theta", "omega"],
        &["u"],
        &[("m", p.m), ("l", p.l), ("g", p.g)],
        &[],
        &["omega", "u/(m*l^2) - g/l*sin(theta + pi)"],
    );
    let m = compile(&s, false).unwrap();
    let mut rng = Rng(11);
    let mut scratch = Vec::new();
    for _ in 0..1000 {
        let x = [rng.next(-10.0, 10.0), rng.next(-20.0, 20.0)];
        let u = [rng.next(-50.0, 50.0)];
        let (mut a, mut b) = ([0.0; 2], [0.0; 2]);
        m.eval(&x, &u, &mut a, &mut scratch);
        p.rhs(&x, &u, &mut b);
        let scale = (u[0] / (p.m * p.l * p.l)).abs() + (p.g / p.l);
        assert_eq!(a[0], b[0]);
        assert!((a[1] - b[1]).abs() <= 1e-15 * scale, "{a:?} {b:?}");
    }
}

#[test]
fn a_definition_used_twice_is_computed_once() {
    let s = spec(
        &["pos", "vel"],
        &["force"],
        &[("k", 2.0)],
        &["s = k*sin(pos)"],
        &["s + vel", "s*s - s + force"],
    );
    let m = compile(&s, false).unwrap();
    // sin, ×k, + vel, s·s, − s, + force.
    assert_eq!(m.count_op("sin"), 1, "{m}");
    assert_eq!(m.n_instructions(), 6, "{m}");
    assert_eq!(m.count_op("sq"), 1, "{m}");
    // The same without the definition: hash-consing finds the common parts by itself.
    let inline = spec(
        &["pos", "vel"],
        &["force"],
        &[("k", 2.0)],
        &[],
        &[
            "k*sin(pos) + vel",
            "(sin(pos)*k)*(k*sin(pos)) - k*sin(pos) + force",
        ],
    );
    let m2 = compile(&inline, false).unwrap();
    assert_eq!(m2.n_instructions(), 6, "{m2}");
    let (mut a, mut b) = ([0.0; 2], [0.0; 2]);
    m.eval(&[0.3, -0.2], &[1.5], &mut a, &mut Vec::new());
    m2.eval(&[0.3, -0.2], &[1.5], &mut b, &mut Vec::new());
    assert_eq!(a, b);
    let s1 = 2.0 * 0.3f64.sin();
    assert_eq!(a, [s1 + -0.2, s1 * s1 - s1 + 1.5]);
    // An unused definition costs nothing.
    let mut s3 = s.clone();
    s3.definitions.push("waste = exp(vel)*cosh(pos)".into());
    assert_eq!(compile(&s3, false).unwrap().n_instructions(), 6);
}

#[test]
fn registers_are_reused_and_eval_does_not_allocate() {
    let defs: Vec<String> = (0..20).map(|i| format!("d{i} = sin(x + {i})")).collect();
    let sum: Vec<String> = (0..20).map(|i| format!("d{i}")).collect();
    let mut s = spec(&["x"], &["u"], &[], &[], &[]);
    s.definitions = defs;
    s.rhs = Some(vec![sum.join(" + ") + " + u"]);
    let m = compile(&s, false).unwrap();
    assert_eq!(m.n_instructions(), 60, "{m}");
    // Linear scan keeps only a few values alive at a time (the sums are in one chain).
    assert!(m.n_registers() <= 6, "{} registers\n{m}", m.n_registers());
    let mut scratch = Vec::new();
    let mut out = [0.0];
    m.eval(&[0.1], &[0.2], &mut out, &mut scratch);
    let (cap, ptr) = (scratch.capacity(), scratch.as_ptr());
    for i in 0..100 {
        m.eval(&[0.1 * i as f64], &[0.2], &mut out, &mut scratch);
    }
    assert_eq!((scratch.capacity(), scratch.as_ptr()), (cap, ptr));
    let direct: f64 = (0..20).map(|i| (9.9 + i as f64).sin()).sum::<f64>() + 0.2;
    assert!((out[0] - direct).abs() < 1e-12);
}

#[test]
fn the_contract_table_reads_and_writes_back() {
    let text = r#"
[system]
kind = "ode"
states = ["pos", "vel"]
inputs = ["force"]
parameters = { k = 2, c = 0.3 }
definitions = ["spring = k*pos + 0.5*pos^3"]
rhs = ["vel", "force - spring - c*vel"]
units = { pos = "m", force = "N" }
"#;
    let file: File = toml::from_str(text).unwrap();
    let Sys::Ode(spec) = &file.system else {
        panic!("{file:?}")
    };
    assert_eq!(spec.parameters["k"], 2.0); // an integer in TOML is a number too
    let m = compile(spec, false).unwrap();
    let mut out = [0.0; 2];
    m.eval(&[1.0, 2.0], &[3.0], &mut out, &mut Vec::new());
    assert_eq!(out, [2.0, 3.0 - (2.0 + 0.5) - 0.3 * 2.0]);
    // Serialising gives the same table, twice the same text.
    let back = toml::to_string(&file).unwrap();
    assert_eq!(back, toml::to_string(&file).unwrap());
    let again: File = toml::from_str(&back).unwrap();
    assert_eq!(again.system, file.system);
    assert!(back.contains("kind = \"ode\""), "{back}");
    assert!(!back.contains("next"), "{back}");
    // Unknown keys and a discrete system.
    let bad = text.replace("units", "unit");
    let e = toml::from_str::<File>(&bad).unwrap_err().to_string();
    assert!(e.contains("unknown field `unit`"), "{e}");
    let discrete = r#"
[system]
kind = "discrete"
states = ["x"]
inputs = ["u"]
parameters = { a = 0.9 }
next = ["a*x + u"]
"#;
    let m = load(discrete);
    assert!(m.is_discrete());
    let mut out = [0.0];
    m.eval(&[2.0], &[1.0], &mut out, &mut Vec::new());
    assert_eq!(out, [2.8]);
}

/// `cargo test -p trainer --lib problem::model::expr -- --ignored --nocapture`
#[test]
#[ignore = "timing, run by hand"]
fn timing_pendulum_eval_vs_built_in() {
    use num_dual::Dual2SVec64;
    use std::hint::black_box;
    use std::time::Instant;
    let m = load(PENDULUM);
    let p = Pendulum::default();
    let n = 20_000_000;
    let mut scratch = Vec::new();
    let mut out = [0.0; 2];
    let mut acc = 0.0;
    let t = Instant::now();
    for i in 0..n {
        let x = [black_box(0.1 + 1e-9 * i as f64), 0.2];
        m.eval(black_box(&x), black_box(&[0.3]), &mut out, &mut scratch);
        acc += black_box(out[1]);
    }
    let tape = t.elapsed().as_secs_f64() * 1e9 / n as f64;
    let t = Instant::now();
    for i in 0..n {
        let x = [black_box(0.1 + 1e-9 * i as f64), 0.2];
        p.rhs(black_box(&x), black_box(&[0.3]), &mut out);
        acc += black_box(out[1]);
    }
    let built_in = t.elapsed().as_secs_f64() * 1e9 / n as f64;
    let n2 = n / 10;
    let mut s2 = Vec::new();
    let mut o2 = [Dual2SVec64::<3>::from(0.0); 2];
    let t = Instant::now();
    for i in 0..n2 {
        let x = [
            Dual2SVec64::<3>::from(black_box(0.1 + 1e-9 * i as f64)).derivative(0),
            Dual2SVec64::<3>::from(0.2).derivative(1),
        ];
        let u = [Dual2SVec64::<3>::from(0.3).derivative(2)];
        m.eval(black_box(&x), black_box(&u), &mut o2, &mut s2);
        acc += black_box(o2[1].re);
    }
    let tape2 = t.elapsed().as_secs_f64() * 1e9 / n2 as f64;
    let t = Instant::now();
    for i in 0..n2 {
        let x = [
            Dual2SVec64::<3>::from(black_box(0.1 + 1e-9 * i as f64)).derivative(0),
            Dual2SVec64::<3>::from(0.2).derivative(1),
        ];
        let u = [Dual2SVec64::<3>::from(0.3).derivative(2)];
        p.rhs(black_box(&x), black_box(&u), &mut o2);
        acc += black_box(o2[1].re);
    }
    let built_in2 = t.elapsed().as_secs_f64() * 1e9 / n2 as f64;
    println!(
        "pendulum rhs, ns per call: f64 tape {tape:.1} vs Pendulum::rhs {built_in:.1}; \
         Dual2SVec64<3> tape {tape2:.1} vs Pendulum::rhs {built_in2:.1} (acc {acc:.3})"
    );
}
