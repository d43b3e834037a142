//! The tiers `trainer run` adds after Theorem 1, and the candidates the export chooses from.
//!
//! ```text
//! refine       when Theorem 1 is vacuous for both nets (ε ≥ d_U) and nx ≤ 3 ([refine] enabled)
//!              → refine/ (model.bin, certificate.json: the local bound max_C ε_C), refine.json
//! statistical  the deployed controller of the best candidate so far (when every band is
//!              vacuous: of the best-fitting net), on n i.i.d. uniform
//!              states ([certify] statistical = n; 0 = off; n drawn ⌈n/(1 − ū)⌉ when the
//!              validation set has unlabelled states, ū their share's upper bound) → certificate_statistical.json
//!              (that certificate with its "statistical" block), statistical.json
//! ```
//!
//! A [`Candidate`] is a net with a band: Theorem 1 of either net, the refined net's local
//! certificate, or the statistical level ε_p of the tested net (P(‖κ − κ̂‖ > ε_p) ≤ p at
//! confidence 1 − β; conditional on the MPC having a solution when the draw had unlabelled
//! states, whose share is bounded apart). The strongest is `argmin (vacuous, tier, ε)`:
//! a non-vacuous band first, then the stronger tier (sound < statistical < estimated),
//! then the smaller ε.

use super::Env;
use super::{fail, fail_at, PipelineError, Stage};
use crate::certify::file::CertificateFile;
use crate::certify::Model;
use crate::io::{write_atomic, RunDir};
use crate::problem::{ProblemConfig, RefineSwitch};
use serde::{Deserialize, Serialize};

/// What the `refine` stage did (`refine.json`).
pub(super) const REFINE_JSON: &str = "refine.json";
/// What the `statistical` stage did (`statistical.json`).
pub(super) const STATISTICAL_JSON: &str = "statistical.json";
/// The tested net's certificate with its `"statistical"` block.
pub(super) const STATISTICAL_CERT: &str = "certificate_statistical.json";
/// The statistical states (a dataset: resumable, reused while the tested net is unchanged).
pub(super) const STATISTICAL_STORE: &str = "statistical.bin";
/// Fresh states of the refinement's check (as the robust loop's).
const CHECK_STATES: usize = 2000;
/// The wall-clock budget of an automatic refinement (`[refine] enabled = "auto"` without
/// `[refine] max_seconds`), so that `trainer run` always ends: a plant whose refinement
/// cannot reach the target (an infeasible region, slow solves) stops after this long with
/// its best certificate and `refine/refine_report.json` (why it stopped, the resume
/// command), and the statistical tier covers it. A refinement that reaches its target
/// sooner is unaffected (its result does not depend on time).
pub(super) const AUTO_REFINE_SECONDS: f64 = 120.0;
/// After the first best (written at once), the refinement's best-so-far certificate is
/// rewritten from this many seconds on.
const BEST_AFTER_SECONDS: f64 = 10.0;

/// Where a candidate's net and certificate live.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub(super) enum Net {
    /// `model_regularized.bin`, `certificate.json`.
    Regularized,
    /// `model_nominal.bin`, `certificate_nominal.json`.
    Nominal,
    /// `refine/model.bin`, `refine/certificate.json`.
    Refined,
}

impl Net {
    fn files(self) -> (&'static str, &'static str) {
        match self {
            Net::Regularized => (RunDir::MODEL_REGULARIZED, RunDir::CERTIFICATE),
            Net::Nominal => (RunDir::MODEL_NOMINAL, RunDir::CERTIFICATE_NOMINAL),
            Net::Refined => ("refine/model.bin", "refine/certificate.json"),
        }
    }

    /// Its name (`regularized`, `nominal`, `refined`).
    pub(super) fn name(self) -> &'static str {
        match self {
            Net::Regularized => "regularized",
            Net::Nominal => "nominal",
            Net::Refined => "refined",
        }
    }
}

/// The outcome of the `refine` stage (`refine.json`).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(super) struct RefineOutcome {
    /// Whether the refinement ran.
    pub ran: bool,
    /// Why it ran or was skipped, in words.
    pub reason: String,
    /// The local bound max_C ε_C (scaled norm), when it ran.
    pub eps: Option<f64>,
    /// Its tier.
    pub tier: Option<String>,
    /// Refinement rounds.
    pub rounds: usize,
    /// Content hash of `refine/model.bin` (keys the later stages).
    pub model_hash: String,
    /// Whether the refined certificate is a candidate band: it ran, its ε is finite and its
    /// file verifies (a certificate whose check at fresh states failed is refused, as
    /// `trainer export` refuses it). When not, [`RefineOutcome::unusable`] says why.
    #[serde(default)]
    pub usable: bool,
    /// Why the refined certificate is not a candidate band (when it ran but is not usable).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unusable: Option<String>,
}

