//! `trainer certify`: certifies a trained model (`--model`) on the dataset it was trained
//! on (`--data`) for the problem file (`--config`): ε = ε_D + (L_MPC + L_NN)·r with every
//! term, and optionally the data density a target ε needs. Prints text or JSON to stdout;
//! writes no file.

use super::common::problem_for_data;
use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};
use trainer::certify::certificate::{requirement, Certificate, CertifyOptions};
use trainer::certify::statistical::{
    certify_statistically, Statistical, StatisticalOptions, Tested, DEFAULT_SEED,
};
use trainer::data::dataset::{Dataset, Shard};

/// The statistical tier's flags (shared by `certify`).
#[derive(clap::Args, Debug, Clone)]
pub(super) struct StatisticalArgs {
    /// Also bound P(‖κ − sat κ_NN‖ > ε) statistically from this many fresh i.i.d. uniform
    /// states of X, each solved by the MPC (Clopper–Pearson; resumable).
    #[arg(long, value_name = "N")]
    statistical: Option<usize>,
    /// Confidence 1 − β of the statistical bound.
    #[arg(long, default_value_t = 0.99, requires = "statistical")]
    confidence: f64,
    /// Probability target: also report the smallest ε whose bound is ≤ this.
    #[arg(long, default_value_t = 1e-3, requires = "statistical")]
    p_target: f64,
    /// Seed of the statistical states.
    #[arg(long, default_value_t = DEFAULT_SEED, requires = "statistical")]
    statistical_seed: u64,
    /// Dataset file for the statistical states (default: `certify`: beside the model,
    /// `<model>.statistical.bin`; `refine`: `statistical.bin` in its output directory).
    #[arg(long, requires = "statistical")]
    statistical_store: Option<PathBuf>,
}

/// `--statistical-closed-loop N`: the closed-loop statistical tier
/// ([`trainer::study::statistical_loop`]).
#[derive(clap::Args, Debug, Clone)]
pub(super) struct ClosedLoopArgs {
    /// Also bound P(a closed-loop trajectory of the deployed controller from a uniform random
    /// initial state violates a constraint) from this many trajectories (Clopper–Pearson).
    #[arg(long, value_name = "N")]
    statistical_closed_loop: Option<usize>,
    /// Confidence 1 − β of the closed-loop bound.
    #[arg(long, default_value_t = 0.99, requires = "statistical_closed_loop")]
    closed_loop_confidence: f64,
    /// Seed of the closed loop's initial states.
    #[arg(long, default_value_t = DEFAULT_SEED, requires = "statistical_closed_loop")]
    closed_loop_seed: u64,
}

impl ClosedLoopArgs {
    /// (trajectories, seed, confidence), checked; None without the flag.
    pub(super) fn options(&self) -> Result<Option<(usize, u64, f64)>> {
        let Some(n) = self.statistical_closed_loop else {
            return Ok(None);
        };
        if n == 0 {
            bail!("--statistical-closed-loop must be at least 1");
        }
        let c = self.closed_loop_confidence;
        if !(c > 0.0 && c < 1.0) {
            bail!("--closed-loop-confidence must be in (0, 1), got {c}");
        }
        Ok(Some((n, self.closed_loop_seed, c)))
    }
}

/// The statistical tiers asked for on the command line.
pub(super) struct Tiers<'a> {
    /// `--statistical N` and its store.
    pub statistical: Option<&'a (StatisticalOptions, PathBuf)>,
    /// `--statistical-closed-loop N`: (trajectories, seed, confidence).
    pub closed_loop: Option<(usize, u64, f64)>,
}

impl StatisticalArgs {
    /// The options and the store path (`default_store` unless `--statistical-store`), or
    /// None without `--statistical`.
    pub(super) fn options(
        &self,
        default_store: PathBuf,
    ) -> Result<Option<(StatisticalOptions, PathBuf)>> {
        let Some(n) = self.statistical else {
            return Ok(None);
        };
        let o = StatisticalOptions {
            samples: n,
            confidence: self.confidence,
            seed: self.statistical_seed,
            p_target: self.p_target,
            progress: true,
            excluded: Vec::new(),
        };
        o.validate().map_err(anyhow::Error::msg)?;
        let store = self.statistical_store.clone().unwrap_or(default_store);
        Ok(Some((o, store)))
    }
}

