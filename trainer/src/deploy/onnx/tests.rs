//! ONNX out → in round trips, torch-shaped graphs (Gemm with and without transB, MatMul +
//! Add, Constant nodes, Sub/Div and Mul/Add scaling), and refusals naming the node.

use super::graph::{decode, FLOAT};
use super::proto::Writer;
use super::*;
use crate::deploy::export::{DenseF64, ExportModel, Scaling};
use crate::learn::mlp::{Activation, Mlp, Workspace};

/// A small export model with distinct per-component scalings and domain bounds.
fn export_model(seed: u64) -> ExportModel {
    let mut em = crate::deploy::export::placeholder_pendulum();
    let m = Mlp::new(
        &[2, 7, 5, 1],
        Activation::Tanh,
        seed,
        &[-3.0, -1.5],
        &[2.0, 1.0],
        &[-4.0],
        &[6.0],
    );
    em.layers = m
        .layers
        .iter()
        .map(|l| DenseF64 {
            w: l.w.chunks(l.inp).map(<[f64]>::to_vec).collect(),
            b: l.b
                .iter()
                .enumerate()
                .map(|(i, _)| 0.1 * i as f64 - 0.2)
                .collect(),
        })
        .collect();
    em.input = Scaling {
        mean: m.in_center.clone(),
        scale: m.in_half.clone(),
    };
    em.output = Scaling {
        mean: m.out_center.clone(),
        scale: m.out_half.clone(),
    };
    em.domain_lo = vec![-3.0, -1.5];
    em.domain_hi = vec![2.0, 1.0];
    em.u_lo = vec![-4.0];
    em.u_hi = vec![6.0];
    em.actuator_lo = vec![-5.0];
    em.actuator_hi = vec![7.0];
    em.eps = 0.25;
    em.hash = "abc123".into();
    em.placeholder = false;
    em
}

#[test]
fn export_then_import_gives_the_controllers_f32_weights_exactly() {
    for act in [Activation::Tanh, Activation::Relu, Activation::Softplus] {
        let em = export_model(3);
        em.validate().unwrap();
        let bytes = render_onnx(&em, act, Some(1e-6));
        let (model, notes) = import_bytes(&bytes, "mem.onnx").unwrap();
        assert!(notes.ampc_export);
        assert_eq!(notes.opset, write::OPSET);
        // 2 input components (different bounds: Split/Clip×2/Concat) + 1 output Clip.
        assert_eq!(notes.clips_dropped, 3);
        let m = &model.mlp;
        assert_eq!(m.activation, act);
        assert_eq!(m.widths(), vec![2, 7, 5, 1]);
        let folded = em.folded();
        for (l, (inp, out, w, b)) in m.layers.iter().zip(&folded.f32_layers) {
            assert_eq!((l.inp, l.out), (*inp, *out));
            let w64: Vec<f64> = w.iter().map(|v| f64::from(*v)).collect();
            let b64: Vec<f64> = b.iter().map(|v| f64::from(*v)).collect();
            assert_eq!(l.w, w64, "weights bit for bit");
            assert_eq!(l.b, b64, "biases bit for bit");
        }
        assert_eq!(m.in_center, vec![0.0, 0.0]);
        assert_eq!(m.in_half, vec![1.0, 1.0]);
        assert_eq!(m.out_center, vec![0.0]);
        assert_eq!(m.out_half, vec![1.0]);
        assert_eq!(model.content_hash(), crate::io::sha256_hex(&bytes));
        // Export of the import: the same tensors (folding an identity scaling is exact).
        let mut em2 = em.clone();
        em2.layers = m
            .layers
            .iter()
            .map(|l| DenseF64 {
                w: l.w.chunks(l.inp).map(<[f64]>::to_vec).collect(),
                b: l.b.clone(),
            })
            .collect();
        em2.input = Scaling::identity(2);
        em2.output = Scaling::identity(1);
        assert_eq!(render_onnx(&em2, act, Some(1e-6)), bytes);
    }
}

