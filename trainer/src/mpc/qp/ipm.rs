//! A structure-exploiting primal-dual interior-point solver for the SQP's QP subproblem.
//!
//! The subproblem (see the parent module) is
//! ```text
//! min_d ½ dᵀ H d + gᵀ d   s.t.   E d + c = 0   (multipliers λ),   G d ≤ b   (ν ≥ 0)
//! ```
//! with `E = ∇c(z)ᵀ` (the linearised initial-state and dynamics constraints) and `b = h − G z`.
//! With slacks `t = b − G d ≥ 0` the optimality conditions are
//! ```text
//! r_d = H d + g + Eᵀλ + Gᵀν = 0,   r_e = E d + c = 0,   r_i = G d + t − b = 0,
//! t ∘ ν = 0,   t, ν ≥ 0.
//! ```
//! Mehrotra's predictor–corrector method (Nocedal & Wright, Alg. 16.4 / 14.3) follows the
//! central path `t ∘ ν = σμ`, `μ = tᵀν/m`. Each Newton step eliminates
//! `Δt = −r_i − GΔd` and `Δν = (r_c − ν∘Δt)/t` (`r_c` the complementarity target) and solves
//! ```text
//! ⎡ H + Gᵀ W G   Eᵀ ⎤ ⎡Δd⎤   ⎡ −r_d − Gᵀ((r_c + ν∘r_i)/t) ⎤
//! ⎣ E            0  ⎦ ⎣Δλ⎦ = ⎣ −r_e                        ⎦ ,    W = diag(ν/t),
//! ```
//! which has the OCP's stage structure: it is factorised once per iteration and solved twice
//! (predictor, corrector). It is factorised by the Riccati recursion of the [`riccati`]
//! module (O(N(nx + nu)³); the soft problem's slacks eliminated stage by stage first); any
//! QP whose R̃_k is not positive definite by the banded LU of the `kkt` module (O(N·b²), b
//! the half-bandwidth).
//!
//! [`riccati`]: super::riccati
//! Both steps use one step length (a QP's dual residual couples d and ν), 99% of the way to
//! the boundary. The starting point is the solution of the `W = I` system shifted into the
//! interior (as in CVXOPT). Termination: relative residuals and the gap `tᵀν` below `1e-10`
//! (as for the clarabel reference), or below the larger tolerance the SQP asks for far from
//! a solution ([`QpData::tol`]); at the iteration limit, after five iterations in which
//! neither that error, nor the residuals alone, nor μ fell by 10 %, or when the iterates
//! diverge (an infeasible QP), the solve reports failure and the caller may fall back —
//! unless the error is below `1e-7` (clarabel's "almost solved"), at that iterate or at an
//! earlier one, which is then the answer: on the soft problem's QPs the band LU's pivots
//! fall to ~1e-20 of its largest as μ → 0, and the residuals may grow again after reaching
//! ~1e-8.

use super::riccati::RiccatiKkt;
use super::{QpData, QpStatus};
use crate::mpc::kkt::{BandedKkt, KktLayout};
use crate::mpc::ocp::Ocp;

/// Target accuracy (relative residuals and gap) unless the caller asks for less
/// ([`QpData::tol`]).
pub const TOL: f64 = 1e-10;
/// Accepted accuracy if progress stalls before `TOL` (clarabel's "almost solved").
const TOL_REDUCED: f64 = 1e-7;
/// Iteration limit.
const MAX_ITER: u32 = 50;
/// Fraction of the step to the boundary.
const TAU: f64 = 0.99;

