//! The tier of the exported certificate: `controller_core::Guarantee` (sound, statistical or
//! estimated; the device crate's type, so the generated files and the exporter name the same
//! enum), the export's rules on it, and its serde form ([`GuaranteeDef`]).
//!
//! tier = the certificate's `"guarantee"`, as decided in `certify/` from the tiers of its
//! terms (`certify::file::CertificateFile`, which refuses a file without the key, without
//! its checksum, or whose tier is stronger than its terms support). Export copies it
//! ([`ExportModel::with_certificate_tier`]) and never recomputes or raises it; the only
//! rules applied here are those of the exported function itself: a placeholder network is
//! `estimated`, a statistical level is `statistical` (never `sound`). An [`ExportModel`]
//! made from a certificate without its tier (`from_certified`) is `estimated`.
//!
//! **A statistical ε** ([`StatisticalClaim`], `trainer export --statistical-band`): ε is the
//! level ε_p of the certificate's `"statistical"` block (the (k*+1)-th largest of n i.i.d.
//! errors, k* the largest count whose Clopper–Pearson bound is ≤ p): with confidence 1 − β
//! over the draw of the states, P(‖κ − sat κ_NN‖ > ε_p) ≤ p (the exceedance probability of
//! an order statistic is Beta(k*+1, n−k*) distributed). It rests on no Lipschitz constant,
//! so its tier is `statistical` whatever L_MPC is — never `sound`.

use serde::{Deserialize, Serialize};

use super::{ExportError, ExportModel};
use crate::certify::tier::Tier;

pub use controller_core::Guarantee;

/// The serde form of [`Guarantee`] (`#[serde(with = "GuaranteeDef")]`): a unit variant named
/// `sound`, `statistical` or `estimated`, variant indices in that order (serde's remote
/// derive over the device crate's enum, which has no serde derive of its own).
#[derive(Serialize, Deserialize)]
#[serde(remote = "Guarantee", rename_all = "snake_case")]
pub enum GuaranteeDef {
    /// Every ingredient is a proven bound.
    Sound,
    /// An ingredient holds with a stated probability.
    Statistical,
    /// An ingredient is a sampled estimate.
    Estimated,
}

/// The tier a model has until a certificate says otherwise: the weakest, `estimated`.
pub fn default_guarantee() -> Guarantee {
    Guarantee::Estimated
}

/// The tier the exported function supports at most: `estimated` for a placeholder network,
/// `statistical` for a statistical ε (it rests on no Lipschitz constant), `sound` otherwise
/// (the certificate's own tier then decides).
pub fn supported_guarantee(placeholder: bool, statistical: bool) -> Guarantee {
    if placeholder {
        Guarantee::Estimated
    } else if statistical {
        Guarantee::Statistical
    } else {
        Guarantee::Sound
    }
}

/// The variant's Rust path segment in a generated `weights.rs` (`Guarantee::<this>`).
pub fn rust_name(g: Guarantee) -> &'static str {
    match g {
        Guarantee::Sound => "Sound",
        Guarantee::Statistical => "Statistical",
        Guarantee::Estimated => "Estimated",
    }
}

/// What a statistical ε rests on (module doc): P(‖κ − sat κ_NN‖ > ε) ≤ `p_exceed_upper`
/// with confidence `confidence`, from `samples` i.i.d. uniform states of X.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StatisticalClaim {
    /// Upper bound p on the probability that a uniform state's error exceeds ε.
    pub p_exceed_upper: f64,
    /// 1 − β.
    pub confidence: f64,
    /// n: the i.i.d. uniform states.
    pub samples: u64,
    /// Set when the claim is conditional on MPC-feasible states (the draw had states where
    /// the MPC's hard problem has no solution — unlabelled, or labelled only by the soft
    /// problem; `samples` then counts the feasible ones): P(a uniform state of X is not
    /// MPC-feasible) ≤ this, its own Clopper–Pearson bound at the same confidence (the name
    /// is kept from the format's first version). `None`: the claim is over every state of X.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unlabelled_p_upper: Option<f64>,
}

