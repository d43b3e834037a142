//! ONNX out: the network as the controller computes it, as an ONNX `ModelProto`
//! (IR 7, opset 13), with the certificate in `metadata_props`.
//!
//! ```text
//! x [N, nx] → Clip to X (f32, rounded outward) → Gemm(W₁', b₁', transB = 1) → α → …
//!           → Gemm(W_L', b_L') → Clip to the band (U_d ⊕ [−ε_tot, ε_tot]) ∩ actuator → u [N, nu]
//! ```
//! `W', b'` are the folded weights rounded to f32 (`Folded::f32_layers`: the scalings folded
//! in f64, then rounded to nearest) — the very numbers of the controller-core blob; X and
//! the band are `ExportModel::domain_f32` and `ExportModel::clamp_band(eps + allowance)`.
//! ONNX `Clip` takes scalar bounds, so a box with different bounds per component is
//! projected component-wise: `Split` (axis 1) → one `Clip` per component → `Concat`.
//! Non-finite states are not mapped to the controller's fallback input (no such op).
//! The weights are FLOAT tensors (raw little-endian data) and stored as initializers; the
//! batch dimension is the symbolic `N`.

use super::proto::Writer;
use crate::deploy::export::ExportModel;
use crate::learn::mlp::Activation;

/// ONNX IR version written (the one of opset 13).
pub const IR_VERSION: i64 = 7;
/// Default-domain opset written.
pub const OPSET: i64 = 13;

fn tensor_f32(name: &str, dims: &[i64], v: &[f32]) -> Writer {
    let mut t = Writer::default();
    t.packed_ints(1, dims)
        .int(2, super::graph::FLOAT)
        .string(8, name);
    let raw: Vec<u8> = v.iter().flat_map(|x| x.to_le_bytes()).collect();
    t.bytes(9, &raw);
    t
}

fn tensor_i64(name: &str, v: &[i64]) -> Writer {
    let mut t = Writer::default();
    t.packed_ints(1, &[v.len() as i64])
        .int(2, super::graph::INT64)
        .string(8, name);
    let raw: Vec<u8> = v.iter().flat_map(|x| x.to_le_bytes()).collect();
    t.bytes(9, &raw);
    t
}

fn node(op: &str, name: &str, inputs: &[&str], outputs: &[&str], attrs: &[Writer]) -> Writer {
    let mut n = Writer::default();
    for i in inputs {
        n.string(1, i);
    }
    for o in outputs {
        n.string(2, o);
    }
    n.string(3, name).string(4, op);
    for a in attrs {
        n.message(5, a);
    }
    n
}

fn attr_int(name: &str, v: i64) -> Writer {
    let mut a = Writer::default();
    // AttributeProto.type INT = 2.
    a.string(1, name).int(3, v).int(20, 2);
    a
}

fn value_info(name: &str, width: usize) -> Writer {
    let mut batch = Writer::default();
    batch.string(2, "N");
    let mut w = Writer::default();
    w.int(1, width as i64);
    let mut shape = Writer::default();
    shape.message(1, &batch).message(1, &w);
    let mut tt = Writer::default();
    tt.int(1, super::graph::FLOAT).message(2, &shape);
    let mut ty = Writer::default();
    ty.message(1, &tt);
    let mut vi = Writer::default();
    vi.string(1, name).message(2, &ty);
    vi
}

/// Graph under construction: nodes and initializers.
#[derive(Default)]
struct Graph {
    nodes: Vec<Writer>,
    inits: Vec<Writer>,
}

