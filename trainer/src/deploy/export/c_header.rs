//! The C header of `controller-core/capi` for an exported network ([`render_c_header`]):
//! `AMPC_NX`, `AMPC_NU`, the flag bits, `ampc_evaluate` and the certificate as a `static
//! const struct ampc_certificate` (ε, its tier, domain X, clamp band, model hash; one per
//! device tanh, chosen by `AMPC_FAST_TANH`).
//!
//! The struct's layout is the `#[repr(C)]` `AmpcCertificate` of the C API crate, which also
//! exports the linked library's own copy (`ampc_linked_certificate`): a C program can check
//! that the header it was compiled with belongs to the library it links. Numbers are written
//! as the shortest decimal that reads back to the same f64 (`f` suffix: f32), so the header's
//! values equal the Rust constants bit for bit. Plain C99, ASCII only.

use super::{ExportError, ExportModel, ExportReport, Tanh};

/// Capacity of the hash field (characters, without the terminating NUL): a SHA-256 in hex.
pub const HASH_CAPACITY: usize = 64;

pub(super) fn c64(v: f64) -> String {
    format!("{v:?}")
}

pub(super) fn c32(v: f32) -> String {
    format!("{v:?}f")
}

pub(super) fn list(items: impl Iterator<Item = String>) -> String {
    format!("{{{}}}", items.collect::<Vec<_>>().join(", "))
}

/// The header template (`c/ampc.h.in`); `{{KEY}}` fields are filled by [`fill`].
const HEADER: &str = include_str!("c/ampc.h.in");

/// `template` with every `{{KEY}}` replaced by its value (each key must occur; no field may
/// remain: a template and its caller out of step are a bug, caught by the unit tests).
pub(super) fn fill(template: &str, fields: &[(&str, &str)]) -> String {
    let mut out = template.to_string();
    for (key, value) in fields {
        let pat = format!("{{{{{key}}}}}");
        debug_assert!(out.contains(&pat), "template field {pat} missing");
        out = out.replace(&pat, value);
    }
    debug_assert!(!out.contains("{{"), "template field left unfilled");
    out
}

/// The intro of the header of `controller-core/capi`.
const CAPI_INTRO: &str = "C interface of controller-core (crate controller-core/capi, \
                          libampc_capi.a)";
/// What the capi header says about its library.
const CAPI_LINK: &str = "Plain C99. libampc_capi.a (controller-core/capi) implements it only for \
                         the controller\n * compiled into controller-core; for your own net, \
                         `trainer export --c-lib DIR` writes this\n * header with the C \
                         sources of that net.";

/// Refuses a hash the C string could not hold verbatim.
pub(super) fn check_hash(model: &ExportModel) -> Result<(), ExportError> {
    if model.hash.len() > HASH_CAPACITY
        || !model
            .hash
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
    {
        return Err(ExportError::Invalid(format!(
            "hash {:?}: the C header holds at most {HASH_CAPACITY} ASCII letters, digits, '-' or '_'",
            model.hash
        )));
    }
    Ok(())
}

/// `a-b-…`: the layer widths, input first.
pub(super) fn architecture(model: &ExportModel) -> String {
    std::iter::once(model.nx())
        .chain(model.layers.iter().map(|l| l.b.len()))
        .map(|s| s.to_string())
        .collect::<Vec<_>>()
        .join("-")
}

/// ε of the certificate for the device tanh `t`: the learning side's plus its f32 allowance.
pub(super) fn total_eps(model: &ExportModel, report: &ExportReport, t: Tanh) -> f64 {
    let k = Tanh::ALL.iter().position(|a| *a == t).unwrap_or(0);
    model.eps + report.f32_allowance[k]
}

/// The initialiser `{eps, …, "hash"}` of a `struct ampc_certificate` for the tanh `t`.
pub(super) fn certificate_initializer(
    model: &ExportModel,
    report: &ExportReport,
    t: Tanh,
) -> String {
    let eps = total_eps(model, report, t);
    let (clo, chi) = model.clamp_band(eps);
    format!(
        "{{\n    \
         {eps}, /* eps */\n    \
         AMPC_GUARANTEE_{tier}, /* guarantee */\n    \
         {ph}, /* placeholder */\n    \
         {ft}, /* fast_tanh */\n    \
         {dlo}, /* domain_lo */\n    \
         {dhi}, /* domain_hi */\n    \
         {clo}, /* clamp_lo */\n    \
         {chi}, /* clamp_hi */\n    \
         \"{hash}\" /* hash */\n}}",
        eps = c64(eps),
        tier = model.guarantee.name().to_uppercase(),
        ph = u8::from(model.placeholder),
        ft = u8::from(t == Tanh::Fast),
        dlo = list(model.domain_lo.iter().map(|v| c64(*v))),
        dhi = list(model.domain_hi.iter().map(|v| c64(*v))),
        clo = list(clo.iter().map(|v| c32(*v))),
        chi = list(chi.iter().map(|v| c32(*v))),
        hash = model.hash,
    )
}

/// `#ifdef AMPC_FAST_TANH` / `#else` / `#endif` around `item(tanh)` for each tanh.
pub(super) fn per_tanh(item: impl Fn(Tanh) -> String) -> String {
    format!(
        "#ifdef AMPC_FAST_TANH\n{}#else\n{}#endif\n",
        item(Tanh::Fast),
        item(Tanh::Libm)
    )
}

