//! The stages of `trainer run`, in order, each a value: its name, the inputs it hashes
//! (files of earlier stages and the settings it reads), the files it writes, and its body.
//!
//! ```text
//! sample → validate → train → certify → refine → statistical → export → closed_loop → seeds
//!        → plots → report
//! ```

use super::manifest::{settings_hash, sha_file, Ctx};
use super::Env;
use super::{fail, fail_at, fail_in, PipelineError, Stage};
use crate::certify::certificate::CertifyOptions;
use crate::certify::file::CertificateFile;
use crate::certify::Model;
use crate::data::dataset::{generate, Dataset, GenerateOptions};
use crate::io::{write_atomic, RunDir};
use crate::learn::setpoint::Hold;
use crate::learn::train::{train, TrainOptions, TrainSet};
use crate::problem::{ProblemConfig, SamplerKind, SamplingSettings};
use crate::study::plots::{FigureEntry, PLOTS};
use crate::study::scenarios::{closed_loop, initial_states, ClosedLoop, ClosedLoopFile};
use rayon::prelude::*;
use std::collections::BTreeMap;
use std::path::Path;

type Inputs = BTreeMap<String, String>;

/// One stage of the pipeline: what it reads, writes and does.
pub(super) struct Step {
    /// Which stage (its name: `manifest_<name>.json`, `--force <name>`).
    pub(super) stage: Stage,
    /// Input name → hash.
    pub(super) inputs: fn(&Ctx, &ProblemConfig) -> Result<Inputs, PipelineError>,
    /// The files it writes, relative to the run directory.
    pub(super) outputs: fn() -> Vec<String>,
    /// Does the work in the run directory; returns a one-line summary.
    pub(super) body: fn(&Env, &RunDir) -> Result<String, PipelineError>,
}

/// The stages in order ([`Stage::ALL`]).
pub(super) const ALL: [Step; 11] = [
    Step {
        stage: Stage::Sample,
        inputs: sample_inputs,
        outputs: || files(&[RunDir::DATASET, RunDir::DATASET_CSV]),
        body: sample,
    },
    Step {
        stage: Stage::Validate,
        inputs: validate_inputs,
        outputs: || files(&[RunDir::VALIDATION]),
        body: validate,
    },
    Step {
        stage: Stage::Train,
        inputs: train_inputs,
        outputs: || files(&[RunDir::MODEL_NOMINAL, RunDir::MODEL_REGULARIZED]),
        body: train_both,
    },
    Step {
        stage: Stage::Certify,
        inputs: certify_inputs,
        outputs: || files(&[RunDir::CERTIFICATE, RunDir::CERTIFICATE_NOMINAL]),
        body: certify_both,
    },
    Step {
        stage: Stage::Refine,
        inputs: refine_inputs,
        outputs: || files(&[super::tiers::REFINE_JSON]),
        body: super::tiers::refine,
    },
    Step {
        stage: Stage::Statistical,
        inputs: statistical_inputs,
        outputs: || files(&[super::tiers::STATISTICAL_JSON]),
        body: super::tiers::statistical,
    },
    Step {
        stage: Stage::Export,
        inputs: export_inputs,
        outputs: || {
            files(&[
                RunDir::WEIGHTS_RS,
                RunDir::WEIGHTS_BIN,
                RunDir::EXPORT_REPORT,
            ])
        },
        body: super::exported::export,
    },
    Step {
        stage: Stage::ClosedLoop,
        inputs: closed_loop_inputs,
        outputs: || {
            files(&[
                RunDir::CLOSED_LOOP,
                super::exported::CLOSED_LOOP_STATISTICAL,
            ])
        },
        body: closed_loop_study,
    },
    Step {
        stage: Stage::Seeds,
        inputs: seeds_inputs,
        outputs: || files(&[RunDir::SEEDS]),
        body: seeds,
    },
    Step {
        stage: Stage::Plots,
        inputs: plots_inputs,
        outputs: plot_files,
        body: plots,
    },
    Step {
        stage: Stage::Report,
        inputs: report_inputs,
        outputs: || files(&[RunDir::REPORT_MD, RunDir::REPORT_HTML]),
        body: report,
    },
];

