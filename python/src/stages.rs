//! The stages as Python functions over `ampc.Dataset` and `ampc.Model`: the trainer's
//! facade (`trainer::{sample, train, certify, export, run}`), each the computation of the
//! `trainer` subcommand of the same name:
//!
//! ```text
//! D    = sample(P, path)                 κ, ∂κ/∂x on P's sampling plan, saved at path
//! κ_NN = train(P, D, V, nominal)         min λ₁·MSE + λ₂·Jacobian mismatch + λ₃·Σ‖W‖²
//! C    = certify(P, κ_NN, D, V)          ε = ε_D + (L_MPC + L_NN)·r + f32 allowance
//! export(P, κ_NN, C, weights.rs, .bin)   controller-core's files and the f32 analysis
//! run(P, out)                            the whole nominal pipeline into out/<name>/
//! ```
//! The certificate crosses the boundary as its sealed `certificate.json` text (the Python
//! side reads it as a dict with the file's keys), and is re-read and re-checked by
//! `export` as any certificate file is.

use crate::problem::Problem;
use crate::{ampc_err, ampc_msg};
use numpy::{PyArray2, PyArray3, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;
use trainer::certify::file::CertificateFile;
use trainer::pipeline::{RunOptions, Stage};

/// A labelled dataset (`dataset.bin`): states, κ, ∂κ/∂x and each solve's status.
#[pyclass(module = "ampc._ampc", frozen)]
pub struct Dataset {
    pub(crate) data: trainer::Dataset,
}

#[pymethods]
impl Dataset {
    /// Reads and checks the dataset file at `path`.
    #[staticmethod]
    fn load(path: PathBuf) -> PyResult<Self> {
        let data = trainer::Dataset::load(&path).map_err(|e| ampc_err(&e))?;
        Ok(Dataset { data })
    }

    /// Writes the dataset file at `path` (atomically).
    fn save(&self, path: PathBuf) -> PyResult<()> {
        self.data.save(&path).map_err(|e| ampc_err(&e))
    }

    fn __len__(&self) -> usize {
        self.data.records.len()
    }

    /// The states, shape (n, nx).
    #[getter]
    fn x<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        self.column(py, |r| &r.x)
    }

    /// κ at the states, shape (n, nu) (NaN where unlabelled).
    #[getter]
    fn u<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        self.column(py, |r| &r.u)
    }

    /// ∂κ/∂x at the states, shape (n, nu, nx).
    #[getter]
    fn du_dx<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray3<f64>>> {
        let (n, nx) = (self.data.records.len(), self.data.header.nx as usize);
        let nu = self.data.header.nu as usize;
        let flat: Vec<f64> = self
            .data
            .records
            .iter()
            .flat_map(|r| r.du_dx.iter().copied())
            .collect();
        numpy::PyArray1::from_vec(py, flat)
            .reshape([n, nu, nx])
            .map_err(|e| ampc_msg(e.to_string()))
    }

    /// Each state's solver status (`trainer solve`'s names).
    #[getter]
    fn status(&self) -> Vec<&'static str> {
        self.data
            .records
            .iter()
            .map(|r| r.status.as_str())
            .collect()
    }

    /// The problem hash the labels belong to.
    #[getter]
    fn problem_hash(&self) -> String {
        self.data.header.problem_hash.clone()
    }

    fn __repr__(&self) -> String {
        let c = self.data.counts();
        format!(
            "Dataset(n={}, converged={}, soft={}, infeasible={}, failed={})",
            c.total, c.converged, c.soft, c.infeasible, c.failed
        )
    }
}

impl Dataset {
    /// One per-record vector as rows of an (n, len) array.
    fn column<'py>(
        &self,
        py: Python<'py>,
        f: impl Fn(&trainer::data::dataset::Record) -> &Vec<f64>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let n = self.data.records.len();
        let flat: Vec<f64> = self
            .data
            .records
            .iter()
            .flat_map(|r| f(r).iter().copied())
            .collect();
        let w = flat.len().checked_div(n).unwrap_or(0);
        numpy::PyArray1::from_vec(py, flat)
            .reshape([n, w])
            .map_err(|e| ampc_msg(e.to_string()))
    }
}

/// A trained network (the trainer's model file), with its certificate once certified.
#[pyclass(module = "ampc._ampc", frozen)]
pub struct Model {
    pub(crate) model: trainer::Model,
}

#[pymethods]
impl Model {
    /// Reads the trainer's model file at `path`.
    #[staticmethod]
    fn load(path: PathBuf) -> PyResult<Self> {
        let model = trainer::Model::load(&path).map_err(|e| ampc_err(&e))?;
        Ok(Model { model })
    }

    /// Writes the model file at `path` (what `trainer eval`/`export` and `Controller` read;
    /// with `certificate`, that certificate is stored in it as `trainer certify` stores it).
    #[pyo3(signature = (path, certificate = None))]
    fn save(&self, path: PathBuf, certificate: Option<&str>) -> PyResult<()> {
        let mut m = self.model.clone();
        if let Some(text) = certificate {
            m.certificate = Some(parse_certificate(text)?.base);
        }
        m.save(&path).map_err(|e| ampc_err(&e))
    }

    /// SHA-256 of the network (the `hash` a certificate of it names).
    #[getter]
    fn hash(&self) -> String {
        self.model.content_hash()
    }

