//! A certificate edited by hand never leaves the trainer: `export` and `eval`
//! refuse a `certificate.json` whose ε, domain X, clamp band or tier was edited — with its
//! checksum recomputed (the refusal names the field) and without its checksum (refused as
//! unsealed unless `--accept-unsealed`, which then exports the tier `estimated`) — and one
//! whose check failed or that states no `guarantee`. The library writes the same bytes as
//! `trainer certify --json`. Every case below exited 0 before the certificate file was typed
//! and re-checked.

use ampc_tests::{config, tempdir, trainer};
use serde_json::{json, Value};
use std::path::Path;

fn ok(o: &std::process::Output) -> String {
    assert!(
        o.status.success(),
        "stdout: {}\nstderr: {}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// The certificate text with `edit` applied to its JSON and the checksum recomputed (a
/// careful forger: the seal verifies).
fn resealed(text: &str, edit: impl FnOnce(&mut Value)) -> String {
    let mut v: Value = serde_json::from_str(text).unwrap();
    edit(&mut v);
    trainer::certify::seal::sealed_json(&v).unwrap()
}

/// The certificate text with `edit` applied and its checksum deleted.
fn unsealed(text: &str, edit: impl FnOnce(&mut Value)) -> String {
    let mut v: Value = serde_json::from_str(text).unwrap();
    edit(&mut v);
    v.as_object_mut().unwrap().remove("checksum");
    serde_json::to_string_pretty(&v).unwrap()
}

struct Fixture<'a> {
    dir: &'a Path,
    cfg: String,
    model: String,
}

impl Fixture<'_> {
    fn path(&self, f: &str) -> String {
        self.dir.join(f).to_str().unwrap().to_string()
    }

    /// `export --rust --postcard` and `eval` with the certificate `text`: both refused with
    /// `needle` in the message, no output written. Returns the export's stderr.
    fn refused(&self, case: &str, text: &str, needle: &str) -> String {
        let c = self.path(&format!("{case}.json"));
        std::fs::write(&c, text).unwrap();
        let (rs, bin) = (
            self.path(&format!("{case}.rs")),
            self.path(&format!("{case}.bin")),
        );
        let o = trainer(&[
            "export",
            "--model",
            &self.model,
            "--certificate",
            &c,
            "--rust",
            &rs,
            "--postcard",
            &bin,
        ]);
        let err = String::from_utf8_lossy(&o.stderr).into_owned();
        assert!(!o.status.success(), "{case}: export accepted it\n{err}");
        assert!(err.contains(needle), "{case}: export said\n{err}");
        assert!(!err.contains("panicked"), "{case}: {err}");
        assert!(
            !Path::new(&rs).exists() && !Path::new(&bin).exists(),
            "{case}"
        );
        let o = trainer(&[
            "eval",
            "--model",
            &self.model,
            "--certificate",
            &c,
            "--states",
            &self.path("x.csv"),
            "--out",
            &self.path(&format!("{case}.csv")),
        ]);
        let e = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{case}: eval accepted it\n{e}");
        assert!(e.contains(needle), "{case}: eval said\n{e}");
        err
    }

    /// `export` with the certificate `text` (and `extra` flags): succeeds; the tier written
    /// into `weights.rs`.
    fn exported_tier(&self, case: &str, text: &str, extra: &[&str]) -> (String, String) {
        let c = self.path(&format!("{case}.json"));
        std::fs::write(&c, text).unwrap();
        let rs = self.path(&format!("{case}.rs"));
        let mut args = vec![
            "export",
            "--model",
            &self.model,
            "--certificate",
            &c,
            "--rust",
            &rs,
            "--postcard",
        ];
        let bin = self.path(&format!("{case}.bin"));
        args.push(&bin);
        args.extend_from_slice(extra);
        let err = ok(&trainer(&args));
        let w = std::fs::read_to_string(&rs).unwrap();
        let tier = w
            .lines()
            .find_map(|l| l.trim().strip_prefix("guarantee: Guarantee::"))
            .unwrap_or_else(|| panic!("{case}: no guarantee in weights.rs"))
            .trim_end_matches(',')
            .to_string();
        (tier, err)
    }
}

