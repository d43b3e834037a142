//! `ampc.Problem`: a problem file (`trainer::ProblemConfig`) and the MPC law it defines,
//! κ(x) = u₀*(x) with ∂κ/∂x, solved in parallel for the rows of a NumPy array exactly as
//! `trainer solve` solves the rows of its CSV (each state from a cold start, one
//! `MpcLaw` per worker); and the plant's discrete step x⁺ = F(x, u) (RK4, as the OCP uses it).

use crate::{ampc_err, ampc_msg};
use numpy::{
    AllowTypeChange, PyArray1, PyArray2, PyArray3, PyArrayLike1, PyArrayLike2, PyArrayMethods,
    PyReadonlyArray2, PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use pyo3::types::PyTuple;
use rayon::prelude::*;
use std::borrow::Cow;
use std::sync::Arc;
use trainer::problem::model::Discrete;
use trainer::{MpcLaw, ProblemConfig};

/// A control problem: the system, the OCP, the domain X and every stage's settings.
#[pyclass(module = "ampc._ampc", frozen)]
pub struct Problem {
    pub(crate) cfg: Arc<ProblemConfig>,
    /// The problem file's text (what `run` writes as `problem.toml`).
    pub(crate) text: String,
}

/// The rows of `x` (shape (n, nx)) as one row-major slice: borrowed when `x` is C-contiguous,
/// else copied once. `what` names the argument in errors.
pub(crate) fn rows<'a>(
    x: &'a PyReadonlyArray2<'_, f64>,
    nx: usize,
    what: &str,
) -> PyResult<Cow<'a, [f64]>> {
    let shape = x.as_array().shape().to_vec();
    if shape[1] != nx {
        return Err(ampc_msg(format!(
            "{what} has shape ({}, {}): expected (n, {nx}), one state of {nx} entries per row",
            shape[0], shape[1]
        )));
    }
    // `as_slice` also accepts a Fortran-ordered array (its memory is column-major): only a
    // C-ordered one is read in place.
    Ok(match x.as_slice() {
        Ok(s) if x.is_c_contiguous() => Cow::Borrowed(s),
        _ => Cow::Owned(x.as_array().iter().copied().collect()),
    })
}

#[pymethods]
impl Problem {
    /// Reads and validates the problem file at `path`.
    #[staticmethod]
    fn from_file(path: std::path::PathBuf) -> PyResult<Self> {
        let text = std::fs::read_to_string(&path)
            .map_err(|e| ampc_msg(format!("cannot read {}: {e}", path.display())))?;
        let cfg = ProblemConfig::from_toml_str(&text, &path.display().to_string())
            .map_err(|e| ampc_err(&e))?;
        Ok(Problem {
            cfg: Arc::new(cfg),
            text,
        })
    }

    /// Parses and validates a problem file's text; `origin` names it in errors.
    #[staticmethod]
    #[pyo3(signature = (text, origin = "(the text given to Problem.from_toml)"))]
    fn from_toml(text: String, origin: &str) -> PyResult<Self> {
        let cfg = ProblemConfig::from_toml_str(&text, origin).map_err(|e| ampc_err(&e))?;
        Ok(Problem {
            cfg: Arc::new(cfg),
            text,
        })
    }

    /// The problem's `name`.
    #[getter]
    fn name(&self) -> String {
        self.cfg.name.clone()
    }

    /// The state dimension n_x.
    #[getter]
    fn nx(&self) -> usize {
        self.cfg.system.nx()
    }

    /// The input dimension n_u.
    #[getter]
    fn nu(&self) -> usize {
        self.cfg.system.nu()
    }

    /// The problem file's text.
    #[getter]
    fn toml(&self) -> String {
        self.text.clone()
    }

    /// The problem hash that keys every label of this problem.
    #[getter]
    fn problem_hash(&self) -> String {
        self.cfg.problem_hash()
    }

    /// The sampling time `ocp.ts` [s].
    #[getter]
    fn ts(&self) -> f64 {
        self.cfg.ocp.ts
    }