fn files(names: &[&str]) -> Vec<String> {
    names.iter().map(|s| s.to_string()).collect()
}

/// Hashes of the named files of the run directory.
fn hashes(cx: &Ctx, stage: Stage, names: &[&str]) -> Result<Inputs, PipelineError> {
    let mut inputs = BTreeMap::new();
    for f in names {
        inputs.insert(f.to_string(), cx.hash(stage, f)?);
    }
    Ok(inputs)
}

fn load_dataset(stage: Stage, p: &Path) -> Result<Dataset, PipelineError> {
    Dataset::load(p).map_err(|e| fail(stage, e))
}

fn load_model(stage: Stage, p: &Path) -> Result<Model, PipelineError> {
    Model::load(p).map_err(|e| fail(stage, e))
}

/// The certificate `name` of the run directory `d`, verified (sealed, with its tier) and
/// re-checked against the model `m`, the run's problem `cfg` and its `dataset.bin`.
fn read_run_certificate(
    stage: Stage,
    (d, cfg): (&RunDir, &ProblemConfig),
    name: &str,
    m: &Model,
) -> Result<CertificateFile, PipelineError> {
    let data = std::fs::read(d.dataset()).map_err(|e| fail_at(stage, &d.dataset(), e))?;
    let (model_hash, dataset_hash) = (m.content_hash(), crate::io::sha256_hex(&data));
    let against = crate::certify::file::Against {
        model_hash: Some(&model_hash),
        problem: Some(cfg),
        dataset_hash: Some(&dataset_hash),
        cells_csv: None,
    };
    crate::certify::file::read_certificate(&d.join(name), false, &against)
        .map(|(f, _)| f)
        .map_err(|e| fail(stage, e))
}

fn load_json<T: serde::de::DeserializeOwned>(stage: Stage, p: &Path) -> Result<T, PipelineError> {
    let text = std::fs::read_to_string(p).map_err(|e| fail_at(stage, p, e))?;
    serde_json::from_str(&text).map_err(|e| fail_at(stage, p, e))
}

// ---- sample: the labelled sampling plan -------------------------------------------------

fn sample_inputs(_: &Ctx, cfg: &ProblemConfig) -> Result<Inputs, PipelineError> {
    let mut inputs = BTreeMap::new();
    inputs.insert("problem".into(), cfg.problem_hash());
    inputs.insert("sampling".into(), settings_hash(&cfg.sampling));
    if cfg.keeps_sequences() {
        // (Absent by default, so a default run's manifest is unchanged.)
        inputs.insert("sequences".into(), "kept".into());
    }
    Ok(inputs)
}

fn sample(env: &Env, d: &RunDir) -> Result<String, PipelineError> {
    let g = GenerateOptions {
        shard: None,
        progress: env.progress,
    };
    let ds = generate(env.cfg, &d.dataset(), &g).map_err(|e| fail(Stage::Sample, e))?;
    let c = ds.counts();
    let mut line = format!(
        "{} states: {} converged, {} soft, {} infeasible, {} failed, {} degenerate",
        c.total, c.converged, c.soft, c.infeasible, c.failed, c.degenerate
    );
    // The feasibility pre-scan: where the plan's states have no label (the later stages
    // use the labelled ones).
    let un = crate::data::unlabelled::Unlabelled::of(&ds);
    if let Some((lo, hi)) = &un.bounding_box {
        let text = serde_json::to_string_pretty(&un).map_err(|e| fail(Stage::Sample, e))?;
        write_atomic(&d.infeasible(), text.as_bytes()).map_err(|e| fail(Stage::Sample, e))?;
        line += &format!(
            "; {} unlabelled, inside {lo:?} … {hi:?} (infeasible.json; later stages use the \
             labelled states)",
            un.unlabelled
        );
    }
    Ok(line)
}

// ---- validate: MPC labels of random states (R², L_MPC estimate) ------------------------

