//! The Adam optimiser's state and update ([`Adam`]), in f64 on the master parameters:
//! ```text
//! t ← t + 1,  m ← β₁m + (1 − β₁)g,  v ← β₂v + (1 − β₂)g²,
//! θ ← θ − lr·(m / (1 − β₁ᵗ)) / (√(v / (1 − β₂ᵗ)) + 10⁻⁸)      (β₁ = 0.9, β₂ = 0.999)
//! ```
//! element by element, so the result does not depend on how the loop is vectorised (AVX or
//! AVX-512 where the CPU has it: the same IEEE operations, division and square root
//! correctly rounded, hence the same bits as the portable loop).

/// β₁, β₂ of Adam.
const B1: f64 = 0.9;
const B2: f64 = 0.999;

/// Adam's moments (flat, in the parameters' order) and step count.
#[derive(Debug, Clone)]
pub(super) struct Adam {
    m: Vec<f64>,
    v: Vec<f64>,
    t: u64,
}

impl Adam {
    /// Zero moments for `n` parameters.
    pub(super) fn new(n: usize) -> Self {
        Adam {
            m: vec![0.0; n],
            v: vec![0.0; n],
            t: 0,
        }
    }

    /// Starts step t + 1: returns its bias corrections (1 − β₁ᵗ, 1 − β₂ᵗ).
    pub(super) fn begin_step(&mut self) -> (f64, f64) {
        self.t += 1;
        let (p1, p2) = powi2(B1, B2, self.t as i32);
        (1.0 - p1, 1.0 - p2)
    }

    /// Updates the parameter blocks `params` (each with its gradient), which hold the
    /// parameters in the order of the moments, with learning rate `lr` and the step's bias
    /// corrections `c`.
    pub(super) fn update<'a>(
        &mut self,
        params: impl Iterator<Item = (&'a mut [f64], &'a [f64])>,
        lr: f64,
        c: (f64, f64),
    ) {
        let (mut am, mut av) = (&mut self.m[..], &mut self.v[..]);
        for (p, g) in params {
            let (m0, m1) = std::mem::take(&mut am).split_at_mut(p.len());
            let (v0, v1) = std::mem::take(&mut av).split_at_mut(p.len());
            (am, av) = (m1, v1);
            update_block(p, g, m0, v0, lr, c);
        }
    }
}

/// (aᵏ, bᵏ) for k ≥ 1 by binary powering, the two chains side by side: the multiplications
/// of `f64::powi` (the runtime's `__powidf2`: y = a if k is odd else 1, then while k ≫= 1:
/// a ← a·a and, if k is odd, y ← y·a), so the same bits, without two calls per step.
#[inline]
fn powi2(a: f64, b: f64, k: i32) -> (f64, f64) {
    debug_assert!(k >= 1);
    let mut n = k as u32;
    let (mut a, mut b) = (a, b);
    let (mut ya, mut yb) = if n & 1 == 1 { (a, b) } else { (1.0, 1.0) };
    loop {
        n >>= 1;
        if n == 0 {
            return (ya, yb);
        }
        a *= a;
        b *= b;
        if n & 1 == 1 {
            ya *= a;
            yb *= b;
        }
    }
}

/// The update of one block (dispatch to the AVX build where the CPU has it).
fn update_block(p: &mut [f64], g: &[f64], m: &mut [f64], v: &mut [f64], lr: f64, c: (f64, f64)) {
    #[cfg(target_arch = "x86_64")]
    if crate::learn::mlp::cpu_has_avx512() {
        // SAFETY: the CPU has AVX, AVX2 and AVX-512F (`cpu_has_avx512`, which checks
        // AVX-512VL too), the features this `#[target_feature]` function enables.
        return unsafe { update_avx512(p, g, m, v, lr, c) };
    }
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx") {
        // SAFETY: the CPU has AVX (checked just above), the one requirement of calling a
        // `#[target_feature(enable = "avx")]` function.
        return unsafe { update_avx(p, g, m, v, lr, c) };
    }
    update_impl(p, g, m, v, lr, c)
}

/// [`update_impl`] compiled with AVX (4 f64 lanes; the same operations, the same bits).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
fn update_avx(p: &mut [f64], g: &[f64], m: &mut [f64], v: &mut [f64], lr: f64, c: (f64, f64)) {
    update_impl(p, g, m, v, lr, c)
}

