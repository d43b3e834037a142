//! The f32 range of an export: every number written into `weights.rs`, the blob, `ampc.h`
//! or the ONNX file must be a finite f32 (or, for the f64 fields of the certificate, a
//! number an f32 can hold, so the device's f32 arithmetic means what the file says):
//!
//! ```text
//! |v| ≤ f32::MAX = 3.4028235e38   for v in W, b, scalings, folded W', b', X, U, actuator,
//!                                  fallback, excluded boxes, ε, ε_D, L_NN, L_MPC, r,
//!                                  and the f32 allowance and observed difference of the report
//! ```
//! A number beyond it is an [`ExportError::Invalid`] naming the field and the value — not a
//! `weights.rs` holding `inf` (which does not compile) or a controller computing ±∞.

use super::{ExportError, ExportModel, ExportReport};

/// Largest magnitude an f32 holds.
const MAX: f64 = f32::MAX as f64;

fn check(what: &str, v: f64) -> Result<(), ExportError> {
    if v.is_finite() && v.abs() <= MAX {
        return Ok(());
    }
    Err(ExportError::Invalid(format!(
        "{what} = {v:e} is beyond the f32 range (|v| ≤ {MAX:e}): the device computes in f32, \
         so the export is refused"
    )))
}

fn check_all(what: &str, v: &[f64]) -> Result<(), ExportError> {
    v.iter()
        .enumerate()
        .try_for_each(|(i, x)| check(&format!("{what}[{i}]"), *x))
}

/// Checks every number of `model` (dimensions already validated), the folded weights
/// (`folded layers[k]`) included: folding the scalings into the first and last layer may
/// leave the f32 range although each factor is inside it.
pub fn check_model(model: &ExportModel) -> Result<(), ExportError> {
    for (k, l) in model.layers.iter().enumerate() {
        for (o, row) in l.w.iter().enumerate() {
            check_all(&format!("layers[{k}].w[{o}]"), row)?;
        }
        check_all(&format!("layers[{k}].b"), &l.b)?;
    }
    for (v, w) in [
        (&model.input.mean, "input.mean"),
        (&model.input.scale, "input.scale"),
        (&model.output.mean, "output.mean"),
        (&model.output.scale, "output.scale"),
        (&model.domain_lo, "domain_lo"),
        (&model.domain_hi, "domain_hi"),
        (&model.u_lo, "u_lo"),
        (&model.u_hi, "u_hi"),
        (&model.actuator_lo, "actuator_lo"),
        (&model.actuator_hi, "actuator_hi"),
    ] {
        check_all(w, v)?;
    }
    if let Some(f) = &model.fallback {
        check_all("fallback", f)?;
    }
    for (k, (lo, hi)) in model.excluded.iter().enumerate() {
        check_all(&format!("excluded[{k}].lo"), lo)?;
        check_all(&format!("excluded[{k}].hi"), hi)?;
    }
    for (v, w) in [
        (model.eps, "eps"),
        (model.eps_d, "eps_d"),
        (model.l_nn, "l_nn"),
        (model.l_mpc, "l_mpc"),
        (model.covering_radius, "covering_radius"),
    ] {
        check(w, v)?;
    }
    for (k, l) in model.folded().layers.iter().enumerate() {
        for (o, row) in l.w.iter().enumerate() {
            check_all(&format!("folded layers[{k}].w[{o}]"), row)?;
        }
        check_all(&format!("folded layers[{k}].b"), &l.b)?;
    }
    Ok(())
}

/// Checks the report's allowances and observed differences, and ε plus each allowance.
pub fn check_report(model: &ExportModel, report: &ExportReport) -> Result<(), ExportError> {
    let pairs = report.f32_allowance.iter().zip(&report.f32_observed);
    for (k, (&allowance, &observed)) in pairs.enumerate() {
        check(&format!("f32_allowance[{k}]"), allowance)?;
        check(
            &format!("f32_observed[{k}] (the f32 network overflowed on a sampled state)"),
            observed,
        )?;
        check(&format!("eps + f32_allowance[{k}]"), model.eps + allowance)?;
    }
    Ok(())
}