/// Reusable workspace of the interior-point QP solver for one OCP structure.
#[derive(Debug, Clone)]
pub struct IpmQp {
    kkt: BandedKkt,
    riccati: Option<RiccatiKkt>,
    /// Whether the current solve factorises by Riccati (else by the band LU).
    use_riccati: bool,
    /// Whether the band LU holds the current QP's base matrix.
    band_ready: bool,
    d: Vec<f64>,
    lam: Vec<f64>,
    nu: Vec<f64>,
    t: Vec<f64>,
    w: Vec<f64>,
    b: Vec<f64>,
    rd: Vec<f64>,
    re: Vec<f64>,
    ri: Vec<f64>,
    rhs: Vec<f64>,
    scratch: Vec<f64>,
    tmp: Vec<f64>,
    dt_aff: Vec<f64>,
    dnu_aff: Vec<f64>,
    dt: Vec<f64>,
    dnu: Vec<f64>,
    /// Interior-point iterations of the last solve.
    pub last_iterations: u32,
}

/// The state dimension: the constant `NX` of a kernel specialised by `by_nx!`, else (0) the
/// OCP's.
#[inline(always)]
fn dim_x<const NX: usize>(ocp: &Ocp) -> usize {
    if NX == 0 {
        ocp.nx
    } else {
        NX
    }
}

/// `out = H x` for the stage-block Hessian plus the slack diagonal.
fn mul_h<const NX: usize>(ocp: &Ocp, hess: &[f64], x: &[f64], out: &mut [f64]) {
    let (nx, nu, n) = (dim_x::<NX>(ocp), ocp.nu, ocp.horizon);
    let nz = nx + nu;
    for s in 0..=n {
        let off = s * nz;
        let size = if s < n { nz } else { nx };
        let blk = &hess[s * nz * nz..(s + 1) * nz * nz];
        for i in 0..size {
            let mut acc = 0.0;
            for j in 0..size {
                acc += blk[i * nz + j] * x[off + j];
            }
            out[off + i] = acc;
        }
    }
    let sc = ocp.slack_curvature();
    for i in ocp.is()..ocp.n_var {
        out[i] = sc * x[i];
    }
}

/// `out = E x` with `E = ∇c(z)ᵀ` (rows c_0 = x_0 − x_s, c_{k+1} = F(x_k, u_k) − x_{k+1}):
/// the linearised change of the equalities along x (also the SQP's second-order correction).
pub(crate) fn mul_e(ocp: &Ocp, jac_x: &[f64], jac_u: &[f64], x: &[f64], out: &mut [f64]) {
    mul_e_nx::<0>(ocp, jac_x, jac_u, x, out)
}

/// [`mul_e`] with the state dimension `NX` (0: the OCP's).
fn mul_e_nx<const NX: usize>(ocp: &Ocp, jac_x: &[f64], jac_u: &[f64], x: &[f64], out: &mut [f64]) {
    let (nx, nu, n) = (dim_x::<NX>(ocp), ocp.nu, ocp.horizon);
    out[..nx].copy_from_slice(&x[..nx]);
    for k in 0..n {
        let (ix, iu, ixn) = (ocp.ix(k), ocp.iu(k), ocp.ix(k + 1));
        for r in 0..nx {
            let mut acc = -x[ixn + r];
            for j in 0..nx {
                acc += jac_x[k * nx * nx + r * nx + j] * x[ix + j];
            }
            for j in 0..nu {
                acc += jac_u[k * nx * nu + r * nu + j] * x[iu + j];
            }
            out[(k + 1) * nx + r] = acc;
        }
    }
}

/// `out += Eᵀ y`.
fn add_et<const NX: usize>(ocp: &Ocp, jac_x: &[f64], jac_u: &[f64], y: &[f64], out: &mut [f64]) {
    let (nx, nu, n) = (dim_x::<NX>(ocp), ocp.nu, ocp.horizon);
    for i in 0..nx {
        out[i] += y[i];
    }
    for k in 0..n {
        let (ix, iu, ixn) = (ocp.ix(k), ocp.iu(k), ocp.ix(k + 1));
        let l = &y[(k + 1) * nx..(k + 2) * nx];
        for r in 0..nx {
            for j in 0..nx {
                out[ix + j] += jac_x[k * nx * nx + r * nx + j] * l[r];
            }
            for j in 0..nu {
                out[iu + j] += jac_u[k * nx * nu + r * nu + j] * l[r];
            }
            out[ixn + r] -= l[r];
        }
    }
}

