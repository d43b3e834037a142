//! The generated Rust file `controller-core/src/demo/weights.rs` ([`render_rust`]):
//! the folded f32 layers, the network type and constant, the f32 domain and one
//! `Certificate` per device tanh, laid out the way rustfmt formats it (width [`WIDTH`]).
//!
//! The file is a plain list of items for `controller_core::include_controller!` (which
//! wraps it in a module, imports `Certificate`, `Guarantee`, `Dense`, `Hidden` and allows
//! the float-literal lints): no inner attributes, no `use` of `crate::` paths, so the same
//! file compiles inside `controller-core` and in any crate that depends on it.

use std::fmt::Write as _;

use super::{ExportModel, ExportReport, Folded, Tanh};

/// Width rustfmt formats to.
const WIDTH: usize = 100;

/// Shortest round-trip text of an f32 (Rust's `Debug`, always with `.` or exponent).
fn lit32(v: f32) -> String {
    format!("{v:?}")
}

/// Shortest round-trip text of an f64.
fn lit64(v: f64) -> String {
    format!("{v:?}")
}

/// An array literal laid out as rustfmt does: on one line if it fits, else one item per
/// line (or filled lines when every item is at most 10 characters).
pub(super) fn array(items: &[String], indent: usize, used: usize, tail: usize) -> String {
    let one = format!("[{}]", items.join(", "));
    if !one.contains('\n') && used + one.len() + tail <= WIDTH {
        return one;
    }
    let pad = " ".repeat(indent + 4);
    let mut s = String::from("[\n");
    if items.len() > 1 && items.iter().all(|i| i.len() <= 10 && !i.contains('\n')) {
        let mut line = String::new();
        for it in items {
            if !line.is_empty() && indent + 4 + line.len() + 1 + it.len() + 1 > WIDTH {
                let _ = writeln!(s, "{pad}{line}");
                line.clear();
            }
            if !line.is_empty() {
                line.push(' ');
            }
            line.push_str(it);
            line.push(',');
        }
        let _ = writeln!(s, "{pad}{line}");
    } else {
        for it in items {
            let _ = writeln!(s, "{pad}{it},");
        }
    }
    s.push_str(&" ".repeat(indent));
    s.push(']');
    s
}

/// `pub const NAME: TY = VALUE;` with rustfmt's line breaking for array values.
fn const_array(out: &mut String, doc: &str, vis: &str, name: &str, ty: &str, items: &[String]) {
    let head = format!("{vis}const {name}: {ty} = ");
    let _ = writeln!(out, "/// {doc}");
    let _ = writeln!(out, "{head}{};", array(items, 0, head.len(), 1));
}

fn certificate_literal(
    model: &ExportModel,
    tanh: Tanh,
    report: &ExportReport,
    k: usize,
) -> Vec<(String, String)> {
    let eps_total = model.eps + report.f32_allowance[k];
    let (clo, chi) = model.clamp_band(eps_total);
    let fb = model.fallback_f32(&clo, &chi);
    let v64 = |v: &[f64]| v.iter().map(|x| lit64(*x)).collect::<Vec<_>>();
    let v32 = |v: &[f32]| v.iter().map(|x| lit32(*x)).collect::<Vec<_>>();
    let arr = |name: &str, items: Vec<String>| {
        let used = 4 + name.len() + 2;
        (name.to_string(), array(&items, 4, used, 1))
    };
    vec![
        ("eps".into(), lit64(eps_total)),
        (
            "guarantee".into(),
            format!("Guarantee::{}", super::rust_name(model.guarantee)),
        ),
        ("eps_nn".into(), lit64(model.eps)),
        ("eps_d".into(), lit64(model.eps_d)),
        ("l_nn".into(), lit64(model.l_nn)),
        ("l_nn_method".into(), format!("{:?}", model.l_nn_method)),
        ("l_mpc".into(), lit64(model.l_mpc)),
        (
            "l_mpc_is_estimate".into(),
            model.l_mpc_is_estimate.to_string(),
        ),
        ("covering_radius".into(), lit64(model.covering_radius)),
        ("f32_allowance".into(), lit64(report.f32_allowance[k])),
        ("f32_observed".into(), lit64(report.f32_observed[k])),
        ("tanh".into(), format!("{:?}", tanh.name())),
        ("tanh_max_abs_err".into(), lit64(tanh.max_abs_err())),
        arr("domain_lo", v64(&model.domain_lo)),
        arr("domain_hi", v64(&model.domain_hi)),
        arr("u_lo", v64(&model.u_lo)),
        arr("u_hi", v64(&model.u_hi)),
        arr("actuator_lo", v64(&model.actuator_lo)),
        arr("actuator_hi", v64(&model.actuator_hi)),
        arr("clamp_lo", v32(&clo)),
        arr("clamp_hi", v32(&chi)),
        arr("fallback", v32(&fb)),
        arr_excluded(model),
        ("hash".into(), format!("{:?}", model.hash)),
        ("placeholder".into(), model.placeholder.to_string()),
    ]
}

