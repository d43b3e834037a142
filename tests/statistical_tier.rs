//! `trainer certify --statistical N` end to end on a small double-integrator model: the
//! JSON's `"statistical"` block (the keys) against a recount made here with an
//! independent evaluation of the deployed controller (the blob exported with the
//! certificate, decoded and evaluated by controller-core) at the stored states, and the
//! Clopper–Pearson bound against a bisection on the binomial CDF written here; the states
//! are drawn from the model's hash (another model: other states), none is a training
//! state; a second call reuses the stored states (same answer, file untouched); bad flags
//! are clear errors.

use ampc_tests::{config, tempdir, trainer};
use controller_core::layer::Dense;
use controller_core::mlp::Hidden;
use std::path::Path;

/// The default `[training] hidden = [10, 10]` net of the double integrator.
type Net = Hidden<2, 10, Hidden<10, 10, Dense<10, 1>>>;

/// P(Bin(n, p) ≤ k), by the pmf recursion in log space.
fn binomial_cdf(n: u64, k: u64, p: f64) -> f64 {
    let mut ln_pmf = n as f64 * (1.0 - p).ln();
    let mut sum = ln_pmf.exp();
    for i in 0..k {
        ln_pmf += ((n - i) as f64 / (i + 1) as f64).ln() + p.ln() - (1.0 - p).ln();
        sum += ln_pmf.exp();
    }
    sum
}

