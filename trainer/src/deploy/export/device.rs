//! `device`: the exported controller as `controller-core` computes it, in the trainer
//! ([`Device`], used by `trainer eval`'s default output).
//!
//! For a state x (rounded to f32, nearest): if a component is not finite, u = the fallback
//! and the flags are `NON_FINITE`; otherwise x is projected onto the f32 domain
//! [`ExportModel::domain_f32`] (`OUT_OF_DOMAIN` when that moved it), the folded f32 network
//! runs with the device tanh ([`eval_f32`]), and each output is clamped to the band
//! [`ExportModel::clamp_band`]`(ε + f32 allowance)` (`CLAMPED` when that moved it; a NaN
//! output takes the fallback and `NON_FINITE`); a projected state inside one of the
//! certificate's excluded boxes ([`ExportModel::excluded_f32`]) is flagged `EXCLUDED`. The
//! same arithmetic, in the same order, as
//! `controller_core::Controller::evaluate`, so the results are bit-identical.

use super::{eval_f32, f32_allowance, ExportError, ExportModel, Folded, Tanh};

/// Flag bit: the state was outside the certified domain and was projected onto it.
pub const OUT_OF_DOMAIN: u8 = 1;
/// Flag bit: a state component (or an output) was not a number; u is the fallback.
pub const NON_FINITE: u8 = 2;
/// Flag bit: the network's output was outside the clamp band and was clamped.
pub const CLAMPED: u8 = 4;
/// Flag bit: the state lies in a box the certificate excludes (ε does not cover it).
pub const EXCLUDED: u8 = 8;

/// The exported controller, ready to evaluate (see the module doc).
#[derive(Clone, Debug)]
pub struct Device {
    folded: Folded,
    /// The f32 domain (rounded outward: it contains X).
    pub domain: (Vec<f32>, Vec<f32>),
    /// The clamp band (f32).
    pub band: (Vec<f32>, Vec<f32>),
    /// The fallback input (f32, inside the band).
    pub fallback: Vec<f32>,
    /// The excluded boxes (f32, rounded outward).
    pub excluded: Vec<(Vec<f32>, Vec<f32>)>,
    tanh: Tanh,
}

impl Device {
    /// The controller `export` writes for `model` with the device tanh `tanh`: validates
    /// the model and computes its f32 allowance (which widens the band by ε + allowance
    /// before the actuator limits cut it).
    pub fn new(model: &ExportModel, tanh: Tanh) -> Result<Self, ExportError> {
        model.validate()?;
        let (allowance, _) = f32_allowance(model, tanh);
        let band = model.clamp_band(model.eps + allowance);
        let fallback = model.fallback_f32(&band.0, &band.1);
        Ok(Device {
            folded: model.folded(),
            domain: model.domain_f32(),
            band,
            fallback,
            excluded: model.excluded_f32(),
            tanh,
        })
    }

