//! `trainer certify --statistical N` end to end on a small double-integrator model: the
//! JSON's `"statistical"` block (the keys) against a recount made here from the
//! stored states (`trainer eval` of the model at them, the certificate's clamp band) and
//! the closed form of the Clopper–Pearson bound for k = 0; a second call reuses the
//! stored states (same answer, file untouched); bad flags are clear errors.

use ampc_tests::{config, tempdir, trainer};
use std::path::Path;

fn csv(p: &Path) -> (Vec<String>, Vec<Vec<String>>) {
    let text = std::fs::read_to_string(p).unwrap();
    let mut lines = text.lines();
    let head = lines.next().unwrap().split(',').map(String::from).collect();
    let rows = lines
        .map(|l| l.split(',').map(String::from).collect())
        .collect();
    (head, rows)
}

#[test]
fn statistical_tier_counts_and_bounds_exceedances() {
    let dir = tempdir();
    let d = dir.path();
    let text = std::fs::read_to_string(config("double_integrator.toml"))
        .unwrap()
        .replace("counts = [21, 11]", "counts = [9, 5]")
        + "\n[training]\nepochs = 60\nbatch_size = 9\nvalidation_n = 20\nlog_every = 50\n";
    let cfg = d.join("di.toml");
    std::fs::write(&cfg, text).unwrap();
    let (cfg, data, model) = (
        cfg.to_str().unwrap().to_string(),
        d.join("di.bin"),
        d.join("m.bin"),
    );
    let (data, model) = (data.to_str().unwrap(), model.to_str().unwrap());
    for args in [
        vec!["sample", "--config", &cfg, "--out", data, "--quiet"],
        vec![
            "train", "--config", &cfg, "--data", data, "--out", model, "--quiet",
        ],
    ] {
        let o = trainer(&args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    let n = 600usize;
    let certify = |extra: &[&str]| {
        let mut a = vec![
            "certify", "--config", &cfg, "--model", model, "--data", data, "--json",
        ];
        a.extend_from_slice(extra);
        trainer(&a)
    };
    let ns = n.to_string();
    let first = certify(&["--statistical", &ns, "--confidence", "0.95"]);
    assert!(
        first.status.success(),
        "{}",
        String::from_utf8_lossy(&first.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&first.stdout).unwrap();
    let st = &v["statistical"];
    assert_eq!(st["samples"], n);
    assert_eq!(st["confidence"], 0.95);
    let eps = v["eps"].as_f64().unwrap();
    assert_eq!(st["eps"].as_f64(), Some(eps));

    // Recount from the stored states with the model's own outputs.
    let store = d.join("m.statistical.bin");
    let store_csv = d.join("m.statistical.csv");
    assert!(store.exists() && store_csv.exists());
    let (head, rows) = csv(&store_csv);
    assert_eq!(rows.len(), n);
    let col = |name: &str| head.iter().position(|h| h == name).unwrap();
    let (ix1, ix2, iu, ist) = (col("x1"), col("x2"), col("u1"), col("status"));
    let states = d.join("states.csv");
    let mut s = String::from("x1,x2\n");
    for r in &rows {
        s += &format!("{},{}\n", r[ix1], r[ix2]);
    }
    std::fs::write(&states, s).unwrap();
    let evald = d.join("eval.csv");
    let o = trainer(&[
        "eval",
        "--raw",
        "--model",
        model,
        "--states",
        states.to_str().unwrap(),
        "--out",
        evald.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (eh, erows) = csv(&evald);
    let eu = eh.iter().position(|h| h == "u1").unwrap();
    let (lo, hi) = (
        v["clamp_lo"][0].as_f64().unwrap(),
        v["clamp_hi"][0].as_f64().unwrap(),
    );
    let mut errors = Vec::new();
    for (r, e) in rows.iter().zip(&erows) {
        let labelled = r[ist] == "converged" || r[ist] == "soft";
        let err = if labelled {
            let kappa: f64 = r[iu].parse().unwrap();
            let net: f64 = e[eu].parse().unwrap();
            (kappa - net.clamp(lo, hi)).abs()
        } else {
            f64::INFINITY
        };
        errors.push(err);
    }
    let k = errors.iter().filter(|e| **e > eps).count();
    assert_eq!(st["exceedances"], k);
    let max = errors
        .iter()
        .filter(|e| e.is_finite())
        .fold(0.0f64, |m, e| m.max(*e));
    assert!((st["max_error"].as_f64().unwrap() - max).abs() <= 1e-9 * (1.0 + max));
    let p = st["p_exceed_upper"].as_f64().unwrap();
    if k == 0 {
        let closed = 1.0 - 0.05f64.powf(1.0 / n as f64);
        assert!((p - closed).abs() <= 1e-10 * closed, "{p} vs {closed}");
    } else {
        // At least the observed rate.
        assert!(p >= k as f64 / n as f64, "{p} below the observed rate");
    }
    // The level for P ≤ 1e-2: exceedances of it are few enough that their bound is ≤ 1e-2.
    let o2 = certify(&[
        "--statistical",
        &ns,
        "--confidence",
        "0.95",
        "--p-target",
        "0.02",
    ]);
    assert!(o2.status.success());
    let v2: serde_json::Value = serde_json::from_slice(&o2.stdout).unwrap();
    let e2 = v2["statistical"]["eps_at_p_target"]
        .as_f64()
        .expect("reachable with 600 states");
    let k2 = errors.iter().filter(|e| **e > e2).count();
    // 1 − 0.05^{1/600} = 5.0e-3 ≤ 0.02: a level exists; its exceedance rate is below 2 %.
    assert!((k2 as f64) < 0.02 * n as f64, "{k2} exceedances of {e2}");
    assert!(errors.iter().filter(|e| **e >= e2).count() > k2 || e2 == 0.0);

    // That level as the exported ε and clamp band (`export --statistical-band`): tier
    // statistical, ε = level + the f32 allowance, band U_d ⊕ ε; refused without the block.
    let c2 = d.join("c2.json");
    std::fs::write(&c2, &o2.stdout).unwrap();
    let export = |cert: &Path, tag: &str| {
        let (rs, pc) = (d.join(format!("{tag}.rs")), d.join(format!("{tag}.bin")));
        let o = trainer(&[
            "export",
            "--model",
            model,
            "--certificate",
            cert.to_str().unwrap(),
            "--rust",
            rs.to_str().unwrap(),
            "--postcard",
            pc.to_str().unwrap(),
            "--statistical-band",
        ]);
        (o, rs)
    };
    let (o, rs) = export(&c2, "w2");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let rust = std::fs::read_to_string(&rs).unwrap();
    let lit = |key: &str| -> f64 {
        let at = rust.find(&format!("    {key}: ")).unwrap() + key.len() + 6;
        let end = at + rust[at..].find([',', '\n']).unwrap();
        rust[at..end].parse().unwrap()
    };
    assert!(rust.contains("guarantee: Guarantee::Statistical"), "{rust}");
    assert!(rust.contains("statistical level"), "{rust}");
    assert_eq!(lit("eps_nn"), e2);
    let total = lit("eps");
    let allowance = total - e2;
    assert!(allowance > 0.0 && allowance < 1e-3, "allowance {allowance}");
    // The band (U_d ⊕ ε) ∩ actuator (the actuator limits are U_d here): contains U_d and
    // lies within U_d ⊕ ε.
    let u_lo = v2["u_lo"][0].as_f64().unwrap();
    let at = rust.find("clamp_lo: [").unwrap() + 11;
    let lo: f64 = rust[at..at + rust[at..].find([',', ']']).unwrap()]
        .trim()
        .parse()
        .unwrap();
    assert!(
        lo <= u_lo && lo >= u_lo - total - 1e-5,
        "{lo} vs {u_lo} − {total}"
    );
    let (o, _) = export(&d.join("nonexistent.json"), "w3");
    assert!(!o.status.success());
    // A sealed certificate without the block: a clear error naming the file and the key.
    let c1 = d.join("c1.json");
    std::fs::write(&c1, &certify(&[]).stdout).unwrap();
    let (o, _) = export(&c1, "w4");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("c1.json") && err.contains("\"statistical\""),
        "{err}"
    );

    // Reused, not re-solved: the store is untouched and the answer the same.
    let before = std::fs::metadata(&store).unwrap().modified().unwrap();
    let o3 = certify(&["--statistical", &ns, "--confidence", "0.95"]);
    assert!(o3.status.success());
    assert_eq!(o3.stdout, first.stdout);
    assert_eq!(
        std::fs::metadata(&store).unwrap().modified().unwrap(),
        before
    );

    // Bad flags name themselves.
    for (flag, val) in [("--confidence", "1.5"), ("--statistical", "0")] {
        let o = certify(&["--statistical", "10", flag, val]);
        assert!(!o.status.success());
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains(flag), "{err}");
    }
    // Without the flag nothing is solved.
    std::fs::remove_file(&store).unwrap();
    let o = certify(&[]);
    assert!(o.status.success());
    assert!(!store.exists());
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(v.get("statistical").is_none());
    assert!(v.get("statistical_closed_loop").is_none());

    // The closed loop's tier: n trajectories, k violating, the Clopper–Pearson bound of
    // (n, k); the same seed gives the same bytes; the certificate stays sealed.
    let o = certify(&["--statistical-closed-loop", "120"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8(o.stdout).unwrap();
    assert_eq!(
        trainer::certify::seal::verify(&text, "stdout"),
        Ok(trainer::certify::seal::Seal::Verified)
    );
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    let b = &v["statistical_closed_loop"];
    for part in ["all", "feasible_starts"] {
        let (n, k) = (
            b[part]["trajectories"].as_u64().unwrap(),
            b[part]["violating"].as_u64().unwrap(),
        );
        assert!(k <= n && n <= 120, "{b}");
        let p = trainer::certify::statistical::clopper_pearson_upper(n, k, 0.99);
        assert_eq!(b[part]["p_violation_upper"].as_f64().unwrap(), p, "{b}");
    }
    assert_eq!(b["all"]["trajectories"], 120);
    assert_eq!(b["confidence"], 0.99);
    let again = certify(&["--statistical-closed-loop", "120"]);
    assert_eq!(String::from_utf8(again.stdout).unwrap(), text);
    let o = certify(&[
        "--statistical-closed-loop",
        "5",
        "--closed-loop-confidence",
        "1",
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--closed-loop-confidence"));
}
