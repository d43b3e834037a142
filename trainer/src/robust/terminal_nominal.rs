//! The **nominal terminal ingredients** of the safety-augmented controller (issue 41 §4):
//! the terminal set, terminal controller and terminal cost for the *nominal* model (no tube,
//! no input error), used by `controller_core::safe` when the robust design has no region.
//!
//! ```text
//! X_f = { x : (x − x_r)ᵀP_f(x − x_r) ≤ α },   κ_f(x) = u_r + K (x − x_r),   V_f(x) = (x − x_r)ᵀP_f(x − x_r)
//! (i)   κ_f(x) ∈ U, x ∈ X and every `[ocp]` constraint g(x, κ_f(x)) ≤ 0     on X_f
//! (ii)  V_f(F(x, κ_f(x))) − V_f(x) ≤ −ℓ(x, κ_f(x))                            on X_f
//! ```
//! (ii) implies invariance: V_f(F) ≤ V_f(x) − ℓ ≤ α. K is the LQR gain of the linearisation
//! (A, B) of F at (x_r, u_r) with the OCP's Q, R (discrete Riccati equation, `tube::dare`,
//! P_d its solution). P_f is one of two candidates:
//! - the OCP's terminal weight P (then the online cost is the MPC's own), or
//! - λ·P_d with λ = [`LAMBDA`]: for the linearisation
//!   `(A + BK)ᵀ λP_d (A + BK) − λP_d = −λ(Q + KᵀRK)`, so (ii) holds with the slack
//!   `(λ − 1)(Q + KᵀRK)` that absorbs the nonlinear remainder on a small enough set.
//!
//! For each candidate the level is the largest α = c², c from `c_max · 0.8^k` (k < 60), with
//! c_max from (i) on the boxes and affine constraints — exact support functions
//! `σ_i c = c·√((P_f⁻¹)_ii)`, `τ_j c = c·√(K_j P_f⁻¹ K_jᵀ)`, `c·‖P_f^{−1/2}(aₓ + Kᵀa_u)‖₂`
//! (f64, not rounding-proven) — such that (ii) and the nonlinear `[ocp]` constraints hold on
//! `samples` seeded points of X_f (half on its boundary, half uniform in it). The candidate
//! with the larger set volume (α^{n/2}/√det P_f) wins.
//!
//! **Tier** ([`NominalTerminal::tier`]): `sampled` (with the number of points) when (ii) held
//! on every sample; there is no `proven` tier yet — no interval or Lipschitz bound of the
//! remainder F(x, κ_f(x)) − x_r − (A + BK)(x − x_r) is computed for expression plants — and
//! `None` (not established) is returned when no level passes. The online check must use
//! this P_f as its terminal cost: (ii) was checked for it and no other.

use super::jacobians::linearize_at;
use super::tube::dare;
use crate::problem::model::Discrete;
use crate::problem::ProblemConfig;
use crate::rng::uniform;
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// The scale λ of the Riccati matrix in the second candidate P_f = λ·P_d.
pub const LAMBDA: f64 = 2.0;

/// Seeded points of X_f on which (ii) and the nonlinear constraints are checked.
pub const NOMINAL_SAMPLES: usize = 10_000;

/// Which matrix the terminal cost is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TerminalCostSource {
    /// The OCP's terminal weight `ocp.p`.
    OcpP,
    /// λ times the Riccati matrix of the linearisation at (x_r, u_r).
    ScaledRiccati,
}

/// The nominal terminal ingredients (module doc).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NominalTerminal {
    /// Centre x_r (the setpoint clamped into the domain).
    pub x_ref: Vec<f64>,
    /// Input at the centre u_r (clamped into U).
    pub u_ref: Vec<f64>,
    /// P_f: the terminal set's matrix and the terminal cost V_f.
    pub p: Vec<Vec<f64>>,
    /// K: κ_f(x) = u_r + K(x − x_r).
    pub k: Vec<Vec<f64>>,
    /// Level α.
    pub alpha: f64,
    /// Largest radius allowed by (i) on the boxes and affine constraints.
    pub radius_max: f64,
    /// Where P_f comes from.
    pub cost: TerminalCostSource,
    /// Points of X_f on which (ii) was checked.
    pub samples: usize,
    /// The largest V_f(F) − V_f + ℓ over those points (≤ 0).
    pub decrease_worst: f64,
}

impl NominalTerminal {
    /// The tier of (ii) and invariance: always `"sampled"` (module doc).
    pub fn tier(&self) -> &'static str {
        "sampled"
    }
}

fn rows(m: &DMatrix<f64>) -> Vec<Vec<f64>> {
    (0..m.nrows())
        .map(|i| m.row(i).iter().copied().collect())
        .collect()
}