impl RefineOutcome {
    /// Whether the refined net and certificate are a candidate band.
    pub(super) fn candidate(&self) -> bool {
        self.ran && self.usable
    }
}

/// The outcome of the `statistical` stage (`statistical.json`).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(super) struct StatisticalOutcome {
    /// Whether the statistical tier ran.
    pub ran: bool,
    /// Why not, or what was tested, in words.
    pub reason: String,
    /// The net tested (its deployed controller).
    pub net: Option<Net>,
    /// The exported level ε_p (scaled norm), when there is a finite one.
    pub eps_p: Option<f64>,
    /// Whether ε_p is the level conditional on MPC-feasible states (the hard OCP has a
    /// solution; unlabelled states in the draw: unconditionally the level is ∞).
    pub conditional: bool,
    /// P(the MPC leaves a uniform state unlabelled) ≤ this (its own Clopper–Pearson bound).
    pub unlabelled_p_upper: Option<f64>,
    /// Unlabelled states of the draw.
    pub unlabelled: u64,
    /// P(the MPC's hard OCP has no solution at a uniform state: unlabelled or soft-labelled)
    /// ≤ this (its own Clopper–Pearson bound); the share the conditional ε_p says nothing
    /// about. Absent in files written before it existed.
    #[serde(default)]
    pub infeasible_p_upper: Option<f64>,
    /// States of the draw where the hard OCP has no solution (unlabelled or soft-labelled).
    #[serde(default)]
    pub infeasible: u64,
    /// Of those, the soft-labelled ones.
    #[serde(default)]
    pub soft: u64,
    /// n: states drawn.
    pub samples: u64,
    /// p of ε_p.
    pub p_target: f64,
    /// 1 − β.
    pub confidence: f64,
}

/// A net with its certificate file and a band (module doc).
pub(super) struct Candidate {
    /// Which net.
    pub net: Net,
    /// The net.
    pub model: Model,
    /// Its certificate (with the `"statistical"` block for a statistical candidate).
    pub file: CertificateFile,
    /// The band's ε (scaled norm): the certificate's, or the statistical level.
    pub eps: f64,
    /// The band's tier.
    pub tier: crate::certify::tier::Tier,
    /// Whether the band is vacuous (ε in physical units ≥ d_U, or not finite).
    pub vacuous: bool,
    /// `theorem1`, `local` or `statistical`.
    pub source: &'static str,
}

impl Candidate {
    /// A candidate whose band is its certificate's ε.
    fn certified(net: Net, model: Model, file: CertificateFile) -> Self {
        let eps = file.base.eps;
        let vacuous = vacuous(&file.base, eps);
        let tier = file.guarantee.guarantee;
        let source = if net == Net::Refined {
            "local"
        } else {
            "theorem1"
        };
        Candidate {
            net,
            model,
            file,
            eps,
            tier,
            vacuous,
            source,
        }
    }

    /// The order key: non-vacuous first, then the stronger tier, then the smaller ε.
    fn key(&self) -> (bool, crate::certify::tier::Tier) {
        (self.vacuous, self.tier)
    }

    /// Whether `self` is strictly stronger than `other` (module doc).
    pub(super) fn beats(&self, other: &Candidate) -> bool {
        self.key()
            .cmp(&other.key())
            .then(self.eps.total_cmp(&other.eps))
            .is_lt()
    }

    /// One line: source, net, ε, tier, vacuity.
    pub(super) fn describe(&self) -> String {
        let c = &self.file.base;
        let mut shown = c.clone();
        shown.eps = self.eps;
        shown.epsilon_per_input = Vec::new();
        let (ratio, _) = crate::study::report::judge(shown.eps_physical(), &c.u_lo, &c.u_hi);
        let what = match self.source {
            "theorem1" => "Theorem 1",
            "local" => "local certificate",
            _ => "statistical level",
        };
        format!(
            "{what} of the {} net: ε = {:.4} ({}, {:.1} % of the input range{})",
            self.net.name(),
            self.eps,
            self.tier.name(),
            100.0 * ratio,
            if self.vacuous { ", vacuous" } else { "" }
        )
    }
}

