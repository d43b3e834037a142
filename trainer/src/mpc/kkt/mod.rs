//! The KKT system of the OCP on a fixed active set, ordered stage-wise into a banded matrix
//! and factorised by a banded LU with partial pivoting.
//!
//! With the active inequality rows `G_A z = h_A` treated as equalities, the Newton matrix of
//! the KKT conditions is
//! ```text
//!     ⎡ ∇²L + Gᵀ W G   ∇cᵀ   G_Aᵀ ⎤
//! K = ⎢ ∇c              0     0   ⎥      unknowns (Δz, λ, ν_A)
//!     ⎣ G_A             0     0   ⎦
//! ```
//! (`W` is an optional nonnegative diagonal weight of all inequality rows, used by the
//! interior-point QP solver `qp::ipm`; the active-set Newton systems have `W = 0`).
//! It serves twice: the SQP's final Newton polish (quadratic convergence once the active set
//! is known) and the parametric sensitivity (`sensitivity` module), which solves
//! `K · ∂(z, λ, ν_A)/∂x_s = (0, E, 0)` with E the identity on the rows of `c_0 = x_0 − x_s`.
//! K is nonsingular exactly when LICQ and the second-order sufficient condition hold on the
//! active set; a tiny LU pivot flags that failure.
//!
//! **Structure.** Every unknown belongs to a stage k: λ_k (the multiplier of `c_k`, which
//! couples stage k−1 to stage k), x_k, u_k, the soft problem's slacks of the state bounds
//! at stage k, and the multipliers of the active rows whose variables are in stage k. Ordered
//! stage by stage in that order, `P K Pᵀ` is banded with half-bandwidth b about the size of
//! one stage block (`2nx + nu + n_active,k + n_slack,k`), independent of N. The banded LU
//! with partial pivoting (LAPACK's `gbtf2`: row interchanges within the band, U gets
//! bandwidth ≤ 2b) then costs O(N·b²) time and O(N·b) memory instead of the dense O(N³).
//! Partial pivoting makes it valid for the indefinite K; singularity is detected, as for the
//! dense LU, by the ratio of the smallest to the largest |U_ii|.

use crate::mpc::ocp::Ocp;
use nalgebra::{DMatrix, DVector};

pub use band_lu::BandLu;

mod band_lu;

/// Stage-wise ordering of the KKT unknowns `(z, λ, ν_A)` for one OCP structure and active
/// set, and the resulting bandwidth.
#[derive(Debug, Clone, Default)]
pub struct KktLayout {
    /// Active inequality rows (indices into `ocp.rows`), in the order of ν_A.
    pub active: Vec<usize>,
    /// Band position of each unknown in natural order `(z, λ, ν_A)`.
    pos: Vec<usize>,
    /// Half-bandwidth of the permuted K.
    bw: usize,
    /// Per band position: the last position its row (and, K being structurally symmetric,
    /// its column) may hold a nonzero in.
    ends: Vec<usize>,
}

/// Stage of each variable of z (slacks: the stage of the states and inputs of the rows
/// they relax — every row lies within one stage).
fn var_stages(ocp: &Ocp) -> Vec<usize> {
    let nz = ocp.nx + ocp.nu;
    let mut st: Vec<usize> = (0..ocp.n_var).map(|v| v / nz).collect();
    let is = ocp.is();
    for row in &ocp.rows {
        let idx = &row.idx[..row.len];
        if let Some(&v) = idx.iter().find(|&&v| v < is) {
            for &s in idx.iter().filter(|&&s| s >= is) {
                st[s] = v / nz;
            }
        }
    }
    st
}