    /// The layer widths (nx, hidden…, nu).
    #[getter]
    fn widths(&self) -> Vec<usize> {
        self.model.mlp.widths()
    }

    fn __repr__(&self) -> String {
        format!(
            "Model(widths={:?}, hash={:?})",
            self.model.mlp.widths(),
            &self.model.content_hash()[..12]
        )
    }
}

/// The certificate of a sealed `certificate.json` text (checksum verified).
fn parse_certificate(text: &str) -> PyResult<CertificateFile> {
    let (c, _) =
        CertificateFile::parse(text, "the certificate given", false).map_err(|e| ampc_err(&e))?;
    Ok(c)
}

/// `trainer sample`: labels `problem`'s sampling plan and saves the dataset at `path`.
#[pyfunction]
pub fn sample(py: Python<'_>, problem: &Problem, path: PathBuf) -> PyResult<Dataset> {
    let cfg = problem.cfg.clone();
    let data = py
        .detach(|| trainer::sample(&cfg, &path))
        .map_err(|e| ampc_err(&e))?;
    Ok(Dataset { data })
}

/// `trainer train`: the regularized net (`nominal`: λ₂ = λ₃ = 0) on `data`, with
/// `validation` (default: `data`) for its statistics.
#[pyfunction]
#[pyo3(signature = (problem, data, validation = None, nominal = false))]
pub fn train(
    py: Python<'_>,
    problem: &Problem,
    data: &Dataset,
    validation: Option<&Dataset>,
    nominal: bool,
) -> PyResult<Model> {
    let cfg = problem.cfg.clone();
    let (d, v) = (&data.data, &validation.unwrap_or(data).data);
    let model = py
        .detach(|| trainer::train(&cfg, d, v, nominal))
        .map_err(|e| ampc_err(&e))?;
    Ok(Model { model })
}

/// `trainer certify`: Theorem 1's certificate of `model`, as the sealed text of
/// `certificate.json`.
#[pyfunction]
#[pyo3(signature = (problem, model, data, validation = None))]
pub fn certify(
    py: Python<'_>,
    problem: &Problem,
    model: &Model,
    data: &Dataset,
    validation: Option<&Dataset>,
) -> PyResult<String> {
    let cfg = problem.cfg.clone();
    let v = validation.map(|v| &v.data);
    let c = py
        .detach(|| trainer::certify(&cfg, &model.model, &data.data, v))
        .map_err(|e| ampc_err(&e))?;
    c.sealed().map_err(|e| ampc_err(&e))
}

/// `trainer export --rust … --postcard …`: writes controller-core's files of `model` under
/// the certificate (sealed JSON text); returns the f32 analysis.
#[pyfunction]
pub fn export<'py>(
    py: Python<'py>,
    problem: &Problem,
    model: &Model,
    certificate: &str,
    rust: PathBuf,
    postcard: PathBuf,
) -> PyResult<Bound<'py, PyDict>> {
    let cert = parse_certificate(certificate)?;
    let cfg = problem.cfg.clone();
    let r = py
        .detach(|| trainer::export(&cfg, &model.model, &cert, &rust, &postcard))
        .map_err(|e| ampc_err(&e))?;
    let d = PyDict::new(py);
    d.set_item("f32_allowance_libm", r.f32_allowance[0])?;
    d.set_item("f32_allowance_fast", r.f32_allowance[1])?;
    d.set_item("f32_observed_libm", r.f32_observed[0])?;
    d.set_item("f32_observed_fast", r.f32_observed[1])?;
    d.set_item("samples", r.samples)?;
    d.set_item("boxes", r.boxes)?;
    Ok(d)
}

/// `trainer run` (the nominal pipeline; the robust loop stays with the CLI): every stage
/// into `out/<name>/`, each skipped when its inputs are unchanged, `force` naming stages to
/// redo. Returns one dict per stage (`stage`, `skipped`, `seconds`, `summary`, `outputs`)
/// and the run directory.
#[pyfunction]
#[pyo3(signature = (problem, out, force = Vec::new()))]
pub fn run<'py>(
    py: Python<'py>,
    problem: &Problem,
    out: PathBuf,
    force: Vec<String>,
) -> PyResult<(Vec<Bound<'py, PyDict>>, PathBuf)> {
    let force = force
        .iter()
        .map(|s| s.parse::<Stage>().map_err(|e| ampc_err(&e)))
        .collect::<PyResult<Vec<_>>>()?;
    let mut cfg = (*problem.cfg).clone();
    // As `trainer run`: the nominal pipeline never sees the robust settings.
    let _ = std::mem::take(&mut cfg.robust);
    let opts = RunOptions {
        root: out.clone(),
        force,
        ..Default::default()
    };
    let text = problem.text.clone();
    let reports = py
        .detach(|| trainer::run(&cfg, &text, &opts))
        .map_err(|e| ampc_err(&e))?;
    let mut stages = Vec::new();
    for r in reports {
        let d = PyDict::new(py);
        d.set_item("stage", r.stage)?;
        d.set_item("skipped", r.skipped)?;
        d.set_item("seconds", r.seconds)?;
        d.set_item("summary", r.summary)?;
        d.set_item("outputs", r.outputs)?;
        stages.push(d);
    }
    Ok((stages, out.join(&cfg.name)))
}