/// ε vacuous for the certificate `c`'s norm and U: in physical units ≥ d_U, or not finite.
fn vacuous(c: &crate::certify::certificate::Certificate, eps: f64) -> bool {
    let mut shown = c.clone();
    shown.eps = eps;
    shown.epsilon_per_input = Vec::new();
    !eps.is_finite()
        || crate::study::report::judge(shown.eps_physical(), &c.u_lo, &c.u_hi).1 == "vacuous"
}

/// Reads the certificate candidate of `net` in the run `d` (verified against its model; the
/// refined net's against the refinement's dataset).
pub(super) fn read_candidate(
    stage: Stage,
    (d, cfg): (&RunDir, &ProblemConfig),
    net: Net,
    cert_name: Option<&str>,
) -> Result<Candidate, PipelineError> {
    let (model, cert) = net.files();
    let cert = cert_name.unwrap_or(cert);
    let m = Model::load(&d.join(model)).map_err(|e| fail(stage, e))?;
    let data = if net == Net::Refined {
        d.join("refine").join(RunDir::DATASET)
    } else {
        d.dataset()
    };
    let bytes = std::fs::read(&data).map_err(|e| fail_at(stage, &data, e))?;
    let (model_hash, dataset_hash) = (m.content_hash(), crate::io::sha256_hex(&bytes));
    let against = crate::certify::file::Against {
        model_hash: Some(&model_hash),
        problem: Some(cfg),
        dataset_hash: Some(&dataset_hash),
        cells_csv: None,
    };
    let (f, _) = crate::certify::file::read_certificate(&d.join(cert), false, &against)
        .map_err(|e| fail(stage, e))?;
    Ok(Candidate::certified(net, m, f))
}

/// Theorem 1 of both nets and, when `refine.json` says it ran, the local certificate.
pub(super) fn certified_candidates(
    stage: Stage,
    (d, cfg): (&RunDir, &ProblemConfig),
    with_refined: bool,
) -> Result<Vec<Candidate>, PipelineError> {
    let mut v = vec![
        read_candidate(stage, (d, cfg), Net::Regularized, None)?,
        read_candidate(stage, (d, cfg), Net::Nominal, None)?,
    ];
    if with_refined && read_json::<RefineOutcome>(stage, &d.join(REFINE_JSON))?.candidate() {
        v.push(read_candidate(stage, (d, cfg), Net::Refined, None)?);
    }
    Ok(v)
}

/// The net whose deployed controller the statistical tier tests: the strongest candidate
/// when its band is non-vacuous; when every band is vacuous (ε says nothing about the fit),
/// the net with the smallest validation mean error — the statistical level is an observed
/// error, which the better fit makes smaller.
fn tested_candidate(v: Vec<Candidate>) -> Option<Candidate> {
    if v.iter().any(|c| !c.vacuous) {
        return strongest(v);
    }
    let fit = |c: &Candidate| c.model.validation_stats.mean;
    v.into_iter()
        .reduce(|best, c| if fit(&c) < fit(&best) { c } else { best })
}

/// The strongest of `v` (module doc; ties keep the earlier).
pub(super) fn strongest(v: Vec<Candidate>) -> Option<Candidate> {
    v.into_iter()
        .reduce(|best, c| if c.beats(&best) { c } else { best })
}

pub(super) fn read_json<T: serde::de::DeserializeOwned>(
    stage: Stage,
    p: &std::path::Path,
) -> Result<T, PipelineError> {
    let text = std::fs::read_to_string(p).map_err(|e| fail_at(stage, p, e))?;
    serde_json::from_str(&text).map_err(|e| fail_at(stage, p, e))
}

fn write_json<T: Serialize>(stage: Stage, p: &std::path::Path, v: &T) -> Result<(), PipelineError> {
    let text = serde_json::to_string_pretty(v).map_err(|e| fail(stage, e))?;
    write_atomic(p, text.as_bytes()).map_err(|e| fail(stage, e))
}

// ---- refine: local certificates where Theorem 1 is vacuous ------------------------------

