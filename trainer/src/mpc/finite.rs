//! The label gate: which numbers a label rests on, and the rule that makes a solve a label.
//!
//! ```text
//! label(x_s)  ⇔  z*, cost, every part of the KKT residual r(z*, λ*, ν*) and ∂u₀*/∂x_s are
//!                finite  ∧  r re-computed at the returned point ≤ tol
//! ```
//! otherwise the state's status is `numerical_failure` and [`Failure`] names the first
//! quantity that broke the rule (in the order of the rule). A plant whose equations give NaN
//! or ±∞ (`log` of a negative number, `sqrt` of a negative number, a division by zero, …)
//! therefore never yields a label: its first non-finite value stops the SQP
//! ([`Failure::NonFinite`] of [`Quantity::Equations`], …) or, if it appears only in the
//! solution's derivatives, the gate.
//!
//! `f64::max` drops a NaN (`NaN.max(1.0) == 1.0`): a residual folded with it reads 0 where
//! it is NaN. Every fold here and in the solver's residual uses [`nan_max`] instead.

use serde::{Deserialize, Serialize};

/// `max(a, b)`, NaN if either is NaN (unlike `f64::max`, which drops a NaN).
pub fn nan_max(a: f64, b: f64) -> f64 {
    if a.is_nan() || b.is_nan() {
        f64::NAN
    } else {
        a.max(b)
    }
}

/// `max_i |v_i|` (0 for an empty slice), NaN if any entry is NaN.
pub fn abs_max(v: &[f64]) -> f64 {
    v.iter().fold(0.0, |m, x| nan_max(m, x.abs()))
}

/// A number a label rests on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Quantity {
    /// The state x_s itself.
    State,
    /// The plant's equations along the prediction: the dynamics residual
    /// `x_{k+1} − F(x_k, u_k)` or its Jacobian.
    Equations,
    /// The cost or its gradient.
    Cost,
    /// A constraint row of the OCP (its value or slack).
    Constraints,
    /// The Hessian of the Lagrangian (second derivatives of the plant's equations).
    Hessian,
    /// The multipliers λ, ν.
    Multipliers,
    /// The solution z* (states and inputs of the prediction).
    Solution,
    /// The KKT residual's stationarity part.
    Stationarity,
    /// The KKT residual's primal feasibility part.
    PrimalFeasibility,
    /// The KKT residual's dual feasibility part.
    DualFeasibility,
    /// The KKT residual's complementarity part.
    Complementarity,
    /// The soft problem's slacks.
    Slack,
    /// The sensitivity ∂u₀*/∂x_s.
    Sensitivity,
}

impl Quantity {
    /// The quantity in words (for messages).
    pub fn describe(self) -> &'static str {
        match self {
            Quantity::State => "the state x",
            Quantity::Equations => "the plant's equations F(x, u) (or their Jacobian)",
            Quantity::Cost => "the cost (or its gradient)",
            Quantity::Constraints => "a constraint row",
            Quantity::Hessian => "the Hessian of the Lagrangian (second derivatives of F)",
            Quantity::Multipliers => "the multipliers",
            Quantity::Solution => "the solution z* (predicted states and inputs)",
            Quantity::Stationarity => "the KKT residual (stationarity)",
            Quantity::PrimalFeasibility => "the KKT residual (primal feasibility)",
            Quantity::DualFeasibility => "the KKT residual (dual feasibility)",
            Quantity::Complementarity => "the KKT residual (complementarity)",
            Quantity::Slack => "the soft problem's slacks",
            Quantity::Sensitivity => "the sensitivity ∂κ/∂x",
        }
    }
}

/// Why a solve is not a label although the solver did not report a plain failure to converge.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Failure {
    /// The first number of the rule (module doc) that is NaN or ±∞.
    NonFinite(Quantity),
    /// The KKT residual re-computed at the returned point is above the tolerance.
    KktNotMet {
        /// The re-computed residual.
        residual: f64,
        /// The solver's tolerance.
        tol: f64,
    },
}

