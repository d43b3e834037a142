//! A robust design: the ancillary LQR gain (the input weight that tightens least), its tube,
//! the tightened problem with its terminal region. The verdict of a certified ε against the
//! design ε is [`verdict`] (`robust/verdict.rs`).

use super::jacobians::*;
use super::terminal::{terminal_region, Feasibility, TerminalRegion};
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
    /// The terminal region enforced as a terminal constraint (None: none was found, and
    /// recursive feasibility is not established).
    #[serde(default)]
    pub terminal: Option<TerminalRegion>,
}

impl Design {
    /// How recursive feasibility of the hard tightened OCP is established: proven when the
    /// terminal region is enforced and the tube's ρ, w̄ and the region's ρ_f are all sound,
    /// sampled when one of them is an estimate, unknown without an enforced region.
    pub fn recursive_feasibility(&self) -> Feasibility {
        match &self.terminal {
            Some(t) if !t.enforced => Feasibility::Unknown,
            None => Feasibility::Unknown,
            Some(t) if t.proven() && self.tube.bound != JacobianBound::SampledEstimate => {
                Feasibility::Proven
            }
            Some(_) => Feasibility::Sampled,
        }
    }
}

/// Designs the tube (LQR gain of the linearisation at the setpoint — the origin without
/// one —, its Riccati matrix as P,
/// the input weight chosen from `robust.lqr_r_scales` to minimise [`Tube::score`]) or the
/// Lipschitz tightening, and tightens the bounds for `cfg.robust.eps`: the boxes and the
/// affine `[ocp]` path and terminal constraints (`tube` module doc); a nonlinear constraint
/// is refused ([`RobustError::UntightenedConstraints`]).
pub fn design(cfg: &ProblemConfig) -> Result<Design, RobustError> {
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
    let terminal = terminal_region(cfg, &tube);
    Ok(Design {
        tube,
        stages,
        terminal,
    })
}

/// The refinement's target for a design ε, as a fraction of it: the verdict counts the
/// exported controller's f32 allowance too (ε_cert + a_f32 ≤ ε_design), which is only known
/// once the net is trained — about 1e-3 N·m for the pendulum's nets — so the refinement aims
/// 1 % below the design ε.
pub const REFINE_TARGET_FRACTION: f64 = 0.99;

/// The data-generating problem of a design: `cfg` with the tightened stage bounds, named
/// `robust` (so a run goes to `DIR/<name>/robust/`), and the terminal region as its terminal
/// constraint when enforced (`robust.terminal_constraint`, which also turns on
/// `refine.exclude_infeasible`: cells outside the tightened MPC's feasible set leave the
/// certified domain). The constant bounds remain the true constraints (actuator limits and the
/// violation check of the closed loop). Its norm is the unscaled one (`x_scale`, `u_scale`
/// all 1), that of the design's ε.
pub fn robust_config(cfg: &ProblemConfig, d: &Design) -> ProblemConfig {
    let mut r = cfg.clone();
    r.name = "robust".into();
    r.ocp.stages = Some(d.stages.clone());
    // Corollary 1's tube is designed for ‖Δu‖₂ ≤ ε in physical units: the tightened
    // problem's certificates are stated in the unscaled norm, so ε is comparable with it.
    r.ocp.x_scale = Some(vec![1.0; cfg.system.nx()]);
    r.ocp.u_scale = Some(vec![1.0; cfg.system.nu()]);
    if let Some(t) = d.terminal.as_ref().filter(|t| t.enforced) {
        r.ocp.terminal_constraints.push(t.constraint.clone());
        // The terminal region shrinks the feasible set below X: certify where the
        // tightened MPC is feasible (Corollary 1 needs the bound there only), excluding
        // the cells outside it.
        r.refine.exclude_infeasible = true;
    }
    r
}
