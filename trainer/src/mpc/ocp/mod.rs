//! The optimal control problem OCP(x_s) transcribed by multiple shooting into an NLP.
//!
//! ```text
//! min_z  Σ_{k<N} (x_k − x_r)ᵀQ(x_k − x_r) + (u_k − u_r)ᵀR(u_k − u_r) + (x_N − x_r)ᵀP(x_N − x_r)
//!                                                      [+ Σ l1·s + l2·s²  (soft)]
//! s.t.   x_0 − x_s = 0                                 (parameter, an equality: LICQ-safe)
//!        F(x_k, u_k) − x_{k+1} = 0,      k = 0..N−1     (RK4 dynamics)
//!        x_lo,k ≤ x_k ≤ x_hi,k,          k = 1..N       (hard, or x_lo,k − s ≤ x_k ≤ x_hi,k + s, s ≥ 0)
//!        u_lo,k ≤ u_k ≤ u_hi,k,          k = 0..N−1
//!        g_i(x_k, u_k) ≤ 0  [− s]         path constraints (`ocp.constraints`), stages by kind
//!        g_i(x_N) ≤ 0  [− s]              terminal constraints (`ocp.terminal_constraints`)
//! ```
//! The setpoint (x_r, u_r) is `ocp.x_ref`, `ocp.u_ref` (default the origin: then the cost is
//! xᵀQx + uᵀRu bit for bit, since v − 0 = v). It enters the objective and its
//! gradient only; the Hessian 2·diag(Q, R), P does not depend on it.
//! The bounds are the constant `ocp.x_lo`… of the problem file, or the stage-dependent
//! `ocp.stages` of a tightened (robust) design ([`crate::problem::OcpSettings::x_bounds`]);
//! every consumer (SQP, QP, sensitivities) sees them only through the rows built here.
//!
//! Variables are ordered by stage, `z = (x_0, u_0, x_1, u_1, …, x_N, s…)`, so stage k's
//! `(x_k, u_k)` is the contiguous block at `k·(nx+nu)`; the slacks of the soft problem
//! follow. Equalities `c(z) = 0` are numbered `c_0` (initial state) then `c_{k+1}` (the
//! dynamics from stage k). All inequalities are rows `aᵀz ≤ h` ([`LinRow`], in `rows.rs`):
//! the boxes and affine constraints with constant coefficients, a nonlinear constraint
//! `g(x_k, u_k) ≤ 0` as its linearisation at the current iterate z̄,
//! `∇g(z̄)ᵀz ≤ ∇g(z̄)ᵀz̄ − g(z̄)`, refreshed by [`Ocp::relinearize`] whenever z moves (so a
//! row's slack `h − aᵀz̄` is always −g(z̄)). The Lagrangian is `L = f + λᵀc + νᵀ(Gz − h)`,
//! ν ≥ 0, and its Hessian includes `Σ ν_r ∇²g_r` ([`Ocp::hessian_blocks`]).

mod barrier;
mod rows;

pub use barrier::InputBarrier;
pub use rows::{LinRow, MAX_ROW};

use crate::problem::model::expr::ConstraintSet;
use crate::problem::model::Discrete;
use crate::problem::ProblemConfig;
use nalgebra::DMatrix;
use rows::NlRow;

/// Exact-penalty weights of the soft problem.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SoftPenalty {
    /// ℓ₁ weight.
    pub l1: f64,
    /// ℓ₂ weight.
    pub l2: f64,
}

