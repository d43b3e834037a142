//! The sections of the report, in report order: each function returns one section's
//! blocks (heading, paragraphs, tables) from the run's artifacts (numbers and boxes
//! formatted by `format`).

use super::format::{boxed, num};
use super::{
    load, med_min_max, Artifacts, Block, ReportError, Timing, PAPER_TABLE_I, PAPER_TABLE_II,
};
use crate::certify::certificate::Certificate;
use crate::data::dataset::Dataset;
use crate::problem::ProblemConfig;
use crate::study::closed_loop::Run;
use crate::study::plots::{FigureEntry, PLOTS};
use crate::study::seeds::SeedRun;
use std::path::Path;

/// The problem: system, OCP, bounds, certified domain (and the setpoint, when given).
pub(super) fn problem(cfg: &ProblemConfig) -> Vec<Block> {
    let o = &cfg.ocp;
    let setpoint = if o.x_ref.is_some() || o.u_ref.is_some() {
        format!(
            " Setpoint x_ref = {}, u_ref = {}.",
            tuple(&o.x_ref_or_origin(cfg.system.nx())),
            tuple(&o.u_ref_or_zero(cfg.system.nu()))
        )
    } else {
        String::new()
    };
    vec![
        Block::Heading(2, "Problem".into()),
        Block::Para(format!(
            "System `{}` (nx = {}, nu = {}), Ts = {} {}, horizon N = {}, RK4 sub-steps {}; Q = {}, R = {}, P = {}. State bounds on x₁..x_N: x ∈ {}; input bounds U = {}. Certified (and sampled) domain X = {}.{setpoint}",
            cfg.system.name(),
            cfg.system.nx(),
            cfg.system.nu(),
            cfg.ocp.ts,
            cfg.system.time_unit(),
            cfg.ocp.horizon,
            cfg.ocp.rk4_substeps,
            json(&cfg.ocp.q),
            json(&cfg.ocp.r),
            json(&cfg.ocp.p),
            boxed(&cfg.ocp.x_lo, &cfg.ocp.x_hi),
            boxed(&cfg.ocp.u_lo, &cfg.ocp.u_hi),
            boxed(&cfg.domain.lo, &cfg.domain.hi),
        )),
        Block::Para({
            let (xs, us) = crate::study::plots::axis_names(&cfg.system);
            format!("States: {}; inputs: {}.", xs.join(", "), us.join(", "))
        }),
    ]
}

/// `(v₁, v₂, …)` with [`num`].
fn tuple(v: &[f64]) -> String {
    let parts: Vec<String> = v.iter().map(|x| num(*x)).collect();
    format!("({})", parts.join(", "))
}

/// The dataset: counts by label status, training and validation sizes.
pub(super) fn dataset(cfg: &ProblemConfig, a: &Artifacts) -> Vec<Block> {
    let c = a.data.counts();
    vec![
        Block::Heading(2, "Dataset".into()),
        Block::Table {
            head: strs(&[
                "states",
                "sampler",
                "converged",
                "soft (exact-penalty label)",
                "infeasible",
                "failed",
                "degenerate sensitivity",
            ]),
            rows: vec![row([
                c.total.to_string(),
                sampler_cell(&a.data.header.sampling),
                c.converged.to_string(),
                c.soft.to_string(),
                c.infeasible.to_string(),
                c.failed.to_string(),
                c.degenerate.to_string(),
            ])],
        },
        Block::Para(format!(
            "Soft: the hard OCP is infeasible at the state and the label is the exact-penalty optimum; infeasible and failed states have no label and are not trained on; degenerate points keep their value term and drop the Jacobian term. {} labelled training points; R² is measured on {} MPC-labelled random states of X.",
            a.nom.train_stats.n, a.nom.validation_stats.n
        )),
    ]
    .into_iter()
    .chain(starts_disagreement(
        crate::mpc::law::MpcLaw::new(cfg).starts(),
        &a.data,
    ))
    .collect()
}

