//! `trainer import`: a labelled dataset D̂ = {(x_i, u_i, ∂u/∂x_i)} from another solver's CSV,
//! stored as an ampc dataset with its provenance, and the re-solve check of its labels.
//!
//! - [`csv`]: the column rule and the row checks (dimensions, domain X, finite values,
//!   labels inside the input bounds U).
//! - The dataset: one record per row (index = row number), header sampler `imported` (so
//!   the certificate's covering radius is the scattered-point bound, never a grid formula),
//!   and [`ImportedLabels`] — file name, SHA-256 of its bytes, and the re-solve check.
//! - **Re-solve check.** A seeded sample of `resolve` labelled rows (all if fewer) is solved
//!   again by ampc's SQP (cold start) and compared input by input:
//!   ```text
//!   disagreement_i = max_j |u_ij − κ_j(x_i)|,   tolerance_ij = RESOLVE_RTOL·max(1, |κ_j(x_i)|)
//!   ```
//!   A row beyond its tolerance, or one that ampc cannot label while the file says it is
//!   labelled, is an error naming the line and the state unless `trust_labels` is set; the
//!   largest disagreement is recorded either way.

pub mod csv;

pub use crate::data::dataset::ImportedLabels;
use crate::data::dataset::{Dataset, DatasetError, Header, CHUNK, IMPORTED_FORMAT_VERSION, MAGIC};
use crate::mpc::law::MpcLaw;
use crate::problem::{ProblemConfig, SamplerKind, SamplingSettings};
use rayon::prelude::*;
use std::path::Path;

/// Relative tolerance of the re-solve check: a label agrees when
/// `|u − κ(x)| ≤ RESOLVE_RTOL·max(1, |κ(x)|)` for every input (100× the SQP's default KKT
/// tolerance 1e-8; labels of two converged solvers of the same OCP agree far closer).
pub const RESOLVE_RTOL: f64 = 1e-6;

/// Default number of rows re-solved (`--resolve`).
pub const DEFAULT_RESOLVE: usize = 200;

/// Options of an import.
#[derive(Debug, Clone)]
pub struct ImportOptions {
    /// Rows to re-solve (0: none).
    pub resolve: usize,
    /// Seed of the sample.
    pub seed: u64,
    /// Accept labels beyond the tolerance (recorded, not an error).
    pub trust_labels: bool,
}

impl Default for ImportOptions {
    fn default() -> Self {
        ImportOptions {
            resolve: DEFAULT_RESOLVE,
            seed: 0,
            trust_labels: false,
        }
    }
}

