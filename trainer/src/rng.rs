//! Counter-based pseudo-random numbers: `u(seed, a, b) = splitmix64³(seed, a, b) / 2⁵³ ∈ [0, 1)`,
//! and [`FastMod`], exact remainders `a mod d` by multiplication (for shuffles).
//!
//! Every random draw of the trainer (sampling plans, initial weights, sampled bounds,
//! Monte Carlo states) is a pure function of a key, so results do not depend on the order
//! or the thread in which they are drawn. A leaf module: it imports nothing of the crate.

/// SplitMix64: a bijective 64-bit mixing function (Steele, Lea & Flood 2014).
pub fn splitmix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A uniform number in [0, 1) keyed by (seed, a, b).
pub fn uniform(seed: u64, a: u64, b: u64) -> f64 {
    let h = splitmix64(splitmix64(splitmix64(seed) ^ a) ^ b.wrapping_mul(0x2545_F491_4F6C_DD1D));
    (h >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// Exact remainders `a mod d` by a fixed divisor `d ≥ 1` with multiplications instead of a
/// division (Lemire, Kaser & Kurz 2019, "Faster remainder by direct computation", with
/// F = 128 fractional bits for 64-bit numerators: exact for every `a` and `d`):
/// `c = ⌈2¹²⁸/d⌉`, `a mod d = ⌊((c·a) mod 2¹²⁸)·d / 2¹²⁸⌋`. A training run's shuffle takes one
/// remainder per sample and epoch by the divisors 2…n; a 64-bit division costs several
/// times the four multiplications.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FastMod {
    c: u128,
    d: u64,
}

impl FastMod {
    /// The divisor `d` (0 is taken as 1).
    pub fn new(d: u64) -> Self {
        let d = d.max(1);
        // ⌈2¹²⁸/d⌉ = ⌊(2¹²⁸ − 1)/d⌋ + 1 (for d = 1 it wraps to 0, and every remainder is 0).
        FastMod {
            c: (u128::MAX / u128::from(d)).wrapping_add(1),
            d,
        }
    }

    /// `a mod d`, exactly.
    #[inline(always)]
    pub fn of(self, a: u64) -> u64 {
        let low = self.c.wrapping_mul(u128::from(a));
        let d = u128::from(self.d);
        // The top 64 bits of the 192-bit product low·d.
        let bottom = (u128::from(low as u64) * d) >> 64;
        let top = (low >> 64) * d;
        ((bottom + top) >> 64) as u64
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn fast_remainders_are_remainders_at_the_edges() {
        let ds = [
            1,
            2,
            3,
            5,
            7,
            35,
            64,
            641,
            3000,
            1 << 32,
            (1 << 32) + 1,
            u64::MAX - 1,
            u64::MAX,
        ];
        let special = [0, 1, 2, 63, 64, 65, u64::MAX / 3, u64::MAX - 1, u64::MAX];
        for &d in &ds {
            let f = FastMod::new(d);
            for &a in special
                .iter()
                .chain(&[d - 1, d, d.wrapping_add(1), d.wrapping_mul(2)])
            {
                assert_eq!(f.of(a), a % d, "{a} mod {d}");
            }
        }
        assert_eq!(FastMod::new(0).of(12345), 0);
    }

    proptest! {
        #[test]
        fn fast_remainders_are_remainders(a in any::<u64>(), d in 1u64.., small in 1u64..100_000) {
            prop_assert_eq!(FastMod::new(d).of(a), a % d);
            prop_assert_eq!(FastMod::new(small).of(a), a % small);
            let mixed = splitmix64(a);
            prop_assert_eq!(FastMod::new(small).of(mixed), mixed % small);
        }
    }
}
