//! [`QpCertifier`]: where the MPC is a convex QP, proofs that κ is affine (piece by piece)
//! on a box — the exact MPC part of the local certificate.
//!
//! **When the MPC is a QP** ([`QpCertifier::detect`]): the discrete plant is affine,
//! x⁺ = A x + B u + c (the built-in double integrator; an expression plant whose tape is
//! affine — `kind = "discrete"` directly, `kind = "ode"` because RK4 with u held over the
//! step composes affine maps, so F is affine for any number of sub-steps), every `[ocp]`
//! constraint is affine (the state and input boxes always are), and the weights make the
//! cost strictly convex in the inputs: R ≻ 0, Q, P ⪰ 0, checked exactly by diagonal
//! dominance (diagonal weights always pass). Only the hard problem is certified: the soft
//! fallback never enters a proven cell (its vertices are feasible, hence all of it).
//!
//! The multiple-shooting QP in z = (x₀, u₀, …, x_N) (the rows of [`crate::mpc::ocp::Ocp`]):
//! ```text
//! min ½ zᵀHz + gᵀz   s.t.   E z = e₀ + S x,   G z ≤ h
//! ```
//! with `E z = e` the equalities x₀ = x and x_{k+1} − A x_k − B u_k = c. For a fixed set W
//! of active rows, (z, λ, ν_W) solves the KKT system
//! ```text
//! M_W (z, λ, ν_W) = (−g, e₀ + S x, h_W),   M_W = [H Eᵀ G_Wᵀ; E 0 0; G_W 0 0],
//! ```
//! so y_W(x) = Y₀ + Y_x x is affine ([`AffineLaw`]). M_W is proven nonsingular (LICQ of
//! [E; G_W], with a positive definite reduced Hessian since R ≻ 0) by a verified inverse:
//! with X ≈ M⁻¹ and ‖I − XM‖∞ ≤ ρ < 1 (rounding of XM bounded by γₙ|X||M|),
//! ‖M⁻¹‖∞ ≤ ‖X‖∞/(1 − ρ); each computed column ŷ of Y then errs by at most
//! ‖M⁻¹‖∞·(‖b − Mŷ‖∞ + γₙ(|M||ŷ| + |b|)) (componentwise, [`AffineLaw::delta`]).
//!
//! **The cell proof** ([`QpCertifier::prove`]). Let W be the rows active at every corner of
//! the box B and D the rows active at some but not all (the disputed rows). Suppose that
//! [E; G_W] is independent (M_W proven nonsingular), that for every S ⊆ D either the rows
//! W ∪ S are exactly dependent ([`QpCertifier::dependent`], rational arithmetic) or M_{W∪S}
//! is proven nonsingular and at every vertex v of B the law W∪S has ν_i ≥ 0 for i ∈ W and
//! satisfies every row outside W ∪ D, and that P_D(v) is feasible at every vertex — all
//! affine in x, so the vertices decide for the whole box; each value is checked with its
//! rounding and truncation bound, and P_D(v)'s feasibility is witnessed by a law that
//! satisfies all rows of D there or, where no f64 bound decides (a vertex on a degenerate
//! region boundary), by a point computed in rational arithmetic (`critical/exact.rs`).
//! (Independence of W ∪ S needs no separate test where M_{W∪S} is proven nonsingular.)
//! Then at every x ∈ B the QP's solution is
//! y_{W∪S}(x) for one of the checked S. Proof: the problem P_D(x) (W rows as equalities, D
//! rows as inequalities, the others dropped) is feasible at the vertices (the witnesses),
//! hence on B (its feasible parameters form a convex set), and strictly convex (R ≻ 0), so
//! it has a unique optimum with multipliers supported on some S ⊆ D whose rows, with
//! [E; G_W], are independent (Carathéodory; [E; G_W] is independent) — so S is checked,
//! and the optimum is y_{W∪S}(x), which the vertex checks make a KKT point of the full QP
//! (ν_W ≥ 0, the other rows feasible, ν_S ≥ 0 and D∖S feasible from P_D) — the unique
//! optimum of a convex QP. With D = ∅ this is the critical-region test: the whole box lies
//! in W's critical region, and κ is affine on it. Critical regions of a strictly convex QP
//! are convex, so a box whose corners all lie in one region lies in it entirely (corners
//! sharing an active set never hide another region inside); the check fails where a corner
//! sits on a region boundary (a weakly active row) or a region touches no corner: then
//! [`QpCertifier::prove_from_corners`] moves the failing rows into D and tries again, and
//! failing that, refinement splits the cell.
//!
//! **The cell bound** ([`QpCertifier::restricted_bound`], `critical/restrict.rs`): each
//! law bounded only on outer boxes of the part of B where it can be the solution.
//!
//! The QP is the one with the f64 data the code holds (A, B, c from the plant's AD at 0,
//! H, g, G, h from the OCP's rows), the same data the SQP solves.
//!
//! **Why the QP certified is the step the SQP evaluates.** [`QpCertifier::detect`] accepts
//! only an affine F (a `discrete` tape that is affine, or an ODE ẋ = A_c x + B_c u + c_c
//! under RK4 with u held: each RK4 stage is an affine map of (x, u), so F is affine for any
//! number of sub-steps — exact, not a linearisation), affine constraints and a quadratic
//! cost. Forward-mode AD of an affine tape propagates tangents through operations whose
//! partials do not depend on the point, so the Jacobians (A, B) the SQP's linearisation
//! computes at any iterate are the very f64 matrices used here (bit for bit), the cost's
//! Hessian and gradient are the same rows, and the SQP's first full step from any iterate
//! solves this QP; only the offset of the dynamics rows is evaluated at the iterate
//! (F(x_k, u_k) − A x_k − B u_k instead of c = F(0, 0)), which for an affine F differs from
//! c by the rounding of F's evaluation alone. So κ here is the MPC the code defines — the
//! QP with the f64 data (A, B, c) — and the certificate is about that MPC; the rounding of
//! the data themselves (A, B, c as the f64 results of the plant's evaluation, not the
//! real-number coefficients of the ODE's flow) is the one premise the arithmetic does not
//! remove, stated as [`QP_DATA_NOTE`]. A plant that is not affine is not detected, and its
//! cells stay `estimated`.

