//! The tier of the exported certificate ([`Guarantee`]): sound, statistical or estimated.
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

/// How strong the claim |κ − u_f32| ≤ ε on X is; ordered strongest first.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Guarantee {
    /// Every ingredient is a proven bound.
    Sound,
    /// An ingredient holds with a stated probability.
    Statistical,
    /// An ingredient is a sampled estimate (the weakest tier, and the default).
    #[default]
    Estimated,
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
        Ok(())
    }

    /// The claim in words, for the generated files.
    pub fn words(&self) -> String {
        format!(
            "P(‖κ − u‖ > ε) ≤ {:.3e} with confidence {} (Clopper–Pearson, {} i.i.d. uniform states of X)",
            self.p_exceed_upper, self.confidence, self.samples
        )
    }
}

impl Guarantee {
    /// Every tier, strongest first (the C header's enum values are the indices).
    pub const ALL: [Guarantee; 3] = [
        Guarantee::Sound,
        Guarantee::Statistical,
        Guarantee::Estimated,
    ];

    /// The key's value in JSON: `sound`, `statistical`, `estimated`.
    pub fn name(self) -> &'static str {
        match self {
            Guarantee::Sound => "sound",
            Guarantee::Statistical => "statistical",
            Guarantee::Estimated => "estimated",
        }
    }

    /// The variant of `controller_core::Guarantee`.
    pub fn rust_name(self) -> &'static str {
        match self {
            Guarantee::Sound => "Sound",
            Guarantee::Statistical => "Statistical",
            Guarantee::Estimated => "Estimated",
        }
    }

    /// The tier the exported function supports at most: `estimated` for a placeholder
    /// network, `statistical` for a statistical ε (it rests on no Lipschitz constant),
    /// `sound` otherwise (the certificate's own tier then decides).
    pub fn supported(placeholder: bool, statistical: bool) -> Self {
        if placeholder {
            Guarantee::Estimated
        } else if statistical {
            Guarantee::Statistical
        } else {
            Guarantee::Sound
        }
    }

    /// The weaker of the two tiers.
    pub fn weakest(self, other: Guarantee) -> Self {
        self.max(other)
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
        assert_eq!(Guarantee::supported(false, false), Guarantee::Sound);
        assert_eq!(Guarantee::supported(false, true), Guarantee::Statistical);
        assert_eq!(Guarantee::supported(true, false), Guarantee::Estimated);
        assert_eq!(
            Guarantee::Sound.weakest(Guarantee::Estimated),
            Guarantee::Estimated
        );
        assert_eq!(Guarantee::default(), Guarantee::Estimated);
    }
}
