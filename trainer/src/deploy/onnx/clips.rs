//! What an ONNX file must be before its graph is read as an MLP: its default-domain opset
//! within [`SUPPORTED_OPSETS`], every tensor name defined once — and the `Clip` nodes of an
//! ampc export, which the importer drops only when they are exactly the export's own:
//!
//! ```text
//! projection  Clip(x_i, lo_i, hi_i)  dropped ⇔ lo_i = rnd₃₂(ampc.domain_lo[i]), hi_i = rnd₃₂(ampc.domain_hi[i])
//! clamp       Clip(y_j, lo_j, hi_j)  dropped ⇔ lo_j = ampc.clamp_lo[j], hi_j = ampc.clamp_hi[j],
//!                                              and [lo_j, hi_j] ⊇ [ampc.u_lo[j], ampc.u_hi[j]]
//! ```
//! (the band's containment of U up to the exporter's own f32 rounding of a bound of U that
//! has no f32: one f32 step.)
//! (`rnd₃₂`: the f32 next to the value, below or above, as the exporter rounds the domain.)
//! Dropping is exact then: the projection is the identity on X, and a clamp to a band
//! containing U_d ∋ κ_MPC(x) never moves κ_NN(x) away from κ_MPC(x). Any other Clip changes
//! the function (an edited clamp of ±0.5 makes the file compute another controller than the
//! unclipped net); a dense MLP cannot hold it, so the file is refused naming the node and
//! its bounds.

use super::graph::{Node, OnnxModel, Tensor};
use std::collections::{HashMap, HashSet};
use std::ops::RangeInclusive;

/// Default-domain (`ai.onnx`) opsets whose semantics of the operators read here
/// (numpy broadcasting of Add/Sub/Mul/Div and Gemm's C since opset 7; Clip's bounds as
/// inputs since 11, as attributes before) the importer implements.
pub const SUPPORTED_OPSETS: RangeInclusive<i64> = 7..=22;

type R<T> = Result<T, String>;

