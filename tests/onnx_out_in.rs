//! ONNX out and in, end to end.
//!
//! - The exported ONNX file, run by an independent ONNX runtime (`tract-onnx`) on 10⁴
//!   states (inside and around X, so the projection and the clamp are exercised), computes
//!   what the controller computes to f32 rounding.
//! - A network trained in PyTorch and exported with `torch.onnx.export` (the committed
//!   fixtures `reference/di_tanh.onnx`, `di_relu.onnx`, made by `reference/torch_export.py`)
//!   is evaluated, certified (`certify`, `refine --certify-only`) and exported (`export
//!   --onnx`, and `--rust/--postcard` for the tanh net) by the `trainer` binary without
//!   editing the file; the certificate binds the file's hash.
//! - Unsupported graphs are refused with the node named.

use ampc_tests::{config, tempdir, trainer};
use std::path::{Path, PathBuf};
use tract_onnx::prelude::*;
use trainer::deploy::export::{eval_f32, ExportModel, Tanh};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("reference")
        .join(name)
}

/// Runs an ONNX file with tract on `xs` (n × nx, f32) and returns u (n × nu).
fn tract_run(bytes: &[u8], xs: &[f32], nx: usize) -> Vec<f32> {
    let n = xs.len() / nx;
    let plan = tract_onnx::onnx()
        .model_for_read(&mut &bytes[..])
        .expect("tract reads the file")
        .with_input_fact(0, f32::fact([n, nx]).into())
        .expect("input fact")
        .into_optimized()
        .expect("optimise")
        .into_runnable()
        .expect("runnable");
    let input = tract_ndarray::Array2::from_shape_vec((n, nx), xs.to_vec()).expect("shape");
    let out = plan
        .run(tvec!(Tensor::from(input).into()))
        .expect("tract runs");
    out[0]
        .to_array_view::<f32>()
        .expect("f32 output")
        .iter()
        .copied()
        .collect()
}

/// 10⁴ seeded states in X widened by 20 % on each side.
fn states(lo: &[f64], hi: &[f64]) -> Vec<f32> {
    let mut s: u64 = 0x0DD5_EED5;
    let mut out = Vec::new();
    for _ in 0..10_000 {
        for (l, h) in lo.iter().zip(hi) {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let t = (s >> 11) as f64 / (1u64 << 53) as f64;
            let w = h - l;
            out.push((l - 0.2 * w + 1.4 * w * t) as f32);
        }
    }
    out
}

/// The controller's output (controller-core's arithmetic with libm tanh, then the clamp).
fn controller(em: &ExportModel, allowance: f64, xs: &[f32]) -> Vec<f32> {
    let folded = em.folded();
    let (dlo, dhi) = em.domain_f32();
    let (clo, chi) = em.clamp_band(em.eps + allowance);
    xs.chunks(em.nx())
        .flat_map(|x| {
            eval_f32(&folded, &dlo, &dhi, x, Tanh::Libm)
                .into_iter()
                .enumerate()
                .map(|(j, u)| u.max(clo[j]).min(chi[j]))
                .collect::<Vec<_>>()
        })
        .collect()
}

/// Largest |a − b| and the largest |a| (for the f32 rounding scale).
fn max_diff(a: &[f32], b: &[f32]) -> (f64, f64) {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).fold((0.0, 0.0), |(d, m), (x, y)| {
        (
            f64::max(d, (f64::from(*x) - f64::from(*y)).abs()),
            f64::max(m, f64::from(x.abs())),
        )
    })
}

#[test]
fn tract_computes_what_the_controller_computes() {
    let em = trainer::deploy::export::placeholder_pendulum();
    let report = trainer::deploy::export::certify_f32(&em).unwrap();
    let a = report.f32_allowance[0];
    let bytes =
        trainer::deploy::onnx::render_onnx(&em, trainer::learn::mlp::Activation::Tanh, Some(a));
    let xs = states(&em.domain_lo, &em.domain_hi);
    let got = tract_run(&bytes, &xs, em.nx());
    let want = controller(&em, a, &xs);
    let (d, scale) = max_diff(&got, &want);
    // Both are f32 evaluations of the same f32 network: they may differ by the order of the
    // sums and the tanh implementation, each within the sound f32 allowance of the f64 net.
    eprintln!(
        "tract vs controller on 10^4 states: max |Δu| {d:.3e} (allowance {a:.3e}, |u| ≤ {scale})"
    );
    assert!(
        d <= 2.0 * a,
        "tract differs from the controller by {d:e} > 2·{a:e}"
    );
    // And the projection and clamp are there: states outside X give the output at the
    // projected state, within the band.
    let (clo, chi) = em.clamp_band(em.eps + a);
    assert!(got.iter().all(|u| *u >= clo[0] && *u <= chi[0]));
}