impl Graph {
    /// Component-wise `Clip` of `input` (width n) to [lo, hi] into `output`.
    fn clip_box(&mut self, tag: &str, input: &str, output: &str, lo: &[f32], hi: &[f32]) {
        let n = lo.len();
        let same = lo.iter().all(|v| *v == lo[0]) && hi.iter().all(|v| *v == hi[0]);
        let clip = |g: &mut Graph, k: usize, i: &str, o: &str| {
            let (l, h) = (format!("{tag}_lo_{k}"), format!("{tag}_hi_{k}"));
            g.inits.push(tensor_f32(&l, &[], &[lo[k]]));
            g.inits.push(tensor_f32(&h, &[], &[hi[k]]));
            g.nodes.push(node(
                "Clip",
                &format!("{tag}_clip_{k}"),
                &[i, l.as_str(), h.as_str()],
                &[o],
                &[],
            ));
        };
        if n == 1 || same {
            clip(self, 0, input, output);
            return;
        }
        let split = format!("{tag}_split_sizes");
        self.inits.push(tensor_i64(&split, &vec![1; n]));
        let parts: Vec<String> = (0..n).map(|k| format!("{tag}_{k}")).collect();
        let clipped: Vec<String> = (0..n).map(|k| format!("{tag}_{k}_clipped")).collect();
        let p: Vec<&str> = parts.iter().map(String::as_str).collect();
        self.nodes.push(node(
            "Split",
            &format!("{tag}_split"),
            &[input, split.as_str()],
            &p,
            &[attr_int("axis", 1)],
        ));
        for (k, (p, c)) in parts.iter().zip(&clipped).enumerate() {
            clip(self, k, p, c);
        }
        let c: Vec<&str> = clipped.iter().map(String::as_str).collect();
        self.nodes.push(node(
            "Concat",
            &format!("{tag}_concat"),
            &c,
            &[output],
            &[attr_int("axis", 1)],
        ));
    }
}

/// A number as metadata text (`{:?}`: round-trips every f64).
fn num(v: f64) -> String {
    format!("{v:?}")
}

fn list(v: &[f64]) -> String {
    format!(
        "[{}]",
        v.iter().map(|x| num(*x)).collect::<Vec<_>>().join(", ")
    )
}

/// The guarantee the certificate makes, in words (`ampc.guarantee`).
pub fn guarantee(model: &ExportModel, allowance: Option<f64>) -> String {
    // The certificate's norm: ‖S_u⁻¹·‖₂ when it is scaled (crate::certify::norm).
    let diff = if model.u_scale.iter().all(|s| *s == 1.0) {
        "‖κ_MPC(x) − κ_NN(x)‖₂".to_string()
    } else {
        format!(
            "‖S_u⁻¹(κ_MPC(x) − κ_NN(x))‖₂ (S_u = diag{}, so input j errs by ≤ S_u,j·ε)",
            list(&model.u_scale)
        )
    };
    let mut s = format!(
        "for every state x in the box X = {} … {}: {diff} ≤ {} (ampc.eps; \
         tier: {}, ampc.tier) for the f64 network",
        list(&model.domain_lo),
        list(&model.domain_hi),
        num(model.eps),
        model.guarantee.name()
    );
    match allowance {
        Some(a) => s += &format!(
            "; the f32 network of controller-core (libm tanhf) is within {} more (ampc.f32_allowance)",
            num(a)
        ),
        None => s += "; no f32 allowance was computed for this activation (add the runtime's f32 error)",
    }
    if let Some(st) = &model.statistical {
        s += &format!("; ε is a statistical level: {}", st.words());
    } else if model.l_mpc_is_estimate {
        s += "; L_MPC is a sampled estimate, not a proven bound";
    }
    if !model.rests_on.is_empty() {
        s += &format!("; ε rests on: {}", model.rests_on.join("; "));
    }
    s
}

