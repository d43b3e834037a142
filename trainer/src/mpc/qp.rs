//! The SQP's quadratic subproblem, its fast structure-exploiting solver ([`ipm`]) and its
//! reference solver (clarabel).
//!
//! At an iterate z with multipliers λ the subproblem in the step d is
//! ```text
//! min_d ½ dᵀ H d + ∇f(z)ᵀ d
//! s.t.  c(z) + ∇c(z)ᵀ d = 0         (zero cone; multipliers λ⁺)
//!       G d ≤ h − G z                (nonnegative cone; multipliers ν⁺ ≥ 0)
//! ```
//! with H the stage-block Hessian of the Lagrangian made positive definite block by block.
//! The clarabel solver object is built once per OCP structure and only its numerical data
//! (P, q, A, b) is updated between SQP iterations; the sparsity pattern is fixed
//! (dense stage blocks, banded dynamics rows), so no re-analysis is needed.
//!
//! [`QpSolver`] dispatches on [`QpSolverKind`] (`solver.qp` of the problem file): the
//! structured interior-point method, falling back to clarabel for a QP it cannot solve
//! (e.g. an infeasible linearisation, which clarabel certifies), or clarabel alone.

/// Calls `$self.$method::<NX>(…)` with the state dimension `$nx` as the constant `NX` for
/// every `nx < 16` (`MAX_NZ`; the kernels' loops then have fixed trip counts: unrolled, no loop
/// overhead; the same operations in the same order, so the same bits), `NX = 0` (runtime
/// size) otherwise.
macro_rules! by_nx {
    ($nx:expr, $self:ident . $method:ident $args:tt) => {
        by_nx!(@ $nx, $self.$method $args, 1 2 3 4 5 6 7 8 9 10 11 12 13 14 15)
    };
    (@ $nx:expr, $self:ident . $method:ident $args:tt, $($n:literal)*) => {
        match $nx {
            $($n => $self.$method::<$n> $args,)*
            _ => $self.$method::<0> $args,
        }
    };
}

pub(crate) use by_nx;

pub(crate) mod ipm;
pub mod riccati;
mod slacks;

use crate::mpc::ocp::Ocp;
pub use crate::problem::QpSolverKind;
use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultSettings, DefaultSolver, IPSolver, SolverStatus, SupportedConeT};

/// The data of one QP subproblem at an SQP iterate (all borrowed from the SQP's workspace).
#[derive(Debug, Clone, Copy)]
pub struct QpData<'a> {
    /// The iterate z.
    pub z: &'a [f64],
    /// Convexified Hessian stage blocks ([`Ocp::hessian_blocks`] layout).
    pub hess: &'a [f64],
    /// ∇f(z).
    pub grad: &'a [f64],
    /// c(z).
    pub c: &'a [f64],
    /// ∂F/∂x per stage.
    pub jac_x: &'a [f64],
    /// ∂F/∂u per stage.
    pub jac_u: &'a [f64],
    /// The accuracy (relative residuals and gap) at which the structured solver stops,
    /// at least its own `1e-10` ([`ipm::TOL`]); the SQP asks for less while it is far from
    /// a solution. Clarabel ignores it (always `1e-10`-class).
    pub tol: f64,
}

/// Outcome of one QP solve.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum QpStatus {
    /// Solved (full or reduced accuracy).
    Solved,
    /// The linearised constraints have no solution.
    Infeasible,
    /// Iteration limit, numerical error or lack of progress.
    Failed,
}

/// The SQP's QP solver: the chosen backend, workspaces allocated once per OCP structure.
pub struct QpSolver {
    kind: QpSolverKind,
    ipm: Option<ipm::IpmQp>,
    clarabel: Option<ClarabelQp>,
    /// Interior-point iterations of the last solve (both backends, if it fell back).
    pub last_iterations: u32,
    /// How many QPs the structured solver handed to clarabel.
    pub fallbacks: usize,
}