/// Errors of an import; each names the file (and line, column or state).
#[derive(Debug, thiserror::Error)]
pub enum ImportError {
    /// Reading the CSV failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A malformed or out-of-domain row or header.
    #[error(transparent)]
    Csv(#[from] csv::CsvError),
    /// A label disagrees with ampc's re-solve beyond the tolerance.
    #[error("{file}:{line}: label u{input} = {label} at state x = {x:?} disagrees with ampc's re-solve {ampc} by {diff:.3e} (tolerance {tol:.1e} = {RESOLVE_RTOL:e}·max(1,|u|)); {beyond} of {resolved} re-solved rows disagree — fix the labels or pass --trust-labels")]
    Mismatch {
        /// The CSV file.
        file: String,
        /// Its line.
        line: usize,
        /// The state.
        x: Vec<f64>,
        /// 1-based input.
        input: usize,
        /// The file's label.
        label: f64,
        /// ampc's label.
        ampc: f64,
        /// |difference|.
        diff: f64,
        /// The tolerance.
        tol: f64,
        /// Rows beyond the tolerance.
        beyond: usize,
        /// Rows re-solved.
        resolved: usize,
    },
    /// ampc's solver finds no label where the file has one.
    #[error("{file}:{line}: the file labels state x = {x:?} but ampc's solver ends with status {status} there — fix the labels or pass --trust-labels")]
    Unlabelled {
        /// The CSV file.
        file: String,
        /// Its line.
        line: usize,
        /// The state.
        x: Vec<f64>,
        /// ampc's status.
        status: String,
    },
    /// Writing the dataset failed.
    #[error(transparent)]
    Dataset(#[from] DatasetError),
}

/// The sample of row positions to re-solve: `n` distinct labelled rows chosen by a seeded
/// partial Fisher–Yates shuffle (all of them, in order, if there are ≤ n).
pub fn resolve_sample(labelled: &[usize], n: usize, seed: u64) -> Vec<usize> {
    let mut v = labelled.to_vec();
    if n >= v.len() {
        return v;
    }
    for k in 0..n {
        let span = (v.len() - k) as f64;
        let j = k + ((crate::rng::uniform(seed, k as u64, 0) * span) as usize).min(v.len() - k - 1);
        v.swap(k, j);
    }
    v.truncate(n);
    v.sort_unstable();
    v
}

/// Reads `csv_path`, checks it against `cfg` and re-solves a sample; returns the dataset
/// (labels source recorded in [`Dataset::labels`]). Nothing is written.
pub fn import(
    cfg: &ProblemConfig,
    csv_path: &Path,
    opts: &ImportOptions,
) -> Result<Dataset, ImportError> {
    let file = csv_path.display().to_string();
    let bytes = std::fs::read(csv_path).map_err(|source| ImportError::Io {
        path: file.clone(),
        source,
    })?;
    let text = String::from_utf8_lossy(&bytes);
    let names = cfg.system.names();
    let t = csv::parse(
        &text,
        &file,
        (&names.states, &names.inputs),
        &cfg.domain.lo,
        &cfg.domain.hi,
        cfg.system.nu(),
    )?;
    let (u_lo, u_hi) = cfg.ocp.u_bounds(0);
    csv::check_inputs(&t, &file, u_lo, u_hi)?;
    let labelled: Vec<usize> = (0..t.records.len())
        .filter(|&i| t.records[i].is_labelled())
        .collect();
    let sample = resolve_sample(&labelled, opts.resolve, opts.seed);
    let ampc: Vec<crate::mpc::law::Label> = sample
        .par_iter()
        .map_init(
            || MpcLaw::new(cfg),
            |law, &i| law.solve(&t.records[i].x, None).0,
        )
        .collect();
    let mut labels = ImportedLabels {
        source: "imported".into(),
        file: file.clone(),
        sha256: crate::io::sha256_hex(&bytes),
        rows: t.records.len(),
        jacobian: t.jacobian,
        resolved: sample.len(),
        resolve_seed: opts.seed,
        tolerance: format!("|u − κ(x)| ≤ {RESOLVE_RTOL:e}·max(1, |κ(x)|) per input"),
        max_disagreement: 0.0,
        max_line: 0,
        beyond_tolerance: 0,
        unlabelled_by_ampc: 0,
        trusted: opts.trust_labels,
    };
    // The first offending row (in file order) for the error message.
    let mut first_bad: Option<ImportError> = None;
    for (&i, l) in sample.iter().zip(&ampc) {
        let r = &t.records[i];
        let line = t.lines[i];
        if !l.status.is_labelled() {
            labels.unlabelled_by_ampc += 1;
            first_bad.get_or_insert(ImportError::Unlabelled {
                file: file.clone(),
                line,
                x: r.x.clone(),
                status: l.status.as_str().into(),
            });
            continue;
        }
        let mut worst: Option<(usize, f64, f64)> = None;
        for j in 0..r.u.len() {
            let d = (r.u[j] - l.u[j]).abs();
            if d > labels.max_disagreement {
                labels.max_disagreement = d;
                labels.max_line = line;
            }
            let tol = RESOLVE_RTOL * l.u[j].abs().max(1.0);
            if d > tol && worst.is_none_or(|w| d > w.1) {
                worst = Some((j, d, tol));
            }
        }
        if let Some((j, diff, tol)) = worst {
            labels.beyond_tolerance += 1;
            first_bad.get_or_insert(ImportError::Mismatch {
                file: file.clone(),
                line,
                x: r.x.clone(),
                input: j + 1,
                label: r.u[j],
                ampc: l.u[j],
                diff,
                tol,
                beyond: 0,
                resolved: 0,
            });
        }
    }
    if let (Some(mut e), false) = (first_bad, opts.trust_labels) {
        if let ImportError::Mismatch {
            beyond, resolved, ..
        } = &mut e
        {
            *beyond = labels.beyond_tolerance;
            *resolved = labels.resolved;
        }
        return Err(e);
    }
    let n = t.records.len();
    Ok(Dataset {
        magic: MAGIC,
        version: IMPORTED_FORMAT_VERSION,
        header: Header {
            problem: cfg.name.clone(),
            problem_hash: cfg.problem_hash(),
            config_toml: toml::to_string(cfg).unwrap_or_default(),
            nx: cfg.system.nx() as u32,
            nu: cfg.system.nu() as u32,
            sampling: SamplingSettings {
                sampler: SamplerKind::Imported,
                counts: vec![],
                n,
                seed: 0,
            },
            total: n as u64,
            shard: None,
            chunk: CHUNK as u32,
        },
        records: t.records,
        labels: Some(labels),
        disagree: Vec::new(),
    })
}

#[cfg(test)]
mod tests;