/// Why the refinement is skipped for these Theorem-1 candidates, or None to run it.
pub(super) fn refine_skip(cfg: &ProblemConfig, t1: &[Candidate]) -> Option<String> {
    let nx = cfg.system.nx();
    let best = t1
        .iter()
        .map(|c| c.describe())
        .collect::<Vec<_>>()
        .join("; ");
    match cfg.refine.enabled {
        RefineSwitch::Off => Some("[refine] enabled = \"off\"".into()),
        RefineSwitch::On => None,
        RefineSwitch::Auto if t1.iter().any(|c| !c.vacuous) => {
            Some(format!("Theorem 1 is not vacuous ({best})"))
        }
        RefineSwitch::Auto if nx > 3 => Some(format!(
            "nx = {nx} > 3 (local cells grow as 2^nx corners per cell; [refine] enabled = \
             \"on\" forces it)"
        )),
        RefineSwitch::Auto => None,
    }
}

/// The `refine` stage's body (module doc).
pub(super) fn refine(env: &Env, d: &RunDir) -> Result<String, PipelineError> {
    let cfg = env.cfg;
    let t1 = certified_candidates(Stage::Refine, (d, cfg), false)?;
    if let Some(why) = refine_skip(cfg, &t1) {
        let out = RefineOutcome {
            ran: false,
            reason: why.clone(),
            eps: None,
            tier: None,
            rounds: 0,
            model_hash: String::new(),
            usable: false,
            unusable: None,
        };
        write_json(Stage::Refine, &d.join(REFINE_JSON), &out)?;
        return Ok(format!("skipped: {why}"));
    }
    let rdir = d.join("refine");
    std::fs::create_dir_all(&rdir).map_err(|e| fail_at(Stage::Refine, &rdir, e))?;
    let mut rs = cfg.refine.clone();
    if cfg.refine.enabled == RefineSwitch::Auto && rs.max_seconds.is_none() {
        rs.max_seconds = Some(AUTO_REFINE_SECONDS);
    }
    let rs = &rs;
    let resume = format!(
        "trainer refine --config <problem file> --out {}",
        rdir.display()
    );
    let name = cfg.name.clone();
    let opts = crate::certify::refine::RefineOptions {
        on_result: Some(crate::certify::refine::writing_sink(
            cfg,
            &rdir,
            &resume,
            (BEST_AFTER_SECONDS, !env.progress),
            std::sync::Arc::new(move |m, c| crate::deploy::export::deployed_allowance(&name, m, c)),
        )),
        // The check's solves beside the retrainings.
        ahead: Some(std::sync::Arc::new(
            crate::certify::refine::CheckAhead::start(cfg, rs, CHECK_STATES, cfg.certify.seed),
        )),
        ..Default::default()
    };
    let r = crate::certify::refine::refine(cfg, rs, Some(&rdir.join("refine_state.bin")), &opts)
        .map_err(|e| fail_at(Stage::Refine, &rdir, e))?;
    // The check at fresh states only for a certificate that can be a band: with an infinite
    // ε (a cell with an unlabelled corner left when the run stopped) it is never one, and
    // its check solves — many of them failing ones near an infeasible region, each climbing
    // the retry ladder — took 20 min of the CSTR's run for nothing.
    let finite =
        !r.state.bounds.is_empty() && r.state.bounds.iter().all(|(_, b)| b.eps.is_finite());
    let checked = finite.then(|| {
        let (n, seed) = (CHECK_STATES, cfg.certify.seed);
        match &opts.ahead {
            Some(a) => crate::certify::refine::check_ahead(cfg, rs, &r, (n, seed), a),
            None => crate::certify::refine::check(cfg, rs, &r, n, seed),
        }
    });
    if let Some(c) = &checked {
        write_atomic(
            &rdir.join("check.json"),
            crate::certify::refine::pretty(c).as_bytes(),
        )
        .map_err(|e| fail(Stage::Refine, e))?;
    } else {
        // No stale check of an earlier certificate beside this one.
        let _ = std::fs::remove_file(rdir.join("check.json"));
    }
    let lc = crate::certify::refine::write_outputs(cfg, rs, &r, &rdir, checked.as_ref(), &|c| {
        crate::deploy::export::deployed_allowance(&cfg.name, &r.model, c)
    })
    .map_err(|e| fail_at(Stage::Refine, &rdir, e))?;
    let report = crate::certify::refine::RefineReport::new(cfg, rs, &r, r.stopped, resume);
    crate::certify::refine::write_report(&rdir, &report)
        .map_err(|e| fail_at(Stage::Refine, &rdir, e))?;
    let why = match cfg.refine.enabled {
        RefineSwitch::On => "[refine] enabled = \"on\"".to_string(),
        _ => format!(
            "Theorem 1 is vacuous for both nets and nx = {} ≤ 3",
            cfg.system.nx()
        ),
    };
    // A band only when finite and verified: an infinite ε (an unlabelled corner not yet
    // split down to refine.min_cell) or a failed check leaves the other tiers to the export.
    let unusable = if !lc.base.eps.is_finite() {
        Some(format!(
            "the local ε is ∞ ({}; refine/refine_report.json names the cells; not checked at \
             fresh states)",
            r.stopped.describe()
        ))
    } else {
        read_candidate(Stage::Refine, (d, cfg), Net::Refined, None)
            .err()
            .map(|e| format!("the refined certificate is refused: {e}"))
    };
    let out = RefineOutcome {
        ran: true,
        reason: why.clone(),
        eps: Some(lc.base.eps).filter(|e| e.is_finite()),
        tier: Some(lc.guarantee.guarantee.name().to_string()),
        rounds: r.state.log.len(),
        model_hash: r.model.content_hash(),
        usable: unusable.is_none(),
        unusable: unusable.clone(),
    };
    write_json(Stage::Refine, &d.join(REFINE_JSON), &out)?;
    Ok(format!(
        "{why}: local ε {:.4} ({}) after {} rounds, {} cells{}{} → refine/",
        lc.base.eps,
        lc.guarantee.guarantee.name(),
        out.rounds,
        lc.local.cells,
        lc.local
            .excluded
            .as_ref()
            .map_or(String::new(), |e| format!(", {} excluded", e.cells)),
        if let Some(u) = &unusable {
            format!("; not a candidate band: {u}")
        } else if r.met {
            String::new()
        } else {
            format!(
                "; target {} not met: {} (resume: {})",
                rs.target_eps,
                r.stopped.describe(),
                report.resume
            )
        }
    ))
}

