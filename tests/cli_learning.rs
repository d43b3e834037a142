//! `trainer train`, `certify` and `eval` end to end on a small double-integrator dataset:
//! the certificate JSON has the contract's keys and consistent values, `eval` writes the
//! network's outputs and Jacobians (checked against finite differences of its own
//! outputs), and bad inputs are clear errors.

use ampc_tests::{config, tempdir, trainer};

fn setup(d: &std::path::Path) -> (String, String) {
    let text = std::fs::read_to_string(config("double_integrator.toml"))
        .unwrap()
        .replace("counts = [21, 11]", "counts = [11, 6]")
        + "\n[training]\nepochs = 200\nbatch_size = 11\nvalidation_n = 30\nlog_every = 50\n";
    let cfg = d.join("di.toml");
    std::fs::write(&cfg, text).unwrap();
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

#[test]
fn train_certify_eval() {
    let dir = tempdir();
    let d = dir.path();
    let (cfg, data) = setup(d);
    let model = d.join("m.bin");
    let m = model.to_str().unwrap();
    let o = trainer(&[
        "train", "--config", &cfg, "--data", &data, "--out", m, "--quiet",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = trainer(&[
        "certify",
        "--config",
        &cfg,
        "--model",
        m,
        "--data",
        &data,
        "--json",
        "--target-eps",
        "50",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    for k in [
        "eps",
        "eps_d",
        "l_nn",
        "l_nn_method",
        "l_nn_naive",
        "l_nn_lower",
        "l_mpc",
        "l_mpc_is_estimate",
        "covering_radius",
        "f32_allowance",
        "domain_lo",
        "domain_hi",
        "u_lo",
        "u_hi",
        "clamp_lo",
        "clamp_hi",
        "hash",
    ] {
        assert!(v.get(k).is_some(), "missing key {k}: {v}");
    }
    // The tier: L_MPC is sampled, so ε is an estimate; the other terms are sound.
    assert_eq!(v["guarantee"], "estimated", "{v}");
    assert_eq!(v["tiers"]["l_mpc"], "estimated");
    for t in ["eps_d", "l_nn", "covering_radius", "f32_allowance"] {
        assert_eq!(v["tiers"][t], "sound", "{t}");
    }
    assert!(v["assumptions"][0].as_str().unwrap().starts_with("l_mpc"));
    let f = |k: &str| v[k].as_f64().unwrap();
    // The f32 allowance the tier calls sound is computed and stored (not 0), and covers the
    // f32-vs-f64 difference seen here between two other evaluations: controller-core's
    // (the exported blob, decoded) and `trainer eval --raw` (the f64 net).
    f32_allowance_covers_the_device(d, m, &o.stdout, f("f32_allowance"));
    assert!(f("l_nn_lower") <= f("l_nn") && f("l_nn") <= f("l_nn_naive"));
    assert!(
        (f("eps") - (f("eps_d") + (f("l_mpc") + f("l_nn")) * f("covering_radius"))).abs()
            < 1e-9 * f("eps")
    );
    // ε_D recomputed independently: `eval` at every labelled state of the dataset's CSV
    // against its labels (another command, another file) gives the certificate's ε_D.
    let csv = std::fs::read_to_string(d.join("di.csv")).unwrap();
    let mut lines = csv.lines();
    let head: Vec<&str> = lines.next().unwrap().split(',').collect();
    let at = |n: &str| head.iter().position(|c| *c == n).unwrap();
    let (ix1, ix2, iu, ist) = (at("x1"), at("x2"), at("u1"), at("status"));
    let rows: Vec<Vec<&str>> = lines
        .map(|l| l.split(',').collect::<Vec<_>>())
        .filter(|r| r[ist] == "converged" || r[ist] == "soft")
        .collect();
    let mut states = "x1,x2\n".to_string();
    for r in &rows {
        states += &format!("{},{}\n", r[ix1], r[ix2]);
    }
    std::fs::write(d.join("grid.csv"), states).unwrap();
    let out = d.join("grid_out.csv");
    let grid = d.join("grid.csv");
    let o = trainer(&[
        "eval",
        "--raw",
        "--model",
        m,
        "--states",
        grid.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let evals = std::fs::read_to_string(&out).unwrap();
    let eps_d = rows
        .iter()
        .zip(evals.lines().skip(1))
        .map(|(r, e)| {
            let u_nn: f64 = e.split(',').nth(2).unwrap().parse().unwrap();
            (r[iu].parse::<f64>().unwrap() - u_nn).abs()
        })
        .fold(0.0f64, f64::max);
    assert!(
        (eps_d - f("eps_d")).abs() <= 1e-9 * (1.0 + eps_d),
        "ε_D {eps_d} recomputed vs {} certified",
        f("eps_d")
    );
    // 11 × 6 grid on [−4, 4] × [−1, 1], spacings 0.8 and 0.4, measured in the certificate's
    // norm: the default state scales are the domain's half-widths 4 and 1, so
    // r = ½·√((0.8/4)² + (0.4/1)²).
    let xs: Vec<f64> = v["norm"]["x_scale"]
        .as_array()
        .expect("the certificate states its norm")
        .iter()
        .map(|s| s.as_f64().unwrap())
        .collect();
    assert_eq!(xs, [4.0, 1.0]);
    let r = 0.5 * ((0.8f64 / 4.0).powi(2) + (0.4f64 / 1.0).powi(2)).sqrt();
    assert!(
        (f("covering_radius") - r).abs() < 1e-12,
        "{}",
        f("covering_radius")
    );
    assert_eq!(v["l_mpc_is_estimate"], serde_json::Value::Bool(true));
    let req = &v["requirement"];
    let delta = req["delta"].as_f64().unwrap();
    assert!((f("eps_d") + (f("l_mpc") + f("l_nn")) * delta - 50.0).abs() < 1e-9);
    // A proven L_MPC replaces the estimate.
    let o = trainer(&[
        "certify", "--config", &cfg, "--model", m, "--data", &data, "--json", "--l-mpc", "2.5",
    ]);
    let v2: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v2["l_mpc"].as_f64(), Some(2.5));
    assert_eq!(v2["l_mpc_is_estimate"], serde_json::Value::Bool(false));

    // eval: outputs and Jacobians; the Jacobian matches differences of the outputs.
    let states = d.join("s.csv");
    let h = 1e-6;
    std::fs::write(
        &states,
        format!(
            "x1,x2\n0.5,0.25\n{},0.25\n{},0.25\n0.5,{}\n0.5,{}\n",
            0.5 + h,
            0.5 - h,
            0.25 + h,
            0.25 - h
        ),
    )
    .unwrap();
    let out = d.join("e.csv");
    let o = trainer(&[
        "eval",
        "--raw",
        "--model",
        m,
        "--states",
        states.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = std::fs::read_to_string(&out).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next().unwrap(), "x1,x2,u1,du1_dx1,du1_dx2");
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    let fd1 = (rows[1][2] - rows[2][2]) / (2.0 * h);
    let fd2 = (rows[3][2] - rows[4][2]) / (2.0 * h);
    assert!(
        (fd1 - rows[0][3]).abs() < 1e-5 * (1.0 + fd1.abs()),
        "{fd1} vs {}",
        rows[0][3]
    );
    assert!(
        (fd2 - rows[0][4]).abs() < 1e-5 * (1.0 + fd2.abs()),
        "{fd2} vs {}",
        rows[0][4]
    );
}

/// `allowance` (the certificate's f32 allowance, printed as `cert_json`) is positive and at
/// least the largest |u_device − u_f64| on 2,000 states of X (the device: the blob exported
/// with that certificate, decoded and evaluated by controller-core; f64: `trainer eval
/// --raw`), on the states where the device did not clamp.
fn f32_allowance_covers_the_device(
    d: &std::path::Path,
    model: &str,
    cert_json: &[u8],
    allowance: f64,
) {
    use controller_core::layer::Dense;
    use controller_core::mlp::Hidden;
    assert!(
        allowance > 0.0 && allowance < 1e-3,
        "stored f32 allowance {allowance}"
    );
    let cert = d.join("c.json");
    std::fs::write(&cert, cert_json).unwrap();
    let (rs, bin) = (d.join("w.rs"), d.join("w.bin"));
    let o = trainer(&[
        "export",
        "--model",
        model,
        "--certificate",
        cert.to_str().unwrap(),
        "--rust",
        rs.to_str().unwrap(),
        "--postcard",
        bin.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let blob = std::fs::read(&bin).unwrap();
    // The default [training] hidden = [10, 10].
    type Net = Hidden<2, 10, Hidden<10, 10, Dense<10, 1>>>;
    let dec = controller_core::blob::decode::<2, 1, Net>(&blob).expect("the blob decodes");
    // States of X = [−4, 4] × [−1, 1], exact in f32 (so both evaluations see the same x).
    let mut s = 0x2545_f491_4f6c_dd1du64;
    let mut next = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 40) as f32 / (1u64 << 24) as f32
    };
    let xs: Vec<[f32; 2]> = (0..2000)
        .map(|_| [-4.0 + 8.0 * next(), -1.0 + 2.0 * next()])
        .collect();
    let states = d.join("f32_states.csv");
    let mut text = String::from("x1,x2\n");
    for x in &xs {
        text += &format!("{},{}\n", f64::from(x[0]), f64::from(x[1]));
    }
    std::fs::write(&states, text).unwrap();
    let out = d.join("f32_states_out.csv");
    let o = trainer(&[
        "eval",
        "--raw",
        "--model",
        model,
        "--states",
        states.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let evals = std::fs::read_to_string(&out).unwrap();
    let mut worst = 0.0f64;
    let mut compared = 0;
    for (x, line) in xs.iter().zip(evals.lines().skip(1)) {
        let u64: f64 = line.split(',').nth(2).unwrap().parse().unwrap();
        let out = dec.controller.evaluate(x);
        if out.flags.0 != 0 {
            continue;
        }
        compared += 1;
        worst = worst.max((f64::from(out.u[0]) - u64).abs());
    }
    // Outside the clamp band both sides saturate; the unclamped states are the comparison.
    assert!(compared > 500, "{compared} unclamped states");
    if controller_core::activation::TANH_KIND != "fast" {
        assert!(
            worst > 0.0 && worst <= allowance,
            "observed f32 difference {worst:e} vs stored allowance {allowance:e}"
        );
    }
}

#[test]
fn learning_commands_reject_bad_input() {
    let dir = tempdir();
    let d = dir.path();
    let (cfg, data) = setup(d);
    // Data labelled for another problem than the config (without --config, the dataset's
    // own problem is used: see tests/integrity.rs).
    let model = d.join("m.bin");
    let pendulum = config("pendulum.toml");
    let o = trainer(&[
        "train",
        "--config",
        &pendulum,
        "--data",
        &data,
        "--out",
        model.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("another problem"));
    // A corrupt model names the file.
    let bad = d.join("bad.bin");
    std::fs::write(&bad, b"garbage").unwrap();
    let o = trainer(&[
        "certify",
        "--config",
        &cfg,
        "--model",
        bad.to_str().unwrap(),
        "--data",
        &data,
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("bad.bin"));
    let o = trainer(&[
        "eval",
        "--model",
        bad.to_str().unwrap(),
        "--states",
        "x.csv",
        "--out",
        "y.csv",
    ]);
    assert_eq!(o.status.code(), Some(1));
    // A dataset file given as a model is refused.
    let o = trainer(&[
        "eval", "--model", &data, "--states", "x.csv", "--out", "y.csv",
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("not an ampc model"));
}

/// The README's `compare` and `export` commands: Table I over seeds (text table and JSON),
/// and the export of a trained model with its stored certificate to a Rust file and a blob.
#[test]
fn compare_and_export() {
    let dir = tempdir();
    let d = dir.path();
    let (cfg, data) = setup(d);
    let json = d.join("seeds.json");
    let o = trainer(&[
        "compare",
        "--config",
        &cfg,
        "--data",
        &data,
        "--seeds",
        "2",
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let table = String::from_utf8_lossy(&o.stdout);
    assert!(
        table.contains("| nominal |") && table.contains("| regularized |"),
        "{table}"
    );
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let rows = v.as_array().unwrap();
    assert_eq!(rows.len(), 4, "2 seeds × 2 nets");
    // Seed 0 of `compare` is `train --seed 0` on the same data: the same ε, recomputed by
    // another command (the seeds' nets differ, so their ε must too).
    let mut eps: Vec<f64> = rows.iter().map(|r| r["eps"].as_f64().unwrap()).collect();
    assert!(eps.iter().all(|e| e.is_finite() && *e > 0.0));
    eps.dedup();
    assert_eq!(
        eps.len(),
        4,
        "four different nets, four different ε: {eps:?}"
    );
    assert_eq!(
        trainer(&["compare", "--config", &cfg, "--data", &data, "--seeds", "0"])
            .status
            .code(),
        Some(1)
    );

    let model = d.join("m.bin");
    let o = trainer(&[
        "train",
        "--config",
        &cfg,
        "--data",
        &data,
        "--out",
        model.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (rs, bin) = (d.join("w.rs"), d.join("w.bin"));
    let o = trainer(&[
        "export",
        "--model",
        model.to_str().unwrap(),
        "--rust",
        rs.to_str().unwrap(),
        "--postcard",
        bin.to_str().unwrap(),
        "--name",
        "double_integrator",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = std::fs::read_to_string(&rs).unwrap();
    assert!(
        text.starts_with("// @generated by trainer export"),
        "{text:.200}"
    );
    assert!(std::fs::metadata(&bin).unwrap().len() > 100);
    assert!(String::from_utf8_lossy(&o.stderr).contains("f32 allowance"));
}