    /// The domain X = [lo, hi] (`domain.lo`, `domain.hi`).
    #[getter]
    fn domain<'py>(
        &self,
        py: Python<'py>,
    ) -> (Bound<'py, PyArray1<f64>>, Bound<'py, PyArray1<f64>>) {
        (
            PyArray1::from_slice(py, &self.cfg.domain.lo),
            PyArray1::from_slice(py, &self.cfg.domain.hi),
        )
    }

    /// κ(x) = u₀*(x), ∂κ/∂x and the solver status at every row of `x` (shape (n, nx)):
    /// `(U (n, nu), dU_dX (n, nu, nx), status)` — `trainer solve`'s columns, with its status
    /// names (`converged`, `soft`, `infeasible`, `max_iterations`, `numerical_failure`);
    /// NaN where a state has no label. Runs on all cores with the GIL released.
    /// With `with_cost`, a fourth entry: the optimal cost per state (n,), `trainer solve`'s
    /// `cost` column (the k = 0 state term included; NaN when unlabelled).
    #[pyo3(signature = (x, with_cost = false))]
    fn solve<'py>(
        &self,
        py: Python<'py>,
        x: PyArrayLike2<'py, f64, AllowTypeChange>,
        with_cost: bool,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let (nx, nu) = (self.nx(), self.nu());
        let xs = rows(&x, nx, "X")?;
        let n = xs.len() / nx.max(1);
        let u = PyArray2::<f64>::zeros(py, [n, nu], false);
        let du = PyArray3::<f64>::zeros(py, [n, nu, nx], false);
        let mut status = vec![""; n];
        let mut cost = vec![f64::NAN; n];
        {
            let mut uw = u.readwrite();
            let mut dw = du.readwrite();
            let us = uw.as_slice_mut().map_err(|e| ampc_msg(e.to_string()))?;
            let ds = dw.as_slice_mut().map_err(|e| ampc_msg(e.to_string()))?;
            let cfg = &*self.cfg;
            let xs: &[f64] = &xs;
            if n > 0 {
                py.detach(|| {
                    xs.par_chunks(nx)
                        .zip(us.par_chunks_mut(nu))
                        .zip(ds.par_chunks_mut(nu * nx))
                        .zip(status.par_iter_mut().zip(cost.par_iter_mut()))
                        .for_each_init(
                            || MpcLaw::new(cfg),
                            |law, (((x, u), du), (s, c))| {
                                let l = law.solve(x, None).0;
                                u.copy_from_slice(&l.u);
                                du.copy_from_slice(&l.du_dx);
                                *s = l.status.as_str();
                                *c = l.cost;
                            },
                        )
                });
            }
        }
        let mut out = vec![u.into_any(), du.into_any(), status.into_pyobject(py)?];
        if with_cost {
            out.push(PyArray1::from_vec(py, cost).into_any());
        }
        PyTuple::new(py, out)
    }

    /// The plant's discrete step x⁺ = F(x, u) (RK4 over `ocp.ts` with `ocp.rk4_substeps`,
    /// the model the OCP predicts with): `x` of nx entries, `u` of nu.
    fn step<'py>(
        &self,
        py: Python<'py>,
        x: PyArrayLike1<'py, f64, AllowTypeChange>,
        u: PyArrayLike1<'py, f64, AllowTypeChange>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let (nx, nu) = (self.nx(), self.nu());
        let (x, u) = (x.as_array().to_vec(), u.as_array().to_vec());
        if x.len() != nx || u.len() != nu {
            return Err(ampc_msg(format!(
                "step(x, u): x has {} entries and u {}; problem `{}` has nx = {nx}, nu = {nu}",
                x.len(),
                u.len(),
                self.cfg.name
            )));
        }
        let f = Discrete::new(
            self.cfg.system.clone(),
            self.cfg.ocp.ts,
            self.cfg.ocp.rk4_substeps,
        );
        let mut out = vec![0.0; nx];
        f.step(&x, &u, &mut out);
        Ok(PyArray1::from_vec(py, out))
    }

    fn __repr__(&self) -> String {
        format!(
            "Problem(name={:?}, nx={}, nu={})",
            self.cfg.name,
            self.nx(),
            self.nu()
        )
    }
}
