//! The exported controller of a run: the strongest non-vacuous band among the candidates of
//! [`super::tiers`] (Theorem 1 of the net `choice` picks, the local certificate, the
//! statistical level), its files, the verdict in words (which guarantee was reached, why
//! not a stronger one, the next command), and the closed loop's statistical statement
//! when the band is statistical (`closed_loop_statistical.json`).
//!
//! ```text
//! exported = argmin over candidates of (vacuous, tier, ε)   (sound < statistical < estimated)
//! ```

use super::tiers::{self, Candidate, RefineOutcome, StatisticalOutcome};
use super::Env;
use super::{fail, PipelineError, Stage};
use crate::deploy::export::{ExportModel, StatisticalClaim};
use crate::io::{write_atomic, RunDir};
use crate::problem::ProblemConfig;
use serde::{Deserialize, Serialize};

/// The closed loop's statistical statement (`closed_loop_statistical.json`).
pub(super) const CLOSED_LOOP_STATISTICAL: &str = "closed_loop_statistical.json";

/// The verdict in words (`export_report.json`'s `"verdict"`).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Verdict {
    /// Which guarantee was reached.
    pub reached: String,
    /// Why not a stronger one (one line per tier not reached or not chosen).
    pub why_not_stronger: Vec<String>,
    /// The next command to run.
    pub next: String,
}

/// The export's choice: the controller and where its band comes from.
pub(super) struct Exported {
    /// The controller as exported.
    pub em: ExportModel,
    /// The chosen candidate.
    pub best: Candidate,
    /// Why the Theorem-1 net (nominal or regularized) was preferred over the other.
    pub net_reason: String,
    /// The statistical stage's outcome.
    pub statistical: StatisticalOutcome,
    /// The verdict in words.
    pub verdict: Verdict,
}

