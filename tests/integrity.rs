//! Nothing wrong gets certified and nothing is lost, through the CLI (issue: integrity):
//! a command never replaces one of its inputs, a model is never certified on data of another
//! problem or for another domain, a dataset without `--config` is certified for its own
//! stored problem (not the embedded pendulum), and export refuses another model's
//! certificate. Each case failed (exit 0, a silent overwrite or a wrong ε) before the fix.

use ampc_tests::{config, tempdir, trainer};
use std::path::Path;

fn ok(o: &std::process::Output) {
    assert!(
        o.status.success(),
        "stdout: {}\nstderr: {}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
}

/// Fails with a message containing `needle`, and leaves `kept` byte-identical.
fn refused(args: &[&str], needle: &str, kept: &Path) {
    let before = std::fs::read(kept).unwrap();
    let o = trainer(args);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{args:?} succeeded");
    assert!(err.contains(needle), "{args:?}: {err}");
    assert!(!err.contains("panicked"), "{args:?}: {err}");
    assert_eq!(
        std::fs::read(kept).unwrap(),
        before,
        "{args:?} changed {}",
        kept.display()
    );
}

/// A problem file: the shipped one with a small grid and short training.
fn small(dir: &Path, name: &str, extra: &str) -> String {
    let text = std::fs::read_to_string(config(name)).unwrap();
    let text = text
        .replace("counts = [35, 10]", "counts = [6, 4]")
        .replace("counts = [21, 11]", "counts = [6, 4]");
    let p = dir.join(name);
    std::fs::write(
        &p,
        format!("{text}\n{extra}\n[training]\nepochs = 20\nvalidation_n = 20\nlog_every = 50\n"),
    )
    .unwrap();
    p.to_str().unwrap().to_string()
}

#[test]
fn integrity_through_the_cli() {
    let dir = tempdir();
    let d = dir.path();
    let s = |p: &str| d.join(p).to_str().unwrap().to_string();
    // Two problems with the same dimensions: the double integrator, and a pendulum near upright.
    let di = small(d, "double_integrator.toml", "");
    let pend_text = std::fs::read_to_string(config("pendulum.toml"))
        .unwrap()
        .replace("counts = [35, 10]", "counts = [6, 4]");
    std::fs::write(
        d.join("pend.toml"),
        format!("{pend_text}\n[training]\nepochs = 20\nvalidation_n = 20\nlog_every = 50\n"),
    )
    .unwrap();
    let pend = s("pend.toml");
    for (cfg, data) in [(&di, "di.bin"), (&pend, "p.bin")] {
        ok(&trainer(&[
            "sample",
            "--config",
            cfg,
            "--out",
            &s(data),
            "--quiet",
        ]));
    }
    for (data, model) in [("di.bin", "di_model.bin"), ("p.bin", "p_model.bin")] {
        ok(&trainer(&[
            "train",
            "--data",
            &s(data),
            "--out",
            &s(model),
            "--quiet",
        ]));
    }

    // Never overwrite an input.
    refused(
        &["train", "--data", &s("di.bin"), "--out", &s("di.bin")],
        "is the input",
        &d.join("di.bin"),
    );
    std::fs::hard_link(d.join("di.bin"), d.join("link.bin")).unwrap();
    refused(
        &["train", "--data", &s("di.bin"), "--out", &s("link.bin")],
        "is the input",
        &d.join("di.bin"),
    );
    refused(
        &["merge", &s("di.bin"), &s("di.bin")],
        "is the input",
        &d.join("di.bin"),
    );
    std::fs::write(d.join("x.csv"), "x1,x2\n0.1,0.2\n").unwrap();
    refused(
        &[
            "solve",
            "--config",
            &di,
            "--states",
            &s("x.csv"),
            "--out",
            &s("x.csv"),
        ],
        "is the input",
        &d.join("x.csv"),
    );
    refused(
        &[
            "eval",
            "--model",
            &s("di_model.bin"),
            "--states",
            &s("x.csv"),
            "--out",
            &s("x.csv"),
        ],
        "is the input",
        &d.join("x.csv"),
    );
    refused(
        &[
            "export",
            "--model",
            &s("di_model.bin"),
            "--rust",
            &s("di_model.bin"),
            "--postcard",
            &s("w.bin"),
        ],
        "is the input",
        &d.join("di_model.bin"),
    );

    // A pendulum net certified on double-integrator data: refused (was: ε = 25.6, exit 0).
    let o = trainer(&[
        "certify",
        "--model",
        &s("p_model.bin"),
        "--data",
        &s("di.bin"),
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("trained on labels of problem hash"));
    // Data of one problem certified for another problem file: refused.
    let o = trainer(&[
        "certify",
        "--config",
        &pend,
        "--model",
        &s("di_model.bin"),
        "--data",
        &s("di.bin"),
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("was labelled for problem"));
    // The same problem with a wider X: the grid's covering radius would be wrong — refused.
    let wide = std::fs::read_to_string(&di).unwrap();
    let wide = wide.replacen(
        "[domain]\nlo = [-4.0, -1.0]\nhi = [4.0, 1.0]",
        "[domain]\nlo = [-4.0, -1.0]\nhi = [4.0, 10.0]",
        1,
    );
    assert!(
        wide.contains("hi = [4.0, 10.0]"),
        "the double integrator's domain changed: update this test"
    );
    std::fs::write(d.join("wide.toml"), wide).unwrap();
    let o = trainer(&[
        "certify",
        "--config",
        &s("wide.toml"),
        "--model",
        &s("di_model.bin"),
        "--data",
        &s("di.bin"),
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("domain X"));

    // Without --config: the dataset's own problem, said on stderr, and the same ε as with it.
    let json = |args: &[&str]| -> serde_json::Value {
        let o = trainer(args);
        ok(&o);
        serde_json::from_slice(&o.stdout).unwrap()
    };
    let own = json(&[
        "certify",
        "--model",
        &s("di_model.bin"),
        "--data",
        &s("di.bin"),
        "--json",
    ]);
    let given = json(&[
        "certify",
        "--config",
        &di,
        "--model",
        &s("di_model.bin"),
        "--data",
        &s("di.bin"),
        "--json",
    ]);
    assert_eq!(own["eps"], given["eps"]);
    assert_eq!(own["domain_hi"], given["domain_hi"]);
    let o = trainer(&[
        "certify",
        "--model",
        &s("di_model.bin"),
        "--data",
        &s("di.bin"),
    ]);
    assert!(String::from_utf8_lossy(&o.stderr).contains("no --config given"));

    // `certify --json` of a model on a dataset (must succeed), and `export` of the DI model
    // with a certificate file.
    let certify_json = |model: &str, data: &str| {
        let o = trainer(&[
            "certify",
            "--model",
            &s(model),
            "--data",
            &s(data),
            "--json",
        ]);
        ok(&o);
        o.stdout
    };
    let export = |cert: &str| {
        trainer(&[
            "export",
            "--model",
            &s("di_model.bin"),
            "--certificate",
            &s(cert),
            "--rust",
            &s("w.rs"),
            "--postcard",
            &s("w.bin"),
        ])
    };
    // Export with the certificate of another model: refused, nothing written.
    std::fs::write(d.join("p_cert.json"), certify_json("p_model.bin", "p.bin")).unwrap();
    let o = export("p_cert.json");
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("another network"));
    assert!(!d.join("w.rs").exists() && !d.join("w.bin").exists());

    // The certificate's own numbers are checksummed: its own certificate exports; the same
    // file with ε lowered by hand (or its tier raised) is refused, naming the file.
    let text = String::from_utf8(certify_json("di_model.bin", "di.bin")).unwrap();
    std::fs::write(d.join("di_cert.json"), &text).unwrap();
    ok(&export("di_cert.json"));
    let _ = std::fs::remove_file(d.join("w.rs"));
    let _ = std::fs::remove_file(d.join("w.bin"));
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    let eps = v["eps"].to_string();
    let tier = format!("\"guarantee\": {}", v["guarantee"]);
    for (from, to) in [
        (
            format!("\"eps\": {eps}"),
            format!("\"eps\": {}", v["eps"].as_f64().unwrap() / 2.0),
        ),
        (
            tier.clone(),
            if v["guarantee"] == "sound" {
                "\"guarantee\": \"statistical\"".to_string()
            } else {
                "\"guarantee\": \"sound\"".to_string()
            },
        ),
    ] {
        assert!(text.contains(&from), "{from} not in {text}");
        std::fs::write(d.join("edited.json"), text.replacen(&from, &to, 1)).unwrap();
        let o = export("edited.json");
        assert!(!o.status.success(), "{from} → {to} was accepted");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            err.contains("edited.json") && err.contains("checksum mismatch"),
            "{err}"
        );
        assert!(!d.join("w.rs").exists() && !d.join("w.bin").exists());
    }
}