/// The header `ampc.h` for `model` (errors: a hash longer than [`HASH_CAPACITY`] or not
/// ASCII hex/`-`/alphanumeric, which the C string could not hold verbatim).
pub fn render_c_header(model: &ExportModel, report: &ExportReport) -> Result<String, ExportError> {
    render_header(model, report, (CAPI_INTRO, CAPI_LINK), "")
}

/// The header for `model`: `intro` = (what it is the interface of, what to link), `link`:
/// declarations before the library's names (empty, or `c_lib`'s link check).
pub(super) fn render_header(
    model: &ExportModel,
    report: &ExportReport,
    (what, link_note): (&str, &str),
    link: &str,
) -> Result<String, ExportError> {
    model.validate()?;
    super::range::check_report(model, report)?;
    check_hash(model)?;
    let intro = format!(
        " * ampc.h: {what} for\n * the `{name}` controller, architecture {arch} (tanh hidden \
         layers), model hash\n * {hash}.\n * {link_note}\n",
        name = model.name,
        arch = architecture(model),
        hash = model.hash,
    );
    let certificates =
        "/* This header's certificate: define AMPC_FAST_TANH if the library was built with\n \
         * the fast-tanh feature. */\n"
            .to_string()
            + &rests_on(model)
            + &per_tanh(|t| {
                format!(
                    "static const struct ampc_certificate AMPC_CERTIFICATE = {};\n",
                    certificate_initializer(model, report, t)
                )
            });
    Ok(fill(
        HEADER,
        &[
            ("INTRO", &intro),
            ("NX", &model.nx().to_string()),
            ("NU", &model.nu().to_string()),
            ("HASH_CAPACITY", &HASH_CAPACITY.to_string()),
            ("CERTIFICATES", &certificates),
            ("LINK", link),
        ],
    ))
}

/// What ε rests on ([`ExportModel::rests_on`]) as a C comment; empty when nothing.
fn rests_on(model: &ExportModel) -> String {
    if model.rests_on.is_empty() {
        return String::new();
    }
    let mut o = String::from("/* ε rests on (the certificate's assumptions and premises):\n");
    for r in &model.rests_on {
        o += &format!(" * - {}\n", r.replace("*/", "* /").replace('\n', " "));
    }
    o + " */\n"
}

#[cfg(test)]
mod tests {
    use super::super::placeholder_pendulum;
    use super::*;

    fn report() -> ExportReport {
        ExportReport {
            f32_allowance: [1.25e-4, 3.0e-3],
            f32_observed: [1e-5, 1e-3],
            samples: 10,
            boxes: 4,
        }
    }

    /// The initialiser of `AMPC_CERTIFICATE` in the `#ifdef`/`#else` branch `fast`.
    fn block(h: &str, fast: bool) -> &str {
        let (a, b) = h.split_once("#else\n").unwrap();
        if fast {
            a.rsplit_once("#ifdef AMPC_FAST_TANH\n").unwrap().1
        } else {
            b.split_once("#endif").unwrap().0
        }
    }

    #[test]
    fn header_values_read_back_to_the_exported_numbers() {
        let m = placeholder_pendulum();
        let h = render_c_header(&m, &report()).unwrap();
        assert!(h.contains("#define AMPC_NX 2\n") && h.contains("#define AMPC_NU 1\n"));
        assert!(h.is_ascii(), "the header is ASCII only");
        for (k, fast) in [(0, false), (1, true)] {
            let b = block(&h, fast);
            let eps: f64 = b
                .split_once("{\n    ")
                .unwrap()
                .1
                .split_once(',')
                .unwrap()
                .0
                .parse()
                .unwrap();
            assert_eq!(eps.to_bits(), (m.eps + report().f32_allowance[k]).to_bits());
            assert!(b.contains("AMPC_GUARANTEE_ESTIMATED"));
            assert!(b.contains(&format!("{}, /* fast_tanh */", u8::from(fast))));
            assert!(b.contains(&format!("\"{}\"", m.hash)));
            let (lo, hi) = m.clamp_band(m.eps + report().f32_allowance[k]);
            assert!(b.contains(&format!("{{{:?}f}}, /* clamp_lo */", lo[0])));
            assert!(b.contains(&format!("{{{:?}f}}, /* clamp_hi */", hi[0])));
        }
        let mut sound = m.clone();
        sound.guarantee = super::super::Guarantee::Sound;
        // A placeholder (or a sampled L_MPC) cannot claim `sound`.
        assert!(render_c_header(&sound, &report()).is_err());
        sound.placeholder = false;
        sound.l_mpc_is_estimate = false;
        let h = render_c_header(&sound, &report()).unwrap();
        assert!(block(&h, false).contains("AMPC_GUARANTEE_SOUND"));
    }

    #[test]
    fn a_hash_the_c_field_cannot_hold_is_refused() {
        let mut m = placeholder_pendulum();
        m.hash = "x".repeat(HASH_CAPACITY + 1);
        let e = render_c_header(&m, &report()).unwrap_err().to_string();
        assert!(e.contains("hash"), "{e}");
        m.hash = "a\"b".into();
        assert!(render_c_header(&m, &report()).is_err());
    }
}
