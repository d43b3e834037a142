//! The local partials of one tape instruction ([`local`]): for `c = φ(a, b)` the value and
//! `[φ_a, φ_b, φ_aa, φ_ab, φ_bb]` from the operands' values, the value computed by the same
//! `f64` function as the tape's evaluation (bit for bit) — what the sweeps of `sweep`
//! propagate.

use super::tape::Op;
use num_dual::DualNum;

/// The value of an instruction and its local partials `[φ_a, φ_b, φ_aa, φ_ab, φ_bb]`; the
/// value is computed by the same `f64` function as the tape's f64 evaluation (bit for bit).
#[inline(always)]
pub(super) fn local(op: Op, v: &[f64]) -> (f64, [f64; 5]) {
    let g = |r: u32| v[r as usize];
    let un = |value: f64, d: f64, dd: f64| (value, [d, 0.0, dd, 0.0, 0.0]);
    match op {
        Op::Const(c) => (c, [0.0; 5]),
        Op::Add(a, b) => (g(a) + g(b), [1.0, 1.0, 0.0, 0.0, 0.0]),
        Op::Sub(a, b) => (g(a) - g(b), [1.0, -1.0, 0.0, 0.0, 0.0]),
        Op::Mul(a, b) => (g(a) * g(b), [g(b), g(a), 0.0, 1.0, 0.0]),
        Op::Div(a, b) => {
            let (x, y) = (g(a), g(b));
            let c = x / y;
            let r = 1.0 / y;
            (c, [r, -c * r, 0.0, -r * r, 2.0 * c * r * r])
        }
        Op::AddC(a, c) => un(g(a) + c, 1.0, 0.0),
        Op::CSub(c, a) => un(c - g(a), -1.0, 0.0),
        Op::MulC(a, c) => un(g(a) * c, c, 0.0),
        Op::DivC(a, c) => un(g(a) / c, 1.0 / c, 0.0),
        Op::CDiv(c, a) => {
            let x = g(a);
            let value = c / x;
            let r = 1.0 / x;
            un(value, -c * r * r, 2.0 * value * r * r)
        }
        Op::Neg(a) => un(-g(a), -1.0, 0.0),
        Op::Sq(a) => un(g(a) * g(a), 2.0 * g(a), 2.0),
        Op::Recip(a) => {
            let value = DualNum::recip(&g(a));
            un(value, -value * value, 2.0 * value * value * value)
        }
        Op::Powi(a, n) => {
            let x = g(a);
            let value = super::dag::powi(x, n);
            match n {
                0 => un(value, 0.0, 0.0),
                1 => un(value, 1.0, 0.0),
                2 => un(value, 2.0 * x, 2.0),
                _ => {
                    // As the dual numbers: x^(n−3)·x·x·n.
                    let p3 = x.powi(n - 3);
                    let p2 = p3 * x;
                    un(value, p2 * x * f64::from(n), f64::from(n * (n - 1)) * p2)
                }
            }
        }
        Op::Powf(a, c) => {
            let x = g(a);
            let value = DualNum::powf(&x, c);
            if c == 0.0 {
                un(value, 0.0, 0.0)
            } else if c == 1.0 {
                un(value, 1.0, 0.0)
            } else {
                // As the dual numbers: x^(c−3)·x·x·c.
                let p3 = x.powf(c - 1.0 - 1.0 - 1.0);
                let p2 = p3 * x;
                un(value, p2 * x * c, c * (c - 1.0) * p2)
            }
        }
        Op::Pow(a, b) => {
            let (x, y) = (g(a), g(b));
            let value = DualNum::powd(&x, y);
            let l = x.ln();
            let p1 = x.powf(y - 1.0);
            (
                value,
                [
                    y * p1,
                    value * l,
                    y * (y - 1.0) * x.powf(y - 2.0),
                    p1 * (1.0 + y * l),
                    value * l * l,
                ],
            )
        }
        Op::Sin(a)
        | Op::Cos(a)
        | Op::Tan(a)
        | Op::Asin(a)
        | Op::Acos(a)
        | Op::Atan(a)
        | Op::Exp(a)
        | Op::Log(a)
        | Op::Sqrt(a)
        | Op::Sinh(a)
        | Op::Cosh(a)
        | Op::Tanh(a)
        | Op::Abs(a) => elementary(op, g(a)),
        Op::Atan2(a, b) => {
            let (x, y) = (g(a), g(b));
            let r = 1.0 / (x * x + y * y);
            let r2 = r * r;
            (
                DualNum::atan2(&x, y),
                [
                    y * r,
                    -x * r,
                    -2.0 * x * y * r2,
                    (x * x - y * y) * r2,
                    2.0 * x * y * r2,
                ],
            )
        }
        // By the values, at a tie `a` (as `dag::min`/`dag::max`).
        Op::Min(a, b) => {
            if g(b) < g(a) {
                (g(b), [0.0, 1.0, 0.0, 0.0, 0.0])
            } else {
                (g(a), [1.0, 0.0, 0.0, 0.0, 0.0])
            }
        }
        Op::Max(a, b) => {
            if g(b) > g(a) {
                (g(b), [0.0, 1.0, 0.0, 0.0, 0.0])
            } else {
                (g(a), [1.0, 0.0, 0.0, 0.0, 0.0])
            }
        }
    }
}