/// `out += Gᵀ y`.
fn add_gt(ocp: &Ocp, y: &[f64], out: &mut [f64]) {
    for (row, &v) in ocp.rows.iter().zip(y) {
        for j in 0..row.len {
            out[row.idx[j]] += row.coef[j] * v;
        }
    }
}

/// `max(0, max_i |v_i|)` over the entries that are not NaN (as `f64::max` folds it; in four
/// independent lanes, which gives the same maximum in fewer dependent steps).
fn inf_norm(v: &[f64]) -> f64 {
    let mut m = [0.0f64; 4];
    let chunks = v.chunks_exact(4);
    for (j, x) in chunks.remainder().iter().enumerate() {
        m[j] = m[j].max(x.abs());
    }
    for c in chunks {
        for j in 0..4 {
            m[j] = m[j].max(c[j].abs());
        }
    }
    m[0].max(m[1]).max(m[2].max(m[3]))
}

/// Largest α ∈ (0, 1] with `v + α dv ≥ 0` (v > 0): the minimum of 1 and the (non-NaN)
/// ratios `−v_i/dv_i` over `dv_i < 0`, in four independent lanes (the same minimum).
fn max_step(v: &[f64], dv: &[f64]) -> f64 {
    let mut a = [1.0f64; 4];
    for (i, (x, dx)) in v.iter().zip(dv).enumerate() {
        if *dx < 0.0 {
            a[i % 4] = a[i % 4].min(-x / dx);
        }
    }
    a[0].min(a[1]).min(a[2].min(a[3]))
}

/// The status of a solve that ends without reaching `TOL` at an iterate of error above
/// `TOL_REDUCED`: solved (with reduced accuracy) if an earlier iterate within `TOL_REDUCED`,
/// of error `kept`, is in the outputs, else failed.
fn kept_or_failed(kept: f64) -> QpStatus {
    if kept <= TOL_REDUCED {
        QpStatus::Solved
    } else {
        QpStatus::Failed
    }
}

impl IpmQp {
    /// Workspace for `ocp` (layout and bandwidth computed once).
    pub fn new(ocp: &Ocp) -> Self {
        let (nv, ne, m) = (ocp.n_var, ocp.n_eq, ocp.rows.len());
        IpmQp {
            kkt: BandedKkt::new(KktLayout::new(ocp, Vec::new())),
            riccati: RiccatiKkt::new(ocp),
            use_riccati: false,
            band_ready: false,
            d: vec![0.0; nv],
            lam: vec![0.0; ne],
            nu: vec![0.0; m],
            t: vec![0.0; m],
            w: vec![0.0; m],
            b: vec![0.0; m],
            rd: vec![0.0; nv],
            re: vec![0.0; ne],
            ri: vec![0.0; m],
            rhs: vec![0.0; nv + ne],
            scratch: Vec::with_capacity(nv + ne),
            tmp: vec![0.0; m],
            dt_aff: vec![0.0; m],
            dnu_aff: vec![0.0; m],
            dt: vec![0.0; m],
            dnu: vec![0.0; m],
            last_iterations: 0,
        }
    }

    /// Factorises by the band LU only (tests compare the two factorisations).
    #[cfg(test)]
    pub(crate) fn without_riccati(&mut self) {
        self.riccati = None;
    }

