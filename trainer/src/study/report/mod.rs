//! The run report: one structured document ([`Report`]) built from a run directory's
//! artifacts, rendered as Markdown (`report.md`) and as a self-contained HTML page
//! (`report.html`, the figures inlined as SVG).
//!
//! Content: the problem, the dataset's counts (failures, soft labels, degenerate points),
//! Table I and Table II for both nets beside the paper's figures, every term of the
//! certificate and which ones are estimates, the closed-loop distributions (initial states,
//! robustness runs, training seeds as median [min, max]), the figures, the per-stage
//! timings and the command that reproduces the run. Every number is read from the run's
//! files; the only constants are the paper's published figures.
//!
//! This file owns the document ([`Report`], [`Block`]), its inputs (the run's artifacts,
//! [`Timing`]) and [`build`], the list of sections; `sections.rs` builds each section's
//! blocks, `verdict.rs` the opening verdict, `format.rs` formats numbers and boxes,
//! `render.rs` turns the document into Markdown and HTML.

mod format;
mod render;
mod sections;

pub use render::{esc, inline};

use crate::certify::certificate::Certificate;
use crate::certify::file::CertificateFile;
use crate::certify::Model;
use crate::data::dataset::Dataset;
use crate::io::RunDir;
use crate::problem::ProblemConfig;
use crate::study::scenarios::{ClosedLoop, ClosedLoopFile};
use crate::study::seeds::SeedRun;
use std::path::Path;

