//! `trainer run` end to end on a small double-integrator problem: every stage's artifact
//! and manifest exists, the report and JSON files hold the contract's keys, a second run
//! skips every stage, and `--force` redoes one.

use ampc_tests::{config, tempdir, trainer};

#[test]
fn run_writes_artifacts_and_skips_unchanged_stages() {
    let dir = tempdir();
    let d = dir.path();
    let text = std::fs::read_to_string(config("double_integrator.toml"))
        .unwrap()
        .replace("counts = [21, 11]", "counts = [9, 5]")
        + "\n[training]\nepochs = 100\nbatch_size = 9\nvalidation_n = 40\nlog_every = 50\n"
        + "\n[closed_loop]\nsteps = 40\nrandom_initial_states = 3\nnoise_runs = 1\n";
    let cfg = d.join("di.toml");
    std::fs::write(&cfg, text).unwrap();
    let out = d.join("runs");
    let args = ["run", cfg.to_str().unwrap(), "--out", out.to_str().unwrap()];
    let o = trainer(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let run = out.join("double_integrator");
    for f in [
        "problem.toml",
        "dataset.bin",
        "dataset.csv",
        "validation.bin",
        "model_nominal.bin",
        "model_regularized.bin",
        "certificate.json",
        "certificate_nominal.json",
        "closed_loop.json",
        "report.md",
    ] {
        assert!(run.join(f).exists(), "missing {f}");
    }
    for st in [
        "sample",
        "validate",
        "train",
        "certify",
        "closed_loop",
        "report",
    ] {
        let m: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(run.join(format!("manifest_{st}.json"))).unwrap(),
        )
        .unwrap();
        assert_eq!(m["stage"], st);
        assert!(m["inputs"].as_object().is_some_and(|o| !o.is_empty()));
    }
    let cl: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("closed_loop.json")).unwrap())
            .unwrap();
    for k in ["mpc", "nominal", "regularized"] {
        let r = &cl[k][0];
        for f in [
            "x0",
            "steps",
            "violation_steps",
            "max_violation",
            "max_input_divergence",
            "cost",
        ] {
            assert!(r.get(f).is_some(), "{k} run lacks {f}");
        }
    }
    let report = std::fs::read_to_string(run.join("report.md")).unwrap();
    assert!(
        report.contains("Table I") && report.contains("Table II") && report.contains("Certificate")
    );
    // Unchanged inputs: every stage is skipped.
    let o = trainer(&args);
    assert!(o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(err.matches("] skipped").count(), 7, "{err}");
    // --force train retrains; training is deterministic, so the later stages see the same
    // model bytes and stay skipped.
    let mut forced = args.to_vec();
    forced.extend(["--force", "train"]);
    let o = trainer(&forced);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success());
    assert!(err.contains("[      train] done"), "{err}");
    assert_eq!(err.matches("] skipped").count(), 6, "{err}");
    // A usage error exits 2; a broken problem file exits 1 naming the key.
    assert_eq!(
        trainer(&["run", "--force", "nonsense"]).status.code(),
        Some(2)
    );
    std::fs::write(&cfg, "name = \"x\"\n").unwrap();
    let o = trainer(&args);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("di.toml"));
}