/// The transcribed OCP: layout, data and evaluation routines.
#[derive(Debug, Clone)]
pub struct Ocp {
    /// Discrete dynamics F.
    pub model: Discrete,
    /// Horizon N.
    pub horizon: usize,
    /// State dimension.
    pub nx: usize,
    /// Input dimension.
    pub nu: usize,
    q: DMatrix<f64>,
    r: DMatrix<f64>,
    p: DMatrix<f64>,
    /// Setpoint state x_ref of the costs (the origin unless `ocp.x_ref` is given).
    pub x_ref: Vec<f64>,
    /// Setpoint input u_ref of the stage cost (0 unless `ocp.u_ref` is given).
    pub u_ref: Vec<f64>,
    /// Soft-constraint penalty, if this is the soft problem.
    pub soft: Option<SoftPenalty>,
    /// Number of variables (states, inputs, slacks).
    pub n_var: usize,
    /// Number of slacks (0 for the hard problem).
    pub n_slack: usize,
    /// Number of equality constraints, (N+1)·nx.
    pub n_eq: usize,
    /// Inequality rows `Gz ≤ h` (nonlinear ones linearised at the last
    /// [`relinearize`](Ocp::relinearize) point).
    pub rows: Vec<LinRow>,
    /// The compiled path and terminal constraints, if any.
    constraints: Option<ConstraintSet>,
    /// The rows of nonlinear constraints, by stage.
    nl_rows: Vec<NlRow>,
    /// The rows of all `[ocp]` constraints.
    constraint_rows: Vec<usize>,
    /// The log barrier of the input bounds added to the objective (`barrier` module), `None`
    /// for the true OCP.
    pub barrier: Option<InputBarrier>,
}

impl Ocp {
    /// Transcribes a validated problem; `soft` selects the exact-penalty variant. The OCP is
    /// [`ProblemConfig::mpc_problem`]: with `ocp.online_check`, its terminal set, terminal cost
    /// and tightened state bounds are part of it.
    pub fn new(cfg: &ProblemConfig, soft: bool) -> Self {
        let cfg = cfg.mpc_problem();
        let cfg = cfg.as_ref();
        let model = Discrete::new(cfg.system.clone(), cfg.ocp.ts, cfg.ocp.rk4_substeps);
        let (nx, nu, n) = (model.nx(), model.nu(), cfg.ocp.horizon);
        let nw = n * (nx + nu) + nx;
        let constraints = cfg.constraint_set().ok().flatten();
        let rows::Built {
            rows,
            nl: nl_rows,
            constraint_rows,
            n_slack,
        } = rows::build(cfg, constraints.as_ref(), nx, nu, nw, soft);
        Ocp {
            model,
            horizon: n,
            nx,
            nu,
            q: cfg.q(),
            r: cfg.r(),
            p: cfg.p(),
            x_ref: cfg.ocp.x_ref_or_origin(nx),
            u_ref: cfg.ocp.u_ref_or_zero(nu),
            soft: soft.then_some(SoftPenalty {
                l1: cfg.solver.soft_l1,
                l2: cfg.solver.soft_l2,
            }),
            n_var: nw + n_slack,
            n_slack,
            n_eq: (n + 1) * nx,
            rows,
            constraints,
            nl_rows,
            constraint_rows,
            barrier: None,
        }
    }

    /// Index of x_k in z.
    pub fn ix(&self, k: usize) -> usize {
        k * (self.nx + self.nu)
    }
    /// Index of u_k in z.
    pub fn iu(&self, k: usize) -> usize {
        k * (self.nx + self.nu) + self.nx
    }
    /// Index of the first slack.
    pub fn is(&self) -> usize {
        self.n_var - self.n_slack
    }