/// Chooses the exported controller of the run `d` (module doc).
pub(super) fn choose(
    stage: Stage,
    (d, cfg): (&RunDir, &ProblemConfig),
) -> Result<Exported, PipelineError> {
    let reg = tiers::read_candidate(stage, (d, cfg), tiers::Net::Regularized, None)?;
    let nom = tiers::read_candidate(stage, (d, cfg), tiers::Net::Nominal, None)?;
    let (net, net_reason) = super::choice::choose((&nom.model, &nom.file), (&reg.model, &reg.file));
    let t1 = if net == "nominal" { nom } else { reg };
    let refine: RefineOutcome = tiers::read_json(stage, &d.join(tiers::REFINE_JSON))?;
    let statistical: StatisticalOutcome =
        tiers::read_json(stage, &d.join(tiers::STATISTICAL_JSON))?;
    let t1_line = t1.describe();
    let mut cands = vec![t1];
    if refine.candidate() {
        cands.push(tiers::read_candidate(
            stage,
            (d, cfg),
            tiers::Net::Refined,
            None,
        )?);
    }
    if let Some((c, _)) = tiers::statistical_candidate(stage, (d, cfg))? {
        cands.push(c);
    }
    let lines: Vec<(String, &'static str)> =
        cands.iter().map(|c| (c.describe(), c.source)).collect();
    let best = tiers::strongest(cands).ok_or_else(|| fail(stage, "no candidate band"))?;
    // The reason names the band actually exported; the Theorem-1 choice between the two nets
    // follows it when another band won.
    let net_reason = if best.source == "theorem1" {
        net_reason
    } else {
        format!(
            "the {} net, whose {} band (tier {}, ε = {:.4}) is the strongest guarantee reached; \
             between the two Theorem-1 nets: {net_reason}",
            best.net.name(),
            best.source,
            best.tier.name(),
            best.eps
        )
    };
    let em = export_model(cfg, &best, &statistical).map_err(|e| fail(stage, e))?;
    let verdict = verdict(cfg, d, (&best, &t1_line, &lines), (&refine, &statistical));
    Ok(Exported {
        em,
        best,
        net_reason,
        statistical,
        verdict,
    })
}

/// The controller of `best`: its certificate's ε and tier, its excluded boxes, and for a
/// statistical band the level ε_p with its claim.
fn export_model(
    cfg: &ProblemConfig,
    best: &Candidate,
    st: &StatisticalOutcome,
) -> Result<ExportModel, crate::deploy::export::ExportError> {
    let c = &best.file.base;
    let mut em = ExportModel::from_trained(&cfg.name, &best.model, c)?
        .with_certificate_guarantee(&best.file.guarantee);
    em.excluded = best
        .file
        .local
        .as_ref()
        .and_then(|l| l.excluded.as_ref())
        .map_or_else(Vec::new, |e| e.boxes.clone());
    if best.source == "statistical" {
        let block = best.file.statistical.as_ref();
        // Conditional on a hard-feasible state: the claim counts the states it rests on
        // (older files: the labelled ones) and the infeasible share's bound.
        let given = block.and_then(|b| b.given_feasible.as_ref().or(b.given_labelled.as_ref()));
        let samples = match (st.conditional, given) {
            (true, Some(g)) => g.samples,
            _ => st.samples,
        };
        let claim = StatisticalClaim {
            p_exceed_upper: st.p_target,
            confidence: st.confidence,
            samples,
            unlabelled_p_upper: st
                .conditional
                .then_some(st.infeasible_p_upper.or(st.unlabelled_p_upper))
                .flatten(),
        };
        em = em.with_statistical_eps(best.eps, claim)?;
    }
    Ok(em)
}

/// The verdict in words (module doc).
fn verdict(
    cfg: &ProblemConfig,
    d: &RunDir,
    (best, t1_line, lines): (&Candidate, &str, &[(String, &'static str)]),
    (refine, st): (&RefineOutcome, &StatisticalOutcome),
) -> Verdict {
    let tier = best.tier.name();
    let reached = match best.source {
        "statistical" => format!(
            "{tier}: P(‖κ − κ̂‖ > ε = {:.4}) ≤ {:e} with confidence {}{} ({} i.i.d. uniform \
             states; the deployed controller of the {} net){}",
            best.eps,
            st.p_target,
            st.confidence,
            if st.conditional {
                " given that the MPC's hard problem has a solution"
            } else {
                ""
            },
            st.samples,
            best.net.name(),
            match (
                st.conditional,
                st.infeasible_p_upper.or(st.unlabelled_p_upper)
            ) {
                (true, Some(p)) => format!(
                    "; the MPC has no solution on a share ≤ {p:.3e} of X ({} of {} states: {} \
                     unlabelled, {} labelled only by the soft problem; its own Clopper–Pearson \
                     bound)",
                    st.infeasible.max(st.unlabelled),
                    st.samples,
                    st.unlabelled,
                    st.soft
                ),
                _ => String::new(),
            }
        ),
        _ => format!("{tier}: {}", best.describe()),
    };
    let mut why = Vec::new();
    if best.source != "theorem1" {
        why.push(t1_line.to_string());
    }
    let nx = cfg.system.nx();
    if let Some(u) = refine.unusable.as_ref().filter(|_| refine.ran) {
        why.push(format!("local refinement: {u}"));
    } else if refine.ran {
        if best.source != "local" {
            if let Some((l, _)) = lines.iter().find(|(_, s)| *s == "local") {
                why.push(format!(
                    "{l}: a weaker tier or a larger ε than the band exported"
                ));
            }
        }
    } else {
        why.push(format!("local refinement skipped: {}", refine.reason));
    }
    if !st.ran {
        why.push(format!("statistical tier skipped: {}", st.reason));
    } else if st.eps_p.is_none() {
        why.push(format!(
            "statistical tier: no finite level at P ≤ {:e} from {} states",
            st.p_target, st.samples
        ));
    } else if best.source != "statistical" {
        if let Some((l, _)) = lines.iter().find(|(_, s)| *s == "statistical") {
            why.push(format!("{l}: not stronger than the band exported"));
        }
    }
    let problem = d.problem().display().to_string();
    let model = d.join(best_model(best)).display().to_string();
    let data = d.dataset().display().to_string();
    let next = if best.tier == crate::certify::tier::Tier::Sound {
        format!(
            "`trainer eval --model {model}` (the band is proven; check the device with the \
             firmware example)"
        )
    } else if nx <= 3 && !refine.ran {
        format!(
            "`trainer refine --config {problem}` (local certificates over X: a worst-case bound)"
        )
    } else if nx > 3 {
        format!(
            "`trainer certify --model {model} --data {data} --statistical 46050 --p-target \
             1e-4 --json > certificate_1e-4.json` (a tenfold smaller P; Theorem 1 is vacuous \
             and local cells are for nx ≤ 3, here nx = {nx})"
        )
    } else {
        format!(
            "`trainer refine --config {problem} --check 2000` (more rounds or a smaller [refine] \
             target_eps tighten the local bound)"
        )
    };
    Verdict {
        reached,
        why_not_stronger: why,
        next,
    }
}

/// The model file of a candidate, relative to the run directory.
fn best_model(c: &Candidate) -> &'static str {
    match c.net {
        tiers::Net::Regularized => RunDir::MODEL_REGULARIZED,
        tiers::Net::Nominal => RunDir::MODEL_NOMINAL,
        tiers::Net::Refined => "refine/model.bin",
    }
}

/// The `export` stage's body: weights.rs, weights.bin and export_report.json.
pub(super) fn export(env: &Env, d: &RunDir) -> Result<String, PipelineError> {
    let x = choose(Stage::Export, (d, env.cfg))?;
    let em = &x.em;
    let r = crate::deploy::export::export_files(em, &d.weights_rs(), &d.weights_bin())
        .map_err(|e| fail(Stage::Export, e))?;
    // The band the exported controller (libm tanh, the default) clamps to.
    let (blo, bhi) = em.clamp_band(em.eps + r.f32_allowance[0]);
    let f64s = |v: Vec<f32>| v.into_iter().map(f64::from).collect::<Vec<_>>();
    let c = &x.best.file.base;
    let json = serde_json::json!({
        "clamp_lo": f64s(blo),
        "clamp_hi": f64s(bhi),
        "f32_allowance_libm": r.f32_allowance[0],
        "f32_allowance_fast_tanh": r.f32_allowance[1],
        "f32_observed_libm": r.f32_observed[0],
        "f32_observed_fast_tanh": r.f32_observed[1],
        "samples": r.samples,
        "eps_f64": em.eps,
        "eps_device_libm": em.eps + r.f32_allowance[0],
        "eps_certificate": c.eps,
        "net": x.best.net.name(),
        "net_reason": x.net_reason,
        "source": x.best.source,
        "tier": x.best.tier.name(),
        "conditional": x.best.source == "statistical" && x.statistical.conditional,
        "model": best_model(&x.best),
        "verdict": x.verdict,
    });
    write_atomic(&d.export_report(), json.to_string().as_bytes())
        .map_err(|e| fail(Stage::Export, e))?;
    Ok(format!(
        "weights.rs + weights.bin of the {} net, band ε {:.4} ({}, {}); f32 allowance {:.3e} (observed {:.3e} on {} states)",
        x.best.net.name(),
        em.eps,
        x.best.source,
        x.best.tier.name(),
        r.f32_allowance[0],
        r.f32_observed[0],
        r.samples
    ))
}

/// The closed loop's statistical statement when the exported band is statistical (else a
/// file saying why not): `[certify] closed_loop` runs of the exported controller from i.i.d.
/// uniform starts (`study::statistical_loop`). Returns the stage line's part.
pub(super) fn closed_loop_statistical(
    cfg: &ProblemConfig,
    d: &RunDir,
) -> Result<String, PipelineError> {
    let x = choose(Stage::ClosedLoop, (d, cfg))?;
    let p = d.join(CLOSED_LOOP_STATISTICAL);
    let n = cfg.certify.closed_loop;
    let skip = if x.best.source != "statistical" {
        Some(format!(
            "the exported band is {} ({}), not statistical",
            x.best.tier.name(),
            x.best.source
        ))
    } else if n == 0 {
        Some("[certify] closed_loop = 0".to_string())
    } else {
        None
    };
    if let Some(why) = skip {
        let v = serde_json::json!({ "ran": false, "reason": why });
        write_atomic(&p, v.to_string().as_bytes()).map_err(|e| fail(Stage::ClosedLoop, e))?;
        return Ok(format!("closed-loop statistical: skipped ({why})"));
    }
    let dep = crate::deploy::export::Deployed::from_export(&x.em)
        .map_err(|e| fail(Stage::ClosedLoop, e))?;
    let s = crate::study::statistical_loop::closed_loop_statistical(
        cfg,
        &dep,
        &x.best.model.content_hash(),
        n,
        cfg.certify.seed,
        cfg.certify.confidence,
    );
    let text = serde_json::to_string_pretty(&s).map_err(|e| fail(Stage::ClosedLoop, e))?;
    write_atomic(&p, text.as_bytes()).map_err(|e| fail(Stage::ClosedLoop, e))?;
    let (f, ff) = (
        s.failing.clone().unwrap_or_else(|| s.all.clone()),
        s.failing_feasible
            .clone()
            .unwrap_or_else(|| s.feasible_starts.clone()),
    );
    let mpc = match (&s.mpc_failing, s.controller_failing_same) {
        (Some(m), Some(c)) => format!(
            "; the MPC itself from {} other i.i.d. starts: {} fail (controller on those: {c})",
            m.trajectories, m.violating
        ),
        _ => String::new(),
    };
    let offset = match s.setpoint_offset {
        Some(o) if o > crate::study::statistical_loop::CONVERGE_TOL => format!(
            "; the controller has a steady offset at the setpoint ({o:.3} scaled, above the \
             tolerance {}): its runs cannot converge",
            crate::study::statistical_loop::CONVERGE_TOL
        ),
        _ => String::new(),
    };
    let left = match (s.failing_left_domain, &s.reach) {
        (Some(k), Some((lo, hi))) if k > 0 => format!(
            "; {k} of the {} failing runs left X (the device projects such states onto X), \
             the runs reached [{}] … [{}]",
            f.violating,
            crate::study::statistical_loop::short(lo),
            crate::study::statistical_loop::short(hi)
        ),
        _ => String::new(),
    };
    Ok(format!(
        "closed-loop statistical: P(run violates or does not converge) ≤ {:.3e} from MPC-feasible starts ({} of {}), ≤ {:.3e} from all ({} of {}), confidence {}, {} steps{mpc}{offset}{left}",
        ff.p_violation_upper, ff.violating, ff.trajectories, f.p_violation_upper, f.violating, f.trajectories, s.confidence, s.steps
    ))
}