/// The arguments of `trainer certify` (their doc comments are the help text).
#[derive(clap::Args)]
pub(super) struct Args {
    /// Problem file (default: the embedded pendulum).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Model file from `trainer train`, or an ONNX file (detected by content).
    #[arg(long)]
    model: PathBuf,
    /// The dataset the model was trained on (for a net trained elsewhere: a dataset of
    /// this problem from `trainer sample`).
    #[arg(long)]
    data: PathBuf,
    /// Also report the data density a target ε requires.
    #[arg(long)]
    target_eps: Option<f64>,
    /// A proven Lipschitz constant of the MPC law (otherwise an estimate is used).
    #[arg(long)]
    l_mpc: Option<f64>,
    /// Print JSON (the certificate record) instead of text.
    #[arg(long)]
    json: bool,
    #[command(flatten)]
    statistical: StatisticalArgs,
    /// With --statistical N: label only shard K of M (`K/M`, 0 ≤ K < M) of the N statistical
    /// states into the store (give each shard its own --statistical-store) and stop — no
    /// bound. `trainer merge` of the M stores gives the unsharded store; then
    /// `certify --statistical N --statistical-store MERGED` computes the bound from it.
    #[arg(long, value_name = "K/M", requires = "statistical")]
    shard: Option<Shard>,
    #[command(flatten)]
    closed_loop: ClosedLoopArgs,
}

impl Args {
    /// Certifies `--model` on `--data` and prints the certificate.
    pub(super) fn run(self) -> Result<()> {
        let stat = self
            .statistical
            .options(self.model.with_extension("statistical.bin"))?;
        if let (Some(shard), Some(st)) = (self.shard, &stat) {
            return label_shard(self.config.as_deref(), &self.model, &self.data, st, shard);
        }
        execute(
            self.config.as_deref(),
            &self.model,
            &self.data,
            self.target_eps,
            self.l_mpc,
            self.json,
            Tiers {
                statistical: stat.as_ref(),
                closed_loop: self.closed_loop.options()?,
            },
        )
    }
}

/// `--statistical N --shard K/M`: the shard's statistical states of `model`, labelled into
/// the store; nothing else is computed.
fn label_shard(
    config: Option<&Path>,
    model: &Path,
    data: &Path,
    (o, store): &(StatisticalOptions, PathBuf),
    shard: Shard,
) -> Result<()> {
    let m = super::common::load_model(model)?;
    let d = Dataset::load(data)?;
    let cfg = problem_for_data(config, data, &d)?;
    super::common::refuse_overwrite(&[store], &[model, data])?;
    let ds = trainer::certify::statistical::label_shard(&cfg, &m.content_hash(), store, o, shard)
        .with_context(|| format!("statistical states in {}", store.display()))?;
    eprintln!(
        "shard {}/{} of the {} statistical states of {}: {} labelled into {}; `trainer merge` \
         the {} shard stores, then `trainer certify … --statistical {} --statistical-store \
         MERGED` computes the bound",
        shard.index,
        shard.count,
        o.samples,
        model.display(),
        ds.records.len(),
        store.display(),
        shard.count,
        o.samples
    );
    Ok(())
}

