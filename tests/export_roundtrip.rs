//! Export round trip: the committed `controller-core/src/demo/weights.{rs,bin}` are
//! exactly what `trainer::export` produces (byte for byte), and the core computes exactly
//! what the exporter's f32 model of the device computes (bit for bit).
//!
//! The committed weights are the paper's pendulum controller (sensitivity-regularized) as
//! `trainer run` produces it from the embedded `configs/pendulum.toml`: this test reruns
//! that pipeline (sample → train → certify → export) and compares the files byte for byte.
//! Regenerate them (and the C API's header `controller-core/capi/include/ampc.h`) with
//! `cargo run --release -p trainer -- run && cp runs/pendulum/weights.{rs,bin} controller-core/src/demo/`
//! and `trainer export … --c-header` (README, "The embedded side"), or with
//! `AMPC_BLESS=1 cargo test -p ampc-tests --test export_roundtrip` (writes the three files
//! from this test's own pipeline run).

use ampc_tests::tempdir;
use controller_core::activation;
use trainer::deploy::export::{self, Tanh};

fn committed(name: &str) -> Vec<u8> {
    let p = format!(
        "{}/../controller-core/src/demo/{name}",
        env!("CARGO_MANIFEST_DIR")
    );
    std::fs::read(&p).unwrap_or_else(|e| panic!("{p}: {e}"))
}

#[test]
fn committed_files_are_what_the_exporter_writes() {
    let (model, run_dir) = ampc_tests::trained_pendulum();
    assert!(!model.placeholder);
    let dir = tempdir();
    let (rs, bin) = (
        dir.path().join("weights.rs"),
        dir.path().join("weights.bin"),
    );
    let report = export::export_files(model, &rs, &bin).unwrap();
    let generated = format!("{}/../controller-core/src/demo", env!("CARGO_MANIFEST_DIR"));
    let header_path = format!(
        "{}/../controller-core/capi/include/ampc.h",
        env!("CARGO_MANIFEST_DIR")
    );
    if std::env::var_os("AMPC_BLESS").is_some() {
        std::fs::copy(&rs, format!("{generated}/weights.rs")).unwrap();
        std::fs::copy(&bin, format!("{generated}/weights.bin")).unwrap();
        std::fs::write(
            &header_path,
            export::render_c_header(model, &report).unwrap(),
        )
        .unwrap();
    }
    // The pipeline's export stage wrote the same files.
    assert_eq!(
        std::fs::read(&rs).unwrap(),
        std::fs::read(run_dir.join("weights.rs")).unwrap()
    );
    assert!(report.f32_allowance[0] >= report.f32_observed[0]);
    assert!(report.f32_allowance[1] >= report.f32_observed[1]);
    let fresh = std::fs::read(&rs).unwrap();
    assert!(
        fresh == committed("weights.rs"),
        "controller-core/src/demo/weights.rs is stale: regenerate it with trainer export"
    );
    assert_eq!(std::fs::read(&bin).unwrap(), committed("weights.bin"));
    // The C API's header is the exporter's for the same model and allowances.
    let header = export::render_c_header(model, &report).unwrap();
    let p = header_path;
    assert!(
        std::fs::read_to_string(&p).unwrap_or_default() == header,
        "{p} is stale: regenerate it with trainer export --c-header"
    );
    assert_eq!(controller_core::demo::CERTIFICATE.hash, model.hash);
}

#[test]
fn core_matches_the_exporters_f32_model_bit_for_bit() {
    let (model, _) = ampc_tests::trained_pendulum();
    let folded = model.folded();
    let (lo, hi) = model.domain_f32();
    let tanh = if activation::TANH_KIND == "fast" {
        Tanh::Fast
    } else {
        Tanh::Libm
    };
    let mut s = 0x1234_5678_9abc_def1u64;
    let mut rnd = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 40) as f32 / (1u64 << 24) as f32
    };
    for _ in 0..200_000 {
        let x = [-8.0 + 16.0 * rnd(), -1.5 + 3.0 * rnd()];
        let y = export::eval_f32(&folded, &lo, &hi, &x, tanh)[0];
        let c = &controller_core::demo::CERTIFICATE;
        let expect = y.clamp(c.clamp_lo[0], c.clamp_hi[0]);
        let got = controller_core::demo::evaluate(&x).u[0];
        assert_eq!(got.to_bits(), expect.to_bits(), "x = {x:?}");
    }
}