/// The problem whose sampling plan is the validation set (`[training] validation_n` random
/// states from `validation_seed`): the `validate` stage labels it, `trainer sample
/// --validation` labels it (or one shard of it, `--shard K/M`; `trainer merge` of the M
/// shards is byte-identical to the stage's `validation.bin`).
pub fn validation_config(cfg: &ProblemConfig) -> ProblemConfig {
    // (Validation only counts the states the MPC leaves unlabelled: no retry ladder.)
    let mut vcfg = crate::mpc::law::ladder::counting_problem(cfg);
    vcfg.sampling = SamplingSettings {
        sampler: SamplerKind::Random,
        n: cfg.training.validation_n.max(1),
        seed: cfg.training.validation_seed,
        counts: vec![],
    };
    vcfg
}

fn validate_inputs(_: &Ctx, cfg: &ProblemConfig) -> Result<Inputs, PipelineError> {
    let mut inputs = BTreeMap::new();
    inputs.insert("problem".into(), cfg.problem_hash());
    inputs.insert(
        "sampling".into(),
        settings_hash(&validation_config(cfg).sampling),
    );
    Ok(inputs)
}

fn validate(env: &Env, d: &RunDir) -> Result<String, PipelineError> {
    let g = GenerateOptions {
        shard: None,
        progress: env.progress,
    };
    let vcfg = validation_config(env.cfg);
    let ds = generate(&vcfg, &d.validation(), &g).map_err(|e| fail(Stage::Validate, e))?;
    let labelled = ds.records.iter().filter(|r| r.is_labelled()).count();
    let mut line = format!("{labelled} random validation states labelled");
    if labelled < ds.records.len() {
        line += &format!(
            ", {} unlabelled (left out of R² and the estimates)",
            ds.records.len() - labelled
        );
    }
    Ok(line)
}

// ---- train: nominal and regularized nets from the same initial weights -----------------

fn train_inputs(cx: &Ctx, cfg: &ProblemConfig) -> Result<Inputs, PipelineError> {
    let mut inputs = BTreeMap::new();
    inputs.insert("dataset".into(), cx.hash(Stage::Train, RunDir::DATASET)?);
    inputs.insert(
        "validation".into(),
        cx.hash(Stage::Train, RunDir::VALIDATION)?,
    );
    inputs.insert("training".into(), settings_hash(&cfg.training));
    Ok(inputs)
}

fn train_both(env: &Env, d: &RunDir) -> Result<String, PipelineError> {
    let cfg = env.cfg;
    let data = load_dataset(Stage::Train, &d.dataset())?;
    let val = load_dataset(Stage::Train, &d.validation())?;
    let dh = sha_file(&d.dataset()).map_err(|e| fail(Stage::Train, e))?;
    let (set, vset) = (TrainSet::from_dataset(&data), TrainSet::from_dataset(&val));
    if set.is_empty() {
        return Err(fail(Stage::Train, "the dataset has no labelled points"));
    }
    // Both nets hold the setpoint (`training.hold_setpoint`): κ(x_ref) solved once.
    let hold =
        Hold::if_enabled(cfg, cfg.training.hold_setpoint).map_err(|e| fail(Stage::Train, e))?;
    let toml = cfg.to_toml_string().map_err(|e| fail(Stage::Train, e))?;
    let one = |nominal: bool| -> Result<Model, PipelineError> {
        let opts = TrainOptions {
            nominal,
            progress: None,
            hold: hold.clone(),
            keep_best: None,
        };
        let mut m: Model = if cfg.keeps_sequences() {
            // The sequence net; the model's net is its u₀ rows (`learn::sequence`).
            let names = (RunDir::DATASET, RunDir::VALIDATION);
            let (ph, dh) = (&data.header.problem_hash, &dh);
            crate::learn::sequence::train_sequence(cfg, &opts, &data, &val, names, ph, dh)
                .map_err(|e| fail(Stage::Train, e))?
        } else {
            train(
                &cfg.training,
                &opts,
                &set,
                &vset,
                (&cfg.domain.lo, &cfg.domain.hi),
                (&cfg.ocp.u_lo, &cfg.ocp.u_hi),
                &data.header.problem_hash,
                &dh,
            )
        };
        m.problem_toml = Some(toml.clone());
        Ok(m)
    };
    let (n, r) = rayon::join(|| one(true), || one(false));
    let (n, r) = (n?, r?);
    n.save(&d.model_nominal())
        .map_err(|e| fail(Stage::Train, e))?;
    r.save(&d.model_regularized())
        .map_err(|e| fail(Stage::Train, e))?;
    let unlabelled = data.records.len() - set.len();
    Ok(format!(
        "nominal ε_D {:.3}, R² {:.4}; regularized ε_D {:.3}, R² {:.4}{}",
        n.train_stats.max,
        n.validation_stats.r2,
        r.train_stats.max,
        r.validation_stats.r2,
        if unlabelled > 0 {
            format!(
                " (on {} labelled states; {unlabelled} unlabelled left out)",
                set.len()
            )
        } else {
            String::new()
        }
    ))
}