/// The certificate's `excluded` field: `&[]`, or one `([lo…], [hi…])` box per line (f32,
/// rounded outward).
fn arr_excluded(model: &ExportModel) -> (String, String) {
    let boxes = model.excluded_f32();
    if boxes.is_empty() {
        return ("excluded".into(), "&[]".into());
    }
    let list = |v: &[f32]| v.iter().map(|x| lit32(*x)).collect::<Vec<_>>().join(", ");
    let mut s = String::from("&[\n");
    for (lo, hi) in &boxes {
        let _ = writeln!(s, "        ([{}], [{}]),", list(lo), list(hi));
    }
    s.push_str("    ]");
    ("excluded".into(), s)
}

/// The generated Rust file `controller-core/src/demo/weights.rs`.
pub fn render_rust(model: &ExportModel, report: &ExportReport) -> String {
    let folded = model.folded();
    let (nx, nu) = (model.nx(), model.nu());
    let sizes: Vec<usize> = std::iter::once(nx)
        .chain(model.layers.iter().map(|l| l.b.len()))
        .collect();
    let mut o = String::new();
    header(&mut o, model, report, &sizes);
    let _ = writeln!(o, "/// State dimension.\npub const NX: usize = {nx};");
    let _ = writeln!(o, "/// Input dimension.\npub const NU: usize = {nu};");
    network(&mut o, &folded, &sizes);
    let (lo, hi) = model.domain_f32();
    let v32 = |v: &[f32]| v.iter().map(|x| lit32(*x)).collect::<Vec<_>>();
    o.push('\n');
    const_array(
        &mut o,
        "Lower corner of X in f32 (rounded outward: the f32 box contains X).",
        "pub ",
        "X_LO",
        &format!("[f32; {nx}]"),
        &v32(&lo),
    );
    const_array(
        &mut o,
        "Upper corner of X in f32 (rounded outward: the f32 box contains X).",
        "pub ",
        "X_HI",
        &format!("[f32; {nx}]"),
        &v32(&hi),
    );
    for (k, t) in Tanh::ALL.iter().enumerate() {
        let _ = writeln!(
            o,
            "\n/// The certificate for the {} tanh.\npub const CERTIFICATE_{}: Certificate<{nx}, {nu}> = Certificate {{",
            t.name(),
            t.name().to_uppercase()
        );
        for (f, v) in certificate_literal(model, *t, report, k) {
            let _ = writeln!(o, "    {f}: {v},");
        }
        o.push_str("};\n");
    }
    o
}

/// The generated file's leading comment: what the weights are (or that they are a
/// placeholder), the architecture, the f32 allowance, the guarantee tier and what ε rests
/// on, and how to compile the file.
fn header(o: &mut String, model: &ExportModel, report: &ExportReport, sizes: &[usize]) {
    o.push_str("// @generated by trainer export — do not edit\n");
    if model.placeholder {
        let _ = writeln!(
            o,
            "// PLACEHOLDER weights for `{}`: a deterministic stand-in network, NOT the trained",
            model.name
        );
        o.push_str(
            "// controller and NOT certified (eps_nn = 0; only the f32 allowance is computed).\n\
             // It exists so that the embedded side can be built and tested before training;\n\
             // `trainer export` replaces it with the trained network.\n",
        );
    } else {
        let _ = writeln!(
            o,
            "// Weights and certificates of the `{}` controller.",
            model.name
        );
    }
    let arch: Vec<String> = sizes.iter().map(usize::to_string).collect();
    let _ = writeln!(
        o,
        "//\n// Architecture {} (tanh hidden layers, linear output), input and output scalings\n\
         // folded into the first and last layer (physical units in and out). Model hash:\n\
         // `{}`.",
        arch.join("-"),
        model.hash
    );
    let _ = writeln!(
        o,
        "//\n// f32 allowance (sound bound on |κ_NN,f32 − κ_NN,f64| over X, {} sub-boxes) vs the\n\
         // largest difference on {} random states: accurate tanh {:.3e} vs {:.3e}; fast tanh\n\
         // {:.3e} vs {:.3e}. Guarantee tier of ε: {}.",
        report.boxes,
        report.samples,
        report.f32_allowance[0],
        report.f32_observed[0],
        report.f32_allowance[1],
        report.f32_observed[1],
        model.guarantee.name()
    );
    if let Some(s) = &model.statistical {
        let _ = writeln!(
            o,
            "// ε is a statistical level (eps_nn + the f32 allowance): {}.",
            s.words()
        );
    }
    if !model.rests_on.is_empty() {
        o.push_str(
            "// ε rests on (the certificate's assumptions and premises):
",
        );
        for r in &model.rests_on {
            let _ = writeln!(o, "// - {}", r.replace('\n', " "));
        }
    }
    o.push_str(
        "//\n// Compile it with `controller_core::include_controller!(\"weights.rs\")` (it provides\n\
         // `Certificate`, `Guarantee`, `Dense` and `Hidden`).\n\n",
    );
}

