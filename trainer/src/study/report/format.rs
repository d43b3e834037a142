//! The report's number and box formatting: a number with at most 6 significant digits
//! (trailing zeros dropped, 0 and non-finite values as Rust prints them) and a box
//! `[lo₁, hi₁] × [lo₂, hi₂] × …` of such numbers; every section and the verdict use them.

/// A number with at most 6 significant digits.
pub(super) fn num(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let digits = (5 - v.abs().log10().floor() as i32).clamp(0, 12) as usize;
    let s = format!("{v:.digits$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// A box `[lo₁, hi₁] × [lo₂, hi₂] × …`.
pub(super) fn boxed(lo: &[f64], hi: &[f64]) -> String {
    let parts: Vec<String> = lo
        .iter()
        .zip(hi)
        .map(|(l, h)| format!("[{}, {}]", num(*l), num(*h)))
        .collect();
    parts.join(" × ")
}
