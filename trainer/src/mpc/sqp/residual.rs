//! The KKT residual of an SQP iterate (the parts of [`KktResidual`], all ∞-norms, every fold
//! keeping a NaN), and the first non-finite quantity behind a residual that is not finite
//! ([`crate::mpc::finite`]):
//! ```text
//! stationarity = ‖∇f + ∇cᵀλ + Gᵀν‖ / max(1, ‖∇f‖)     primal = max(‖c‖, max(0, Gz − h))
//! dual = max(0, −ν) / max(1, ‖ν‖)     complementarity = max |min(ν_r, h_r − g_rᵀz)| / max(1, ‖ν‖)
//! ```

use super::{Evals, KktResidual, PrimalDual};
use crate::mpc::finite::{abs_max, first_non_finite, nan_max, Quantity};
use crate::mpc::ocp::Ocp;

/// The KKT residual of (z, λ, ν) given first-order evaluations at z.
pub(super) fn residual(ocp: &Ocp, z: &[f64], ev: &Evals, lam: &[f64], nu: &[f64]) -> KktResidual {
    let (nx, nuu, n) = (ocp.nx, ocp.nu, ocp.horizon);
    let mut r = ev.grad.clone();
    for i in 0..nx {
        r[i] += lam[i];
    }
    for k in 0..n {
        let l = &lam[(k + 1) * nx..(k + 2) * nx];
        for j in 0..nx {
            let mut s = 0.0;
            for i in 0..nx {
                s += ev.jac_x[k * nx * nx + i * nx + j] * l[i];
            }
            r[ocp.ix(k) + j] += s;
            r[ocp.ix(k + 1) + j] -= l[j];
        }
        for j in 0..nuu {
            let mut s = 0.0;
            for i in 0..nx {
                s += ev.jac_u[k * nx * nuu + i * nuu + j] * l[i];
            }
            r[ocp.iu(k) + j] += s;
        }
    }
    // Every fold keeps a NaN (`f64::max` would drop it and read a NaN residual as 0).
    let mut primal = abs_max(&ev.c);
    let nu_scale = nan_max(1.0, abs_max(nu));
    let (mut dual, mut compl) = (0.0f64, 0.0f64);
    for (row, &v) in ocp.rows.iter().zip(nu) {
        for j in 0..row.len {
            r[row.idx[j]] += row.coef[j] * v;
        }
        let s = row.slack(z);
        primal = nan_max(primal, -s);
        dual = nan_max(dual, -v);
        // (min(ν, s) with s = +∞ on a row without a bound is ν: `f64::min` is fine here
        // for s; a NaN ν or s is kept by the check below.)
        let c = if v.is_nan() || s.is_nan() {
            f64::NAN
        } else {
            v.min(s).abs()
        };
        compl = nan_max(compl, c);
    }
    let gscale = nan_max(1.0, abs_max(&ev.grad));
    KktResidual {
        stationarity: abs_max(&r) / gscale,
        primal,
        dual: dual / nu_scale,
        complementarity: compl / nu_scale,
    }
}

/// The first non-finite quantity behind a non-finite KKT residual `res` at `p`.
pub(super) fn non_finite_part(
    ocp: &Ocp,
    p: &PrimalDual,
    ev: &Evals,
    res: &KktResidual,
) -> Quantity {
    let rows: Vec<f64> = ocp.rows.iter().map(|row| row.slack(&p.z)).collect();
    // (An infinite slack is a row without a bound; only a NaN one is at fault.)
    let rows_nan = if rows.iter().any(|s| s.is_nan()) {
        &[f64::NAN][..]
    } else {
        &[][..]
    };
    // (The equations first: a cold start's states are simulated by F, so a NaN there shows
    // in z too.)
    first_non_finite([
        (Quantity::Equations, &ev.c[..]),
        (Quantity::Equations, &ev.jac_x[..]),
        (Quantity::Equations, &ev.jac_u[..]),
        (Quantity::Cost, &ev.grad[..]),
        (Quantity::Constraints, rows_nan),
        (Quantity::Solution, &p.z[..]),
        (Quantity::Multipliers, &p.lam[..]),
        (Quantity::Multipliers, &p.nu[..]),
        (
            Quantity::Stationarity,
            std::slice::from_ref(&res.stationarity),
        ),
        (
            Quantity::PrimalFeasibility,
            std::slice::from_ref(&res.primal),
        ),
        (Quantity::DualFeasibility, std::slice::from_ref(&res.dual)),
    ])
    .unwrap_or(Quantity::Complementarity)
}
