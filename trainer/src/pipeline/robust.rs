//! The Corollary 1 design loop (`trainer run` with `[robust] eps > 0`): design the tube,
//! run the pipeline on the tightened problem in `DIR/<name>/robust/`, refine with local
//! certificates if asked, run the robust closed-loop study, and write `robust.json` and
//! `robust.md` with the verdict.
//!
//! `robust.json`'s verdict keys: `design_eps`, `certified_eps` (the net simulated and
//! judged: the refined one when refinement improved ε), `f32_allowance` (the sound f32
//! allowance of that net's export, libm tanh, in the 2-norm ε is stated in), `verdict`:
//! `"certified"`, `"conditional"` or `"not_certified"` (`robust::verdict`: certified only
//! when ε + allowance ≤ design ε and ε is sound, recursive feasibility proven, the per-cell
//! check passed and no excluded cell is merely estimated infeasible; `verdict_detail.rests_on`
//! lists what a conditional verdict rests on); `guarantee` (the
//! certificate's tier: `sound` / `statistical` / `estimated`) and `recursive_feasibility`
//! (`proven` / `sampled` / `unknown`, from the design's terminal region); `verdict_detail`
//! the same with the message.

use super::{PipelineError, RunOptions, Stage};
use crate::certify::certificate::Certificate;
use crate::certify::tier::Tier;
use crate::certify::Model;
use crate::io::{write_atomic, RunDir};
use crate::mpc::law::MpcLaw;
use crate::mpc::sqp::SqpStatus;
use crate::problem::ProblemConfig;
use crate::robust::{
    design, robust_config, verdict, Check, Design, Evidence, Feasibility, RobustError, Verdict,
    VerdictStatus,
};
use crate::study::closed_loop::Run;
use crate::study::robust::*;
use crate::study::scenarios::{initial_states, ClosedLoop, ClosedLoopFile};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

