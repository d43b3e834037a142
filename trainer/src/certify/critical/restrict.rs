//! Where on a cell one candidate law can be the QP's solution ([`LawRegion`]), and the cell
//! bound that bounds each law only there ([`QpCertifier::restricted_bound`]).
//!
//! **The region of a law.** Law L = W ∪ S (y_L(x) = y₀ + Y_x x, [`AffineLaw`]) is the QP's
//! solution at x only if it is a KKT point there: its multipliers are nonnegative and every
//! row outside L is feasible,
//! ```text
//! P_L = { x ∈ B :  ν_i(x) ≥ 0 (i ∈ L),   h_r − G_r z(x) ≥ 0 (r ∉ L) },
//! ```
//! a polytope (every condition is affine in x). In the cell proof of
//! [`QpCertifier::prove`] the solution at x ∈ B is y_L(x) for one of the returned laws, and
//! then x ∈ P_L; so sup_B |κ − sat κ_NN| ≤ max_L sup_{P_L} |κ_L − sat κ_NN|, and a law whose
//! P_L is empty never is the solution on B.
//!
//! **Outer boxes, soundly.** Each condition is φ(x) = c + gᵀx ≥ 0 with c, g known only as
//! computed ĉ, ĝ: the law's coefficient errors ([`AffineLaw::delta`]) and the rounding of ĉ,
//! ĝ give |φ(x) − (ĉ + ĝᵀx)| ≤ m_c + Σ_j m_j |x_j| (bounded with the γₙ of the module
//! above). Interval constraint propagation then shrinks a box [l, u] ⊇ P_L ∩ box: for
//! ĝ_k > 0, x_k ≥ (−ĉ − M − Σ_{j≠k} max(ĝ_j l_j, ĝ_j u_j)) / ĝ_k with M the margin's
//! maximum on the box (and ≤ for ĝ_k < 0); every sum carries its rounding bound, every
//! quotient its relative rounding, always moved outward. A box emptied this way (a lower
//! bound above the upper one, or a condition whose maximum on the box is below 0 after the
//! rounding allowance) proves P_L ∩ box = ∅: the law is dropped there. No step uses a
//! tolerance that could drop a law wrongly: an uncertain comparison keeps it.
//!
//! **The restricted bound.** Each law is bounded by the exact bound of
//! [`crate::certify::local::exact_cell_bound`] on its outer box (its value at that box's
//! corners, its exact gain, the network's enclosures over that box), and where that is
//! above the goal the box is bisected and each half shrunk and bounded again (a few
//! levels): the extrapolation of a law beyond its region, which makes the whole-box bound
//! loose at a steep region boundary, shrinks with the boxes. Either bound of a box is
//! valid; the smaller is kept, and the cell's bound is the largest over the laws' boxes.

use super::{gamma, AffineLaw, QpCertifier, U};
use crate::certify::local::{exact_cell_bound, CellBound};
use crate::certify::netbounds::NetBounder;
use crate::learn::mlp::Mlp;
use std::sync::Arc;

/// Levels of bisection of a law's box in [`QpCertifier::restricted_bound`].
pub const MAX_DEPTH: usize = 6;

/// One condition ĉ + ĝᵀx ≥ −(m_c + Σ_j m_j |x_j|) of a law's region.
#[derive(Debug, Clone)]
struct Cond {
    c: f64,
    g: Vec<f64>,
    mc: f64,
    mg: Vec<f64>,
}

impl Cond {
    /// An upper bound on the margin m_c + Σ_j m_j |x_j| over the box.
    fn margin(&self, lo: &[f64], hi: &[f64]) -> f64 {
        let n = lo.len();
        let s: f64 = self.mc
            + (0..n)
                .map(|j| self.mg[j] * lo[j].abs().max(hi[j].abs()))
                .sum::<f64>();
        s * (1.0 + gamma(2 * n + 1))
    }

    /// A lower bound on min over the box of ĉ + ĝᵀx − margin (≥ 0: the condition holds on
    /// the whole box) and an upper bound on its max plus the margin (< 0: it holds nowhere).
    fn range(&self, lo: &[f64], hi: &[f64]) -> (f64, f64) {
        let n = lo.len();
        let m = self.margin(lo, hi);
        let (mut smin, mut smax, mut mag) = (self.c, self.c, self.c.abs() + m);
        for j in 0..n {
            let (a, b) = (self.g[j] * lo[j], self.g[j] * hi[j]);
            smin += a.min(b);
            smax += a.max(b);
            mag += a.abs().max(b.abs());
        }
        let e = gamma(n + 3) * mag * (1.0 + gamma(n + 3));
        (smin - m - e, smax + m + e)
    }
}

/// The conditions of a law's region P_L (see the module doc), those that hold on the whole
/// cell dropped.
#[derive(Debug, Clone)]
pub struct LawRegion {
    conds: Vec<Cond>,
}