#[test]
fn edited_certificates_are_refused_by_export_and_eval() {
    let dir = tempdir();
    let d = dir.path();
    let text = std::fs::read_to_string(config("double_integrator.toml"))
        .unwrap()
        .replace("counts = [21, 11]", "counts = [6, 4]");
    let cfg = d.join("di.toml");
    std::fs::write(
        &cfg,
        format!("{text}\n[training]\nepochs = 20\nvalidation_n = 20\nlog_every = 50\n"),
    )
    .unwrap();
    let f = Fixture {
        dir: d,
        cfg: cfg.to_str().unwrap().to_string(),
        model: d.join("m.bin").to_str().unwrap().to_string(),
    };
    ok(&trainer(&[
        "sample",
        "--config",
        &f.cfg,
        "--out",
        &f.path("d.bin"),
        "--quiet",
    ]));
    ok(&trainer(&[
        "train",
        "--config",
        &f.cfg,
        "--data",
        &f.path("d.bin"),
        "--out",
        &f.model,
        "--quiet",
    ]));
    std::fs::write(d.join("x.csv"), "x1,x2\n0.1,0.2\n").unwrap();
    let certify = |extra: &[&str]| -> String {
        let mut args = vec!["certify", "--config", &f.cfg, "--model", &f.model, "--data"];
        let data = f.path("d.bin");
        args.push(&data);
        args.push("--json");
        args.extend_from_slice(extra);
        let o = trainer(&args);
        ok(&o);
        String::from_utf8(o.stdout).unwrap()
    };
    let sealed = certify(&[]);
    let v: Value = serde_json::from_str(&sealed).unwrap();
    let eps = v["eps"].as_f64().unwrap();
    assert!(eps > 0.05, "ε = {eps}: the edit to 0.01 must be a lowering");

    // The library writes exactly what the CLI prints.
    {
        let problem = trainer::problem::ProblemConfig::load(Path::new(&f.cfg)).unwrap();
        let m = trainer::certify::Model::load(Path::new(&f.model)).unwrap();
        let data = trainer::data::dataset::Dataset::load(&d.join("d.bin")).unwrap();
        let (c, _) = trainer::deploy::export::certify_deployed(
            &problem.name,
            &m,
            &data,
            &problem,
            &Default::default(),
        )
        .unwrap();
        let lib = d.join("lib.json");
        trainer::certify::file::write_certificate(
            &lib,
            &trainer::certify::file::CertificateFile::theorem1(c),
        )
        .unwrap();
        assert_eq!(
            std::fs::read_to_string(&lib).unwrap(),
            sealed.trim_end(),
            "the library's certificate.json differs from `trainer certify --json`'s"
        );
    }

    // The untouched certificate exports, with its own tier.
    let (tier, _) = f.exported_tier("good", &sealed, &[]);
    assert_eq!(tier, "Estimated", "a sampled L_MPC is an estimate");

    // Edits with a recomputed checksum: refused, naming the field.
    let e = f.refused(
        "eps",
        &resealed(&sealed, |v| v["eps"] = json!(0.01)),
        "`eps` = 0.01 but ε_D + (L_MPC + L_NN)·r",
    );
    assert!(e.contains("eps.json"), "{e}");
    f.refused(
        "domain",
        &resealed(&sealed, |v| {
            v["domain_lo"] = json!([-60.0, -60.0]);
            v["domain_hi"] = json!([60.0, 60.0]);
        }),
        "`domain_lo`",
    );
    f.refused(
        "band",
        &resealed(&sealed, |v| v["clamp_hi"] = json!([1e9])),
        "`clamp_hi[0]` = 1000000000",
    );
    f.refused(
        "tier",
        &resealed(&sealed, |v| v["guarantee"] = json!("sound")),
        "`guarantee` = \"sound\"",
    );
    f.refused(
        "tiers",
        &resealed(&sealed, |v| {
            v["guarantee"] = json!("sound");
            for t in v["tiers"].as_object_mut().unwrap().values_mut() {
                *t = json!("sound");
            }
            v["assumptions"] = json!([]);
        }),
        "`guarantee` = \"sound\" but the terms support \"estimated\"",
    );
    f.refused(
        "problem",
        &resealed(&sealed, |v| v["problem_hash"] = json!("0".repeat(64))),
        "`problem_hash`",
    );
    // A certificate that does not say its tier is refused, not taken as sound (a user-given
    // L_MPC would otherwise export as `sound`).
    let given = certify(&["--l-mpc", "2.0"]);
    let (tier, _) = f.exported_tier("given", &given, &[]);
    assert_eq!(
        tier, "Estimated",
        "a user-given L_MPC is the user's assumption"
    );
    f.refused(
        "no_guarantee",
        &resealed(&given, |v| {
            v.as_object_mut().unwrap().remove("guarantee");
        }),
        "no `guarantee`",
    );
    // A failed check is part of the certificate and stops the export.
    f.refused(
        "check",
        &resealed(&sealed, |v| {
            v["check"] = json!({"states": 100, "exceedances": 3, "passed": false,
                                "report": "check.json"});
        }),
        "check failed (3 of 100",
    );

    // The same edits without the checksum: refused as unsealed.
    for (case, text) in [
        ("u_eps", unsealed(&sealed, |v| v["eps"] = json!(0.01))),
        (
            "u_domain",
            unsealed(&sealed, |v| v["domain_lo"] = json!([-60.0, -60.0])),
        ),
        (
            "u_band",
            unsealed(&sealed, |v| v["clamp_hi"] = json!([1e9])),
        ),
        (
            "u_tier",
            unsealed(&sealed, |v| v["guarantee"] = json!("sound")),
        ),
        ("u_plain", unsealed(&sealed, |_| {})),
    ] {
        f.refused(case, &text, "no `checksum`");
    }
    // `--accept-unsealed` reads an older file, says so, and exports it as `estimated` (here
    // one that claims `sound`); its numbers are still re-checked.
    let (tier, err) = f.exported_tier(
        "accepted",
        &unsealed(&sealed, |v| v["guarantee"] = json!("sound")),
        &["--accept-unsealed"],
    );
    assert_eq!(tier, "Estimated");
    assert!(
        err.contains("no checksum") && err.contains("estimated"),
        "{err}"
    );
    // The reason travels with the files: the Rust file says what ε rests on.
    let w = std::fs::read_to_string(f.path("accepted.rs")).unwrap();
    assert!(
        w.contains("// ε rests on") && w.contains("unsealed:") && w.contains("--accept-unsealed"),
        "weights.rs does not say why the tier is estimated:\n{w}"
    );
    let c = f.path("u_eps_acc.json");
    std::fs::write(&c, unsealed(&sealed, |v| v["eps"] = json!(0.01))).unwrap();
    let o = trainer(&[
        "export",
        "--model",
        &f.model,
        "--certificate",
        &c,
        "--rust",
        &f.path("u_eps_acc.rs"),
        "--postcard",
        &f.path("u_eps_acc.bin"),
        "--accept-unsealed",
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("`eps` = 0.01"));
}
