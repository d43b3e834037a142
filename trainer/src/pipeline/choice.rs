//! Which of the run's two nets (nominal, regularized) is exported: the one with the
//! strongest guarantee reached, then the better fit.
//!
//! ```text
//! key(net) = (vacuous(ε), tier, ε, validation mean error),
//! exported = argmin key  (lexicographic; ties keep the regularized net)
//! ```
//!
//! ε is vacuous when it is at least the diagonal of U (`study::report::judge`); a net with a
//! non-vacuous bound wins, then the stronger tier (sound < statistical < estimated), then the
//! smaller ε — also between two vacuous bounds, where the smaller one still bounds the
//! error more tightly (the paper's pendulum: Theorem 1 is vacuous for both nets, the
//! regularized net's ε is the smaller) — and only at equal ε the fit. The reason is written into `export_report.json` (`net`, `net_reason`) and
//! the report's verdict.

use crate::certify::file::CertificateFile;
use crate::certify::Model;
use crate::study::report::judge;

/// The exported net's name (`"nominal"` or `"regularized"`) and why it was chosen.
pub(super) fn choose(
    nominal: (&Model, &CertificateFile),
    regularized: (&Model, &CertificateFile),
) -> (&'static str, String) {
    let describe = |(m, f): (&Model, &CertificateFile)| {
        let c = &f.base;
        let vacuous =
            judge(c.eps_physical(), &c.u_lo, &c.u_hi).1 == "vacuous" || !c.eps.is_finite();
        let fit = m.validation_stats.mean;
        (
            vacuous,
            f.guarantee.guarantee,
            c.eps,
            fit,
            m.validation_stats.r2,
        )
    };
    let (nv, nt, ne, nf, nr) = describe(nominal);
    let (rv, rt, re, rf, rr) = describe(regularized);
    let n_key = (nv, nt, ne, nf);
    let r_key = (rv, rt, re, rf);
    let better = |a: (bool, _, f64, f64), b: (bool, _, f64, f64)| -> bool {
        (a.0, a.1)
            .cmp(&(b.0, b.1))
            .then(a.2.total_cmp(&b.2))
            .then(a.3.total_cmp(&b.3))
            .is_lt()
    };
    let name = |t: crate::certify::tier::Tier| t.name();
    let line = |v: bool, t, e: f64, r: f64| {
        format!(
            "ε = {e:.4} ({}{}), validation R² {r:.4}",
            name(t),
            if v { ", vacuous" } else { "" }
        )
    };
    let (n_s, r_s) = (line(nv, nt, ne, nr), line(rv, rt, re, rr));
    let why = match (nv, rv) {
        (false, true) | (true, false) => "only it has a non-vacuous bound",
        _ if nt != rt => "the stronger tier",
        _ if ne != re => "the smaller ε",
        _ => "equal bounds, so the better fit (validation mean error)",
    };
    if better(n_key, r_key) {
        (
            "nominal",
            format!("the nominal net: {why} (nominal {n_s}; regularized {r_s})"),
        )
    } else {
        (
            "regularized",
            format!("the regularized net: {why} (regularized {r_s}; nominal {n_s})"),
        )
    }
}
