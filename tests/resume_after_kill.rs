//! A `trainer sample` run killed with SIGKILL mid-way resumes from its checkpoint when the
//! same command is run again, and the final file equals an uninterrupted run's.

use ampc_tests::{kill_at_checkpoint, tempdir, trainer};

#[test]
fn killed_run_resumes_to_the_same_dataset() {
    let dir = tempdir();
    let d = dir.path();
    // A plan long enough to be interrupted: 3000 random pendulum states.
    let cfg = d.join("p.toml");
    let text = trainer::problem::PENDULUM_TOML.replace(
        "sampler = \"grid\"\ncounts = [35, 10]\nseed = 0",
        "sampler = \"random\"\nn = 3000\nseed = 3",
    );
    assert!(text.contains("n = 3000"));
    std::fs::write(&cfg, text).unwrap();
    let cfg = cfg.to_str().unwrap();
    let reference = d.join("ref.bin");
    let o = trainer(&[
        "sample",
        "--config",
        cfg,
        "--out",
        reference.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));

    let out = d.join("run.bin");
    let partial = d.join("run.bin.partial");
    let running = kill_at_checkpoint(
        &[
            "sample",
            "--config",
            cfg,
            "--out",
            out.to_str().unwrap(),
            "--quiet",
        ],
        &partial,
    );
    assert!(
        running,
        "the run ended before its first checkpoint: make the plan longer"
    );
    assert!(!out.exists(), "killed before the end, no final file");
    assert!(partial.exists());
    let (_, records) = trainer::data::dataset::checkpoint::load(&partial)
        .unwrap()
        .expect("a checkpoint");
    assert!(
        !records.is_empty() && records.len() < 3000,
        "{} records",
        records.len()
    );
    let o = trainer(&[
        "sample",
        "--config",
        cfg,
        "--out",
        out.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(
        std::fs::read(&out).unwrap(),
        std::fs::read(&reference).unwrap()
    );
    assert!(!partial.exists());
}
