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
//! in the 2-norm.
//!
//! **Network parts (sound).** ∂_k κ_NN, ∂²_kk κ_NN and κ_NN over C are enclosed by
//! [`crate::certify::netbounds`]. The clamp: if the enclosure of κ_NN,i lies inside the band, sat is
//! the identity on C; if it lies beyond one bound, sat∘κ_NN,i is constant on C (derivatives
//! 0); otherwise the clamp may kink inside C, ∂_k sat(κ_NN) ∈ hull(J_k ∪ {0}) and only the
//! first-order form applies.
//!
//! **MPC parts (estimates, with a safety factor s).** κ is known only at solved points:
//! - range of ∂_k κ on C: the hull of the corner sensitivities ∂_k κ(v) and of the secant
//!   slopes (κ(v + w_k e_k) − κ(v))/w_k along the k-edges (by the mean-value theorem each
//!   secant is a value of ∂_k κ on its edge, so an active-set change inside C shows up in
//!   them), widened about its centre by the factor s;
//! - |∂²_kk κ| on C, only where all corners are regular hard solutions with the same
//!   strongly active set (κ is smooth where the active set is constant — assumed to hold on
//!   the whole cell): s × the largest edge difference quotient |∂_kκ(v + w_k e_k) −
//!   ∂_kκ(v)| / w_k (each is a mean of ∂²_kk κ along its edge).
//!
//! These are estimates: a region of another active set strictly inside C, touching no
//! corner, is not seen. The soundness check (`trainer refine --check`) measures how often
//! the estimated ranges miss sampled values.

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
}