#[test]
fn export_metadata_holds_the_certificate() {
    let em = export_model(5);
    let g = decode(&render_onnx(&em, Activation::Tanh, Some(2e-6))).unwrap();
    assert_eq!(g.meta("ampc.eps"), Some("0.25"));
    assert_eq!(g.meta("ampc.hash"), Some("abc123"));
    assert_eq!(g.meta("ampc.f32_allowance"), Some("2e-6"));
    assert!(g.meta("ampc.guarantee").unwrap().contains("≤ 0.25"));
    assert_eq!(g.opsets, vec![(String::new(), write::OPSET)]);
    // The clamp band: U_d ⊕ (ε + allowance), within the actuator limits.
    let (lo, hi) = em.clamp_band(0.25 + 2e-6);
    assert_eq!(
        g.meta("ampc.clamp_lo").unwrap(),
        format!("[{:?}]", f64::from(lo[0]))
    );
    assert!(f64::from(hi[0]) >= 6.25 && f64::from(lo[0]) <= -4.25);
}

// ---- Graphs shaped like torch.onnx.export's ----

fn tensor(name: &str, dims: &[i64], v: &[f32], raw: bool) -> Writer {
    let mut t = Writer::default();
    t.packed_ints(1, dims).int(2, FLOAT).string(8, name);
    if raw {
        let b: Vec<u8> = v.iter().flat_map(|x| x.to_le_bytes()).collect();
        t.bytes(9, &b);
    } else {
        let b: Vec<u8> = v.iter().flat_map(|x| x.to_le_bytes()).collect();
        t.bytes(4, &b);
    }
    t
}

fn attr_i(name: &str, v: i64) -> Writer {
    let mut a = Writer::default();
    a.string(1, name).int(3, v).int(20, 2);
    a
}

fn attr_t(name: &str, t: &Writer) -> Writer {
    let mut a = Writer::default();
    a.string(1, name).message(5, t).int(20, 4);
    a
}

fn node(op: &str, name: &str, ins: &[&str], outs: &[&str], attrs: &[Writer]) -> Writer {
    let mut n = Writer::default();
    for i in ins {
        n.string(1, i);
    }
    for o in outs {
        n.string(2, o);
    }
    n.string(3, name).string(4, op);
    for a in attrs {
        n.message(5, a);
    }
    n
}

fn io(name: &str, width: i64) -> Writer {
    let mut b = Writer::default();
    b.string(2, "batch_size");
    let mut w = Writer::default();
    w.int(1, width);
    let mut sh = Writer::default();
    sh.message(1, &b).message(1, &w);
    let mut tt = Writer::default();
    tt.int(1, FLOAT).message(2, &sh);
    let mut ty = Writer::default();
    ty.message(1, &tt);
    let mut v = Writer::default();
    v.string(1, name).message(2, &ty);
    v
}

fn model(nodes: &[Writer], inits: &[Writer], nx: i64, nu: i64, out: &str) -> Vec<u8> {
    let mut g = Writer::default();
    for n in nodes {
        g.message(1, n);
    }
    g.string(2, "main_graph");
    for t in inits {
        g.message(5, t);
    }
    g.message(11, &io("input", nx)).message(12, &io(out, nu));
    let mut op = Writer::default();
    op.string(1, "").int(2, 13);
    let mut m = Writer::default();
    m.int(1, 7)
        .string(2, "pytorch")
        .message(7, &g)
        .message(8, &op);
    m.buf
}

/// Weights of a 2-3-1 net: W1 (3×2), b1, W2 (1×3), b2; scalings mean/std and scale/offset.
struct Net {
    w1: Vec<f32>,
    b1: Vec<f32>,
    w2: Vec<f32>,
    b2: Vec<f32>,
    mean: Vec<f32>,
    std: Vec<f32>,
    scale: f32,
    offset: f32,
}

fn net() -> Net {
    Net {
        w1: vec![0.5, -1.25, 0.75, 0.3, -0.6, 1.1],
        b1: vec![0.1, -0.2, 0.05],
        w2: vec![1.5, -0.7, 0.9],
        b2: vec![0.01],
        mean: vec![0.25, -0.5],
        std: vec![2.0, 0.8],
        scale: 3.5,
        offset: -0.4,
    }
}

