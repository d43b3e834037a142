//! `controller`: the safe evaluation `x ↦ u` around the network, with its flags.
//!
//! ```text
//! evaluate(x):
//!   any x_i NaN/±inf           → u = fallback,                       flags = NON_FINITE
//!   x_p = Π_X(x)  (per axis)   → flag OUT_OF_DOMAIN if x_p ≠ x
//!   x_p in an excluded box     → flag EXCLUDED   (u computed as below all the same)
//!   y   = κ_NN(x_p)            (network in physical units, see below)
//!   y_j NaN                    → u_j = fallback_j,                   flag NON_FINITE
//!   u_j = clamp(y_j, clamp_lo_j, clamp_hi_j) → flag CLAMPED if u_j ≠ y_j
//! ```
//! X = `[x_lo, x_hi]` is the certified box; the band `[clamp_lo, clamp_hi]` is
//! `(U_d ⊕ [−ε, ε]) ∩ actuator limits`, rounded by the exporter so that it contains U_d and
//! lies inside the actuator limits. Since κ(x) ∈ U_d and |κ − κ_NN,f32| ≤ ε on X, the clamp
//! never increases the error and `u` is always finite and admissible.
//!
//! **Excluded boxes.** A certificate may cover X minus some boxes (cells outside the MPC's
//! feasible set, `refine.exclude_infeasible`; [`crate::Certificate::excluded`]); a state
//! in one (closed box, bounds rounded outward by the exporter) is flagged `EXCLUDED`: `u` is
//! still finite and inside the band, but ε does not cover it.
//!
//! **Scaling.** The trainer normalises inputs and outputs (`x̃ = (x − m_x)/s_x`,
//! `u = m_u + s_u ũ`). The exporter folds both affine maps into the first and the last
//! layer, so the network here takes physical states and returns physical inputs; the
//! rounding of the folded weights is part of the certified f32 allowance.

use crate::mlp::Network;

/// Bit set of conditions met during one evaluation.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Flags(pub u8);

impl Flags {
    /// No condition: the state was inside X and the output inside the band.
    pub const EMPTY: Flags = Flags(0);
    /// The state was outside X and was projected onto it (the certificate covers the
    /// projected state, not the measured one).
    pub const OUT_OF_DOMAIN: Flags = Flags(1);
    /// A state component (or the network output) was NaN/±inf; `u` is the fallback.
    pub const NON_FINITE: Flags = Flags(2);
    /// The network output was outside the clamp band and was clamped.
    pub const CLAMPED: Flags = Flags(4);
    /// The (projected) state lies in a box excluded from the certified domain (outside the
    /// MPC's feasible set as the certificate estimates it): ε does not cover this state.
    pub const EXCLUDED: Flags = Flags(8);

    /// Whether every flag in `other` is set.
    ///
    /// ```
    /// use controller_core::Flags;
    /// assert!(Flags(5).contains(Flags::CLAMPED));
    /// ```
    pub const fn contains(self, other: Flags) -> bool {
        self.0 & other.0 == other.0
    }

    /// The union of both sets.
    pub const fn union(self, other: Flags) -> Flags {
        Flags(self.0 | other.0)
    }
}

/// Result of [`Controller::evaluate`]: an admissible input and what happened.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Output<const NU: usize> {
    /// The input to apply (always finite, always inside the clamp band).
    pub u: [f32; NU],
    /// Conditions met on the way.
    pub flags: Flags,
}

/// Why a set of controller parameters is not usable.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InvalidController {
    /// A bound, weight or fallback is NaN or infinite.
    NonFinite,
    /// A lower bound exceeds its upper bound (domain or clamp band).
    EmptyBox,
    /// The fallback input is outside the clamp band.
    FallbackOutsideBand,
}

/// The deployed controller: network, certified domain, clamp band and fallback.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Controller<const NX: usize, const NU: usize, N> {
    /// κ_NN in physical units (scalings folded in).
    pub net: N,
    /// Lower corner of X (f32, rounded outward by the exporter).
    pub x_lo: [f32; NX],
    /// Upper corner of X (f32, rounded outward by the exporter).
    pub x_hi: [f32; NX],
    /// Lower end of the clamp band.
    pub clamp_lo: [f32; NU],
    /// Upper end of the clamp band.
    pub clamp_hi: [f32; NU],
    /// Input returned for a non-finite state (default: centre of U_d).
    pub fallback: [f32; NU],
    /// Boxes (lower, upper corner) of X excluded from the certified domain; a state in one
    /// is flagged [`Flags::EXCLUDED`]. Empty unless the certificate excludes cells.
    pub excluded: &'static [([f32; NX], [f32; NX])],
}

const fn all_finite(mut s: &[f32]) -> bool {
    while let [a, rest @ ..] = s {
        if !a.is_finite() {
            return false;
        }
        s = rest;
    }
    true
}

