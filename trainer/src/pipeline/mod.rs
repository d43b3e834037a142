//! `trainer run`: one command from a problem file to a certified controller.
//!
//! Stages, each writing its artifacts under `DIR/<name>/` with a manifest
//! (`manifest_<stage>.json`: input hashes, settings, crate version, timing):
//! `sample` (dataset.bin/.csv) → `validate` (validation.bin: MPC labels of random states)
//! → `train` (model_nominal.bin, model_regularized.bin, same initial weights) → `certify`
//! (certificate.json, certificate_nominal.json) → `export` (weights.rs, weights.bin,
//! export_report.json: the regularized net for controller-core) → `closed_loop`
//! (closed_loop.json) → `seeds` (seeds.json: both nets retrained from other seeds' initial
//! weights and simulated from the reference initial state) → `plots` (plots/*.svg,
//! plots/*.png) → `report` (report.md, report.html). A stage whose manifest matches its current inputs and whose
//! outputs exist is skipped; `force` redoes named stages (and, through the changed hashes,
//! everything downstream). Dataset generation resumes from its checkpoint when killed.

use crate::certify::certificate::{certify, Certificate, CertifyOptions};
use crate::certify::Model;
use crate::data::dataset::{generate, Dataset, GenerateOptions};
use crate::io::hex;
use crate::io::write_atomic;
use crate::learn::train::{train, TrainOptions, TrainSet};
use crate::problem::{ProblemConfig, SamplerKind, SamplingSettings};
pub mod robust;

use crate::study::plots::{FigureEntry, PLOTS};
use crate::study::scenarios::{closed_loop, initial_states, ClosedLoop};
use crate::study::seeds::seed_study;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The stages in order.
pub const STAGES: [&str; 9] = [
    "sample",
    "validate",
    "train",
    "certify",
    "export",
    "closed_loop",
    "seeds",
    "plots",
    "report",
];

/// A failure, naming the stage and the cause.
#[derive(Debug, thiserror::Error)]
#[error("stage `{stage}` failed: {cause}")]
pub struct PipelineError {
    /// The stage.
    pub stage: String,
    /// What went wrong (names the file or setting).
    pub cause: String,
}

fn fail(stage: &str, e: impl std::fmt::Display) -> PipelineError {
    PipelineError {
        stage: stage.to_string(),
        cause: e.to_string(),
    }
}

/// A stage's manifest.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// Stage name.
    pub stage: String,
    /// trainer version.
    pub version: String,
    /// Input name → SHA-256 (files) or settings hash.
    pub inputs: BTreeMap<String, String>,
    /// Output files (relative to the run directory).
    pub outputs: Vec<String>,
    /// Wall time in seconds.
    pub seconds: f64,
}

/// What happened to a stage.
#[derive(Debug, Clone)]
pub struct StageReport {
    /// Stage name.
    pub stage: String,
    /// Skipped because its inputs were unchanged.
    pub skipped: bool,
    /// Wall time (of this run, or of the run that produced the artifacts when skipped).
    pub seconds: f64,
    /// One-line summary.
    pub summary: String,
    /// Input name → hash, as in the manifest.
    pub inputs: BTreeMap<String, String>,
    /// Output files (relative to the run directory).
    pub outputs: Vec<String>,
}

/// Options of a pipeline run.
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// Run directory root (the run goes to `root/<name>/`).
    pub root: PathBuf,
    /// Stages to redo even if unchanged.
    pub force: Vec<String>,
    /// Progress bars on a terminal.
    pub progress: bool,
    /// Called after each stage (for one summary line per stage).
    pub on_stage: Option<fn(&StageReport)>,
    /// Stop after this stage (default: run all).
    pub until: Option<String>,
}

fn sha_file(p: &Path) -> Result<String, std::io::Error> {
    Ok(hex(&Sha256::digest(std::fs::read(p)?)))
}

fn sha_str(s: &str) -> String {
    hex(&Sha256::digest(s.as_bytes()))
}

struct Ctx<'a> {
    dir: PathBuf,
    opts: &'a RunOptions,
    reports: Vec<StageReport>,
}