use crate::certify::local::ExactPiece;
use crate::mpc::ocp::{LinRow, Ocp};
use crate::problem::ProblemConfig;
use nalgebra::{DMatrix, DVector};
use std::collections::HashMap;
use std::sync::{Arc, Mutex};

/// What an exact (QP) cell bound is about, for the certificate's notes: the MPC is the QP
/// with the f64 data (A, B, c) of the affine plant (module doc).
pub const QP_DATA_NOTE: &str = "mpc_range (exact cells): κ is the solution of the MPC's QP with \
    the f64 plant data (A, B, c) the code computes — exact for an affine plant (RK4 of a linear \
    ODE is affine), the same Jacobians the SQP uses at every iterate; the data's own rounding \
    relative to the real-number flow of the ODE is not bounded";

/// Most disputed rows in one cell (2^this laws are checked).
pub const MAX_DISPUTED: usize = 6;

/// Unit roundoff of f64.
const U: f64 = f64::EPSILON / 2.0;

/// γ_n = n·u / (1 − n·u), doubled: the bound on the relative rounding of an n-term dot
/// product, with room for the rounding of the bound's own computation.
fn gamma(n: usize) -> f64 {
    let nu = (n as f64 + 2.0) * U;
    2.0 * nu / (1.0 - nu)
}

/// The affine law of one active set: y(x) = y₀ + Y_x x for y = (z, λ, ν_W), with bounds on
/// the error of the computed coefficients.
#[derive(Debug, Clone)]
pub struct AffineLaw {
    /// The active rows W (ascending).
    pub set: Vec<usize>,
    /// y₀ (computed).
    pub y0: DVector<f64>,
    /// Y_x (computed), dim × nx.
    pub yx: DMatrix<f64>,
    /// delta[0]: bound on every |y₀,true − y₀|; delta[1 + j]: on every entry of column j
    /// of Y_x.
    pub delta: Vec<f64>,
}

