//! Tests of the expression language: the parser (`parser`), the error messages (`errors`),
//! the tape against a direct evaluation of random trees and its derivatives against finite
//! differences (`props`), the derivative sweeps against the dual numbers (`sweep`), and the paper's pendulum, CSE, serde and timing (`pendulum`).

mod errors;
mod parser;
mod pendulum;
mod props;
mod sweep;

use super::{compile, ExprError, ExprModel, SystemSpec};
use std::collections::BTreeMap;

/// A spec over states `states`, inputs `inputs`, with parameters, definitions and `rhs`.
pub(super) fn spec(
    states: &[&str],
    inputs: &[&str],
    parameters: &[(&str, f64)],
    definitions: &[&str],
    rhs: &[&str],
) -> SystemSpec {
    let s = |v: &[&str]| v.iter().map(|t| t.to_string()).collect::<Vec<_>>();
    SystemSpec {
        states: s(states),
        inputs: s(inputs),
        parameters: parameters
            .iter()
            .map(|(k, v)| (k.to_string(), *v))
            .collect(),
        definitions: s(definitions),
        rhs: Some(s(rhs)),
        next: None,
        units: BTreeMap::new(),
        time_unit: None,
    }
}

/// Compiles `rhs = [text]` over the state `x` and the input `u`.
pub(super) fn one(text: &str) -> Result<ExprModel, ExprError> {
    compile(&spec(&["x"], &["u"], &[], &[], &[text]), false)
}

/// The value of `text` at `x`, `u`.
pub(super) fn value_at(text: &str, x: f64, u: f64) -> f64 {
    let m = one(text).unwrap_or_else(|e| panic!("{text}: {e}"));
    let mut out = [0.0];
    m.eval(&[x], &[u], &mut out, &mut Vec::new());
    out[0]
}