/// Where the starts of `solver.starts` reached different hard optima (the dataset's
/// disagreeing indices): the count, the rule that chose the label, and the first few states.
/// Nothing when they never disagreed (the report of such a run is unchanged).
pub(super) fn starts_disagreement(
    starts: &[crate::problem::solver::Start],
    data: &Dataset,
) -> Vec<Block> {
    let d = &data.disagree;
    if d.is_empty() {
        return Vec::new();
    }
    let starts: Vec<&str> = starts.iter().map(|s| s.as_str()).collect();
    let rows: Vec<Vec<String>> = d
        .iter()
        .filter_map(|&i| data.records.iter().find(|r| r.index == i))
        .take(5)
        .map(|r| {
            let v = |x: &[f64]| {
                let s: Vec<String> = x.iter().map(|v| format!("{v:.4}")).collect();
                format!("({})", s.join(", "))
            };
            vec![
                r.index.to_string(),
                v(&r.x),
                v(&r.u),
                format!("{:.6e}", r.cost),
            ]
        })
        .collect();
    vec![
        Block::Para(format!(
            "**Where the starts disagree.** At {} of {} states the starts `{}` reached different hard optima (costs and u₀ apart by more than {:e} relative): the MPC law is set-valued there, and a regression would average branches. The label is the lowest-cost optimum; costs within {:e} relative go to the earlier start in the list (`warm` first: the branch continued from the previous labelled state). The first of them (index, x, the chosen u₀, its cost):",
            d.len(),
            data.records.len(),
            starts.join(", "),
            crate::mpc::law::starts::OPTIMA_TOL,
            crate::mpc::law::starts::TIE_TOL,
        )),
        Block::Table {
            head: strs(&["index", "x", "u₀ (chosen)", "cost"]),
            rows,
        },
    ]
}

/// The sampler of the dataset table: a grid with its counts per axis, the other samplers
/// with their number of states and seed.
fn sampler_cell(s: &crate::problem::SamplingSettings) -> String {
    match s.sampler {
        crate::problem::SamplerKind::Grid => format!("{:?} {:?}", s.sampler, s.counts),
        _ => format!("{:?}, n = {}, seed {}", s.sampler, s.n, s.seed),
    }
}

/// Whether this is the paper's problem (the embedded pendulum's dynamics dimensions and OCP:
/// sampling time, horizon, weights and bounds), whose Tables I and II are shown beside ours.
/// Other problems get no paper columns: the paper's figures are about another plant.
pub(super) fn is_paper_problem(cfg: &ProblemConfig) -> bool {
    let paper = ProblemConfig::default();
    let (a, b) = (&cfg.ocp, &paper.ocp);
    cfg.system.nx() == paper.system.nx()
        && cfg.system.nu() == paper.system.nu()
        && a.ts == b.ts
        && a.horizon == b.horizon
        && a.q == b.q
        && a.r == b.r
        && a.p == b.p
        && a.x_lo == b.x_lo
        && a.x_hi == b.x_hi
        && a.u_lo == b.u_lo
        && a.u_hi == b.u_hi
}

/// Table I: both nets after training (R², ε_D, the Lipschitz bounds) beside the paper's
/// (for the paper's problem only, [`is_paper_problem`]).
pub(super) fn table_i(cfg: &ProblemConfig, a: &Artifacts) -> Vec<Block> {
    let paper_cols = is_paper_problem(cfg);
    let mut rows = Vec::new();
    for ((name, m, ce), (_, paper)) in [
        ("nominal", &a.nom, &a.cert_n),
        ("regularized", &a.reg, &a.cert),
    ]
    .into_iter()
    .zip(PAPER_TABLE_I)
    {
        let mut r = row([
            name.to_string(),
            format!("{:.4}", m.validation_stats.r2),
            format!("{:.3}", ce.eps_d),
            format!("{:.2} ({:?})", ce.l_nn, ce.l_nn_method),
            format!("{:.2}", ce.l_nn_lipsdp),
            format!("{:.2}", ce.l_nn_naive),
            format!("{:.2}", ce.l_nn_lower),
            format!("{:.3}", m.train_stats.median),
            format!("{} / {} / {}", paper[0], paper[1], paper[2]),
        ]);
        if !paper_cols {
            r.pop();
        }
        rows.push(r);
    }
    let mut head = strs(&[
        "net",
        "validation R²",
        "ε_D",
        "L_NN (sound, method)",
        "LipSDP-Neuron",
        "naive",
        "sampled lower",
        "median error",
        "paper R² / ε_D / L_NN",
    ]);
    if !paper_cols {
        head.pop();
    }
    vec![
        Block::Heading(2, "Table I: networks after training".into()),
        Block::Table { head, rows },
    ]
}

