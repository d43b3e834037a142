//! `trainer refine`: adaptive refinement with local certificates for the problem file's
//! `[refine]` table (`--config`; a robust design refines the tightened MPC). Resumes from
//! `<out>/refine_state.bin` and writes the model, dataset, certificate, cells and log into
//! the output directory (default `runs/<name>/refine`), plus `eps_map.svg`/`.png` for two or
//! more states, `refine_rounds.svg`/`.png` (ε per round) and, with `--check`, `check.json`; with `--statistical N` the certificate
//! gets its statistical tier (states kept in `statistical.bin`). Fails if the target ε is
//! not met. `--certify-only --model M` keeps the network of M (a model file or an ONNX file)
//! fixed and refines only the cells; the certificate is about M (its hash); for an ONNX M no
//! `model.bin` is written (export M itself with the certificate).
//!
//! The problem: `--config`, else the one stored in `--data` (its header) or in `--model`
//! (`learn::model_file`), else — nothing names one — the embedded pendulum (said on
//! stderr). A model of another problem than the refined one is refused.

use super::certify::{print_statistical, StatisticalArgs};
use super::common::{embedded_pendulum, load_config, problem_for_data, problem_for_model};
use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};
use trainer::certify::refine::{self, LocalCertificate, Refined, RoundLog};
use trainer::certify::statistical::StatisticalOptions;
use trainer::data::dataset::Dataset;
use trainer::problem::{ProblemConfig, RefineSettings};

/// The arguments of `trainer refine` (their doc comments are the help text).
#[derive(clap::Args)]
pub(super) struct Args {
    /// Problem file (default: the embedded pendulum); its `[refine]` table applies.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Target certified ε (overrides `refine.target_eps`).
    #[arg(long)]
    target_eps: Option<f64>,
    /// Budget of OCP solves (overrides `refine.budget`).
    #[arg(long)]
    budget: Option<usize>,
    /// Output directory (default: runs/<name>/refine).
    #[arg(long)]
    out: Option<PathBuf>,
    /// After refining, check the certificate at this many random states solved by the
    /// MPC (writes check.json).
    #[arg(long)]
    check: Option<usize>,
    /// Seed of the check's states.
    #[arg(long, default_value_t = 2024)]
    check_seed: u64,
    /// Labels for the first round: a dataset of this problem (e.g. from `trainer
    /// import`) whose records on the initial grid label those corners (no OCP solve).
    #[arg(long)]
    data: Option<PathBuf>,
    /// Keep the network of --model fixed: only split the cells (solving the MPC at their
    /// corners) until the target or the budget, and certify that network (no training).
    #[arg(long, requires = "model")]
    certify_only: bool,
    /// The network to certify with --certify-only: a model file or an ONNX file.
    #[arg(long, requires = "certify_only")]
    model: Option<PathBuf>,
    /// No progress lines.
    #[arg(long, short)]
    quiet: bool,
    #[command(flatten)]
    statistical: StatisticalArgs,
}

impl Args {
    /// Refines (or, with `--certify-only`, certifies `--model` cell by cell).
    pub(super) fn run(self) -> Result<()> {
        execute(
            self.config.as_deref(),
            self.target_eps,
            self.budget,
            self.out.as_deref(),
            (self.check.map(|n| (n, self.check_seed)), &self.statistical),
            self.data.as_deref(),
            self.model.as_deref(),
            self.quiet,
        )
    }
}