fn sample_di(d: &Path) -> (String, String) {
    let cfg = d.join("di.toml");
    std::fs::copy(config("double_integrator.toml"), &cfg).unwrap();
    let data = d.join("di.bin");
    let o = trainer(&[
        "sample",
        "--config",
        cfg.to_str().unwrap(),
        "--out",
        data.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    (
        cfg.to_str().unwrap().to_string(),
        data.to_str().unwrap().to_string(),
    )
}

fn ok(o: &std::process::Output) -> String {
    assert!(
        o.status.success(),
        "{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn sha256(p: &Path) -> String {
    trainer::io::sha256_hex(&std::fs::read(p).unwrap())
}

#[test]
fn pytorch_net_is_certified_and_exported_unedited() {
    let dir = tempdir();
    let d = dir.path();
    let (cfg, data) = sample_di(d);
    let net = fixture("di_tanh.onnx");
    let netp = net.to_str().unwrap();
    // eval: the ONNX file is read by content.
    let states_csv = d.join("states.csv");
    std::fs::write(&states_csv, "x1,x2\n0.5,-0.25\n-3.0,0.75\n").unwrap();
    let ev = d.join("eval.csv");
    let log = ok(&trainer(&[
        "eval",
        "--raw",
        "--model",
        netp,
        "--states",
        states_csv.to_str().unwrap(),
        "--out",
        ev.to_str().unwrap(),
    ]));
    assert!(log.contains("ONNX"), "{log}");
    let evtext = std::fs::read_to_string(&ev).unwrap();
    assert_eq!(evtext.lines().count(), 3);
    // certify (Theorem 1 on the sampled grid): the certificate binds the file's hash.
    let o = trainer(&[
        "certify", "--config", &cfg, "--model", netp, "--data", &data, "--json",
    ]);
    ok(&o);
    let c: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(c["hash"], sha256(&net));
    let eps_global = c["eps"].as_f64().unwrap();
    assert!(eps_global.is_finite() && eps_global > 0.0);
    // refine --certify-only: the net fixed, cells refined to a target.
    let out = d.join("refine");
    let target = 0.5;
    let log = ok(&trainer(&[
        "refine",
        "--config",
        &cfg,
        "--certify-only",
        "--model",
        netp,
        "--target-eps",
        &target.to_string(),
        "--budget",
        "3000",
        "--out",
        out.to_str().unwrap(),
        "--quiet",
    ]));
    let cert_path = out.join("certificate.json");
    let lc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&cert_path).unwrap()).unwrap();
    assert_eq!(lc["hash"], sha256(&net), "{log}");
    assert!(lc["eps"].as_f64().unwrap() <= target);
    assert!(
        !out.join("model.bin").exists(),
        "an ONNX net is not rewritten"
    );
    // The fixture is untouched (nothing retrained it).
    let before = sha256(&net);
    // export: ONNX and the controller-core files from the same certificate.
    let onnx = d.join("controller.onnx");
    let (rs, blob) = (d.join("w.rs"), d.join("w.bin"));
    ok(&trainer(&[
        "export",
        "--model",
        netp,
        "--certificate",
        cert_path.to_str().unwrap(),
        "--onnx",
        onnx.to_str().unwrap(),
        "--rust",
        rs.to_str().unwrap(),
        "--postcard",
        blob.to_str().unwrap(),
        "--name",
        "double_integrator",
    ]));
    assert_eq!(sha256(&net), before);
    let bytes = std::fs::read(&onnx).unwrap();
    let g = trainer::deploy::onnx::graph::decode(&bytes).unwrap();
    assert_eq!(g.meta("ampc.hash"), Some(before.as_str()));
    assert_eq!(
        g.meta("ampc.eps").unwrap().parse::<f64>().unwrap(),
        lc["eps"].as_f64().unwrap()
    );
    assert!(std::fs::read_to_string(&rs).unwrap().contains(&before));
    // tract runs the exported file like the controller (the net's weights re-imported from
    // the export are the controller's f32 weights).
    let (m, _) = trainer::deploy::onnx::load_any(&net).unwrap();
    let cert: trainer::certify::certificate::Certificate =
        serde_json::from_value(lc.clone()).unwrap();
    let em = ExportModel::from_trained("double_integrator", &m, &cert).unwrap();
    let a: f64 = g.meta("ampc.f32_allowance").unwrap().parse().unwrap();
    let xs = states(&em.domain_lo, &em.domain_hi);
    let (d_max, _) = max_diff(&tract_run(&bytes, &xs, 2), &controller(&em, a, &xs));
    assert!(d_max <= 2.0 * a, "{d_max:e} vs allowance {a:e}");
    let (back, notes) = trainer::deploy::onnx::load_any(&onnx).unwrap();
    assert!(notes.unwrap().ampc_export);
    for (l, (_, _, w, b)) in back.mlp.layers.iter().zip(&em.folded().f32_layers) {
        assert!(l.w.iter().zip(w).all(|(x, y)| *x == f64::from(*y)));
        assert!(l.b.iter().zip(b).all(|(x, y)| *x == f64::from(*y)));
    }
    // A certificate of another network is refused.
    let relu = fixture("di_relu.onnx");
    let o = trainer(&[
        "export",
        "--model",
        relu.to_str().unwrap(),
        "--certificate",
        cert_path.to_str().unwrap(),
        "--onnx",
        d.join("x.onnx").to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("another network"));
}

#[test]
fn relu_net_exports_to_onnx_not_to_controller_core() {
    let dir = tempdir();
    let d = dir.path();
    let (cfg, data) = sample_di(d);
    let net = fixture("di_relu.onnx");
    let netp = net.to_str().unwrap();
    let o = trainer(&[
        "certify", "--config", &cfg, "--model", netp, "--data", &data, "--json",
    ]);
    ok(&o);
    let cert = d.join("cert.json");
    std::fs::write(&cert, &o.stdout).unwrap();
    let c: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    // Sound L_NN for ReLU: never below the sampled lower bound.
    assert!(c["l_nn"].as_f64().unwrap() >= c["l_nn_lower"].as_f64().unwrap());
    let o = trainer(&[
        "export",
        "--model",
        netp,
        "--certificate",
        cert.to_str().unwrap(),
        "--rust",
        d.join("w.rs").to_str().unwrap(),
        "--postcard",
        d.join("w.bin").to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(e.contains("Relu") && e.contains("tanh"), "{e}");
    let onnx = d.join("relu.onnx");
    ok(&trainer(&[
        "export",
        "--model",
        netp,
        "--certificate",
        cert.to_str().unwrap(),
        "--onnx",
        onnx.to_str().unwrap(),
    ]));
    let bytes = std::fs::read(&onnx).unwrap();
    let g = trainer::deploy::onnx::graph::decode(&bytes).unwrap();
    assert_eq!(g.meta("ampc.activation"), Some("relu"));
    assert_eq!(g.meta("ampc.f32_allowance"), Some("not computed"));
    // tract agrees with the imported f64 net at states inside X to f32 rounding.
    let (m, _) = trainer::deploy::onnx::load_any(&net).unwrap();
    let xs: Vec<f32> = states(&[-4.0, -1.0], &[4.0, 1.0])
        .chunks(2)
        .filter(|x| x[0].abs() < 4.0 && x[1].abs() < 1.0)
        .flatten()
        .copied()
        .collect();
    let got = tract_run(&bytes, &xs, 2);
    // The clamp band written in the metadata (U_d ⊕ ε within the actuator limits).
    let band = |k: &str| -> f64 {
        let v = g.meta(k).unwrap();
        v.trim_matches(|c| c == '[' || c == ']').parse().unwrap()
    };
    let (lo, hi) = (band("ampc.clamp_lo"), band("ampc.clamp_hi"));
    assert!(lo <= c["u_lo"][0].as_f64().unwrap() && hi >= c["u_hi"][0].as_f64().unwrap());
    for (x, u) in xs.chunks(2).zip(&got) {
        let x64 = [f64::from(x[0]), f64::from(x[1])];
        let r = m.mlp.predict(&x64)[0].clamp(lo, hi);
        assert!(
            (f64::from(*u) - r).abs() <= 1e-5 * (1.0 + r.abs()),
            "x {x:?}: tract {u} vs f64 {r}"
        );
    }
}

#[test]
fn unsupported_node_is_named() {
    let dir = tempdir();
    let d = dir.path();
    // The torch fixture with its Tanh op type replaced by Atan (same length, so the file
    // stays valid protobuf): an unsupported operator in an otherwise valid graph.
    let mut bytes = std::fs::read(fixture("di_tanh.onnx")).unwrap();
    let pat = b"\x22\x04Tanh";
    let k = bytes
        .windows(pat.len())
        .position(|w| w == pat)
        .expect("a Tanh node");
    bytes[k + 2..k + 6].copy_from_slice(b"Atan");
    let bad = d.join("atan.onnx");
    std::fs::write(&bad, &bytes).unwrap();
    let states_csv = d.join("s.csv");
    std::fs::write(&states_csv, "x1,x2\n0,0\n").unwrap();
    let o = trainer(&[
        "eval",
        "--model",
        bad.to_str().unwrap(),
        "--states",
        states_csv.to_str().unwrap(),
        "--out",
        d.join("o.csv").to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        e.contains("atan.onnx") && e.contains("(Atan)") && e.contains("unsupported operator Atan"),
        "{e}"
    );
    // Not a model at all.
    let junk = d.join("junk.bin");
    std::fs::write(&junk, b"\x00\x01 definitely not protobuf").unwrap();
    let o = trainer(&[
        "eval",
        "--model",
        junk.to_str().unwrap(),
        "--states",
        states_csv.to_str().unwrap(),
        "--out",
        d.join("o2.csv").to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("junk.bin"));
}
