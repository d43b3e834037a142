//! `ampc._ampc`: the trainer's library facade as a Python extension module (PyO3).
//!
//! Owns the bridge only; every computation is the trainer's:
//! ```text
//! Problem.solve(X)   →  κ(x_i), ∂κ/∂x(x_i), status_i   (trainer::MpcLaw, as `trainer solve`)
//! sample/train/certify/export/run                     (trainer's stage functions)
//! Controller.eval(X) →  u_i, flags_i                    (trainer::Controller, as `trainer eval`)
//! ```
//! NumPy arrays come in as borrowed slices (copied only when not C-contiguous) and go out as
//! arrays allocated once and filled in place. Errors are `ampc.AmpcError` with the trainer's
//! message (its chain of causes, each naming its file, key or state).

use pyo3::prelude::*;

mod controller;
mod problem;
mod stages;

pyo3::create_exception!(
    _ampc,
    AmpcError,
    pyo3::exceptions::PyException,
    "An error of ampc: the trainer's message, naming the file, key or state at fault."
);

/// `AmpcError` carrying `e`'s message and the messages of its causes not already in it.
pub(crate) fn ampc_err(e: &(dyn std::error::Error + 'static)) -> PyErr {
    let mut msg = e.to_string();
    let mut source = e.source();
    while let Some(s) = source {
        let t = s.to_string();
        if !msg.contains(&t) {
            msg = format!("{msg}: {t}");
        }
        source = s.source();
    }
    AmpcError::new_err(msg)
}

/// `AmpcError` with a message of this crate (an argument's shape, a missing key).
pub(crate) fn ampc_msg(msg: impl Into<String>) -> PyErr {
    AmpcError::new_err(msg.into())
}

/// The extension module.
#[pymodule]
fn _ampc(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("AmpcError", m.py().get_type::<AmpcError>())?;
    m.add_class::<problem::Problem>()?;
    m.add_class::<stages::Dataset>()?;
    m.add_class::<stages::Model>()?;
    m.add_class::<controller::Controller>()?;
    m.add_function(wrap_pyfunction!(stages::sample, m)?)?;
    m.add_function(wrap_pyfunction!(stages::train, m)?)?;
    m.add_function(wrap_pyfunction!(stages::certify, m)?)?;
    m.add_function(wrap_pyfunction!(stages::export, m)?)?;
    m.add_function(wrap_pyfunction!(stages::run, m)?)?;
    Ok(())
}