/// The end of Table I's section: R² and ε_D of both nets over the training seeds.
pub(super) fn training_seeds(cfg: &ProblemConfig, a: &Artifacts) -> Vec<Block> {
    let seeds = &a.seeds;
    vec![
        Block::Para(format!(
            "Training seed {} (initial weights and shuffling, the same for both nets). Over {} seeds ({}), median [min, max]:",
            cfg.training.seed,
            seeds.len(),
            seed_range(seeds)
        )),
        Block::Table {
            head: strs(&["net", "validation R²", "ε_D"]),
            rows: ["nominal", "regularized"]
                .iter()
                .enumerate()
                .map(|(k, name)| {
                    row([
                        name.to_string(),
                        mmm(&seed_list(seeds, k, |s| s.r2_validation)),
                        mmm(&seed_list(seeds, k, |s| s.eps_d)),
                    ])
                })
                .collect(),
        },
    ]
}

/// The certificate (Theorem 1): every term for both nets, how it was obtained and whether
/// it is an estimate; the f32 allowance of the exported controller and its clamp band.
pub(super) fn certificate(a: &Artifacts) -> Vec<Block> {
    let (cert, cert_n) = (&a.cert, &a.cert_n);
    let f32a = a.export["f32_allowance_libm"].as_f64().unwrap_or(f64::NAN);
    let cert_rows = |name: &str, f: &dyn Fn(&Certificate) -> String, how: String| {
        row([name.to_string(), f(cert), f(cert_n), how])
    };
    let mut rows = vec![
        cert_rows(
            "ε_D",
            &|c| format!("{:.6}", c.eps_d),
            format!("max ‖κ − κ_NN‖ over {} labelled points (computed)", cert.n_points),
        ),
        cert_rows(
            "L_NN",
            &|c| format!("{:.4}", c.l_nn),
            format!("{:?}: a sound upper bound (naive product of norms {:.2}, sampled lower bound {:.2})", cert.l_nn_method, cert.l_nn_naive, cert.l_nn_lower),
        ),
        cert_rows(
            "L_MPC",
            &|c| format!("{:.4}", c.l_mpc),
            format!(
                "{}{}",
                cert.l_mpc_method,
                if cert.l_mpc_is_estimate { " — **an estimate**, not a proven bound" } else { " — supplied as proven" }
            ),
        ),
        cert_rows(
            "r",
            &|c| format!("{:.6}", c.covering_radius),
            cert.covering_method.clone(),
        ),
        cert_rows(
            "**ε**",
            &|c| format!("**{:.4}**", c.eps),
            format!(
                "ε_D + (L_MPC + L_NN)·r{}",
                if cert.l_mpc_is_estimate { "; L_MPC is an estimate, so ε is too" } else { "" }
            ),
        ),
    ];
    rows.push(row([
        "f32 allowance".to_string(),
        format!("{f32a:.3e}"),
        "—".into(),
        "sound bound on |κ_NN,f32 − κ_NN,f64| over X for the exported controller (libm tanh); added to ε on the device".into(),
    ]));
    rows.push(row([
        "ε on the device".to_string(),
        format!("{:.4}", cert.eps + f32a),
        "—".into(),
        "ε + f32 allowance".into(),
    ]));
    vec![
        Block::Heading(2, "Certificate (Theorem 1)".into()),
        Block::Table {
            head: strs(&["term", "regularized", "nominal", "how"]),
            rows,
        },
        Block::Para({
            let (lo, hi) = super::verdict::exported_band(a);
            format!(
                "The exported (regularized) controller clamps to (U ⊕ [−ε, ε]) ∩ U = u ∈ {} (the actuator limits are U: a clamp wider than U would let the controller ask for inputs the MPC never gives).",
                boxed(&lo, &hi)
            )
        }),
    ]
}

