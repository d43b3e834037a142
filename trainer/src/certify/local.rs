//! The local (cell-wise) certificate: a bound ε_C on the error e = κ − sat(κ_NN) over a box
//! C whose 2ⁿ corners are labelled data points, where sat clamps the network's output to the
//! band the controller applies (the input bounds U).
//!
//! **Interpolation split.** Let I e be the multilinear interpolant of the corner errors
//! e_v = κ(v) − sat(κ_NN(v)). Then |e(x)| ≤ |I e(x)| + |e(x) − I e(x)| and |I e(x)| ≤
//! max_v |e_v| (a convex combination of the corner values). The remainder is bounded one
//! axis at a time (tensor-product interpolation, e − I₁⋯Iₙe = Σ_k I₁⋯I_{k−1}(e − I_k e),
//! and each I_j is a convex combination):
//! - **first-order form** (always valid): if ∂_k e ∈ [a_k, b_k] on C, linear interpolation
//!   along an edge of length w_k errs by at most (b_k − a_k)·w_k / 4 (g = e − I_k e vanishes
//!   at both ends and g′ = ∂_k e − s with s the edge's secant slope ∈ [a_k, b_k], so
//!   g(x) ≤ min(x(b_k − s), (w_k − x)(s − a_k)) ≤ w_k(s − a_k)(b_k − s)/(b_k − a_k) ≤
//!   w_k(b_k − a_k)/4, and the same below), so `ε_C = max_v |e_v| + Σ_k (b_k − a_k) w_k / 4`
//!   — no larger than the Lipschitz form Σ_k max|∂_k e|·w_k/2, and much smaller where ∂_k e
//!   keeps its sign;
//! - **second-order form** (where e is C² on C): if |∂²_kk e| ≤ M_k on C, the 1-D error is
//!   at most M_k w_k² / 8, so `ε_C = max_v |e_v| + Σ_k M_k w_k² / 8` — it shrinks
//!   quadratically with the cell, and only the fit at the corners remains.
//!
//! The smaller of the two is used; vector outputs are bounded per component and combined
//! in the certificate's norm (`[ocp] u_scale`, [`crate::certify::norm`]): ε_C =
//! ‖(ε_C,i / s_u,i)_i‖₂. The per-output bounds themselves do not depend on `x_scale`: under
//! z = S_x⁻¹x the slope ranges scale by s_x,k and the widths by 1/s_x,k, so every term
//! (b_k − a_k)·w_k/4 and M_k·w_k²/8 is unchanged; only the division by s_u,i and the
//! combination over outputs follow the norm (and with all scales 1 every division is
//! exact: the unscaled bound bit for bit). The per-input bound in physical units is
//! s_u,j·ε (`certificate.json`'s `epsilon_per_input`).
//!
//! **Network parts (sound).** ∂_k κ_NN, ∂²_kk κ_NN and κ_NN over C are enclosed by
//! [`crate::certify::netbounds`]. The clamp: if the enclosure of κ_NN,i lies inside the band, sat is
//! the identity on C; if it lies beyond one bound, sat∘κ_NN,i is constant on C (derivatives
//! 0); otherwise the clamp may kink inside C, ∂_k sat(κ_NN) ∈ hull(J_k ∪ {0}) and only the
//! first-order form applies.
//!
//! **MPC parts (estimates, with a safety factor s and a regional floor c).** κ is known
//! only at solved points:
//! - range of ∂_k κ on C: the hull of the corner sensitivities ∂_k κ(v), of the secant
//!   slopes (κ(v + w_k e_k) − κ(v))/w_k along the k-edges (by the mean-value theorem each
//!   secant is a value of ∂_k κ on its edge, so an active-set change inside C shows up in
//!   them) and, where solved, of the centre's sensitivity, widened about its centre by the
//!   factor s; its half-width is at least c·G_k (the **floor**), where G_k is the spread
//!   max − min of ∂_k κ over the corners and the labelled points one cell width outside
//!   them (the cell's neighbourhood, [`Regional`]), so that corners which agree do not give
//!   a zero range where the neighbourhood varies;
//! - |∂²_kk κ| on C, only where all corners are regular hard solutions with the same
//!   strongly active set (κ is smooth where the active set is constant — assumed to hold on
//!   the whole cell) and, where the centre was solved, the centre too has that active set
//!   and its value agrees with the curvature estimate (|κ(c) − Iκ(c)| ≤ Σ_k M_k w_k²/8, the
//!   interpolation error the estimate allows at the centre); otherwise the first-order form
//!   alone: M_k = max(s × the largest edge difference quotient |∂_kκ(v + w_k e_k) −
//!   ∂_kκ(v)| / w_k (each is a mean of ∂²_kk κ along its edge), c × the largest such
//!   quotient between a corner and its outward neighbour along k).
//!
//! These are estimates: a region of another active set strictly inside C, touching no
//! corner and missing the centre, is not seen. The soundness check (`trainer refine
//! --check`) samples every cell and measures how often the estimated ranges miss sampled
//! sensitivities; it fails above a stated rate and names the cells.