pub(super) fn execute(
    config: Option<&Path>,
    model: &Path,
    data: &Path,
    target: Option<f64>,
    l_mpc: Option<f64>,
    json: bool,
    tiers: Tiers<'_>,
) -> Result<()> {
    let Tiers {
        statistical: stat,
        closed_loop,
    } = tiers;
    let m = super::common::load_model(model)?;
    let d = Dataset::load(data)?;
    let cfg = problem_for_data(config, data, &d)?;
    if let Some(v) = l_mpc {
        if !(v.is_finite() && v >= 0.0) {
            bail!("--l-mpc must be a finite number ≥ 0, got {v}");
        }
    }
    if let Some(e) = target {
        if !(e.is_finite() && e > 0.0) {
            bail!("--target-eps must be a finite number > 0, got {e}");
        }
    }
    // The deployed controller (f32, projection, clamp band): its f32 allowance is stored in
    // the certificate (the tier of that term is claimed sound), and it is the function the
    // statistical tiers test.
    let (c, deployed) = trainer::deploy::export::certify_deployed(
        &cfg.name,
        &m,
        &d,
        &cfg,
        &CertifyOptions {
            l_mpc,
            ..Default::default()
        },
    )
    .with_context(|| format!("cannot certify {} on {}", model.display(), data.display()))?;
    // In the certificate's norm: the target, δ and the spacing in scaled units (the box S_x⁻¹X).
    let (slo, shi) = c.norm().scale_box(&cfg.domain.lo, &cfg.domain.hi);
    let req = target.map(|e| requirement(e, c.eps_d, c.l_mpc, c.l_nn, &slo, &shi));
    let statistical = match stat {
        Some((o, store)) => {
            super::common::refuse_overwrite(&[store], &[model, data])?;
            let dep = deployed.as_ref().map_err(|e| {
                anyhow::anyhow!(
                    "--statistical tests the deployed controller, which {} cannot be: {e}",
                    model.display()
                )
            })?;
            let training: Vec<Vec<f64>> = d.records.iter().map(|r| r.x.clone()).collect();
            let tested = Tested {
                controller: dep,
                model_hash: &c.hash,
                training: &training,
            };
            Some(
                certify_statistically(&cfg, &tested, c.eps, store, o)
                    .with_context(|| format!("statistical states in {}", store.display()))?,
            )
        }
        None => None,
    };
    let loop_bound = match closed_loop {
        Some((n, seed, conf)) => {
            let dep = deployed.as_ref().map_err(|e| {
                anyhow::anyhow!(
                    "--statistical-closed-loop simulates the deployed controller, which {} \
                     cannot be: {e}",
                    model.display()
                )
            })?;
            if !json {
                eprintln!(
                    "closed loop: {n} trajectories of {} steps …",
                    cfg.closed_loop.steps
                );
            }
            Some(trainer::study::statistical_loop::closed_loop_statistical(
                &cfg, dep, &c.hash, n, seed, conf,
            ))
        }
        None => None,
    };
    if json {
        let mut f = trainer::certify::file::CertificateFile::theorem1(c.clone());
        f.statistical_closed_loop = loop_bound.as_ref().map(serde_json::to_value).transpose()?;
        f.requirement = req;
        f.statistical = statistical.clone();
        println!("{}", f.sealed()?);
        return Ok(());
    }
    println!(
        "certificate of {} on {} ({} labelled points)",
        model.display(),
        data.display(),
        c.n_points
    );
    print_terms(&c);
    if let Some(l) = &c.labels {
        println!(
            "  labels           imported from {} (sha256 {}…): {} of {} rows re-solved by ampc, \
             max |Δu| {:.3e}{}",
            l.file,
            super::common::short(&l.sha256),
            l.resolved,
            l.rows,
            l.max_disagreement,
            if l.beyond_tolerance + l.unlabelled_by_ampc > 0 {
                format!(
                    ", {} beyond tolerance / {} unlabelled by ampc, accepted by --trust-labels",
                    l.beyond_tolerance, l.unlabelled_by_ampc
                )
            } else {
                String::new()
            }
        );
    }
    if let Some(st) = &statistical {
        print_statistical(st);
    }
    if let Some(b) = &loop_bound {
        println!(
            "  closed loop      P(trajectory violates) ≤ {:.3e} with confidence {} ({} of {} \
             trajectories of {} steps; from MPC-feasible starts: ≤ {:.3e}, {} of {}; largest \
             violation {:.3e}; statistical, Clopper–Pearson)",
            b.all.p_violation_upper,
            b.confidence,
            b.all.violating,
            b.all.trajectories,
            b.steps,
            b.feasible_starts.p_violation_upper,
            b.feasible_starts.violating,
            b.feasible_starts.trajectories,
            b.max_violation
        );
    }
    if let Some(r) = req {
        match (r.delta, r.spacing, r.solves) {
            (Some(dl), Some(h), Some(n)) => println!(
                "  target eps {}: covering radius δ ≤ {:.6}, e.g. a grid with spacing {:.6} per axis: {:.0} OCP solves",
                r.target_eps, dl, h, n
            ),
            _ => println!("  target eps {} ≤ eps_D {:.6}: no data density can certify it with this network", r.target_eps, c.eps_d),
        }
    }
    Ok(())
}

