//! The binomial arithmetic of the statistical tier: the one-sided Clopper–Pearson upper
//! bound p̄ on a probability from k events in n i.i.d. trials at confidence 1 − β,
//!
//!   P(Bin(n, p̄) ≤ k) = Σ_{i ≤ k} C(n, i) p̄ⁱ (1 − p̄)^{n−i} = β,
//!
//! the smallest observed level ε_p whose bound meets a target ([`eps_for_probability`]) and
//! the draw that aims at a number of labelled states ([`draw_for_labelled`]).

/// ln P(Bin(n, p) ≤ k), summed in log space (no underflow for n up to 10⁸ or more).
fn ln_binomial_cdf(n: u64, k: u64, p: f64) -> f64 {
    if p <= 0.0 {
        return 0.0;
    }
    if p >= 1.0 {
        return if k >= n { 0.0 } else { f64::NEG_INFINITY };
    }
    let (lp, lq) = (p.ln(), (-p).ln_1p());
    // ln pmf(0) = n ln(1 − p); ln pmf(i+1) = ln pmf(i) + ln((n − i)/(i + 1)) + ln(p/(1−p)).
    let mut term = n as f64 * lq;
    let (mut max, mut terms) = (term, Vec::with_capacity(k.min(n) as usize + 1));
    terms.push(term);
    for i in 0..k.min(n) {
        term += ((n - i) as f64 / (i + 1) as f64).ln() + lp - lq;
        max = max.max(term);
        terms.push(term);
    }
    max + terms.iter().map(|t| (t - max).exp()).sum::<f64>().ln()
}

/// Clopper–Pearson upper bound p̄ on a binomial probability from k successes in n trials
/// at `confidence` = 1 − β (one-sided): P(Bin(n, p̄) ≤ k) = β. Bisection to 1e-15
/// relative; 1 for k ≥ n or n = 0; NaN for a confidence outside (0, 1).
pub fn clopper_pearson_upper(n: u64, k: u64, confidence: f64) -> f64 {
    if !(confidence > 0.0 && confidence < 1.0) {
        return f64::NAN;
    }
    if n == 0 || k >= n {
        return 1.0;
    }
    let ln_beta = (1.0 - confidence).ln();
    // The CDF falls in p: find the crossing of ln β.
    let (mut lo, mut hi) = (0.0f64, 1.0f64);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if ln_binomial_cdf(n, k, mid) > ln_beta {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo <= 1e-15 * hi {
            break;
        }
    }
    // The upper end: the bound is never rounded down.
    hi
}

/// The draw that aims at `target` states of the conditioning set (labelled; in the
/// pipeline, hard-feasible) when an independent, earlier sample (the validation set: `u`
/// of `n` outside the set — unlabelled, or in the pipeline unlabelled or soft-labelled)
/// shows part of X outside it:
/// ```text
/// ū = clopper_pearson_upper(n, u, confidence),  draw = ⌈target / (1 − ū)⌉,  target ≤ draw ≤ 4·target
/// ```
/// The conditional bound (`GivenLabelled`) counts only the states of the set, so a default
/// sized for P ≤ p with zero exceedances (4603 for 1e-3 at 99 %) needs that many of them.
/// The size is fixed before the statistical states are drawn and from other states, so the
/// bounds keep their meaning (they are computed from whatever n and n_L result). `target`
/// when the earlier sample is empty or has no state outside the set.
pub fn draw_for_labelled(target: usize, n: u64, u: u64, confidence: f64) -> usize {
    if target == 0 || n == 0 || u == 0 {
        return target;
    }
    let ub = clopper_pearson_upper(n, u, confidence);
    let cap = target.saturating_mul(4);
    if ub.is_nan() || ub >= 0.75 {
        return cap;
    }
    let draw = (target as f64 / (1.0 - ub)).ceil();
    (draw as usize).clamp(target, cap)
}

/// The smallest level ε_p among the observed errors such that counting exceedances of
/// ε_p gives a bound ≤ `p_target`: with the errors sorted decreasingly e₍₁₎ ≥ e₍₂₎ ≥ …,
/// ε_p = e₍k*+1₎ where k* is the largest k with `clopper_pearson_upper(n, k) ≤ p_target`
/// (exceedances of e₍k*+1₎ are strict, so at most k*). `errors` holds one entry per sample,
/// +∞ for an unlabelled state. None when even k = 0 does not reach `p_target`.
pub fn eps_for_probability(errors: &[f64], p_target: f64, confidence: f64) -> Option<f64> {
    let n = errors.len() as u64;
    if clopper_pearson_upper(n, 0, confidence) > p_target {
        return None;
    }
    // The bound grows with k: bisect for k*.
    let (mut lo, mut hi) = (0u64, n);
    while lo < hi {
        let mid = lo + (hi - lo).div_ceil(2);
        if clopper_pearson_upper(n, mid, confidence) <= p_target {
            lo = mid;
        } else {
            hi = mid - 1;
        }
    }
    let mut sorted: Vec<f64> = errors
        .iter()
        .map(|e| if e.is_nan() { f64::INFINITY } else { *e })
        .collect();
    sorted.sort_by(|a, b| b.total_cmp(a));
    sorted.get(lo as usize).copied().or(Some(0.0))
}