use crate::certify::netbounds::{BoxBounds, Iv};
use serde::{Deserialize, Serialize};

/// Accuracy allowance on the labels κ(v): the solver's KKT tolerance makes |κ̂ − κ| far
/// below this; it is added to every ε_C (a cell whose corners all saturate would otherwise
/// get ε_C = 0 while the labels themselves are only known to ~1e-8).
pub const LABEL_TOL: f64 = 1e-6;

/// Settings of the local certificate.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LocalSettings {
    /// Safety factor s ≥ 1 on the estimated MPC parts (default 2).
    pub safety: f64,
    /// Regional floor c ≥ 0 (default 0.5): the estimated range of ∂_kκ has half-width at
    /// least c·G_k and the curvature estimate is at least c·Q_k ([`Regional`]).
    pub floor: f64,
}

impl Default for LocalSettings {
    fn default() -> Self {
        LocalSettings {
            safety: 2.0,
            floor: 0.5,
        }
    }
}

/// What a cell's neighbourhood says about the MPC (per output i and axis k, row-major
/// nu × nx; empty: nothing known, no floor). Built from the cell's corners and the labelled
/// points one cell width outside them (`certify::refine`).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Regional {
    /// G_ik: the spread (max − min) of ∂_kκ_i over those points.
    pub spread: Vec<f64>,
    /// Q_ik: the largest |∂_kκ_i(v ± w_k e_k) − ∂_kκ_i(v)| / w_k over the corners v and
    /// their labelled outward neighbours along k.
    pub quotient: Vec<f64>,
}

impl Regional {
    fn at(v: &[f64], i: usize, nx: usize, k: usize) -> f64 {
        v.get(i * nx + k).copied().unwrap_or(0.0)
    }
}

/// One labelled corner of a cell.
#[derive(Debug, Clone, Copy)]
pub struct Corner<'a> {
    /// κ(v) (nu).
    pub u: &'a [f64],
    /// ∂κ/∂x at v (row-major nu × nx).
    pub du: &'a [f64],
    /// Regular hard solution (converged, not degenerate, no slack).
    pub regular: bool,
    /// Identifier of the strongly active set (equal ids: same smooth piece of κ).
    pub piece: u64,
}

/// Which bound on the interpolation remainder was the smaller.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Form {
    /// Σ_k (b_k − a_k) w_k / 4 with ∂_k e ∈ [a_k, b_k] on the cell.
    FirstOrder,
    /// Σ_k M_k w_k² / 8 (curvature).
    SecondOrder,
}

/// The bound on one cell.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CellBound {
    /// ε_C (2-norm over the outputs of the per-output bounds).
    pub eps: f64,
    /// max_v |e_v| (2-norm over the outputs).
    pub corner: f64,
    /// The remainder bound (2-norm over the outputs).
    pub remainder: f64,
    /// The form used (for the first output; the smaller remainder).
    pub form: Form,
    /// Per-axis contributions to the remainder, summed over the outputs (where to split).
    pub axis_terms: Vec<f64>,
    /// The MPC part is exact (κ proven affine piecewise on the cell, see
    /// [`exact_cell_bound`]). Not stored in checkpoints (recomputed every round).
    #[serde(skip)]
    pub exact: bool,
}