impl std::fmt::Display for Failure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Failure::NonFinite(q) => write!(f, "{} not finite (NaN or ±∞)", q.describe()),
            Failure::KktNotMet { residual, tol } => write!(
                f,
                "the KKT residual re-checked after the solve is {residual:e} > tol {tol:e}"
            ),
        }
    }
}

/// The first entry of `checks` (in order) whose values are not all finite.
pub fn first_non_finite<'a>(
    checks: impl IntoIterator<Item = (Quantity, &'a [f64])>,
) -> Option<Quantity> {
    checks
        .into_iter()
        .find(|(_, v)| v.iter().any(|x| !x.is_finite()))
        .map(|(q, _)| q)
}

/// What a label rests on (module doc), each as computed for the returned point.
pub struct LabelParts<'a> {
    /// The solution z*.
    pub z: &'a [f64],
    /// The cost at z*.
    pub cost: f64,
    /// The KKT residual re-computed at the returned point: stationarity, primal, dual,
    /// complementarity.
    pub residual: [f64; 4],
    /// ∂u₀*/∂x_s.
    pub sensitivity: &'a [f64],
    /// The solver's tolerance on the residual.
    pub tol: f64,
}

/// The gate (module doc): `Ok` if the parts make a label, else the first [`Failure`].
pub fn check_label(p: &LabelParts<'_>) -> Result<(), Failure> {
    let r = &p.residual;
    let first = first_non_finite([
        (Quantity::Solution, p.z),
        (Quantity::Cost, std::slice::from_ref(&p.cost)),
        (Quantity::Stationarity, &r[0..1]),
        (Quantity::PrimalFeasibility, &r[1..2]),
        (Quantity::DualFeasibility, &r[2..3]),
        (Quantity::Complementarity, &r[3..4]),
        (Quantity::Sensitivity, p.sensitivity),
    ]);
    if let Some(q) = first {
        return Err(Failure::NonFinite(q));
    }
    let residual = r.iter().fold(0.0, |m, v| nan_max(m, *v));
    if residual > p.tol {
        return Err(Failure::KktNotMet {
            residual,
            tol: p.tol,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nan_max_keeps_a_nan_that_f64_max_drops() {
        assert_eq!(f64::NAN.max(1.0), 1.0);
        assert!(nan_max(f64::NAN, 1.0).is_nan());
        assert!(nan_max(1.0, f64::NAN).is_nan());
        assert_eq!(nan_max(1.0, 2.0), 2.0);
        assert!(abs_max(&[1.0, f64::NAN, 3.0]).is_nan());
        assert_eq!(abs_max(&[1.0, -4.0, 3.0]), 4.0);
        assert_eq!(abs_max(&[]), 0.0);
    }

    #[test]
    fn the_gate_names_the_first_non_finite_part_in_order() {
        let ok = LabelParts {
            z: &[1.0, 2.0],
            cost: 3.0,
            residual: [1e-12, 0.0, 0.0, 1e-13],
            sensitivity: &[0.5, -0.5],
            tol: 1e-8,
        };
        assert_eq!(check_label(&ok), Ok(()));
        let nan_sens = LabelParts {
            sensitivity: &[f64::NAN, 0.0],
            ..ok
        };
        assert_eq!(
            check_label(&nan_sens),
            Err(Failure::NonFinite(Quantity::Sensitivity))
        );
        let both = LabelParts {
            cost: f64::INFINITY,
            residual: [0.0, f64::NAN, 0.0, 0.0],
            sensitivity: &[f64::NAN, 0.0],
            ..ok
        };
        assert_eq!(check_label(&both), Err(Failure::NonFinite(Quantity::Cost)));
        let unmet = LabelParts {
            residual: [0.0, 1e-3, 0.0, 0.0],
            sensitivity: &[0.0, 0.0],
            ..ok
        };
        assert!(matches!(
            check_label(&unmet),
            Err(Failure::KktNotMet { residual, .. }) if residual == 1e-3
        ));
    }
}