/// The certificate's terms as text: ε_D, L_NN (with every bound), L_MPC, r and ε.
fn print_terms(c: &Certificate) {
    println!(
        "  eps_D            {:.6}   (max ‖κ − κ_NN‖ over the data)",
        c.eps_d
    );
    println!(
        "  L_NN             {:.4}   ({:?}, sound)",
        c.l_nn, c.l_nn_method
    );
    println!("    naive          {:.4}", c.l_nn_naive);
    println!("    LipSDP-Neuron  {:.4}", c.l_nn_lipsdp);
    if let Some(v) = c.l_nn_vertex {
        println!("    slope vertices {v:.4}");
    }
    println!("    sampled lower  {:.4}", c.l_nn_lower);
    println!("  L_MPC            {:.4}   ({})", c.l_mpc, c.l_mpc_method);
    println!(
        "  covering radius  {:.6}   ({})",
        c.covering_radius, c.covering_method
    );
    let g = trainer::certify::tier::theorem1(c);
    println!(
        "  eps              {:.6}   = eps_D + (L_MPC + L_NN)·r   [{}: {}]",
        c.eps,
        g.guarantee.name(),
        if g.assumptions.is_empty() {
            "every term proven".to_string()
        } else {
            g.assumptions.join("; ")
        }
    );
}

/// The statistical tier as text.
pub(super) fn print_statistical(s: &Statistical) {
    println!(
        "  statistical      P(error > eps) ≤ {:.3e} with confidence {} ({} exceedances in {} \
         i.i.d. states, {} unlabelled; max observed {:.6}; Clopper–Pearson)",
        s.p_exceed_upper, s.confidence, s.exceedances, s.samples, s.unlabelled, s.max_error
    );
    match s.eps_at_p_target {
        Some(e) => println!(
            "    eps at P ≤ {:.1e}  {e:.6}   (statistical, confidence {})",
            s.p_target, s.confidence
        ),
        None => println!(
            "    eps at P ≤ {:.1e}  not reachable with {} states (needs more)",
            s.p_target, s.samples
        ),
    }
    if let (Some(g), Some(u)) = (&s.given_labelled, &s.unlabelled_share) {
        print_conditional(
            s,
            (g, u),
            ("labelled", "MPC labels x", "labelled"),
            (
                "unlabelled       P(MPC leaves x unlabelled)",
                "",
                "unlabelled states are not exceedances here",
            ),
        );
    }
    if let (Some(g), Some(u)) = (&s.given_feasible, &s.infeasible_share) {
        print_conditional(
            s,
            (g, u),
            (
                "feasible",
                "the MPC's hard problem is feasible at x",
                "feasible",
            ),
            (
                "infeasible       P(the hard problem has no solution at x)",
                ": unlabelled or soft-labelled",
                "unlabelled and soft-labelled states are left out",
            ),
        );
    }
    if let Some(soft) = &s.soft_labelled {
        println!(
            "    soft-labelled    {} states, max error {:.6} (the soft problem's labels: no bound \
             rests on them)",
            soft.states, soft.max_error
        );
    }
}

/// The statement given a subset of the states (`given`: its name, the condition in words,
/// what its states are called) and the bound on the share outside it (`share`: its line's
/// head, what its states are, what the conditional block leaves out), when that share is
/// not empty.
fn print_conditional(
    s: &trainer::certify::statistical::Statistical,
    (g, u): (
        &trainer::certify::statistical::GivenLabelled,
        &trainer::certify::statistical::UnlabelledShare,
    ),
    (name, condition, states): (&str, &str, &str),
    (head, which, left_out): (&str, &str, &str),
) {
    if u.unlabelled == 0 {
        return;
    }
    println!(
        "    given {name:<10} P(error > eps | {condition}) ≤ {:.3e} ({} exceedances in {} \
         {states} states; {left_out})",
        g.p_exceed_upper, g.exceedances, g.samples
    );
    match g.eps_at_p_target {
        Some(e) => println!(
            "    eps at P ≤ {:.1e} given {name}  {e:.6}   (statistical, confidence {})",
            s.p_target, s.confidence
        ),
        None => println!(
            "    eps at P ≤ {:.1e} given {name}  not reachable with {} states",
            s.p_target, g.samples
        ),
    }
    let place = u.bounding_box.as_ref().map_or(String::new(), |(lo, hi)| {
        format!(", all inside the box {lo:?} … {hi:?}")
    });
    println!(
        "    {head} ≤ {:.3e} ({} of {} states{place}{which}; Clopper–Pearson, confidence {})",
        u.p_upper, u.unlabelled, u.samples, s.confidence
    );
}