/// The estimated range of ∂κ_i/∂x_k over a cell (corner sensitivities, k-edge secant
/// slopes and the centre's sensitivity if solved, widened about their centre by the safety
/// factor, half-width at least floor·G_ik) and the curvature estimate M_ik (see the module
/// doc). `wk` is the cell's width along k.
#[allow(clippy::too_many_arguments)]
pub fn mpc_slope_estimate(
    corners: &[Corner],
    centre: Option<&Corner>,
    reg: &Regional,
    wk: f64,
    nx: usize,
    i: usize,
    k: usize,
    s: &LocalSettings,
) -> (Iv, f64) {
    let (mut kmin, mut kmax) = (f64::INFINITY, f64::NEG_INFINITY);
    let mut q = 0.0f64;
    for (c, cv) in corners.iter().enumerate() {
        let g = cv.du[i * nx + k];
        kmin = kmin.min(g);
        kmax = kmax.max(g);
        if c & (1 << k) == 0 {
            let d = &corners[c | (1 << k)];
            let sec = (d.u[i] - cv.u[i]) / wk;
            kmin = kmin.min(sec);
            kmax = kmax.max(sec);
            q = q.max((d.du[i * nx + k] - g).abs() / wk);
        }
    }
    if let Some(&g) = centre
        .and_then(|c| c.du.get(i * nx + k))
        .filter(|g| g.is_finite())
    {
        kmin = kmin.min(g);
        kmax = kmax.max(g);
    }
    let half = (0.5 * (kmax - kmin) * s.safety).max(s.floor * Regional::at(&reg.spread, i, nx, k));
    let mid = 0.5 * (kmin + kmax);
    let m = (s.safety * q).max(s.floor * Regional::at(&reg.quotient, i, nx, k));
    (
        Iv {
            lo: mid - half,
            hi: mid + half,
        },
        m,
    )
}

/// Whether a solved centre sample supports the second-order form on the cell: a regular
/// hard solution with the corners' strongly active set, whose value departs from the
/// corners' multilinear interpolant (at the centre: their mean) by at most the
/// interpolation error the curvature estimate allows there, Σ_k M_ik w_k²/8 (+ the label
/// allowance), for every output i.
pub fn centre_consistent(
    corners: &[Corner],
    centre: &Corner,
    reg: &Regional,
    w: &[f64],
    s: &LocalSettings,
) -> bool {
    let nx = w.len();
    let nu = centre.u.len();
    if !(centre.regular && centre.piece == corners[0].piece) {
        return false;
    }
    (0..nu).all(|i| {
        let mean = corners.iter().map(|c| c.u[i]).sum::<f64>() / corners.len() as f64;
        let allowed: f64 = (0..nx)
            .filter(|&k| w[k] > 0.0)
            .map(|k| {
                let (_, m) = mpc_slope_estimate(corners, None, reg, w[k], nx, i, k, s);
                m * w[k] * w[k] / 8.0
            })
            .sum();
        (centre.u[i] - mean).abs() <= allowed + 2.0 * LABEL_TOL
    })
}

/// Where the clamp leaves κ_NN,i over the cell.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Clamp {
    Inside,
    Constant,
    Mixed,
}