impl LawRegion {
    /// Number of conditions that can cut the cell.
    pub fn len(&self) -> usize {
        self.conds.len()
    }

    /// Whether no condition cuts the cell (P_L is the whole cell).
    pub fn is_empty(&self) -> bool {
        self.conds.is_empty()
    }

    /// A box containing P_L ∩ [lo, hi], or `None` if that set is proven empty.
    pub fn shrink(&self, lo: &[f64], hi: &[f64]) -> Option<(Vec<f64>, Vec<f64>)> {
        let n = lo.len();
        let (mut l, mut u) = (lo.to_vec(), hi.to_vec());
        for _ in 0..8 {
            let mut moved = false;
            for cd in &self.conds {
                let (_, smax) = cd.range(&l, &u);
                // NaN: not proven empty.
                if smax < 0.0 {
                    return None;
                }
                let m = cd.margin(&l, &u);
                for k in 0..n {
                    let gk = cd.g[k];
                    if gk == 0.0 || !gk.is_finite() {
                        continue;
                    }
                    // s = −ĉ − M − Σ_{j≠k} max(ĝ_j l_j, ĝ_j u_j), ĝ_k x_k ≥ s on the set.
                    let (mut s, mut mag) = (-cd.c - m, cd.c.abs() + m);
                    for j in (0..n).filter(|&j| j != k) {
                        let t = (cd.g[j] * l[j]).max(cd.g[j] * u[j]);
                        s -= t;
                        mag += t.abs();
                    }
                    let e = gamma(n + 3) * mag * (1.0 + gamma(n + 3));
                    let q = (s - e) / gk;
                    if !q.is_finite() {
                        continue;
                    }
                    let slack = q.abs() * 4.0 * U + f64::MIN_POSITIVE;
                    let tol = 1e-9 * (hi[k] - lo[k]);
                    if gk > 0.0 {
                        let b = q - slack;
                        if b > l[k] {
                            moved |= b - l[k] > tol;
                            l[k] = b;
                        }
                    } else {
                        let b = q + slack;
                        if b < u[k] {
                            moved |= u[k] - b > tol;
                            u[k] = b;
                        }
                    }
                    if l[k] > u[k] {
                        return None;
                    }
                }
            }
            if !moved {
                break;
            }
        }
        Some((l, u))
    }
}

impl QpCertifier {
    /// The region of law `l` on the cell [lo, hi] (its conditions that may fail there).
    pub fn law_region(&self, l: &AffineLaw, lo: &[f64], hi: &[f64]) -> LawRegion {
        let (nv, ne, nx) = (self.n_var, self.n_eq, self.nx);
        let mut conds = Vec::new();
        // Multipliers: ν_a(x) = y₀ + Y_x x exactly up to the law's coefficient errors.
        for a in 0..l.set.len() {
            let p = nv + ne + a;
            conds.push(Cond {
                c: l.y0[p],
                g: (0..nx).map(|j| l.yx[(p, j)]).collect(),
                mc: l.delta[0],
                mg: l.delta[1..].to_vec(),
            });
        }
        // Rows outside the set: h_r − G_r z(x) ≥ 0.
        for (r, row) in self.rows.iter().enumerate() {
            if l.set.binary_search(&r).is_ok() {
                continue;
            }
            let gl = gamma(row.len + 1);
            let (mut c, mut cmag, mut abs_coef) = (row.rhs, row.rhs.abs(), 0.0);
            let (mut g, mut gmag) = (vec![0.0; nx], vec![0.0; nx]);
            for t in 0..row.len {
                let (i, cf) = (row.idx[t], row.coef[t]);
                c -= cf * l.y0[i];
                cmag += (cf * l.y0[i]).abs();
                abs_coef += cf.abs();
                for j in 0..nx {
                    g[j] -= cf * l.yx[(i, j)];
                    gmag[j] += (cf * l.yx[(i, j)]).abs();
                }
            }
            let mc = (abs_coef * l.delta[0] + gl * cmag) * (1.0 + gl);
            let mg = (0..nx)
                .map(|j| (abs_coef * l.delta[1 + j] + gl * gmag[j]) * (1.0 + gl))
                .collect();
            conds.push(Cond { c, g, mc, mg });
        }
        // Conditions that hold on the whole cell never cut a sub-box.
        conds.retain(|cd| cd.range(lo, hi).0.is_nan() || cd.range(lo, hi).0 < 0.0);
        LawRegion { conds }
    }

