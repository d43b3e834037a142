//! Properties: the tape equals a direct recursive evaluation of random expression trees, and
//! its dual-number derivatives (first and second order) equal central finite differences.

use super::super::parse::Func;
use super::super::{compile, ErrorKind, ExprModel};
use super::spec;
use nalgebra::Const;
use num_dual::{Dual2SVec64, DualSVec64};
use proptest::prelude::*;

/// A random expression over x, y (states) and z (input).
#[derive(Debug, Clone)]
pub(super) enum T {
    Num(f64),
    Var(usize),
    Neg(Box<T>),
    Bin(char, Box<T>, Box<T>),
    Call(Func, Vec<T>),
}

const VARS: [&str; 3] = ["x", "y", "z"];

pub(super) fn tree() -> impl Strategy<Value = T> {
    let leaf = prop_oneof![
        (-3.0f64..3.0).prop_map(T::Num),
        prop::sample::select(vec![0.0, 1.0, 2.0, 3.0, 0.5, -1.0, -2.0, 1e-3]).prop_map(T::Num),
        (0usize..3).prop_map(T::Var),
        (0usize..3).prop_map(T::Var),
    ];
    leaf.prop_recursive(5, 48, 2, |inner| {
        prop_oneof![
            inner.clone().prop_map(|a| T::Neg(Box::new(a))),
            (
                prop::sample::select(vec!['+', '-', '*', '/', '^']),
                inner.clone(),
                inner.clone()
            )
                .prop_map(|(op, a, b)| T::Bin(op, Box::new(a), Box::new(b))),
            (inner.clone(), -3i32..5).prop_map(|(a, n)| T::Bin(
                '^',
                Box::new(a),
                Box::new(T::Num(n as f64))
            )),
            (
                prop::sample::select(Func::ALL.to_vec()),
                inner.clone(),
                inner
            )
                .prop_map(|(f, a, b)| T::Call(
                    f,
                    if f.arity() == 2 { vec![a, b] } else { vec![a] }
                )),
        ]
    })
}

/// Precedence of the rendering: 1 `+ -`, 2 `* /`, 3 unary minus, 4 `^`, 5 atoms.
fn prec(t: &T) -> u8 {
    match t {
        T::Num(v) if *v < 0.0 => 3,
        T::Num(_) | T::Var(_) | T::Call(..) => 5,
        T::Neg(_) => 3,
        T::Bin('+' | '-', ..) => 1,
        T::Bin('*' | '/', ..) => 2,
        T::Bin(..) => 4,
    }
}

/// Text with as few parentheses as the grammar allows (so the parser's rules are exercised).
pub(super) fn render(t: &T) -> String {
    let wrap = |t: &T, paren: bool| {
        if paren {
            format!("({})", render(t))
        } else {
            render(t)
        }
    };
    match t {
        T::Num(v) if *v < 0.0 => format!("-{:?}", -v),
        T::Num(v) => format!("{v:?}"),
        T::Var(i) => VARS[*i].to_string(),
        T::Neg(a) => format!("-{}", wrap(a, prec(a) < 3)),
        T::Bin('^', a, b) => format!("{}^{}", wrap(a, prec(a) <= 4), wrap(b, prec(b) < 3)),
        T::Bin(op, a, b) => {
            let p = prec(t);
            format!("{} {op} {}", wrap(a, prec(a) < p), wrap(b, prec(b) <= p))
        }
        T::Call(f, args) => format!(
            "{}({})",
            f.name(),
            args.iter().map(render).collect::<Vec<_>>().join(", ")
        ),
    }
}

fn has_var(t: &T) -> bool {
    match t {
        T::Num(_) => false,
        T::Var(_) => true,
        T::Neg(a) => has_var(a),
        T::Bin(_, a, b) => has_var(a) || has_var(b),
        T::Call(_, args) => args.iter().any(has_var),
    }
}

/// `x^e` for a constant exponent, by the language's rules: integers by multiplication.
fn pow_const(x: f64, e: f64) -> f64 {
    if e.fract() == 0.0 && e.abs() <= 64.0 {
        match e as i32 {
            0 => 1.0,
            1 => x,
            2 => x * x,
            -1 => 1.0 / x,
            n => x.powi(n),
        }
    } else if e == 0.5 {
        x.sqrt()
    } else {
        x.powf(e)
    }
}