    /// Residuals r_d, r_e, r_i at the current iterate; returns the objective ½dᵀHd + gᵀd.
    #[allow(clippy::too_many_arguments)]
    fn residuals<const NX: usize>(
        &mut self,
        ocp: &Ocp,
        hess: &[f64],
        grad: &[f64],
        c: &[f64],
        jx: &[f64],
        ju: &[f64],
    ) -> f64 {
        mul_h::<NX>(ocp, hess, &self.d, &mut self.rd);
        let mut pobj = 0.0;
        for ((r, g), d) in self.rd.iter_mut().zip(grad).zip(&self.d) {
            pobj += (0.5 * *r + g) * d;
            *r += g;
        }
        add_et::<NX>(ocp, jx, ju, &self.lam, &mut self.rd);
        add_gt(ocp, &self.nu, &mut self.rd);
        mul_e_nx::<NX>(ocp, jx, ju, &self.d, &mut self.re);
        for (r, ci) in self.re.iter_mut().zip(c) {
            *r += ci;
        }
        for (i, row) in ocp.rows.iter().enumerate() {
            self.ri[i] = row.dot(&self.d) + self.t[i] - self.b[i];
        }
        pobj
    }

    /// Factorises `H + Gᵀ diag(self.w) G` (with E): by Riccati while it applies, else by the
    /// band LU (assembled on first use in this QP). Returns false if singular.
    fn factor<const NX: usize>(
        &mut self,
        ocp: &Ocp,
        hess: &[f64],
        jx: &[f64],
        ju: &[f64],
        min_ratio: f64,
    ) -> bool {
        if self.use_riccati {
            if let Some(r) = self.riccati.as_mut() {
                if r.factor_nx::<NX>(ocp, hess, jx, ju, &self.w) {
                    return true;
                }
            }
            self.use_riccati = false;
        }
        if !self.band_ready {
            if !self.kkt.set_base(ocp, hess, jx, ju) {
                return false;
            }
            self.band_ready = true;
        }
        let ratio = self.kkt.factor_weighted(&self.w);
        !(ratio.is_nan() || ratio <= min_ratio)
    }

    /// Solves the factorised system for `self.rhs` in place.
    fn solve_system<const NX: usize>(&mut self, ocp: &Ocp, jx: &[f64], ju: &[f64]) -> bool {
        match self.riccati.as_mut() {
            Some(r) if self.use_riccati => {
                r.solve_nx::<NX>(ocp, jx, ju, &mut self.rhs);
                self.rhs.iter().all(|v| v.is_finite())
            }
            _ => self.kkt.solve_in_place(&mut self.rhs, &mut self.scratch),
        }
    }

    /// Solves the Newton system for the complementarity target `rc` (in `self.tmp`) with the
    /// current factorisation; writes Δd, Δλ into `self.rhs` and Δt, Δν into `dt`, `dnu`.
    fn newton<const NX: usize>(
        &mut self,
        ocp: &Ocp,
        jx: &[f64],
        ju: &[f64],
        use_aff: bool,
    ) -> bool {
        let (nv, ne) = (ocp.n_var, ocp.n_eq);
        // rhs_z = −r_d − Gᵀ((r_c + ν∘r_i)/t), rhs_λ = −r_e.
        for i in 0..nv {
            self.rhs[i] = -self.rd[i];
        }
        for i in 0..ne {
            self.rhs[nv + i] = -self.re[i];
        }
        for (i, row) in ocp.rows.iter().enumerate() {
            let v = (self.tmp[i] + self.nu[i] * self.ri[i]) / self.t[i];
            for j in 0..row.len {
                self.rhs[row.idx[j]] -= row.coef[j] * v;
            }
        }
        if !self.solve_system::<NX>(ocp, jx, ju) {
            return false;
        }
        let (dt, dnu) = if use_aff {
            (&mut self.dt_aff, &mut self.dnu_aff)
        } else {
            (&mut self.dt, &mut self.dnu)
        };
        for (i, row) in ocp.rows.iter().enumerate() {
            dt[i] = -self.ri[i] - row.dot(&self.rhs[..nv]);
            dnu[i] = (self.tmp[i] - self.nu[i] * dt[i]) / self.t[i];
        }
        true
    }