impl AffineLaw {
    /// ŷ(x) and a bound on |y_true(x) − ŷ(x)| per entry (coefficient errors plus the
    /// rounding of this evaluation).
    pub fn eval(&self, x: &[f64]) -> (Vec<f64>, Vec<f64>) {
        let nx = x.len();
        let trunc: f64 =
            self.delta[0] + (0..nx).map(|j| self.delta[1 + j] * x[j].abs()).sum::<f64>();
        let g = gamma(nx + 1);
        let mut y = Vec::with_capacity(self.y0.len());
        let mut e = Vec::with_capacity(self.y0.len());
        for i in 0..self.y0.len() {
            let mut v = self.y0[i];
            let mut a = self.y0[i].abs();
            for (j, xj) in x.iter().enumerate() {
                v += self.yx[(i, j)] * xj;
                a += (self.yx[(i, j)] * xj).abs();
            }
            y.push(v);
            e.push((trunc + g * a) * (1.0 + g));
        }
        (y, e)
    }
}

/// Why a problem's MPC is not treated as a QP.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("the MPC is not a certified QP: {0}")]
pub struct NotQp(pub String);

/// The QP data of a problem whose MPC is a convex QP, and a cache of affine laws by
/// active set.
#[derive(Debug)]
pub struct QpCertifier {
    nx: usize,
    nu: usize,
    n_var: usize,
    n_eq: usize,
    /// Index of u₀ in z.
    iu0: usize,
    h: DMatrix<f64>,
    g: Vec<f64>,
    e: DMatrix<f64>,
    /// Constant part of the equalities' right-hand side.
    e0: Vec<f64>,
    rows: Vec<LinRow>,
    /// The discrete plant's A (nx × nx) and B (nx × nu), row-major.
    a: Vec<f64>,
    b: Vec<f64>,
    horizon: usize,
    cache: Mutex<HashMap<Vec<usize>, Option<Arc<AffineLaw>>>>,
    dependent: Mutex<HashMap<Vec<usize>, bool>>,
    /// The rational data of `exact.rs`, built on first use.
    exact: std::sync::OnceLock<exact::Exact>,
    /// S_u of the certificate's norm (`[ocp] u_scale`): the cell bounds are in it.
    u_scale: Vec<f64>,
}

/// Exact test of symmetric positive (semi)definiteness by diagonal dominance: every
/// diagonal entry above (at least) the sum of the other magnitudes of its row, with the
/// rounding of that sum allowed for.
fn dominant(m: &DMatrix<f64>, strict: bool) -> bool {
    let n = m.nrows();
    if m.ncols() != n || m.iter().any(|v| !v.is_finite()) {
        return false;
    }
    (0..n).all(|i| {
        let off: f64 = (0..n).filter(|&j| j != i).map(|j| m[(i, j)].abs()).sum();
        let off = off * (1.0 + gamma(n));
        let sym = (0..n).all(|j| m[(i, j)] == m[(j, i)]);
        sym && if strict {
            m[(i, i)] > off
        } else {
            m[(i, i)] >= off
        }
    })
}