fn quad(m: &DMatrix<f64>, d: &[f64]) -> f64 {
    let v = DVector::from_column_slice(d);
    (v.transpose() * m * &v)[(0, 0)]
}

/// The centre: the setpoint clamped into the domain and the input box.
fn centre(cfg: &ProblemConfig) -> (Vec<f64>, Vec<f64>) {
    let (nx, nu) = (cfg.system.nx(), cfg.system.nu());
    let (xr, ur) = (cfg.ocp.x_ref_or_origin(nx), cfg.ocp.u_ref_or_zero(nu));
    (
        (0..nx)
            .map(|i| xr[i].clamp(cfg.domain.lo[i], cfg.domain.hi[i]))
            .collect(),
        (0..nu)
            .map(|j| ur[j].clamp(cfg.ocp.u_lo[j], cfg.ocp.u_hi[j]))
            .collect(),
    )
}

/// The largest c with (i) on the boxes and the affine `[ocp]` constraints (exact support
/// functions in f64); `NEG_INFINITY` when the centre itself violates one.
fn radius_max(cfg: &ProblemConfig, p: &DMatrix<f64>, k: &DMatrix<f64>) -> f64 {
    let (xr, ur) = centre(cfg);
    let Some(pinv) = p.clone().try_inverse() else {
        return f64::NEG_INFINITY;
    };
    let o = &cfg.ocp;
    let mut c = f64::INFINITY;
    let mut fit = |at: f64, lo: f64, hi: f64, per: f64| {
        let room = (at - lo).min(hi - at);
        if room < 0.0 || room.is_nan() || per.is_nan() {
            c = f64::NEG_INFINITY;
        } else if per > 0.0 {
            c = c.min(room / per);
        }
    };
    for i in 0..xr.len() {
        fit(xr[i], o.x_lo[i], o.x_hi[i], pinv[(i, i)].max(0.0).sqrt());
    }
    for j in 0..ur.len() {
        let kj = k.row(j);
        let per = (kj * &pinv * kj.transpose())[(0, 0)].max(0.0).sqrt();
        fit(ur[j], o.u_lo[j], o.u_hi[j], per);
    }
    if let Ok(Some(cs)) = cfg.constraint_set() {
        let (nx, nu) = (cs.nx(), cs.nu());
        let (mut g0, mut jac) = (vec![0.0; cs.len()], vec![0.0; cs.len() * (nx + nu)]);
        cs.linearize(&vec![0.0; nx], &vec![0.0; nu], &mut g0, &mut jac);
        for (i, item) in cs.items.iter().enumerate() {
            if !item.affine {
                continue; // checked on the samples
            }
            let row = &jac[i * (nx + nu)..(i + 1) * (nx + nu)];
            let v = DVector::from_fn(nx, |a, _| {
                row[a] + (0..nu).map(|j| k[(j, a)] * row[nx + j]).sum::<f64>()
            });
            let per = (v.transpose() * &pinv * &v)[(0, 0)].max(0.0).sqrt();
            let at: f64 = (0..nx).map(|a| row[a] * xr[a]).sum::<f64>()
                + (0..nu).map(|j| row[nx + j] * ur[j]).sum::<f64>();
            fit(at, f64::NEG_INFINITY, -g0[i], per);
        }
    }
    c
}

/// Seeded points with ‖x − x_r‖_{P_f} = c·t: t = 1 for even n (the boundary), t = s^{1/n}
/// (uniform in the ellipsoid) for odd n, through the Cholesky factor P_f = LLᵀ.
pub fn set_points(p: &DMatrix<f64>, xr: &[f64], c: f64, n: usize, seed: u64) -> Vec<Vec<f64>> {
    let nx = xr.len();
    let Some(ch) = p.clone().cholesky() else {
        return vec![];
    };
    let lt = ch.l().transpose();
    (0..n as u64)
        .filter_map(|s| {
            // Gaussian-free direction: uniform in the cube, normalised (covers all
            // directions; not uniform on the sphere, which the check does not need).
            let w: Vec<f64> = (0..nx)
                .map(|i| 2.0 * uniform(seed, s, i as u64) - 1.0)
                .collect();
            let norm = w.iter().map(|v| v * v).sum::<f64>().sqrt().max(1e-300);
            let t = if s % 2 == 0 {
                1.0
            } else {
                uniform(seed ^ 0x51, s, 0).powf(1.0 / nx as f64)
            };
            let w = DVector::from_iterator(nx, w.iter().map(|v| v * c * t / norm));
            let d = lt.solve_upper_triangular(&w)?;
            Some((0..nx).map(|i| xr[i] + d[i]).collect())
        })
        .collect()
}