    /// The starting point: the solution with W = I, i.e. of
    /// min ½dᵀHd + gᵀd + ½‖Gd − b‖² s.t. Ed = −c, into (d, λ); `false` on a singular system.
    fn start<const NX: usize>(
        &mut self,
        ocp: &Ocp,
        hess: &[f64],
        grad: &[f64],
        c: &[f64],
        jac_x: &[f64],
        jac_u: &[f64],
    ) -> bool {
        let (nv, ne) = (ocp.n_var, ocp.n_eq);
        self.use_riccati = self.riccati.is_some();
        self.band_ready = false;
        self.w.fill(1.0);
        if !self.factor::<NX>(ocp, hess, jac_x, jac_u, 1e-14) {
            return false;
        }
        for i in 0..nv {
            self.rhs[i] = -grad[i];
        }
        for i in 0..ne {
            self.rhs[nv + i] = -c[i];
        }
        add_gt(ocp, &self.b, &mut self.rhs[..nv]);
        if !self.solve_system::<NX>(ocp, jac_x, jac_u) {
            return false;
        }
        self.d.copy_from_slice(&self.rhs[..nv]);
        self.lam.copy_from_slice(&self.rhs[nv..]);
        true
    }

    /// t̂ = b − G d, ν̂ = −t̂, both shifted into the interior (t, ν > 0).
    fn shift_into_interior(&mut self, ocp: &Ocp) {
        let m = ocp.rows.len();
        // t̂ = b − G d, ν̂ = −t̂, both shifted into the interior.
        for (i, row) in ocp.rows.iter().enumerate() {
            self.t[i] = self.b[i] - row.dot(&self.d);
        }
        let tmin = self.t.iter().fold(f64::INFINITY, |a, &v| a.min(v));
        let tmax = -self.t.iter().fold(f64::INFINITY, |a, &v| a.min(-v));
        let shift_t = if tmin <= 0.0 { 1.0 - tmin } else { 0.0 };
        let shift_n = if -tmax <= 0.0 { 1.0 + tmax } else { 0.0 };
        for i in 0..m {
            let r = self.t[i];
            self.t[i] = r + shift_t;
            self.nu[i] = -r + shift_n;
        }
    }

    /// One Mehrotra predictor–corrector step at (d, λ, t, ν) with the factored system: the
    /// affine direction, σ = (gap_aff / gap)³, the corrected direction and the step
    /// α = min(1, τ·α_max) to the boundary; `false` on a singular system.
    fn step<const NX: usize>(
        &mut self,
        ocp: &Ocp,
        jac_x: &[f64],
        jac_u: &[f64],
        mu: f64,
        gap: f64,
    ) -> bool {
        let (nv, ne, m) = (ocp.n_var, ocp.n_eq, ocp.rows.len());
        // Predictor (affine scaling) step: r_c = −t∘ν.
        for i in 0..m {
            self.tmp[i] = -self.t[i] * self.nu[i];
        }
        if !self.newton::<NX>(ocp, jac_x, jac_u, true) {
            return false;
        }
        let a_aff = max_step(&self.t, &self.dt_aff).min(max_step(&self.nu, &self.dnu_aff));
        let mut gap_aff = 0.0;
        for i in 0..m {
            gap_aff +=
                (self.t[i] + a_aff * self.dt_aff[i]) * (self.nu[i] + a_aff * self.dnu_aff[i]);
        }
        let sigma = (gap_aff / gap).powi(3).clamp(0.0, 1.0);
        // Corrector: r_c = σμ − t∘ν − Δt_aff∘Δν_aff.
        for i in 0..m {
            self.tmp[i] = sigma * mu - self.t[i] * self.nu[i] - self.dt_aff[i] * self.dnu_aff[i];
        }
        if !self.newton::<NX>(ocp, jac_x, jac_u, false) {
            return false;
        }
        let amax = max_step(&self.t, &self.dt).min(max_step(&self.nu, &self.dnu));
        let alpha = (TAU * amax).min(1.0);
        for i in 0..nv {
            self.d[i] += alpha * self.rhs[i];
        }
        for i in 0..ne {
            self.lam[i] += alpha * self.rhs[nv + i];
        }
        for i in 0..m {
            self.t[i] += alpha * self.dt[i];
            self.nu[i] += alpha * self.dnu[i];
        }
        true
    }