#[allow(clippy::too_many_arguments)]
pub(super) fn execute(
    config: Option<&Path>,
    target_eps: Option<f64>,
    budget: Option<usize>,
    out: Option<&Path>,
    (check, statistical): (Option<(usize, u64)>, &StatisticalArgs),
    data: Option<&Path>,
    fixed: Option<&Path>,
    quiet: bool,
) -> Result<()> {
    let fixed_path = fixed;
    let fixed_model = fixed
        .map(|p| super::common::load_model(p).map(|m| (p, m)))
        .transpose()?;
    let base = refined_problem(config, data, fixed_model.as_ref())?;
    // A problem stored in an artifact may already be a robust design's tightened MPC.
    let tightened = config.is_none() && base.ocp.stages.is_some();
    let (cfg, robust_design) = refine_config(base, tightened, target_eps, budget)?;
    let initial_labels = data
        .map(|p| first_round_labels(&cfg, p, quiet))
        .transpose()?;
    let fixed = fixed_model
        .map(|(p, m)| fixed_network(&cfg, p, m))
        .transpose()?;
    let rs = cfg.refine.clone();
    let dir = out
        .map(Path::to_path_buf)
        .unwrap_or_else(|| Path::new("runs").join(&cfg.name).join("refine"));
    std::fs::create_dir_all(&dir)
        .with_context(|| format!("cannot create output directory {}", dir.display()))?;
    let stat = statistical.options(dir.join("statistical.bin"))?;
    let t0 = std::time::Instant::now();
    let name = cfg.name.clone();
    let resume = resume_command(config, target_eps, budget, &dir, data, fixed_path);
    let opts = refine::RefineOptions {
        on_round: (!quiet).then_some(print_round as fn(&RoundLog, usize)),
        initial_labels,
        fixed,
        on_result: Some(refine::writing_sink(
            &cfg,
            &dir,
            &resume,
            (BEST_AFTER_SECONDS, quiet),
            std::sync::Arc::new(move |m, c| {
                trainer::deploy::export::deployed_allowance(&name, m, c)
            }),
        )),
        // The check's solves beside the retrainings.
        ahead: check
            .map(|(n, seed)| std::sync::Arc::new(refine::CheckAhead::start(&cfg, &rs, n, seed))),
    };
    let (r, checked) = refine_and_check(&cfg, &opts, &dir.join("refine_state.bin"), check, quiet)?;
    let mut cert = refine::write_outputs(&cfg, &rs, &r, &dir, checked.as_ref(), &|c| {
        trainer::deploy::export::deployed_allowance(&cfg.name, &r.model, c)
    })?;
    if let Some(st) = &stat {
        add_statistical(&cfg, &r, &mut cert, st, &dir, quiet)?;
    }
    if cfg.system.nx() >= 2 {
        write_eps_map(&cfg, &rs, &r, &dir)?;
    }
    write_rounds(&cfg, &rs, &r, &dir)?;
    if !quiet {
        print_summary(&cfg, &rs, &cert, t0.elapsed().as_secs_f64(), &dir);
    }
    if let Some(c) = &checked {
        check_certificate(c, &dir, quiet)?;
    }
    if let Some(design) = robust_design {
        let v = robust_verdict(&cfg, &r, &cert, checked.as_ref(), design);
        if !quiet {
            println!("robust design: {}", v.message);
        }
    }
    let report = refine::RefineReport::new(&cfg, &rs, &r, r.stopped, resume);
    refine::write_report(&dir, &report)?;
    if !r.met {
        refine::print_infinite(&report.infinite);
        bail!(
            "target ε {} not met ({}; budget {} solves, {} rounds{}): certified ε {:.4} \
             (outputs and {} in {}; resume: {})",
            rs.target_eps,
            r.stopped.describe(),
            rs.budget,
            rs.max_rounds,
            rs.max_seconds.map_or(String::new(), |s| format!(", {s} s")),
            cert.base.eps,
            refine::REPORT_FILE,
            dir.display(),
            report.resume
        );
    }
    Ok(())
}

/// Seconds of a run after which its best certificate so far is rewritten (the first best is
/// written at once).
const BEST_AFTER_SECONDS: f64 = 10.0;

/// The command that resumes this run from its checkpoint (the same problem, output
/// directory and overrides).
fn resume_command(
    config: Option<&Path>,
    target_eps: Option<f64>,
    budget: Option<usize>,
    dir: &Path,
    data: Option<&Path>,
    fixed: Option<&Path>,
) -> String {
    let mut c = String::from("trainer refine");
    if let Some(p) = config {
        c += &format!(" --config {}", p.display());
    }
    if let Some(p) = data {
        c += &format!(" --data {}", p.display());
    }
    if let Some(p) = fixed {
        c += &format!(" --certify-only --model {}", p.display());
    }
    if let Some(t) = target_eps {
        c += &format!(" --target-eps {t}");
    }
    if let Some(b) = budget {
        c += &format!(" --budget {b}");
    }
    c + &format!(" --out {}", dir.display())
}