/// [`update_impl`] compiled with AVX-512F (8 f64 lanes; the same operations, the same bits).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx,avx2,avx512f")]
fn update_avx512(p: &mut [f64], g: &[f64], m: &mut [f64], v: &mut [f64], lr: f64, c: (f64, f64)) {
    update_impl(p, g, m, v, lr, c)
}

#[inline(always)]
fn update_impl(p: &mut [f64], g: &[f64], m: &mut [f64], v: &mut [f64], lr: f64, c: (f64, f64)) {
    let (c1, c2) = c;
    for (((p, &g), m), v) in p.iter_mut().zip(g).zip(m.iter_mut()).zip(v.iter_mut()) {
        *m = B1 * *m + (1.0 - B1) * g;
        *v = B2 * *v + (1.0 - B2) * g * g;
        *p -= lr * (*m / c1) / ((*v / c2).sqrt() + 1e-8);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The bias corrections' powers are `f64::powi`'s bits at every step count a training
    /// reaches (and beyond), for Adam's β and for arbitrary bases.
    #[test]
    fn powi2_gives_the_bits_of_powi() {
        for k in 1..=300_000 {
            assert_eq!(powi2(B1, B2, k), (B1.powi(k), B2.powi(k)), "k = {k}");
        }
        let mut s = 0x9E37_79B9_7F4A_7C15u64;
        for _ in 0..20_000 {
            s = crate::rng::splitmix64(s);
            // Bases near ±1, so that the powers stay finite and nonzero for these k.
            let a = 1.0 + ((s >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 2f64.powi(-9);
            let b = -(1.0 + ((s & 0xFFFF) as f64 / 65_536.0 - 0.5) * 2f64.powi(-10));
            let k = 1 + (s >> 40) as i32 % 4_000;
            let (pa, pb) = powi2(a, b, k);
            assert_eq!(pa.to_bits(), a.powi(k).to_bits(), "{a:e}^{k}");
            assert_eq!(pb.to_bits(), b.powi(k).to_bits(), "{b:e}^{k}");
        }
    }

    /// The AVX build and the portable loop give the same bits, and the update is Adam's
    /// formula evaluated element by element.
    #[test]
    fn avx_and_portable_updates_agree_with_the_formula() {
        let n = 37;
        let g: Vec<f64> = (0..n)
            .map(|i| ((i * 7919) % 97) as f64 / 13.0 - 3.0)
            .collect();
        let p0: Vec<f64> = (0..n).map(|i| (i as f64).sin()).collect();
        let (mut a, mut b) = (Adam::new(n), Adam::new(n));
        let (mut pa, mut pb) = (p0.clone(), p0.clone());
        for _ in 0..5 {
            let c = a.begin_step();
            assert_eq!(c, b.begin_step());
            a.update(std::iter::once((&mut pa[..], &g[..])), 1e-2, c);
            let (m, v) = (&mut b.m[..], &mut b.v[..]);
            for i in 0..n {
                m[i] = 0.9 * m[i] + (1.0 - 0.9) * g[i];
                v[i] = 0.999 * v[i] + (1.0 - 0.999) * g[i] * g[i];
                pb[i] -= 1e-2 * (m[i] / c.0) / ((v[i] / c.1).sqrt() + 1e-8);
            }
        }
        assert_eq!(pa, pb);
        let (mut pc, mut cstate) = (p0.clone(), Adam::new(n));
        for _ in 0..5 {
            let c = cstate.begin_step();
            let (m, v) = (&mut cstate.m[..], &mut cstate.v[..]);
            update_impl(&mut pc, &g, m, v, 1e-2, c);
        }
        assert_eq!(pa, pc);
        // Each x86 build that the CPU can run, called directly (the dispatch picks one).
        #[cfg(target_arch = "x86_64")]
        for (has, f) in [
            (
                std::arch::is_x86_feature_detected!("avx"),
                update_avx
                    as unsafe fn(&mut [f64], &[f64], &mut [f64], &mut [f64], f64, (f64, f64)),
            ),
            (crate::learn::mlp::cpu_has_avx512(), update_avx512),
        ] {
            if !has {
                continue;
            }
            let (mut pd, mut dstate) = (p0.clone(), Adam::new(n));
            for _ in 0..5 {
                let c = dstate.begin_step();
                let (m, v) = (&mut dstate.m[..], &mut dstate.v[..]);
                // SAFETY: the CPU has the build's features (checked just above).
                unsafe { f(&mut pd, &g, m, v, 1e-2, c) };
            }
            assert_eq!(pa, pd);
        }
    }
}