    /// u and the flags for the state `x` (module doc).
    pub fn evaluate(&self, x: &[f32]) -> (Vec<f32>, u8) {
        let (lo, hi) = &self.domain;
        let mut flags = 0u8;
        let mut xp = Vec::with_capacity(x.len());
        for ((&xi, &l), &h) in x.iter().zip(lo).zip(hi) {
            if !xi.is_finite() {
                return (self.fallback.clone(), NON_FINITE);
            }
            xp.push(if xi < l {
                flags |= OUT_OF_DOMAIN;
                l
            } else if xi > h {
                flags |= OUT_OF_DOMAIN;
                h
            } else {
                xi
            });
        }
        let inside = |(l, h): &(Vec<f32>, Vec<f32>)| {
            xp.iter()
                .zip(l.iter().zip(h))
                .all(|(v, (a, b))| *a <= *v && *v <= *b)
        };
        if self.excluded.iter().any(inside) {
            flags |= EXCLUDED;
        }
        let y = eval_f32(&self.folded, lo, hi, &xp, self.tanh);
        let mut u = self.fallback.clone();
        for (((uj, yj), &l), &h) in u.iter_mut().zip(y).zip(&self.band.0).zip(&self.band.1) {
            if yj.is_nan() {
                flags |= NON_FINITE;
            } else if yj < l {
                flags |= CLAMPED;
                *uj = l;
            } else if yj > h {
                flags |= CLAMPED;
                *uj = h;
            } else {
                *uj = yj;
            }
        }
        (u, flags)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::deploy::export::{placeholder_pendulum, DenseF64};

    #[test]
    fn flags_and_clamp_follow_the_core_rules() {
        let m = placeholder_pendulum();
        let d = Device::new(&m, Tanh::Libm).unwrap();
        let (lo, hi) = d.domain.clone();
        // Inside: no flag, u inside the band and equal to the f32 network.
        let x = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])];
        let (u, f) = d.evaluate(&x);
        let y = eval_f32(&m.folded(), &lo, &hi, &x, Tanh::Libm);
        assert!(f & (OUT_OF_DOMAIN | NON_FINITE) == 0);
        assert_eq!(u[0], y[0].clamp(d.band.0[0], d.band.1[0]));
        // Outside X: projected; the output is the network's at the projected state.
        let (u2, f2) = d.evaluate(&[hi[0] + 1.0, lo[1] - 3.0]);
        assert!(f2 & OUT_OF_DOMAIN != 0);
        let (u3, _) = d.evaluate(&[hi[0], lo[1]]);
        assert_eq!(u2, u3);
        // Non-finite: fallback, only that flag.
        for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            assert_eq!(d.evaluate(&[bad, 0.0]), (d.fallback.clone(), NON_FINITE));
        }
    }

    #[test]
    fn the_corners_of_x_are_in_the_domain() {
        // The pendulum's X = [−2π, 2π] × [−1, 1]: 2π has no f32, and the f32 nearest it lies
        // outside X. `eval` reads a state as that nearest f32: no corner may be flagged.
        let m = placeholder_pendulum();
        let d = Device::new(&m, Tanh::Libm).unwrap();
        for c in 0..4 {
            let x: Vec<f32> = (0..2)
                .map(|i| {
                    let v = if c >> i & 1 == 0 {
                        m.domain_lo[i]
                    } else {
                        m.domain_hi[i]
                    };
                    v as f32
                })
                .collect();
            let (_, f) = d.evaluate(&x);
            assert_eq!(f & OUT_OF_DOMAIN, 0, "corner {x:?} flagged out of domain");
        }
    }

    #[test]
    fn states_in_excluded_boxes_are_flagged_with_the_same_input() {
        let plain = placeholder_pendulum();
        let mut m = plain.clone();
        // A box with bounds that are not f32 numbers: rounded outward, its edges stay in.
        m.excluded = vec![(vec![0.1, -0.3], vec![0.7, 0.30000001])];
        let (d, d0) = (
            Device::new(&m, Tanh::Libm).unwrap(),
            Device::new(&plain, Tanh::Libm).unwrap(),
        );
        for x in [[0.1f32, -0.3], [0.4, 0.0], [0.7, 0.3]] {
            let ((u, f), (u0, f0)) = (d.evaluate(&x), d0.evaluate(&x));
            assert_eq!((u, f), (u0, f0 | EXCLUDED), "{x:?}");
        }
        for x in [[0.09f32, 0.0], [0.4, 0.31], [-0.5, 0.0]] {
            assert_eq!(d.evaluate(&x).1 & EXCLUDED, 0, "{x:?}");
        }
        // An empty box is refused naming it.
        m.excluded = vec![(vec![0.5, 0.0], vec![0.4, 0.1])];
        let e = Device::new(&m, Tanh::Libm).unwrap_err().to_string();
        assert!(e.contains("excluded[0]"), "{e}");
    }

    #[test]
    fn a_large_output_is_clamped_to_the_actuator_band() {
        let mut m = placeholder_pendulum();
        // Last layer: a huge bias → the raw output leaves the band.
        let last = m.layers.len() - 1;
        let DenseF64 { b, .. } = &mut m.layers[last];
        b[0] = 1e6;
        let d = Device::new(&m, Tanh::Libm).unwrap();
        let (u, f) = d.evaluate(&[0.0, 0.0]);
        assert_eq!(f, CLAMPED);
        assert_eq!(u[0], d.band.1[0]);
        assert!(f64::from(d.band.1[0]) <= m.actuator_hi[0]);
    }
}