impl KktLayout {
    /// The stage-wise ordering for `ocp` with active rows `active`. The bandwidth covers the
    /// `Gᵀ W G` pattern of all rows too (it lies within a stage).
    pub fn new(ocp: &Ocp, active: Vec<usize>) -> Self {
        let (nx, nv, ne) = (ocp.nx, ocp.n_var, ocp.n_eq);
        let stage = var_stages(ocp);
        let is = ocp.is();
        let nz = ocp.nx + ocp.nu;
        let dim = nv + ne + active.len();
        // Sort key (stage, kind, natural index).
        let mut keys: Vec<(usize, u8, usize)> = Vec::with_capacity(dim);
        for v in 0..nv {
            let kind = if v >= is {
                3
            } else if v % nz < nx {
                1
            } else {
                2
            };
            keys.push((stage[v], kind, v));
        }
        for e in 0..ne {
            keys.push((e / nx, 0, nv + e));
        }
        for (t, &r) in active.iter().enumerate() {
            let row = &ocp.rows[r];
            let s = (0..row.len).map(|j| stage[row.idx[j]]).min().unwrap_or(0);
            keys.push((s, 4, nv + ne + t));
        }
        keys.sort_unstable();
        let mut pos = vec![0; dim];
        for (p, &(_, _, i)) in keys.iter().enumerate() {
            pos[i] = p;
        }
        let mut layout = KktLayout {
            active,
            pos,
            bw: 0,
            ends: (0..dim).collect(),
        };
        let mut bw = 0usize;
        let mut ends = std::mem::take(&mut layout.ends);
        layout.for_each_pattern(ocp, |i, j| {
            bw = bw.max(i.abs_diff(j));
            ends[i] = ends[i].max(j);
            ends[j] = ends[j].max(i);
        });
        layout.bw = bw;
        layout.ends = ends;
        layout
    }

    /// Dimension of K.
    pub fn dim(&self) -> usize {
        self.pos.len()
    }

    /// Half-bandwidth of the stage-ordered K.
    pub fn bandwidth(&self) -> usize {
        self.bw
    }

    /// Calls `f(pos_i, pos_j)` for (at least) every structurally nonzero entry of K with
    /// `i ≥ j` in band positions, including the `Gᵀ W G` pattern of all rows.
    fn for_each_pattern(&self, ocp: &Ocp, mut f: impl FnMut(usize, usize)) {
        let mut g = |i: usize, j: usize| f(self.pos[i], self.pos[j]);
        let (nx, nu, n, nv) = (ocp.nx, ocp.nu, ocp.horizon, ocp.n_var);
        let nz = nx + nu;
        for s in 0..=n {
            let size = if s < n { nz } else { nx };
            for i in 0..size {
                for j in 0..size {
                    g(s * nz + i, s * nz + j);
                }
            }
        }
        for i in 0..nx {
            g(nv + i, i);
        }
        for s in 0..n {
            for r in 0..nx {
                let row = nv + (s + 1) * nx + r;
                for j in 0..nz {
                    g(row, s * nz + j);
                }
                g(row, ocp.ix(s + 1) + r);
            }
        }
        for row in &ocp.rows {
            for a in 0..row.len {
                for b in 0..row.len {
                    g(row.idx[a], row.idx[b]);
                }
            }
        }
        let a0 = nv + ocp.n_eq;
        for (t, &r) in self.active.iter().enumerate() {
            let row = &ocp.rows[r];
            for j in 0..row.len {
                g(a0 + t, row.idx[j]);
            }
        }
    }
}