/// Table II: the closed loop of the MPC and both nets from the reference initial state,
/// beside the paper's (for the paper's problem only, [`is_paper_problem`]).
pub(super) fn table_ii(cfg: &ProblemConfig, a: &Artifacts) -> Vec<Block> {
    let first = |k: &str| a.cl.get(k).and_then(|v| v.first());
    let x0: Vec<String> = first("mpc")
        .map(|r| r.x0.iter().map(|v| num(*v)).collect())
        .unwrap_or_default();
    let steps = first("mpc").map_or(0, |r| r.steps);
    let paper_cols = is_paper_problem(cfg);
    let mut rows = Vec::new();
    for k in ["mpc", "nominal", "regularized"] {
        let paper = PAPER_TABLE_II
            .iter()
            .find(|(n, _)| *n == k)
            .map_or("—".to_string(), |(_, p)| {
                format!("{} / {} / {}", p[0], p[1], p[2])
            });
        if let Some(r) = first(k) {
            let mut cells = row([
                k.to_string(),
                format!("{:.3}", r.violation_percent),
                format!("{:.4}", r.max_violation),
                format!("{:.4}", r.max_input_divergence),
                format!("{:.1}", r.cost),
                r.settling_step.map_or("never".into(), |v| v.to_string()),
                r.left_band.to_string(),
                paper,
            ]);
            if !paper_cols {
                cells.pop();
            }
            rows.push(cells);
        }
    }
    let mut head = strs(&[
        "controller",
        "violating steps %",
        "max violation",
        "max input divergence",
        "cost",
        "settling step",
        "left certified band",
        "paper % / max / divergence",
    ]);
    if !paper_cols {
        head.pop();
    }
    vec![
        Block::Heading(2, "Table II: closed loop".into()),
        Block::Para(format!(
            "From x₀ = ({}) ({steps} steps = {} {}, nominal plant, no noise), training seed {}:",
            x0.join(", "),
            steps as f64 * cfg.ocp.ts,
            cfg.system.time_unit(),
            cfg.training.seed
        )),
        Block::Table { head, rows },
        final_offsets(cfg, a),
    ]
}

/// The summary line of the final offsets |x_steps − x_ref| of the runs from x₀, and the
/// nets' outputs at the setpoint when they hold it.
fn final_offsets(cfg: &ProblemConfig, a: &Artifacts) -> Block {
    let x_ref = cfg.ocp.x_ref_or_origin(cfg.system.nx());
    let sci = |v: &[f64]| {
        let parts: Vec<String> = v.iter().map(|x| format!("{x:.3e}")).collect();
        format!("({})", parts.join(", "))
    };
    let parts: Vec<String> = ["mpc", "nominal", "regularized"]
        .iter()
        .filter_map(|k| {
            let r = a.cl.get(*k).and_then(|v| v.first())?;
            Some(format!("{k} {}", sci(&r.final_offset)))
        })
        .collect();
    let mut s = format!(
        "Final offset |x − x_ref| per state after the last step, x_ref = {}: {}.",
        tuple(&x_ref),
        parts.join("; ")
    );
    let held: Vec<String> = [("nominal", &a.nom), ("regularized", &a.reg)]
        .iter()
        .filter(|(_, m)| m.settings.hold_setpoint)
        .map(|(k, m)| format!("{k} {}", sci(&m.mlp.predict(&x_ref))))
        .collect();
    if !held.is_empty() {
        s += &format!(
            " The nets hold the setpoint (`training.hold_setpoint`: κ(x_ref) − κ_NN(x_ref) folded into the last bias); their outputs at x_ref: {}.",
            held.join("; ")
        );
    }
    Block::Para(s)
}

/// Table II's closed loop of both nets over the training seeds.
pub(super) fn closed_loop_seeds(a: &Artifacts) -> Vec<Block> {
    let seeds = &a.seeds;
    vec![
        Block::Para(format!(
            "Over {} training seeds ({}), same x₀, median [min, max]:",
            seeds.len(),
            seed_range(seeds)
        )),
        Block::Table {
            head: strs(&[
                "net",
                "violating steps %",
                "max violation",
                "max input divergence",
                "cost",
            ]),
            rows: ["nominal", "regularized"]
                .iter()
                .enumerate()
                .map(|(k, name)| {
                    row([
                        name.to_string(),
                        mmm(&seed_list(seeds, k, |s| s.run.violation_percent)),
                        mmm(&seed_list(seeds, k, |s| s.run.max_violation)),
                        mmm(&seed_list(seeds, k, |s| s.run.max_input_divergence)),
                        mmm(&seed_list(seeds, k, |s| s.run.cost)),
                    ])
                })
                .collect(),
        },
    ]
}

