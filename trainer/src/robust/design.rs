//! A robust design: the ancillary LQR gain (the input weight that tightens least), its tube,
//! the tightened problem, and the verdict of a certified ε against the design ε.

use super::jacobians::*;
use super::tube::*;
use super::RobustError;
use crate::problem::model::Discrete;
use crate::problem::{ProblemConfig, RobustMethod, StageBounds};
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

/// A robust design: the tube and the tightened bounds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Design {
    /// The tube.
    pub tube: Tube,
    /// The tightened OCP bounds.
    pub stages: StageBounds,
}

/// Designs the tube (LQR gain of the linearisation at the setpoint — the origin without
/// one —, its Riccati matrix as P,
/// the input weight chosen from `robust.lqr_r_scales` to minimise [`Tube::score`]) or the
/// Lipschitz tightening, and tightens the bounds for `cfg.robust.eps`. A problem with
/// `[ocp]` path or terminal constraints is refused ([`RobustError::UntightenedConstraints`]):
/// the tube tightens the boxes only.
pub fn design(cfg: &ProblemConfig) -> Result<Design, RobustError> {
    for (key, list) in [
        ("ocp.constraints", &cfg.ocp.constraints),
        ("ocp.terminal_constraints", &cfg.ocp.terminal_constraints),
    ] {
        if !list.is_empty() {
            return Err(RobustError::UntightenedConstraints { key: key.into() });
        }
    }
    let rs = &cfg.robust;
    let js = jacobian_set(cfg);
    let (nx, nu) = (cfg.system.nx(), cfg.system.nu());
    let n = cfg.ocp.horizon;
    let tube = match rs.method {
        RobustMethod::Lipschitz => Tube::new(
            &js,
            &DMatrix::zeros(nu, nx),
            &DMatrix::identity(nx, nx),
            rs.eps,
            n,
            RobustMethod::Lipschitz,
        ),
        RobustMethod::Tube => {
            let model = Discrete::new(cfg.system.clone(), cfg.ocp.ts, cfg.ocp.rk4_substeps);
            // The ancillary LQR is designed where the loop settles: the setpoint
            // (x_ref, u_ref), the origin without one (clamped into X and U).
            let (xr, ur) = (cfg.ocp.x_ref_or_origin(nx), cfg.ocp.u_ref_or_zero(nu));
            let x0: Vec<f64> = (0..nx)
                .map(|i| xr[i].clamp(cfg.domain.lo[i], cfg.domain.hi[i]))
                .collect();
            let u0: Vec<f64> = (0..nu)
                .map(|j| ur[j].clamp(cfg.ocp.u_lo[j], cfg.ocp.u_hi[j]))
                .collect();
            let (a0, b0) = linearize_at(&model, &x0, &u0);
            let q = rs
                .lqr_q
                .as_ref()
                .and_then(|m| m.to_dmatrix())
                .unwrap_or_else(|| cfg.q());
            let mut best: Option<(f64, Tube)> = None;
            for &scale in &rs.lqr_r_scales {
                let Some((p, k)) = dare(&a0, &b0, &q, &(cfg.r() * scale)) else {
                    continue;
                };
                let mut t = Tube::new(&js, &k, &p, rs.eps, n, RobustMethod::Tube);
                t.lqr_r_scale = Some(scale);
                let sc = t.score(cfg);
                if best.as_ref().is_none_or(|b| sc < b.0) {
                    best = Some((sc, t));
                }
            }
            best.ok_or_else(|| RobustError::Infeasible {
                eps: rs.eps,
                reason: "the Riccati equation of the linearisation at the setpoint has no \
                         stabilising solution for any robust.lqr_r_scales"
                    .into(),
            })?
            .1
        }
    };
    let stages = tube.tighten(cfg)?;
    Ok(Design { tube, stages })
}

/// The data-generating problem of a design: `cfg` with the tightened stage bounds, named
/// `robust` (so a run goes to `DIR/<name>/robust/`). The constant bounds remain the true
/// constraints (actuator limits and the violation check of the closed loop).
pub fn robust_config(cfg: &ProblemConfig, d: &Design) -> ProblemConfig {
    let mut r = cfg.clone();
    r.name = "robust".into();
    r.ocp.stages = Some(d.stages.clone());
    r
}

/// Whether a trained net's certified ε covers the design ε.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Verdict {
    /// The ε the MPC was made robust against.
    pub design_eps: f64,
    /// The certified ε of the net (Theorem 1, or a tighter certificate).
    pub certified_eps: f64,
    /// certified_eps ≤ design_eps: Corollary 1 applies.
    pub certified: bool,
    /// One line for humans, with the numbers.
    pub message: String,
}

/// The verdict of a certificate against a design: the hook for local certificates /
/// adaptive refinement, which only need to supply a smaller `certified_eps`.
pub fn verdict(design_eps: f64, certified_eps: f64) -> Verdict {
    let certified = certified_eps.is_finite() && certified_eps <= design_eps;
    let message = if certified {
        format!(
            "certified: ε = {certified_eps:.4} ≤ design ε = {design_eps:.4}; Corollary 1 \
             applies (closed loop stays in the robust MPC's feasible set)"
        )
    } else {
        format!(
            "NOT certified: certified ε = {certified_eps:.4} exceeds the design ε = \
             {design_eps:.4} (factor {:.1}); the closed-loop guarantee does not hold, \
             only the Monte Carlo evidence below",
            certified_eps / design_eps
        )
    };
    Verdict {
        design_eps,
        certified_eps,
        certified,
        message,
    }
}