/// Direct recursive evaluation; `None` as soon as an intermediate value is not finite.
fn direct(t: &T, v: &[f64; 3]) -> Option<f64> {
    let r = match t {
        T::Num(c) => *c,
        T::Var(i) => v[*i],
        T::Neg(a) => -direct(a, v)?,
        T::Bin(op, a, b) => {
            let (x, y) = (direct(a, v)?, direct(b, v)?);
            match op {
                '+' => x + y,
                '-' => x - y,
                '*' => x * y,
                '/' => x / y,
                _ if has_var(b) => x.powf(y),
                _ => pow_const(x, y),
            }
        }
        T::Call(f, args) => {
            let x = direct(&args[0], v)?;
            let y = match args.get(1) {
                Some(b) => direct(b, v)?,
                None => 0.0,
            };
            match f {
                Func::Sin => x.sin(),
                Func::Cos => x.cos(),
                Func::Tan => x.tan(),
                Func::Asin => x.asin(),
                Func::Acos => x.acos(),
                Func::Atan => x.atan(),
                Func::Atan2 => x.atan2(y),
                Func::Exp => x.exp(),
                Func::Log => x.ln(),
                Func::Sqrt => x.sqrt(),
                Func::Sinh => x.sinh(),
                Func::Cosh => x.cosh(),
                Func::Tanh => x.tanh(),
                Func::Abs => x.abs(),
                Func::Min => {
                    if y < x {
                        y
                    } else {
                        x
                    }
                }
                Func::Max => {
                    if y > x {
                        y
                    } else {
                        x
                    }
                }
            }
        }
    };
    r.is_finite().then_some(r)
}

/// The model `rhs = [a, b]` over states x, y and input z.
fn model(texts: &[String]) -> Result<ExprModel, super::super::ExprError> {
    let t: Vec<&str> = texts.iter().map(String::as_str).collect();
    compile(&spec(&["x", "y"], &["z"], &[], &[], &t), false)
}

proptest! {
    #![proptest_config(ProptestConfig {
        rng_seed: proptest::test_runner::RngSeed::Fixed(0x616d_7063),
        ..ProptestConfig::with_cases(1024)
    })]
    #[test]
    fn tape_equals_direct_evaluation(
        a in tree(),
        b in tree(),
        v in prop::array::uniform3(-2.5f64..2.5),
    ) {
        let texts = vec![render(&a), render(&b)];
        let m = match model(&texts) {
            Ok(m) => m,
            // A constant part that is not finite (e.g. `log(-2)`) is refused at compile time.
            Err(e) if matches!(e.kind, ErrorKind::NonFiniteConstant { .. }) => return Ok(()),
            Err(e) => return Err(TestCaseError::fail(format!("{texts:?}: {e}"))),
        };
        let mut out = [0.0; 2];
        let mut scratch = Vec::new();
        m.eval(&v[..2], &v[2..], &mut out, &mut scratch);
        for (k, t) in [&a, &b].into_iter().enumerate() {
            if let Some(d) = direct(t, &v) {
                let o = out[k];
                prop_assert!(
                    o == d || (o - d).abs() <= 1e-12 * d.abs().max(o.abs()),
                    "{}: tape {o:e} direct {d:e} at {v:?}\n{m}", texts[k]
                );
            }
        }
        // Evaluating again with the grown scratch gives the same bits.
        let mut again = [0.0; 2];
        m.eval(&v[..2], &v[2..], &mut again, &mut scratch);
        prop_assert_eq!(out.map(f64::to_bits), again.map(f64::to_bits));
    }
}

/// Smooth expressions covering every operation (kinks and singularities away from the box
/// x, y ∈ [0.5, 1.5], z ∈ [0.2, 0.8]).
pub(super) const SMOOTH: [[&str; 2]; 6] = [
    ["sin(x)*cos(y) + tan(z)", "asin(z) + acos(z/2) - atan(x*y)"],
    [
        "atan2(y, x) + exp(-x^2)*log(y)",
        "sqrt(x + y) + sinh(z) - cosh(x)/tanh(y)",
    ],
    [
        "x^y + z^3 - x^-2 + y^0.5 + x^1.5",
        "2^x + (x*y - z)^2/(1 + z^4) - 3/x",
    ],
    [
        "abs(x - 3) + min(x, y + 5) + max(z, -1)",
        "-(x - y)^5 + 1 - y - -z",
    ],
    ["d*d + e", "e*sin(d) + z*x*y"],
    ["x*y*z - x/y/z", "(x + 2*y - z)^7/10"],
];

