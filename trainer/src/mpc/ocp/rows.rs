//! The OCP's inequality rows `aᵀz ≤ h` ([`LinRow`]): state and input boxes, the path and
//! terminal constraints g(x_k, u_k) ≤ 0, and the linearisation of the nonlinear ones.
//!
//! A nonlinear constraint's row at stage k is its first-order model at the iterate z̄,
//! `∇g(z̄)ᵀ z ≤ ∇g(z̄)ᵀ z̄ − g(z̄)` (minus its slack in the soft problem), so that the row's
//! slack at z̄ is exactly −g(z̄): the QP subproblem sees the SQP linearisation, and the KKT
//! residual, the active set and the sensitivities see the true constraint. Affine
//! constraints have constant rows. Where each constraint holds:
//!
//! | constraint in | stages |
//! |---|---|
//! | states only | x₁ … x_N |
//! | inputs only | u₀ … u_{N−1} |
//! | states and inputs | (x_k, u_k), k = 1 … N−1 |
//! | `terminal_constraints` | x_N |
//!
//! A robust design's margins (`ocp.stages.margins`) lower the right-hand side of an affine
//! constraint's row per stage.
//!
//! In the soft problem every row that involves a state gets its own slack s ≥ 0
//! (`g − s ≤ 0`), as the state boxes do; input-only rows stay hard, as the input boxes.

use super::Ocp;
use crate::problem::model::expr::ConstraintSet;
use crate::problem::model::MAX_NZ;
use crate::problem::ProblemConfig;

/// Most entries of one row: a stage's `nx + nu` variables and one slack.
pub const MAX_ROW: usize = MAX_NZ + 1;

/// One linear inequality row `Σ coef·z[idx] ≤ rhs` (`len` entries).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinRow {
    /// Number of entries.
    pub len: usize,
    /// Right-hand side h.
    pub rhs: f64,
    /// Variable indices (the first `len` are meaningful).
    pub idx: [usize; MAX_ROW],
    /// Coefficients.
    pub coef: [f64; MAX_ROW],
}

impl LinRow {
    /// The row `Σ coef·z[idx] ≤ rhs` of the given entries (at most [`MAX_ROW`]).
    pub fn new(entries: &[(usize, f64)], rhs: f64) -> Self {
        let mut row = LinRow {
            len: entries.len().min(MAX_ROW),
            rhs,
            idx: [0; MAX_ROW],
            coef: [0.0; MAX_ROW],
        };
        for (j, &(i, c)) in entries.iter().take(MAX_ROW).enumerate() {
            row.idx[j] = i;
            row.coef[j] = c;
        }
        row
    }
    /// `aᵀz`.
    pub fn dot(&self, z: &[f64]) -> f64 {
        (0..self.len).map(|j| self.coef[j] * z[self.idx[j]]).sum()
    }
    /// Slack `h − aᵀz` (≥ 0 when satisfied).
    pub fn slack(&self, z: &[f64]) -> f64 {
        self.rhs - self.dot(z)
    }
}

/// A row of a nonlinear constraint: which row, stage and constraint, and how many of its
/// entries are variables (a slack entry, if any, follows them).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct NlRow {
    row: usize,
    stage: usize,
    con: usize,
    n_vars: usize,
}

/// Whether constraint `c` holds at stage `k` of a horizon `n`.
fn holds_at(
    c: &crate::problem::model::expr::ConstraintInfo,
    nx: usize,
    k: usize,
    n: usize,
) -> bool {
    if c.terminal {
        return k == n;
    }
    match (c.uses_states(nx), c.uses_inputs(nx)) {
        (true, false) => k >= 1,
        (false, true) => k < n,
        _ => k >= 1 && k < n,
    }
}

/// The rows of an OCP as built: all rows, the nonlinear ones, the indices of the rows of
/// `[ocp]` constraints (affine or not), the number of slacks.
pub(super) struct Built {
    pub(super) rows: Vec<LinRow>,
    pub(super) nl: Vec<NlRow>,
    pub(super) constraint_rows: Vec<usize>,
    pub(super) n_slack: usize,
}

