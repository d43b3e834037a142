//! Where a command's problem comes from (issue: integrity, "no silent default problem"), and
//! every subcommand on inputs of mismatched dimensions:
//! - `eval`, `export` and `merge` accept `--config` (as `run` does besides its positional
//!   form) and refuse an artifact of another problem, naming the file and both problems;
//! - without `--config` a model's own problem (stored in the model file) is used and named,
//!   never the embedded pendulum; the pendulum only when nothing names a problem, said on
//!   the first line of stderr;
//! - `export --name` defaults to the model's problem name, made an identifier;
//! - a 2-state model or dataset given with 4-state data, states or certificates: every
//!   subcommand exits 1 with a message naming the file at fault, never a panic (exit 101).

use ampc_tests::{config, tempdir, trainer};
use std::path::Path;
use std::process::Output;

fn ok(o: &Output) -> String {
    let err = String::from_utf8_lossy(&o.stderr).to_string();
    assert!(
        o.status.success(),
        "stdout: {}\nstderr: {err}",
        String::from_utf8_lossy(&o.stdout)
    );
    err
}

/// Exit 1 (a clear error, not a panic or a usage error), stderr containing every needle.
fn fails(args: &[&str], needles: &[&str]) -> String {
    let o = trainer(args);
    let err = String::from_utf8_lossy(&o.stderr).to_string();
    assert_eq!(o.status.code(), Some(1), "{args:?}: {err}");
    assert!(!err.contains("panicked"), "{args:?}: {err}");
    for n in needles {
        assert!(err.contains(n), "{args:?}: `{n}` not in: {err}");
    }
    err
}

/// The shipped problem file `name` with a small plan and short training, renamed `rename`.
fn small(dir: &Path, name: &str, rename: &str) -> String {
    let text = std::fs::read_to_string(config(name)).unwrap();
    let text = text
        .replace("counts = [21, 11]", "counts = [6, 4]")
        .replace("n = 500", "n = 12")
        .replacen(
            &format!("name = \"{}\"", name.trim_end_matches(".toml")),
            &format!("name = \"{rename}\""),
            1,
        );
    assert!(text.contains(&format!("name = \"{rename}\"")), "{name}");
    let p = dir.join(format!("{rename}.toml"));
    std::fs::write(
        &p,
        format!("{text}\n[training]\nepochs = 20\nvalidation_n = 20\nlog_every = 50\n"),
    )
    .unwrap();
    p.to_str().unwrap().to_string()
}