/// ε_C of the box [lo, hi] with corners `corners` (corner c has x_k = hi_k iff bit k of c
/// is set), the solved centre sample if any (`centre`; `None`: not checked, the corners
/// alone decide the second-order form), the neighbourhood `reg`, the network's outputs at
/// the corners `net_u` (2ⁿ × nu, f64 evaluation), its enclosures `net` over the box and the
/// clamp `band`.
#[allow(clippy::too_many_arguments)]
pub fn cell_bound(
    lo: &[f64],
    hi: &[f64],
    corners: &[Corner],
    centre: Option<&Corner>,
    reg: &Regional,
    net_u: &[f64],
    net: &BoxBounds,
    band: (&[f64], &[f64]),
    s: &LocalSettings,
    u_scale: &[f64],
) -> CellBound {
    let nx = lo.len();
    debug_assert_eq!(corners.len(), 1 << nx);
    let finite = corners
        .iter()
        .all(|c| c.u.iter().chain(c.du).all(|v| v.is_finite()));
    let w: Vec<f64> = lo.iter().zip(hi).map(|(a, b)| b - a).collect();
    let smooth = corners
        .iter()
        .all(|c| c.regular && c.piece == corners[0].piece)
        && centre.is_none_or(|c| centre_consistent(corners, c, reg, &w, s));
    bound_with(
        lo,
        hi,
        finite,
        |c, i| corners[c].u[i],
        0.0,
        |i, k| mpc_slope_estimate(corners, centre, reg, w[k], nx, i, k, s),
        smooth,
        net_u,
        net,
        (band, u_scale),
        Labels::Solved,
    )
}

/// One affine piece κ(x) = K x + k of the MPC law on a cell, known up to stated errors
/// (from [`crate::certify::critical`]): `u` its values at the 2ⁿ corners (2ⁿ × nu, f64),
/// `u_err` a bound on |κ_true(v) − u_v| at every corner, `gain` = K̂ (nu × nx) and
/// `gain_err[k]` a bound on |K_ik − K̂_ik|.
#[derive(Debug, Clone, PartialEq)]
pub struct ExactPiece {
    /// κ̂ at the corners (2ⁿ × nu).
    pub u: Vec<f64>,
    /// Bound on the error of every corner value.
    pub u_err: f64,
    /// K̂, row-major nu × nx.
    pub gain: Vec<f64>,
    /// Bound on the error of K̂'s column k, per k.
    pub gain_err: Vec<f64>,
}

/// ε_C of a cell on which κ is, at every point, one of the affine `pieces` (proven by
/// [`crate::certify::critical`]): the MPC part is exact — ∂_k κ of a piece is the point
/// K_ik (± its rounding bound) and ∂²κ = 0 — so ε_C = max over pieces of the bound of
/// |κ_piece − sat(κ_NN)| over the whole box (each piece is bounded on the whole cell, a
/// superset of where it holds). Empty `pieces`: no bound (∞).
///
/// Nothing in it is an f64 value taken on trust: the network's corner values `net_u`
/// (2ⁿ × nu) are outward-rounded enclosures ([`NetBounder::value_at`](crate::certify::netbounds::NetBounder::value_at));
/// as sat is 1-Lipschitz, |κ(v) − sat(κ_NN(v))| ≤ |κ̂_v − sat(m_v)| + ρ + δ_u with m_v the
/// enclosure's midpoint, ρ the largest enclosure radius and δ_u the piece's verified corner
/// error (the QP solve's verified residual bound, [`ExactPiece::u_err`]) — the label
/// tolerance, in place of the constant [`LABEL_TOL`] of solved labels; and the bound's own
/// arithmetic (sums, products and the root of non-negative terms, a few dozen operations)
/// is rounded up by a relative 10⁻¹² (far above its γ_n) plus 10⁻³⁰⁰.
pub fn exact_cell_bound(
    lo: &[f64],
    hi: &[f64],
    pieces: &[ExactPiece],
    net_u: &[Iv],
    net: &BoxBounds,
    band: (&[f64], &[f64]),
    u_scale: &[f64],
) -> CellBound {
    let nx = lo.len();
    let mid: Vec<f64> = net_u.iter().map(|v| 0.5 * (v.lo + v.hi)).collect();
    let mut rad = 0.0f64;
    for (v, m) in net_u.iter().zip(&mid) {
        let r = (v.hi - m).max(m - v.lo);
        rad = if r.is_nan() {
            f64::INFINITY
        } else {
            rad.max(r)
        };
    }
    let rad = rad * (1.0 + 4.0 * f64::EPSILON);
    let mut best: Option<CellBound> = None;
    for p in pieces {
        let finite =
            p.u.iter()
                .chain(&p.gain)
                .chain(&p.gain_err)
                .chain([&p.u_err, &rad])
                .all(|v| v.is_finite());
        let b = bound_with(
            lo,
            hi,
            finite,
            |c, i| p.u[c * (p.gain.len() / nx) + i],
            p.u_err + rad,
            |i, k| {
                let g = p.gain[i * nx + k];
                let d = p.gain_err[k];
                (
                    Iv {
                        lo: g - d,
                        hi: g + d,
                    },
                    0.0,
                )
            },
            true,
            &mid,
            net,
            (band, u_scale),
            Labels::Verified,
        );
        best = Some(match best {
            None => b,
            Some(a) => CellBound::larger(a, b),
        });
    }
    let mut b = best.unwrap_or_else(|| infinite(nx));
    b.exact = !pieces.is_empty() && b.eps.is_finite();
    b
}

