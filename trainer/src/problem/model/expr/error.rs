//! [`ExprError`]: what is wrong with a `[system]` table given as expressions, and where.
//!
//! Every error names the dotted key at fault (`system.rhs[1]`, `system.definitions[0]`,
//! `system.parameters.k`, `system.states`); when the fault is inside an expression it also
//! carries the expression's text and the 1-based column (counted in characters) of the
//! offending token, so the message reads
//! ``system.rhs[1], column 9 of `force - sprng - c*vel`: unknown name `sprng` (…)``.

use std::fmt;

/// An error of [`compile`](super::compile): the key, the place in the text, and the kind.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{key}{}: {kind}", At(.at))]
pub struct ExprError {
    /// The dotted key at fault, e.g. `system.rhs[1]`.
    pub key: String,
    /// The expression's text and the 1-based column of the fault, when the fault is in one.
    pub at: Option<(String, usize)>,
    /// What is wrong.
    pub kind: ErrorKind,
}

/// Formats the optional location of an [`ExprError`].
struct At<'a>(&'a Option<(String, usize)>);

impl fmt::Display for At<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.0 {
            Some((text, col)) => write!(f, ", column {col} of `{text}`"),
            None => Ok(()),
        }
    }
}

/// The kinds of [`ExprError`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ErrorKind {
    /// The text does not follow the grammar (the message says what was expected).
    #[error("{0}")]
    Syntax(String),
    /// A name that is no state, input, parameter, definition nor `pi`.
    #[error("unknown name `{name}` (known here: {known})")]
    UnknownName {
        /// The name.
        name: String,
        /// The names that may be used at this place.
        known: String,
    },
    /// A call of something that is not one of the functions.
    #[error("unknown function `{name}` (functions: {})", super::func::Func::list())]
    UnknownFunction {
        /// The name called.
        name: String,
    },
    /// A function called with the wrong number of arguments.
    #[error("`{func}` takes {expected} argument{}, got {got}", if *.expected == 1 { "" } else { "s" })]
    Arity {
        /// The function.
        func: String,
        /// Its number of arguments.
        expected: usize,
        /// The number given.
        got: usize,
    },
    /// A definition used in itself or in an earlier definition.
    #[error("definition `{name}` is used before it is defined (in {defined_at}); definitions are read in order")]
    UsedBeforeDefined {
        /// The definition's name.
        name: String,
        /// The key that defines it.
        defined_at: String,
    },
    /// A name given twice, or a name that is `pi` or a function.
    #[error("name `{name}` is already {first}")]
    Duplicate {
        /// The name.
        name: String,
        /// What it already names, e.g. ``a state (`system.states[0]`)``.
        first: String,
    },
    /// A state, input, parameter or definition name that is not an identifier.
    #[error("`{name}` is not a valid name (a letter or `_`, then letters, digits or `_`)")]
    InvalidName {
        /// The name.
        name: String,
    },
    /// Not one equation per state (the message names the state or equation at fault).
    #[error("{0}")]
    EquationCount(String),
    /// `rhs` for a discrete system, `next` for an ODE, or neither, or both.
    #[error("{0}")]
    EquationKey(String),
    /// A parameter that is NaN or infinite.
    #[error("parameter `{name}` must be finite, got {value}")]
    NonFiniteParameter {
        /// The parameter.
        name: String,
        /// Its value.
        value: f64,
    },
    /// `states = []`.
    #[error("a system needs at least one state")]
    EmptyStates,
    /// A part of an expression that depends on no state or input evaluates to NaN or ±∞
    /// (with the parameters substituted), e.g. `log(k - 2)` with `k = 2`.
    #[error("this part depends on no state or input and evaluates to {value}")]
    NonFiniteConstant {
        /// The value.
        value: f64,
    },
    /// A constraint that is not one inequality `lhs <= rhs` / `lhs >= rhs` in the states and
    /// inputs, or a terminal constraint that uses an input (the message says which).
    #[error("{0}")]
    Constraint(String),
    /// A `time_unit` that is empty, longer than 16 characters or has control characters.
    #[error("time unit `{unit}` must be 1 to 16 printable characters, e.g. \"s\" or \"min\"")]
    BadTimeUnit {
        /// The unit as written.
        unit: String,
    },
    /// A `units` entry for a name that is no state, input, parameter or definition.
    #[error("units given for `{name}`, which is no state, input, parameter or definition")]
    UnknownUnitName {
        /// The name.
        name: String,
    },
}

impl ExprError {
    /// An error without a place in an expression.
    pub(super) fn key(key: impl Into<String>, kind: ErrorKind) -> Self {
        ExprError {
            key: key.into(),
            at: None,
            kind,
        }
    }
    /// An error at 1-based column `col` of `text`.
    pub(super) fn at(key: impl Into<String>, text: &str, col: usize, kind: ErrorKind) -> Self {
        ExprError {
            key: key.into(),
            at: Some((text.to_string(), col)),
            kind,
        }
    }
    /// The message without the key (for callers that report the key separately), e.g.
    /// ``column 9 of `force - sprng`: unknown name `sprng` (…)``.
    pub fn reason(&self) -> String {
        match &self.at {
            Some((text, col)) => format!("column {col} of `{text}`: {}", self.kind),
            None => self.kind.to_string(),
        }
    }
}
