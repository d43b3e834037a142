//! [`Deployed`]: the exported controller as the function the statistical tiers test,
//!
//! ```text
//! κ̂(x) = clamp_{U ⊕ [−(ε + a), ε + a]}( κ_NN,f32( Π_X32(fl32(x)) ) )     (a: f32 allowance)
//! ```
//!
//! evaluated by [`Device`] (the same arithmetic, in the same order, as
//! `controller_core::Controller::evaluate`, libm tanh). `certify` owns the statistic but may
//! not import `deploy`, so it takes the function as a
//! [`TestedController`](crate::certify::statistical::TestedController) and this file
//! provides it; the caller (CLI, study) builds it from the model and its certificate.

use super::device::Device;
use super::{f32_allowance, ExportError, ExportModel, Tanh};
use crate::certify::certificate::Certificate;
use crate::certify::statistical::TestedController;
use crate::certify::Model;

/// The deployed controller of a model and its certificate (module doc).
#[derive(Clone, Debug)]
pub struct Deployed {
    device: Device,
    /// The f32 allowance the band was widened by (libm tanh, 2-norm over the outputs).
    pub allowance: f64,
    eps: f64,
}

impl Deployed {
    /// The controller `export` writes for `model` with `cert` (libm tanh): refused as
    /// [`ExportModel::from_trained`] refuses (another model's certificate, a non-tanh net,
    /// invalid numbers).
    pub fn new(name: &str, model: &Model, cert: &Certificate) -> Result<Self, ExportError> {
        let em = ExportModel::from_trained(name, model, cert)?;
        Self::from_export(&em)
    }

    /// The same from an [`ExportModel`].
    pub fn from_export(em: &ExportModel) -> Result<Self, ExportError> {
        let device = Device::new(em, Tanh::Libm)?;
        let (allowance, _) = f32_allowance(em, Tanh::Libm);
        Ok(Deployed {
            device,
            allowance,
            eps: em.eps,
        })
    }

    /// The clamp band (f32, lower and upper).
    pub fn band(&self) -> (&[f32], &[f32]) {
        (&self.device.band.0, &self.device.band.1)
    }
}

impl TestedController for Deployed {
    fn input(&self, x: &[f64]) -> Vec<f64> {
        let x32: Vec<f32> = x.iter().map(|v| *v as f32).collect();
        let (u, _) = self.device.evaluate(&x32);
        u.into_iter().map(f64::from).collect()
    }

    fn describe(&self) -> String {
        format!(
            "the deployed controller (state rounded to f32 and projected onto X, the folded \
             f32 network with libm tanh, outputs clamped to U ⊕ [−(ε + a), ε + a] with \
             ε = {} and the f32 allowance a = {:.3e}), as controller-core evaluates it",
            self.eps, self.allowance
        )
    }
}

/// Theorem 1's certificate of `model` on `data` as `trainer certify` and the pipeline write
/// it: [`crate::certify::certificate::certify`], then the deployed controller's f32 allowance
/// (libm tanh, 2-norm) stored beside ε — the one library entry, so a Rust caller writes the
/// same `certificate.json` as the CLI. A net the device cannot run (non-tanh) keeps
/// allowance 0 and the reason in the returned `Err`; `export` refuses such a net.
pub fn certify_deployed(
    name: &str,
    model: &Model,
    data: &crate::data::dataset::Dataset,
    cfg: &crate::problem::ProblemConfig,
    opts: &crate::certify::certificate::CertifyOptions,
) -> Result<(Certificate, Result<Deployed, ExportError>), crate::certify::certificate::MismatchError>
{
    let mut c = crate::certify::certificate::certify(model, data, cfg, opts)?;
    let deployed = Deployed::new(name, model, &c);
    if let Ok(dep) = &deployed {
        c.f32_allowance = dep.allowance;
    }
    Ok((c, deployed))
}

/// The f32 allowance (libm tanh, 2-norm over the outputs) of the controller `export` writes
/// for `model` with `cert`; `None` when the device cannot run it (`export` refuses such a
/// net). The `allowance` argument of [`crate::certify::refine::write_outputs`].
pub fn deployed_allowance(name: &str, model: &Model, cert: &Certificate) -> Option<f64> {
    Deployed::new(name, model, cert).ok().map(|d| d.allowance)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::deploy::export::placeholder_pendulum;

    /// The tested function is the device's: bit for bit the outputs of [`Device`], clamped
    /// to the band, at states inside and outside X.
    #[test]
    fn deployed_is_the_device() {
        let mut m = placeholder_pendulum();
        m.eps = 0.5;
        let d = Deployed::from_export(&m).unwrap();
        let dev = Device::new(&m, Tanh::Libm).unwrap();
        let (lo, hi) = d.band();
        for x in [[0.3, -0.2], [-9.0, 1.0], [2.0, 0.5], [6.2, -0.99]] {
            let u = d.input(&x);
            let x32 = [x[0] as f32, x[1] as f32];
            assert_eq!(u, vec![f64::from(dev.evaluate(&x32).0[0])]);
            assert!(u[0] >= f64::from(lo[0]) && u[0] <= f64::from(hi[0]));
        }
        assert!(d.describe().contains("f32"));
    }
}