const fn ordered(mut lo: &[f32], mut hi: &[f32]) -> bool {
    while let ([a, ra @ ..], [b, rb @ ..]) = (lo, hi) {
        if *a > *b {
            return false;
        }
        lo = ra;
        hi = rb;
    }
    true
}

impl<const NX: usize, const NU: usize, N> Controller<NX, NU, N> {
    /// A controller from its parts; check it with [`Controller::validate`] (the generated
    /// weights do so at compile time).
    ///
    /// ```
    /// use controller_core::{Controller, layer::Dense};
    /// const C: Controller<1, 1, Dense<1, 1>> =
    ///     Controller::new(Dense::new([[-2.0]], [0.0]), [-1.0], [1.0], [-1.5], [1.5], [0.0]);
    /// const _: () = assert!(C.validate().is_ok());
    /// assert_eq!(C.evaluate(&[0.5]).u, [-1.0]);
    /// ```
    pub const fn new(
        net: N,
        x_lo: [f32; NX],
        x_hi: [f32; NX],
        clamp_lo: [f32; NU],
        clamp_hi: [f32; NU],
        fallback: [f32; NU],
    ) -> Self {
        Self {
            net,
            x_lo,
            x_hi,
            clamp_lo,
            clamp_hi,
            fallback,
            excluded: &[],
        }
    }

    /// The same controller with `excluded` boxes (the certificate's
    /// [`crate::Certificate::excluded`]): states in them are flagged [`Flags::EXCLUDED`].
    ///
    /// ```
    /// use controller_core::{Controller, Flags, layer::Dense};
    /// const C: Controller<1, 1, Dense<1, 1>> =
    ///     Controller::new(Dense::new([[-2.0]], [0.0]), [-1.0], [1.0], [-1.5], [1.5], [0.0])
    ///         .with_excluded(&[([0.5], [1.0])]);
    /// assert_eq!(C.evaluate(&[0.75]).flags, Flags::EXCLUDED);
    /// assert_eq!(C.evaluate(&[0.25]).flags, Flags::EMPTY);
    /// ```
    pub const fn with_excluded(mut self, excluded: &'static [([f32; NX], [f32; NX])]) -> Self {
        self.excluded = excluded;
        self
    }

    /// Checks the invariants `evaluate` relies on: finite bounds and fallback, non-empty
    /// boxes (the excluded ones too), fallback inside the band. (Weights are checked by the blob decoder; for the
    /// compiled-in weights the exporter guarantees them.)
    pub const fn validate(&self) -> Result<(), InvalidController> {
        if !(all_finite(&self.x_lo)
            && all_finite(&self.x_hi)
            && all_finite(&self.clamp_lo)
            && all_finite(&self.clamp_hi)
            && all_finite(&self.fallback))
        {
            return Err(InvalidController::NonFinite);
        }
        if !(ordered(&self.x_lo, &self.x_hi) && ordered(&self.clamp_lo, &self.clamp_hi)) {
            return Err(InvalidController::EmptyBox);
        }
        if !(ordered(&self.clamp_lo, &self.fallback) && ordered(&self.fallback, &self.clamp_hi)) {
            return Err(InvalidController::FallbackOutsideBand);
        }
        let mut rest = self.excluded;
        while let [(lo, hi), tail @ ..] = rest {
            if !(all_finite(lo) && all_finite(hi)) {
                return Err(InvalidController::NonFinite);
            }
            if !ordered(lo, hi) {
                return Err(InvalidController::EmptyBox);
            }
            rest = tail;
        }
        Ok(())
    }
}

