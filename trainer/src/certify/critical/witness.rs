//! Exact feasibility witnesses of the cell proof's problem P_D at a vertex
//! ([`QpCertifier::exact_witness`]), for vertices where no law's f64 check can decide.
//!
//! The proof of [`QpCertifier::prove`] needs P_D(v) feasible at every vertex v of the box:
//! some z with the dynamics from x₀ = v, the rows W as equalities and the rows D as
//! inequalities. A law's value there witnesses it when its D rows hold with their error
//! bounds; but a vertex on a degenerate region boundary (e.g. the double integrator's
//! v₀ + h·Σu = v_max: five saturated inputs bring the velocity exactly to its bound, so an
//! input row and a velocity row are both active and linearly dependent) leaves a slack of
//! the order of the data's rounding (1e-16) that no f64 bound can show to be ≥ 0.
//!
//! Here the witness is built in rational arithmetic from the f64 data (every f64 is a
//! dyadic rational, so this is the QP the code holds, exactly): with U = (u₀, …, u_{N−1}),
//! x_{k+1} = A x_k + B u_k + c from x₀ = v makes every row affine in U,
//! ```text
//! α_rᵀ U + β_r ≤ h_r ;
//! ```
//! the W rows are solved as equalities by Gaussian elimination over Q (the free inputs set
//! to the given f64 hint, e.g. the law of W at v, read as rationals), and the D rows are
//! checked at that U exactly. `true` proves P_D(v) feasible; `false` proves nothing.

use super::{AffineLaw, QpCertifier};
use std::sync::Arc;
use num_rational::BigRational;
use num_traits::{Signed, Zero};

type Q = BigRational;

fn q(v: f64) -> Q {
    Q::from_float(v).unwrap_or_else(Q::zero)
}

impl QpCertifier {
    /// Whether some S ⊆ D gives an exact witness of P_D(x) ([`Self::exact_witness`] with
    /// equalities W ∪ S and inequalities D ∖ S), the hint from the law of W ∪ S if among
    /// `laws`, else from each law in turn.
    pub(super) fn exact_witness_any(
        &self,
        x: &[f64],
        w: &[usize],
        d: &[usize],
        laws: &[Arc<AffineLaw>],
    ) -> bool {
        let nz = self.nx + self.nu;
        let hint = |l: &AffineLaw| -> Vec<f64> {
            let (y, _) = l.eval(x);
            (0..self.horizon * self.nu)
                .map(|i| y[(i / self.nu) * nz + self.nx + i % self.nu])
                .collect()
        };
        (0..1usize << d.len()).any(|mask| {
            let (mut eq, mut ineq) = (w.to_vec(), Vec::new());
            for (b, &r) in d.iter().enumerate() {
                if mask & (1 << b) != 0 {
                    eq.push(r);
                } else {
                    ineq.push(r);
                }
            }
            eq.sort_unstable();
            match laws.iter().find(|l| l.set == eq) {
                Some(l) => self.exact_witness(x, &eq, &ineq, &hint(l)),
                None => laws
                    .iter()
                    .any(|l| self.exact_witness(x, &eq, &ineq, &hint(l))),
            }
        })
    }