/// Calls `put(i, j, v)` for every nonzero of K (natural order `(z, λ, ν_A)`, both triangles;
/// entries at the same (i, j) are to be summed). `row_weight[r]` (if given) adds
/// `w_r a_r a_rᵀ` for every inequality row r to the (z, z) block.
#[allow(clippy::too_many_arguments)]
fn for_each_entry(
    ocp: &Ocp,
    hess: &[f64],
    jac_x: &[f64],
    jac_u: &[f64],
    active: &[usize],
    row_weight: Option<&[f64]>,
    mut put: impl FnMut(usize, usize, f64),
) {
    let (nx, nu, n) = (ocp.nx, ocp.nu, ocp.horizon);
    let nz = nx + nu;
    for s in 0..=n {
        let off = s * nz;
        let size = if s < n { nz } else { nx };
        let blk = &hess[s * nz * nz..(s + 1) * nz * nz];
        for i in 0..size {
            for j in 0..size {
                put(off + i, off + j, blk[i * nz + j]);
            }
        }
    }
    let sc = ocp.slack_curvature();
    for i in ocp.is()..ocp.n_var {
        put(i, i, sc);
    }
    if let Some(w) = row_weight {
        for (row, &wr) in ocp.rows.iter().zip(w) {
            for a in 0..row.len {
                for b in 0..row.len {
                    put(row.idx[a], row.idx[b], wr * row.coef[a] * row.coef[b]);
                }
            }
        }
    }
    let e0 = ocp.n_var;
    let mut sym = |r: usize, c: usize, v: f64| {
        put(r, c, v);
        put(c, r, v);
    };
    for i in 0..nx {
        sym(e0 + i, i, 1.0);
    }
    for s in 0..n {
        for r in 0..nx {
            let row = e0 + (s + 1) * nx + r;
            for j in 0..nx {
                sym(row, ocp.ix(s) + j, jac_x[s * nx * nx + r * nx + j]);
            }
            for j in 0..nu {
                sym(row, ocp.iu(s) + j, jac_u[s * nx * nu + r * nu + j]);
            }
            sym(row, ocp.ix(s + 1) + r, -1.0);
        }
    }
    let a0 = e0 + ocp.n_eq;
    for (t, &r) in active.iter().enumerate() {
        let row = &ocp.rows[r];
        for j in 0..row.len {
            sym(a0 + t, row.idx[j], row.coef[j]);
        }
    }
}

/// A reusable banded KKT factorisation for one layout (OCP structure and active set).
#[derive(Debug, Clone, Default)]
pub struct BandedKkt {
    /// The ordering.
    pub layout: KktLayout,
    lu: BandLu,
    /// The assembled K without row weights (see [`BandedKkt::set_base`]).
    base: Vec<f64>,
    /// For each entry of `w_r a_r a_rᵀ`: (band storage index, row r, coefficient product).
    weight_slots: Vec<(usize, usize, f64)>,
}

impl BandedKkt {
    /// Workspace for `layout`.
    pub fn new(layout: KktLayout) -> Self {
        BandedKkt {
            layout,
            ..BandedKkt::default()
        }
    }

    /// Assembles K without row weights and keeps it as the base for
    /// [`BandedKkt::factor_weighted`], which then only adds `Gᵀ W G` (the interior-point
    /// iterations of one QP share H and ∇c). Returns false on a layout bug.
    pub fn set_base(&mut self, ocp: &Ocp, hess: &[f64], jac_x: &[f64], jac_u: &[f64]) -> bool {
        let (dim, bw) = (self.layout.dim(), self.layout.bw);
        self.lu.reset(dim, bw, bw);
        let (pos, lu) = (&self.layout.pos, &mut self.lu);
        let mut inside = true;
        for_each_entry(
            ocp,
            hess,
            jac_x,
            jac_u,
            &self.layout.active,
            None,
            |i, j, v| {
                inside &= lu.add(pos[i], pos[j], v);
            },
        );
        self.base.clear();
        self.base.extend_from_slice(&self.lu.a);
        self.weight_slots.clear();
        for (r, row) in ocp.rows.iter().enumerate() {
            for a in 0..row.len {
                for b in 0..row.len {
                    let (i, j) = (pos[row.idx[a]], pos[row.idx[b]]);
                    match self.lu.slot(i, j) {
                        Some(s) => self.weight_slots.push((s, r, row.coef[a] * row.coef[b])),
                        None => inside = false,
                    }
                }
            }
        }
        inside
    }

