//! The closed-loop stage's safety study (`[closed_loop] safety = true`): the exported model's
//! sequence net as the candidate source of the device's safe controller, emulated at runtime
//! dimensions (`deploy::safe_emulation`), run by `study::safety`; its result goes into
//! `closed_loop.json` (top-level `safe`, `plain`, `mpc` and `safety`: `study::scenarios`).

use super::{fail, PipelineError, Stage};
use crate::certify::Model;
use crate::deploy::safe_emulation::{EmulatedPlant, EmulatedSequenceNet};
use crate::problem::ProblemConfig;
use crate::study::safety::{safety_study as study, SafetyStudy};

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
