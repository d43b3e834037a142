//! `[ocp]`: the optimal control problem's data — sampling time, horizon, the setpoint
//! (x_ref, u_ref) and the weights of ℓ(x, u) = (x − x_ref)ᵀQ(x − x_ref) + (u − u_ref)ᵀR(u − u_ref),
//! V_f(x) = (x − x_ref)ᵀP(x − x_ref) (x_ref = 0, u_ref = 0 unless given), the constraint
//! boxes x_k ∈ X_k, u_k ∈ U_k, and the optional path and terminal constraints g(x, u) ≤ 0
//! written as expressions (`constraints`, `terminal_constraints`; compiled by
//! [`ConstraintSet`](crate::problem::model::expr::ConstraintSet)).

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

/// A square matrix given as a diagonal or as full rows.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum MatrixSpec {
    /// Diagonal entries.
    Diagonal(Vec<f64>),
    /// Full matrix, row-major rows.
    Full(Vec<Vec<f64>>),
}

impl MatrixSpec {
    /// Dense matrix; `None` if the rows are ragged.
    pub fn to_dmatrix(&self) -> Option<DMatrix<f64>> {
        match self {
            MatrixSpec::Diagonal(d) => Some(DMatrix::from_diagonal(
                &nalgebra::DVector::from_column_slice(d),
            )),
            MatrixSpec::Full(rows) => {
                let n = rows.len();
                let m = rows.first().map_or(0, |r| r.len());
                if rows.iter().any(|r| r.len() != m) {
                    return None;
                }
                Some(DMatrix::from_fn(n, m, |i, j| rows[i][j]))
            }
        }
    }
}

/// The optimal control problem's data (`[ocp]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OcpSettings {
    /// Sampling time Ts in s (pendulum: 0.05).
    pub ts: f64,
    /// Horizon N ≥ 1 (pendulum: 20).
    pub horizon: usize,
    /// RK4 sub-steps per sample (default 1).
    #[serde(default = "one")]
    pub rk4_substeps: usize,
    /// Stage state weight Q (symmetric PSD).
    pub q: MatrixSpec,
    /// Stage input weight R (symmetric positive definite).
    pub r: MatrixSpec,
    /// Terminal weight P (symmetric PSD).
    pub p: MatrixSpec,
    /// Setpoint state x_ref of the stage and terminal costs (default: the origin). Must lie
    /// in the domain and the state bounds. Absent by default, and then not serialised, so
    /// hashes of existing problems are unchanged.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub x_ref: Option<Vec<f64>>,
    /// Setpoint input u_ref of the stage cost (default: 0). Must lie in the input bounds.
    /// Not serialised when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub u_ref: Option<Vec<f64>>,
    /// Largest accepted one-step residual |F(x_ref, u_ref) − x_ref|_i of the setpoint,
    /// relative to each state's scale (the domain's half-width or |x_ref_i|); see
    /// [`crate::problem::setpoint`]. Default 1e-6; not serialised when default.
    #[serde(
        default = "default_setpoint_tol",
        skip_serializing_if = "is_default_setpoint_tol"
    )]
    pub setpoint_tol: f64,
    /// The setpoint input computed from the model when `u_ref` is omitted (the input in U
    /// that holds x_ref; filled when the file is read). Never serialised.
    #[serde(skip)]
    pub derived_u_ref: Option<Vec<f64>>,
    /// Lower state bounds on x₁..x_N (`-inf` for none).
    pub x_lo: Vec<f64>,
    /// Upper state bounds on x₁..x_N (`inf` for none).
    pub x_hi: Vec<f64>,
    /// Lower input bounds on u₀..u_{N−1}.
    pub u_lo: Vec<f64>,
    /// Upper input bounds on u₀..u_{N−1}.
    pub u_hi: Vec<f64>,
    /// Stage-dependent bounds (a tightened, robust OCP; see `trainer::robust`). When
    /// present they replace the constant bounds above inside the OCP; the constant bounds
    /// stay the true constraint set X × U (actuator limits, closed-loop violation checks).
    /// Absent by default, and then not serialised, so hashes of existing problems are
    /// unchanged.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stages: Option<StageBounds>,
    /// Path constraints `lhs <= rhs` / `lhs >= rhs` in the states and inputs (by name): one in
    /// states only holds on x₁…x_N, one in inputs only on u₀…u_{N−1}, one in both on
    /// k = 1…N−1. Empty by default (and then not serialised: existing hashes unchanged).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub constraints: Vec<String>,
    /// Terminal constraints in the states, on x_N only (a terminal region).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub terminal_constraints: Vec<String>,
    /// Scale S_x of the states in the certificate's norm (one finite entry > 0 per state):
    /// every bound measures a state difference as ‖S_x⁻¹ Δx‖₂. Default (absent): the
    /// half-widths of the domain X. Not part of the problem hash (labels do not depend on
    /// it) and not serialised when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub x_scale: Option<Vec<f64>>,
    /// Scale S_u of the inputs in the certificate's norm (one finite entry > 0 per input):
    /// ε bounds ‖S_u⁻¹(κ − κ_NN)‖₂, so |κ_j − κ_NN,j| ≤ s_u,j·ε per input in physical
    /// units. Default (absent): the half-widths of U (`u_lo`, `u_hi`). Not part of the
    /// problem hash and not serialised when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub u_scale: Option<Vec<f64>>,
    /// The safety-augmented controller's online check imposed on the MPC only (terminal set,
    /// terminal cost, the check's box margins; [`super::online_check`]): filled by `trainer
    /// run` when `[closed_loop] safety = true` (and `safety_terminal`); absent by default, and
    /// then not serialised, so hashes of existing problems are unchanged.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub online_check: Option<super::online_check::OnlineCheck>,
}