// ---- certify: Theorem 1 for both nets --------------------------------------------------

fn certify_inputs(cx: &Ctx, _: &ProblemConfig) -> Result<Inputs, PipelineError> {
    hashes(
        cx,
        Stage::Certify,
        &[
            RunDir::DATASET,
            RunDir::VALIDATION,
            RunDir::MODEL_NOMINAL,
            RunDir::MODEL_REGULARIZED,
        ],
    )
}

fn certify_both(env: &Env, d: &RunDir) -> Result<String, PipelineError> {
    let data = load_dataset(Stage::Certify, &d.dataset())?;
    let val = load_dataset(Stage::Certify, &d.validation())?;
    let extra = Some(TrainSet::from_dataset(&val));
    // Theorem 1 with the deployed controller's f32 allowance (libm tanh, 2-norm) stored
    // beside ε, as `trainer certify` writes it. The two nets are certified side by side
    // (each certificate a pure function of its net and the data; their serial parts, e.g.
    // the covering radius's branch and bound, overlap), then written in order.
    let one = |file: &str| {
        let m = load_model(Stage::Certify, &d.join(file))?;
        crate::deploy::export::certify_deployed(
            &env.cfg.name,
            &m,
            &data,
            env.cfg,
            &CertifyOptions {
                extra: extra.clone(),
                ..Default::default()
            },
        )
        .map(|(c, _)| c)
        .map_err(|e| {
            fail_in(
                Stage::Certify,
                format_args!("{file} on {}", RunDir::DATASET),
                e,
            )
        })
    };
    let (reg, nom) = rayon::join(
        || one(RunDir::MODEL_REGULARIZED),
        || one(RunDir::MODEL_NOMINAL),
    );
    let mut out = String::new();
    for (file, json, c) in [
        (RunDir::MODEL_REGULARIZED, RunDir::CERTIFICATE, reg),
        (RunDir::MODEL_NOMINAL, RunDir::CERTIFICATE_NOMINAL, nom),
    ] {
        let c = c?;
        crate::certify::file::write_certificate(
            &d.join(json),
            &CertificateFile::theorem1(c.clone()),
        )
        .map_err(|e| fail(Stage::Certify, e))?;
        out += &format!(
            "{file}: ε {:.3} (ε_D {:.3}, L_NN {:.1}, r {:.4}); ",
            c.eps, c.eps_d, c.l_nn, c.covering_radius
        );
    }
    Ok(out)
}

// ---- export: the net with the strongest guarantee for controller-core ------------------

fn export_inputs(cx: &Ctx, _: &ProblemConfig) -> Result<Inputs, PipelineError> {
    hashes(
        cx,
        Stage::Export,
        &[
            RunDir::MODEL_REGULARIZED,
            RunDir::CERTIFICATE,
            RunDir::MODEL_NOMINAL,
            RunDir::CERTIFICATE_NOMINAL,
            super::tiers::REFINE_JSON,
            super::tiers::STATISTICAL_JSON,
        ],
    )
}