/// The file's default-domain opset, or an error naming what is missing or unsupported.
pub fn default_opset(m: &OnnxModel) -> R<i64> {
    let default: Vec<i64> = m
        .opsets
        .iter()
        .filter(|(d, _)| d.is_empty() || d == "ai.onnx")
        .map(|o| o.1)
        .collect();
    let listed = || {
        m.opsets
            .iter()
            .map(|(d, v)| format!("'{d}' {v}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    match default.as_slice() {
        [] => Err(format!(
            "opset_import has no default-domain (ai.onnx) entry (it lists: {}); the operators' \
             versions are unknown",
            listed()
        )),
        [v] if SUPPORTED_OPSETS.contains(v) => Ok(*v),
        [v] => Err(format!(
            "default-domain opset {v} is not supported (supported: {}–{})",
            SUPPORTED_OPSETS.start(),
            SUPPORTED_OPSETS.end()
        )),
        _ => Err(format!(
            "opset_import names the default domain {} times ({}); one version is expected",
            default.len(),
            listed()
        )),
    }
}

/// The initializers by name; a name given twice is an error naming it (which of the two
/// a node would read is not defined).
pub fn initializers(m: &OnnxModel) -> R<HashMap<String, Tensor>> {
    let mut seen = HashSet::new();
    for t in &m.initializers {
        if !seen.insert(t.name.as_str()) {
            return Err(format!(
                "initializer '{}' is defined twice (tensor names must be unique)",
                t.name
            ));
        }
    }
    Ok(m.initializers
        .iter()
        .map(|t| (t.name.clone(), t.clone()))
        .collect())
}

/// Which end of the chain a Clip is at.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    /// Before the first layer: the projection onto X.
    Projection,
    /// After the last layer: the output clamp.
    Clamp,
}

/// One Clip of an ampc export, as found in the graph.
#[derive(Debug, Clone, PartialEq)]
pub struct Clip {
    /// Its node, as named in messages.
    pub label: String,
    /// Which end.
    pub side: Side,
    /// The component it clips (`None`: all, with scalar bounds).
    pub component: Option<usize>,
    /// Lower bound (−∞ when absent).
    pub lo: f64,
    /// Upper bound (+∞ when absent).
    pub hi: f64,
    /// Number of chain steps before it (a clamp must stay at the end).
    pub at_step: usize,
}

/// The bounds of a Clip node: inputs 2 and 3 (opset ≥ 11) or attributes `min`/`max`
/// (earlier opsets); `constant` resolves an input name to a constant tensor.
pub fn clip_bounds(
    n: &Node,
    label: &str,
    constant: impl Fn(&str) -> Option<Tensor>,
) -> R<(f64, f64)> {
    let bound = |i: usize, attr: &str, none: f64| -> R<f64> {
        if let Some(name) = n.inputs.get(i).filter(|s| !s.is_empty()) {
            let t = constant(name)
                .ok_or_else(|| format!("{label}: bound '{name}' is not a constant"))?;
            return match t.values.as_slice() {
                [v] => Ok(*v),
                v => Err(format!(
                    "{label}: bound '{name}' has {} values (a scalar expected)",
                    v.len()
                )),
            };
        }
        Ok(n.attr(attr).and_then(|a| a.f).map_or(none, f64::from))
    };
    Ok((
        bound(1, "min", f64::NEG_INFINITY)?,
        bound(2, "max", f64::INFINITY)?,
    ))
}

/// A metadata list `[a, b, …]` of numbers, or an error naming the key.
fn meta_list(m: &OnnxModel, key: &str, n: usize) -> R<Vec<f64>> {
    let v = m
        .meta(key)
        .ok_or_else(|| format!("metadata '{key}' is missing (needed to check the Clip nodes)"))?;
    let inner = v
        .trim()
        .strip_prefix('[')
        .and_then(|s| s.strip_suffix(']'))
        .ok_or_else(|| format!("metadata '{key}' = '{v}' is not a list"))?;
    let vals: Vec<f64> = inner
        .split(',')
        .filter(|s| !s.trim().is_empty())
        .map(|s| s.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("metadata '{key}' = '{v}' is not a list of numbers"))?;
    if vals.len() != n {
        return Err(format!(
            "metadata '{key}' has {} values for {n} components",
            vals.len()
        ));
    }
    Ok(vals)
}

/// Whether `b` (an f32 bound widened to f64) is `v` or one of the two f32 next to it.
fn f32_rounding_of(b: f64, v: f64) -> bool {
    if b == v {
        return true;
    }
    let c = v as f32;
    let down = if f64::from(c) > v { c.next_down() } else { c };
    let up = if f64::from(c) < v { c.next_up() } else { c };
    b == f64::from(down) || b == f64::from(up)
}

/// Checks every Clip found against the metadata (module doc); `steps` is the chain's length,
/// `nx`, `nu` the network's dimensions. The error names the node, its bounds and the
/// metadata's.
pub fn check(m: &OnnxModel, clips: &[Clip], steps: usize, nx: usize, nu: usize) -> R<()> {
    if clips.is_empty() {
        return Ok(());
    }
    let has = |s: Side| clips.iter().any(|c| c.side == s);
    let domain = if has(Side::Projection) {
        Some((
            meta_list(m, "ampc.domain_lo", nx)?,
            meta_list(m, "ampc.domain_hi", nx)?,
        ))
    } else {
        None
    };
    let band = if has(Side::Clamp) {
        let (lo, hi) = (
            meta_list(m, "ampc.clamp_lo", nu)?,
            meta_list(m, "ampc.clamp_hi", nu)?,
        );
        let (ulo, uhi) = (
            meta_list(m, "ampc.u_lo", nu)?,
            meta_list(m, "ampc.u_hi", nu)?,
        );
        let parts = lo.iter().zip(&hi).zip(ulo.iter().zip(&uhi));
        for (j, ((&l, &h), (&ul, &uh))) in parts.enumerate() {
            // The exporter keeps the band inside the actuator limits, rounding a limit that
            // has no f32 inward: a bound one f32 step inside U is the exporter's own.
            // (NaN compares false: a NaN bound is refused here too.)
            let below = l <= ul || f32_rounding_of(l, ul);
            let above = uh <= h || f32_rounding_of(h, uh);
            if !(below && above) {
                return Err(format!(
                    "metadata: clamp band u{} ∈ [{l}, {h}] does not contain U = [{ul}, {uh}] \
                     (ampc.clamp_lo/hi, ampc.u_lo/hi): the clamp would change the certified \
                     controller",
                    j + 1
                ));
            }
        }
        Some((lo, hi))
    } else {
        None
    };
    for c in clips {
        let (want, n, what, exact) = match c.side {
            Side::Projection => (
                domain.as_ref(),
                nx,
                "the domain X (ampc.domain_lo/hi)",
                false,
            ),
            Side::Clamp => {
                if c.at_step != steps {
                    return Err(format!(
                        "{}: a Clip between the layers (only the projection onto X before the \
                         first layer and the output clamp after the last are supported)",
                        c.label
                    ));
                }
                (band.as_ref(), nu, "the clamp band (ampc.clamp_lo/hi)", true)
            }
        };
        let (lo, hi) = want.expect("loaded above for each side present");
        let comps: Vec<usize> = match c.component {
            Some(k) if k < n => vec![k],
            Some(k) => {
                return Err(format!(
                    "{}: clips component {} of a {n}-component value",
                    c.label,
                    k + 1
                ))
            }
            None => (0..n).collect(),
        };
        for k in comps {
            let same = |b: f64, v: f64| if exact { b == v } else { f32_rounding_of(b, v) };
            if !(same(c.lo, lo[k]) && same(c.hi, hi[k])) {
                return Err(format!(
                    "{}: Clip to [{}, {}] on component {}, but {what} is [{}, {}]: an edited \
                     Clip changes the function (a dense MLP cannot hold it), so the file is \
                     refused",
                    c.label,
                    c.lo,
                    c.hi,
                    k + 1,
                    lo[k],
                    hi[k]
                ));
            }
        }
    }
    Ok(())
}