    /// Objective f(z) (with the k = 0 state term, which is constant in the OCP but part of
    /// the reported cost).
    pub fn objective(&self, z: &[f64]) -> f64 {
        // (v − c)ᵀM(v − c); with c = 0 exactly vᵀMv.
        let quad = |m: &DMatrix<f64>, v: &[f64], c: &[f64]| -> f64 {
            let n = v.len();
            (0..n)
                .map(|i| {
                    (0..n)
                        .map(|j| (v[i] - c[i]) * m[(i, j)] * (v[j] - c[j]))
                        .sum::<f64>()
                })
                .sum()
        };
        let (nx, nu) = (self.nx, self.nu);
        let (xr, ur) = (&self.x_ref[..], &self.u_ref[..]);
        let mut f = 0.0;
        for k in 0..self.horizon {
            f += quad(&self.q, &z[self.ix(k)..self.ix(k) + nx], xr);
            f += quad(&self.r, &z[self.iu(k)..self.iu(k) + nu], ur);
        }
        let xn = self.ix(self.horizon);
        f += quad(&self.p, &z[xn..xn + nx], xr);
        if let Some(sp) = self.soft {
            for &s in &z[self.is()..] {
                f += sp.l1 * s + sp.l2 * s * s;
            }
        }
        if let Some(b) = &self.barrier {
            for k in 0..self.horizon {
                f += b.value(&z[self.iu(k)..self.iu(k) + nu]);
            }
        }
        f
    }

    /// Gradient ∇f(z) into `g`.
    pub fn gradient(&self, z: &[f64], g: &mut [f64]) {
        let (nx, nu) = (self.nx, self.nu);
        g.fill(0.0);
        // ∇ (v − c)ᵀM(v − c) = 2M(v − c) for symmetric M.
        let add = |m: &DMatrix<f64>, off: usize, c: &[f64], g: &mut [f64]| {
            let n = c.len();
            for i in 0..n {
                g[off + i] = 2.0 * (0..n).map(|j| m[(i, j)] * (z[off + j] - c[j])).sum::<f64>();
            }
        };
        let (xr, ur) = (&self.x_ref[..], &self.u_ref[..]);
        debug_assert_eq!((xr.len(), ur.len()), (nx, nu));
        for k in 0..self.horizon {
            add(&self.q, self.ix(k), xr, g);
            add(&self.r, self.iu(k), ur, g);
        }
        add(&self.p, self.ix(self.horizon), xr, g);
        if let Some(sp) = self.soft {
            for i in self.is()..self.n_var {
                g[i] = sp.l1 + 2.0 * sp.l2 * z[i];
            }
        }
        if let Some(b) = &self.barrier {
            for k in 0..self.horizon {
                let iu = self.iu(k);
                b.add_gradient(&z[iu..iu + nu], &mut g[iu..iu + nu]);
            }
        }
    }

    /// Equality constraints c(z; x_s) into `c`, and the dynamics Jacobians:
    /// `jac_x[k]` = ∂F/∂x (row-major nx×nx) and `jac_u[k]` = ∂F/∂u at stage k.
    pub fn constraints(
        &self,
        z: &[f64],
        xs: &[f64],
        c: &mut [f64],
        jac_x: &mut [f64],
        jac_u: &mut [f64],
    ) {
        let (nx, nu) = (self.nx, self.nu);
        for i in 0..nx {
            c[i] = z[i] - xs[i];
        }
        let mut f = [0.0; crate::problem::model::MAX_NX];
        for k in 0..self.horizon {
            let (xk, uk) = (
                &z[self.ix(k)..self.ix(k) + nx],
                &z[self.iu(k)..self.iu(k) + nu],
            );
            self.model.linearize_at(
                k,
                xk,
                uk,
                &mut f[..nx],
                &mut jac_x[k * nx * nx..(k + 1) * nx * nx],
                &mut jac_u[k * nx * nu..(k + 1) * nx * nu],
            );
            let xn = self.ix(k + 1);
            for i in 0..nx {
                c[(k + 1) * nx + i] = f[i] - z[xn + i];
            }
        }
    }

    /// Equality constraints only (no Jacobians), for line searches.
    pub fn constraint_values(&self, z: &[f64], xs: &[f64], c: &mut [f64]) {
        let (nx, nu) = (self.nx, self.nu);
        for i in 0..nx {
            c[i] = z[i] - xs[i];
        }
        let mut f = [0.0; crate::problem::model::MAX_NX];
        for k in 0..self.horizon {
            self.model.step(
                &z[self.ix(k)..self.ix(k) + nx],
                &z[self.iu(k)..self.iu(k) + nu],
                &mut f[..nx],
            );
            for i in 0..nx {
                c[(k + 1) * nx + i] = f[i] - z[self.ix(k + 1) + i];
            }
        }
    }

