//! `ampc.Controller`: the exported controller of a model file (`trainer::Controller`), for
//! the rows of a NumPy array — `trainer eval`'s computation, bit for bit:
//!
//! ```text
//! u = clamp(κ_NN,f32(proj_X(x as f32)), band),  flags: 1 out of X, 2 not finite,
//!                                                      4 clamped, 8 excluded box
//! ```

use crate::problem::rows;
use crate::{ampc_err, ampc_msg};
use numpy::{AllowTypeChange, PyArray1, PyArray2, PyArrayLike2, PyArrayMethods};
use pyo3::prelude::*;
use std::path::PathBuf;

/// `eval`'s result: u (n, nu) and the flags (n,).
type UAndFlags<'py> = (Bound<'py, PyArray2<f32>>, Bound<'py, PyArray1<u8>>);

/// The deployed controller of a model file under its certificate.
#[pyclass(module = "ampc._ampc", frozen)]
pub struct Controller {
    ctrl: trainer::Controller,
}

#[pymethods]
impl Controller {
    /// The controller of the model at `path` (trainer model file or ONNX) under the
    /// certificate at `certificate` (default: the one stored in the model), read and
    /// re-checked as `trainer eval` reads them.
    #[new]
    #[pyo3(signature = (path, certificate = None))]
    fn new(path: PathBuf, certificate: Option<PathBuf>) -> PyResult<Self> {
        let ctrl =
            trainer::Controller::load(&path, certificate.as_deref()).map_err(|e| ampc_err(&e))?;
        Ok(Controller { ctrl })
    }

    /// The state dimension n_x.
    #[getter]
    fn nx(&self) -> usize {
        self.ctrl.nx()
    }

    /// The input dimension n_u.
    #[getter]
    fn nu(&self) -> usize {
        self.ctrl.nu()
    }

    /// u (float32, shape (n, nu): the device's numbers) and the flags (uint8, shape (n,))
    /// at every row of `x` (shape (n, nx), float64, rounded to f32 as the device receives
    /// it) — `trainer eval`'s `u1..um,flags` columns.
    fn eval<'py>(
        &self,
        py: Python<'py>,
        x: PyArrayLike2<'py, f64, AllowTypeChange>,
    ) -> PyResult<UAndFlags<'py>> {
        let (nx, nu) = (self.ctrl.nx(), self.ctrl.nu());
        let xs = rows(&x, nx, "X")?;
        let n = xs.len() / nx.max(1);
        let u = PyArray2::<f32>::zeros(py, [n, nu], false);
        let flags = PyArray1::<u8>::zeros(py, [n], false);
        {
            let mut uw = u.readwrite();
            let mut fw = flags.readwrite();
            let us = uw.as_slice_mut().map_err(|e| ampc_msg(e.to_string()))?;
            let fs = fw.as_slice_mut().map_err(|e| ampc_msg(e.to_string()))?;
            for (i, x) in xs.chunks(nx).enumerate() {
                let (ui, f) = self.ctrl.evaluate(x);
                us[i * nu..(i + 1) * nu].copy_from_slice(&ui);
                fs[i] = f;
            }
        }
        Ok((u, flags))
    }

    fn __repr__(&self) -> String {
        format!("Controller(nx={}, nu={})", self.ctrl.nx(), self.ctrl.nu())
    }
}