/// The problem refined: `--config`, else the one stored in `--data`, else the one of
/// `--model`, else the embedded pendulum (module doc).
fn refined_problem(
    config: Option<&Path>,
    data: Option<&Path>,
    fixed_model: Option<&(&Path, trainer::certify::Model)>,
) -> Result<ProblemConfig> {
    Ok(match (config, data, fixed_model) {
        (Some(_), _, _) => load_config(config)?,
        (None, Some(p), _) => problem_for_data(None, p, &Dataset::load(p)?)?,
        (None, None, Some((p, m))) => problem_for_model(None, p, m)?.with_context(|| {
            format!(
                "{} names no problem (an ONNX file or a model of an older build): pass --config",
                p.display()
            )
        })?,
        (None, None, None) => embedded_pendulum(),
    })
}

/// The network of `--certify-only --model` (at `p`), checked to be of the refined problem:
/// its dimensions and (when it records one) its problem hash.
fn fixed_network(
    cfg: &ProblemConfig,
    p: &Path,
    m: trainer::certify::Model,
) -> Result<trainer::certify::Model> {
    let (nx, nu) = (cfg.system.nx(), cfg.system.nu());
    if (m.mlp.nx(), m.mlp.nu()) != (nx, nu) {
        bail!(
            "{}: the network maps {} states to {} inputs; problem `{}` has {nx} and {nu}",
            p.display(),
            m.mlp.nx(),
            m.mlp.nu(),
            cfg.name
        );
    }
    if !m.problem_hash.is_empty() && m.problem_hash != cfg.problem_hash() {
        bail!(
            "{} was trained on labels of problem {} (hash {}…), not of the refined \
             problem `{}` (hash {}…)",
            p.display(),
            super::common::stored_name(m.problem_toml.as_deref()),
            super::common::short(&m.problem_hash),
            cfg.name,
            super::common::short(&cfg.problem_hash())
        );
    }
    Ok(m)
}

/// Refines from the checkpoint; with `--check` (states, seed) a failed per-cell check
/// splits its offending cells and refines again, up to `[refine.check] feedback` times;
/// the last check is the verdict.
fn refine_and_check(
    cfg: &ProblemConfig,
    opts: &refine::RefineOptions,
    checkpoint: &Path,
    check: Option<(usize, u64)>,
    quiet: bool,
) -> Result<(Refined, Option<refine::Check>)> {
    let rs = &cfg.refine;
    let mut r = refine::refine(cfg, rs, Some(checkpoint), opts)?;
    let Some((n, check_seed)) = check else {
        return Ok((r, None));
    };
    for pass in 0.. {
        let c = match (&opts.ahead, pass) {
            (Some(a), 0) => refine::check_ahead(cfg, rs, &r, (n, check_seed), a),
            _ => refine::check(cfg, rs, &r, n, check_seed),
        };
        let p = &c.per_cell;
        // Offending cells, and excluded cells where a feasible state was found: split
        // both (an excluded cell's feasible part becomes cells of the domain).
        let mut leaves = p.leaves.clone();
        leaves.extend(&c.feasible_excluded_leaves);
        let passed = p.passed && c.feasible_in_excluded == 0;
        if passed || pass == rs.check.feedback || leaves.is_empty() {
            return Ok((r, Some(c)));
        }
        let split = refine::reopen(cfg, rs, &r.state, &leaves, &p.jump_states, checkpoint)?;
        if !quiet {
            eprintln!(
                "per-cell check failed (miss rate {:.4} > {}, {} over ε_C, {} jumps in {} \
                 cells): {split} cells split, refining again (pass {}/{})",
                p.miss_rate,
                p.tolerance,
                p.over_cell,
                p.jumps,
                p.offending_cells,
                pass + 1,
                rs.check.feedback
            );
        }
        r = refine::refine(cfg, rs, Some(checkpoint), opts)?;
    }
    // Pass `feedback` returns above; `0..` ends only past usize::MAX passes.
    Ok((r, None))
}