/// The one-sided Clopper–Pearson upper bound: the p with P(Bin(n, p) ≤ k) = 1 − confidence,
/// by bisection (the CDF falls in p).
fn cp_upper(n: u64, k: u64, confidence: f64) -> f64 {
    if k >= n {
        return 1.0;
    }
    let (mut lo, mut hi) = (0.0f64, 1.0f64);
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if binomial_cdf(n, k, mid) > 1.0 - confidence {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    hi
}

#[test]
fn the_test_bisection_matches_known_values() {
    // k = 0: 1 − β^{1/n}; and the 95 % one-sided bound for 1 success in 10 trials
    // (0.3942, a textbook table value).
    assert!((cp_upper(600, 0, 0.95) - (1.0 - 0.05f64.powf(1.0 / 600.0))).abs() < 1e-12);
    assert!((cp_upper(10, 1, 0.95) - 0.3942).abs() < 1e-4);
}

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

    // The statement names the function tested and the model it was drawn for.
    assert_eq!(st["model_hash"], v["hash"]);
    let function = st["function"].as_str().unwrap();
    assert!(
        function.contains("deployed controller") && function.contains("f32"),
        "{function}"
    );
    assert_eq!(st["user_seed"].as_u64(), Some(0x5354_4154));
    assert_ne!(
        st["seed"], st["user_seed"],
        "the seed is derived from the model's hash"
    );

    // Recount from the stored states with the deployed controller as controller-core
    // computes it: the blob exported with this very certificate.
    let store = d.join("m.statistical.bin");
    let store_csv = d.join("m.statistical.csv");
    assert!(store.exists() && store_csv.exists());

    // Sharded (`--shard K/M`, then `trainer merge`): the same store byte for byte, and the
    // same statistical block from it.
    let mut shards = Vec::new();
    for k in 0..3 {
        let s = d.join(format!("s{k}.bin"));
        let o = certify(&[
            "--statistical",
            &ns,
            "--confidence",
            "0.95",
            "--shard",
            &format!("{k}/3"),
            "--statistical-store",
            s.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        assert!(o.stdout.is_empty(), "a shard computes no bound");
        shards.push(s.to_str().unwrap().to_string());
    }
    let merged = d.join("merged.bin");
    let mut args = vec!["merge", merged.to_str().unwrap()];
    args.extend(shards.iter().map(String::as_str));
    let o = trainer(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(
        std::fs::read(&merged).unwrap() == std::fs::read(&store).unwrap(),
        "the merged shards differ from the unsharded statistical store"
    );
    let again = certify(&[
        "--statistical",
        &ns,
        "--confidence",
        "0.95",
        "--statistical-store",
        merged.to_str().unwrap(),
    ]);
    assert!(again.status.success());
    let w: serde_json::Value = serde_json::from_slice(&again.stdout).unwrap();
    assert_eq!(w["statistical"], v["statistical"]);
    let (head, rows) = csv(&store_csv);
    assert_eq!(rows.len(), n);
    let col = |name: &str| head.iter().position(|h| h == name).unwrap();
    let (ix1, ix2, iu, ist) = (col("x1"), col("x2"), col("u1"), col("status"));
    let c0 = d.join("c0.json");
    std::fs::write(&c0, &first.stdout).unwrap();
    let (rs0, bin0) = (d.join("w0.rs"), d.join("w0.bin"));
    let o = trainer(&[
        "export",
        "--model",
        model,
        "--certificate",
        c0.to_str().unwrap(),
        "--rust",
        rs0.to_str().unwrap(),
        "--postcard",
        bin0.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let blob = std::fs::read(&bin0).unwrap();
    let dec = controller_core::blob::decode::<2, 1, Net>(&blob).expect("the blob decodes");
    let mut errors = Vec::new();
    for r in &rows {
        let labelled = r[ist] == "converged" || r[ist] == "soft";
        let err = if labelled {
            let kappa: f64 = r[iu].parse().unwrap();
            let x: [f64; 2] = [r[ix1].parse().unwrap(), r[ix2].parse().unwrap()];
            let u = dec.controller.evaluate(&[x[0] as f32, x[1] as f32]).u[0];
            (kappa - f64::from(u)).abs()
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
    assert!((st["max_error"].as_f64().unwrap() - max).abs() <= 1e-12 * (1.0 + max));
    let p = st["p_exceed_upper"].as_f64().unwrap();
    let want = cp_upper(n as u64, k as u64, 0.95);
    assert!(
        p >= want * (1.0 - 1e-12) && p <= want * (1.0 + 1e-9),
        "{p} vs {want} (k = {k})"
    );

    // None of the states is a training state (the dataset's CSV).
    let (dhead, drows) = csv(&d.join("di.csv"));
    let (dx1, dx2) = (
        dhead.iter().position(|h| h == "x1").unwrap(),
        dhead.iter().position(|h| h == "x2").unwrap(),
    );
    let train: std::collections::HashSet<(String, String)> = drows
        .iter()
        .map(|r| (r[dx1].clone(), r[dx2].clone()))
        .collect();
    assert!(rows
        .iter()
        .all(|r| !train.contains(&(r[ix1].clone(), r[ix2].clone()))));

    // Another model (another training seed) is tested on other states, from the same
    // user seed.
    let model2 = d.join("m2.bin");
    let m2 = model2.to_str().unwrap();
    let o = trainer(&[
        "train", "--config", &cfg, "--data", data, "--out", m2, "--seed", "1", "--quiet",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = trainer(&[
        "certify",
        "--config",
        &cfg,
        "--model",
        m2,
        "--data",
        data,
        "--json",
        "--statistical",
        "20",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v2: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_ne!(v2["statistical"]["seed"], st["seed"]);
    let (_, rows2) = csv(&d.join("m2.statistical.csv"));
    assert_ne!(
        (&rows2[0][ix1], &rows2[0][ix2]),
        (&rows[0][ix1], &rows[0][ix2]),
        "fresh states for another model"
    );

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
        let p = b[part]["p_violation_upper"].as_f64().unwrap();
        let want = cp_upper(n, k, 0.99);
        assert!(
            p >= want * (1.0 - 1e-12) && p <= want * (1.0 + 1e-9),
            "{part}: {p} vs {want}"
        );
    }
    assert_eq!(b["all"]["trajectories"], 120);
    assert!(b["function"]
        .as_str()
        .unwrap()
        .contains("deployed controller"));
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
