//! The C library of an exported network ([`render_c_lib`]): a self-contained folder —
//! `ampc.h`, `ampc.c` (portable C99), a `Makefile` and a `CMakeLists.txt` — that builds
//! `libampc.a` with any C99 compiler (host `cc`, `arm-none-eabi-gcc`), no Rust needed.
//!
//! `ampc.c` (template `c/ampc.c.in`) is controller-core's `Controller::evaluate` in C, the
//! same operations in the same order: projection onto the f32 domain, the excluded boxes,
//! the folded f32 network (`acc = b[o]`, then `acc = acc + w[o][i]·x[i]` for i = 0, 1, …,
//! compiled without contraction into FMA), controller-core's tanh (the accurate one, or the
//! rational one with `AMPC_FAST_TANH`), the clamp band and the fallback; weights are written
//! as exact hexadecimal float constants. So u and the flags are bit-identical to the Rust
//! controller (`tests/c_lib.rs` checks it on the host and on a Cortex-M4 in QEMU).
//!
//! **Link check.** The library's names carry the export's identity,
//! `ampc_evaluate_<id>_<tanh>` and `ampc_linked_certificate_<id>_<tanh>`, where `<id>` =
//! the first 16 hex digits of SHA-256(`ampc.c`) (weights, domain, band, fallback, excluded
//! boxes, both certificates: every number the C code or its certificate holds) and `<tanh>`
//! is `accurate` or `fast`. The header maps `ampc_evaluate` and `ampc_linked_certificate` to
//! those names, so a program compiled with one export's header links only with the library
//! built from the same export and the same tanh; any other fails with an undefined reference.

use std::path::Path;

use super::c_header::{
    architecture, c64, certificate_initializer, fill, list, per_tanh, render_header, total_eps,
};
use super::{ExportError, ExportModel, ExportReport, PendingFiles, Tanh};

const SOURCE: &str = include_str!("c/ampc.c.in");
const MAKEFILE: &str = include_str!("c/Makefile.in");
const CMAKE: &str = include_str!("c/CMakeLists.txt.in");

/// The files of the C library folder `dir` for `model` (rendered, not written: the caller
/// writes them with the rest of the export, [`super::write_files`]).
pub fn render_c_lib(
    model: &ExportModel,
    report: &ExportReport,
    dir: &Path,
) -> Result<PendingFiles, ExportError> {
    let source = render_source(model, report);
    let id = link_id(&source);
    let intro = (
        "C interface of the C library in this folder (ampc.c; libampc.a from its\n * \
         Makefile or CMakeLists.txt)",
        "Plain C99. Link the libampc.a built from the ampc.c beside this header, with\n * \
         AMPC_FAST_TANH defined in both or in neither: any other library fails to link.",
    );
    let header = render_header(model, report, intro, &link_block(model, report, &id))?;
    let name = model.name.as_str();
    Ok(vec![
        (dir.join("ampc.h"), header.into_bytes()),
        (dir.join("ampc.c"), source.into_bytes()),
        (
            dir.join("Makefile"),
            fill(MAKEFILE, &[("NAME", name)]).into_bytes(),
        ),
        (
            dir.join("CMakeLists.txt"),
            fill(CMAKE, &[("NAME", &cmake_name(name))]).into_bytes(),
        ),
    ])
}

/// The export's identity in the library's names: the first 16 hex digits of SHA-256 of
/// `ampc.c` (module doc).
pub fn link_id(source: &str) -> String {
    crate::io::sha256_hex(source.as_bytes())[..16].to_string()
}

/// `name` as a CMake project name (letters, digits, `_`).
fn cmake_name(name: &str) -> String {
    name.chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect()
}

/// The f32 list `{a, b, …}` as exact hexadecimal constants.
fn hex_list(v: &[f32]) -> String {
    list(v.iter().map(|x| hex32(*x)))
}

