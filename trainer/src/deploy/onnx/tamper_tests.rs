//! ONNX files that are not what they say: an ampc export whose Clip bounds
//! were edited, a file without a default-domain opset or with one outside the supported
//! range, and duplicate initializer names — each refused, naming what is wrong.

use super::graph::FLOAT;
use super::proto::Writer;
use super::*;
use crate::deploy::export::placeholder_pendulum;
use crate::learn::mlp::Activation;

/// The ONNX export of the pendulum placeholder: X = [−2π, 2π] × [−1, 1] (Split, two Clips,
/// Concat), one output Clip to the band.
fn export() -> Vec<u8> {
    let mut em = placeholder_pendulum();
    em.hash = "feed".into();
    render_onnx(&em, Activation::Tanh, Some(1e-6))
}

/// `bytes` with the f32 value of the scalar initializer `name` replaced by `v`: the raw
/// data field (9, 4 bytes) follows the name in the tensor the exporter writes.
fn edit_scalar(bytes: &[u8], name: &str, v: f32) -> Vec<u8> {
    let mut pat = Vec::from(name.as_bytes());
    pat.extend_from_slice(&[0x4a, 0x04]);
    let at = bytes
        .windows(pat.len())
        .position(|w| w == pat.as_slice())
        .unwrap_or_else(|| panic!("initializer {name} not found"))
        + pat.len();
    let mut out = bytes.to_vec();
    out[at..at + 4].copy_from_slice(&v.to_le_bytes());
    out
}

#[test]
fn an_unedited_export_drops_its_three_clips() {
    let (m, notes) = import_bytes(&export(), "w.onnx").unwrap();
    assert_eq!(notes.clips_dropped, 3);
    assert_eq!(m.mlp.widths(), vec![2, 10, 10, 1]);
}

#[test]
fn an_edited_clamp_is_refused_naming_the_node_and_bounds() {
    // The clamp band edited to ±0.5: onnxruntime would return −0.5 where the net gives −2.81.
    let b = edit_scalar(&export(), "u_lo_0", -0.5);
    let b = edit_scalar(&b, "u_hi_0", 0.5);
    let e = import_bytes(&b, "edited.onnx").unwrap_err().to_string();
    assert!(
        e.contains("edited.onnx") && e.contains("u_clip_0") && e.contains("[-0.5, 0.5]"),
        "{e}"
    );
    // One bound alone is enough.
    let b = edit_scalar(&export(), "u_hi_0", 14.0);
    let e = import_bytes(&b, "edited.onnx").unwrap_err().to_string();
    assert!(e.contains("u_clip_0") && e.contains("clamp band"), "{e}");
}

#[test]
fn an_edited_projection_is_refused() {
    // The domain's second component narrowed from [−1, 1] to [−1, 0.25].
    let b = edit_scalar(&export(), "x_hi_1", 0.25);
    let e = import_bytes(&b, "edited.onnx").unwrap_err().to_string();
    assert!(
        e.contains("x_clip_1") && e.contains("0.25") && e.contains("domain X"),
        "{e}"
    );
}

// ---- Hand-built graphs: opsets and tensor names ----

fn tensor(name: &str, dims: &[i64], v: &[f32]) -> Writer {
    let mut t = Writer::default();
    t.packed_ints(1, dims).int(2, FLOAT).string(8, name);
    let b: Vec<u8> = v.iter().flat_map(|x| x.to_le_bytes()).collect();
    t.bytes(9, &b);
    t
}

fn value_info(name: &str, width: i64) -> Writer {
    let mut n = Writer::default();
    n.string(2, "N");
    let mut w = Writer::default();
    w.int(1, width);
    let mut sh = Writer::default();
    sh.message(1, &n).message(1, &w);
    let mut tt = Writer::default();
    tt.int(1, FLOAT).message(2, &sh);
    let mut ty = Writer::default();
    ty.message(1, &tt);
    let mut v = Writer::default();
    v.string(1, name).message(2, &ty);
    v
}

/// `u = x·Wᵀ + b` (2 → 1) with the given opset imports and initializers.
fn gemm_model(opsets: &[(&str, i64)], inits: &[Writer]) -> Vec<u8> {
    let mut attr = Writer::default();
    attr.string(1, "transB").int(3, 1).int(20, 2);
    let mut node = Writer::default();
    node.string(1, "x")
        .string(1, "W")
        .string(1, "b")
        .string(2, "u")
        .string(3, "gemm")
        .string(4, "Gemm")
        .message(5, &attr);
    let mut g = Writer::default();
    g.message(1, &node).string(2, "g");
    for t in inits {
        g.message(5, t);
    }
    g.message(11, &value_info("x", 2))
        .message(12, &value_info("u", 1));
    let mut m = Writer::default();
    m.int(1, 7).string(2, "handmade").message(7, &g);
    for (d, v) in opsets {
        let mut o = Writer::default();
        o.string(1, d).int(2, *v);
        m.message(8, &o);
    }
    m.buf
}

fn weights() -> Vec<Writer> {
    vec![
        tensor("W", &[1, 2], &[0.5, -2.0]),
        tensor("b", &[1], &[0.25]),
    ]
}

#[test]
fn the_default_domain_opset_must_be_present_and_supported() {
    let ok = gemm_model(&[("", 13)], &weights());
    let (m, notes) = import_bytes(&ok, "ok.onnx").unwrap();
    assert_eq!((notes.opset, m.mlp.widths()), (13, vec![2, 1]));
    for v in [1, 6, 23, 99] {
        let e = import_bytes(&gemm_model(&[("", v)], &weights()), "o.onnx")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(&format!("default-domain opset {v} is not supported")),
            "{v}: {e}"
        );
    }
    let e = import_bytes(&gemm_model(&[("ai.onnx.ml", 3)], &weights()), "o.onnx")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("no default-domain") && e.contains("'ai.onnx.ml' 3"),
        "{e}"
    );
}

#[test]
fn duplicate_initializer_names_are_refused() {
    let mut inits = weights();
    inits.push(tensor("W", &[1, 2], &[7.0, 7.0]));
    let e = import_bytes(&gemm_model(&[("", 13)], &inits), "dup.onnx")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("dup.onnx") && e.contains("initializer 'W' is defined twice"),
        "{e}"
    );
}
