//! The KKT system of the OCP on a fixed active set, assembled densely and LU-factorised.
//!
//! With the active inequality rows `G_A z = h_A` treated as equalities, the Newton matrix of
//! the KKT conditions is
//! ```text
//!     ⎡ ∇²L   ∇cᵀ   G_Aᵀ ⎤
//! K = ⎢ ∇c     0     0   ⎥      unknowns (Δz, λ, ν_A)
//!     ⎣ G_A    0     0   ⎦
//! ```
//! It serves twice: the SQP's final Newton polish (quadratic convergence once the active set
//! is known) and the parametric sensitivity (`sensitivity` module), which solves
//! `K · ∂(z, λ, ν_A)/∂x_s = (0, E, 0)` with E the identity on the rows of `c_0 = x_0 − x_s`.
//! K is nonsingular exactly when LICQ and the second-order sufficient condition hold on the
//! active set; a tiny LU pivot flags that failure.

use crate::ocp::Ocp;
use nalgebra::{DMatrix, DVector};

/// An LU-factorised active-set KKT matrix.
pub struct ActiveSetKkt {
    lu: nalgebra::LU<f64, nalgebra::Dyn, nalgebra::Dyn>,
    /// Active inequality rows (indices into `ocp.rows`), in the order of ν_A.
    pub active: Vec<usize>,
    /// Smallest over largest |U_ii| of the LU factor: ≈ 0 means singular (LICQ/SOSC fail).
    pub pivot_ratio: f64,
}

impl ActiveSetKkt {
    /// Assembles and factorises K from the exact Hessian blocks, the dynamics Jacobians and
    /// the active rows.
    pub fn new(ocp: &Ocp, hess: &[f64], jac_x: &[f64], jac_u: &[f64], active: Vec<usize>) -> Self {
        let (nx, nu, n) = (ocp.nx, ocp.nu, ocp.horizon);
        let nz = nx + nu;
        let dim = ocp.n_var + ocp.n_eq + active.len();
        let mut k = DMatrix::<f64>::zeros(dim, dim);
        // Hessian blocks.
        for s in 0..=n {
            let off = s * nz;
            let size = if s < n { nz } else { nx };
            let blk = &hess[s * nz * nz..(s + 1) * nz * nz];
            for i in 0..size {
                for j in 0..size {
                    k[(off + i, off + j)] = blk[i * nz + j];
                }
            }
        }
        for i in ocp.is()..ocp.n_var {
            k[(i, i)] = ocp.slack_curvature();
        }
        // Equality Jacobian rows (and their transposes).
        let e0 = ocp.n_var;
        let put = |r: usize, c: usize, v: f64, k: &mut DMatrix<f64>| {
            k[(r, c)] = v;
            k[(c, r)] = v;
        };
        for i in 0..nx {
            put(e0 + i, i, 1.0, &mut k);
        }
        for s in 0..n {
            for r in 0..nx {
                let row = e0 + (s + 1) * nx + r;
                for j in 0..nx {
                    put(row, ocp.ix(s) + j, jac_x[s * nx * nx + r * nx + j], &mut k);
                }
                for j in 0..nu {
                    put(row, ocp.iu(s) + j, jac_u[s * nx * nu + r * nu + j], &mut k);
                }
                put(row, ocp.ix(s + 1) + r, -1.0, &mut k);
            }
        }
        let a0 = e0 + ocp.n_eq;
        for (t, &r) in active.iter().enumerate() {
            let row = &ocp.rows[r];
            for j in 0..row.len {
                put(a0 + t, row.idx[j], row.coef[j], &mut k);
            }
        }
        let lu = k.lu();
        let diag = lu.u().diagonal();
        let (mut mn, mut mx) = (f64::INFINITY, 0.0f64);
        for v in diag.iter() {
            mn = mn.min(v.abs());
            mx = mx.max(v.abs());
        }
        let pivot_ratio = if mx > 0.0 && mn.is_finite() {
            mn / mx
        } else {
            0.0
        };
        ActiveSetKkt {
            lu,
            active,
            pivot_ratio,
        }
    }

    /// Whether K is numerically singular (LICQ or second-order sufficiency fails).
    pub fn is_singular(&self) -> bool {
        self.pivot_ratio.is_nan() || self.pivot_ratio <= 1e-14
    }

    /// Solves `K x = rhs`; `None` if K is singular.
    pub fn solve(&self, rhs: &DVector<f64>) -> Option<DVector<f64>> {
        if self.is_singular() {
            return None;
        }
        self.lu
            .solve(rhs)
            .filter(|x| x.iter().all(|v| v.is_finite()))
    }

    /// Solves `K X = RHS` for several right-hand sides.
    pub fn solve_many(&self, rhs: &DMatrix<f64>) -> Option<DMatrix<f64>> {
        if self.is_singular() {
            return None;
        }
        self.lu
            .solve(rhs)
            .filter(|x| x.iter().all(|v| v.is_finite()))
    }
}