    /// Whether P_D(x) (rows `w` equalities, rows `d` inequalities, dynamics from x) is
    /// proven feasible by a point computed exactly (see the module doc); `hint` holds the
    /// inputs (N·nu, f64) the free inputs take. Non-finite data: `false`.
    pub(super) fn exact_witness(&self, x: &[f64], w: &[usize], d: &[usize], hint: &[f64]) -> bool {
        let (nx, nu, n) = (self.nx, self.nu, self.horizon);
        let nz = nx + nu;
        let cols = n * nu;
        if x.len() != nx
            || hint.len() != cols
            || x.iter().chain(hint).any(|v| !v.is_finite())
            || w.iter().chain(d).any(|&r| r >= self.rows.len())
        {
            return false;
        }
        let a: Vec<Q> = self.a.iter().map(|&v| q(v)).collect();
        let b: Vec<Q> = self.b.iter().map(|&v| q(v)).collect();
        let c: Vec<Q> = (0..nx).map(|i| q(self.e0[nx + i])).collect();
        // x_k = s[k] + T[k] U: s[k] (nx), T[k] (nx × cols, row-major).
        let mut s: Vec<Vec<Q>> = vec![x.iter().map(|&v| q(v)).collect()];
        let mut t: Vec<Vec<Q>> = vec![vec![Q::zero(); nx * cols]];
        for k in 0..n {
            let (sk, tk) = (&s[k], &t[k]);
            let mut s1 = c.clone();
            let mut t1 = vec![Q::zero(); nx * cols];
            for i in 0..nx {
                for j in 0..nx {
                    let aij = &a[i * nx + j];
                    if aij.is_zero() {
                        continue;
                    }
                    s1[i] += aij * &sk[j];
                    for col in 0..cols {
                        if !tk[j * cols + col].is_zero() {
                            t1[i * cols + col] += aij * &tk[j * cols + col];
                        }
                    }
                }
                for jj in 0..nu {
                    t1[i * cols + k * nu + jj] += &b[i * nu + jj];
                }
            }
            s.push(s1);
            t.push(t1);
        }
        // Row r as (α_r, h_r − β_r).
        let affine = |r: usize| -> (Vec<Q>, Q) {
            let row = &self.rows[r];
            let mut alpha = vec![Q::zero(); cols];
            let mut rhs = q(row.rhs);
            for e in 0..row.len {
                let (idx, cf) = (row.idx[e], q(row.coef[e]));
                let (k, off) = (idx / nz, idx % nz);
                if off < nx {
                    rhs -= &cf * &s[k][off];
                    for col in 0..cols {
                        let v = &t[k][off * cols + col];
                        if !v.is_zero() {
                            alpha[col] += &cf * v;
                        }
                    }
                } else if k < n {
                    alpha[k * nu + off - nx] += cf;
                }
            }
            (alpha, rhs)
        };
        // W rows as equalities: row echelon form over Q.
        let mut m: Vec<(Vec<Q>, Q)> = w.iter().map(|&r| affine(r)).collect();
        let mut pivots: Vec<usize> = Vec::new();
        let mut rank = 0;
        for col in 0..cols {
            let Some(p) = (rank..m.len()).find(|&i| !m[i].0[col].is_zero()) else {
                continue;
            };
            m.swap(rank, p);
            let (prow, prhs) = m[rank].clone();
            for (i, (row, rhs)) in m.iter_mut().enumerate() {
                if i == rank || row[col].is_zero() {
                    continue;
                }
                let f = &row[col] / &prow[col];
                for j in col..cols {
                    if !prow[j].is_zero() {
                        let v = &f * &prow[j];
                        row[j] -= v;
                    }
                }
                *rhs -= &f * &prhs;
            }
            pivots.push(col);
            rank += 1;
            if rank == m.len() {
                break;
            }
        }
        // A W row reduced to 0 = nonzero: inconsistent (not feasible as stated).
        if m[rank..].iter().any(|(_, r)| !r.is_zero()) {
            return false;
        }
        // Free inputs from the hint; pivots solved (reduced form: one pivot per row).
        let mut u: Vec<Q> = hint.iter().map(|&v| q(v)).collect();
        for (i, &pc) in pivots.iter().enumerate() {
            let (row, rhs) = &m[i];
            let mut v = rhs.clone();
            for j in 0..cols {
                if j != pc && !pivots.contains(&j) && !row[j].is_zero() {
                    v -= &row[j] * &u[j];
                }
            }
            u[pc] = v / &row[pc];
        }
        // D rows exactly.
        d.iter().all(|&r| {
            let (alpha, rhs) = affine(r);
            let lhs = alpha
                .iter()
                .zip(&u)
                .filter(|(a, _)| !a.is_zero())
                .fold(Q::zero(), |acc, (a, v)| acc + a * v);
            !(lhs - rhs).is_positive()
        })
    }
}
