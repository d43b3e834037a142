//! [`ImportedLabels`]: the provenance of a dataset whose labels come from another solver's
//! CSV (`trainer import`), stored after the records in a dataset file of format version 3
//! and copied into the certificate as `"labels"`: the file and the SHA-256 of its bytes, and
//! the outcome of the re-solve check, max_i max_j |u_ij − κ_j(x_i)| over a seeded sample of
//! rows against the tolerance `RESOLVE_RTOL·max(1, |κ_j(x_i)|)`.

use serde::{Deserialize, Serialize};

/// Where a dataset's labels come from (`"labels"` in the certificate): stored in imported
/// dataset files (format version 3).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ImportedLabels {
    /// Always `"imported"` (ampc's own datasets carry no such record).
    pub source: String,
    /// The CSV file as given on the command line.
    pub file: String,
    /// SHA-256 of the CSV file's bytes (hex).
    pub sha256: String,
    /// Data rows in the file.
    pub rows: usize,
    /// Whether the file had Jacobian columns `du{j}_dx{i}` (without them training drops the
    /// Jacobian term: λ₂ = 0 in effect).
    pub jacobian: bool,
    /// Rows re-solved by ampc's SQP.
    pub resolved: usize,
    /// Seed of the re-solved sample.
    pub resolve_seed: u64,
    /// The tolerance rule of the check.
    pub tolerance: String,
    /// Largest |u − κ(x)| over the re-solved rows (∞-norm over the inputs; 0 if none).
    pub max_disagreement: f64,
    /// File line of that row (0 if none was re-solved).
    pub max_line: usize,
    /// Re-solved rows beyond the tolerance.
    pub beyond_tolerance: usize,
    /// Re-solved rows labelled in the file that ampc's solver could not label.
    pub unlabelled_by_ampc: usize,
    /// Whether `--trust-labels` accepted disagreements beyond the tolerance.
    pub trusted: bool,
}