    /// Factorises `base + Gᵀ W G` (after [`BandedKkt::set_base`]); returns the pivot ratio.
    pub fn factor_weighted(&mut self, row_weight: &[f64]) -> f64 {
        self.lu.a.copy_from_slice(&self.base);
        for &(s, r, c) in &self.weight_slots {
            self.lu.a[s] += row_weight[r] * c;
        }
        self.lu
            .factor_with_ends(&self.layout.ends, &self.layout.ends);
        self.lu.pivot_ratio
    }

    /// Assembles K from the Hessian blocks, the dynamics Jacobians, the layout's active rows
    /// and the optional row weights W, and factorises it. Returns the pivot ratio.
    pub fn factor(
        &mut self,
        ocp: &Ocp,
        hess: &[f64],
        jac_x: &[f64],
        jac_u: &[f64],
        row_weight: Option<&[f64]>,
    ) -> f64 {
        let (dim, bw) = (self.layout.dim(), self.layout.bw);
        self.lu.reset(dim, bw, bw);
        let (pos, lu) = (&self.layout.pos, &mut self.lu);
        let mut inside = true;
        for_each_entry(
            ocp,
            hess,
            jac_x,
            jac_u,
            &self.layout.active,
            row_weight,
            |i, j, v| {
                inside &= lu.add(pos[i], pos[j], v);
            },
        );
        // The pattern walk bounds every entry, so `inside` holds; an entry outside would be a
        // layout bug: report it as singular rather than factorising a wrong matrix.
        if inside {
            self.lu
                .factor_with_ends(&self.layout.ends, &self.layout.ends);
        } else {
            self.lu.pivot_ratio = 0.0;
        }
        self.lu.pivot_ratio
    }

    /// Smallest over largest |U_ii| of the last factorisation.
    pub fn pivot_ratio(&self) -> f64 {
        self.lu.pivot_ratio
    }

    /// Solves `K x = b` in place (natural order), `scratch` has length ≥ dim. Returns
    /// false if the result is not finite.
    pub fn solve_in_place(&self, b: &mut [f64], scratch: &mut Vec<f64>) -> bool {
        let dim = self.layout.dim();
        scratch.clear();
        scratch.resize(dim, 0.0);
        for (i, &p) in self.layout.pos.iter().enumerate() {
            scratch[p] = b[i];
        }
        self.lu.solve_in_place(scratch);
        for (i, &p) in self.layout.pos.iter().enumerate() {
            b[i] = scratch[p];
        }
        b.iter().all(|v| v.is_finite())
    }

    /// [`BandedKkt::solve_in_place`] for `m` right-hand sides, `b` row-major dim × m (the
    /// same bits per column).
    pub fn solve_many_in_place(&self, b: &mut [f64], m: usize, scratch: &mut Vec<f64>) -> bool {
        let dim = self.layout.dim();
        scratch.clear();
        scratch.resize(dim * m, 0.0);
        for (i, &p) in self.layout.pos.iter().enumerate() {
            scratch[p * m..(p + 1) * m].copy_from_slice(&b[i * m..(i + 1) * m]);
        }
        self.lu.solve_many_in_place(scratch, m);
        for (i, &p) in self.layout.pos.iter().enumerate() {
            b[i * m..(i + 1) * m].copy_from_slice(&scratch[p * m..(p + 1) * m]);
        }
        b.iter().all(|v| v.is_finite())
    }
}

/// A factorised active-set KKT matrix.
pub struct ActiveSetKkt {
    kkt: BandedKkt,
    /// Active inequality rows (indices into `ocp.rows`), in the order of ν_A.
    pub active: Vec<usize>,
    /// Smallest over largest |U_ii| of the LU factor: ≈ 0 means singular (LICQ/SOSC fail).
    pub pivot_ratio: f64,
}

impl ActiveSetKkt {
    /// Assembles and factorises K from the exact Hessian blocks, the dynamics Jacobians and
    /// the active rows.
    pub fn new(ocp: &Ocp, hess: &[f64], jac_x: &[f64], jac_u: &[f64], active: Vec<usize>) -> Self {
        Self::with_layout(ocp, hess, jac_x, jac_u, KktLayout::new(ocp, active))
    }