/// s_u,i of the certificate's norm (1 where `u_scale` has no entry: unscaled).
pub fn scale_of(u_scale: &[f64], i: usize) -> f64 {
    u_scale.get(i).copied().unwrap_or(1.0)
}

/// [`LABEL_TOL`] in the certificate's norm: LABEL_TOL / min_i s_u,i (LABEL_TOL unscaled).
pub fn label_tol(u_scale: &[f64]) -> f64 {
    let m = u_scale.iter().copied().fold(f64::INFINITY, f64::min);
    if m.is_finite() {
        LABEL_TOL / m
    } else {
        LABEL_TOL
    }
}

/// The clamped error in the certificate's norm, ‖S_u⁻¹(κ − sat(κ_NN))‖₂, of a label `u`
/// and the network's output `un` clamped to `band` (`u_scale` empty: unscaled). With all
/// scales 1 it is the unscaled 2-norm bit for bit (division by 1 is exact).
pub fn clamped_error(u: &[f64], un: &[f64], band: (&[f64], &[f64]), u_scale: &[f64]) -> f64 {
    u.iter()
        .zip(un)
        .enumerate()
        .map(|(r, (a, n))| ((a - n.clamp(band.0[r], band.1[r])) / scale_of(u_scale, r)).powi(2))
        .sum::<f64>()
        .sqrt()
}

fn infinite(nx: usize) -> CellBound {
    CellBound {
        eps: f64::INFINITY,
        corner: f64::INFINITY,
        remainder: f64::INFINITY,
        form: Form::FirstOrder,
        axis_terms: vec![f64::INFINITY; nx],
        exact: false,
    }
}

/// How the corner values of the MPC are known.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Labels {
    /// Solved labels: known to the solver's tolerance, covered by [`LABEL_TOL`].
    Solved,
    /// Values of a proven affine piece with a verified error bound (in `corner_tol`): no
    /// constant is added, the bound's own rounding is covered instead.
    Verified,
}