impl QpCertifier {
    /// The QP of `cfg` if its MPC is one (see the module doc), else why not.
    pub fn detect(cfg: &ProblemConfig) -> Result<Self, NotQp> {
        if !cfg.system.is_affine() {
            return Err(NotQp(format!(
                "the plant ({}) is not affine in (x, u)",
                cfg.system.name()
            )));
        }
        if !dominant(&cfg.r(), true) || !dominant(&cfg.q(), false) || !dominant(&cfg.p(), false) {
            return Err(NotQp(
                "the weights are not proven convex (R ≻ 0, Q, P ⪰ 0 by diagonal dominance)".into(),
            ));
        }
        let ocp = Ocp::new(cfg, false);
        if ocp.has_nonlinear_rows() {
            return Err(NotQp("some [ocp] constraints are not affine".into()));
        }
        let (nx, nu, n) = (ocp.nx, ocp.nu, ocp.horizon);
        let (n_var, n_eq) = (ocp.n_var, ocp.n_eq);
        let nz = nx + nu;
        // Hessian and linear term: the OCP's own (at z = 0, no multipliers).
        let z0 = vec![0.0; n_var];
        let mut blocks = vec![0.0; (n + 1) * nz * nz];
        ocp.hessian_blocks(&z0, &vec![0.0; n_eq], &[], &mut blocks);
        let mut h = DMatrix::zeros(n_var, n_var);
        for k in 0..=n {
            let m = if k < n { nz } else { nx };
            for a in 0..m {
                for b in 0..m {
                    h[(k * nz + a, k * nz + b)] = blocks[k * nz * nz + a * nz + b];
                }
            }
        }
        let mut g = vec![0.0; n_var];
        ocp.gradient(&z0, &mut g);
        // Equalities: F(x, u) = A x + B u + c, exactly (the plant is affine).
        let (mut c, mut a, mut b) = (vec![0.0; nx], vec![0.0; nx * nx], vec![0.0; nx * nu]);
        ocp.model
            .linearize(&vec![0.0; nx], &vec![0.0; nu], &mut c, &mut a, &mut b);
        let mut e = DMatrix::zeros(n_eq, n_var);
        let mut e0 = vec![0.0; n_eq];
        for i in 0..nx {
            e[(i, i)] = 1.0;
        }
        for k in 0..n {
            for i in 0..nx {
                let r = (k + 1) * nx + i;
                e[(r, ocp.ix(k + 1) + i)] = 1.0;
                for j in 0..nx {
                    e[(r, ocp.ix(k) + j)] = -a[i * nx + j];
                }
                for j in 0..nu {
                    e[(r, ocp.iu(k) + j)] = -b[i * nu + j];
                }
                e0[r] = c[i];
            }
        }
        if h.iter().chain(&g).chain(e.iter()).any(|v| !v.is_finite()) {
            return Err(NotQp("the QP data are not finite".into()));
        }
        Ok(QpCertifier {
            nx,
            nu,
            n_var,
            n_eq,
            iu0: ocp.iu(0),
            h,
            g,
            e,
            e0,
            rows: ocp.rows.clone(),
            a,
            b,
            horizon: n,
            cache: Mutex::new(HashMap::new()),
            dependent: Mutex::new(HashMap::new()),
            exact: std::sync::OnceLock::new(),
            u_scale: crate::certify::norm::Norm::of_problem(cfg).u_scale,
        })
    }

    /// Number of inequality rows.
    pub fn n_rows(&self) -> usize {
        self.rows.len()
    }

    /// The affine law of active set `set` (ascending row indices), `None` if M_W is not
    /// proven nonsingular. Cached.
    pub fn law(&self, set: &[usize]) -> Option<Arc<AffineLaw>> {
        if let Some(l) = self.cache.lock().ok()?.get(set) {
            return l.clone();
        }
        let l = self.build_law(set).map(Arc::new);
        if let Ok(mut c) = self.cache.lock() {
            c.insert(set.to_vec(), l.clone());
        }
        l
    }