fn reference(n: &Net, act: fn(f64) -> f64, x: &[f64]) -> f64 {
    let a: Vec<f64> = (0..2)
        .map(|i| (x[i] - f64::from(n.mean[i])) / f64::from(n.std[i]))
        .collect();
    let h: Vec<f64> = (0..3)
        .map(|r| {
            act(f64::from(n.b1[r])
                + f64::from(n.w1[2 * r]) * a[0]
                + f64::from(n.w1[2 * r + 1]) * a[1])
        })
        .collect();
    let y = f64::from(n.b2[0]) + (0..3).map(|r| f64::from(n.w2[r]) * h[r]).sum::<f64>();
    y * f64::from(n.scale) + f64::from(n.offset)
}

fn transpose(w: &[f32], rows: usize, cols: usize) -> Vec<f32> {
    let mut t = vec![0.0; w.len()];
    for r in 0..rows {
        for c in 0..cols {
            t[c * rows + r] = w[r * cols + c];
        }
    }
    t
}

fn check(bytes: &[u8], n: &Net, act: Activation, f: fn(f64) -> f64) {
    let (m, notes) = import_bytes(bytes, "torch.onnx").unwrap();
    assert!(!notes.ampc_export);
    assert_eq!(m.mlp.activation, act);
    assert_eq!(m.mlp.in_center, vec![0.25, -0.5]);
    assert_eq!(m.mlp.in_half, vec![2.0, f64::from(0.8f32)]);
    assert_eq!(m.mlp.out_half, vec![3.5]);
    assert_eq!(m.mlp.out_center, vec![f64::from(-0.4f32)]);
    let mut ws = Workspace::default();
    for x in [[0.3, -0.2], [-1.7, 0.9], [2.5, 1.1]] {
        let (mut u, mut j) = ([0.0], [0.0; 2]);
        m.mlp.eval(&x, &mut u, &mut j, &mut ws);
        let r = reference(n, f, &x);
        assert!(
            (u[0] - r).abs() < 1e-12 * (1.0 + r.abs()),
            "{} vs {r}",
            u[0]
        );
    }
}

/// torch ≤ 1.x / TorchScript exporter: Sub/Div by initializers, Gemm (transB = 1), Tanh,
/// Mul/Add by Constant nodes.
#[test]
fn torch_style_gemm_graph_imports() {
    let n = net();
    let c = |name: &str, v: f32| {
        node(
            "Constant",
            &format!("Constant_{name}"),
            &[],
            &[name],
            &[attr_t("value", &tensor("", &[], &[v], true))],
        )
    };
    let nodes = [
        node("Sub", "Sub_0", &["input", "mean"], &["s"], &[]),
        node("Div", "Div_1", &["s", "std"], &["d"], &[]),
        node(
            "Gemm",
            "Gemm_2",
            &["d", "net.0.weight", "net.0.bias"],
            &["g"],
            &[attr_i("transB", 1)],
        ),
        node("Tanh", "Tanh_3", &["g"], &["t"], &[]),
        node(
            "Gemm",
            "Gemm_4",
            &["t", "net.2.weight", "net.2.bias"],
            &["y"],
            &[attr_i("transB", 1)],
        ),
        c("k_scale", n.scale),
        node("Mul", "Mul_5", &["y", "k_scale"], &["ys"], &[]),
        c("k_offset", n.offset),
        node("Add", "Add_6", &["ys", "k_offset"], &["output"], &[]),
    ];
    let inits = [
        tensor("mean", &[2], &n.mean, true),
        tensor("std", &[2], &n.std, false),
        tensor("net.0.weight", &[3, 2], &n.w1, true),
        tensor("net.0.bias", &[3], &n.b1, true),
        tensor("net.2.weight", &[1, 3], &n.w2, true),
        tensor("net.2.bias", &[1], &n.b2, true),
    ];
    check(
        &model(&nodes, &inits, 2, 1, "output"),
        &n,
        Activation::Tanh,
        f64::tanh,
    );
}