    /// The bound of the module doc on the cell [lo, hi] whose proof returned `laws`:
    /// each law bounded on outer boxes of its region, bisected up to [`MAX_DEPTH`] levels
    /// while a box's bound is above `goal`. `exact` is false (and ε infinite) if a bound is
    /// not finite or every law is proven absent (which a valid proof excludes).
    #[allow(clippy::too_many_arguments)]
    pub fn restricted_bound(
        &self,
        lo: &[f64],
        hi: &[f64],
        laws: &[Arc<AffineLaw>],
        mlp: &Mlp,
        nb: &NetBounder,
        band: (&[f64], &[f64]),
        goal: f64,
    ) -> CellBound {
        let mut out: Option<CellBound> = None;
        let ctx = Bisect {
            q: self,
            mlp,
            nb,
            band,
            goal,
            width: lo.iter().zip(hi).map(|(a, b)| b - a).collect(),
        };
        for l in laws {
            let region = self.law_region(l, lo, hi);
            let b = region
                .shrink(lo, hi)
                .and_then(|(a, b)| ctx.bound(l, &region, &a, &b, MAX_DEPTH));
            if let Some(b) = b {
                out = Some(match out {
                    None => b,
                    Some(a) => merge(a, b),
                });
            }
        }
        match out {
            Some(b) if b.eps.is_finite() => CellBound { exact: true, ..b },
            _ => exact_cell_bound(lo, hi, &[], &[], &nb.bounds(lo, hi), band, &self.u_scale),
        }
    }
}

/// The larger of two cell bounds, field by field.
fn merge(a: CellBound, b: CellBound) -> CellBound {
    CellBound::larger(a, b)
}

struct Bisect<'a> {
    q: &'a QpCertifier,
    mlp: &'a Mlp,
    nb: &'a NetBounder,
    band: (&'a [f64], &'a [f64]),
    goal: f64,
    /// The cell's widths (bisection axis: the longest side relative to them).
    width: Vec<f64>,
}

impl Bisect<'_> {
    /// The bound of law `l` on [lo, hi] (already shrunk to its region), bisected while
    /// above the goal; `None` if the law's region misses the box.
    fn bound(
        &self,
        l: &Arc<AffineLaw>,
        region: &LawRegion,
        lo: &[f64],
        hi: &[f64],
        depth: usize,
    ) -> Option<CellBound> {
        let nx = lo.len();
        let nu = self.mlp.nu();
        // The network at the corners as outward-rounded enclosures, not plain f64 values.
        let mut net_u = Vec::with_capacity(nu << nx);
        for c in 0..1usize << nx {
            let v: Vec<f64> = (0..nx)
                .map(|k| if c & (1 << k) != 0 { hi[k] } else { lo[k] })
                .collect();
            net_u.extend(self.nb.value_at(&v));
        }
        let pieces = self.q.pieces(lo, hi, std::slice::from_ref(l));
        let b = exact_cell_bound(
            lo,
            hi,
            &pieces,
            &net_u,
            &self.nb.bounds(lo, hi),
            self.band,
            &self.q.u_scale,
        );
        if depth == 0 || b.eps <= self.goal || !b.eps.is_finite() || self.hopeless(l, lo, hi) {
            return Some(b);
        }
        let axis = (0..nx).filter(|&k| self.width[k] > 0.0).max_by(|&a, &c| {
            ((hi[a] - lo[a]) / self.width[a]).total_cmp(&((hi[c] - lo[c]) / self.width[c]))
        })?;
        let mid = 0.5 * (lo[axis] + hi[axis]);
        let mut halves: Option<CellBound> = None;
        for (a, c) in [(lo[axis], mid), (mid, hi[axis])] {
            let (mut hlo, mut hhi) = (lo.to_vec(), hi.to_vec());
            hlo[axis] = a;
            hhi[axis] = c;
            let Some((slo, shi)) = region.shrink(&hlo, &hhi) else {
                continue;
            };
            if let Some(h) = self.bound(l, region, &slo, &shi, depth - 1) {
                halves = Some(match halves {
                    None => h,
                    Some(p) => merge(p, h),
                });
            }
        }
        // Both halves empty: the region misses the box (each half proven empty).
        let h = halves?;
        Some(if h.eps < b.eps { h } else { b })
    }

    /// Whether the error of law `l` at the box's centre, where the law (by its computed
    /// coefficients) holds, already exceeds the goal: then no bisection can meet it (a
    /// heuristic that only saves time; the bounds do not depend on it).
    fn hopeless(&self, l: &AffineLaw, lo: &[f64], hi: &[f64]) -> bool {
        let c: Vec<f64> = lo.iter().zip(hi).map(|(a, b)| 0.5 * (a + b)).collect();
        let region = self.q.law_region(l, &c, &c);
        if !region.is_empty() {
            return false;
        }
        let (k, _) = self.q.kappa(l, &c);
        let n = self.mlp.predict(&c);
        let e = crate::certify::local::clamped_error(&k, &n, self.band, &self.q.u_scale);
        e > self.goal
    }
}
