//! The documented upper limits on the sizes a problem file (or a network) may ask for,
//! checked at the edge: by [`ProblemConfig::validate`](super::ProblemConfig::validate) for the
//! problem file's keys, and by [`check_net`] for a network about to be certified (trained
//! here or imported from ONNX). Each error names the key, the limit and the value.
//!
//! ```text
//! ocp.horizon ≤ 10 000   ocp.rk4_substeps ≤ 10 000   horizon · rk4_substeps ≤ 1 000 000
//! hidden widths ≤ 4 096  hidden layers ≤ 64          certify: Σ hidden units ≤ 2 048
//! ```
//! Why these numbers (generous against every shipped problem, safe on a laptop):
//! - the OCP workspace grows as N·(n_x + n_u)² (stage Hessian blocks, the banded KKT); with
//!   n_x + n_u ≤ 16 a horizon of 10⁴ needs ~25 MB per solver thread, 10⁸ would need 2 GB
//!   before the first solve. Shipped problems use N ≤ 60.
//! - one evaluation of F costs 4·rk4_substeps right-hand sides, N of them per SQP iterate:
//!   N·substeps ≤ 10⁶ keeps an iterate to about a second (shipped problems: ≤ 200).
//! - a hidden layer of width 4 096 after another is 16.8 M weights (134 MB in f64, plus Adam's
//!   two moments); 64 layers are far beyond what the Sobolev training or Theorem 1's
//!   Lipschitz bounds are useful for (shipped nets: 2 layers of ≤ 48).
//! - certification runs LipSDP-Neuron, dense Cholesky factorisations of order
//!   n_x + Σ hidden units, thousands of times: Σ ≤ 2 048 keeps it to minutes, while a
//!   2-2000-2000-1 net (4 000 units) takes many minutes without a word. Bigger nets are
//!   refused at certify time instead of appearing to hang.

use super::{invalid, ConfigError};

/// Largest `ocp.horizon` N.
pub const MAX_HORIZON: usize = 10_000;
/// Largest `ocp.rk4_substeps`.
pub const MAX_RK4_SUBSTEPS: usize = 10_000;
/// Largest `ocp.horizon · ocp.rk4_substeps` (RK4 steps of one prediction).
pub const MAX_PREDICTION_STEPS: usize = 1_000_000;
/// Largest width of a hidden layer (`training.hidden`, `refine.training.hidden`, an
/// imported net).
pub const MAX_HIDDEN_WIDTH: usize = 4_096;
/// Largest number of hidden layers.
pub const MAX_HIDDEN_LAYERS: usize = 64;
/// Largest total number of hidden units of a network that `certify` accepts.
pub const MAX_CERTIFY_HIDDEN_UNITS: usize = 2_048;

/// `ocp.horizon` and `ocp.rk4_substeps` against their limits.
pub(super) fn check_ocp_sizes(horizon: usize, substeps: usize) -> Result<(), ConfigError> {
    if horizon > MAX_HORIZON {
        return Err(invalid(
            "ocp.horizon",
            format!("at most {MAX_HORIZON} (documented limit), got {horizon}"),
        ));
    }
    if substeps > MAX_RK4_SUBSTEPS {
        return Err(invalid(
            "ocp.rk4_substeps",
            format!("at most {MAX_RK4_SUBSTEPS} (documented limit), got {substeps}"),
        ));
    }
    if horizon * substeps > MAX_PREDICTION_STEPS {
        return Err(invalid(
            "ocp.rk4_substeps",
            format!(
                "horizon × rk4_substeps at most {MAX_PREDICTION_STEPS} (documented limit), \
                 got {horizon} × {substeps} = {}",
                horizon * substeps
            ),
        ));
    }
    Ok(())
}