/// The largest V_f(F(x, κ_f)) − V_f(x) + ℓ(x, κ_f) over the points (NaN if any is NaN) and
/// whether every nonlinear `[ocp]` constraint holds at (x, κ_f(x)) on all of them.
fn check_points(
    cfg: &ProblemConfig,
    p: &DMatrix<f64>,
    k: &DMatrix<f64>,
    pts: &[Vec<f64>],
) -> (f64, bool) {
    let (xr, ur) = centre(cfg);
    let (nx, nu) = (xr.len(), ur.len());
    let (xs, us) = (cfg.ocp.x_ref_or_origin(nx), cfg.ocp.u_ref_or_zero(nu));
    let (q, r) = (cfg.q(), cfg.r());
    let model = Discrete::new(cfg.system.clone(), cfg.ocp.ts, cfg.ocp.rk4_substeps);
    let cs = cfg.constraint_set().ok().flatten();
    let (mut g, mut scratch) = (vec![0.0; cs.as_ref().map_or(0, |c| c.len())], Vec::new());
    let mut ok = true;
    let mut worst = f64::NEG_INFINITY;
    let mut xp = vec![0.0; nx];
    for x in pts {
        let d: Vec<f64> = (0..nx).map(|i| x[i] - xr[i]).collect();
        let u: Vec<f64> = (0..nu)
            .map(|j| ur[j] + (0..nx).map(|i| k[(j, i)] * d[i]).sum::<f64>())
            .collect();
        model.step(x, &u, &mut xp);
        let dp: Vec<f64> = (0..nx).map(|i| xp[i] - xr[i]).collect();
        let ex: Vec<f64> = (0..nx).map(|i| x[i] - xs[i]).collect();
        let eu: Vec<f64> = (0..nu).map(|j| u[j] - us[j]).collect();
        let v = quad(p, &dp) - quad(p, &d) + quad(&q, &ex) + quad(&r, &eu);
        worst = if v.is_nan() || worst.is_nan() {
            f64::NAN
        } else {
            worst.max(v)
        };
        if let Some(cs) = &cs {
            cs.eval(x, &u, &mut g, &mut scratch);
            for (gi, item) in g.iter().zip(&cs.items) {
                if !item.affine && (gi.is_nan() || *gi > 0.0) {
                    ok = false;
                }
            }
        }
    }
    (worst, ok)
}

/// The nominal terminal ingredients of `cfg` (module doc), or None when neither candidate
/// admits a level (not established).
pub fn nominal_terminal(cfg: &ProblemConfig, samples: usize) -> Option<NominalTerminal> {
    let (xr, ur) = centre(cfg);
    let nx = xr.len();
    let model = Discrete::new(cfg.system.clone(), cfg.ocp.ts, cfg.ocp.rk4_substeps);
    let (a, b) = linearize_at(&model, &xr, &ur);
    let (pd, k) = dare(&a, &b, &cfg.q(), &cfg.r())?;
    let mut best: Option<(f64, NominalTerminal)> = None;
    for (source, p) in [
        (TerminalCostSource::OcpP, cfg.p()),
        (TerminalCostSource::ScaledRiccati, &pd * LAMBDA),
    ] {
        let cmax = radius_max(cfg, &p, &k);
        if !cmax.is_finite() || cmax <= 0.0 {
            continue;
        }
        let mut c = cmax;
        for _ in 0..60 {
            let pts = set_points(&p, &xr, c, samples, 0x7e4f);
            let (worst, ok) = check_points(cfg, &p, &k, &pts);
            if pts.len() == samples && ok && worst <= 0.0 {
                let alpha = c * c;
                let volume = alpha.powf(nx as f64 / 2.0) / p.determinant().max(1e-300).sqrt();
                if best.as_ref().is_none_or(|(v, _)| volume > *v) {
                    best = Some((
                        volume,
                        NominalTerminal {
                            x_ref: xr.clone(),
                            u_ref: ur.clone(),
                            p: rows(&p),
                            k: rows(&k),
                            alpha,
                            radius_max: cmax,
                            cost: source,
                            samples,
                            decrease_worst: worst,
                        },
                    ));
                }
                break;
            }
            c *= 0.8;
        }
    }
    best.map(|b| b.1)
}

#[cfg(test)]
#[path = "terminal_nominal_tests.rs"]
mod tests;

/// The terminal controller's gain K of the safety-augmented controller of `cfg`, chosen as
/// `deploy::plant_rs_safe` chooses it: the robust design's ancillary gain when the design
/// has a terminal region, else the nominal ingredients' gain ([`nominal_terminal`]); None
/// when neither exists. The sequence net's feedback form is trained with it.
pub fn safe_terminal_gain(cfg: &ProblemConfig) -> Option<Vec<Vec<f64>>> {
    if let Ok(d) = super::design::design(cfg) {
        if d.terminal.is_some() {
            return Some(d.tube.k.clone());
        }
    }
    nominal_terminal(cfg, NOMINAL_SAMPLES).map(|t| t.k)
}