impl StatisticalClaim {
    /// Checks p ∈ (0, 1], 1 − β ∈ (0, 1), n ≥ 1; the message names the field.
    pub fn validate(&self) -> Result<(), ExportError> {
        let bad = |m: String| Err(ExportError::Invalid(m));
        if !(self.p_exceed_upper > 0.0 && self.p_exceed_upper <= 1.0) {
            return bad(format!(
                "statistical.p_exceed_upper must lie in (0, 1], got {}",
                self.p_exceed_upper
            ));
        }
        if !(self.confidence > 0.0 && self.confidence < 1.0) {
            return bad(format!(
                "statistical.confidence must lie in (0, 1), got {}",
                self.confidence
            ));
        }
        if self.samples == 0 {
            return bad("statistical.samples must be at least 1".into());
        }
        if let Some(q) = self.unlabelled_p_upper {
            if !(0.0..=1.0).contains(&q) {
                return bad(format!(
                    "statistical.unlabelled_p_upper must lie in [0, 1], got {q}"
                ));
            }
        }
        Ok(())
    }

    /// The claim in words, for the generated files: conditional on MPC-feasible states when
    /// it is ([`StatisticalClaim::unlabelled_p_upper`]), with the unlabelled share's bound.
    pub fn words(&self) -> String {
        match self.unlabelled_p_upper {
            None => format!(
                "P(‖κ − u‖ > ε) ≤ {:.3e} with confidence {} (Clopper–Pearson, {} i.i.d. uniform states of X)",
                self.p_exceed_upper, self.confidence, self.samples
            ),
            Some(q) => format!(
                "P(‖κ − u‖ > ε | the MPC has a solution at x) ≤ {:.3e} with confidence {} \
                 (Clopper–Pearson, {} i.i.d. uniform states of X where the MPC's hard problem \
                 is feasible): conditional on MPC-feasible states; a uniform state of X is not \
                 MPC-feasible (unlabelled, or only the soft problem solved) with P ≤ {:.3e} \
                 (its own Clopper–Pearson bound), where the claim says nothing",
                self.p_exceed_upper, self.confidence, self.samples, q
            ),
        }
    }
}

impl From<Tier> for Guarantee {
    /// The certificate's tier as the export names it (the same three, the same order).
    fn from(t: Tier) -> Self {
        match t {
            Tier::Sound => Guarantee::Sound,
            Tier::Statistical => Guarantee::Statistical,
            Tier::Estimated => Guarantee::Estimated,
        }
    }
}

impl ExportModel {
    /// This model with the certificate's tier (`certify::file::CertificateFile::tier`):
    /// copied as it is, up or down — the certificate decided it.
    pub fn with_certificate_tier(mut self, tier: Guarantee) -> Self {
        self.guarantee = tier;
        self
    }

    /// This model with the certificate's tier and what it rests on (`assumptions`, then
    /// `premises`): the tier copied as [`ExportModel::with_certificate_tier`] does, the
    /// reasons into [`ExportModel::rests_on`] so every exported file says them.
    pub fn with_certificate_guarantee(self, g: &crate::certify::tier::Guarantee) -> Self {
        let mut m = self.with_certificate_tier(g.guarantee.into());
        m.rests_on = g.rests_on();
        m
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_certificate_tier_is_copied_and_only_the_function_caps_it() {
        assert_eq!(Guarantee::from(Tier::Sound), Guarantee::Sound);
        assert_eq!(Guarantee::from(Tier::Statistical), Guarantee::Statistical);
        assert_eq!(Guarantee::from(Tier::Estimated), Guarantee::Estimated);
        assert_eq!(supported_guarantee(false, false), Guarantee::Sound);
        assert_eq!(supported_guarantee(false, true), Guarantee::Statistical);
        assert_eq!(supported_guarantee(true, false), Guarantee::Estimated);
        assert_eq!(
            Guarantee::Sound.weakest(Guarantee::Estimated),
            Guarantee::Estimated
        );
        assert_eq!(default_guarantee(), Guarantee::Estimated);
    }

    /// A claim conditional on MPC-feasible states says so in its words, with the
    /// unlabelled share's bound; an unconditional one does not.
    #[test]
    fn a_conditional_claim_says_it_is_conditional() {
        let mut c = StatisticalClaim {
            p_exceed_upper: 1e-3,
            confidence: 0.99,
            samples: 4500,
            unlabelled_p_upper: None,
        };
        assert!(!c.words().contains("conditional"));
        c.unlabelled_p_upper = Some(0.031);
        let w = c.words();
        assert!(w.contains("conditional on MPC-feasible states"), "{w}");
        assert!(w.contains("| the MPC has a solution at x"), "{w}");
        assert!(w.contains("3.100e-2"), "{w}");
        assert!(c.validate().is_ok());
        c.unlabelled_p_upper = Some(1.5);
        assert!(c.validate().is_err());
    }
}
