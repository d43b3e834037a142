//! Where the MPC is a QP (the 3-state DC motor of `configs/dc_motor.toml`, a linear ODE
//! with a general affine constraint), `trainer refine` proves the MPC part of every cell
//! (critical regions checked at the vertices) and its certificate says `"guarantee":
//! "sound"` with no assumption; the deployed (clamped) controller's error at fresh MPC
//! solves never exceeds that ε. Exported with that certificate, the tier arrives as `sound`
//! in all three outputs: `weights.rs` (`Guarantee::Sound`), `ampc.h`
//! (`AMPC_GUARANTEE_SOUND`) and the ONNX metadata (`ampc.tier` = `sound`).

use ampc_tests::{tempdir, trainer};

#[test]
fn the_dc_motor_certificate_is_sound_and_holds_at_sampled_states() {
    let dir = tempdir();
    let d = dir.path();
    let cfg = std::path::PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../configs/dc_motor.toml"
    ));
    let out = d.join("r");
    let o = trainer(&[
        "refine",
        "--config",
        cfg.to_str().unwrap(),
        "--target-eps",
        "1.0",
        "--budget",
        "8000",
        "--out",
        out.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(
        o.status.success(),
        "stdout: {}\nstderr: {}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    let cert: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("certificate.json")).unwrap()).unwrap();
    assert_eq!(cert["guarantee"], "sound", "{cert:#}");
    assert_eq!(cert["assumptions"], serde_json::json!([]));
    assert_eq!(cert["tiers"]["mpc_range"], "sound");
    assert_eq!(cert["local"]["cells_exact"], cert["local"]["cells"]);
    let eps = cert["eps"].as_f64().unwrap();
    assert!(eps.is_finite() && eps <= 1.0, "ε = {eps}");
    // Fresh MPC solves at seeded uniform states: the clamped net never errs by more than ε.
    let problem = trainer::problem::ProblemConfig::load(&cfg).unwrap();
    let model = trainer::certify::Model::load(&out.join("model.bin")).unwrap();
    let mut law = trainer::mpc::law::MpcLaw::new(&problem);
    let (lo, hi) = (&problem.domain.lo, &problem.domain.hi);
    let mut worst = 0.0f64;
    for i in 0..3000u64 {
        let x: Vec<f64> = (0..lo.len())
            .map(|k| lo[k] + (hi[k] - lo[k]) * trainer::rng::uniform(77, i, k as u64))
            .collect();
        let (l, _) = law.solve(&x, None);
        assert_eq!(
            l.status,
            trainer::mpc::sqp::SqpStatus::Converged,
            "at {x:?}"
        );
        let (ulo, uhi) = problem.ocp.u_bounds(0);
        let u = model.mlp.predict(&x)[0].clamp(ulo[0], uhi[0]);
        let e = (l.u[0] - u).abs();
        assert!(e <= eps, "at {x:?}: error {e} > ε {eps}");
        worst = worst.max(e);
    }
    assert!(worst > 0.0);
    exported_tier_is_sound(&out);
}

/// `trainer export` with the sound certificate: every output says `sound`.
fn exported_tier_is_sound(out: &std::path::Path) {
    let p = |f: &str| out.join(f).to_str().unwrap().to_string();
    let o = trainer(&[
        "export",
        "--model",
        &p("model.bin"),
        "--certificate",
        &p("certificate.json"),
        "--rust",
        &p("weights.rs"),
        "--postcard",
        &p("weights.bin"),
        "--c-header",
        &p("ampc.h"),
        "--onnx",
        &p("model.onnx"),
    ]);
    assert!(
        o.status.success(),
        "export: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let rs = std::fs::read_to_string(out.join("weights.rs")).unwrap();
    assert!(
        rs.contains("guarantee: Guarantee::Sound"),
        "weights.rs:\n{rs}"
    );
    assert!(!rs.contains("Guarantee::Estimated"), "weights.rs:\n{rs}");
    let h = std::fs::read_to_string(out.join("ampc.h")).unwrap();
    assert!(
        h.contains("AMPC_GUARANTEE_SOUND, /* guarantee */"),
        "ampc.h:\n{h}"
    );
    let onnx = std::fs::read(out.join("model.onnx")).unwrap();
    let m = trainer::deploy::onnx::graph::decode(&onnx).expect("the exported ONNX decodes");
    assert_eq!(
        m.meta("ampc.tier"),
        Some("sound"),
        "ONNX metadata ampc.tier"
    );
    assert!(
        m.meta("ampc.guarantee")
            .is_some_and(|g| g.contains("sound")),
        "ONNX metadata ampc.guarantee: {:?}",
        m.meta("ampc.guarantee")
    );
    // Sound, and about what: the QP with the f64 plant data — in every exported file.
    let premise = "the f64 plant data (A, B, c)";
    assert!(rs.contains(premise), "weights.rs:\n{rs}");
    assert!(h.contains(premise), "ampc.h:\n{h}");
    assert!(
        m.meta("ampc.guarantee")
            .is_some_and(|g| g.contains(premise)),
        "ONNX metadata ampc.guarantee: {:?}",
        m.meta("ampc.guarantee")
    );
    let cert = std::fs::read_to_string(out.join("certificate.json")).unwrap();
    assert!(cert.contains("\"premises\"") && cert.contains(premise));
}