impl Default for LocalSettings {
    fn default() -> Self {
        LocalSettings { safety: 2.0 }
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

/// The estimated range of ∂κ_i/∂x_k over a cell (corner sensitivities and k-edge secant
/// slopes, widened about their centre by `safety`) and the largest k-edge difference
/// quotient of ∂κ_i/∂x_k (unscaled). `wk` is the cell's width along k.
pub fn mpc_slope_estimate(
    corners: &[Corner],
    wk: f64,
    nx: usize,
    i: usize,
    k: usize,
    safety: f64,
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
    let (mid, half) = (0.5 * (kmin + kmax), 0.5 * (kmax - kmin) * safety);
    (
        Iv {
            lo: mid - half,
            hi: mid + half,
        },
        q,
    )
}

/// Where the clamp leaves κ_NN,i over the cell.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Clamp {
    Inside,
    Constant,
    Mixed,
}

/// ε_C of the box [lo, hi] with corners `corners` (corner c has x_k = hi_k iff bit k of c
/// is set), the network's outputs at the corners `net_u` (2ⁿ × nu, f64 evaluation), its
/// enclosures `net` over the box and the clamp `band`.
pub fn cell_bound(
    lo: &[f64],
    hi: &[f64],
    corners: &[Corner],
    net_u: &[f64],
    net: &BoxBounds,
    band: (&[f64], &[f64]),
    s: &LocalSettings,
) -> CellBound {
    let nx = lo.len();
    debug_assert_eq!(corners.len(), 1 << nx);
    let finite = corners
        .iter()
        .all(|c| c.u.iter().chain(c.du).all(|v| v.is_finite()));
    let smooth = corners
        .iter()
        .all(|c| c.regular && c.piece == corners[0].piece);
    let w: Vec<f64> = lo.iter().zip(hi).map(|(a, b)| b - a).collect();
    bound_with(
        lo,
        hi,
        finite,
        |c, i| corners[c].u[i],
        0.0,
        |i, k| {
            let (kr, q) = mpc_slope_estimate(corners, w[k], nx, i, k, s.safety);
            (kr, s.safety * q)
        },
        smooth,
        net_u,
        net,
        band,
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
pub fn exact_cell_bound(
    lo: &[f64],
    hi: &[f64],
    pieces: &[ExactPiece],
    net_u: &[f64],
    net: &BoxBounds,
    band: (&[f64], &[f64]),
) -> CellBound {
    let nx = lo.len();
    let mut best: Option<CellBound> = None;
    for p in pieces {
        let finite =
            p.u.iter()
                .chain(&p.gain)
                .chain(&p.gain_err)
                .chain([&p.u_err])
                .all(|v| v.is_finite());
        let b = bound_with(
            lo,
            hi,
            finite,
            |c, i| p.u[c * (p.gain.len() / nx) + i],
            p.u_err,
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
            net_u,
            net,
            band,
        );
        best = Some(match best {
            None => b,
            Some(a) => {
                let axis_terms = a
                    .axis_terms
                    .iter()
                    .zip(&b.axis_terms)
                    .map(|(x, y)| x.max(*y))
                    .collect();
                let form = if b.eps > a.eps { b.form } else { a.form };
                CellBound {
                    eps: a.eps.max(b.eps),
                    corner: a.corner.max(b.corner),
                    remainder: a.remainder.max(b.remainder),
                    form,
                    axis_terms,
                    exact: true,
                }
            }
        });
    }
    let mut b = best.unwrap_or_else(|| infinite(nx));
    b.exact = !pieces.is_empty() && b.eps.is_finite();
    b
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
    band: (&[f64], &[f64]),
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
        // Corner errors after the clamp.
        let mut e0 = 0.0f64;
        for c in 0..1usize << nx {
            let e = corner_u(c, i) - net_u[c * nu + i].clamp(blo, bhi);
            e0 = e0.max(e.abs());
        }
        e0 += corner_tol;
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
            term_a[k] = (kr.width() + jr.width()).max(0.0) * w[k] / 4.0;
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
                term_b[k] = m * w[k] * w[k] / 8.0;
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
    CellBound {
        eps: eps2.sqrt() + LABEL_TOL,
        corner: corner2.sqrt(),
        remainder: rem2.sqrt(),
        form,
        axis_terms,
        exact: false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::certify::netbounds::NetBounder;
    use crate::learn::mlp::{Activation, Mlp, Workspace};
    use crate::rng::uniform;

    /// A smooth "MPC law" with exact derivatives: κ(x) = 3 sin(x₁) + x₁x₂ + 0.5 x₂².
    fn smooth(x: &[f64]) -> (f64, [f64; 2]) {
        (
            3.0 * x[0].sin() + x[0] * x[1] + 0.5 * x[1] * x[1],
            [3.0 * x[0].cos() + x[1], x[0] + x[1]],
        )
    }
    /// A kinked law (an active-set change along x₁ + 0.3 x₂ = 0.2), saturated at ±2.
    fn kinked(x: &[f64]) -> (f64, [f64; 2], u64) {
        let s = x[0] + 0.3 * x[1] - 0.2;
        let (v, g, p) = if s > 0.0 {
            (4.0 * s, [4.0, 1.2], 1)
        } else {
            (s, [1.0, 0.3], 0)
        };
        if v > 2.0 {
            (2.0, [0.0, 0.0], 2)
        } else if v < -2.0 {
            (-2.0, [0.0, 0.0], 3)
        } else {
            (v, g, p)
        }
    }

    fn net() -> Mlp {
        Mlp::new(
            &[2, 8, 8, 1],
            Activation::Tanh,
            3,
            &[-2.0, -2.0],
            &[2.0, 2.0],
            &[-2.0],
            &[2.0],
        )
    }

    /// A test law: x ↦ (κ, ∂κ/∂x, active-set id).
    type Law = dyn Fn(&[f64]) -> (f64, [f64; 2], u64);

    /// Bounds a cell of `law`; returns (bound, max sampled |e|).
    fn check_cell(law: &Law, m: &Mlp, lo: [f64; 2], hi: [f64; 2], seed: u64) -> (CellBound, f64) {
        let nb = NetBounder::new(m);
        let band = ([-2.0], [2.0]);
        let mut us = Vec::new();
        let mut dus = Vec::new();
        let mut pieces = Vec::new();
        let mut net_u = Vec::new();
        for c in 0..4 {
            let x = [
                if c & 1 == 0 { lo[0] } else { hi[0] },
                if c & 2 == 0 { lo[1] } else { hi[1] },
            ];
            let (u, g, p) = law(&x);
            us.push([u]);
            dus.push(g);
            pieces.push(p);
            net_u.push(m.predict(&x)[0]);
        }
        let corners: Vec<Corner> = (0..4)
            .map(|c| Corner {
                u: &us[c],
                du: &dus[c],
                regular: true,
                piece: pieces[c],
            })
            .collect();
        let b = cell_bound(
            &lo,
            &hi,
            &corners,
            &net_u,
            &nb.bounds(&lo, &hi),
            (&band.0, &band.1),
            &LocalSettings::default(),
        );
        let mut worst = 0.0f64;
        let mut ws = Workspace::default();
        for s in 0..400u64 {
            let x = [
                lo[0] + (hi[0] - lo[0]) * uniform(seed, s, 0),
                lo[1] + (hi[1] - lo[1]) * uniform(seed, s, 1),
            ];
            let (mut u, mut j) = ([0.0], [0.0; 2]);
            m.eval(&x, &mut u, &mut j, &mut ws);
            worst = worst.max((law(&x).0 - u[0].clamp(-2.0, 2.0)).abs());
        }
        (b, worst)
    }

    #[test]
    fn bounds_hold_on_random_cells_of_smooth_and_kinked_laws() {
        let m = net();
        let sm = |x: &[f64]| {
            let (u, g) = smooth(x);
            (
                u.clamp(-2.0, 2.0),
                if u.abs() < 2.0 { g } else { [0.0; 2] },
                (u.abs() >= 2.0) as u64 * (1 + (u > 0.0) as u64),
            )
        };
        let mut second = 0;
        for (li, law) in [&sm as &Law, &kinked].into_iter().enumerate() {
            for cell in 0..300u64 {
                let c = [
                    -1.8 + 3.6 * uniform(40 + li as u64, cell, 0),
                    -1.8 + 3.6 * uniform(40 + li as u64, cell, 1),
                ];
                let w = [0.4, 0.1, 0.02][cell as usize % 3];
                let lo = [c[0] - w / 2.0, c[1] - w];
                let hi = [c[0] + w / 2.0, c[1] + w];
                let (b, worst) = check_cell(law, &m, lo, hi, cell);
                assert!(
                    worst <= b.eps,
                    "law {li} cell {lo:?}..{hi:?}: observed {worst} > bound {b:?}"
                );
                second += (b.form == Form::SecondOrder) as usize;
            }
        }
        assert!(
            second > 50,
            "the second-order form was used on {second} cells only"
        );
    }

    /// Centre, radius and height of the pocket of [`pocket`].
    const POCKET: ([f64; 2], f64, f64) = ([0.23, 0.21], 0.15, 5.0);

    /// A law with an interior pocket: the linear κ₀ = x₁ + 0.3x₂ (active set 0), and on the
    /// disk |x − p| < ρ another active set (1) that lifts κ by a cone H·(1 − |x − p|/ρ),
    /// touching neither the corners nor the edges of the cell [0, 0.4]². With `lift` false:
    /// κ₀ everywhere, but the active set still reported (the corner data a code would see
    /// if it used only the corners' values and sensitivities).
    fn pocket_law(x: &[f64], lift: bool) -> (f64, [f64; 2], u64) {
        let ([p0, p1], rho, h) = POCKET;
        let d = ((x[0] - p0).powi(2) + (x[1] - p1).powi(2)).sqrt();
        let (mut u, mut g) = (x[0] + 0.3 * x[1], [1.0, 0.3]);
        if lift && d < rho {
            u += h * (1.0 - d / rho);
            if d > 0.0 {
                g[0] -= h / rho * (x[0] - p0) / d;
                g[1] -= h / rho * (x[1] - p1) / d;
            }
        }
        (u, g, (d < rho) as u64)
    }

    /// The pocket inside a cell: its corners (and edges) see only κ₀, so the cell's bound
    /// equals that of κ₀ — the documented blind spot of corner data. One split, as the
    /// refinement makes while ε_C is above its target, puts a corner into the pocket, and
    /// then every child's bound covers the error sampled in it. In the child holding the
    /// pocket's apex, the corner errors plus the network's part of the remainder alone are
    /// exceeded by the samples: the bound must use the MPC's slope range on the cell (here
    /// the pocket corner's sensitivity, which sees the cone's slope; the edge secants see
    /// it too — a pocket corner with κ₀'s sensitivity would need the secants alone, not
    /// tested here) and the change of active set (first-order form).
    #[test]
    fn a_pocket_inside_a_cell_is_covered_once_a_split_puts_a_corner_in_it() {
        let m = net();
        let pocket = |x: &[f64]| pocket_law(x, true);
        let flat = |x: &[f64]| pocket_law(x, false);
        let kappa0 = |x: &[f64]| (x[0] + 0.3 * x[1], [1.0, 0.3], 0u64);
        let (parent, worst_parent) = check_cell(&pocket, &m, [0.0, 0.0], [0.4, 0.4], 5);
        let (parent0, _) = check_cell(&kappa0, &m, [0.0, 0.0], [0.4, 0.4], 5);
        assert_eq!(parent, parent0, "corner data cannot see the pocket");
        eprintln!(
            "parent cell: bound {} vs sampled max {worst_parent}",
            parent.eps
        );
        for (lo, hi) in [
            ([0.0, 0.0], [0.2, 0.2]),
            ([0.2, 0.0], [0.4, 0.2]),
            ([0.0, 0.2], [0.2, 0.4]),
            ([0.2, 0.2], [0.4, 0.4]),
        ] {
            let (b, worst) = check_cell(&pocket, &m, lo, hi, 7);
            assert_eq!(b.form, Form::FirstOrder, "{lo:?}: the active set changes");
            assert!(
                worst <= b.eps,
                "child {lo:?}..{hi:?}: sampled {worst} > bound {b:?}"
            );
            // The network's part of the first-order remainder (κ₀'s secants equal its
            // sensitivities, the active set change forces the first-order form).
            let (b0, _) = check_cell(&flat, &m, lo, hi, 7);
            let corners_only = b.corner + b0.remainder + LABEL_TOL;
            eprintln!(
                "child {lo:?}: bound {} (corner {}, remainder {}), sampled {worst}, \
                 corners only {corners_only}",
                b.eps, b.corner, b.remainder
            );
            if lo == [0.2, 0.2] {
                assert!(
                    worst > corners_only,
                    "the apex's child does not discriminate: sampled {worst} ≤ {corners_only}"
                );
            }
        }
    }

    #[test]
    fn a_non_finite_network_gets_no_bound() {
        let mut m = net();
        let (lo, hi) = ([0.1, 0.1], [0.2, 0.2]);
        let (b, _) = check_cell(&kinked, &m, lo, hi, 3);
        assert!(b.eps.is_finite());
        m.layers[0].b[0] = f64::NAN;
        let (b, _) = check_cell(&kinked, &m, lo, hi, 3);
        assert!(b.eps.is_infinite() && b.corner.is_infinite());
    }

    #[test]
    fn remainder_shrinks_quadratically_where_smooth_and_linearly_across_a_kink() {
        let m = net();
        let sm = |x: &[f64]| {
            let (u, g) = smooth(x);
            (u, g, 0u64)
        };
        let mut prev: Option<f64> = None;
        for e in 0..4 {
            let w = 0.2 / f64::powi(2.0, e);
            let (b, _) = check_cell(&sm, &m, [0.1, 0.1], [0.1 + w, 0.1 + w], 1);
            assert_eq!(b.form, Form::SecondOrder);
            if let Some(p) = prev {
                let ratio = p / b.remainder;
                assert!((3.5..4.5).contains(&ratio), "ratio {ratio}");
            }
            prev = Some(b.remainder);
        }
        // Across the kink (x₁ + 0.3x₂ = 0.2 through the cell centre): first order, ratio ≈ 2.
        let mut prev: Option<f64> = None;
        for e in 0..4 {
            let w = 0.2 / f64::powi(2.0, e);
            let (b, worst) = check_cell(
                &kinked,
                &m,
                [0.2 - w / 2.0, -w / 2.0],
                [0.2 + w / 2.0, w / 2.0],
                2,
            );
            assert_eq!(b.form, Form::FirstOrder);
            assert!(worst <= b.eps);
            if let Some(p) = prev {
                let ratio = p / b.remainder;
                assert!((1.8..2.2).contains(&ratio), "ratio {ratio}");
            }
            prev = Some(b.remainder);
        }
    }
}
