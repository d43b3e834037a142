//! `decimal`: f32 → text without `core::fmt` (which costs ~25 KB of flash).
//!
//! Format: `[-]d.dddddddde[-]x` — 9 significant digits, which identify an f32 uniquely:
//! the decimal spacing 10^(e−8) ≤ 10⁻⁸·|v| is below the f32 half-spacing ≥ 2⁻²⁵·|v|,
//! with a factor 6 to spare for the f64 scaling error (≤ 10⁻¹⁴ relative), so
//! `text.parse::<f32>()` gives back the same bits (property-tested on the host). Zero
//! prints as `0` / `-0`; NaN and infinities as `NaN`, `inf`, `-inf`.

/// Writes `v` into `out` and returns the length (at most 16 bytes).
pub fn write_f32(v: f32, out: &mut [u8; 24]) -> usize {
    let mut n = 0;
    let mut put = |b: u8| {
        if let Some(s) = out.get_mut(n) {
            *s = b;
            n += 1;
        }
    };
    if v.is_nan() {
        b"NaN".iter().for_each(|b| put(*b));
        return n;
    }
    if v.is_sign_negative() {
        put(b'-');
    }
    if v.is_infinite() {
        b"inf".iter().for_each(|b| put(*b));
        return n;
    }
    if v == 0.0 {
        put(b'0');
        return n;
    }
    let a = f64::from(v.abs());
    let mut e: i32 = 0;
    let mut p = 1.0f64; // 10^e
    while a >= p * 10.0 {
        p *= 10.0;
        e += 1;
    }
    while a < p {
        p /= 10.0;
        e -= 1;
    }
    let mut m = (a / p * 1e8 + 0.5) as u64; // 9 digits, 1e8 ≤ m ≤ 1e9
    if m >= 1_000_000_000 {
        m /= 10;
        e += 1;
    }
    let mut digits = [0u8; 9];
    for d in digits.iter_mut().rev() {
        *d = b'0' + (m % 10) as u8;
        m /= 10;
    }
    for (i, d) in digits.iter().enumerate() {
        put(*d);
        if i == 0 {
            put(b'.');
        }
    }
    put(b'e');
    if e < 0 {
        put(b'-');
    }
    let mut tmp = [0u8; 24];
    let l = write_u32(e.unsigned_abs(), &mut tmp);
    for b in tmp.iter().take(l) {
        put(*b);
    }
    n
}

/// Writes `v` in decimal; returns the length.
pub fn write_u32(mut v: u32, out: &mut [u8; 24]) -> usize {
    let mut rev = [0u8; 10];
    let mut k = 0;
    loop {
        if let Some(s) = rev.get_mut(k) {
            *s = b'0' + (v % 10) as u8;
        }
        k += 1;
        v /= 10;
        if v == 0 {
            break;
        }
    }
    for (i, s) in out.iter_mut().take(k).enumerate() {
        *s = rev.get(k - 1 - i).copied().unwrap_or(b'?');
    }
    k
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn text(v: f32) -> String {
        let mut b = [0u8; 24];
        let n = write_f32(v, &mut b);
        String::from_utf8(b[..n].to_vec()).unwrap()
    }

    #[test]
    fn examples() {
        assert_eq!(text(1.0), "1.00000000e0");
        assert_eq!(text(-0.05), "-5.00000007e-2"); // −0.05f32 = −0.0500000007…
        assert_eq!(text(-0.5), "-5.00000000e-1");
        assert_eq!(text(f32::MAX), "3.40282347e38");
        assert_eq!(text(f32::from_bits(1)), "1.40129846e-45");
        assert_eq!(text(0.0), "0");
        assert_eq!(text(-0.0), "-0");
        let mut b = [0u8; 24];
        let n = write_u32(4_294_967_295, &mut b);
        assert_eq!(&b[..n], b"4294967295");
    }

    proptest! {
        #![proptest_config(ProptestConfig {
        rng_seed: proptest::test_runner::RngSeed::Fixed(0x616d_7063),
        ..ProptestConfig::with_cases(200_000)
    })]
        #[test]
        fn every_finite_f32_round_trips(bits in any::<u32>()) {
            let v = f32::from_bits(bits);
            let t = text(v);
            if v.is_nan() {
                prop_assert_eq!(t, "NaN");
            } else {
                prop_assert_eq!(t.parse::<f32>().unwrap().to_bits(), bits, "{}", t);
            }
        }
    }
}
