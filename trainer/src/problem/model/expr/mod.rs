//! Plant models written as expressions in the problem file: the language and its compiler.
//!
//! A `[system]` table with `kind = "ode"` or `"discrete"` ([`SystemSpec`]) names the states,
//! inputs, parameters and definitions and gives one expression per state. [`compile`] checks
//! it (every [`ExprError`] names the key, the expression and the column) and turns it into an
//! [`ExprModel`], whose [`ExprModel::eval`] computes all outputs generically over the number
//! type, like [`Dynamics::rhs`](super::Dynamics::rhs): in `f64`, or in num-dual's dual numbers
//! for exact first and second derivatives.
//!
//! The way from text to numbers, one file each:
//!
//! | step | file | object |
//! |---|---|---|
//! | TOML table | `spec.rs` | [`SystemSpec`] |
//! | the functions of the language | `func.rs` | [`Func`] |
//! | text → syntax tree (grammar in EBNF) | `parse.rs` | `Ast` |
//! | names, checks, parameters and definitions substituted | `compile.rs` | [`compile`] |
//! | hash-consed graph: CSE, constant folding | `dag.rs` | `Dag` |
//! | flat instruction tape on registers | `tape.rs` | `Tape` |
//! | F = RK4 of the tape on single-assignment slots, exact derivative sweeps | `sweep.rs` | [`Sweep`] |
//! | the compiled model | `model.rs` | [`ExprModel`] |
//! | `[ocp]` constraints g(x, u) ≤ 0 | `constraint.rs` | [`ConstraintSet`] |
//! | errors | `error.rs` | [`ExprError`], [`ErrorKind`] |
//!
//! Evaluation order: an expression is computed in the order it is written (no reassociation),
//! so `u/(m*l^2) - g/l*sin(theta + pi)` gives the same bits as the same formula written in
//! Rust; constant parts are folded with the very `f64` functions the tape uses.

mod compile;
mod constraint;
mod dag;
mod error;
mod func;
mod model;
mod parse;
mod partials;
mod spec;
mod sweep;
mod tape;

#[cfg(test)]
mod tests;

pub use compile::compile;
pub use constraint::{ConstraintInfo, ConstraintSet};
pub use error::{ErrorKind, ExprError};
pub use model::ExprModel;
pub use parse::{Func, MAX_DEPTH, MAX_NESTING};
pub use spec::SystemSpec;
pub use sweep::Sweep;
pub use tape::{Instr, Op, Tape};
