//! Sharded generation through the CLI: `sample --shard K/N` on each shard then `merge`
//! gives a file byte-identical to one unsharded `sample` run (postcard and CSV).

use ampc_tests::{config, tempdir, trainer};

#[test]
fn shards_merge_to_the_single_run() {
    let dir = tempdir();
    let d = dir.path();
    let cfg = config("double_integrator.toml");
    let single = d.join("single.bin");
    let o = trainer(&[
        "sample",
        "--config",
        &cfg,
        "--out",
        single.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let mut shards = Vec::new();
    for k in 0..4 {
        let p = d.join(format!("shard{k}.bin"));
        let spec = format!("{k}/4");
        let o = trainer(&[
            "sample",
            "--config",
            &cfg,
            "--out",
            p.to_str().unwrap(),
            "--shard",
            &spec,
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        shards.push(p.to_str().unwrap().to_string());
    }
    let merged = d.join("merged.bin");
    let mut args = vec!["merge", merged.to_str().unwrap()];
    args.extend(shards.iter().rev().map(String::as_str));
    let o = trainer(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(
        std::fs::read(&merged).unwrap(),
        std::fs::read(&single).unwrap()
    );
    assert_eq!(
        std::fs::read(merged.with_extension("csv")).unwrap(),
        std::fs::read(single.with_extension("csv")).unwrap()
    );
    // An incomplete set is refused, naming what is missing.
    let o = trainer(&[
        "merge",
        d.join("m2.bin").to_str().unwrap(),
        &shards[0],
        &shards[1],
    ]);
    assert_eq!(o.status.code(), Some(1));
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(e.contains("missing shards: 2/4, 3/4"), "{e}");
    // A corrupt input is refused, naming the file.
    let bad = d.join("bad.bin");
    std::fs::write(&bad, b"not a dataset").unwrap();
    let o = trainer(&[
        "merge",
        d.join("m3.bin").to_str().unwrap(),
        bad.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("bad.bin"));
}

/// The validation set shards the same way (issue 43 §3): `sample --validation --shard K/M`
/// on each shard, then `merge`, is byte-identical (postcard and CSV) to the `validation.bin`
/// that `trainer run`'s `validate` stage labels.
#[test]
fn validation_shards_merge_to_the_run_stage() {
    let dir = tempdir();
    let d = dir.path();
    let cfg = config("double_integrator.toml");
    let runs = d.join("runs");
    let o = trainer(&[
        "run",
        &cfg,
        "--out",
        runs.to_str().unwrap(),
        "--until",
        "validate",
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let stage = std::fs::read_dir(&runs)
        .unwrap()
        .map(|e| e.unwrap().path().join("validation.bin"))
        .find(|p| p.exists())
        .expect("the validate stage wrote validation.bin");
    let mut shards = Vec::new();
    for k in 0..3 {
        let p = d.join(format!("val{k}.bin"));
        let spec = format!("{k}/3");
        let o = trainer(&[
            "sample",
            "--config",
            &cfg,
            "--validation",
            "--out",
            p.to_str().unwrap(),
            "--shard",
            &spec,
            "--quiet",
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        shards.push(p.to_str().unwrap().to_string());
    }
    let merged = d.join("validation_merged.bin");
    let mut args = vec!["merge", merged.to_str().unwrap()];
    args.extend(shards.iter().map(String::as_str));
    let o = trainer(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(
        std::fs::read(&merged).unwrap(),
        std::fs::read(&stage).unwrap()
    );
    assert_eq!(
        std::fs::read(merged.with_extension("csv")).unwrap(),
        std::fs::read(stage.with_extension("csv")).unwrap()
    );
    // Without --validation the same shards are the sampling plan's: not the validation set.
    let plan = d.join("plan.bin");
    let o = trainer(&[
        "sample",
        "--config",
        &cfg,
        "--out",
        plan.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_ne!(
        std::fs::read(&plan).unwrap(),
        std::fs::read(&stage).unwrap()
    );
}