// ---- refine and statistical: the tiers after Theorem 1 (`tiers`) -----------------------

fn refine_inputs(cx: &Ctx, cfg: &ProblemConfig) -> Result<Inputs, PipelineError> {
    let mut inputs = hashes(
        cx,
        Stage::Refine,
        &[
            RunDir::MODEL_REGULARIZED,
            RunDir::CERTIFICATE,
            RunDir::MODEL_NOMINAL,
            RunDir::CERTIFICATE_NOMINAL,
        ],
    )?;
    inputs.insert("problem".into(), cfg.problem_hash());
    inputs.insert("refine".into(), settings_hash(&cfg.refine));
    inputs.insert("enabled".into(), settings_hash(&cfg.refine.enabled));
    Ok(inputs)
}

fn statistical_inputs(cx: &Ctx, cfg: &ProblemConfig) -> Result<Inputs, PipelineError> {
    let mut inputs = hashes(
        cx,
        Stage::Statistical,
        &[
            RunDir::MODEL_REGULARIZED,
            RunDir::CERTIFICATE,
            RunDir::MODEL_NOMINAL,
            RunDir::CERTIFICATE_NOMINAL,
            super::tiers::REFINE_JSON,
        ],
    )?;
    inputs.insert("problem".into(), cfg.problem_hash());
    inputs.insert("certify".into(), settings_hash(&cfg.certify));
    Ok(inputs)
}

// ---- closed_loop: MPC and both nets in the loop ----------------------------------------

fn closed_loop_inputs(cx: &Ctx, cfg: &ProblemConfig) -> Result<Inputs, PipelineError> {
    let mut inputs = hashes(
        cx,
        Stage::ClosedLoop,
        &[
            RunDir::MODEL_NOMINAL,
            RunDir::MODEL_REGULARIZED,
            RunDir::CERTIFICATE,
            RunDir::CERTIFICATE_NOMINAL,
            RunDir::EXPORT_REPORT,
        ],
    )?;
    inputs.insert("problem".into(), cfg.problem_hash());
    inputs.insert("settings".into(), settings_hash(&cfg.closed_loop));
    inputs.insert("certify".into(), settings_hash(&cfg.certify));
    Ok(inputs)
}

fn closed_loop_study(env: &Env, d: &RunDir) -> Result<String, PipelineError> {
    let load = |f: &str, c: &str| -> Result<Model, PipelineError> {
        let mut m = load_model(Stage::ClosedLoop, &d.join(f))?;
        m.certificate = Some(read_run_certificate(Stage::ClosedLoop, (d, env.cfg), c, &m)?.base);
        Ok(m)
    };
    let (n, r) = (
        load(RunDir::MODEL_NOMINAL, RunDir::CERTIFICATE_NOMINAL)?,
        load(RunDir::MODEL_REGULARIZED, RunDir::CERTIFICATE)?,
    );
    // The closed-loop statistical runs beside the study: its many short runs fill the core
    // that the study's longest run leaves idle.
    let ((cl, safety), statistical) = rayon::join(
        || {
            let cl = closed_loop(env.cfg, &n, &r);
            (cl, super::safety::safety_study(env.cfg, &r))
        },
        || super::exported::closed_loop_statistical(env.cfg, d),
    );
    let safety = safety?;
    let file = ClosedLoopFile { safety, runs: cl };
    let text = serde_json::to_string(&file).map_err(|e| fail(Stage::ClosedLoop, e))?;
    write_atomic(&d.closed_loop(), text.as_bytes()).map_err(|e| fail(Stage::ClosedLoop, e))?;
    let (cl, safety) = (file.runs, file.safety);
    let first = |k: &str| cl.get(k).and_then(|v| v.first()).cloned();
    // Runs of a controller (its nominal, noise and mismatch runs) that stopped as diverged.
    let diverged = |k: &str| {
        let runs = cl
            .iter()
            .filter(|(name, _)| *name == k || name.starts_with(&format!("{k}_")))
            .flat_map(|(_, v)| v);
        let (n, d) = runs.fold((0, 0), |(n, d), r| {
            (n + 1, d + usize::from(!r.status.is_completed()))
        });
        (d, n)
    };
    let any_diverged = ["mpc", "nominal", "regularized"]
        .iter()
        .any(|k| diverged(k).0 > 0);
    let mut s = String::new();
    for k in ["mpc", "nominal", "regularized"] {
        if let Some(r) = first(k) {
            s += &format!(
                "{k}: {:.1} % violating, max {:.3}, divergence {:.3}",
                r.violation_percent, r.max_violation, r.max_input_divergence
            );
            if any_diverged {
                let (d, n) = diverged(k);
                s += &format!(", {d} of {n} runs diverged");
            }
            s += "; ";
        }
    }
    if let Some(st) = &safety {
        s += &super::safety::safety_summary(st);
    }
    s += &statistical?;
    Ok(s)
}