// ---- statistical: the deployed controller on i.i.d. uniform states ----------------------

/// The `statistical` stage's body (module doc).
pub(super) fn statistical(env: &Env, d: &RunDir) -> Result<String, PipelineError> {
    let cfg = env.cfg;
    let set = &cfg.certify;
    let off = |reason: String| StatisticalOutcome {
        ran: false,
        reason,
        net: None,
        eps_p: None,
        conditional: false,
        unlabelled_p_upper: None,
        unlabelled: 0,
        infeasible_p_upper: None,
        infeasible: 0,
        soft: 0,
        samples: 0,
        p_target: set.p_target,
        confidence: set.confidence,
    };
    if set.statistical == 0 {
        let out = off("[certify] statistical = 0".into());
        write_json(Stage::Statistical, &d.join(STATISTICAL_JSON), &out)?;
        return Ok("skipped: [certify] statistical = 0".into());
    }
    let Some(best) = tested_candidate(certified_candidates(Stage::Statistical, (d, cfg), true)?)
    else {
        return Err(fail(Stage::Statistical, "no certified net to test"));
    };
    let dep = crate::deploy::export::Deployed::new(&cfg.name, &best.model, &best.file.base)
        .map_err(|e| fail(Stage::Statistical, e))?;
    let data_path = if best.net == Net::Refined {
        d.join("refine").join(RunDir::DATASET)
    } else {
        d.dataset()
    };
    let data =
        crate::data::dataset::Dataset::load(&data_path).map_err(|e| fail(Stage::Statistical, e))?;
    let training: Vec<Vec<f64>> = data.records.iter().map(|r| r.x.clone()).collect();
    let hash = best.model.content_hash();
    let tested = crate::certify::statistical::Tested {
        controller: &dep,
        model_hash: &hash,
        training: &training,
    };
    // Aim at `statistical` hard-feasible states (the conditional bound counts those): the
    // draw is sized from the validation set's share of states where the hard OCP has no
    // solution, unlabelled or soft-labelled (`draw_for_labelled`).
    let (vn, vu) = crate::data::dataset::Dataset::load(&d.validation())
        .map(|v| {
            let hard = crate::mpc::sqp::SqpStatus::Converged;
            let out = v.records.iter().filter(|r| r.status != hard).count();
            (v.records.len() as u64, out as u64)
        })
        .unwrap_or((0, 0));
    let samples =
        crate::certify::statistical::draw_for_labelled(set.statistical, vn, vu, set.confidence);
    let opts = crate::certify::statistical::StatisticalOptions {
        samples,
        confidence: set.confidence,
        seed: set.seed,
        p_target: set.p_target,
        progress: env.progress,
        excluded: best
            .file
            .local
            .as_ref()
            .and_then(|l| l.excluded.as_ref())
            .map_or_else(Vec::new, |e| e.boxes.clone()),
    };
    let store = d.join(STATISTICAL_STORE);
    let st = crate::certify::statistical::certify_statistically(
        cfg,
        &tested,
        best.file.base.eps,
        &store,
        &opts,
    )
    .map_err(|e| fail_at(Stage::Statistical, &store, e))?;
    let mut file = best.file.clone();
    file.statistical = Some(st.clone());
    crate::certify::file::write_certificate(&d.join(STATISTICAL_CERT), &file)
        .map_err(|e| fail(Stage::Statistical, e))?;
    let finite = |e: Option<f64>| e.filter(|v| v.is_finite());
    let (eps_p, conditional) = match finite(st.eps_at_p_target) {
        Some(e) => (Some(e), false),
        // Conditional on the hard-feasible states (soft labels are not MPC-feasible).
        None => (
            finite(st.given_feasible.as_ref().and_then(|g| g.eps_at_p_target)),
            true,
        ),
    };
    let share = st.unlabelled_share.as_ref();
    let infeasible = st.infeasible_share.as_ref();
    let out = StatisticalOutcome {
        ran: true,
        reason: format!(
            "the deployed controller of the {} net ({}) on {} i.i.d. uniform states",
            best.net.name(),
            best.describe(),
            st.samples
        ),
        net: Some(best.net),
        eps_p,
        conditional: conditional && eps_p.is_some(),
        unlabelled_p_upper: share.map(|s| s.p_upper),
        unlabelled: st.unlabelled,
        infeasible_p_upper: infeasible.map(|s| s.p_upper),
        infeasible: infeasible.map_or(st.unlabelled, |s| s.unlabelled),
        soft: st.soft_labelled.as_ref().map_or(0, |s| s.states),
        samples: st.samples,
        p_target: st.p_target,
        confidence: st.confidence,
    };
    write_json(Stage::Statistical, &d.join(STATISTICAL_JSON), &out)?;
    let level = match (eps_p, out.conditional) {
        (Some(e), false) => format!("ε_p = {e:.4}"),
        (Some(e), true) => format!(
            "ε_p = {e:.4} given a hard-feasible MPC state ({} of {} states infeasible: {} \
             unlabelled, {} soft-labelled{}; P(infeasible) ≤ {:.3e})",
            out.infeasible,
            st.samples,
            st.unlabelled,
            out.soft,
            st.soft_labelled.as_ref().map_or(String::new(), |s| format!(
                ", max error there {:.4}, no bound rests on it",
                s.max_error
            )),
            out.infeasible_p_upper.unwrap_or(f64::NAN)
        ),
        (None, _) => "no finite level (too few states or every one exceeding)".into(),
    };
    let drawn = if samples > set.statistical {
        format!(
            " (drawn for {} hard-feasible: {vu} of {vn} validation states infeasible or \
             unlabelled)",
            set.statistical
        )
    } else {
        String::new()
    };
    Ok(format!(
        "{} states{drawn} of the {} net's deployed controller: {} exceed ε {:.4}, max error {:.4}; {level} at P ≤ {:e}, confidence {}",
        st.samples,
        best.net.name(),
        st.exceedances,
        st.eps,
        st.max_error,
        st.p_target,
        st.confidence
    ))
}

/// The statistical candidate of the run (the tested net with its level as band), if the
/// stage found a finite level.
pub(super) fn statistical_candidate(
    stage: Stage,
    (d, cfg): (&RunDir, &ProblemConfig),
) -> Result<Option<(Candidate, StatisticalOutcome)>, PipelineError> {
    let out: StatisticalOutcome = read_json(stage, &d.join(STATISTICAL_JSON))?;
    let (Some(net), Some(eps_p)) = (out.net, out.eps_p) else {
        return Ok(None);
    };
    let mut c = read_candidate(stage, (d, cfg), net, Some(STATISTICAL_CERT))?;
    c.vacuous = vacuous(&c.file.base, eps_p);
    c.eps = eps_p;
    c.tier = crate::certify::tier::Tier::Statistical;
    c.source = "statistical";
    Ok(Some((c, out)))
}