/// `v` as a C99 hexadecimal floating constant of type float: exact, whatever the compiler's
/// decimal rounding (finite `v`; the model is validated).
pub fn hex32(v: f32) -> String {
    let bits = v.to_bits();
    let sign = if bits >> 31 == 1 { "-" } else { "" };
    let exp = ((bits >> 23) & 0xff) as i32;
    let man = (bits & 0x7f_ffff) << 1;
    match (exp, man) {
        (0, 0) => format!("{sign}0x0p+0f"),
        (0, _) => format!("{sign}0x0.{man:06x}p-126f"),
        _ => format!("{sign}0x1.{man:06x}p{:+}f", exp - 127),
    }
}

/// `ampc.c` for `model` (template `c/ampc.c.in`).
fn render_source(model: &ExportModel, report: &ExportReport) -> String {
    let folded = model.folded();
    let n = folded.f32_layers.len();
    let mut layers = format!("#define AMPC_N_LAYERS_ {n}u\n");
    let width = folded
        .f32_layers
        .iter()
        .map(|(_, out, _, _)| *out)
        .max()
        .unwrap_or(1);
    layers += &format!("#define AMPC_WIDTH_ {width}u\n");
    let mut table = String::new();
    for (k, (inp, out, w, b)) in folded.f32_layers.iter().enumerate() {
        layers += &format!(
            "/* layer {k}: {inp} -> {out}{} */\n\
             static const float AMPC_W{k}_[{}] = {};\n\
             static const float AMPC_B{k}_[{out}] = {};\n",
            if k + 1 < n { ", tanh" } else { ", linear" },
            w.len(),
            hex_list(w),
            hex_list(b),
        );
        table += &format!("    {{{inp}u, {out}u, AMPC_W{k}_, AMPC_B{k}_}},\n");
    }
    let (x_lo, x_hi) = model.domain_f32();
    let bands = per_tanh(|t| {
        let (lo, hi) = model.clamp_band(total_eps(model, report, t));
        let fb = model.fallback_f32(&lo, &hi);
        format!(
            "/* eps = {eps} ({tanh} tanh) */\n\
             static const float AMPC_CLAMP_LO_[AMPC_NU] = {};\n\
             static const float AMPC_CLAMP_HI_[AMPC_NU] = {};\n\
             static const float AMPC_FALLBACK_[AMPC_NU] = {};\n",
            hex_list(&lo),
            hex_list(&hi),
            hex_list(&fb),
            eps = c64(total_eps(model, report, t)),
            tanh = if t == Tanh::Fast {
                "rational"
            } else {
                "accurate"
            },
        )
    });
    let linked = per_tanh(|t| {
        format!(
            "const struct ampc_certificate ampc_linked_certificate = {};\n",
            certificate_initializer(model, report, t)
        )
    });
    fill(
        SOURCE,
        &[
            ("NAME", &model.name),
            ("ARCH", &architecture(model)),
            ("HASH", &model.hash),
            ("LAYERS", &layers),
            ("LAYER_TABLE", &table),
            ("X_LO", &hex_list(&x_lo)),
            ("X_HI", &hex_list(&x_hi)),
            ("BANDS", &bands),
            ("EXCLUDED", &excluded_block(model)),
            ("LINKED_CERTIFICATE", &linked),
        ],
    )
}

/// `ampc_excluded(xp)`: whether the projected state lies in one of the certificate's
/// excluded boxes (closed, rounded outward to f32), as controller-core tests it.
fn excluded_block(model: &ExportModel) -> String {
    let boxes = model.excluded_f32();
    if boxes.is_empty() {
        return "/* The certificate excludes no box of X. */\n\
                static int ampc_excluded(const float xp[AMPC_NX])\n{\n    (void)xp;\n    \
                return 0;\n}\n"
            .into();
    }
    let rows = |upper: bool| {
        boxes
            .iter()
            .map(|(lo, hi)| format!("    {},\n", hex_list(if upper { hi } else { lo })))
            .collect::<String>()
    };
    format!(
        "/* Boxes of X the certificate excludes (closed, rounded outward). */\n\
         #define AMPC_N_EXCLUDED_ {n}u\n\
         static const float AMPC_EXCL_LO_[AMPC_N_EXCLUDED_][AMPC_NX] = {{\n{lo}}};\n\
         static const float AMPC_EXCL_HI_[AMPC_N_EXCLUDED_][AMPC_NX] = {{\n{hi}}};\n\
         static int ampc_excluded(const float xp[AMPC_NX])\n{{\n    \
         unsigned k, i;\n    \
         for (k = 0; k < AMPC_N_EXCLUDED_; ++k) {{\n        \
         int inside = 1;\n        \
         for (i = 0; i < AMPC_NX; ++i) {{\n            \
         if (!(AMPC_EXCL_LO_[k][i] <= xp[i] && xp[i] <= AMPC_EXCL_HI_[k][i])) {{\n                \
         inside = 0;\n            }}\n        }}\n        \
         if (inside) {{\n            return 1;\n        }}\n    }}\n    \
         return 0;\n}}\n",
        n = boxes.len(),
        lo = rows(false),
        hi = rows(true),
    )
}