    /// [`ActiveSetKkt::new`] for the active rows of `layout`, an ordering already computed
    /// (by [`KktLayout::new`] for this OCP structure) and reused.
    pub fn with_layout(
        ocp: &Ocp,
        hess: &[f64],
        jac_x: &[f64],
        jac_u: &[f64],
        layout: KktLayout,
    ) -> Self {
        let active = layout.active.clone();
        let mut kkt = BandedKkt::new(layout);
        let pivot_ratio = kkt.factor(ocp, hess, jac_x, jac_u, None);
        ActiveSetKkt {
            kkt,
            active,
            pivot_ratio,
        }
    }

    /// Assembles and factorises K anew for new Hessian blocks and Jacobians (same OCP and
    /// active rows), reusing the ordering and the storage (the bits of a new one).
    pub fn refactor(&mut self, ocp: &Ocp, hess: &[f64], jac_x: &[f64], jac_u: &[f64]) {
        self.pivot_ratio = self.kkt.factor(ocp, hess, jac_x, jac_u, None);
    }

    /// The ordering (to reuse for the same active rows).
    pub fn layout(&self) -> &KktLayout {
        &self.kkt.layout
    }

    /// Dimension of K.
    pub fn dim(&self) -> usize {
        self.kkt.layout.dim()
    }

    /// Whether K is numerically singular (LICQ or second-order sufficiency fails).
    pub fn is_singular(&self) -> bool {
        self.pivot_ratio.is_nan() || self.pivot_ratio <= 1e-14
    }

    /// Solves `K x = b` in place; false (b unspecified) if K is singular or the result is
    /// not finite, or b has the wrong length.
    pub fn solve_slice(&self, b: &mut [f64], scratch: &mut Vec<f64>) -> bool {
        if self.is_singular() || b.len() != self.dim() {
            return false;
        }
        self.kkt.solve_in_place(b, scratch)
    }

    /// Solves `K x = rhs`; `None` if K is singular.
    pub fn solve(&self, rhs: &DVector<f64>) -> Option<DVector<f64>> {
        let mut x = rhs.clone();
        let mut scratch = Vec::new();
        self.solve_slice(x.as_mut_slice(), &mut scratch)
            .then_some(x)
    }

    /// Solves `K X = RHS` for several right-hand sides (all at once; each column's bits are
    /// those of [`ActiveSetKkt::solve`]); `None` if K is singular or a result is not finite.
    pub fn solve_many(&self, rhs: &DMatrix<f64>) -> Option<DMatrix<f64>> {
        let (n, m) = rhs.shape();
        if self.is_singular() || n != self.dim() {
            return None;
        }
        // Row-major copy of the column-major RHS.
        let mut b = vec![0.0; n * m];
        for (c, col) in rhs.column_iter().enumerate() {
            for (i, &v) in col.iter().enumerate() {
                b[i * m + c] = v;
            }
        }
        let mut scratch = Vec::new();
        if !self.kkt.solve_many_in_place(&mut b, m, &mut scratch) {
            return None;
        }
        Some(DMatrix::from_row_slice(n, m, &b))
    }
}

/// The dense K in natural order `(z, λ, ν_A)` (plus `Gᵀ W G` if `row_weight` is given): the
/// reference the banded factorisation is tested against.
pub fn dense_kkt_matrix(
    ocp: &Ocp,
    hess: &[f64],
    jac_x: &[f64],
    jac_u: &[f64],
    active: &[usize],
    row_weight: Option<&[f64]>,
) -> DMatrix<f64> {
    let dim = ocp.n_var + ocp.n_eq + active.len();
    let mut k = DMatrix::<f64>::zeros(dim, dim);
    for_each_entry(ocp, hess, jac_x, jac_u, active, row_weight, |i, j, v| {
        k[(i, j)] += v
    });
    k
}

#[cfg(test)]
mod tests;