    fn build_law(&self, set: &[usize]) -> Option<AffineLaw> {
        if set.iter().any(|&r| r >= self.rows.len()) {
            return None;
        }
        let (nv, ne, na, nx) = (self.n_var, self.n_eq, set.len(), self.nx);
        let dim = nv + ne + na;
        let mut m = DMatrix::zeros(dim, dim);
        m.view_mut((0, 0), (nv, nv)).copy_from(&self.h);
        m.view_mut((nv, 0), (ne, nv)).copy_from(&self.e);
        m.view_mut((0, nv), (nv, ne)).copy_from(&self.e.transpose());
        // Right-hand sides: column 0 constant, column 1 + j the coefficient of x_j.
        let mut rhs = DMatrix::zeros(dim, nx + 1);
        for i in 0..nv {
            rhs[(i, 0)] = -self.g[i];
        }
        for i in 0..ne {
            rhs[(nv + i, 0)] = self.e0[i];
        }
        for j in 0..nx {
            rhs[(nv + j, 1 + j)] = 1.0;
        }
        for (a, &r) in set.iter().enumerate() {
            let row = &self.rows[r];
            for t in 0..row.len {
                m[(nv + ne + a, row.idx[t])] += row.coef[t];
                m[(row.idx[t], nv + ne + a)] += row.coef[t];
            }
            rhs[(nv + ne + a, 0)] = row.rhs;
        }
        let x = m.clone().try_inverse()?;
        // ρ ≥ ‖I − XM‖∞ including the rounding of XM.
        let xm = &x * &m;
        let prod = x.abs() * m.abs();
        let gd = gamma(dim);
        let mut rho = 0.0f64;
        let mut xnorm = 0.0f64;
        for i in 0..dim {
            let mut s = 0.0;
            let mut t = 0.0;
            for j in 0..dim {
                let id = if i == j { 1.0 } else { 0.0 };
                s += (id - xm[(i, j)]).abs() + gd * prod[(i, j)];
                t += x[(i, j)].abs();
            }
            rho = rho.max(s * (1.0 + gd));
            xnorm = xnorm.max(t * (1.0 + gd));
        }
        // NaN fails too: the proof needs ρ < 0.5 established, not merely not refuted.
        if rho.is_nan() || rho >= 0.5 {
            return None;
        }
        let minv = xnorm / (1.0 - rho) * (1.0 + gd);
        let y = &x * &rhs;
        let res = &rhs - &m * &y;
        let absm = m.abs();
        let mut delta = Vec::with_capacity(nx + 1);
        for col in 0..=nx {
            let yc = y.column(col).abs();
            let my = &absm * yc;
            let mut r = 0.0f64;
            for i in 0..dim {
                r = r.max(res[(i, col)].abs() + gd * (my[i] + rhs[(i, col)].abs()));
            }
            delta.push(minv * r * (1.0 + gd) * (1.0 + gd));
        }
        if delta.iter().any(|d| !d.is_finite()) || y.iter().any(|v| !v.is_finite()) {
            return None;
        }
        Some(AffineLaw {
            set: set.to_vec(),
            y0: y.column(0).into_owned(),
            yx: y.columns(1, nx).into_owned(),
            delta,
        })
    }

    /// The vertices of the box [lo, hi] (vertex c has x_k = hi_k iff bit k of c is set).
    fn vertices(lo: &[f64], hi: &[f64]) -> Vec<Vec<f64>> {
        (0..1usize << lo.len())
            .map(|c| {
                (0..lo.len())
                    .map(|k| if c & (1 << k) != 0 { hi[k] } else { lo[k] })
                    .collect()
            })
            .collect()
    }

    /// The vertex checks of law `l` (set W ∪ S) on `verts`: the rows that fail them (ν_i ≥ 0
    /// for i ∈ `w`, every row outside `skip` = W ∪ D satisfied; each with its error bound),
    /// and per vertex whether the law satisfies every row of `d` there (a feasibility
    /// witness of P_D).
    fn checks(
        &self,
        l: &AffineLaw,
        w: &[usize],
        d: &[usize],
        skip: &[usize],
        verts: &[Vec<f64>],
    ) -> (Vec<usize>, Vec<bool>) {
        let (nv, ne) = (self.n_var, self.n_eq);
        let mut fails = Vec::new();
        let mut witness = Vec::with_capacity(verts.len());
        for v in verts {
            let (y, err) = l.eval(v);
            for (a, r) in l.set.iter().enumerate() {
                // A NaN multiplier bound is a failed check, like a negative one.
                let nu_lo = y[nv + ne + a] - err[nv + ne + a];
                if w.binary_search(r).is_ok() && (nu_lo.is_nan() || nu_lo < 0.0) {
                    fails.push(*r);
                }
            }
            let feasible = |r: usize| {
                let row = &self.rows[r];
                let (mut dot, mut mag, mut e) = (0.0, row.rhs.abs(), 0.0);
                for t in 0..row.len {
                    let (i, cf) = (row.idx[t], row.coef[t]);
                    dot += cf * y[i];
                    mag += (cf * y[i]).abs();
                    e += cf.abs() * err[i];
                }
                let bound = (e + gamma(row.len + 1) * mag) * (1.0 + gamma(row.len + 1));
                row.rhs - dot - bound >= 0.0
            };
            for r in 0..self.rows.len() {
                if skip.binary_search(&r).is_err() && !feasible(r) {
                    fails.push(r);
                }
            }
            witness.push(
                d.iter()
                    .all(|r| l.set.binary_search(r).is_ok() || feasible(*r)),
            );
        }
        fails.sort_unstable();
        fails.dedup();
        (fails, witness)
    }

