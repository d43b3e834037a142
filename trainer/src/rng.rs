//! Counter-based pseudo-random numbers: `u(seed, a, b) = splitmix64³(seed, a, b) / 2⁵³ ∈ [0, 1)`.
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