/// The header's link check and the certificate's macros (module doc).
fn link_block(model: &ExportModel, report: &ExportReport, id: &str) -> String {
    let names = per_tanh(|t| {
        let suffix = if t == Tanh::Fast { "fast" } else { "accurate" };
        format!(
            "#define AMPC_EPS {eps}\n\
             #define ampc_evaluate ampc_evaluate_{id}_{suffix}\n\
             #define ampc_linked_certificate ampc_linked_certificate_{id}_{suffix}\n",
            eps = c64(total_eps(model, report, t)),
        )
    });
    format!(
        "\n/* The certificate's model hash, tier and eps (for this tanh) as macros. */\n\
         #define AMPC_MODEL_HASH \"{hash}\"\n\
         #define AMPC_TIER AMPC_GUARANTEE_{tier}\n\
         /* Link check: the library's names carry this export's identity (the first 16 hex\n \
         * digits of the SHA-256 of its ampc.c) and the tanh, so a program compiled with this\n \
         * header links only with the library built from the same export and the same tanh;\n \
         * any other controller's library fails with an undefined reference. */\n\
         #define AMPC_LINK_ID \"{id}\"\n{names}",
        hash = model.hash,
        tier = model.guarantee.name().to_uppercase(),
    )
}

#[cfg(test)]
mod tests {
    use super::super::placeholder_pendulum;
    use super::*;

    #[test]
    fn hex_constants_are_exact() {
        for (v, s) in [
            (1.0f32, "0x1.000000p+0f"),
            (-0.875, "-0x1.c00000p-1f"),
            (0.0, "0x0p+0f"),
            (-0.0, "-0x0p+0f"),
            (f32::MIN_POSITIVE / 2.0, "0x0.800000p-126f"),
            (f32::MAX, "0x1.fffffep+127f"),
        ] {
            assert_eq!(hex32(v), s);
        }
    }

    #[test]
    fn folder_files_are_filled_and_carry_the_link_id() {
        let m = placeholder_pendulum();
        let r = super::super::certify_f32(&m).unwrap();
        let files = render_c_lib(&m, &r, Path::new("out")).unwrap();
        let names: Vec<String> = files
            .iter()
            .map(|(p, _)| p.file_name().unwrap().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names, ["ampc.h", "ampc.c", "Makefile", "CMakeLists.txt"]);
        let text = |k: usize| String::from_utf8(files[k].1.clone()).unwrap();
        let (h, c) = (text(0), text(1));
        for t in [&h, &c, &text(2), &text(3)] {
            assert!(!t.contains("{{") && t.is_ascii());
        }
        let id = link_id(&c);
        assert!(h.contains(&format!("ampc_evaluate_{id}_accurate")));
        assert!(h.contains(&format!("ampc_evaluate_{id}_fast")));
        assert!(h.contains(&format!("#define AMPC_MODEL_HASH \"{}\"", m.hash)));
        // Another network (one weight changed by one ulp) has another identity.
        let mut other = m.clone();
        let w = &mut other.layers[0].w[0][0];
        *w = f64::from(f32::from_bits((*w as f32).to_bits() + 1));
        let c2 = String::from_utf8(
            render_c_lib(&other, &r, Path::new("o")).unwrap()[1]
                .1
                .clone(),
        )
        .unwrap();
        assert_ne!(link_id(&c2), id);
    }
}
