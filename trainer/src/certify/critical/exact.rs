//! Rational arithmetic on the QP's f64 data (every f64 is a dyadic rational, so this is the
//! QP the code holds, exactly): the rows in the inputs U = (u₀, …, u_{N−1}) ([`Exact`]),
//! the dependence test of [`QpCertifier::dependent`] and the feasibility witnesses of the
//! cell proof's problem P_D at a vertex ([`QpCertifier::exact_witness`]).
//!
//! **Rows in U.** x_{k+1} = A x_k + B u_k + c from x₀ = v gives x_k = Φ_k v + T_k U + s_k
//! (Φ_k = A^k, T_k U = Σ_{j<k} A^{k−1−j} B u_j, s_k = Σ_{j<k} A^{k−1−j} c), so every row
//! aᵀ(x_k, u_k) ≤ h is
//! ```text
//! α_rᵀ U + β_r(v) ≤ h_r,   α_r = aₓᵀT_k + a_uᵀ e_{u_k},   β_r(v) = aₓᵀ(Φ_k v + s_k).
//! ```
//! **Dependence.** On {x₀ = 0} the equalities leave U free, so rows are dependent (LICQ
//! fails for W = set) iff their α_r have rank < |set|.
//!
//! **Witnesses.** The proof needs P_D(v) feasible at every vertex v: some z with the
//! dynamics from x₀ = v, the rows W as equalities and the rows D as inequalities. A law's
//! value witnesses it when its D rows hold with their f64 error bounds; but a vertex on a
//! degenerate region boundary (the double integrator's v₀ + h·Σu = v_max: five saturated
//! inputs bring the velocity exactly to its bound, so an input row and a velocity row are
//! both active and dependent) leaves a slack of the order of the data's rounding (1e-16)
//! that no f64 bound shows to be ≥ 0. Here the W rows (with some S ⊆ D) are solved as
//! equalities over Q by Gauss–Jordan elimination, the free inputs set to a law's f64 value
//! read as rationals, and the remaining D rows checked at that U exactly: `true` proves
//! P_D(v) feasible; `false` proves nothing.

use super::{AffineLaw, QpCertifier};
use num_rational::BigRational;
use num_traits::{Signed, Zero};
use std::sync::Arc;

type Q = BigRational;

fn q(v: f64) -> Q {
    Q::from_float(v).unwrap_or_else(Q::zero)
}

/// The rows in U (see the module doc), built once per certifier.
#[derive(Debug)]
pub(super) struct Exact {
    /// α_r per row (N·nu entries).
    alpha: Vec<Vec<Q>>,
    /// Per row: the (stage, state, coefficient) terms of aₓ (for β_r).
    xterms: Vec<Vec<(usize, usize, Q)>>,
    /// A (nx × nx) and c (nx), rationals.
    a: Vec<Q>,
    c: Vec<Q>,
    /// Whether the data were finite.
    finite: bool,
}