    /// Whether the rows `set` are linearly dependent on the equalities' null space (LICQ
    /// fails for W = set), decided exactly: on {x₀ = 0}, x_k = Σ_j A^{k−1−j} B u_j, so row
    /// aᵀ(x_k, u_k) ≤ h restricts to aₓᵀΓ_k U + a_uᵀu_k, and the rows are dependent iff
    /// these |set| rows in U have rank < |set| — computed in rational arithmetic from the
    /// f64 data (every f64 is a dyadic rational). Cached.
    pub fn dependent(&self, set: &[usize]) -> bool {
        if let Some(&v) = self
            .dependent
            .lock()
            .ok()
            .and_then(|c| c.get(set).copied())
            .as_ref()
        {
            return v;
        }
        let v = self.exact_rank_deficient(set);
        if let Ok(mut c) = self.dependent.lock() {
            c.insert(set.to_vec(), v);
        }
        v
    }

    /// Proves that on [lo, hi] the QP's solution is, at every point, that of one of the
    /// laws W ∪ S, S ⊆ D (see the module doc); returns those laws, or `None` if a check
    /// fails. `w` and `d` ascending and disjoint, |D| ≤ [`MAX_DISPUTED`].
    pub fn prove(
        &self,
        lo: &[f64],
        hi: &[f64],
        w: &[usize],
        d: &[usize],
    ) -> Option<Vec<Arc<AffineLaw>>> {
        self.attempt(lo, hi, w, d).ok()
    }

    /// [`prove`](Self::prove), or the rows whose checks failed (empty: no retry helps).
    fn attempt(
        &self,
        lo: &[f64],
        hi: &[f64],
        w: &[usize],
        d: &[usize],
    ) -> Result<Vec<Arc<AffineLaw>>, Vec<usize>> {
        if d.len() > MAX_DISPUTED || lo.len() != self.nx || hi.len() != self.nx {
            return Err(Vec::new());
        }
        let verts = Self::vertices(lo, hi);
        let mut skip: Vec<usize> = w.iter().chain(d).copied().collect();
        skip.sort_unstable();
        let mut laws = Vec::with_capacity(1 << d.len());
        let mut fails = Vec::new();
        let mut witnessed = vec![false; verts.len()];
        for mask in 0..1usize << d.len() {
            let mut set: Vec<usize> = w.to_vec();
            set.extend((0..d.len()).filter(|b| mask & (1 << b) != 0).map(|b| d[b]));
            set.sort_unstable();
            // A set whose rows are exactly dependent is never the support of P_D's
            // multipliers (see the module doc): skipped. W itself must be independent.
            // (A proven nonsingular M_{W∪S} shows independence: the exact test only runs
            // where the verified inverse fails.)
            let Some(l) = self.law(&set) else {
                if mask != 0 && self.dependent(&set) {
                    continue;
                }
                return Err(Vec::new());
            };
            let (f, wit) = self.checks(&l, w, d, &skip, &verts);
            fails.extend(f);
            for (a, b) in witnessed.iter_mut().zip(wit) {
                *a |= b;
            }
            laws.push(l);
        }
        fails.sort_unstable();
        fails.dedup();
        if !fails.is_empty() {
            return Err(fails);
        }
        // A vertex no law witnesses within its f64 error bounds (e.g. on a degenerate
        // region boundary): P_D's feasibility there decided exactly (`witness.rs`), with
        // the rows W ∪ S as equalities for some S ⊆ D (a point of that system satisfying
        // D ∖ S is one of P_D), the free inputs from a law's value.
        for (v, ok) in verts.iter().zip(witnessed.iter_mut()) {
            *ok = *ok || self.exact_witness_any(v, w, d, &laws);
        }
        if witnessed.iter().all(|&b| b) {
            Ok(laws)
        } else {
            Err(Vec::new())
        }
    }