impl QpSolver {
    /// Workspace for `ocp` with backend `kind` (clarabel's is built on first use).
    pub fn new(ocp: &Ocp, kind: QpSolverKind) -> Self {
        QpSolver {
            kind,
            ipm: (kind == QpSolverKind::Structured).then(|| ipm::IpmQp::new(ocp)),
            clarabel: None,
            last_iterations: 0,
            fallbacks: 0,
        }
    }

    /// The structured solver factorises by the band LU only (tests).
    #[cfg(test)]
    pub(crate) fn without_riccati(&mut self) {
        if let Some(i) = self.ipm.as_mut() {
            i.without_riccati();
        }
    }

    /// Forgets clarabel's solver object (see [`ClarabelQp::reset`]); the structured solver
    /// keeps no state between solves.
    pub fn reset(&mut self) {
        if let Some(c) = self.clarabel.as_mut() {
            c.reset();
        }
    }

    /// The backend.
    pub fn kind(&self) -> QpSolverKind {
        self.kind
    }

    /// Solves the subproblem; arguments and outputs as [`ClarabelQp::solve`].
    pub fn solve(
        &mut self,
        ocp: &Ocp,
        data: &QpData,
        d: &mut [f64],
        lam: &mut [f64],
        nu: &mut [f64],
    ) -> QpStatus {
        self.last_iterations = 0;
        if let Some(ipm) = self.ipm.as_mut() {
            let st = ipm.solve(ocp, data, d, lam, nu);
            self.last_iterations = ipm.last_iterations;
            if st == QpStatus::Solved {
                return st;
            }
            self.fallbacks += 1;
        }
        let cl = self.clarabel.get_or_insert_with(|| ClarabelQp::new(ocp));
        let st = cl.solve(ocp, data, d, lam, nu);
        self.last_iterations += cl.last_iterations;
        st
    }
}

/// Reusable clarabel QP workspace for one OCP structure.
pub struct ClarabelQp {
    solver: Option<DefaultSolver<f64>>,
    p_colptr: Vec<usize>,
    p_rowval: Vec<usize>,
    a_colptr: Vec<usize>,
    a_rowval: Vec<usize>,
    /// For each variable, the inequality rows it is in (index into `ocp.rows`, entry of the
    /// row): coefficients are read at each solve (nonlinear rows change).
    col_rows: Vec<Vec<(usize, usize)>>,
    p_val: Vec<f64>,
    a_val: Vec<f64>,
    b: Vec<f64>,
    /// Interior-point iterations of the last solve.
    pub last_iterations: u32,
}

impl ClarabelQp {
    /// Builds the fixed sparsity patterns of P and A for this OCP.
    pub fn new(ocp: &Ocp) -> Self {
        let (nx, nu, n) = (ocp.nx, ocp.nu, ocp.horizon);
        let nz = nx + nu;
        let mut col_rows = vec![Vec::new(); ocp.n_var];
        for (r, row) in ocp.rows.iter().enumerate() {
            for j in 0..row.len {
                col_rows[row.idx[j]].push((r, j));
            }
        }
        // P: upper triangle of each stage block, then the slack diagonal.
        let (mut p_colptr, mut p_rowval) = (vec![0], Vec::new());
        for col in 0..ocp.n_var {
            if col < ocp.is() {
                let k = col / nz;
                let start = k * nz;
                for row in start..=col {
                    p_rowval.push(row);
                }
            } else {
                p_rowval.push(col);
            }
            p_colptr.push(p_rowval.len());
        }
        // A: equality rows (0..n_eq) then inequality rows (n_eq..).
        let (mut a_colptr, mut a_rowval) = (vec![0], Vec::new());
        for col in 0..ocp.n_var {
            if col < ocp.is() {
                let k = col / nz;
                let local = col % nz;
                if local < nx {
                    // x_k: in c_k (identity or −identity) and in c_{k+1}'s A_k column.
                    a_rowval.push(k * nx + local);
                    if k < n {
                        for r in 0..nx {
                            a_rowval.push((k + 1) * nx + r);
                        }
                    }
                } else {
                    for r in 0..nx {
                        a_rowval.push((k + 1) * nx + r);
                    }
                }
            }
            for &(r, _) in &col_rows[col] {
                a_rowval.push(ocp.n_eq + r);
            }
            a_colptr.push(a_rowval.len());
        }
        let p_nnz = p_rowval.len();
        let a_nnz = a_rowval.len();
        ClarabelQp {
            solver: None,
            p_colptr,
            p_rowval,
            a_colptr,
            a_rowval,
            col_rows,
            p_val: vec![0.0; p_nnz],
            a_val: vec![0.0; a_nnz],
            b: vec![0.0; ocp.n_eq + ocp.rows.len()],
            last_iterations: 0,
        }
    }