impl QpCertifier {
    fn exact_data(&self) -> &Exact {
        self.exact.get_or_init(|| {
            let (nx, nu, n) = (self.nx, self.nu, self.horizon);
            let (nz, cols) = (nx + nu, n * nu);
            let finite = self
                .a
                .iter()
                .chain(&self.b)
                .chain(&self.e0)
                .all(|v| v.is_finite())
                && self
                    .rows
                    .iter()
                    .all(|r| r.coef[..r.len].iter().all(|v| v.is_finite()));
            let a: Vec<Q> = self.a.iter().map(|&v| q(v)).collect();
            let b: Vec<Q> = self.b.iter().map(|&v| q(v)).collect();
            let c: Vec<Q> = (0..nx).map(|i| q(self.e0[nx + i])).collect();
            // T_k (nx × cols, row-major): T_0 = 0, T_{k+1} = A T_k + B e_{u_k}.
            let mut t: Vec<Vec<Q>> = vec![vec![Q::zero(); nx * cols]];
            for k in 0..n {
                let tk = &t[k];
                let mut t1 = vec![Q::zero(); nx * cols];
                for i in 0..nx {
                    for j in 0..nx {
                        let aij = &a[i * nx + j];
                        if aij.is_zero() {
                            continue;
                        }
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
                t.push(t1);
            }
            let mut alpha = Vec::with_capacity(self.rows.len());
            let mut xterms = Vec::with_capacity(self.rows.len());
            for row in &self.rows {
                let mut al = vec![Q::zero(); cols];
                let mut xt = Vec::new();
                for e in 0..row.len {
                    let (idx, cf) = (row.idx[e], q(row.coef[e]));
                    let (k, off) = (idx / nz, idx % nz);
                    if off < nx {
                        for col in 0..cols {
                            let v = &t[k][off * cols + col];
                            if !v.is_zero() {
                                al[col] += &cf * v;
                            }
                        }
                        xt.push((k, off, cf));
                    } else if k < n {
                        al[k * nu + off - nx] += cf;
                    }
                }
                alpha.push(al);
                xterms.push(xt);
            }
            Exact {
                alpha,
                xterms,
                a,
                c,
                finite,
            }
        })
    }

    /// The rank test of [`Self::dependent`]: whether the α_r of `set` have rank < |set|
    /// (Gaussian elimination over Q).
    pub(super) fn exact_rank_deficient(&self, set: &[usize]) -> bool {
        let ex = self.exact_data();
        let mut m: Vec<(Vec<Q>, Q)> = set
            .iter()
            .map(|&r| (ex.alpha[r].clone(), Q::zero()))
            .collect();
        let (rank, _) = eliminate(&mut m);
        rank < set.len()
    }

    /// Whether some S ⊆ D gives an exact witness of P_D(x) ([`Self::exact_witness`] with
    /// equalities W ∪ S and inequalities D ∖ S), the free inputs from the law of W ∪ S if
    /// among `laws`, else from W's law (`laws[0]`).
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
            let Some(l) = laws.iter().find(|l| l.set == eq).or(laws.first()) else {
                return false;
            };
            self.exact_witness(x, &eq, &ineq, &hint(l))
        })
    }

    /// Whether P_D(x) (rows `w` equalities, rows `d` inequalities, dynamics from x) is
    /// proven feasible by a point computed exactly (see the module doc); `hint` holds the
    /// inputs (N·nu, f64) the free inputs take. Non-finite data: `false`.
    pub(super) fn exact_witness(&self, x: &[f64], w: &[usize], d: &[usize], hint: &[f64]) -> bool {
        let (nx, n) = (self.nx, self.horizon);
        let cols = n * self.nu;
        let ex = self.exact_data();
        if !ex.finite
            || x.len() != nx
            || hint.len() != cols
            || x.iter().chain(hint).any(|v| !v.is_finite())
            || w.iter().chain(d).any(|&r| r >= self.rows.len())
        {
            return false;
        }
        // Φ_k v + s_k for every k.
        let mut xs: Vec<Vec<Q>> = vec![x.iter().map(|&v| q(v)).collect()];
        for k in 0..n {
            let mut x1 = ex.c.clone();
            for (i, xi) in x1.iter_mut().enumerate() {
                for j in 0..nx {
                    let aij = &ex.a[i * nx + j];
                    if !aij.is_zero() {
                        *xi += aij * &xs[k][j];
                    }
                }
            }
            xs.push(x1);
        }
        // Row r as (α_r, h_r − β_r).
        let affine = |r: usize| -> (Vec<Q>, Q) {
            let mut rhs = q(self.rows[r].rhs);
            for (k, off, cf) in &ex.xterms[r] {
                rhs -= cf * &xs[*k][*off];
            }
            (ex.alpha[r].clone(), rhs)
        };
        let mut m: Vec<(Vec<Q>, Q)> = w.iter().map(|&r| affine(r)).collect();
        let (rank, pivots) = eliminate(&mut m);
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

/// Gauss–Jordan elimination of the rows (coefficients, right-hand side) over Q: the rank
/// and the pivot columns; the first `rank` rows end in reduced form (each pivot column
/// zero but in its own row), the rest with zero coefficients.
fn eliminate(m: &mut [(Vec<Q>, Q)]) -> (usize, Vec<usize>) {
    let cols = m.first().map_or(0, |r| r.0.len());
    let mut pivots = Vec::new();
    let mut rank = 0;
    for col in 0..cols {
        if rank == m.len() {
            break;
        }
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
    }
    (rank, pivots)
}