    /// Solves the subproblem (same arguments and outputs as the clarabel solver). Returns
    /// [`QpStatus::Failed`] at the iteration limit, on divergence (e.g. an infeasible QP)
    /// or on a singular Newton system — unless an iterate reached the reduced accuracy
    /// `1e-7`: then the most accurate such iterate, as solved.
    pub fn solve(
        &mut self,
        ocp: &Ocp,
        data: &QpData,
        d: &mut [f64],
        lam: &mut [f64],
        nu: &mut [f64],
    ) -> QpStatus {
        by_nx!(ocp.nx, self.solve_nx(ocp, data, d, lam, nu))
    }

    /// [`IpmQp::solve`] with the state dimension `NX` (0: the OCP's) in every kernel.
    fn solve_nx<const NX: usize>(
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
            tol,
        } = *data;
        let tol = tol.max(TOL);
        let m = ocp.rows.len();
        self.last_iterations = 0;
        for (i, row) in ocp.rows.iter().enumerate() {
            self.b[i] = row.slack(z);
        }
        let scale_g = 1.0 + inf_norm(grad);
        let scale_c = 1.0 + inf_norm(c);
        let scale_b = 1.0 + inf_norm(&self.b);
        if !(scale_g.is_finite() && scale_c.is_finite() && scale_b.is_finite()) {
            return QpStatus::Failed;
        }
        if !self.start::<NX>(ocp, hess, grad, c, jac_x, jac_u) {
            return QpStatus::Failed;
        }
        if m == 0 {
            // No inequalities: the equality-constrained QP is solved exactly.
            d.copy_from_slice(&self.d);
            lam.copy_from_slice(&self.lam);
            self.last_iterations = 1;
            return QpStatus::Solved;
        }
        self.shift_into_interior(ocp);
        let (mut best, mut best_mu, mut best_res) = (f64::INFINITY, f64::INFINITY, f64::INFINITY);
        let mut stall = 0;
        let mut it = 0;
        // The error of the iterate kept in the outputs (d, λ, ν): the most accurate one within
        // `TOL_REDUCED` so far (∞: none). A solve that reaches `TOL` overwrites it.
        let mut kept = f64::INFINITY;
        loop {
            self.last_iterations = it;
            let pobj = self.residuals::<NX>(ocp, hess, grad, c, jac_x, jac_u);
            let gap: f64 = self.t.iter().zip(&self.nu).map(|(a, b)| a * b).sum();
            let mu = gap / m as f64;
            let residual = (inf_norm(&self.rd) / scale_g)
                .max(inf_norm(&self.re) / scale_c)
                .max(inf_norm(&self.ri) / scale_b);
            let rel_gap = gap / (1.0 + pobj.abs());
            let err = residual.max(rel_gap);
            if !err.is_finite() {
                return kept_or_failed(kept);
            }
            if err <= tol {
                break;
            }
            if err <= TOL_REDUCED && err < kept {
                d.copy_from_slice(&self.d);
                lam.copy_from_slice(&self.lam);
                nu.copy_from_slice(&self.nu);
                kept = err;
            }
            // Progress: the error measure fell by 10 % below its best, or — while the relative
            // gap is the error's largest part — μ did. The relative gap
            // `tᵀν / (1 + |½dᵀHd + gᵀd|)` is not monotone: on the soft problem's QPs (slack
            // weights ~1e4) the objective shrinks towards 0 while μ falls steadily, and the
            // error alone declared a stall after 7–13 iterations of QPs that then converge.
            // Where the residuals dominate (e.g. at their rounding floor) μ does not count,
            // so the stall exit still ends such a solve. The residuals alone count too: from the
            // off-centre start of the soft problem's QPs on curved constraints (the stress
            // files) the primal residual falls steadily while μ first rises ~100-fold and the
            // relative gap (the error's largest part) with it; without this, 5 such iterations
            // declared a stall and clarabel solved the QP (cartpole_public_nl: most of its
            // fallbacks, 22 % of its instructions).
            if err < 0.9 * best
                || residual < 0.9 * best_res
                || (rel_gap >= residual && mu < 0.9 * best_mu)
            {
                stall = 0;
            } else {
                stall += 1;
            }
            best = best.min(err);
            best_mu = best_mu.min(mu);
            best_res = best_res.min(residual);
            let diverged = inf_norm(&self.nu) > 1e14 || inf_norm(&self.d) > 1e14;
            if it >= MAX_ITER || stall >= 5 || diverged {
                if err <= TOL_REDUCED {
                    break;
                }
                return kept_or_failed(kept);
            }
            for i in 0..m {
                self.w[i] = self.nu[i] / self.t[i];
            }
            if !self.factor::<NX>(ocp, hess, jac_x, jac_u, 0.0) {
                if err <= TOL_REDUCED {
                    break;
                }
                return kept_or_failed(kept);
            }
            if !self.step::<NX>(ocp, jac_x, jac_u, mu, gap) {
                return kept_or_failed(kept);
            }
            it += 1;
        }
        d.copy_from_slice(&self.d);
        lam.copy_from_slice(&self.lam);
        nu.copy_from_slice(&self.nu);
        QpStatus::Solved
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mpc::sqp::SqpSolver;
    use crate::problem::ProblemConfig;