/// `--statistical N`: the statistical tier of the refined net's deployed controller, added
/// to the certificate (rewritten in `dir`).
fn add_statistical(
    cfg: &ProblemConfig,
    r: &Refined,
    cert: &mut LocalCertificate,
    (o, store): &(StatisticalOptions, std::path::PathBuf),
    dir: &Path,
    quiet: bool,
) -> Result<()> {
    // The function tested: the deployed controller of the refined net; the states
    // drawn from its hash, none a corner the net was trained on.
    let dep =
        trainer::deploy::export::Deployed::new(&cfg.name, &r.model, &cert.base).map_err(|e| {
            anyhow::anyhow!(
                "--statistical tests the deployed controller, which the refined net cannot \
                 be: {e}"
            )
        })?;
    let training: Vec<Vec<f64>> = r.state.points.iter().map(|p| p.x.clone()).collect();
    let s = trainer::certify::statistical::certify_statistically(
        cfg,
        &trainer::certify::statistical::Tested {
            controller: &dep,
            model_hash: &cert.base.hash,
            training: &training,
        },
        cert.base.eps,
        store,
        &StatisticalOptions {
            progress: !quiet,
            excluded: cert
                .local
                .excluded
                .as_ref()
                .map_or_else(Vec::new, |e| e.boxes.clone()),
            ..o.clone()
        },
    )
    .with_context(|| format!("statistical states in {}", store.display()))?;
    if !quiet {
        print_statistical(&s);
    }
    cert.statistical = Some(s);
    trainer::certify::file::write_certificate(
        &dir.join(trainer::certify::file::FILE_NAME),
        &cert.file(),
    )?;
    Ok(())
}

/// The robust design's verdict on the refined certificate (`design`: design ε and how
/// recursive feasibility is established).
fn robust_verdict(
    cfg: &ProblemConfig,
    r: &Refined,
    cert: &LocalCertificate,
    checked: Option<&refine::Check>,
    (design, rf): (f64, trainer::robust::Feasibility),
) -> trainer::robust::Verdict {
    // The exported controller's f32 allowance counts against the design ε too.
    // (NaN when the device cannot run the net: then nothing is certified.)
    let allowance = trainer::deploy::export::deployed_allowance(&cfg.name, &r.model, &cert.base)
        .unwrap_or(f64::NAN);
    let check = match checked {
        None => trainer::robust::Check::NotRun,
        Some(c) if c.per_cell.passed && c.feasible_in_excluded == 0 => {
            trainer::robust::Check::Passed
        }
        Some(_) => trainer::robust::Check::Failed,
    };
    trainer::robust::verdict(&trainer::robust::Evidence {
        design_eps: design,
        certified_eps: cert.base.eps,
        f32_allowance: allowance,
        recursive_feasibility: rf,
        eps_sound: cert.guarantee.guarantee == trainer::certify::tier::Tier::Sound,
        eps_rests_on: cert.guarantee.assumptions.clone(),
        check,
        // `refine` holds no design to prove the exclusions with: each box is assumed.
        excluded_unproven: cert.local.excluded.as_ref().map_or(0, |e| e.boxes.len()),
        feasible_in_excluded: checked.map_or(0, |c| c.feasible_in_excluded),
        // `refine` does not search beyond X (the robust loop of `trainer run` does).
        feasible_outside_domain: 0,
    })
}

/// `--data`: a dataset (e.g. from `trainer import`) labelled for this very problem, with
/// Jacobian labels; its records on the initial grid label the first round's corners.
fn first_round_labels(cfg: &ProblemConfig, path: &Path, quiet: bool) -> Result<Dataset> {
    let d = Dataset::load(path)?;
    if d.header.problem_hash != cfg.problem_hash() {
        bail!(
            "{} was labelled for problem `{}` (hash {}…), not for the refined problem `{}`",
            path.display(),
            d.header.problem,
            super::common::short(&d.header.problem_hash),
            cfg.name
        );
    }
    if d.labels.as_ref().is_some_and(|l| !l.jacobian) {
        bail!(
            "{}: imported without Jacobian columns du{{j}}_dx{{i}}; the local certificate \
             needs ∂κ/∂x at every corner",
            path.display()
        );
    }
    let (n, total) = refine::initial_corners_labelled(cfg, &cfg.refine, &d);
    if !quiet {
        eprintln!(
            "first round: {n} of the {total} initial grid corners labelled from {}{}",
            path.display(),
            if d.labels.is_some() {
                " (imported labels)"
            } else {
                ""
            }
        );
    }
    Ok(d)
}