impl<const NX: usize, const NU: usize, N: Network<NX, Output = [f32; NU]>> Controller<NX, NU, N> {
    /// The control input for state `x` (see the module doc). Never panics, never fails:
    /// for a controller that passes [`Controller::validate`], `u` is finite and inside
    /// `[clamp_lo, clamp_hi]` for every bit pattern of `x`.
    #[cfg_attr(feature = "no-panic", no_panic::no_panic)]
    pub fn evaluate(&self, x: &[f32; NX]) -> Output<NU> {
        let mut flags = Flags::EMPTY;
        let mut xp = [0.0f32; NX];
        for (((p, &xi), &lo), &hi) in xp.iter_mut().zip(x).zip(&self.x_lo).zip(&self.x_hi) {
            if !xi.is_finite() {
                return Output {
                    u: self.fallback,
                    flags: Flags::NON_FINITE,
                };
            }
            *p = if xi < lo {
                flags = flags.union(Flags::OUT_OF_DOMAIN);
                lo
            } else if xi > hi {
                flags = flags.union(Flags::OUT_OF_DOMAIN);
                hi
            } else {
                xi
            };
        }
        let inside = |(lo, hi): &([f32; NX], [f32; NX])| {
            xp.iter()
                .zip(lo.iter().zip(hi))
                .all(|(v, (l, h))| *l <= *v && *v <= *h)
        };
        if self.excluded.iter().any(inside) {
            flags = flags.union(Flags::EXCLUDED);
        }
        let y = self.net.forward(&xp);
        let mut u = self.fallback;
        for (((uj, yj), &lo), &hi) in u.iter_mut().zip(y).zip(&self.clamp_lo).zip(&self.clamp_hi) {
            if yj.is_nan() {
                flags = flags.union(Flags::NON_FINITE);
            } else if yj < lo {
                flags = flags.union(Flags::CLAMPED);
                *uj = lo;
            } else if yj > hi {
                flags = flags.union(Flags::CLAMPED);
                *uj = hi;
            } else {
                *uj = yj;
            }
        }
        Output { u, flags }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::layer::Dense;

    const C: Controller<2, 1, Dense<2, 1>> = Controller::new(
        Dense::new([[10.0, 1.0]], [0.0]),
        [-1.0, -2.0],
        [1.0, 2.0],
        [-5.0],
        [5.0],
        [0.25],
    );

    #[test]
    fn flags_follow_the_documented_cases() {
        assert_eq!(C.evaluate(&[0.1, 0.0]).flags, Flags::EMPTY);
        assert_eq!(C.evaluate(&[0.1, 0.0]).u, [1.0]);
        let o = C.evaluate(&[3.0, 0.0]);
        assert_eq!((o.u, o.flags), ([5.0], Flags(Flags::OUT_OF_DOMAIN.0 | 4)));
        let o = C.evaluate(&[-0.2, -2.5]);
        assert_eq!(o.flags, Flags::OUT_OF_DOMAIN);
        assert_eq!(o.u, [-4.0]);
        for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            let o = C.evaluate(&[0.0, bad]);
            assert_eq!((o.u, o.flags), ([0.25], Flags::NON_FINITE));
        }
    }

    #[test]
    fn overflowing_network_output_is_handled() {
        let c = Controller::new(
            Dense::<2, 1>::new([[f32::MAX, f32::MAX]], [0.0]),
            [-2.0, -2.0],
            [2.0, 2.0],
            [-1.0],
            [1.0],
            [0.0],
        );
        let o = c.evaluate(&[1.0, 1.0]); // MAX + MAX = +inf: clamped
        assert_eq!((o.u, o.flags), ([1.0], Flags::CLAMPED));
        let c = Controller {
            net: Dense::<2, 1>::new([[f32::MAX, -f32::MAX]], [0.0]),
            ..c
        };
        let o = c.evaluate(&[2.0, 2.0]); // +inf + (−inf) = NaN: fallback
        assert_eq!((o.u, o.flags), ([0.0], Flags::NON_FINITE));
    }

    #[test]
    fn states_in_excluded_boxes_are_flagged_and_still_answered() {
        const E: Controller<2, 1, Dense<2, 1>> = C.with_excluded(&[([0.5, -2.0], [1.0, 0.0])]);
        // Inside (and on the boundary of) the box: flagged, same u as without the box.
        for x in [[0.75, -1.0], [0.5, 0.0], [1.0, -2.0]] {
            let (o, plain) = (E.evaluate(&x), C.evaluate(&x));
            assert_eq!(o.flags, plain.flags.union(Flags::EXCLUDED), "{x:?}");
            assert_eq!(o.u, plain.u);
        }
        // Outside it: not flagged.
        for x in [[0.25, -1.0], [0.75, 0.5], [-1.0, -2.0]] {
            assert!(!E.evaluate(&x).flags.contains(Flags::EXCLUDED), "{x:?}");
        }
        // A state projected into the box is flagged too (with OUT_OF_DOMAIN).
        let o = E.evaluate(&[5.0, -1.0]);
        assert!(o.flags.contains(Flags::EXCLUDED) && o.flags.contains(Flags::OUT_OF_DOMAIN));
        // Non-finite state: the fallback alone (only NON_FINITE).
        assert_eq!(E.evaluate(&[f32::NAN, 0.0]).flags, Flags::NON_FINITE);
        assert_eq!(E.validate(), Ok(()));
        assert_eq!(
            C.with_excluded(&[([0.5, 0.0], [0.4, 1.0])]).validate(),
            Err(InvalidController::EmptyBox)
        );
        assert_eq!(
            C.with_excluded(&[([f32::NAN, 0.0], [0.4, 1.0])]).validate(),
            Err(InvalidController::NonFinite)
        );
    }

    #[test]
    fn validate_rejects_broken_parameters() {
        assert_eq!(C.validate(), Ok(()));
        let bad = Controller {
            x_lo: [f32::NAN, 0.0],
            ..C
        };
        assert_eq!(bad.validate(), Err(InvalidController::NonFinite));
        let bad = Controller {
            clamp_lo: [6.0],
            ..C
        };
        assert_eq!(bad.validate(), Err(InvalidController::EmptyBox));
        let bad = Controller {
            fallback: [5.5],
            ..C
        };
        assert_eq!(bad.validate(), Err(InvalidController::FallbackOutsideBand));
    }
}
