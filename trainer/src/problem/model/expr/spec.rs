//! [`SystemSpec`]: the `[system]` table of a model given as expressions, as read from TOML.
//!
//! ```toml
//! [system]
//! kind = "ode"                        # or "discrete" with `next = [...]` instead of `rhs`
//! states = ["pos", "vel"]
//! inputs = ["force"]
//! parameters = { k = 2.0, c = 0.3 }   # optional named constants
//! definitions = ["spring = k*pos + 0.5*pos^3"]   # optional, in order
//! rhs = ["vel", "force - spring - c*vel"]        # one expression per state
//! units = { pos = "m", force = "N" }  # optional
//! time_unit = "s"                     # optional: the unit of time of ẋ and ocp.ts
//! ```
//!
//! `kind` is not a field: the caller's `#[serde(tag = "kind")]` enum reads it and holds a
//! `SystemSpec` as the payload of its `ode` / `discrete` variants. Reading checks only the
//! shape (unknown keys are errors); [`compile`](super::compile) checks the content.
//! Serialising writes the same keys back in a fixed order (maps are sorted), empty optional
//! keys omitted.

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The `[system]` table of an expression model (without `kind`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SystemSpec {
    /// State names, in order (x₀, x₁, …).
    pub states: Vec<String>,
    /// Input names, in order (u₀, …).
    pub inputs: Vec<String>,
    /// Named constants, substituted into the expressions.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub parameters: BTreeMap<String, f64>,
    /// `name = expression`, in order; each may use the states, inputs, parameters and the
    /// definitions before it.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub definitions: Vec<String>,
    /// ODE right-hand side ẋ = f(x, u), one expression per state (`kind = "ode"`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rhs: Option<Vec<String>>,
    /// Discrete map x⁺ = F(x, u), one expression per state (`kind = "discrete"`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub next: Option<Vec<String>>,
    /// Units of states, inputs, parameters or definitions (for reports).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub units: BTreeMap<String, String>,
    /// The unit of time of `rhs` (ẋ per this unit) and of `ocp.ts`, e.g. `"min"` (default
    /// `"s"`; reports and figures label times with it). Not serialised when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time_unit: Option<String>,
}