/// [`local`] of an elementary function `c = φ(a)` at `a = x`: the value and `[φ', 0, φ'', 0,
/// 0]`. `op` is one of `Sin … Abs`; any other op gives NaN (`local` handles those).
#[inline(always)]
fn elementary(op: Op, x: f64) -> (f64, [f64; 5]) {
    let un = |value: f64, d: f64, dd: f64| (value, [d, 0.0, dd, 0.0, 0.0]);
    match op {
        Op::Sin(_) => {
            let s = DualNum::sin(&x);
            un(s, x.cos(), -s)
        }
        Op::Cos(_) => {
            let c = DualNum::cos(&x);
            un(c, -x.sin(), -c)
        }
        Op::Tan(_) => {
            let t = DualNum::tan(&x);
            let d = 1.0 + t * t;
            un(t, d, 2.0 * t * d)
        }
        Op::Asin(_) | Op::Acos(_) => {
            let r = 1.0 / (1.0 - x * x);
            let d = r.sqrt();
            let sign = if matches!(op, Op::Asin(_)) { 1.0 } else { -1.0 };
            let value = if sign > 0.0 {
                DualNum::asin(&x)
            } else {
                DualNum::acos(&x)
            };
            un(value, sign * d, sign * x * d * r)
        }
        Op::Atan(_) => {
            let r = 1.0 / (1.0 + x * x);
            un(DualNum::atan(&x), r, -2.0 * x * r * r)
        }
        Op::Exp(_) => {
            let e = DualNum::exp(&x);
            un(e, e, e)
        }
        Op::Log(_) => {
            let r = 1.0 / x;
            un(DualNum::ln(&x), r, -r * r)
        }
        Op::Sqrt(_) => {
            let s = DualNum::sqrt(&x);
            let d = s * x.recip() * 0.5;
            un(s, d, -0.5 * d / x)
        }
        Op::Sinh(_) => {
            let s = DualNum::sinh(&x);
            un(s, x.cosh(), s)
        }
        Op::Cosh(_) => {
            let c = DualNum::cosh(&x);
            un(c, x.sinh(), c)
        }
        Op::Tanh(_) => {
            let t = DualNum::tanh(&x);
            let d = 1.0 - t * t;
            un(t, d, -2.0 * t * d)
        }
        Op::Abs(_) => {
            // num-dual's convention (`is_positive` of num-traits is `is_sign_positive`): the
            // derivative is +1 at +0.0 and −1 at −0.0.
            un(x.abs(), if x.is_sign_positive() { 1.0 } else { -1.0 }, 0.0)
        }
        _ => (f64::NAN, [f64::NAN; 5]),
    }
}
