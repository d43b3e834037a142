//! Parametric sensitivity ∂z*/∂x_s of the OCP's primal-dual solution, by implicit
//! differentiation of the KKT conditions on the active set (Fiacco 1976; the paper's
//! Section IV-A).
//!
//! At a KKT point with active rows A, the conditions
//! `∇f + ∇cᵀλ + G_Aᵀν_A = 0`, `c(z; x_s) = 0`, `G_A z = h_A` define (z, λ, ν_A) as a smooth
//! function of x_s when LICQ, strict complementarity and second-order sufficiency hold.
//! Differentiating, with `∂c/∂x_s = (−I, 0, …, 0)` (only `c_0 = x_0 − x_s` depends on x_s):
//! ```text
//! K · ∂(z, λ, ν_A)/∂x_s = (0, E, 0),    E = [I_nx; 0]
//! ```
//! with K the active-set KKT matrix (`kkt` module). `∂κ/∂x = ∂u_0*/∂x_s` is the u_0 rows.
//!
//! Degenerate points are detected and flagged, not hidden:
//! - *weakly active* rows (slack ≤ tol and multiplier ≤ tol·max(1, ‖ν‖∞)): strict
//!   complementarity fails and κ is only directionally differentiable. We return the
//!   derivative with those rows treated as inactive (the one-sided derivative for
//!   perturbations that move the state into the row's interior).
//! - a singular K: LICQ fails (an active row is implied by others, e.g. a state bound
//!   reached exactly by saturated inputs) or second-order sufficiency fails. Active rows
//!   with the smallest multipliers are dropped until K is nonsingular (at most 8) and that
//!   derivative is returned, flagged `Singular`; if none is found, zeros.

use crate::mpc::sqp::{PrimalDual, SqpSolver};
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

/// Why a point's sensitivity is not a plain derivative.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Degeneracy {
    /// Some constraints are weakly active (their count); a one-sided derivative is returned.
    WeaklyActive(u32),
    /// The active-set KKT matrix is singular (LICQ or SOSC fails): the derivative with the
    /// smallest-multiplier rows dropped is returned (zeros if that fails too).
    Singular,
}

/// The sensitivity of one solution.
#[derive(Debug, Clone, PartialEq)]
pub struct Sensitivity {
    /// ∂u_0*/∂x_s, row-major nu × nx.
    pub du0_dx: Vec<f64>,
    /// ∂z*/∂x_s for the whole primal vector (n_var × nx), `None` if singular.
    pub dz_dx: Option<DMatrix<f64>>,
    /// Active rows used (strongly active only).
    pub active: Vec<usize>,
    /// Degeneracy, if any.
    pub degeneracy: Option<Degeneracy>,
}

/// Computes the sensitivity at a converged point `p` of `solver`'s problem for state `xs`;
/// `p` is the result of the solver's last solve (nonlinear rows are linearised there).
/// `tol` is the degeneracy tolerance (`solver.degeneracy_tol`).
pub fn sensitivity(solver: &SqpSolver, xs: &[f64], p: &PrimalDual, tol: f64) -> Sensitivity {
    let ocp = &solver.ocp;
    let (nx, nu) = (ocp.nx, ocp.nu);
    let nu_scale = p.nu.iter().fold(1.0f64, |m, v| m.max(v.abs()));
    let mut active = Vec::new();
    let mut weak = 0u32;
    for (r, row) in ocp.rows.iter().enumerate() {
        let slack = row.slack(&p.z);
        if slack <= tol * (1.0 + row.rhs.abs()) {
            if p.nu[r] > tol * nu_scale {
                active.push(r);
            } else {
                weak += 1;
            }
        }
    }
    let (nv, ne) = (ocp.n_var, ocp.n_eq);
    let mut sol = None;
    let mut licq_fails = false;
    for _ in 0..=8 {
        let kkt = solver.active_set_kkt(xs, p, active.clone());
        let mut rhs = DMatrix::zeros(nv + ne + active.len(), nx);
        for i in 0..nx {
            rhs[(nv + i, i)] = 1.0;
        }
        sol = kkt.solve_many(&rhs);
        if sol.is_some() || active.is_empty() {
            break;
        }
        // Singular: drop the active row with the smallest multiplier (a row implied by the
        // others when LICQ fails) and retry.
        licq_fails = true;
        let k = (0..active.len())
            .min_by(|&a, &b| p.nu[active[a]].total_cmp(&p.nu[active[b]]))
            .unwrap_or(0);
        active.remove(k);
    }
    let iu = ocp.iu(0);
    match sol {
        Some(s) => {
            let mut du0 = vec![0.0; nu * nx];
            for j in 0..nu {
                for i in 0..nx {
                    du0[j * nx + i] = s[(iu + j, i)];
                }
            }
            Sensitivity {
                du0_dx: du0,
                dz_dx: Some(s.rows(0, nv).into_owned()),
                active,
                degeneracy: if licq_fails {
                    Some(Degeneracy::Singular)
                } else {
                    (weak > 0).then_some(Degeneracy::WeaklyActive(weak))
                },
            }
        }
        None => Sensitivity {
            du0_dx: vec![0.0; nu * nx],
            dz_dx: None,
            active,
            degeneracy: Some(Degeneracy::Singular),
        },
    }
}