fn smooth_model(pair: &[&str; 2]) -> ExprModel {
    let s = spec(
        &["x", "y"],
        &["z"],
        &[],
        &["d = x*y + z", "e = d^2 - sin(x)"],
        pair,
    );
    compile(&s, false).unwrap_or_else(|e| panic!("{pair:?}: {e}"))
}

fn f64_eval(m: &ExprModel, v: &[f64; 3]) -> [f64; 2] {
    let mut out = [0.0; 2];
    m.eval(&v[..2], &v[2..], &mut out, &mut Vec::new());
    out
}

/// Gradients of both outputs by first-order duals: `g[k][j] = ∂out_k/∂v_j`.
fn gradients(m: &ExprModel, v: &[f64; 3]) -> ([f64; 2], [[f64; 3]; 2]) {
    let d: Vec<DualSVec64<3>> = (0..3)
        .map(|j| DualSVec64::<3>::from(v[j]).derivative(j))
        .collect();
    let mut out = [DualSVec64::<3>::from(0.0); 2];
    m.eval(&d[..2], &d[2..], &mut out, &mut Vec::new());
    let mut g = [[0.0; 3]; 2];
    for k in 0..2 {
        let e = out[k].eps.unwrap_generic(Const::<3>, Const::<1>);
        for j in 0..3 {
            g[k][j] = e[j];
        }
    }
    (out.map(|o| o.re), g)
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * (1.0 + a.abs().max(b.abs()))
}

proptest! {
    #![proptest_config(ProptestConfig {
        rng_seed: proptest::test_runner::RngSeed::Fixed(0x616d_7063),
        ..ProptestConfig::with_cases(96)
    })]
    #[test]
    fn dual_derivatives_equal_finite_differences(
        x in 0.5f64..1.5,
        y in 0.5f64..1.5,
        z in 0.2f64..0.8,
    ) {
        let v = [x, y, z];
        let h = 1e-5;
        for pair in &SMOOTH {
            let m = smooth_model(pair);
            let f = f64_eval(&m, &v);
            let (re, g) = gradients(&m, &v);
            // Second order: value, gradient and Hessian from one evaluation.
            let d2: Vec<Dual2SVec64<3>> =
                (0..3).map(|j| Dual2SVec64::<3>::from(v[j]).derivative(j)).collect();
            let mut o2 = [Dual2SVec64::<3>::from(0.0); 2];
            m.eval(&d2[..2], &d2[2..], &mut o2, &mut Vec::new());
            for k in 0..2 {
                prop_assert!(close(re[k], f[k], 1e-14), "{}: dual value {} f64 {}", pair[k], re[k], f[k]);
                prop_assert!(close(o2[k].re, f[k], 1e-14));
                let g2 = o2[k].v1.unwrap_generic(Const::<1>, Const::<3>);
                let hess = o2[k].v2.unwrap_generic(Const::<3>, Const::<3>);
                for j in 0..3 {
                    let (mut p, mut q) = (v, v);
                    p[j] += h;
                    q[j] -= h;
                    let fd = (f64_eval(&m, &p)[k] - f64_eval(&m, &q)[k]) / (2.0 * h);
                    prop_assert!(close(g[k][j], fd, 1e-6), "{}: d/dv{j}: dual {} fd {fd}", pair[k], g[k][j]);
                    prop_assert!(close(g2[j], g[k][j], 1e-13), "{}: second-order gradient", pair[k]);
                    let (gp, gq) = (gradients(&m, &p).1[k], gradients(&m, &q).1[k]);
                    for i in 0..3 {
                        let fd2 = (gp[i] - gq[i]) / (2.0 * h);
                        prop_assert!(
                            close(hess[(i, j)], fd2, 1e-6),
                            "{}: d2/dv{i}dv{j}: dual {} fd {fd2}", pair[k], hess[(i, j)]
                        );
                    }
                }
            }
        }
    }
}