    /// Forgets the clarabel solver object, so that the next solve sets it up afresh.
    ///
    /// clarabel keeps the equilibration scaling of the first problem it was built with and
    /// reuses it after data updates; a solve's result would then depend on which problem
    /// the workspace saw first. Resetting at the start of every SQP run makes each run a
    /// function of its inputs only (whatever the thread schedule); within a run the solver
    /// is reused.
    pub fn reset(&mut self) {
        self.solver = None;
    }

    fn settings() -> DefaultSettings<f64> {
        DefaultSettings {
            verbose: false,
            presolve_enable: false,
            input_sparse_dropzeros: false,
            tol_gap_abs: 1e-10,
            tol_gap_rel: 1e-10,
            tol_feas: 1e-10,
            max_iter: 100,
            ..DefaultSettings::default()
        }
    }

    /// Solves the subproblem. `hess` are the (already convexified) stage blocks as produced
    /// by [`Ocp::hessian_blocks`]; `jac_x`, `jac_u` the dynamics Jacobians; `c` the
    /// equality values at z. On success writes the step `d`, the equality multipliers
    /// `lam` (length n_eq) and the inequality multipliers `nu` (length rows).
    pub fn solve(
        &mut self,
        ocp: &Ocp,
        data: &QpData,
        d: &mut [f64],
        lam: &mut [f64],
        nu: &mut [f64],
    ) -> QpStatus {
        let QpData {
            z,
            hess,
            grad,
            c,
            jac_x,
            jac_u,
            tol: _,
        } = *data;
        let (nx, nu_dim, n) = (ocp.nx, ocp.nu, ocp.horizon);
        let nz = nx + nu_dim;
        // P values in CSC order.
        let mut p = 0;
        for col in 0..ocp.n_var {
            if col < ocp.is() {
                let k = col / nz;
                let start = k * nz;
                let cl = col - start;
                let blk = &hess[k * nz * nz..(k + 1) * nz * nz];
                for rl in 0..=cl {
                    self.p_val[p] = blk[rl * nz + cl];
                    p += 1;
                }
            } else {
                self.p_val[p] = ocp.slack_curvature();
                p += 1;
            }
        }
        // A values in CSC order.
        let mut a = 0;
        for col in 0..ocp.n_var {
            if col < ocp.is() {
                let k = col / nz;
                let local = col % nz;
                if local < nx {
                    self.a_val[a] = if k == 0 { 1.0 } else { -1.0 };
                    a += 1;
                    if k < n {
                        for r in 0..nx {
                            self.a_val[a] = jac_x[k * nx * nx + r * nx + local];
                            a += 1;
                        }
                    }
                } else {
                    let j = local - nx;
                    for r in 0..nx {
                        self.a_val[a] = jac_u[k * nx * nu_dim + r * nu_dim + j];
                        a += 1;
                    }
                }
            }
            for &(r, j) in &self.col_rows[col] {
                self.a_val[a] = ocp.rows[r].coef[j];
                a += 1;
            }
        }
        for i in 0..ocp.n_eq {
            self.b[i] = -c[i];
        }
        for (r, row) in ocp.rows.iter().enumerate() {
            self.b[ocp.n_eq + r] = row.slack(z);
        }
        let updated = match self.solver.as_mut() {
            Some(s) => s
                .update_P(&self.p_val)
                .and_then(|_| s.update_A(&self.a_val))
                .and_then(|_| s.update_q(&grad.to_vec()))
                .and_then(|_| s.update_b(&self.b))
                .is_ok(),
            None => false,
        };
        if !updated {
            let pm = CscMatrix::new(
                ocp.n_var,
                ocp.n_var,
                self.p_colptr.clone(),
                self.p_rowval.clone(),
                self.p_val.clone(),
            );
            let am = CscMatrix::new(
                ocp.n_eq + ocp.rows.len(),
                ocp.n_var,
                self.a_colptr.clone(),
                self.a_rowval.clone(),
                self.a_val.clone(),
            );
            let cones = [
                SupportedConeT::ZeroConeT(ocp.n_eq),
                SupportedConeT::NonnegativeConeT(ocp.rows.len()),
            ];
            match DefaultSolver::new(&pm, grad, &am, &self.b, &cones, Self::settings()) {
                Ok(s) => self.solver = Some(s),
                Err(_) => return QpStatus::Failed,
            }
        }
        let Some(solver) = self.solver.as_mut() else {
            return QpStatus::Failed;
        };
        solver.solve();
        let sol = &solver.solution;
        self.last_iterations = sol.iterations;
        match sol.status {
            SolverStatus::Solved | SolverStatus::AlmostSolved => {
                d.copy_from_slice(&sol.x);
                lam.copy_from_slice(&sol.z[..ocp.n_eq]);
                nu.copy_from_slice(&sol.z[ocp.n_eq..]);
                QpStatus::Solved
            }
            SolverStatus::PrimalInfeasible | SolverStatus::AlmostPrimalInfeasible => {
                QpStatus::Infeasible
            }
            _ => QpStatus::Failed,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mpc::law::MpcLaw;
    use crate::problem::ProblemConfig;
    use crate::rng::uniform;

    fn load(name: &str) -> ProblemConfig {
        let path = std::path::PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/"))
            .join(name);
        ProblemConfig::load(&path).unwrap()
    }

    /// The structured interior point and clarabel give the same labels (status, u₀*, cost,
    /// ∂u₀*/∂x) on random states of all three problems, including the pendulum's
    /// infeasible corners (soft labels) and the cart-pole's long solves.
    #[test]
    fn structured_and_clarabel_qp_give_the_same_sqp_solutions() {
        for (name, n) in [
            ("pendulum.toml", 60u64),
            ("cartpole.toml", 30),
            ("double_integrator.toml", 40),
        ] {
            let mut cfg = load(name);
            cfg.solver.qp = QpSolverKind::Structured;
            let mut fast = MpcLaw::new(&cfg);
            cfg.solver.qp = QpSolverKind::Clarabel;
            let mut reference = MpcLaw::new(&cfg);
            let mut agree = 0;
            for i in 0..n {
                let xs: Vec<f64> = (0..cfg.system.nx())
                    .map(|j| {
                        let (lo, hi) = (cfg.domain.lo[j], cfg.domain.hi[j]);
                        lo + (hi - lo) * uniform(11, i, j as u64)
                    })
                    .collect();
                let (a, _) = fast.solve(&xs, None);
                let (b, _) = reference.solve(&xs, None);
                assert_eq!(a.status, b.status, "{name} {xs:?}");
                if !a.status.is_labelled() {
                    continue;
                }
                let close = |x: f64, y: f64, tol: f64| (x - y).abs() <= tol * (1.0 + y.abs());
                assert!(
                    close(a.cost, b.cost, 1e-7),
                    "{name} {xs:?}: cost {} vs {}",
                    a.cost,
                    b.cost
                );
                for (x, y) in a.u.iter().zip(&b.u) {
                    assert!(close(*x, *y, 1e-6), "{name} {xs:?}: u {x} vs {y}");
                }
                assert_eq!(a.degeneracy, b.degeneracy, "{name} {xs:?}");
                for (x, y) in a.du_dx.iter().zip(&b.du_dx) {
                    assert!(close(*x, *y, 1e-5), "{name} {xs:?}: du/dx {x} vs {y}");
                }
                agree += 1;
            }
            assert!(agree as u64 >= n / 2, "{name}: only {agree} labelled");
        }
    }

    /// The soft problem's QPs of hard-infeasible stress-file states (curved constraints,
    /// slack weights ~1e4) are solved by the structured interior point without clarabel,
    /// and the SQP reaches clarabel's solution. Before the residuals counted as progress
    /// (`ipm`, stall test), 45, 2 and 2 of these soft solves' QPs stalled after 5–8
    /// iterations — their primal residual falling while μ rose from an off-centre start —
    /// and went to clarabel.
    #[test]
    fn soft_stress_qps_are_solved_without_clarabel() {
        soft_solves_without_clarabel(&[
            [
                -0.39778782066805407,
                -1.2542083494672087,
                -0.09624336122738181,
                -0.5302274608852291,
            ],
            [
                -1.0299626425385253,
                -1.4028416297387776,
                0.10556006450513908,
                -0.8243394793082861,
            ],
            [
                1.2159811130448137,
                -1.0730791213057325,
                0.08668678254922627,
                -0.5369451329466639,
            ],
        ]);
    }

    /// As above, for states where 5 QPs each of the soft solve went to clarabel before the
    /// interior point kept its most accurate iterate within `1e-7`: their residuals reach
    /// ~1e-8, then grow as the band LU's pivots fall to ~1e-20 of its largest (μ → 0).
    #[test]
    fn soft_stress_qps_keep_their_most_accurate_iterate() {
        soft_solves_without_clarabel(&[
            [
                0.5805364170306877,
                0.9336647474584518,
                -0.01805341768820007,
                0.5912517191470479,
            ],
            [
                0.9970828503805875,
                1.2687550871126718,
                0.0575560290918912,
                -0.6281335072301921,
            ],
        ]);
    }

    /// State 86 of the IPOPT script (seed 7) on cartpole_public_nl: a soft label (the base's
    /// 347075.14028180), which the structured QP's iterates lost to the iteration limit
    /// until the soft problem tried the polish after a full step where the exact Hessian
    /// fails the convexity test (`sqp`, step 4): the blockwise-convexified steps near its
    /// optimum crawl without a full step.
    #[test]
    fn soft_state_86_is_labelled() {
        use crate::mpc::sqp::SqpStatus;
        let path = std::path::PathBuf::from(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../tests/reference/cartpole_public_nl.toml"
        ));
        let mut cfg = ProblemConfig::load(&path).unwrap();
        cfg.solver.qp = QpSolverKind::Structured;
        let x = [
            -1.3296769128212498,
            1.486084978286991,
            0.1166097920124998,
            0.8326478699468061,
        ];
        let (l, _) = MpcLaw::new(&cfg).solve(&x, None);
        assert_eq!(l.status, SqpStatus::Soft);
        assert!(l.cost <= 347075.1402818004 * (1.0 + 1e-9), "{}", l.cost);
    }

    /// The soft problem of cartpole_public_nl from each state: solved with the structured
    /// QP solver without a clarabel fallback, to clarabel's solution (1e-6 relative).
    fn soft_solves_without_clarabel(states: &[[f64; 4]]) {
        use crate::mpc::sqp::{SqpSolver, SqpStatus};
        let path = std::path::PathBuf::from(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../tests/reference/cartpole_public_nl.toml"
        ));
        let mut cfg = ProblemConfig::load(&path).unwrap();
        for x in states {
            cfg.solver.qp = QpSolverKind::Structured;
            let mut fast = SqpSolver::new(&cfg, true);
            let a = fast.solve(x, fast.cold_start(x));
            cfg.solver.qp = QpSolverKind::Clarabel;
            let mut reference = SqpSolver::new(&cfg, true);
            let b = reference.solve(x, reference.cold_start(x));
            assert_eq!(a.status, SqpStatus::Converged, "{x:?}");
            assert_eq!(b.status, SqpStatus::Converged, "{x:?}");
            assert_eq!(fast.qp_fallbacks(), 0, "{x:?}");
            for (p, q) in a.point.z.iter().zip(&b.point.z) {
                assert!((p - q).abs() <= 1e-6 * (1.0 + q.abs()), "{x:?}: {p} vs {q}");
            }
        }
    }
}