/// The bound of the module doc with the MPC part given: `corner_u(c, i)` = κ_i at corner
/// c (known to ± `corner_tol`), `slope(i, k)` = (range of ∂_k κ_i on the cell, bound on
/// |∂²_kk κ_i| on it), `smooth`: κ is C² on the cell (the second-order form may be used).
#[allow(clippy::too_many_arguments)]
fn bound_with(
    lo: &[f64],
    hi: &[f64],
    mpc_finite: bool,
    corner_u: impl Fn(usize, usize) -> f64,
    corner_tol: f64,
    slope: impl Fn(usize, usize) -> (Iv, f64),
    smooth: bool,
    net_u: &[f64],
    net: &BoxBounds,
    (band, u_scale): ((&[f64], &[f64]), &[f64]),
    labels: Labels,
) -> CellBound {
    let nx = lo.len();
    let nu = net.value.len();
    let w: Vec<f64> = lo.iter().zip(hi).map(|(a, b)| b - a).collect();
    // A non-finite network output or enclosure (a diverged net) or label: no bound.
    let finite = net_u.iter().all(|v| v.is_finite())
        && net
            .value
            .iter()
            .all(|v| v.lo.is_finite() && v.hi.is_finite())
        && net.jac.iter().all(|v| v.lo.is_finite() && v.hi.is_finite())
        && mpc_finite;
    if !finite {
        return infinite(nx);
    }
    let mut axis_terms = vec![0.0; nx];
    let (mut corner2, mut rem2, mut eps2) = (0.0, 0.0, 0.0);
    let mut form = Form::FirstOrder;
    for i in 0..nu {
        let (blo, bhi) = (band.0[i], band.1[i]);
        let si = scale_of(u_scale, i);
        // Corner errors after the clamp.
        let mut e0 = 0.0f64;
        for c in 0..1usize << nx {
            let e = corner_u(c, i) - net_u[c * nu + i].clamp(blo, bhi);
            e0 = e0.max(e.abs());
        }
        // In the certificate's norm: output i divided by s_u,i (exact for s_u,i = 1).
        e0 = (e0 + corner_tol) / si;
        let v = net.value[i];
        let clamp = if v.lo > blo && v.hi < bhi {
            Clamp::Inside
        } else if v.lo >= bhi || v.hi <= blo {
            Clamp::Constant
        } else {
            Clamp::Mixed
        };
        let mut term_a = vec![0.0; nx];
        let mut term_b = vec![0.0; nx];
        let mut b_ok = smooth && clamp != Clamp::Mixed;
        for k in 0..nx {
            if w[k] <= 0.0 {
                continue;
            }
            let (kr, sq) = slope(i, k);
            let j = net.jac[i * nx + k];
            let jr = match clamp {
                Clamp::Inside => j,
                Clamp::Constant => Iv { lo: 0.0, hi: 0.0 },
                Clamp::Mixed => Iv {
                    lo: j.lo.min(0.0),
                    hi: j.hi.max(0.0),
                },
            };
            // ∂_k e ∈ [kr.lo − jr.hi, kr.hi − jr.lo]: the interpolation error along an edge
            // is at most (width of that range)·w_k/4 (see the module doc).
            term_a[k] = (kr.width() + jr.width()).max(0.0) * w[k] / 4.0 / si;
            if b_ok {
                let h = match (clamp, &net.hess_diag) {
                    (Clamp::Constant, _) => 0.0,
                    (_, Some(h)) if h[i * nx + k].mag().is_finite() => h[i * nx + k].mag(),
                    _ => {
                        b_ok = false;
                        0.0
                    }
                };
                let m = sq + h;
                term_b[k] = m * w[k] * w[k] / 8.0 / si;
            }
        }
        let ra: f64 = term_a.iter().sum();
        let rb: f64 = if b_ok {
            term_b.iter().sum()
        } else {
            f64::INFINITY
        };
        let (r, terms) = if rb < ra {
            if i == 0 {
                form = Form::SecondOrder;
            }
            (rb, &term_b)
        } else {
            (ra, &term_a)
        };
        for (a, t) in axis_terms.iter_mut().zip(terms) {
            *a += t;
        }
        corner2 += e0 * e0;
        rem2 += r * r;
        eps2 += (e0 + r) * (e0 + r);
    }
    let eps = match labels {
        Labels::Solved => eps2.sqrt() + label_tol(u_scale),
        Labels::Verified => eps2.sqrt() * (1.0 + 1e-12) + 1e-300,
    };
    CellBound {
        eps,
        corner: corner2.sqrt(),
        remainder: rem2.sqrt(),
        form,
        axis_terms,
        exact: false,
    }
}

#[cfg(test)]
mod tests;

impl CellBound {
    /// The larger of two cell bounds, field by field (the form of the larger ε; exact only
    /// if both are).
    pub(crate) fn larger(a: CellBound, b: CellBound) -> CellBound {
        let form = if b.eps > a.eps { b.form } else { a.form };
        CellBound {
            eps: a.eps.max(b.eps),
            corner: a.corner.max(b.corner),
            remainder: a.remainder.max(b.remainder),
            form,
            axis_terms: a
                .axis_terms
                .iter()
                .zip(&b.axis_terms)
                .map(|(x, y)| x.max(*y))
                .collect(),
            exact: a.exact && b.exact,
        }
    }
}