    /// The first QP of a cold planar-quadrotor solve (curved rows, nu = 2): asked for 1e-4 it
    /// stops in fewer iterations at a step near the exact one; a tolerance below `TOL` is
    /// `TOL` (the same bits).
    #[test]
    fn the_requested_tolerance_is_honoured() {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../tests/reference/planar_quadrotor_nl.toml"
        );
        let cfg = ProblemConfig::load(std::path::Path::new(path)).unwrap();
        let sqp = SqpSolver::new(&cfg, false);
        let mut ocp = sqp.ocp.clone();
        let xs = [0.3, -0.4, 0.2, 0.5, -0.6, 0.4];
        let p = sqp.cold_start(&xs);
        ocp.relinearize(&p.z);
        let (nx, nu, n) = (ocp.nx, ocp.nu, ocp.horizon);
        let mut grad = vec![0.0; ocp.n_var];
        let mut c = vec![0.0; ocp.n_eq];
        let (mut jx, mut ju) = (vec![0.0; n * nx * nx], vec![0.0; n * nx * nu]);
        let mut hess = vec![0.0; (n + 1) * (nx + nu) * (nx + nu)];
        ocp.gradient(&p.z, &mut grad);
        ocp.constraints(&p.z, &xs, &mut c, &mut jx, &mut ju);
        ocp.hessian_blocks(&p.z, &p.lam, &p.nu, &mut hess);
        let solve = |tol: f64| {
            let data = QpData {
                z: &p.z,
                hess: &hess,
                grad: &grad,
                c: &c,
                jac_x: &jx,
                jac_u: &ju,
                tol,
            };
            let mut ipm = IpmQp::new(&ocp);
            let (mut d, mut lam, mut nu) = (
                vec![0.0; ocp.n_var],
                vec![0.0; ocp.n_eq],
                vec![0.0; ocp.rows.len()],
            );
            assert_eq!(
                ipm.solve(&ocp, &data, &mut d, &mut lam, &mut nu),
                QpStatus::Solved
            );
            (ipm.last_iterations, d)
        };
        let (it_exact, d_exact) = solve(TOL);
        let (it_loose, d_loose) = solve(1e-4);
        let (it_zero, d_zero) = solve(0.0);
        assert!(it_loose < it_exact, "{it_loose} vs {it_exact}");
        let scale = 1.0 + inf_norm(&d_exact);
        let dev = d_loose
            .iter()
            .zip(&d_exact)
            .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
        assert!(dev > 0.0 && dev <= 1e-2 * scale, "{dev}");
        assert_eq!((it_zero, d_zero), (it_exact, d_exact));
    }
}
