//! The tier of the exported certificate ([`Guarantee`]): sound, statistical or estimated.
//!
//! tier = the weaker of (what the learning side's certificate declares in its `"guarantee"`
//! key, if it has one) and (what its numbers rest on: `estimated` when L_MPC is a sampled
//! estimate, `l_mpc_is_estimate`, or the network is the untrained placeholder; `sound`
//! otherwise — ε_D is a maximum over the data, L_NN and r are sound upper bounds). A claim
//! is never rounded up: a declaration stronger than the numbers allow is lowered.
//!
//! **A statistical ε** ([`StatisticalClaim`], `trainer export --statistical-band`): ε is the
//! level ε_p of the certificate's `"statistical"` block (the (k*+1)-th largest of n i.i.d.
//! errors, k* the largest count whose Clopper–Pearson bound is ≤ p): with confidence 1 − β
//! over the draw of the states, P(‖κ − sat κ_NN‖ > ε_p) ≤ p (the exceedance probability of
//! an order statistic is Beta(k*+1, n−k*) distributed). It rests on no Lipschitz constant,
//! so its tier is `statistical` whatever L_MPC is — never `sound`.

use serde::{Deserialize, Serialize};

use super::ExportError;

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

    /// The tier the numbers support without a declaration (module doc).
    pub fn derived(l_mpc_is_estimate: bool, placeholder: bool) -> Self {
        if l_mpc_is_estimate || placeholder {
            Guarantee::Estimated
        } else {
            Guarantee::Sound
        }
    }

    /// The tier the numbers support: `estimated` for a placeholder network, `statistical`
    /// for a statistical ε (it rests on no Lipschitz constant), else [`Guarantee::derived`].
    pub fn supported(l_mpc_is_estimate: bool, placeholder: bool, statistical: bool) -> Self {
        if placeholder {
            Guarantee::Estimated
        } else if statistical {
            Guarantee::Statistical
        } else {
            Guarantee::derived(l_mpc_is_estimate, false)
        }
    }

    /// The weaker of the two tiers.
    pub fn weakest(self, other: Guarantee) -> Self {
        self.max(other)
    }

    /// The `"guarantee"` a certificate JSON declares: `None` without the key, an error
    /// naming `file` for a value that is not one of the tiers.
    pub fn declared_in(json: &str, file: &str) -> Result<Option<Self>, ExportError> {
        let v: serde_json::Value = serde_json::from_str(json)
            .map_err(|e| ExportError::Invalid(format!("{file}: not JSON: {e}")))?;
        match v.get("guarantee") {
            None | Some(serde_json::Value::Null) => Ok(None),
            Some(g) => Guarantee::ALL
                .into_iter()
                .find(|t| g.as_str() == Some(t.name()))
                .map(Some)
                .ok_or_else(|| {
                    ExportError::Invalid(format!(
                        "{file}: key \"guarantee\" is {g}, expected \"sound\", \"statistical\" \
                         or \"estimated\""
                    ))
                }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn declared_tier_is_read_and_never_raised() {
        let d = |s: &str| Guarantee::declared_in(s, "c.json");
        assert_eq!(d(r#"{"eps": 1.0}"#).unwrap(), None);
        assert_eq!(
            d(r#"{"guarantee": "statistical"}"#).unwrap(),
            Some(Guarantee::Statistical)
        );
        let e = d(r#"{"guarantee": "proven"}"#).unwrap_err().to_string();
        assert!(e.contains("c.json") && e.contains("guarantee"), "{e}");
        // A sampled L_MPC caps any declaration at `estimated`.
        let from_numbers = Guarantee::derived(true, false);
        assert_eq!(Guarantee::Sound.weakest(from_numbers), Guarantee::Estimated);
        assert_eq!(
            Guarantee::Statistical.weakest(Guarantee::derived(false, false)),
            Guarantee::Statistical
        );
        assert_eq!(Guarantee::derived(false, true), Guarantee::Estimated);
        assert_eq!(Guarantee::default(), Guarantee::Estimated);
    }
}