/// The network's type `Net`, its layers' constants `W1, B1, …` and the constant `NET`.
pub(crate) fn network(o: &mut String, folded: &Folded, sizes: &[usize]) {
    // Network type
    let n = sizes.len() - 1; // the number of layers
    let mut ty = format!("Dense<{}, {}>", sizes[n - 1], sizes[n]);
    for k in (0..n - 1).rev() {
        ty = format!("Hidden<{}, {}, {ty}>", sizes[k], sizes[k + 1]);
    }
    let _ = writeln!(
        o,
        "/// The network type: {}.\npub type Net = {ty};\n",
        sizes
            .iter()
            .enumerate()
            .map(|(k, s)| if k == 0 || k == n {
                s.to_string()
            } else {
                format!("{s} (tanh)")
            })
            .collect::<Vec<_>>()
            .join(" → ")
    );
    for (k, (n_in, n_out, w, b)) in folded.f32_layers.iter().enumerate() {
        let items = |r: &[f32]| r.iter().map(|v| lit32(*v)).collect::<Vec<_>>();
        let rows: Vec<String> = w.chunks(*n_in).map(|r| array(&items(r), 4, 4, 1)).collect();
        let name = format!("W{}", k + 1);
        let doc = format!("Layer {} weights ({n_in} → {n_out}, out × in).", k + 1);
        let ty = format!("[[f32; {n_in}]; {n_out}]");
        let head = format!("const {name}: {ty} = ");
        if *n_out == 1 && head.len() + rows[0].len() + 3 > WIDTH {
            // rustfmt writes a lone multi-line row as `[[ … ]]`.
            let _ = writeln!(o, "/// {doc}\n{head}[{}];", array(&items(w), 0, WIDTH, 0));
        } else {
            const_array(o, &doc, "", &name, &ty, &rows);
        }
        let bs: Vec<String> = b.iter().map(|v| lit32(*v)).collect();
        const_array(
            o,
            &format!("Layer {} biases.", k + 1),
            "",
            &format!("B{}", k + 1),
            &format!("[f32; {n_out}]"),
            &bs,
        );
    }
    // NET expression
    let mut expr = format!("Dense::new(W{n}, B{n})");
    for k in (1..n).rev() {
        expr = format!("Hidden::new(Dense::new(W{k}, B{k}), {expr})");
    }
    let _ = writeln!(o, "/// The network, physical units in and out.");
    let line = format!("pub const NET: Net = {expr};");
    if line.len() <= WIDTH {
        let _ = writeln!(o, "{line}");
    } else {
        o.push_str(&nested_call("pub const NET: Net = ", &expr));
    }
}

/// Formats `head` + a nested `Hidden::new(a, Hidden::new(b, c))` call the way rustfmt
/// breaks it: arguments one per line, recursively, when the call does not fit.
fn nested_call(head: &str, expr: &str) -> String {
    fn split_args(inner: &str) -> Vec<String> {
        let mut args = Vec::new();
        let mut depth = 0;
        let mut cur = String::new();
        for c in inner.chars() {
            match c {
                '(' => depth += 1,
                ')' => depth -= 1,
                ',' if depth == 0 => {
                    args.push(cur.trim().to_string());
                    cur.clear();
                    continue;
                }
                _ => {}
            }
            cur.push(c);
        }
        args.push(cur.trim().to_string());
        args
    }
    fn fmt(expr: &str, indent: usize, used: usize, tail: usize) -> String {
        if used + expr.len() + tail <= WIDTH {
            return expr.to_string();
        }
        let open = expr.find('(').unwrap_or(expr.len());
        let name = &expr[..open];
        let inner = &expr[open + 1..expr.len() - 1];
        let pad = " ".repeat(indent + 4);
        let mut s = format!("{name}(\n");
        for a in split_args(inner) {
            let f = fmt(&a, indent + 4, indent + 4, 1);
            let _ = writeln!(s, "{pad}{f},");
        }
        s.push_str(&" ".repeat(indent));
        s.push(')');
        s
    }
    format!("{head}{};\n", fmt(expr, 0, head.len(), 1))
}