/// The problem to refine (`cfg`, tightened already if `tightened`), with `--target-eps` and `--budget` applied, and the design ε of
/// a robust design (`[robust] eps > 0`), whose tightened MPC is then the problem.
fn refine_config(
    mut cfg: ProblemConfig,
    tightened: bool,
    target_eps: Option<f64>,
    budget: Option<usize>,
) -> Result<(ProblemConfig, Option<(f64, trainer::robust::Feasibility)>)> {
    // A robust design (`[robust] eps > 0`): refine the data of the tightened MPC, with the
    // design ε as the default target (Corollary 1 needs certified ε ≤ design ε).
    let mut robust_note = None;
    if cfg.robust.enabled() && !tightened {
        let design = trainer::robust::design(&cfg)?;
        let eps = cfg.robust.eps;
        let mut rcfg = trainer::robust::robust_config(&cfg, &design);
        if !cfg.name.ends_with("robust") {
            rcfg.name = format!("{}_robust", cfg.name);
        } else {
            rcfg.name = cfg.name.clone();
        }
        if target_eps.is_none() {
            // Room for the exported f32 allowance, which the verdict counts too.
            rcfg.refine.target_eps = eps * trainer::robust::REFINE_TARGET_FRACTION;
        }
        robust_note = Some((eps, design.recursive_feasibility()));
        cfg = rcfg;
    }
    if let Some(e) = target_eps {
        cfg.refine.target_eps = e;
    }
    if let Some(b) = budget {
        cfg.refine.budget = b;
    }
    cfg.refine
        .validate(cfg.system.nx())
        .context("invalid --target-eps / --budget")?;
    Ok((cfg, robust_note))
}

/// One progress line per refinement round (stderr).
fn print_round(l: &RoundLog, budget: usize) {
    eprintln!(
        "round {:>2}: cells {}/{} ok, certified ε {:.4} (corner max {:.4}), {} second-order, \
         solves {}/{budget}, {:.1} s",
        l.round, l.cells_ok, l.cells, l.eps, l.eps_d, l.second_order, l.solves, l.seconds
    );
}

/// The map of the cells' ε_C: `eps_map.svg` and `eps_map.png` in `dir`.
fn write_eps_map(cfg: &ProblemConfig, rs: &RefineSettings, r: &Refined, dir: &Path) -> Result<()> {
    let fig = trainer::study::plots::eps_map(
        cfg,
        &refine::cell_views(cfg, rs, &r.state),
        rs.target_eps,
        &refine::sensitivity_spread(cfg, &r.state),
    )?;
    let png = trainer::study::plots::to_png(fig.name, &fig.svg, cfg.plots.png_scale as f32)?;
    trainer::io::write_atomic(&dir.join("eps_map.svg"), fig.svg.as_bytes())?;
    trainer::io::write_atomic(&dir.join("eps_map.png"), &png)?;
    Ok(())
}

/// The ε-per-round curve: `refine_rounds.svg` and `refine_rounds.png` in `dir`.
fn write_rounds(cfg: &ProblemConfig, rs: &RefineSettings, r: &Refined, dir: &Path) -> Result<()> {
    let fig = trainer::study::plots::refine_rounds(&r.state.log, rs.target_eps)?;
    let png = trainer::study::plots::to_png(fig.name, &fig.svg, cfg.plots.png_scale as f32)?;
    trainer::io::write_atomic(&dir.join("refine_rounds.svg"), fig.svg.as_bytes())?;
    trainer::io::write_atomic(&dir.join("refine_rounds.png"), &png)?;
    Ok(())
}

/// The result line (stdout): certified ε against the target, solves, cells, and the global
/// Theorem 1 grid the same ε would need.
fn print_summary(
    cfg: &ProblemConfig,
    rs: &RefineSettings,
    cert: &LocalCertificate,
    seconds: f64,
    dir: &Path,
) {
    let l = &cert.local;
    println!(
        "{}: certified ε {:.4} (target {}{}) with {} solves, {} cells ({} second-order), \
         max corner error {:.4}; global Theorem 1 grid for this ε: {}; {:.1} s -> {}",
        cfg.name,
        cert.base.eps,
        rs.target_eps,
        if l.met { ", met" } else { ", NOT met" },
        l.solves,
        l.cells,
        l.cells_second_order,
        cert.base.eps_d,
        match (l.global_grid_solves, l.sparsification) {
            (Some(g), Some(s)) => format!("{g:.3e} solves ({s:.0}× more)"),
            _ => "none suffices (ε ≤ ε_D)".into(),
        },
        seconds,
        dir.display()
    );
    if let Some(e) = &l.excluded {
        println!(
            "certified domain: X minus {} excluded cells ({:.1} % of X, {} boxes; every \
             corner infeasible for the MPC) — listed in certificate.json (local.excluded)",
            e.cells,
            100.0 * e.volume_fraction,
            e.boxes.len()
        );
    }
}