// ---- seeds: the nets from other seeds' initial weights, in the closed loop -------------

fn seeds_inputs(cx: &Ctx, cfg: &ProblemConfig) -> Result<Inputs, PipelineError> {
    let mut inputs = hashes(
        cx,
        Stage::Seeds,
        &[
            RunDir::DATASET,
            RunDir::VALIDATION,
            RunDir::MODEL_NOMINAL,
            RunDir::MODEL_REGULARIZED,
        ],
    )?;
    inputs.insert("problem".into(), cfg.problem_hash());
    inputs.insert("training".into(), settings_hash(&cfg.training));
    inputs.insert("settings".into(), settings_hash(&cfg.closed_loop));
    Ok(inputs)
}

fn seeds(env: &Env, d: &RunDir) -> Result<String, PipelineError> {
    // The study computed beside the stages since `train` (`beside`; the wait for it is
    // this stage's time), else here.
    let pre = env
        .seeds
        .borrow_mut()
        .take()
        .and_then(|(b, inputs)| b.take(&inputs));
    let (study, note) = match pre {
        Some((r, secs)) => (
            r?,
            format!(" (computed beside the stages before it: {secs:.2} s of its own)"),
        ),
        None => (
            super::beside::seed_study_of(env.cfg, d, env.progress)?,
            String::new(),
        ),
    };
    let text = serde_json::to_string(&study).map_err(|e| fail(Stage::Seeds, e))?;
    write_atomic(&d.seeds(), text.as_bytes()).map_err(|e| fail(Stage::Seeds, e))?;
    Ok(format!(
        "{} seeds × 2 nets from x₀ = {:?}{note}",
        study.len(),
        initial_states(env.cfg)[0]
    ))
}

// ---- plots: the figures, SVG and PNG ---------------------------------------------------

fn plot_files() -> Vec<String> {
    PLOTS
        .iter()
        .flat_map(|n| [format!("plots/{n}.svg"), format!("plots/{n}.png")])
        .chain(["plots/figures.json".to_string()])
        .collect()
}

fn plots_inputs(cx: &Ctx, cfg: &ProblemConfig) -> Result<Inputs, PipelineError> {
    let mut inputs = hashes(
        cx,
        Stage::Plots,
        &[
            RunDir::DATASET,
            RunDir::VALIDATION,
            RunDir::MODEL_NOMINAL,
            RunDir::MODEL_REGULARIZED,
            RunDir::CLOSED_LOOP,
        ],
    )?;
    inputs.insert("problem".into(), cfg.problem_hash());
    inputs.insert("settings".into(), settings_hash(&cfg.plots));
    Ok(inputs)
}

