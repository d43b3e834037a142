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
        Op::Sin(a) => {
            let x = g(a);
            let s = DualNum::sin(&x);
            un(s, x.cos(), -s)
        }
        Op::Cos(a) => {
            let x = g(a);
            let c = DualNum::cos(&x);
            un(c, -x.sin(), -c)
        }
        Op::Tan(a) => {
            let t = DualNum::tan(&g(a));
            let d = 1.0 + t * t;
            un(t, d, 2.0 * t * d)
        }
        Op::Asin(a) | Op::Acos(a) => {
            let x = g(a);
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
        Op::Atan(a) => {
            let x = g(a);
            let r = 1.0 / (1.0 + x * x);
            un(DualNum::atan(&x), r, -2.0 * x * r * r)
        }
        Op::Exp(a) => {
            let e = DualNum::exp(&g(a));
            un(e, e, e)
        }
        Op::Log(a) => {
            let x = g(a);
            let r = 1.0 / x;
            un(DualNum::ln(&x), r, -r * r)
        }
        Op::Sqrt(a) => {
            let x = g(a);
            let s = DualNum::sqrt(&x);
            let d = s * x.recip() * 0.5;
            un(s, d, -0.5 * d / x)
        }
        Op::Sinh(a) => {
            let x = g(a);
            let s = DualNum::sinh(&x);
            un(s, x.cosh(), s)
        }
        Op::Cosh(a) => {
            let x = g(a);
            let c = DualNum::cosh(&x);
            un(c, x.sinh(), c)
        }
        Op::Tanh(a) => {
            let t = DualNum::tanh(&g(a));
            let d = 1.0 - t * t;
            un(t, d, -2.0 * t * d)
        }
        Op::Abs(a) => {
            // num-dual's convention (`is_positive` of num-traits is `is_sign_positive`): the
            // derivative is +1 at +0.0 and −1 at −0.0.
            let x = g(a);
            un(x.abs(), if x.is_sign_positive() { 1.0 } else { -1.0 }, 0.0)
        }
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