/// `trainer eval` (default: the controller) computes what the core computes, flags and all,
/// bit for bit (with the core's default tanh; within the f32 allowances with `fast-tanh`) —
/// inside X, outside it (projection) and where the clamp acts; `--raw` is the bare network
/// (no projection: its output differs outside X).
#[test]
fn eval_gives_the_cores_output_and_flags() {
    let (_, run_dir) = ampc_tests::trained_pendulum();
    let dir = tempdir();
    let mut s = 0x0bad_cafe_1234_5678u64;
    let mut rnd = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 40) as f32 / (1u64 << 24) as f32
    };
    // Twice X's width in each direction: about three quarters of the states are outside.
    let xs: Vec<[f32; 2]> = (0..2000)
        .map(|_| [-16.0 + 32.0 * rnd(), -3.0 + 6.0 * rnd()])
        .collect();
    let mut text = String::from("x1,x2\n");
    for x in &xs {
        text += &format!("{:?},{:?}\n", f64::from(x[0]), f64::from(x[1]));
    }
    let states = dir.path().join("s.csv");
    std::fs::write(&states, text).unwrap();
    let model = run_dir.join("model_regularized.bin");
    let run = |out: &str, raw: bool| {
        let out = dir.path().join(out);
        let mut args = vec![
            "eval",
            "--model",
            model.to_str().unwrap(),
            "--states",
            states.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ];
        let cert = run_dir.join("certificate.json");
        if raw {
            args.push("--raw");
        } else {
            // The pipeline keeps the certificate beside the model, not in it.
            args.extend(["--certificate", cert.to_str().unwrap()]);
        }
        let o = ampc_tests::trainer(&args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        std::fs::read_to_string(out).unwrap()
    };
    let ctrl = run("c.csv", false);
    let mut lines = ctrl.lines();
    assert_eq!(lines.next(), Some("x1,x2,u1,flags"));
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run_dir.join("export_report.json")).unwrap())
            .unwrap();
    // `trainer eval` computes the default (accurate) tanh's device arithmetic: with the core
    // built with `fast-tanh` the two agree only within both f32 allowances (each bounds the
    // distance to the same f64 network; projection and clamp do not widen it), and the
    // CLAMPED flag may differ at the band's edge.
    let fast = activation::TANH_KIND == "fast";
    let both = report["f32_allowance_libm"].as_f64().unwrap()
        + report["f32_allowance_fast_tanh"].as_f64().unwrap();
    let (mut outside, mut clamped) = (0, 0);
    for (x, l) in xs.iter().zip(lines) {
        let f: Vec<&str> = l.split(',').collect();
        let u: f64 = f[2].parse().unwrap();
        let flags: u8 = f[3].parse().unwrap();
        let core = controller_core::demo::evaluate(x);
        if fast {
            assert!((u - f64::from(core.u[0])).abs() <= both, "x = {x:?}");
            assert_eq!(flags & !4, core.flags.0 & !4, "x = {x:?}");
        } else {
            assert_eq!(u, f64::from(core.u[0]), "x = {x:?}");
            assert_eq!(flags, core.flags.0, "x = {x:?}");
        }
        outside += usize::from(flags & 1 != 0);
        clamped += usize::from(flags & 4 != 0);
    }
    assert!(outside > 1000, "{outside} states outside X");
    let raw = run("r.csv", true);
    assert!(raw.starts_with("x1,x2,u1,du1_dx1,du1_dx2\n"));
    // Where the controller neither projected nor clamped, it is the f64 network within the
    // sound f32 allowance of the export.
    let allowance = report["f32_allowance_libm"].as_f64().unwrap();
    let mut inside = 0;
    for (r, c) in raw.lines().skip(1).zip(ctrl.lines().skip(1)) {
        let c: Vec<&str> = c.split(',').collect();
        if c[3] != "0" {
            continue;
        }
        inside += 1;
        let (ur, uc): (f64, f64) = (
            r.split(',').nth(2).unwrap().parse().unwrap(),
            c[2].parse().unwrap(),
        );
        assert!(
            (ur - uc).abs() <= allowance,
            "{r} vs {c:?}: allowance {allowance}"
        );
    }
    assert!(inside > 100, "{inside} states inside X");
    eprintln!("{outside} outside, {clamped} clamped, {inside} inside and unclamped");
}
