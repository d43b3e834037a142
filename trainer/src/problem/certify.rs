//! `[certify]`: the tiers `trainer run` adds after Theorem 1 — the statistical tier's sample
//! size, confidence and probability target, and the closed loop's statistical tier.
//!
//! The default sample size is the smallest n for which zero exceedances give the
//! Clopper–Pearson bound P(‖κ − κ̂‖ > ε) ≤ p at confidence 1 − β:
//!
//! ```text
//! 1 − β^{1/n} ≤ p   ⇔   n ≥ ln β / ln(1 − p),   n = ⌈ln 0.01 / ln(1 − 10⁻³)⌉ = 4603
//! ```

use serde::{Deserialize, Serialize};

/// n = ⌈ln β / ln(1 − p)⌉ for β = 0.01, p = 10⁻³ (module doc).
pub const DEFAULT_STATISTICAL: usize = 4603;

/// The statistical tiers of `trainer run` (`[certify]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CertifySettings {
    /// n: i.i.d. uniform states of X on which the deployed controller is tested (default
    /// 4603, sized for P ≤ 1e-3 at 99 % with zero exceedances; 0 = no statistical tier).
    pub statistical: usize,
    /// Confidence 1 − β of the statistical bounds (default 0.99).
    pub confidence: f64,
    /// Probability target p of the statistical level ε_p (default 1e-3).
    pub p_target: f64,
    /// Closed loops of the deployed controller from i.i.d. uniform MPC-feasible starts for
    /// the closed-loop statistical statement (default 4603; 0 = none). Run when the
    /// exported band is statistical.
    pub closed_loop: usize,
    /// Seed of the statistical states and starts, mixed with the model's hash (default
    /// 0x53544154, the CLI's `--statistical-seed` default).
    pub seed: u64,
}

impl Default for CertifySettings {
    fn default() -> Self {
        CertifySettings {
            statistical: DEFAULT_STATISTICAL,
            confidence: 0.99,
            p_target: 1e-3,
            closed_loop: DEFAULT_STATISTICAL,
            seed: 0x5354_4154,
        }
    }
}

impl CertifySettings {
    /// Whether these are the default settings (then not serialised).
    pub fn is_default(&self) -> bool {
        *self == Self::default()
    }

    /// Checks the numbers; the error names the key.
    pub fn validate(&self) -> Result<(), super::ConfigError> {
        if !(self.confidence > 0.0 && self.confidence < 1.0) {
            return Err(super::invalid(
                "certify.confidence",
                format!("must lie in (0, 1), got {}", self.confidence),
            ));
        }
        if !(self.p_target > 0.0 && self.p_target < 1.0) {
            return Err(super::invalid(
                "certify.p_target",
                format!("must lie in (0, 1), got {}", self.p_target),
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_default_sample_size_is_the_smallest_for_p_1e3_at_99_percent() {
        let n = super::DEFAULT_STATISTICAL as u64;
        // Zero exceedances of n: the Clopper–Pearson bound is 1 − β^{1/n}.
        let cp = |n: u64| 1.0 - 0.01f64.powf(1.0 / n as f64);
        assert!(cp(n) <= 1e-3, "{}", cp(n));
        assert!(cp(n - 1) > 1e-3, "{}", cp(n - 1));
    }
}