fn plots(env: &Env, d: &RunDir) -> Result<String, PipelineError> {
    let cfg = env.cfg;
    let figs = make_plots(cfg, d)?;
    let pdir = d.plots();
    std::fs::create_dir_all(&pdir).map_err(|e| fail_at(Stage::Plots, &pdir, e))?;
    let pngs: Vec<Result<Vec<u8>, crate::study::plots::PlotError>> = figs
        .par_iter()
        .map(|f| crate::study::plots::to_png(f.name, &f.svg, cfg.plots.png_scale as f32))
        .collect();
    let mut index = Vec::new();
    for (f, png) in figs.iter().zip(pngs) {
        let png = png.map_err(|e| fail(Stage::Plots, e))?;
        index.push(FigureEntry {
            name: f.name.to_string(),
            caption: f.caption.clone(),
            svg: format!("plots/{}.svg", f.name),
            png: format!("plots/{}.png", f.name),
        });
        write_atomic(&pdir.join(format!("{}.svg", f.name)), f.svg.as_bytes())
            .map_err(|e| fail(Stage::Plots, e))?;
        write_atomic(&pdir.join(format!("{}.png", f.name)), &png)
            .map_err(|e| fail(Stage::Plots, e))?;
    }
    let json = serde_json::to_string_pretty(&index).map_err(|e| fail(Stage::Plots, e))?;
    write_atomic(&pdir.join("figures.json"), json.as_bytes()).map_err(|e| fail(Stage::Plots, e))?;
    Ok(format!(
        "{} figures (SVG + PNG) in {}",
        figs.len(),
        pdir.display()
    ))
}

/// Renders the figures of the run in `dir` (labels the error-map grid with the MPC).
fn make_plots(
    cfg: &ProblemConfig,
    d: &RunDir,
) -> Result<Vec<crate::study::plots::Figure>, PipelineError> {
    let data = load_dataset(Stage::Plots, &d.dataset())?;
    let val = load_dataset(Stage::Plots, &d.validation())?;
    let nom = load_model(Stage::Plots, &d.model_nominal())?;
    let reg = load_model(Stage::Plots, &d.model_regularized())?;
    let cl: ClosedLoop = load_json::<ClosedLoopFile>(Stage::Plots, &d.closed_loop())?.runs;
    let (train, validation) = (TrainSet::from_dataset(&data), TrainSet::from_dataset(&val));
    let axes = crate::study::plots::slice_axes(cfg, &train);
    let grid = crate::study::plots::ErrorGrid::label(cfg, &reg.mlp, cfg.plots.error_map_grid, axes);
    let inputs = crate::study::plots::PlotInputs {
        cfg,
        train: &train,
        validation: &validation,
        nominal: &nom,
        regularized: &reg,
        closed_loop: &cl,
        grid: &grid,
    };
    let figs = crate::study::plots::all(&inputs).map_err(|e| fail(Stage::Plots, e))?;
    debug_assert_eq!(figs.len(), PLOTS.len());
    Ok(figs)
}

// ---- report: everything in one page, Markdown and HTML ---------------------------------

// Timings change from run to run: they are shown, not hashed (a skipped report keeps the
// timings of the run that wrote it).
fn report_inputs(cx: &Ctx, _: &ProblemConfig) -> Result<Inputs, PipelineError> {
    let mut inputs = hashes(
        cx,
        Stage::Report,
        &[
            RunDir::EXPORT_REPORT,
            RunDir::DATASET,
            RunDir::CERTIFICATE,
            RunDir::CERTIFICATE_NOMINAL,
            RunDir::CLOSED_LOOP,
            RunDir::MODEL_NOMINAL,
            RunDir::MODEL_REGULARIZED,
            RunDir::SEEDS,
        ],
    )?;
    for f in plot_files() {
        let h = cx.hash(Stage::Report, &f)?;
        inputs.insert(f, h);
    }
    Ok(inputs)
}

fn report(env: &Env, d: &RunDir) -> Result<String, PipelineError> {
    let rep = crate::study::report::build(env.cfg, d.path(), &env.timings)
        .map_err(|e| fail(Stage::Report, e))?;
    write_atomic(&d.report_md(), rep.to_markdown().as_bytes())
        .map_err(|e| fail(Stage::Report, e))?;
    let html = rep.to_html(d.path()).map_err(|e| fail(Stage::Report, e))?;
    write_atomic(&d.report_html(), html.as_bytes()).map_err(|e| fail(Stage::Report, e))?;
    Ok(format!("{} + report.html", d.report_md().display()))
}
