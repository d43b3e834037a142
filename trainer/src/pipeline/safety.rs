//! The closed-loop stage's safety study (`[closed_loop] safety = true`): the exported model's
//! sequence net as the candidate source of the device's safe controller, emulated at runtime
//! dimensions (`deploy::safe_emulation`), run by `study::safety`; its result goes into
//! `closed_loop.json` (top-level `safe`, `plain`, `mpc` and `safety`: `study::scenarios`);
//! and [`labelling_problem`], the problem whose MPC imposes the device's online check
//! (`problem::online_check`): with it the MPC's own sequence passes the check wherever its
//! OCP is feasible, the consistency of Hose et al.'s method.
//!
//! ```text
//! check:  (x_N − x_r)ᵀP_f(x_N − x_r) ≤ α(1 − m_f),  x_k ∈ box ⊖ m_s·S_x (k < N),  x_N ∈ box ⊖ m_f·S_x
//! MPC:    (x_N − x_r)ᵀP_f(x_N − x_r) ≤ α(1 − m_f − δ),  box ⊖ (m_s + δ)·S_x,  box ⊖ (m_f + δ)·S_x,
//!         terminal cost V_f of the check,  δ = CHECK_SLACK
//! ```

use super::{fail, PipelineError, Stage};
use crate::certify::Model;
use crate::deploy::plant_rs_safe::TerminalSource;
use crate::deploy::safe_emulation::{EmulatedPlant, EmulatedSequenceNet};
use crate::problem::{OnlineCheck, ProblemConfig};
use crate::study::safety::{safety_study as study, SafetyStudy};

/// δ: what the MPC's terminal set and state box keep beyond the check's margins (relative to
/// α, and in units of S_x): it covers the SQP's constraint tolerance and the f32 rounding of
/// the sequence handed to `init_with`, so that a sequence the MPC finds feasible passes the
/// f32 check.
pub const CHECK_SLACK: f64 = 1e-3;

/// The problem the pipeline labels, trains and studies: `cfg` itself, unless
/// `closed_loop.safety` and `closed_loop.safety_terminal` are set and `ocp.online_check` is
/// absent — then `cfg` with `ocp.online_check` filled from the generated safe plant of `cfg`
/// (its terminal set P_f, α and centre, its terminal cost V_f, its margins m_s, m_f; module
/// doc). The device's plant is generated from the problem without the block (the block is
/// read by the MPC only), so the check is the same for both. An error names the plant the
/// generator refuses.
pub fn labelling_problem(cfg: &ProblemConfig) -> Result<ProblemConfig, PipelineError> {
    let c = &cfg.closed_loop;
    if !(c.safety && c.safety_terminal) || cfg.ocp.online_check.is_some() {
        return Ok(cfg.clone());
    }
    let (plant, g) = EmulatedPlant::new(cfg)
        .map_err(|e| fail("setup", format!("closed_loop.safety_terminal: {e}")))?;
    let (m_s, m_f) = (
        f64::from(plant.margins.0).max(0.0),
        f64::from(plant.margins.1).max(0.0),
    );
    let (centre, terminal_cost) = match &g.terminal {
        TerminalSource::Robust(t) => {
            let p = cfg.p();
            let nx = cfg.system.nx();
            let rows = (0..nx)
                .map(|i| (0..nx).map(|j| p[(i, j)]).collect())
                .collect();
            (t.x_ref.clone(), rows)
        }
        TerminalSource::Nominal(t) => (t.x_ref.clone(), t.p.clone()),
    };
    let scale = cfg.ocp.x_scale_or_default(&cfg.domain.lo, &cfg.domain.hi);
    let margin = |m: f64| scale.iter().map(|s| (m + CHECK_SLACK) * s).collect();
    let mut out = cfg.clone();
    out.ocp.online_check = Some(OnlineCheck {
        centre,
        p_f: g.p_f.clone(),
        alpha: g.terminal.alpha() * (1.0 - m_f - CHECK_SLACK),
        terminal_cost,
        stage_box_margin: margin(m_s),
        terminal_box_margin: margin(m_f),
    });
    out.validate()
        .map_err(|e| fail("setup", format!("closed_loop.safety_terminal: {e}")))?;
    Ok(out)
}

/// The study for `model` (the regularized net, the one the run exports by default) when
/// `closed_loop.safety` is set; an error names the missing sequence net or the plant the
/// generator refuses.
pub(super) fn safety_study(
    cfg: &ProblemConfig,
    model: &Model,
) -> Result<Option<SafetyStudy>, PipelineError> {
    if !cfg.closed_loop.safety {
        return Ok(None);
    }
    let seq = model.sequence.as_ref().ok_or_else(|| {
        fail(
            Stage::ClosedLoop,
            "closed_loop.safety: the model has no sequence net (train with `[training] \
             outputs = \"sequence\"`)",
        )
    })?;
    if model.settings.sequence_form != cfg.training.sequence_form {
        return Err(fail(
            Stage::ClosedLoop,
            format!(
                "closed_loop.safety: the model's sequence net is in the {:?} form, the \
                 problem's training.sequence_form is {:?}: train it again",
                model.settings.sequence_form, cfg.training.sequence_form
            ),
        ));
    }
    let (plant, g) = EmulatedPlant::new(cfg)
        .map_err(|e| fail(Stage::ClosedLoop, format!("closed_loop.safety: {e}")))?;
    let nu = cfg.system.nu();
    let net = EmulatedSequenceNet::new(seq, cfg.ocp.horizon, nu);
    let source = move |x: &[f32]| net.sequence(x);
    Ok(Some(study(
        cfg,
        &plant,
        (plant_tier(&g.terminal), g.decrease),
        &source,
    )))
}

/// The invariance tier of the generated plant's terminal set.
fn plant_tier(t: &crate::deploy::plant_rs_safe::TerminalSource) -> &'static str {
    match t {
        crate::deploy::plant_rs_safe::TerminalSource::Robust(r) if r.proven() => "proven",
        _ => "sampled",
    }
}

/// One line for the stage's summary.
pub(super) fn safety_summary(s: &SafetyStudy) -> String {
    let g = &s.nominal;
    let ratio = |r: Option<f64>| r.map_or("—".to_string(), |v| format!("{v:.3}"));
    format!(
        "safety ({} runs): safe {} violating steps, fallback {:.2} % of steps, cost ×{} MPC, \
         {} converged; plain {} violating steps, cost ×{}; mpc {} violating steps; ",
        s.runs,
        g.safe.total_violations,
        100.0 * g.safe.fallback_share,
        ratio(g.safe.median_cost_ratio),
        g.safe.converged,
        g.plain.total_violations,
        ratio(g.plain.median_cost_ratio),
        g.mpc.total_violations
    )
}