    /// The proof of [`prove`](Self::prove) with W the rows active at every corner whose
    /// active set is known and D the rows active at some of them (a corner without a known
    /// set, e.g. a failed solve, only gives no candidate: the proof does not use labels).
    /// `None` if no set is known or |D| > [`MAX_DISPUTED`].
    pub fn prove_from_corners(
        &self,
        lo: &[f64],
        hi: &[f64],
        sets: &[Option<&[usize]>],
    ) -> Option<Vec<Arc<AffineLaw>>> {
        let (mut w, mut d) = Self::candidates(sets)?;
        // Rows whose check fails (a row weakly active at a corner, a region the corners
        // miss) are moved into D and the proof is tried again.
        for _ in 0..3 {
            match self.attempt(lo, hi, &w, &d) {
                Ok(laws) => return Some(laws),
                Err(f) if f.is_empty() => return None,
                Err(f) => {
                    w.retain(|r| !f.contains(r));
                    d.extend(f);
                    d.sort_unstable();
                    d.dedup();
                }
            }
        }
        None
    }

    /// (W, D) of [`prove_from_corners`](Self::prove_from_corners).
    pub fn candidates(sets: &[Option<&[usize]>]) -> Option<(Vec<usize>, Vec<usize>)> {
        let sets: Vec<&[usize]> = sets.iter().flatten().copied().collect();
        let first = sets.first()?;
        let mut w: Vec<usize> = first
            .iter()
            .copied()
            .filter(|r| sets.iter().all(|s| s.contains(r)))
            .collect();
        let mut d: Vec<usize> = sets
            .iter()
            .flat_map(|s| s.iter().copied())
            .filter(|r| !w.contains(r))
            .collect();
        w.sort_unstable();
        d.sort_unstable();
        d.dedup();
        Some((w, d))
    }

    /// The exact pieces of the cell bound: for each law, κ̂ = û₀ at the box's corners with
    /// its error bound, and the gain K̂ with its error bounds.
    pub fn pieces(&self, lo: &[f64], hi: &[f64], laws: &[Arc<AffineLaw>]) -> Vec<ExactPiece> {
        let (nx, nu) = (self.nx, self.nu);
        let verts = Self::vertices(lo, hi);
        laws.iter()
            .map(|l| {
                let mut u = Vec::with_capacity(verts.len() * nu);
                let mut u_err = 0.0f64;
                for v in &verts {
                    let (y, e) = l.eval(v);
                    for j in 0..nu {
                        u.push(y[self.iu0 + j]);
                        u_err = u_err.max(e[self.iu0 + j]);
                    }
                }
                let mut gain = vec![0.0; nu * nx];
                for j in 0..nu {
                    for k in 0..nx {
                        gain[j * nx + k] = l.yx[(self.iu0 + j, k)];
                    }
                }
                ExactPiece {
                    u,
                    u_err,
                    gain,
                    gain_err: l.delta[1..].to_vec(),
                }
            })
            .collect()
    }

    /// κ(x) by law `l`: û₀(x) and a bound on its error.
    pub fn kappa(&self, l: &AffineLaw, x: &[f64]) -> (Vec<f64>, f64) {
        let (y, e) = l.eval(x);
        let r = self.iu0..self.iu0 + self.nu;
        (
            y[r.clone()].to_vec(),
            e[r].iter().fold(0.0, |m, v| m.max(*v)),
        )
    }
}

mod exact;
mod restrict;
pub use restrict::{LawRegion, MAX_DEPTH};

#[cfg(test)]
mod tests;
