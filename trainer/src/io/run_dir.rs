//! `RunDir`: the directory of one `trainer run` (`<out>/<name>/`, or its `robust/`) and the
//! names of the files in it. Every stage, the report and the robust loop name a run's files
//! through this type, so each file name is spelled once.

use std::path::{Path, PathBuf};

/// A run directory: the path of each file a run writes or reads (module doc).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RunDir {
    dir: PathBuf,
}

/// Declares the file names of a run directory and a path accessor for each.
macro_rules! run_files {
    ($($(#[$doc:meta])* $konst:ident, $method:ident = $name:literal;)*) => {
        impl RunDir {
            $(
                $(#[$doc])*
                pub const $konst: &'static str = $name;
                $(#[$doc])*
                pub fn $method(&self) -> PathBuf {
                    self.dir.join(Self::$konst)
                }
            )*
        }
    };
}

run_files! {
    /// The problem file the run was made from (`problem.toml`).
    PROBLEM, problem = "problem.toml";
    /// Where the sampling plan's states have no MPC label (`infeasible.json`; written only
    /// when some have none).
    INFEASIBLE, infeasible = "infeasible.json";
    /// The labelled dataset of the sampling plan (`dataset.bin`).
    DATASET, dataset = "dataset.bin";
    /// The dataset's CSV export (`dataset.csv`).
    DATASET_CSV, dataset_csv = "dataset.csv";
    /// The MPC labels of random validation states (`validation.bin`).
    VALIDATION, validation = "validation.bin";
    /// The nominally trained net (`model_nominal.bin`).
    MODEL_NOMINAL, model_nominal = "model_nominal.bin";
    /// The sensitivity-regularized net (`model_regularized.bin`).
    MODEL_REGULARIZED, model_regularized = "model_regularized.bin";
    /// The regularized net's certificate (`certificate.json`).
    CERTIFICATE, certificate = "certificate.json";
    /// The nominal net's certificate (`certificate_nominal.json`).
    CERTIFICATE_NOMINAL, certificate_nominal = "certificate_nominal.json";
    /// The generated Rust weights of the regularized net (`weights.rs`).
    WEIGHTS_RS, weights_rs = "weights.rs";
    /// The postcard blob of the regularized net (`weights.bin`).
    WEIGHTS_BIN, weights_bin = "weights.bin";
    /// The export's clamp band and f32 allowance (`export_report.json`).
    EXPORT_REPORT, export_report = "export_report.json";
    /// The closed-loop study (`closed_loop.json`).
    CLOSED_LOOP, closed_loop = "closed_loop.json";
    /// The seed study (`seeds.json`).
    SEEDS, seeds = "seeds.json";
    /// The report in Markdown (`report.md`).
    REPORT_MD, report_md = "report.md";
    /// The report in HTML (`report.html`).
    REPORT_HTML, report_html = "report.html";
    /// The per-state check of a certificate (`check.json`).
    CHECK, check = "check.json";
    /// The robust design loop's verdict (`robust.json`).
    ROBUST, robust = "robust.json";
    /// The local certificates' cells of a refinement (`cells.csv`).
    CELLS, cells = "cells.csv";
    /// The figures' folder (`plots`).
    PLOTS, plots = "plots";
}

impl RunDir {
    /// The run directory at `dir`.
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        Self { dir: dir.into() }
    }

    /// The directory itself.
    pub fn path(&self) -> &Path {
        &self.dir
    }

    /// The file `name` (relative to the run directory).
    pub fn join(&self, name: impl AsRef<Path>) -> PathBuf {
        self.dir.join(name)
    }

    /// The manifest of stage `stage` (`manifest_<stage>.json`).
    pub fn manifest(&self, stage: &str) -> PathBuf {
        self.dir.join(format!("manifest_{stage}.json"))
    }
}

impl AsRef<Path> for RunDir {
    fn as_ref(&self) -> &Path {
        &self.dir
    }
}

#[cfg(test)]
mod tests {
    use super::RunDir;

    #[test]
    fn each_file_is_named_under_the_directory() {
        let d = RunDir::new("runs/pendulum");
        assert_eq!(
            d.certificate(),
            std::path::Path::new("runs/pendulum/certificate.json")
        );
        assert_eq!(d.dataset(), d.join(RunDir::DATASET));
        assert_eq!(
            d.manifest("export"),
            std::path::Path::new("runs/pendulum/manifest_export.json")
        );
    }
}