/// A hidden-layer list (`key` = `training.hidden`, …) against the width and layer limits.
pub(super) fn check_hidden(key: &str, hidden: &[usize]) -> Result<(), ConfigError> {
    if hidden.len() > MAX_HIDDEN_LAYERS {
        return Err(invalid(
            key,
            format!(
                "at most {MAX_HIDDEN_LAYERS} hidden layers (documented limit), got {}",
                hidden.len()
            ),
        ));
    }
    if let Some(i) = hidden.iter().position(|&w| w > MAX_HIDDEN_WIDTH) {
        return Err(invalid(
            format!("{key}[{i}]"),
            format!(
                "at most {MAX_HIDDEN_WIDTH} units per layer (documented limit), got {}",
                hidden[i]
            ),
        ));
    }
    Ok(())
}

/// A network too large for a stage (the limits of the module doc).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "the network ({shape}) is too large to certify: {what} (documented limit {limit}, got {got})"
)]
pub struct NetTooLarge {
    /// The layer widths, `2-16-16-1`.
    pub shape: String,
    /// Which limit.
    pub what: String,
    /// The limit.
    pub limit: usize,
    /// The network's value.
    pub got: usize,
}

/// Whether a network of layer widths `widths` (inputs, hidden…, outputs) is within the
/// limits for certification: hidden layers, their widths, and their total.
pub fn check_net(widths: &[usize]) -> Result<(), NetTooLarge> {
    let hidden = widths.get(1..widths.len().saturating_sub(1)).unwrap_or(&[]);
    let shape = || {
        if widths.len() > 12 {
            format!(
                "{}-…-{} ({} layers)",
                widths[0],
                widths[widths.len() - 1],
                widths.len()
            )
        } else {
            widths
                .iter()
                .map(|w| w.to_string())
                .collect::<Vec<_>>()
                .join("-")
        }
    };
    let err = |what: &str, limit, got| NetTooLarge {
        shape: shape(),
        what: what.into(),
        limit,
        got,
    };
    if hidden.len() > MAX_HIDDEN_LAYERS {
        return Err(err("hidden layers", MAX_HIDDEN_LAYERS, hidden.len()));
    }
    if let Some(&w) = hidden.iter().find(|&&w| w > MAX_HIDDEN_WIDTH) {
        return Err(err("units in a hidden layer", MAX_HIDDEN_WIDTH, w));
    }
    let total: usize = hidden.iter().sum();
    if total > MAX_CERTIFY_HIDDEN_UNITS {
        return Err(err(
            "hidden units in total (LipSDP's matrices grow with them)",
            MAX_CERTIFY_HIDDEN_UNITS,
            total,
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn limits_name_the_key_the_limit_and_the_value() {
        assert!(check_ocp_sizes(MAX_HORIZON, 1).is_ok());
        let e = check_ocp_sizes(100_000_000, 1).unwrap_err().to_string();
        assert!(
            e.contains("ocp.horizon") && e.contains("10000") && e.contains("100000000"),
            "{e}"
        );
        let e = check_ocp_sizes(20, 10_000_000_000).unwrap_err().to_string();
        assert!(
            e.contains("ocp.rk4_substeps") && e.contains("10000000000"),
            "{e}"
        );
        let e = check_ocp_sizes(1000, 5000).unwrap_err().to_string();
        assert!(e.contains("5000000"), "{e}");
        let e = check_hidden("training.hidden", &[100_000_000])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("training.hidden[0]") && e.contains("100000000"),
            "{e}"
        );
        assert!(check_hidden("training.hidden", &[8; 65]).is_err());
        assert!(check_hidden("training.hidden", &[4096, 16]).is_ok());
    }

    #[test]
    fn certify_refuses_nets_beyond_the_limits() {
        assert!(check_net(&[2, 16, 16, 1]).is_ok());
        let e = check_net(&[2, 2000, 2000, 1]).unwrap_err();
        assert_eq!((e.limit, e.got), (MAX_CERTIFY_HIDDEN_UNITS, 4000));
        assert!(e.to_string().contains("2-2000-2000-1"), "{e}");
        let mut deep = vec![2];
        deep.extend(vec![4; 3000]);
        deep.push(1);
        let e = check_net(&deep).unwrap_err();
        assert_eq!((e.limit, e.got), (MAX_HIDDEN_LAYERS, 3000));
    }
}