/// Builds all rows of the OCP. `nw` is the
/// number of states and inputs (slacks are numbered from it).
pub(super) fn build(
    cfg: &ProblemConfig,
    cons: Option<&ConstraintSet>,
    nx: usize,
    nu: usize,
    nw: usize,
    soft: bool,
) -> Built {
    let (o, n) = (&cfg.ocp, cfg.ocp.horizon);
    let mut rows = Vec::new();
    let mut nl = Vec::new();
    let mut constraint_rows = Vec::new();
    let mut n_slack = 0;
    // Constant rows of the affine constraints: g(v) = aᵀv + g(0).
    let m = cons.map_or(0, |c| c.len());
    let (mut g0, mut jac0) = (vec![0.0; m], vec![0.0; m * (nx + nu)]);
    if let Some(c) = cons {
        c.linearize(&vec![0.0; nx], &vec![0.0; nu], &mut g0, &mut jac0);
    }
    for k in 0..=n {
        let off = k * (nx + nu);
        if k >= 1 {
            let (x_lo, x_hi) = o.x_bounds(k);
            for i in 0..nx {
                let (lo, hi) = (x_lo[i], x_hi[i]);
                if !lo.is_finite() && !hi.is_finite() {
                    continue;
                }
                if soft {
                    let s = nw + n_slack;
                    n_slack += 1;
                    if hi.is_finite() {
                        rows.push(LinRow::new(&[(off + i, 1.0), (s, -1.0)], hi));
                    }
                    if lo.is_finite() {
                        rows.push(LinRow::new(&[(off + i, -1.0), (s, -1.0)], -lo));
                    }
                    rows.push(LinRow::new(&[(s, -1.0)], 0.0));
                } else {
                    if hi.is_finite() {
                        rows.push(LinRow::new(&[(off + i, 1.0)], hi));
                    }
                    if lo.is_finite() {
                        rows.push(LinRow::new(&[(off + i, -1.0)], -lo));
                    }
                }
            }
        }
        if k < n {
            let (u_lo, u_hi) = o.u_bounds(k);
            for j in 0..nu {
                if u_hi[j].is_finite() {
                    rows.push(LinRow::new(&[(off + nx + j, 1.0)], u_hi[j]));
                }
                if u_lo[j].is_finite() {
                    rows.push(LinRow::new(&[(off + nx + j, -1.0)], -u_lo[j]));
                }
            }
        }
        let Some(cs) = cons else { continue };
        for (ci, c) in cs.items.iter().enumerate() {
            if !holds_at(c, nx, k, n) {
                continue;
            }
            let mut entries: Vec<(usize, f64)> = c
                .vars
                .iter()
                .map(|&v| (off + v, jac0[ci * (nx + nu) + v]))
                .collect();
            let n_vars = entries.len();
            let with_slack = soft && c.uses_states(nx);
            if with_slack {
                entries.push((nw + n_slack, -1.0));
            }
            if !c.affine {
                nl.push(NlRow {
                    row: rows.len(),
                    stage: k,
                    con: ci,
                    n_vars,
                });
            }
            constraint_rows.push(rows.len());
            // A robust design tightens affine constraints by a per-stage margin
            // (`robust::Tube::tighten`); nonlinear rows are re-linearised without one, and a
            // design never gives them one.
            let margin = if c.affine {
                o.constraint_margin(ci, k)
            } else {
                0.0
            };
            rows.push(LinRow::new(&entries, -g0[ci] - margin));
            if with_slack {
                rows.push(LinRow::new(&[(nw + n_slack, -1.0)], 0.0));
                n_slack += 1;
            }
        }
    }
    Built {
        rows,
        nl,
        constraint_rows,
        n_slack,
    }
}

impl Ocp {
    /// The compiled `[ocp]` constraints, if any.
    pub fn constraint_set(&self) -> Option<&ConstraintSet> {
        self.constraints.as_ref()
    }