/// MatMul (weights [in, out]) + Add bias, Gemm without transB, Relu, Softplus.
#[test]
fn matmul_add_and_untransposed_gemm_import() {
    let n = net();
    let relu = |z: f64| z.max(0.0);
    let softplus = |z: f64| z.exp().ln_1p();
    for (act, opname, f) in [
        (Activation::Relu, "Relu", relu as fn(f64) -> f64),
        (Activation::Softplus, "Softplus", softplus as fn(f64) -> f64),
    ] {
        let nodes = [
            node("Sub", "sub", &["input", "mean"], &["s"], &[]),
            node("Div", "div", &["s", "std"], &["d"], &[]),
            node("MatMul", "mm0", &["d", "W0t"], &["m0"], &[]),
            node("Add", "add0", &["m0", "b0"], &["g"], &[]),
            node(opname, "act", &["g"], &["t"], &[]),
            node("Gemm", "gemm1", &["t", "W1t", "b1"], &["y"], &[]),
            node("Mul", "mul", &["scale", "y"], &["ys"], &[]),
            node("Add", "add", &["ys", "offset"], &["output"], &[]),
        ];
        let inits = [
            tensor("mean", &[1, 2], &n.mean, true),
            tensor("std", &[2], &n.std, true),
            tensor("W0t", &[2, 3], &transpose(&n.w1, 3, 2), true),
            tensor("b0", &[3], &n.b1, true),
            tensor("W1t", &[3, 1], &transpose(&n.w2, 1, 3), true),
            tensor("b1", &[1], &n.b2, true),
            tensor("scale", &[1], &[n.scale], true),
            tensor("offset", &[], &[n.offset], true),
        ];
        check(&model(&nodes, &inits, 2, 1, "output"), &n, act, f);
    }
}

#[test]
fn unsupported_graphs_are_refused_naming_the_node() {
    let n = net();
    let inits = [
        tensor("W", &[3, 2], &n.w1, true),
        tensor("b", &[3], &n.b1, true),
        tensor("W2", &[1, 3], &n.w2, true),
    ];
    let gemm = |name: &str, i: &str, w: &str, o: &str| {
        node("Gemm", name, &[i, w, "b"], &[o], &[attr_i("transB", 1)])
    };
    let cases: Vec<(Vec<Writer>, &str)> = vec![
        (
            vec![
                gemm("fc1", "input", "W", "g"),
                node("Sigmoid", "my_sigmoid", &["g"], &["t"], &[]),
                node("MatMul", "fc2", &["t", "W2"], &["output"], &[]),
            ],
            "node 'my_sigmoid' (Sigmoid): unsupported operator Sigmoid",
        ),
        (
            vec![
                gemm("fc1", "input", "W", "g"),
                node("Tanh", "t1", &["g"], &["output"], &[]),
            ],
            "node 't1' (Tanh): an activation after the last layer",
        ),
        (
            vec![
                gemm("fc1", "input", "W", "g"),
                node("Tanh", "t1", &["g"], &["t"], &[]),
                node("Clip", "clamp", &["t", "", ""], &["output"], &[]),
            ],
            "node 'clamp' (Clip): unsupported operator Clip",
        ),
        (
            vec![
                gemm("fc1", "input", "W", "g"),
                node("Tanh", "t1", &["g"], &["t"], &[]),
                node("Mul", "mid", &["t", "t"], &["output"], &[]),
            ],
            "node 'mid' (Mul): input 't' is not a constant",
        ),
        (
            vec![
                gemm("fc1", "input", "W", "g"),
                node("Tanh", "t1", &["g"], &["t"], &[]),
                node("Relu", "r1", &["t"], &["r"], &[]),
                node("MatMul", "fc2", &["r", "W2"], &["output"], &[]),
            ],
            "node 'r1' (Relu): two activations in a row",
        ),
    ];
    for (nodes, want) in cases {
        let bytes = model(&nodes, &inits, 2, 1, "output");
        let e = import_bytes(&bytes, "foreign.onnx")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("foreign.onnx") && e.contains(want),
            "{e}\nwanted: {want}"
        );
    }
    let e = import_bytes(b"not a model at all", "junk.bin")
        .unwrap_err()
        .to_string();
    assert!(e.contains("junk.bin") && e.contains("neither"), "{e}");
}