/// Errors of the robust design loop.
#[derive(Debug, thiserror::Error)]
pub enum RobustRunError {
    /// The design itself failed (an empty tightened set).
    #[error(transparent)]
    Design(#[from] RobustError),
    /// A pipeline stage of the robust run failed.
    #[error(transparent)]
    Pipeline(#[from] PipelineError),
    /// Reading or writing a file of the robust run, or a step that writes into a directory
    /// of it (the refinement, its figure).
    #[error("robust design: {path}: {source}")]
    File {
        /// The file or directory.
        path: String,
        /// What went wrong.
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// The robust run's certificate does not read or re-check.
    #[error("robust design: {0}")]
    Certificate(#[from] crate::certify::file::CertFileError),
    /// The tightened problem cannot be written as a problem file.
    #[error("robust design: {0}")]
    Problem(#[from] toml::ser::Error),
}

/// What a robust run produced (also written as `robust.json`).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RobustReport {
    /// The design ε.
    pub design_eps: f64,
    /// The certified ε of the net judged.
    pub certified_eps: f64,
    /// The f32 allowance of that net's export (libm tanh).
    pub f32_allowance: f64,
    /// `"certified"`, `"conditional"` or `"not_certified"` (module doc).
    pub verdict: String,
    /// The certificate's tier (`sound`, `statistical`, `estimated`).
    pub guarantee: Tier,
    /// How recursive feasibility of the tightened OCP is established.
    pub recursive_feasibility: Feasibility,
    /// The design.
    pub design: Design,
    /// The certificate's verdict in full, with its message.
    pub verdict_detail: Verdict,
    /// Parts of the certificate (ε_D, L_NN, L_MPC, r).
    pub certificate: BTreeMap<String, f64>,
    /// Whether the robust MPC's hard problem is feasible at the upswing state.
    pub upswing_feasible: bool,
    /// Monte Carlo states found in the robust MPC's feasible set.
    pub monte_carlo_states: usize,
    /// Summaries per `closed_loop.json` key.
    pub summaries: BTreeMap<String, RunSummary>,
    /// The upswing run per key (Table II rows).
    pub upswing: BTreeMap<String, RunSummary>,
    /// Mean cost of the robust MPC over that of the nominal MPC from the same states.
    pub cost_ratio_mean: f64,
    /// The same ratio for the upswing.
    pub cost_ratio_upswing: f64,
    /// Wall time of the closed-loop study in s.
    pub study_seconds: f64,
    /// When the refined net's certificate excludes cells (outside the tightened MPC's
    /// feasible set, `refine.exclude_infeasible`): how many, their share of X and the boxes;
    /// the certified ε holds on X minus them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub excluded: Option<crate::certify::refine::Excluded>,
    /// Monte Carlo initial states (feasible for the tightened MPC) inside an excluded box;
    /// any makes the verdict `not_certified`.
    #[serde(default)]
    pub feasible_in_excluded: usize,
    /// When the design loop refined (`robust.refine` and the first certificate missed the
    /// design ε): its rounds, its certified ε and the ε-per-round figure (relative path).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub refinement: Option<Refinement>,
}

/// The refinement step of the design loop, as the report states it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Refinement {
    /// Refinement rounds run.
    pub rounds: usize,
    /// The refined net's certified ε (before the f32 allowance).
    pub certified_eps: f64,
    /// The ε-per-round figure, relative to the run directory.
    pub figure: String,
}

/// The sound f32 allowance (libm tanh) of the export of `net` with `cert`; NaN when the
/// net cannot be exported (then nothing is certified).
fn f32_allowance(name: &str, net: &Model, cert: &Certificate) -> f64 {
    crate::deploy::export::deployed_allowance(name, net, cert).unwrap_or(f64::NAN)
}

/// States of the check the design loop runs on a refined certificate (uniform on X, seeded
/// by `robust.seed`), as `trainer refine --check N` would.
pub const CHECK_STATES: usize = 200;

/// The robust run's `certificate.json` in `dir`, verified and re-checked against its net,
/// its problem `rcfg` and its dataset.
fn read_run_certificate(
    dir: &RunDir,
    net: &Model,
    rcfg: &ProblemConfig,
) -> Result<crate::certify::file::CertificateFile, RobustRunError> {
    let dpath = dir.dataset();
    let data = std::fs::read(&dpath).map_err(|e| io(&dpath, e))?;
    let (model_hash, dataset_hash) = (net.content_hash(), crate::io::sha256_hex(&data));
    let against = crate::certify::file::Against {
        model_hash: Some(&model_hash),
        problem: Some(rcfg),
        dataset_hash: Some(&dataset_hash),
        cells_csv: None,
    };
    Ok(
        crate::certify::file::read_certificate(&dir.certificate(), false, &against)
            .map(|(f, _)| f)?,
    )
}

fn io(p: &Path, e: impl Into<Box<dyn std::error::Error + Send + Sync>>) -> RobustRunError {
    RobustRunError::File {
        path: p.display().to_string(),
        source: e.into(),
    }
}

/// The net the design loop judges, its certificate and what the verdict rests on.
struct Judged {
    net: Model,
    cert: Certificate,
    /// The tier the certificate file states (never recomputed here).
    guarantee: crate::certify::tier::Guarantee,
    /// The check at fresh states: run on a refined certificate only (the Theorem-1
    /// certificate of the stages has none; the verdict then rests on it).
    check: Option<crate::certify::file::CheckSummary>,
    excluded: Option<crate::certify::refine::Excluded>,
    /// The f32 allowance of the net's export (libm tanh).
    allowance: f64,
}

impl Judged {
    /// The verdict's evidence, with the Monte Carlo counts of feasible states in an excluded
    /// box and outside X (a box counts as proven infeasible only by `robust::exclusion`).
    fn evidence(
        &self,
        cfg: &ProblemConfig,
        d: &Design,
        feasible_in_excluded: usize,
        feasible_outside_domain: usize,
    ) -> Evidence {
        Evidence {
            design_eps: cfg.robust.eps,
            certified_eps: self.cert.eps,
            f32_allowance: self.allowance,
            recursive_feasibility: d.recursive_feasibility(),
            eps_sound: self.guarantee.guarantee == Tier::Sound,
            eps_rests_on: self.guarantee.assumptions.clone(),
            check: match &self.check {
                None => Check::NotRun,
                Some(k) if k.passed => Check::Passed,
                Some(_) => Check::Failed,
            },
            excluded_unproven: self.excluded.as_ref().map_or(0, |e| {
                crate::robust::exclusion::unproven_boxes(cfg, &d.stages, &e.boxes)
            }),
            feasible_in_excluded,
            feasible_outside_domain,
        }
    }
}

/// The robust design loop for `cfg` (with `cfg.robust.eps` > 0): design the tightened
/// MPC, run the pipeline's stages on it in `DIR/<name>/robust/` (data, training,
/// certificate, export, closed loop, report), add the robust closed-loop study to its
/// `closed_loop.json`, and write `robust.json` and `robust.md` with the verdict.
pub fn run(cfg: &ProblemConfig, opts: &RunOptions) -> Result<RobustReport, RobustRunError> {
    let d = design(cfg)?;
    let rcfg = robust_config(cfg, &d);
    let text = toml::to_string(&rcfg)?;
    let root = RunDir::new(opts.root.join(&cfg.name));
    let dir = RunDir::new(root.join(&rcfg.name));
    let mut o = opts.clone();
    o.root = root.path().to_path_buf();
    o.until = Some(Stage::ClosedLoop);
    crate::pipeline::run(&rcfg, &text, &o)?;
    let mpath = dir.model_regularized();
    let mut net = Model::load(&mpath).map_err(|e| io(&mpath, e))?;
    let cfile = read_run_certificate(&dir, &net, &rcfg)?;
    net.certificate = Some(cfile.base.clone());
    let mut j = Judged {
        allowance: f32_allowance(&cfg.name, &net, &cfile.base),
        net,
        cert: cfile.base,
        guarantee: cfile.guarantee,
        check: None,
        excluded: None,
    };
    let mut v = verdict(&j.evidence(cfg, &d, 0, 0));
    let mut refinement = None;
    if v.status == VerdictStatus::NotCertified && cfg.robust.refine {
        refinement = Some(refine_step(cfg, &rcfg, &dir, &mut j)?);
        v = verdict(&j.evidence(cfg, &d, 0, 0));
    }
    // The study (skipped when closed_loop.json already holds it for the same inputs).
    let clpath = dir.closed_loop();
    let cltext = std::fs::read_to_string(&clpath).map_err(|e| io(&clpath, e))?;
    let mut file: ClosedLoopFile = serde_json::from_str(&cltext).map_err(|e| io(&clpath, e))?;
    let inputs = study_inputs(cfg, &rcfg, &root, &j.cert);
    let spath = dir.join("robust_study.json");
    let cached: Option<(String, RobustReport)> = std::fs::read_to_string(&spath)
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok());
    if let Some((inp, rep)) = cached {
        if inp == inputs && file.runs.contains_key("robust") && rep.verdict_detail == v {
            return Ok(rep);
        }
    }
    let (rep, st) = study_report(cfg, &rcfg, &root, d, j, refinement);
    for (k, runs) in st {
        file.runs.insert(k, runs);
    }
    let text_cl = serde_json::to_string(&file).map_err(|e| io(&clpath, e))?;
    write_atomic(&clpath, text_cl.as_bytes()).map_err(|e| io(&clpath, e))?;
    super::manifest::reseal(&dir, Stage::ClosedLoop, RunDir::CLOSED_LOOP)?;
    let json = serde_json::to_string_pretty(&rep).map_err(|e| io(dir.path(), e))?;
    write_atomic(&dir.robust(), json.as_bytes()).map_err(|e| io(dir.path(), e))?;
    write_atomic(&dir.join("robust.md"), markdown(&rep).as_bytes())
        .map_err(|e| io(dir.path(), e))?;
    let cached = serde_json::to_string(&(&inputs, &rep)).map_err(|e| io(&spath, e))?;
    write_atomic(&spath, cached.as_bytes()).map_err(|e| io(&spath, e))?;
    // The report stage (re-runs because closed_loop.json changed).
    let mut o = opts.clone();
    o.root = root.path().to_path_buf();
    crate::pipeline::run(&rcfg, &text, &o)?;
    Ok(rep)
}

/// The design loop's second step: refine data and network with local certificates until
/// the certified ε meets the design ε (or the refinement budget is spent), in `dir/refine/`;
/// the refined net replaces the judged one when its certified ε is smaller.
fn refine_step(
    cfg: &ProblemConfig,
    rcfg: &ProblemConfig,
    dir: &RunDir,
    j: &mut Judged,
) -> Result<Refinement, RobustRunError> {
    let mut fcfg = rcfg.clone();
    // Room for the exported f32 allowance, which the verdict counts too.
    fcfg.refine.target_eps = cfg.robust.eps * crate::robust::REFINE_TARGET_FRACTION;
    let rdir = RunDir::new(dir.join("refine"));
    std::fs::create_dir_all(rdir.path()).map_err(|e| io(rdir.path(), e))?;
    let r = crate::certify::refine::refine(
        &fcfg,
        &fcfg.refine,
        Some(&rdir.join("refine_state.bin")),
        &crate::certify::refine::RefineOptions::default(),
    )
    .map_err(|e| io(rdir.path(), e))?;
    // The check at fresh states, as `refine --check` runs it: its result is written into
    // the certificate (a failed check leaves `met: false`) and a failed check makes the
    // verdict `not_certified`.
    let checked =
        crate::certify::refine::check(&fcfg, &fcfg.refine, &r, CHECK_STATES, cfg.robust.seed);
    let text = crate::certify::refine::pretty(&checked);
    write_atomic(&rdir.check(), text.as_bytes()).map_err(|e| io(rdir.path(), e))?;
    let lc = crate::certify::refine::write_outputs(
        &fcfg,
        &fcfg.refine,
        &r,
        rdir.path(),
        Some(&checked),
        &|c| crate::deploy::export::deployed_allowance(&cfg.name, &r.model, c),
    )
    .map_err(|e| io(rdir.path(), e))?;
    // The ε-per-round curve of the refinement, beside its outputs.
    let fig = crate::study::plots::refine_rounds(&r.state.log, fcfg.refine.target_eps)
        .map_err(|e| io(rdir.path(), e))?;
    let png = crate::study::plots::to_png(fig.name, &fig.svg, cfg.plots.png_scale as f32)
        .map_err(|e| io(rdir.path(), e))?;
    for (name, bytes) in [
        ("refine_rounds.svg", fig.svg.as_bytes()),
        ("refine_rounds.png", &png[..]),
    ] {
        let p = rdir.join(name);
        write_atomic(&p, bytes).map_err(|e| io(&p, e))?;
    }
    let refinement = Refinement {
        rounds: r.state.log.len(),
        certified_eps: lc.base.eps,
        figure: "refine/refine_rounds.svg".into(),
    };
    if lc.base.eps < j.cert.eps {
        j.check = lc.check.clone();
        j.net = r.model;
        j.net.certificate = Some(lc.base.clone());
        j.cert = lc.base;
        j.guarantee = lc.guarantee;
        j.excluded = lc.local.excluded;
        j.allowance = f32_allowance(&cfg.name, &j.net, &j.cert);
    }
    Ok(refinement)
}

/// What the cached study depends on: the version, the nominal net, the tightened problem,
/// the judged certificate and the robust and closed-loop settings.
fn study_inputs(
    cfg: &ProblemConfig,
    rcfg: &ProblemConfig,
    root: &RunDir,
    cert: &Certificate,
) -> String {
    let nominal_hash = std::fs::read(root.model_regularized())
        .map(|b| crate::io::hex(&<sha2::Sha256 as sha2::Digest>::digest(&b)))
        .unwrap_or_default();
    format!(
        "{}|{}|{}|{}|{}|{}",
        env!("CARGO_PKG_VERSION"),
        nominal_hash,
        rcfg.problem_hash(),
        cert.hash,
        serde_json::to_string(&cfg.robust).unwrap_or_default(),
        serde_json::to_string(&cfg.closed_loop).unwrap_or_default()
    )
}

/// The nominal design's net (from the nominal run in `root`) and its certified ε, for
/// comparison; `None` when it does not read.
fn load_nominal(root: &RunDir) -> Option<(Model, f64)> {
    let m = Model::load(&root.model_regularized()).ok()?;
    let (c, _) = crate::certify::file::read_certificate(
        &root.certificate(),
        false,
        &crate::certify::file::Against {
            model_hash: Some(&m.content_hash()),
            ..Default::default()
        },
    )
    .ok()?;
    // The band's half-width in physical units (ε itself for the unscaled norm).
    Some((m, c.base.eps_per_input().into_iter().fold(0.0, f64::max)))
}

/// The robust closed-loop study of the judged net and its report (with the final verdict,
/// which counts the Monte Carlo states inside excluded boxes and outside X); also the
/// study's runs per key, for `closed_loop.json`.
fn study_report(
    cfg: &ProblemConfig,
    rcfg: &ProblemConfig,
    root: &RunDir,
    d: Design,
    j: Judged,
    refinement: Option<Refinement>,
) -> (RobustReport, ClosedLoop) {
    let t = std::time::Instant::now();
    let up = initial_states(cfg)[0].clone();
    let upswing_feasible = MpcLaw::new(rcfg).solve(&up, None).0.status == SqpStatus::Converged;
    let mc = feasible_states(rcfg, cfg.robust.monte_carlo_states, cfg.robust.seed);
    // Feasible states the certificate does not cover (inside an excluded box): Corollary 1
    // needs ε on the whole feasible set, so the verdict cannot be `certified` then.
    let feasible_in_excluded = j.excluded.as_ref().map_or(0, |e| {
        mc.iter()
            .filter(|x| crate::certify::statistical::in_any_box(x, &e.boxes))
            .count()
    });
    // The feasible set beyond X (within the OCP's state bounds): ε must cover it too.
    let outside = feasible_outside_domain(rcfg, cfg.robust.monte_carlo_states, cfg.robust.seed);
    let v = verdict(&j.evidence(cfg, &d, feasible_in_excluded, outside.len()));
    let nominal = load_nominal(root);
    let st = study(
        cfg,
        rcfg,
        (&j.net, j.cert.eps),
        nominal.as_ref().map(|(m, e)| (m, *e)),
        &mc,
    );
    let study_seconds = t.elapsed().as_secs_f64();
    let mut summaries = BTreeMap::new();
    let mut upswing = BTreeMap::new();
    for (k, runs) in &st {
        summaries.insert(k.clone(), summarize(runs));
        upswing.insert(k.clone(), summarize(&runs[..1]));
    }
    let ratio = |a: &[Run], b: &[Run]| {
        let n = a.len().min(b.len());
        a[..n].iter().map(|r| r.cost).sum::<f64>() / b[..n].iter().map(|r| r.cost).sum::<f64>()
    };
    let (rm, nm) = (&st["robust_mpc"], &st["nominal_mpc"]);
    let cert = &j.cert;
    let rep = RobustReport {
        design_eps: v.design_eps,
        certified_eps: v.certified_eps,
        f32_allowance: v.f32_allowance,
        verdict: v.status.name().into(),
        guarantee: j.guarantee.guarantee,
        recursive_feasibility: v.recursive_feasibility,
        design: d,
        verdict_detail: v,
        certificate: BTreeMap::from([
            ("eps".to_string(), cert.eps),
            ("eps_d".to_string(), cert.eps_d),
            ("l_nn".to_string(), cert.l_nn),
            ("l_mpc".to_string(), cert.l_mpc),
            ("covering_radius".to_string(), cert.covering_radius),
        ]),
        upswing_feasible,
        monte_carlo_states: mc.len(),
        summaries,
        upswing,
        cost_ratio_mean: ratio(rm, nm),
        cost_ratio_upswing: rm[0].cost / nm[0].cost,
        study_seconds,
        excluded: j.excluded,
        feasible_in_excluded,
        refinement,
    };
    (rep, st)
}

/// `robust.md`: design, verdict, Table II rows and the Monte Carlo summaries.
pub fn markdown(r: &RobustReport) -> String {
    let t = &r.design.tube;
    let mut s = String::new();
    s += "# Robust design (Corollary 1)\n\n";
    s += &format!(
        "Design ε = {} ({:?}); ρ = {:.4}, w̄ = {:.4e} ({:?}); K = {:?}, LQR R-scale {:?}\n\n",
        t.eps, t.method, t.rho, t.w, t.bound, t.k, t.lqr_r_scale
    );
    let n = t.s.len() - 1;
    s += &format!(
        "Tightening at stage N: states {:?}, inputs {:?} (ε + τ·s_(N−1))\n\n",
        t.x_margin.iter().map(|m| m * t.s[n]).collect::<Vec<_>>(),
        t.u_margin
            .iter()
            .map(|m| t.eps + m * t.s[n - 1])
            .collect::<Vec<_>>()
    );
    s += &format!("**{}**\n\n", r.verdict_detail.message);
    s += &format!(
        "Verdict: {}; certificate tier: {}; recursive feasibility: {}\n\n",
        r.verdict,
        r.guarantee.name(),
        r.recursive_feasibility.name()
    );
    if let Some(f) = &r.refinement {
        s += &format!(
            "Refinement (the design loop's second step): {} rounds, certified ε {:.4}; ε per \
             round: [{}]({})\n\n",
            f.rounds, f.certified_eps, f.figure, f.figure
        );
    }
    if let Some(e) = &r.excluded {
        s += &format!(
            "Certified domain: X minus {} excluded cells ({:.1} % of X, {} boxes in \
             `certificate.json`), every corner of which is infeasible for the tightened MPC \
             (an estimate from the corners): ε holds on the rest, the exported controller \
             flags states in them.\n\n",
            e.cells,
            100.0 * e.volume_fraction,
            e.boxes.len()
        );
        s += &format!(
            "Feasible Monte Carlo states inside an excluded box: {} of {}\n\n",
            r.feasible_in_excluded, r.monte_carlo_states
        );
    }
    s += &match &r.design.terminal {
        Some(t) => format!(
            "Terminal region (x − x_r)ᵀP(x − x_r) ≤ α = {:.4e} (radius {:.4}, at most {:.4} by the \
             tightened boxes), local rate ρ_f = {:.4} ({:?}), margin ρ^(N−1)·w̄ = {:.3e}, \
             d₀ = {:.1e}: enforced as a terminal constraint\n\n",
            t.alpha, t.radius, t.radius_max, t.rho_local, t.check, t.margin, t.offset
        ),
        None => "No terminal region found (the tightened boxes leave no room or the local \
                 feedback does not contract): recursive feasibility unknown\n\n"
            .into(),
    };
    s += &format!(
        "Certificate: {:?}\n\nUpswing state feasible for the robust MPC: {}; Monte Carlo \
         states: {}; robust/nominal MPC cost: mean {:.4}, upswing {:.4}\n\n",
        r.certificate,
        r.upswing_feasible,
        r.monte_carlo_states,
        r.cost_ratio_mean,
        r.cost_ratio_upswing
    );
    let table = |title: &str, m: &BTreeMap<String, RunSummary>| {
        let mut s = format!(
            "## {title}\n\n| key | runs | runs violating | % steps violating | max violation | \
             max input divergence | MPC infeasible steps | mean cost |\n|---|---|---|---|---|---|---|---|\n"
        );
        for (k, v) in m {
            s += &format!(
                "| {k} | {} | {} | {:.3} | {:.4} | {:.4} | {} | {:.2} |\n",
                v.runs,
                v.runs_violating,
                v.violation_percent,
                v.max_violation,
                v.max_input_divergence,
                v.mpc_soft_steps,
                v.mean_cost
            );
        }
        s + "\n"
    };
    s += &table("Upswing (Table II rows)", &r.upswing);
    s += &table("Monte Carlo", &r.summaries);
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn load(name: &str) -> ProblemConfig {
        let path = std::path::PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/"))
            .join(name);
        ProblemConfig::load(&path).unwrap()
    }

    fn di(eps: f64) -> ProblemConfig {
        let mut c = load("double_integrator.toml");
        c.robust.eps = eps;
        c
    }

    /// The whole robust loop on the double integrator with small sizes: files, keys,
    /// per-run format, verdict, the certificate's U_d, and the cached second run.
    #[test]
    fn robust_run_end_to_end_on_the_double_integrator() {
        let mut cfg = di(0.1);
        cfg.robust.monte_carlo_states = 12;
        cfg.robust.disturbed_states = 3;
        cfg.closed_loop.steps = 40;
        cfg.closed_loop.random_initial_states = 2;
        cfg.closed_loop.noise_runs = 1;
        cfg.training.epochs = 50;
        cfg.training.validation_n = 50;
        let root = std::env::temp_dir().join(format!("ampc_robust_{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let opts = RunOptions {
            root: root.clone(),
            ..Default::default()
        };
        let rep = run(&cfg, &opts).unwrap();
        let dir = root.join("double_integrator").join("robust");
        for f in [
            "robust.json",
            "robust.md",
            "report.md",
            "certificate.json",
            "weights.rs",
        ] {
            assert!(dir.join(f).exists(), "{f}");
        }
        assert!(!rep.verdict_detail.certified);
        assert_eq!(rep.verdict, "not_certified");
        assert_eq!(rep.monte_carlo_states, 12);
        let cl: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("closed_loop.json")).unwrap())
                .unwrap();
        let robust = cl["robust"].as_array().unwrap();
        assert_eq!(robust.len(), 13);
        for k in [
            "x0",
            "steps",
            "violation_steps",
            "max_violation",
            "max_input_divergence",
            "cost",
        ] {
            assert!(robust[0].get(k).is_some(), "{k}");
        }
        for (k, _) in disturbances(0.1) {
            let runs = cl[k].as_array().unwrap();
            assert_eq!(runs.len(), 4, "{k}");
            assert!(runs.iter().all(|r| r["violation_steps"] == 0), "{k}");
        }
        assert!(cl.get("mpc").is_some(), "the pipeline's own keys stay");
        let (cert, _) = crate::certify::file::read_certificate(
            &dir.join("certificate.json"),
            false,
            &Default::default(),
        )
        .unwrap();
        let cert = cert.base;
        assert!((cert.u_hi[0] - 0.9).abs() < 1e-12 && (cert.u_lo[0] + 0.9).abs() < 1e-12);
        // Unchanged inputs: the study is not redone.
        let again = run(&cfg, &opts).unwrap();
        assert_eq!(again.study_seconds, rep.study_seconds);
        let _ = std::fs::remove_dir_all(&root);
    }

    /// The enforced terminal region in the real tightened OCP: from states where the hard
    /// problem is feasible (near the setpoint: on this problem |ω| ≤ 0.5 leaves X_f a θ-width
    /// of a few centiradians, which 1 s of horizon cannot reach from far), the robust MPC under input errors e = ±ε (constant, alternating,
    /// seeded random signs) stays hard-feasible at every step (recursive feasibility, sampled
    /// here, proven by `robust::terminal`) and its predicted x_N lies in X_f.
    #[test]
    fn enforced_terminal_region_keeps_the_tightened_mpc_feasible() {
        let mut cfg = load("pendulum_robust_small.toml");
        cfg.robust.terminal_constraint = true;
        let d = design(&cfg).unwrap();
        assert_eq!(
            d.recursive_feasibility(),
            crate::robust::Feasibility::Proven
        );
        let t = d.terminal.clone().unwrap();
        let rcfg = robust_config(&cfg, &d);
        let (nx, nu, n) = (2, 1, cfg.ocp.horizon);
        let p = &d.tube.p;
        let model = crate::problem::model::Discrete::new(
            cfg.system.clone(),
            cfg.ocp.ts,
            cfg.ocp.rk4_substeps,
        );
        let mut law = MpcLaw::new(&rcfg);
        let mut feasible_starts = 0;
        for x0 in [[0.03, 0.1], [-0.05, 0.2], [0.08, -0.2], [0.5, 0.2]] {
            if law.solve(&x0, None).0.status != SqpStatus::Converged {
                continue;
            }
            feasible_starts += 1;
            for pattern in 0..3u64 {
                let mut x = x0.to_vec();
                for step in 0..40u64 {
                    let (label, pd) = law.solve(&x, None);
                    assert_eq!(
                        label.status,
                        SqpStatus::Converged,
                        "x0 {x0:?}, pattern {pattern}, step {step}: x {x:?}"
                    );
                    let z = pd.unwrap().z;
                    let xn = &z[n * (nx + nu)..n * (nx + nu) + nx];
                    let dx: Vec<f64> = (0..nx).map(|i| xn[i] - t.x_ref[i]).collect();
                    let v: f64 = (0..nx)
                        .flat_map(|i| (0..nx).map(move |j| (i, j)))
                        .map(|(i, j)| p[i][j] * dx[i] * dx[j])
                        .sum();
                    assert!(
                        v <= t.alpha * (1.0 + 1e-6),
                        "x_N {xn:?}: {v} > α {}",
                        t.alpha
                    );
                    let sign = match pattern {
                        0 => 1.0,
                        1 => [1.0, -1.0][(step % 2) as usize],
                        _ => {
                            if crate::rng::uniform(3, step, 0) < 0.5 {
                                -1.0
                            } else {
                                1.0
                            }
                        }
                    };
                    let u = [label.u[0] + sign * cfg.robust.eps];
                    let mut next = vec![0.0; nx];
                    model.step(&x, &u, &mut next);
                    x = next;
                }
            }
        }
        assert!(feasible_starts >= 2, "{feasible_starts} feasible starts");
    }
}