    /// Hessian of the Lagrangian, as stage blocks: `blocks[k]` (k < N) is the row-major
    /// (nx+nu)² block of stage k, `blocks[N]` the nx² terminal block (stored in a
    /// (nx+nu)² slot). Slack curvature (2·l2) is diagonal and not stored here. `mult` are the
    /// inequality multipliers ν (one per row) for the curvature `Σ ν_r ∇²g_r` of nonlinear
    /// constraints; an empty `mult` means ν = 0 (the objective and dynamics part only).
    pub fn hessian_blocks(&self, z: &[f64], lam: &[f64], mult: &[f64], blocks: &mut [f64]) {
        let (nx, nu) = (self.nx, self.nu);
        let nz = nx + nu;
        let bs = nz * nz;
        for k in 0..self.horizon {
            let blk = &mut blocks[k * bs..(k + 1) * bs];
            self.model.lagrangian_hessian_at(
                k,
                &z[self.ix(k)..self.ix(k) + nx],
                &z[self.iu(k)..self.iu(k) + nu],
                &lam[(k + 1) * nx..(k + 2) * nx],
                blk,
            );
            for i in 0..nx {
                for j in 0..nx {
                    blk[i * nz + j] += 2.0 * self.q[(i, j)];
                }
            }
            for i in 0..nu {
                for j in 0..nu {
                    blk[(nx + i) * nz + nx + j] += 2.0 * self.r[(i, j)];
                }
            }
            if let Some(b) = &self.barrier {
                let u = &z[self.iu(k)..self.iu(k) + nu];
                for i in 0..nu {
                    blk[(nx + i) * nz + nx + i] += b.curvature(u, i);
                }
            }
        }
        let blk = &mut blocks[self.horizon * bs..(self.horizon + 1) * bs];
        blk.fill(0.0);
        for i in 0..nx {
            for j in 0..nx {
                blk[i * nz + j] = 2.0 * self.p[(i, j)];
            }
        }
        if !mult.is_empty() {
            self.add_constraint_curvature(z, mult, blocks);
        }
    }

    /// Diagonal curvature of each slack (2·l2), 0 for the hard problem.
    pub fn slack_curvature(&self) -> f64 {
        self.soft.map_or(0.0, |s| 2.0 * s.l2)
    }

    /// A primal initial guess for a cold start: hold the inputs at the projection of u_ref
    /// (0 by default) onto U and simulate from x_s (multiple shooting tolerates the resulting state-bound
    /// violations in the soft problem; the hard problem's states are projected onto the
    /// bounds, which the QP's linearisation then repairs).
    pub fn initial_guess(
        &self,
        cfg_lo: &[f64],
        cfg_hi: &[f64],
        u_lo: &[f64],
        u_hi: &[f64],
        xs: &[f64],
    ) -> Vec<f64> {
        let (nx, nu) = (self.nx, self.nu);
        let mut z = vec![0.0; self.n_var];
        z[..nx].copy_from_slice(xs);
        let mut x = [0.0; crate::problem::model::MAX_NX];
        x[..nx].copy_from_slice(xs);
        let mut xn = [0.0; crate::problem::model::MAX_NX];
        for k in 0..self.horizon {
            let iu = self.iu(k);
            for j in 0..nu {
                z[iu + j] = self.u_ref[j].clamp(u_lo[j], u_hi[j]);
            }
            self.model.step(&x[..nx], &z[iu..iu + nu], &mut xn[..nx]);
            let ix = self.ix(k + 1);
            for i in 0..nx {
                let v = if xn[i].is_finite() { xn[i] } else { x[i] };
                x[i] = v.clamp(cfg_lo[i], cfg_hi[i]);
                z[ix + i] = x[i];
            }
        }
        z
    }
}