impl Ctx<'_> {
    /// Runs `body` unless the manifest says its inputs are unchanged.
    fn stage(
        &mut self,
        name: &str,
        inputs: BTreeMap<String, String>,
        outputs: &[&str],
        body: impl FnOnce(&Path) -> Result<String, PipelineError>,
    ) -> Result<(), PipelineError> {
        let mpath = self.dir.join(format!("manifest_{name}.json"));
        let forced = self.opts.force.iter().any(|f| f == name);
        if !forced {
            if let Ok(text) = std::fs::read_to_string(&mpath) {
                if let Ok(m) = serde_json::from_str::<Manifest>(&text) {
                    if m.inputs == inputs
                        && m.version == env!("CARGO_PKG_VERSION")
                        && outputs.iter().all(|o| self.dir.join(o).exists())
                    {
                        let r = StageReport {
                            stage: name.into(),
                            skipped: true,
                            seconds: m.seconds,
                            summary: "unchanged inputs, skipped".into(),
                            inputs: m.inputs,
                            outputs: m.outputs,
                        };
                        if let Some(f) = self.opts.on_stage {
                            f(&r);
                        }
                        self.reports.push(r);
                        return Ok(());
                    }
                }
            }
        }
        let t = Instant::now();
        // Labelling and seed stages draw their own progress bar; the others show a spinner.
        let spinner = if self.opts.progress && !["sample", "validate", "seeds"].contains(&name) {
            let b = indicatif::ProgressBar::new_spinner();
            b.set_style(
                indicatif::ProgressStyle::with_template("{spinner} [{prefix:>11}] {elapsed}")
                    .unwrap_or_else(|_| indicatif::ProgressStyle::default_spinner()),
            );
            b.set_prefix(name.to_string());
            b.enable_steady_tick(std::time::Duration::from_millis(100));
            Some(b)
        } else {
            None
        };
        let summary = body(&self.dir);
        if let Some(b) = spinner {
            b.finish_and_clear();
        }
        let summary = summary?;
        let seconds = t.elapsed().as_secs_f64();
        let m = Manifest {
            stage: name.into(),
            version: env!("CARGO_PKG_VERSION").into(),
            inputs: inputs.clone(),
            outputs: outputs.iter().map(|s| s.to_string()).collect(),
            seconds,
        };
        let json = serde_json::to_string_pretty(&m).map_err(|e| fail(name, e))?;
        write_atomic(&mpath, json.as_bytes()).map_err(|e| fail(name, e))?;
        let r = StageReport {
            stage: name.into(),
            skipped: false,
            seconds,
            summary,
            inputs,
            outputs: m.outputs,
        };
        if let Some(f) = self.opts.on_stage {
            f(&r);
        }
        self.reports.push(r);
        Ok(())
    }

    fn hash(&self, stage: &str, file: &str) -> Result<String, PipelineError> {
        let p = self.dir.join(file);
        sha_file(&p).map_err(|e| fail(stage, format!("{}: {e}", p.display())))
    }
}