/// A report that cannot be built (names the file at fault); the cause is kept as the
/// error's source.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// A file of the run that does not read or parse.
    #[error("{path}: {source}")]
    File {
        /// The file.
        path: String,
        /// What went wrong.
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// The run's dataset or a net does not read.
    #[error(transparent)]
    Dataset(#[from] crate::data::dataset::DatasetError),
    /// A certificate of the run does not read or re-check.
    #[error(transparent)]
    Certificate(#[from] crate::certify::file::CertFileError),
    /// `plots/figures.json` lacks a figure the report shows.
    #[error("{index} lists no figure `{figure}`")]
    MissingFigure {
        /// The figure index (`plots/figures.json`).
        index: String,
        /// The figure's name.
        figure: String,
    },
}

impl ReportError {
    /// The file `p` failed with `e`.
    fn file(p: &Path, e: impl Into<Box<dyn std::error::Error + Send + Sync>>) -> Self {
        ReportError::File {
            path: p.display().to_string(),
            source: e.into(),
        }
    }
}

/// The paper's Table I (R², ε_D, L_NN) for the nominal and the regularized net.
pub const PAPER_TABLE_I: [(&str, [f64; 3]); 2] = [
    ("nominal", [0.985, 3.231, 384.01]),
    ("regularized", [0.992, 1.823, 207.66]),
];
/// The paper's Table II (violating steps %, max violation, max input divergence).
pub const PAPER_TABLE_II: [(&str, [f64; 3]); 2] = [
    ("nominal", [46.534, 1.113, 2.975]),
    ("regularized", [39.604, 1.032, 0.649]),
];

/// Median, minimum and maximum (NaN entries ignored).
pub fn med_min_max(v: &[f64]) -> (f64, f64, f64) {
    let mut s: Vec<f64> = v.iter().copied().filter(|x| !x.is_nan()).collect();
    if s.is_empty() {
        return (f64::NAN, f64::NAN, f64::NAN);
    }
    s.sort_by(f64::total_cmp);
    let n = s.len();
    let med = if n % 2 == 1 {
        s[n / 2]
    } else {
        0.5 * (s[n / 2 - 1] + s[n / 2])
    };
    (med, s[0], s[n - 1])
}

/// Timing of one stage, for the report.
#[derive(Debug, Clone, PartialEq)]
pub struct Timing {
    /// Stage name.
    pub stage: String,
    /// Wall time in seconds (of the run that produced the artifacts when skipped).
    pub seconds: f64,
    /// Skipped in this run.
    pub skipped: bool,
}

/// A block of the report.
#[derive(Debug, Clone, PartialEq)]
pub enum Block {
    /// A section heading (level 2 or 3).
    Heading(u8, String),
    /// A paragraph; `**bold**` and `` `code` `` are the only inline markup.
    Para(String),
    /// A table.
    Table {
        /// Column headers.
        head: Vec<String>,
        /// Rows of cells (inline markup as in paragraphs).
        rows: Vec<Vec<String>>,
    },
    /// A shell command block.
    Code(String),
    /// A figure `plots/<stem>.svg|png` with its caption.
    Figure {
        /// File stem.
        stem: String,
        /// Caption.
        caption: String,
    },
}

/// The report: a title and blocks.
#[derive(Debug, Clone, PartialEq)]
pub struct Report {
    /// Title.
    pub title: String,
    /// Content in order.
    pub blocks: Vec<Block>,
}

/// The run's artifacts the sections read (all but the figure index, which the figures
/// section reads itself).
struct Artifacts {
    /// `dataset.bin`.
    data: Dataset,
    /// `model_nominal.bin`.
    nom: Model,
    /// `model_regularized.bin`.
    reg: Model,
    /// `certificate.json` (the regularized net's).
    cert: Certificate,
    /// Its tier, as the certificate states it (`guarantee`, `tiers`, `assumptions`).
    tier: crate::certify::tier::Guarantee,
    /// `certificate_nominal.json`.
    cert_n: Certificate,
    /// Its tier.
    tier_n: crate::certify::tier::Guarantee,
    /// `closed_loop.json`'s runs.
    cl: ClosedLoop,
    /// `closed_loop.json`'s safety study, if it ran.
    safety: Option<crate::study::safety::SafetyStudy>,
    /// `seeds.json`: per training seed, the nominal and the regularized net.
    seeds: Vec<[SeedRun; 2]>,
    /// `export_report.json`.
    export: serde_json::Value,
    /// `closed_loop_statistical.json` (absent in runs before it existed).
    cl_stat: Option<serde_json::Value>,
}

impl Artifacts {
    /// The exported net's name (`export_report.json`'s `net`; runs before the choice
    /// existed exported the regularized net), its certificate and tier.
    fn exported(&self) -> (&str, &Certificate, &crate::certify::tier::Guarantee) {
        match self.export["net"].as_str() {
            Some("nominal") => ("nominal", &self.cert_n, &self.tier_n),
            _ => ("regularized", &self.cert, &self.tier),
        }
    }

    /// Reads the artifacts of the run in `dir`; the first missing or unreadable file is the
    /// error.
    fn load(dir: &Path) -> Result<Self, ReportError> {
        let dir = RunDir::new(dir);
        let dpath = dir.dataset();
        let data_bytes = std::fs::read(&dpath).map_err(|e| ReportError::file(&dpath, e))?;
        let data = Dataset::from_bytes(&data_bytes, &dpath.display().to_string())?;
        let data_hash = crate::io::sha256_hex(&data_bytes);
        let nom = Model::load(&dir.model_nominal())?;
        let reg = Model::load(&dir.model_regularized())?;
        let cert = certificate(&dir.certificate(), &reg, &data_hash)?;
        let cert_n = certificate(&dir.certificate_nominal(), &nom, &data_hash)?;
        let clf: ClosedLoopFile = load(&dir.closed_loop())?;
        Ok(Artifacts {
            data,
            nom,
            reg,
            tier: cert.guarantee,
            cert: cert.base,
            tier_n: cert_n.guarantee,
            cert_n: cert_n.base,
            cl: clf.runs,
            safety: clf.safety,
            seeds: load(&dir.seeds())?,
            export: load(&dir.export_report())?,
            cl_stat: load(&dir.join("closed_loop_statistical.json")).ok(),
        })
    }
}

/// Reads a certificate of the run through `certify::file` (sealed, re-checked against the
/// net `m` and the dataset's hash).
fn certificate(p: &Path, m: &Model, data_hash: &str) -> Result<CertificateFile, ReportError> {
    let model_hash = m.content_hash();
    let against = crate::certify::file::Against {
        model_hash: Some(&model_hash),
        dataset_hash: Some(data_hash),
        ..Default::default()
    };
    Ok(crate::certify::file::read_certificate(p, false, &against).map(|(f, _)| f)?)
}

/// Reads a JSON file.
fn load<T: serde::de::DeserializeOwned>(p: &Path) -> Result<T, ReportError> {
    let t = std::fs::read_to_string(p).map_err(|e| ReportError::file(p, e))?;
    serde_json::from_str(&t).map_err(|e| ReportError::file(p, e))
}

/// Builds the report of the run in `dir` from its artifacts.
pub fn build(cfg: &ProblemConfig, dir: &Path, timings: &[Timing]) -> Result<Report, ReportError> {
    let a = Artifacts::load(dir)?;
    let blocks = [
        verdict::verdict(cfg, &a),
        sections::problem(cfg),
        sections::dataset(cfg, &a),
        sections::table_i(cfg, &a),
        sections::training_seeds(cfg, &a),
        sections::certificate(&a),
        sections::table_ii(cfg, &a),
        safety_section::safety(&a),
        sections::closed_loop_seeds(&a),
        sections::all_runs(cfg, &a),
        sections::figures(dir)?,
        sections::timings(timings),
        sections::reproduce(dir),
    ]
    .concat();
    Ok(Report {
        title: format!("ampc run: {}", cfg.name),
        blocks,
    })
}

mod safety_section;
mod verdict;
pub use verdict::judge;

#[cfg(test)]
mod tests;