#[test]
fn the_problem_comes_from_the_config_or_the_artifact_never_silently_the_pendulum() {
    let dir = tempdir();
    let d = dir.path();
    let s = |p: &str| d.join(p).to_str().unwrap().to_string();
    // A problem whose name is not an identifier: export must make it one.
    let di = small(d, "double_integrator.toml", "di-2 states");
    let pend = config("pendulum.toml");
    ok(&trainer(&[
        "sample",
        "--config",
        &di,
        "--out",
        &s("di.bin"),
        "--quiet",
    ]));
    ok(&trainer(&[
        "train",
        "--data",
        &s("di.bin"),
        "--out",
        &s("m.bin"),
        "--quiet",
    ]));
    std::fs::write(d.join("x.csv"), "x1,x2\n0.1,0.2\n-1.5,0.3\n").unwrap();

    // eval: the model's own problem, named; with its --config the same output; with the
    // pendulum's --config refused, naming the model and both problems.
    let err = ok(&trainer(&[
        "eval",
        "--model",
        &s("m.bin"),
        "--states",
        &s("x.csv"),
        "--out",
        &s("y.csv"),
    ]));
    assert!(
        err.lines()
            .next()
            .unwrap()
            .contains("problem `di-2 states` from"),
        "{err}"
    );
    assert!(!err.contains("embedded pendulum"), "{err}");
    ok(&trainer(&[
        "eval",
        "--config",
        &di,
        "--model",
        &s("m.bin"),
        "--states",
        &s("x.csv"),
        "--out",
        &s("y2.csv"),
    ]));
    assert_eq!(
        std::fs::read(d.join("y.csv")).unwrap(),
        std::fs::read(d.join("y2.csv")).unwrap()
    );
    let eval_pend = [
        "eval",
        "--config",
        &pend,
        "--model",
        &s("m.bin"),
        "--states",
        &s("x.csv"),
        "--out",
        &s("y3.csv"),
    ];
    fails(&eval_pend, &["m.bin", "`di-2 states`", "`pendulum`"]);
    assert!(!d.join("y3.csv").exists());

    // export: the default name is the model's problem, as an identifier; --config checked.
    let err = ok(&trainer(&[
        "export",
        "--model",
        &s("m.bin"),
        "--rust",
        &s("w.rs"),
        "--postcard",
        &s("w.bin"),
        "--c-header",
        &s("ampc.h"),
    ]));
    assert!(err.contains("`di_2_states`"), "{err}");
    let rs = std::fs::read_to_string(d.join("w.rs")).unwrap();
    assert!(rs.contains("`di_2_states` controller"), "{rs}");
    assert!(!rs.contains("pendulum"), "{rs}");
    let h = std::fs::read_to_string(d.join("ampc.h")).unwrap();
    assert!(h.contains("di_2_states") && !h.contains("pendulum"));
    ok(&trainer(&[
        "export",
        "--config",
        &di,
        "--model",
        &s("m.bin"),
        "--onnx",
        &s("w.onnx"),
    ]));
    fails(
        &[
            "export",
            "--config",
            &pend,
            "--model",
            &s("m.bin"),
            "--rust",
            &s("v.rs"),
            "--postcard",
            &s("v.bin"),
        ],
        &["m.bin", "`di-2 states`", "`pendulum`"],
    );
    assert!(!d.join("v.rs").exists());
    // A certificate of another problem for this very network: refused under --config.
    let cert: serde_json::Value = serde_json::from_slice(
        &trainer(&[
            "certify",
            "--model",
            &s("m.bin"),
            "--data",
            &s("di.bin"),
            "--json",
        ])
        .stdout,
    )
    .unwrap();
    let mut alien = cert.clone();
    alien["problem_hash"] = "0123456789abcdef".into();
    // Resealed (a recomputed checksum), so the problem check itself is reached.
    std::fs::write(
        d.join("alien.json"),
        trainer::certify::seal::sealed_json(&alien).unwrap(),
    )
    .unwrap();
    fails(
        &[
            "export",
            "--config",
            &di,
            "--model",
            &s("m.bin"),
            "--certificate",
            &s("alien.json"),
            "--onnx",
            &s("v.onnx"),
        ],
        &["alien.json", "0123456789ab", "`di-2 states`"],
    );

    // merge --config: shards of another problem refused, naming the shard.
    for k in 0..2 {
        ok(&trainer(&[
            "sample",
            "--config",
            &di,
            "--out",
            &s(&format!("s{k}.bin")),
            "--shard",
            &format!("{k}/2"),
            "--quiet",
        ]));
    }
    ok(&trainer(&[
        "merge",
        "--config",
        &di,
        &s("merged.bin"),
        &s("s0.bin"),
        &s("s1.bin"),
    ]));
    fails(
        &[
            "merge",
            "--config",
            &pend,
            &s("merged2.bin"),
            &s("s0.bin"),
            &s("s1.bin"),
        ],
        &["s0.bin", "`di-2 states`", "`pendulum`"],
    );

    // Nothing names a problem: the embedded pendulum, said on the first line.
    let err = ok(&trainer(&[
        "solve",
        "--states",
        &s("x.csv"),
        "--out",
        &s("sol.csv"),
    ]));
    assert!(
        err.lines().next().unwrap().contains("embedded pendulum"),
        "{err}"
    );
    // run's flag form is the positional one (an unreadable file named either way).
    for args in [
        vec!["run", "--config", "no/such.toml", "--out", "r"],
        vec!["run", "no/such.toml", "--out", "r"],
    ] {
        fails(&args, &["no/such.toml"]);
    }
}