    /// Whether some rows are nonlinear (and so depend on the linearisation point).
    pub fn has_nonlinear_rows(&self) -> bool {
        !self.nl_rows.is_empty()
    }

    /// Indices of the rows of `[ocp]` constraints (affine or not), ascending.
    pub fn constraint_rows(&self) -> &[usize] {
        &self.constraint_rows
    }

    /// Indices of the nonlinear rows.
    pub fn nonlinear_rows(&self) -> impl Iterator<Item = usize> + '_ {
        self.nl_rows.iter().map(|r| r.row)
    }

    /// `(x_k, u_k)` of stage k of z, u = 0 at the terminal stage (which has no input).
    fn stage_point<'a>(&self, z: &'a [f64], k: usize, zero_u: &'a [f64]) -> (&'a [f64], &'a [f64]) {
        let x = &z[self.ix(k)..self.ix(k) + self.nx];
        let u = if k < self.horizon {
            &z[self.iu(k)..self.iu(k) + self.nu]
        } else {
            zero_u
        };
        (x, u)
    }

    /// Calls `f(stage, rows of that stage)` for each stage that has nonlinear rows.
    fn for_nl_stages(&self, mut f: impl FnMut(usize, &[NlRow])) {
        let mut start = 0;
        while start < self.nl_rows.len() {
            let k = self.nl_rows[start].stage;
            let end = start
                + self.nl_rows[start..]
                    .iter()
                    .take_while(|r| r.stage == k)
                    .count();
            f(k, &self.nl_rows[start..end]);
            start = end;
        }
    }

    /// Re-linearises the nonlinear rows at z: afterwards `rows[r].slack(z) = −g_r(z)`.
    pub fn relinearize(&mut self, z: &[f64]) {
        let Some(cs) = self.constraints.take() else {
            return;
        };
        let (nx, nu, m) = (self.nx, self.nu, cs.len());
        let (mut g, mut jac) = (vec![0.0; m], vec![0.0; m * (nx + nu)]);
        let zero_u = vec![0.0; nu];
        let mut updates: Vec<(usize, LinRow)> = Vec::with_capacity(self.nl_rows.len());
        self.for_nl_stages(|k, rows| {
            let (x, u) = self.stage_point(z, k, &zero_u);
            cs.linearize(x, u, &mut g, &mut jac);
            for r in rows {
                let mut row = self.rows[r.row];
                let mut dot = 0.0;
                for (j, &v) in cs.items[r.con].vars.iter().enumerate().take(r.n_vars) {
                    row.coef[j] = jac[r.con * (nx + nu) + v];
                    dot += row.coef[j] * z[row.idx[j]];
                }
                row.rhs = dot - g[r.con];
                updates.push((r.row, row));
            }
        });
        for (i, row) in updates {
            self.rows[i] = row;
        }
        self.constraints = Some(cs);
    }

    /// Adds `Σ_r ν_r ∇²g_r(x_k, u_k)` of the nonlinear rows to the stage blocks (the terminal
    /// stage only in its x part).
    pub(super) fn add_constraint_curvature(&self, z: &[f64], nu: &[f64], blocks: &mut [f64]) {
        let Some(cs) = self.constraints.as_ref() else {
            return;
        };
        let (nx, nuu) = (self.nx, self.nu);
        let nz = nx + nuu;
        let zero_u = vec![0.0; nuu];
        let mut w = vec![0.0; cs.len()];
        let mut h = vec![0.0; nz * nz];
        self.for_nl_stages(|k, rows| {
            w.fill(0.0);
            for r in rows {
                w[r.con] += nu[r.row];
            }
            if w.iter().all(|&v| v == 0.0) {
                return;
            }
            let (x, u) = self.stage_point(z, k, &zero_u);
            cs.weighted_hessian(x, u, &w, &mut h);
            let size = if k < self.horizon { nz } else { nx };
            let blk = &mut blocks[k * nz * nz..(k + 1) * nz * nz];
            for i in 0..size {
                for j in 0..size {
                    blk[i * nz + j] += h[i * nz + j];
                }
            }
        });
    }

    /// Whether row `r` is the linearisation of a nonlinear constraint.
    pub fn is_nonlinear_row(&self, r: usize) -> bool {
        self.nl_rows.binary_search_by_key(&r, |q| q.row).is_ok()
    }

    /// `Σ_r max(0, g_r(z))` over all inequality rows, with the true constraint function for
    /// nonlinear rows: the inequality part of the SQP's ℓ₁ merit function.
    pub fn inequality_violation(&self, z: &[f64]) -> f64 {
        let linear: f64 = if self.nl_rows.is_empty() {
            self.rows.iter().map(|r| (-r.slack(z)).max(0.0)).sum()
        } else {
            (0..self.rows.len())
                .filter(|&r| !self.is_nonlinear_row(r))
                .map(|r| (-self.rows[r].slack(z)).max(0.0))
                .sum()
        };
        linear + self.nonlinear_violation(z)
    }

    /// `Σ_r max(0, g_r(z) − s_r)` over the nonlinear rows (s_r the row's slack variable in
    /// the soft problem).
    fn nonlinear_violation(&self, z: &[f64]) -> f64 {
        let Some(cs) = self.constraints.as_ref() else {
            return 0.0;
        };
        let zero_u = vec![0.0; self.nu];
        let mut g = vec![0.0; cs.len()];
        let mut total = 0.0;
        self.for_nl_stages(|k, rows| {
            let (x, u) = self.stage_point(z, k, &zero_u);
            cs.values(x, u, &mut g);
            for r in rows {
                let row = &self.rows[r.row];
                let s: f64 = (r.n_vars..row.len)
                    .map(|j| -row.coef[j] * z[row.idx[j]])
                    .sum();
                total += (g[r.con] - s).max(0.0);
            }
        });
        total
    }

    /// Shifts the nonlinear rows (linearised at `z`) for a second-order correction of the
    /// step `d`: `h_r −= g_r(z + d) − g_r(z) − ∇g_r(z)ᵀd`, the remainder of the
    /// linearisation, so that the row reads `∇g_r(z)ᵀd̂ ≤ −g_r(z + d) + ∇g_r(z)ᵀd` (Nocedal &
    /// Wright §18.3; affine rows have no remainder). Returns the previous right-hand sides
    /// for [`Ocp::restore_rhs`].
    pub fn shift_for_correction(&mut self, z: &[f64], d: &[f64]) -> Vec<(usize, f64)> {
        let Some(cs) = self.constraints.as_ref() else {
            return Vec::new();
        };
        let zd: Vec<f64> = z.iter().zip(d).map(|(a, b)| a + b).collect();
        let zero_u = vec![0.0; self.nu];
        let (mut g0, mut g1) = (vec![0.0; cs.len()], vec![0.0; cs.len()]);
        let mut shifts = Vec::with_capacity(self.nl_rows.len());
        self.for_nl_stages(|k, rows| {
            let (x, u) = self.stage_point(z, k, &zero_u);
            cs.values(x, u, &mut g0);
            let (x, u) = self.stage_point(&zd, k, &zero_u);
            cs.values(x, u, &mut g1);
            for r in rows {
                let row = &self.rows[r.row];
                let lin: f64 = (0..r.n_vars).map(|j| row.coef[j] * d[row.idx[j]]).sum();
                shifts.push((r.row, g1[r.con] - g0[r.con] - lin));
            }
        });
        let mut saved = Vec::with_capacity(shifts.len());
        for (i, rem) in shifts {
            saved.push((i, self.rows[i].rhs));
            self.rows[i].rhs -= rem;
        }
        saved
    }

    /// Puts back the right-hand sides saved by [`Ocp::shift_for_correction`].
    pub fn restore_rhs(&mut self, saved: &[(usize, f64)]) {
        for &(i, rhs) in saved {
            self.rows[i].rhs = rhs;
        }
    }
}