/// Runs the pipeline for `cfg`; `config_text` is the problem file's text (hashed).
pub fn run(
    cfg: &ProblemConfig,
    config_text: &str,
    opts: &RunOptions,
) -> Result<Vec<StageReport>, PipelineError> {
    let dir = opts.root.join(&cfg.name);
    std::fs::create_dir_all(&dir).map_err(|e| fail("setup", format!("{}: {e}", dir.display())))?;
    write_atomic(&dir.join("problem.toml"), config_text.as_bytes())
        .map_err(|e| fail("setup", e))?;
    let mut cx = Ctx {
        dir,
        opts,
        reports: Vec::new(),
    };
    let settings = |v: &dyn erased::Ser| sha_str(&v.json());
    // sample
    let mut inputs = BTreeMap::new();
    inputs.insert("problem".into(), cfg.problem_hash());
    inputs.insert("sampling".into(), settings(&cfg.sampling));
    cx.stage("sample", inputs, &["dataset.bin", "dataset.csv"], |d| {
        let g = GenerateOptions {
            shard: None,
            progress: opts.progress,
        };
        let ds = generate(cfg, &d.join("dataset.bin"), &g).map_err(|e| fail("sample", e))?;
        let c = ds.counts();
        Ok(format!(
            "{} states: {} converged, {} soft, {} infeasible, {} failed, {} degenerate",
            c.total, c.converged, c.soft, c.infeasible, c.failed, c.degenerate
        ))
    })?;
    if opts.until.as_deref() == Some("sample") {
        return Ok(cx.reports);
    }
    // validate
    let mut vcfg = cfg.clone();
    vcfg.sampling = SamplingSettings {
        sampler: SamplerKind::Random,
        n: cfg.training.validation_n.max(1),
        seed: cfg.training.validation_seed,
        counts: vec![],
    };
    let mut inputs = BTreeMap::new();
    inputs.insert("problem".into(), cfg.problem_hash());
    inputs.insert("sampling".into(), settings(&vcfg.sampling));
    cx.stage("validate", inputs, &["validation.bin"], |d| {
        let g = GenerateOptions {
            shard: None,
            progress: opts.progress,
        };
        let ds = generate(&vcfg, &d.join("validation.bin"), &g).map_err(|e| fail("validate", e))?;
        Ok(format!(
            "{} random validation states labelled",
            ds.records.len()
        ))
    })?;
    if opts.until.as_deref() == Some("validate") {
        return Ok(cx.reports);
    }
    // train
    let mut inputs = BTreeMap::new();
    inputs.insert("dataset".into(), cx.hash("train", "dataset.bin")?);
    inputs.insert("validation".into(), cx.hash("train", "validation.bin")?);
    inputs.insert("training".into(), settings(&cfg.training));
    cx.stage(
        "train",
        inputs,
        &["model_nominal.bin", "model_regularized.bin"],
        |d| {
            let data = Dataset::load(&d.join("dataset.bin")).map_err(|e| fail("train", e))?;
            let val = Dataset::load(&d.join("validation.bin")).map_err(|e| fail("train", e))?;
            let dh = sha_file(&d.join("dataset.bin")).map_err(|e| fail("train", e))?;
            let (set, vset) = (TrainSet::from_dataset(&data), TrainSet::from_dataset(&val));
            if set.is_empty() {
                return Err(fail("train", "the dataset has no labelled points"));
            }
            let one = |nominal: bool| {
                train::<crate::certify::certificate::Certificate>(
                    &cfg.training,
                    &TrainOptions {
                        nominal,
                        progress: None,
                    },
                    &set,
                    &vset,
                    (&cfg.domain.lo, &cfg.domain.hi),
                    (&cfg.ocp.u_lo, &cfg.ocp.u_hi),
                    &data.header.problem_hash,
                    &dh,
                )
            };
            let (n, r) = rayon::join(|| one(true), || one(false));
            n.save(&d.join("model_nominal.bin"))
                .map_err(|e| fail("train", e))?;
            r.save(&d.join("model_regularized.bin"))
                .map_err(|e| fail("train", e))?;
            Ok(format!(
                "nominal ε_D {:.3}, R² {:.4}; regularized ε_D {:.3}, R² {:.4}",
                n.train_stats.max, n.validation_stats.r2, r.train_stats.max, r.validation_stats.r2
            ))
        },
    )?;
    if opts.until.as_deref() == Some("train") {
        return Ok(cx.reports);
    }
    // certify
    let mut inputs = BTreeMap::new();
    for f in [
        "dataset.bin",
        "validation.bin",
        "model_nominal.bin",
        "model_regularized.bin",
    ] {
        inputs.insert(f.into(), cx.hash("certify", f)?);
    }
    cx.stage(
        "certify",
        inputs,
        &["certificate.json", "certificate_nominal.json"],
        |d| {
            let data = Dataset::load(&d.join("dataset.bin")).map_err(|e| fail("certify", e))?;
            let val = Dataset::load(&d.join("validation.bin")).map_err(|e| fail("certify", e))?;
            let extra = Some(TrainSet::from_dataset(&val));
            let mut out = String::new();
            for (file, json) in [
                ("model_regularized.bin", "certificate.json"),
                ("model_nominal.bin", "certificate_nominal.json"),
            ] {
                let m = Model::load(&d.join(file)).map_err(|e| fail("certify", e))?;
                let c = certify(
                    &m,
                    &data,
                    cfg,
                    &CertifyOptions {
                        extra: extra.clone(),
                        ..Default::default()
                    },
                );
                let text = serde_json::to_string_pretty(&c).map_err(|e| fail("certify", e))?;
                write_atomic(&d.join(json), text.as_bytes()).map_err(|e| fail("certify", e))?;
                out += &format!(
                    "{file}: ε {:.3} (ε_D {:.3}, L_NN {:.1}, r {:.4}); ",
                    c.eps, c.eps_d, c.l_nn, c.covering_radius
                );
            }
            Ok(out)
        },
    )?;
    if opts.until.as_deref() == Some("certify") {
        return Ok(cx.reports);
    }
    // export (the regularized net, for controller-core)
    let mut inputs = BTreeMap::new();
    for f in ["model_regularized.bin", "certificate.json"] {
        inputs.insert(f.into(), cx.hash("export", f)?);
    }
    cx.stage(
        "export",
        inputs,
        &["weights.rs", "weights.bin", "export_report.json"],
        |d| {
            let m = Model::load(&d.join("model_regularized.bin")).map_err(|e| fail("export", e))?;
            let p = d.join("certificate.json");
            let text = std::fs::read_to_string(&p)
                .map_err(|e| fail("export", format!("{}: {e}", p.display())))?;
            let c: Certificate = serde_json::from_str(&text)
                .map_err(|e| fail("export", format!("{}: {e}", p.display())))?;
            let em = crate::deploy::export::ExportModel::from_trained(&cfg.name, &m, &c)
                .map_err(|e| fail("export", e))?;
            let r = crate::deploy::export::export_files(
                &em,
                &d.join("weights.rs"),
                &d.join("weights.bin"),
            )
            .map_err(|e| fail("export", e))?;
            let json = serde_json::json!({
                "f32_allowance_libm": r.f32_allowance[0],
                "f32_allowance_fast_tanh": r.f32_allowance[1],
                "f32_observed_libm": r.f32_observed[0],
                "f32_observed_fast_tanh": r.f32_observed[1],
                "samples": r.samples,
                "eps_f64": c.eps,
                "eps_device_libm": c.eps + r.f32_allowance[0],
            });
            write_atomic(&d.join("export_report.json"), json.to_string().as_bytes())
                .map_err(|e| fail("export", e))?;
            Ok(format!(
                "weights.rs + weights.bin; f32 allowance {:.3e} (observed {:.3e} on {} states)",
                r.f32_allowance[0], r.f32_observed[0], r.samples
            ))
        },
    )?;
    if opts.until.as_deref() == Some("export") {
        return Ok(cx.reports);
    }
    // closed loop
    let mut inputs = BTreeMap::new();
    for f in [
        "model_nominal.bin",
        "model_regularized.bin",
        "certificate.json",
        "certificate_nominal.json",
    ] {
        inputs.insert(f.into(), cx.hash("closed_loop", f)?);
    }
    inputs.insert("problem".into(), cfg.problem_hash());
    inputs.insert("settings".into(), settings(&cfg.closed_loop));
    cx.stage("closed_loop", inputs, &["closed_loop.json"], |d| {
        let load = |f: &str, c: &str| -> Result<Model, PipelineError> {
            let mut m = Model::load(&d.join(f)).map_err(|e| fail("closed_loop", e))?;
            let p = d.join(c);
            let text = std::fs::read_to_string(&p)
                .map_err(|e| fail("closed_loop", format!("{}: {e}", p.display())))?;
            m.certificate = Some(
                serde_json::from_str(&text)
                    .map_err(|e| fail("closed_loop", format!("{}: {e}", p.display())))?,
            );
            Ok(m)
        };
        let (n, r) = (
            load("model_nominal.bin", "certificate_nominal.json")?,
            load("model_regularized.bin", "certificate.json")?,
        );
        let cl = closed_loop(cfg, &n, &r);
        let text = serde_json::to_string(&cl).map_err(|e| fail("closed_loop", e))?;
        write_atomic(&d.join("closed_loop.json"), text.as_bytes())
            .map_err(|e| fail("closed_loop", e))?;
        let first = |k: &str| cl.get(k).and_then(|v| v.first()).cloned();
        let mut s = String::new();
        for k in ["mpc", "nominal", "regularized"] {
            if let Some(r) = first(k) {
                s += &format!(
                    "{k}: {:.1} % violating, max {:.3}, divergence {:.3}; ",
                    r.violation_percent, r.max_violation, r.max_input_divergence
                );
            }
        }
        Ok(s)
    })?;
    if opts.until.as_deref() == Some("closed_loop") {
        return Ok(cx.reports);
    }
    // seeds: the nets from other seeds' initial weights, in the closed loop
    let mut inputs = BTreeMap::new();
    for f in [
        "dataset.bin",
        "validation.bin",
        "model_nominal.bin",
        "model_regularized.bin",
    ] {
        inputs.insert(f.into(), cx.hash("seeds", f)?);
    }
    inputs.insert("problem".into(), cfg.problem_hash());
    inputs.insert("training".into(), settings(&cfg.training));
    inputs.insert("settings".into(), settings(&cfg.closed_loop));
    cx.stage("seeds", inputs, &["seeds.json"], |d| {
        let data = Dataset::load(&d.join("dataset.bin")).map_err(|e| fail("seeds", e))?;
        let val = Dataset::load(&d.join("validation.bin")).map_err(|e| fail("seeds", e))?;
        let own = [
            Model::load(&d.join("model_nominal.bin")).map_err(|e| fail("seeds", e))?,
            Model::load(&d.join("model_regularized.bin")).map_err(|e| fail("seeds", e))?,
        ];
        let dh = sha_file(&d.join("dataset.bin")).map_err(|e| fail("seeds", e))?;
        let study = seed_study(cfg, &data, &val, &dh, &own, opts.progress);
        let text = serde_json::to_string(&study).map_err(|e| fail("seeds", e))?;
        write_atomic(&d.join("seeds.json"), text.as_bytes()).map_err(|e| fail("seeds", e))?;
        Ok(format!(
            "{} seeds × 2 nets from x₀ = {:?}",
            study.len(),
            initial_states(cfg)[0]
        ))
    })?;
    if opts.until.as_deref() == Some("seeds") {
        return Ok(cx.reports);
    }
    // plots
    let mut inputs = BTreeMap::new();
    for f in [
        "dataset.bin",
        "validation.bin",
        "model_nominal.bin",
        "model_regularized.bin",
        "closed_loop.json",
    ] {
        inputs.insert(f.into(), cx.hash("plots", f)?);
    }
    inputs.insert("problem".into(), cfg.problem_hash());
    inputs.insert("settings".into(), settings(&cfg.plots));
    let plot_files: Vec<String> = PLOTS
        .iter()
        .flat_map(|n| [format!("plots/{n}.svg"), format!("plots/{n}.png")])
        .collect();
    let plot_refs: Vec<&str> = plot_files
        .iter()
        .map(String::as_str)
        .chain(["plots/figures.json"])
        .collect();
    cx.stage("plots", inputs, &plot_refs, |d| {
        let figs = make_plots(cfg, d)?;
        let pdir = d.join("plots");
        std::fs::create_dir_all(&pdir)
            .map_err(|e| fail("plots", format!("{}: {e}", pdir.display())))?;
        let pngs: Vec<Result<Vec<u8>, crate::study::plots::PlotError>> = figs
            .par_iter()
            .map(|f| crate::study::plots::to_png(f.name, &f.svg, cfg.plots.png_scale as f32))
            .collect();
        let mut index = Vec::new();
        for (f, png) in figs.iter().zip(pngs) {
            let png = png.map_err(|e| fail("plots", e))?;
            index.push(FigureEntry {
                name: f.name.to_string(),
                caption: f.caption.clone(),
                svg: format!("plots/{}.svg", f.name),
                png: format!("plots/{}.png", f.name),
            });
            write_atomic(&pdir.join(format!("{}.svg", f.name)), f.svg.as_bytes())
                .map_err(|e| fail("plots", e))?;
            write_atomic(&pdir.join(format!("{}.png", f.name)), &png)
                .map_err(|e| fail("plots", e))?;
        }
        let json = serde_json::to_string_pretty(&index).map_err(|e| fail("plots", e))?;
        write_atomic(&pdir.join("figures.json"), json.as_bytes()).map_err(|e| fail("plots", e))?;
        Ok(format!(
            "{} figures (SVG + PNG) in {}",
            figs.len(),
            pdir.display()
        ))
    })?;
    if opts.until.as_deref() == Some("plots") {
        return Ok(cx.reports);
    }
    // report
    let mut inputs = BTreeMap::new();
    for f in [
        "export_report.json",
        "dataset.bin",
        "certificate.json",
        "certificate_nominal.json",
        "closed_loop.json",
        "model_nominal.bin",
        "model_regularized.bin",
        "seeds.json",
    ] {
        inputs.insert(f.into(), cx.hash("report", f)?);
    }
    for f in plot_refs {
        inputs.insert(f.into(), cx.hash("report", f)?);
    }
    let timings: Vec<crate::study::report::Timing> = cx
        .reports
        .iter()
        .map(|r| crate::study::report::Timing {
            stage: r.stage.clone(),
            seconds: r.seconds,
            skipped: r.skipped,
        })
        .collect();
    // Timings change from run to run: they are shown, not hashed (a skipped report keeps the
    // timings of the run that wrote it).
    cx.stage("report", inputs, &["report.md", "report.html"], |d| {
        let rep = crate::study::report::build(cfg, d, &timings).map_err(|e| fail("report", e))?;
        write_atomic(&d.join("report.md"), rep.to_markdown().as_bytes())
            .map_err(|e| fail("report", e))?;
        let html = rep.to_html(d).map_err(|e| fail("report", e))?;
        write_atomic(&d.join("report.html"), html.as_bytes()).map_err(|e| fail("report", e))?;
        Ok(format!("{} + report.html", d.join("report.md").display()))
    })?;
    Ok(cx.reports)
}