#[test]
fn every_subcommand_refuses_mismatched_dimensions_without_a_panic() {
    let dir = tempdir();
    let d = dir.path();
    let s = |p: &str| d.join(p).to_str().unwrap().to_string();
    let di = small(d, "double_integrator.toml", "double_integrator");
    let cp = small(d, "cartpole.toml", "cartpole");
    ok(&trainer(&[
        "sample",
        "--config",
        &di,
        "--out",
        &s("di.bin"),
        "--quiet",
    ]));
    ok(&trainer(&[
        "sample",
        "--config",
        &cp,
        "--out",
        &s("cp.bin"),
        "--quiet",
    ]));
    ok(&trainer(&[
        "train",
        "--data",
        &s("di.bin"),
        "--out",
        &s("m.bin"),
        "--quiet",
    ]));
    std::fs::write(d.join("x2.csv"), "x1,x2\n0.1,0.2\n").unwrap();
    std::fs::write(d.join("x4.csv"), "x1,x2,x3,x4\n0.1,0.2,0.0,0.1\n").unwrap();
    // A 4-state certificate claiming the 2-state network's hash.
    let mut cert: serde_json::Value = serde_json::from_slice(
        &trainer(&[
            "certify",
            "--model",
            &s("m.bin"),
            "--data",
            &s("di.bin"),
            "--json",
        ])
        .stdout,
    )
    .unwrap();
    cert["domain_lo"] = serde_json::json!([-1.0, -1.0, -1.0, -1.0]);
    cert["domain_hi"] = serde_json::json!([1.0, 1.0, 1.0, 1.0]);
    std::fs::write(
        d.join("cert4.json"),
        trainer::certify::seal::sealed_json(&cert).unwrap(),
    )
    .unwrap();
    let cases: Vec<(Vec<String>, &str)> = vec![
        (
            args(&[
                "solve",
                "--config",
                &di,
                "--states",
                &s("x4.csv"),
                "--out",
                &s("o.csv"),
            ]),
            "x4.csv",
        ),
        (
            args(&[
                "eval",
                "--model",
                &s("m.bin"),
                "--states",
                &s("x4.csv"),
                "--out",
                &s("o.csv"),
            ]),
            "x4.csv",
        ),
        (
            args(&[
                "eval",
                "--raw",
                "--model",
                &s("m.bin"),
                "--states",
                &s("x4.csv"),
                "--out",
                &s("o.csv"),
            ]),
            "x4.csv",
        ),
        (
            args(&[
                "eval",
                "--model",
                &s("m.bin"),
                "--certificate",
                &s("cert4.json"),
                "--states",
                &s("x2.csv"),
                "--out",
                &s("o.csv"),
            ]),
            "cert4.json",
        ),
        (
            args(&[
                "eval",
                "--config",
                &cp,
                "--model",
                &s("m.bin"),
                "--states",
                &s("x4.csv"),
                "--out",
                &s("o.csv"),
            ]),
            "m.bin",
        ),
        (
            args(&["certify", "--model", &s("m.bin"), "--data", &s("cp.bin")]),
            "cp.bin",
        ),
        (
            args(&[
                "certify",
                "--config",
                &cp,
                "--model",
                &s("m.bin"),
                "--data",
                &s("cp.bin"),
            ]),
            "m.bin",
        ),
        (
            args(&[
                "train",
                "--config",
                &di,
                "--data",
                &s("cp.bin"),
                "--out",
                &s("o.bin"),
            ]),
            "cp.bin",
        ),
        (
            args(&[
                "train",
                "--data",
                &s("cp.bin"),
                "--validation",
                &s("di.bin"),
                "--out",
                &s("o.bin"),
            ]),
            "di.bin",
        ),
        (
            args(&[
                "compare",
                "--config",
                &di,
                "--data",
                &s("cp.bin"),
                "--seeds",
                "1",
            ]),
            "cp.bin",
        ),
        (
            args(&[
                "export",
                "--model",
                &s("m.bin"),
                "--certificate",
                &s("cert4.json"),
                "--rust",
                &s("o.rs"),
                "--postcard",
                &s("o.pc"),
            ]),
            "cert4.json",
        ),
        (
            args(&[
                "export",
                "--config",
                &cp,
                "--model",
                &s("m.bin"),
                "--onnx",
                &s("o.onnx"),
            ]),
            "m.bin",
        ),
        (
            args(&[
                "refine",
                "--config",
                &cp,
                "--certify-only",
                "--model",
                &s("m.bin"),
                "--out",
                &s("rf"),
                "--quiet",
            ]),
            "m.bin",
        ),
        (
            args(&[
                "refine",
                "--config",
                &di,
                "--data",
                &s("cp.bin"),
                "--out",
                &s("rf"),
                "--quiet",
            ]),
            "cp.bin",
        ),
        (
            args(&[
                "import",
                "--config",
                &di,
                "--csv",
                &s("cp.csv"),
                "--out",
                &s("o.bin"),
                "--quiet",
            ]),
            "cp.csv",
        ),
        (
            args(&["merge", "--config", &di, &s("o.bin"), &s("cp.bin")]),
            "cp.bin",
        ),
        (
            args(&["sample", "--config", &cp, "--out", &s("o.bin"), "--quiet"]),
            "",
        ),
    ];
    for (args, file) in &cases {
        let a: Vec<&str> = args.iter().map(String::as_str).collect();
        if a[0] == "sample" {
            continue; // sample reads no artifact: nothing to mismatch (listed for completeness)
        }
        fails(&a, &[file]);
    }
    // No output was written by any refused command.
    for f in ["o.csv", "o.bin", "o.rs", "o.pc", "o.onnx"] {
        assert!(!d.join(f).exists(), "{f} written");
    }
}

/// A command line as owned strings.
fn args(a: &[&str]) -> Vec<String> {
    a.iter().map(|s| s.to_string()).collect()
}