/// The `metadata_props` of an export: the certificate's numbers under `ampc.*` keys.
pub fn metadata(
    model: &ExportModel,
    activation: Activation,
    allowance: Option<f64>,
) -> Vec<(String, String)> {
    let (clo, chi) = model.clamp_band(model.eps + allowance.unwrap_or(0.0));
    let f = |v: &[f32]| list(&v.iter().map(|x| f64::from(*x)).collect::<Vec<_>>());
    let kv = [
        ("ampc.eps", num(model.eps)),
        ("ampc.guarantee", guarantee(model, allowance)),
        ("ampc.tier", model.guarantee.name().to_string()),
        (
            "ampc.excluded_boxes",
            if model.excluded.is_empty() {
                "[]".into()
            } else {
                serde_json::to_string(&model.excluded).unwrap_or_default()
            },
        ),
        ("ampc.hash", model.hash.clone()),
        ("ampc.eps_d", num(model.eps_d)),
        ("ampc.l_nn", num(model.l_nn)),
        ("ampc.l_nn_method", model.l_nn_method.clone()),
        ("ampc.l_mpc", num(model.l_mpc)),
        (
            "ampc.l_mpc_is_estimate",
            model.l_mpc_is_estimate.to_string(),
        ),
        ("ampc.covering_radius", num(model.covering_radius)),
        (
            "ampc.f32_allowance",
            allowance.map_or("not computed".into(), num),
        ),
        ("ampc.domain_lo", list(&model.domain_lo)),
        ("ampc.domain_hi", list(&model.domain_hi)),
        ("ampc.u_lo", list(&model.u_lo)),
        ("ampc.u_hi", list(&model.u_hi)),
        ("ampc.clamp_lo", f(&clo)),
        ("ampc.clamp_hi", f(&chi)),
        ("ampc.activation", format!("{activation:?}").to_lowercase()),
        ("ampc.name", model.name.clone()),
    ];
    kv.into_iter().map(|(k, v)| (k.to_string(), v)).collect()
}

/// The ONNX file of `model` (validated by the caller) with hidden activation `activation`;
/// `allowance` is the f32 allowance added to ε for the clamp band (`None`: ε alone).
pub fn render_onnx(model: &ExportModel, activation: Activation, allowance: Option<f64>) -> Vec<u8> {
    let folded = model.folded();
    let (dlo, dhi) = model.domain_f32();
    let (clo, chi) = model.clamp_band(model.eps + allowance.unwrap_or(0.0));
    let mut g = Graph::default();
    g.clip_box("x", "x", "x_projected", &dlo, &dhi);
    let mut prev = "x_projected".to_string();
    let n = folded.f32_layers.len();
    let act = match activation {
        Activation::Tanh => "Tanh",
        Activation::Relu => "Relu",
        Activation::Softplus => "Softplus",
    };
    for (k, (inp, out, w, b)) in folded.f32_layers.iter().enumerate() {
        let (wn, bn, zn) = (format!("W{k}"), format!("b{k}"), format!("z{k}"));
        g.inits
            .push(tensor_f32(&wn, &[*out as i64, *inp as i64], w));
        g.inits.push(tensor_f32(&bn, &[*out as i64], b));
        g.nodes.push(node(
            "Gemm",
            &format!("layer{k}"),
            &[prev.as_str(), wn.as_str(), bn.as_str()],
            &[zn.as_str()],
            &[attr_int("transB", 1)],
        ));
        prev = zn;
        if k + 1 < n {
            let an = format!("a{k}");
            g.nodes.push(node(
                act,
                &format!("{}{k}", act.to_lowercase()),
                &[prev.as_str()],
                &[an.as_str()],
                &[],
            ));
            prev = an;
        }
    }
    g.clip_box("u", &prev, "u", &clo, &chi);
    let mut graph = Writer::default();
    for nd in &g.nodes {
        graph.message(1, nd);
    }
    graph.string(2, &format!("ampc_{}", model.name));
    for t in &g.inits {
        graph.message(5, t);
    }
    graph.message(11, &value_info("x", model.nx()));
    graph.message(12, &value_info("u", model.nu()));
    let mut opset = Writer::default();
    opset.string(1, "").int(2, OPSET);
    let mut m = Writer::default();
    m.int(1, IR_VERSION)
        .string(2, "ampc-trainer")
        .string(3, env!("CARGO_PKG_VERSION"))
        .message(7, &graph)
        .message(8, &opset);
    for (k, v) in metadata(model, activation, allowance) {
        let mut e = Writer::default();
        e.string(1, &k).string(2, &v);
        m.message(14, &e);
    }
    m.buf
}