fn default_setpoint_tol() -> f64 {
    crate::problem::setpoint::DEFAULT_SETPOINT_TOL
}

fn is_default_setpoint_tol(v: &f64) -> bool {
    *v == default_setpoint_tol()
}

/// Per-stage bounds of a tightened OCP: `x_lo[k−1]`, `x_hi[k−1]` bound x_k (k = 1..N),
/// `u_lo[k]`, `u_hi[k]` bound u_k (k = 0..N−1). Infinite entries mean no bound.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StageBounds {
    /// Lower state bounds of x_1..x_N (N rows of nx).
    pub x_lo: Vec<Vec<f64>>,
    /// Upper state bounds of x_1..x_N (N rows of nx).
    pub x_hi: Vec<Vec<f64>>,
    /// Lower input bounds of u_0..u_{N−1} (N rows of nu).
    pub u_lo: Vec<Vec<f64>>,
    /// Upper input bounds of u_0..u_{N−1} (N rows of nu).
    pub u_hi: Vec<Vec<f64>>,
    /// Per affine `[ocp]` constraint (in the order of the compiled constraint set: path
    /// constraints, then terminal ones), per stage k = 0..N: how much its right-hand side is
    /// tightened (row `aᵀ(x_k, u_k) ≤ b − margins[c][k]`). Empty (and then not serialised):
    /// no tightening; a missing entry is 0.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub margins: Vec<Vec<f64>>,
}

impl OcpSettings {
    /// The setpoint state x_ref (`ocp.x_ref`, else the origin of dimension `nx`).
    pub fn x_ref_or_origin(&self, nx: usize) -> Vec<f64> {
        self.x_ref.clone().unwrap_or_else(|| vec![0.0; nx])
    }
    /// The setpoint input u_ref: `ocp.u_ref`, else the input computed from the model that
    /// holds x_ref (when the file was read), else 0 of dimension `nu`.
    pub fn u_ref_or_zero(&self, nu: usize) -> Vec<f64> {
        self.u_ref
            .clone()
            .or_else(|| self.derived_u_ref.clone())
            .unwrap_or_else(|| vec![0.0; nu])
    }
    /// The state scale S_x of the certificate's norm: `x_scale`, else the half-widths of
    /// the domain `[lo, hi]` (an entry that is not finite and > 0 becomes 1).
    pub fn x_scale_or_default(&self, lo: &[f64], hi: &[f64]) -> Vec<f64> {
        self.x_scale.clone().unwrap_or_else(|| half_widths(lo, hi))
    }
    /// The input scale S_u of the certificate's norm: `u_scale`, else the half-widths of U
    /// (`u_lo`, `u_hi`; an entry that is not finite and > 0 becomes 1).
    pub fn u_scale_or_default(&self) -> Vec<f64> {
        self.u_scale
            .clone()
            .unwrap_or_else(|| half_widths(&self.u_lo, &self.u_hi))
    }
    /// Bounds `(lo, hi)` on the predicted state x_k, k = 1..N (stage-dependent if
    /// [`stages`](Self::stages) is set).
    pub fn x_bounds(&self, k: usize) -> (&[f64], &[f64]) {
        match &self.stages {
            Some(s) => (&s.x_lo[k - 1], &s.x_hi[k - 1]),
            None => (&self.x_lo, &self.x_hi),
        }
    }
    /// How much constraint `c` of the compiled set is tightened at stage k (0 without
    /// [`stages`](Self::stages) or a margin for it).
    pub fn constraint_margin(&self, c: usize, k: usize) -> f64 {
        self.stages
            .as_ref()
            .and_then(|s| s.margins.get(c))
            .and_then(|m| m.get(k))
            .copied()
            .unwrap_or(0.0)
    }
    /// Bounds `(lo, hi)` on the input u_k, k = 0..N−1.
    pub fn u_bounds(&self, k: usize) -> (&[f64], &[f64]) {
        match &self.stages {
            Some(s) => (&s.u_lo[k], &s.u_hi[k]),
            None => (&self.u_lo, &self.u_hi),
        }
    }
}

/// ½(hi − lo) per entry; 1 where that is not finite and > 0.
fn half_widths(lo: &[f64], hi: &[f64]) -> Vec<f64> {
    lo.iter()
        .zip(hi)
        .map(|(l, h)| {
            let w = 0.5 * (h - l);
            if w.is_finite() && w > 0.0 {
                w
            } else {
                1.0
            }
        })
        .collect()
}

fn one() -> usize {
    1
}