/// `--check`: the certificate at N random states (seeded) and at every cell
/// (`refine::check`), written to `check.json` in `dir`; fails if a state is above ε or above
/// its cell's ε_C, if a jump of κ was found, or if the per-cell miss rate of the estimated
/// ranges exceeds the tolerance (naming the offending cells).
fn check_certificate(c: &refine::Check, dir: &Path, quiet: bool) -> Result<()> {
    trainer::io::write_atomic(
        &dir.join(trainer::io::RunDir::CHECK),
        refine::pretty(c).as_bytes(),
    )?;
    let p = &c.per_cell;
    if !quiet {
        println!(
            "check at {} random states ({} labelled): max observed {:.4} vs certified {:.4} \
             (ratio {:.2}); over ε: {}, over own cell's ε_C: {} (max ratio {:.3}); \
             slope estimate misses {}/{} (max excess {:.3}); {:.1} s",
            c.states,
            c.labelled,
            c.max_observed,
            c.certified,
            c.ratio,
            c.over_eps,
            c.over_cell,
            c.max_cell_ratio,
            c.slope_misses,
            c.slope_checks,
            c.max_slope_excess,
            c.seconds
        );
        if c.excluded_states > 0 {
            println!(
                "excluded cells: {} of the {} states fell in cells outside the certified \
                 domain (not counted above); {} of them are feasible for the MPC{}",
                c.excluded_states,
                c.states,
                c.feasible_in_excluded,
                if c.feasible_in_excluded > 0 {
                    " (the feasible set reaches into excluded cells: Corollary 1 does not \
                     cover those states)"
                } else {
                    ""
                }
            );
        }
        println!(
            "per-cell check: {} states in {} cells ({} near the target): range misses {}/{} \
             (rate {:.4}, tolerance {}), over ε_C {}, jumps {} (max |Δu| {:.2e} of the band): {}",
            p.states,
            p.cells,
            p.near_cells,
            p.range_misses,
            p.regular,
            p.miss_rate,
            p.tolerance,
            p.over_cell,
            p.jumps,
            p.max_jump,
            if p.passed { "passed" } else { "FAILED" }
        );
    }
    if c.feasible_in_excluded > 0 {
        bail!(
            "certificate check failed: {} of the states in excluded cells are feasible for the \
             MPC — the excluded set reaches into the feasible set, which ε must cover (see {}; \
             raise `refine.check.feedback` or the budget to split those cells)",
            c.feasible_in_excluded,
            dir.join(trainer::io::RunDir::CHECK).display()
        );
    }
    if c.over_eps > 0 || c.over_cell > 0 {
        bail!(
            "certificate check failed: {} states above ε, {} above their cell's ε_C (see {})",
            c.over_eps,
            c.over_cell,
            dir.join(trainer::io::RunDir::CHECK).display()
        );
    }
    if !p.passed {
        let cells: Vec<String> = p
            .offending
            .iter()
            .take(5)
            .map(|o| {
                format!(
                    "{:?}..{:?} ({} of {} states missed{}{})",
                    o.lo,
                    o.hi,
                    o.range_misses,
                    o.states,
                    if o.over_cell > 0 { ", over ε_C" } else { "" },
                    if o.jump { ", jump of κ" } else { "" }
                )
            })
            .collect();
        bail!(
            "per-cell check failed: range miss rate {:.4} (tolerance {}), {} states over ε_C, \
             {} jumps of κ, in {} offending cells, e.g. {} (all in {})",
            p.miss_rate,
            p.tolerance,
            p.over_cell,
            p.jumps,
            p.offending_cells,
            cells.join("; "),
            dir.join(trainer::io::RunDir::CHECK).display()
        );
    }
    Ok(())
}
