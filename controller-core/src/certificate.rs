//! `certificate`: the numbers that travel with the weights (design.md, "Contracts").
//!
//! ε = ε_nn + f32_allowance, where ε_nn bounds ‖κ − κ_NN,f64‖ on X (from the learning
//! side: ε_nn = ε_D + (L_NN + L_MPC)·r, r the covering radius of the data) and
//! `f32_allowance` bounds |κ_NN,f32 − κ_NN,f64| on X for the code that runs (weight
//! rounding, every operation's rounding, the device tanh; computed by the exporter by
//! interval forward error analysis). There is one certificate per tanh implementation;
//! [`crate::demo::CERTIFICATE`] is the one of the compiled-in example.
//!
//! [`Guarantee`] is the tier of the claim: what the arithmetic behind ε proves. The exporter
//! takes it from the learning side's certificate (its `guarantee`, when it states one) and
//! never above what the numbers rest on: a sampled L_MPC makes ε an estimate.

/// How strong the claim |κ(x) − u_f32(x)| ≤ ε on X is (strongest first).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
#[repr(u8)]
pub enum Guarantee {
    /// Every ingredient is a proven bound: ε bounds the error on all of X.
    Sound = 0,
    /// An ingredient holds with a stated probability: ε is a statistical bound.
    Statistical = 1,
    /// An ingredient is a sampled estimate (e.g. L_MPC): ε is an estimate, not a bound.
    Estimated = 2,
}

impl Guarantee {
    /// Every tier, strongest first (index = discriminant = the C API's `AMPC_GUARANTEE_*`).
    pub const ALL: [Guarantee; 3] = [
        Guarantee::Sound,
        Guarantee::Statistical,
        Guarantee::Estimated,
    ];

    /// The tier's name in certificates (`"guarantee"` in `certificate.json`), reports and
    /// generated files: `"sound"`, `"statistical"` or `"estimated"`.
    pub const fn name(self) -> &'static str {
        match self {
            Guarantee::Sound => "sound",
            Guarantee::Statistical => "statistical",
            Guarantee::Estimated => "estimated",
        }
    }

    /// The weaker of the two tiers (a claim resting on both is only as strong as this).
    pub fn weakest(self, other: Guarantee) -> Guarantee {
        if other > self {
            other
        } else {
            self
        }
    }
}

/// A certificate for a controller with `NX` states and `NU` inputs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Certificate<const NX: usize, const NU: usize> {
    /// Total bound ε on |κ(x) − u_f32(x)| for x ∈ X: `eps_nn + f32_allowance`.
    pub eps: f64,
    /// The tier of the claim ε (see [`Guarantee`]).
    pub guarantee: Guarantee,
    /// Bound on ‖κ − κ_NN,f64‖ on X from the learning side (its `eps`).
    pub eps_nn: f64,
    /// Largest training-data error ε_D.
    pub eps_d: f64,
    /// Sound upper bound on the network's Lipschitz constant L_NN.
    pub l_nn: f64,
    /// How `l_nn` was obtained.
    pub l_nn_method: &'static str,
    /// Lipschitz constant of the MPC law L_MPC.
    pub l_mpc: f64,
    /// Whether `l_mpc` is an estimate (sampled) rather than a bound.
    pub l_mpc_is_estimate: bool,
    /// Covering radius r of the data set in X.
    pub covering_radius: f64,
    /// Sound bound on |κ_NN,f32 − κ_NN,f64| on X for this build's tanh.
    pub f32_allowance: f64,
    /// Largest |κ_NN,f32 − κ_NN,f64| seen on the exporter's random states.
    pub f32_observed: f64,
    /// Which tanh the allowance is for (`"libm"`: the default accurate tanh, see
    /// [`crate::activation`]; or `"fast"`).
    pub tanh: &'static str,
    /// The tanh error bound used in the allowance.
    pub tanh_max_abs_err: f64,
    /// Lower corner of the certified domain X.
    pub domain_lo: [f64; NX],
    /// Upper corner of the certified domain X.
    pub domain_hi: [f64; NX],
    /// Boxes of X the certificate does not cover (cells outside the MPC's feasible set,
    /// `refine.exclude_infeasible`; f32, rounded outward): ε holds on X minus them, and the
    /// controller flags states inside them ([`crate::Flags::EXCLUDED`]). Usually empty.
    pub excluded: &'static [([f32; NX], [f32; NX])],
    /// Lower input bound U_d used for the data.
    pub u_lo: [f64; NU],
    /// Upper input bound U_d used for the data.
    pub u_hi: [f64; NU],
    /// Actuator lower limits.
    pub actuator_lo: [f64; NU],
    /// Actuator upper limits.
    pub actuator_hi: [f64; NU],
    /// Lower end of the clamp band `(U_d ⊕ [−ε, ε]) ∩ actuator`, in f32.
    pub clamp_lo: [f32; NU],
    /// Upper end of the clamp band, in f32.
    pub clamp_hi: [f32; NU],
    /// Input returned for a non-finite state.
    pub fallback: [f32; NU],
    /// Content hash of the trained model.
    pub hash: &'static str,
    /// True for the placeholder network (no certificate from the learning side yet).
    pub placeholder: bool,
}

#[cfg(test)]
mod tests {
    use super::Guarantee;

    #[test]
    fn tiers_are_ordered_named_and_indexed_by_discriminant() {
        for (i, g) in Guarantee::ALL.into_iter().enumerate() {
            assert_eq!(g as usize, i);
        }
        let names = Guarantee::ALL.map(Guarantee::name);
        assert_eq!(names, ["sound", "statistical", "estimated"]);
        assert_eq!(
            Guarantee::Sound.weakest(Guarantee::Statistical),
            Guarantee::Statistical
        );
        assert_eq!(
            Guarantee::Estimated.weakest(Guarantee::Sound),
            Guarantee::Estimated
        );
    }
}