/// Renders the figures of the run in `dir` (labels the error-map grid with the MPC).
fn make_plots(
    cfg: &ProblemConfig,
    d: &Path,
) -> Result<Vec<crate::study::plots::Figure>, PipelineError> {
    let data = Dataset::load(&d.join("dataset.bin")).map_err(|e| fail("plots", e))?;
    let val = Dataset::load(&d.join("validation.bin")).map_err(|e| fail("plots", e))?;
    let nom = Model::load(&d.join("model_nominal.bin")).map_err(|e| fail("plots", e))?;
    let reg = Model::load(&d.join("model_regularized.bin")).map_err(|e| fail("plots", e))?;
    let p = d.join("closed_loop.json");
    let text =
        std::fs::read_to_string(&p).map_err(|e| fail("plots", format!("{}: {e}", p.display())))?;
    let cl: ClosedLoop =
        serde_json::from_str(&text).map_err(|e| fail("plots", format!("{}: {e}", p.display())))?;
    let grid = crate::study::plots::ErrorGrid::label(cfg, &reg.mlp, cfg.plots.error_map_grid);
    let (train, validation) = (TrainSet::from_dataset(&data), TrainSet::from_dataset(&val));
    let inputs = crate::study::plots::PlotInputs {
        cfg,
        train: &train,
        validation: &validation,
        nominal: &nom,
        regularized: &reg,
        closed_loop: &cl,
        grid: &grid,
    };
    let figs = crate::study::plots::all(&inputs).map_err(|e| fail("plots", e))?;
    debug_assert_eq!(figs.len(), PLOTS.len());
    Ok(figs)
}

mod erased {
    /// Serialises settings for hashing.
    pub trait Ser {
        fn json(&self) -> String;
    }
    impl<T: serde::Serialize> Ser for T {
        fn json(&self) -> String {
            serde_json::to_string(self).unwrap_or_default()
        }
    }
}