/// Every set of closed-loop runs (all initial states, the robustness runs).
pub(super) fn all_runs(cfg: &ProblemConfig, a: &Artifacts) -> Vec<Block> {
    let mut rows = Vec::new();
    for (k, runs) in &a.cl {
        let col = |f: fn(&Run) -> f64| mmm(&runs.iter().map(f).collect::<Vec<_>>());
        rows.push(row([
            k.clone(),
            runs.len().to_string(),
            col(|r| r.violation_percent),
            col(|r| r.max_violation),
            col(|r| r.max_input_divergence),
            col(|r| r.cost),
        ]));
    }
    let has_mass = cfg.system.with_mass_scaled(1.0).is_some();
    let mismatch: String = cfg
        .closed_loop
        .mismatch_scenarios(has_mass)
        .iter()
        .map(|sc| match &sc.parameter {
            None => format!("; `_mass±`: plant mass ±{} %", 100.0 * sc.relative),
            Some(p) => format!("; `_{p}±`: parameter `{p}` ±{} %", 100.0 * sc.relative),
        })
        .collect();
    vec![
        Block::Para(format!(
            "Over all initial states (x₀ and {} random states of X) and the robustness runs (`_noise`: measurement noise {} of the domain half-width, {} seeds{mismatch}), training seed {}, median [min, max]:",
            cfg.closed_loop.random_initial_states,
            cfg.closed_loop.noise_fraction,
            cfg.closed_loop.noise_runs,
            cfg.training.seed
        )),
        Block::Table {
            head: strs(&[
                "runs",
                "n",
                "violating steps %",
                "max violation",
                "max input divergence",
                "cost",
            ]),
            rows,
        },
    ]
}

/// The figures of [`PLOTS`] with their captions from `plots/figures.json`.
pub(super) fn figures(dir: &Path) -> Result<Vec<Block>, ReportError> {
    let mut b = vec![Block::Heading(2, "Figures".into())];
    let figures: Vec<FigureEntry> = load(&dir.join("plots/figures.json"))?;
    for stem in PLOTS {
        let caption = figures
            .iter()
            .find(|f| f.name == stem)
            .map(|f| f.caption.clone())
            .ok_or_else(|| ReportError::MissingFigure {
                index: "plots/figures.json".into(),
                figure: stem.to_string(),
            })?;
        b.push(Block::Figure {
            stem: stem.to_string(),
            caption,
        });
    }
    Ok(b)
}

/// The stage timings and their total.
pub(super) fn timings(timings: &[Timing]) -> Vec<Block> {
    let total: f64 = timings
        .iter()
        .filter(|t| !t.skipped)
        .map(|t| t.seconds)
        .sum();
    let mut rows: Vec<Vec<String>> = timings
        .iter()
        .map(|t| {
            row([
                t.stage.clone(),
                format!("{:.3}", t.seconds),
                if t.skipped {
                    "skipped (time of the run that made it)".into()
                } else {
                    "ran".into()
                },
            ])
        })
        .collect();
    rows.push(row([
        "stages run before the report".to_string(),
        format!("{total:.3}"),
        String::new(),
    ]));
    vec![
        Block::Heading(2, "Stage timings".into()),
        Block::Table {
            head: strs(&["stage", "seconds", "this run"]),
            rows,
        },
        Block::Para(format!(
            "Wall-clock times on this machine ({} threads available to rayon).",
            rayon::current_num_threads()
        )),
    ]
}

/// The command that reproduces the run.
pub(super) fn reproduce(dir: &Path) -> Vec<Block> {
    vec![
        Block::Heading(2, "Reproduce".into()),
        Block::Code(format!(
            "cargo run --release -p trainer -- run {} --out {}",
            dir.join("problem.toml").display(),
            dir.parent().map_or(".".into(), |p| p.display().to_string())
        )),
    ]
}

/// Values of `f` for net `k` (0: nominal, 1: regularized) over the training seeds.
fn seed_list(seeds: &[[SeedRun; 2]], k: usize, f: fn(&SeedRun) -> f64) -> Vec<f64> {
    seeds.iter().map(|s| f(&s[k])).collect()
}

/// The training seeds as `first..=last`.
fn seed_range(seeds: &[[SeedRun; 2]]) -> String {
    match (seeds.first(), seeds.last()) {
        (Some(a), Some(z)) => format!("{}..={}", a[0].seed, z[0].seed),
        _ => "none".into(),
    }
}

/// Median [min, max] with three decimals.
fn mmm(v: &[f64]) -> String {
    let (a, b, c) = med_min_max(v);
    format!("{a:.3} [{b:.3}, {c:.3}]")
}

/// Compact JSON of a value, for the problem summary.
fn json<T: serde::Serialize>(v: &T) -> String {
    serde_json::to_string(v).unwrap_or_default()
}

/// A table row.
fn row(cells: impl IntoIterator<Item = String>) -> Vec<String> {
    cells.into_iter().collect()
}

/// Owned strings.
pub(super) fn strs(v: &[&str]) -> Vec<String> {
    v.iter().map(|s| s.to_string()).collect()
}
