//! The library path of `examples/custom_plant.rs`: a plant implemented in this crate (the
//! paper's pendulum, written again as a user's struct) runs the pipeline through
//! `trainer::pipeline::run_problem` up to the exported weights, and its labels equal those
//! of the built-in pendulum through the same API; the `trainer` command line refuses the
//! files of a custom plant with an error naming the plant.

use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::process::Command;
use trainer::data::dataset::Dataset;
use trainer::pipeline::{run_problem, RunOptions};
use trainer::problem::model::{CustomPlant, DualNum, Dynamics, System};
use trainer::problem::ProblemConfig;

/// ẋ₁ = x₂, ẋ₂ = u/(m l²) − (g/l)·sin(x₁ + π): the paper's pendulum, this crate's own type.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct MyPendulum {
    m: f64,
    l: f64,
    g: f64,
}

impl Dynamics for MyPendulum {
    const NX: usize = 2;
    const NU: usize = 1;
    fn rhs<D: DualNum<Primitive = f64> + Copy>(&self, x: &[D], u: &[D], dx: &mut [D]) {
        dx[0] = x[1];
        dx[1] = u[0] * (1.0 / (self.m * self.l * self.l))
            - (x[0] + std::f64::consts::PI).sin() * (self.g / self.l);
    }
}

fn plant() -> CustomPlant {
    let p = MyPendulum {
        m: 1.0,
        l: 1.0,
        g: 9.81,
    };
    CustomPlant::new("my_pendulum", "1", p).unwrap()
}

/// The paper's pendulum problem, small: a 9 × 5 grid of the full domain, 100 epochs.
fn small(system: Option<System>) -> ProblemConfig {
    let mut cfg = ProblemConfig::default();
    cfg.sampling.counts = vec![9, 5];
    cfg.training.epochs = 100;
    cfg.training.validation_n = 40;
    if let Some(s) = system {
        cfg.name = "my_pendulum".into();
        cfg.system = s;
    }
    cfg.validate().unwrap();
    cfg
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("ampc_custom_{name}_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

fn trainer(args: &[&str], extra: &[&Path]) -> (bool, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_trainer"))
        .args(args)
        .args(extra)
        .output()
        .unwrap();
    (
        o.status.success(),
        String::from_utf8_lossy(&o.stderr).to_string(),
    )
}

#[test]
fn a_custom_plant_runs_the_pipeline_and_matches_the_built_in() {
    let root = tmp("pipeline");
    let opts = |until: &str| RunOptions {
        root: root.clone(),
        until: Some(until.parse().unwrap()),
        ..Default::default()
    };
    let builtin = small(None);
    let custom = small(Some(System::Custom(plant())));
    run_problem(&builtin, &opts("sample")).unwrap();
    let reports = run_problem(&custom, &opts("export")).unwrap();
    let stages: Vec<&str> = reports.iter().map(|r| r.stage.as_str()).collect();
    assert_eq!(
        stages,
        [
            "sample",
            "validate",
            "train",
            "certify",
            "refine",
            "statistical",
            "export"
        ]
    );
    let dir = root.join("my_pendulum");
    for f in [
        "problem.toml",
        "dataset.bin",
        "model_regularized.bin",
        "certificate.json",
        "weights.rs",
        "weights.bin",
    ] {
        assert!(dir.join(f).exists(), "{f}");
    }

    // Labels of the custom plant equal the built-in's.
    let a = Dataset::load(&root.join("pendulum/dataset.bin")).unwrap();
    let b = Dataset::load(&dir.join("dataset.bin")).unwrap();
    assert_eq!(a.records.len(), 45);
    assert_eq!(a.records.len(), b.records.len());
    let mut worst = 0.0f64;
    for (ra, rb) in a.records.iter().zip(&b.records) {
        assert_eq!(ra.x, rb.x);
        assert_eq!(ra.status, rb.status, "x {:?}", ra.x);
        assert!(ra.is_labelled(), "x {:?}", ra.x);
        for (p, q) in
            ra.u.iter()
                .chain(&ra.du_dx)
                .zip(rb.u.iter().chain(&rb.du_dx))
        {
            worst = worst.max((p - q).abs() / (1.0 + p.abs()));
        }
        worst = worst.max((ra.cost - rb.cost).abs() / (1.0 + ra.cost.abs()));
    }
    eprintln!("largest relative difference of the labels (u, ∂u/∂x, cost): {worst:e}");
    assert!(
        worst <= 1e-12,
        "largest relative label difference {worst:e}"
    );

    // The stored problem is the custom one, read back only with its plant.
    assert_eq!(b.header.problem_hash, custom.problem_hash());
    assert_ne!(b.header.problem_hash, a.header.problem_hash);
    let text = std::fs::read_to_string(dir.join("problem.toml")).unwrap();
    let back = ProblemConfig::from_toml_str_with(&text, "problem.toml", &[plant()]).unwrap();
    assert_eq!(back, custom);
    let stored =
        ProblemConfig::from_toml_str_with(&b.header.config_toml, "dataset", &[plant()]).unwrap();
    assert_eq!(stored.problem_hash(), custom.problem_hash());

    // The certificate is about this problem and dataset; the certificate checks pass.
    let cert: trainer::certify::certificate::Certificate =
        serde_json::from_str(&std::fs::read_to_string(dir.join("certificate.json")).unwrap())
            .unwrap();
    assert_eq!(cert.problem_hash, custom.problem_hash());
    assert!(cert.eps.is_finite() && cert.eps >= cert.eps_d, "{cert:?}");

    // A second run skips every stage; another plant under the same name is refused.
    let again = run_problem(&custom, &opts("export")).unwrap();
    assert!(again.iter().all(|r| r.skipped));
    let heavier = CustomPlant::new(
        "my_pendulum",
        "1",
        MyPendulum {
            m: 1.2,
            l: 1.0,
            g: 9.81,
        },
    )
    .unwrap();
    let e = run_problem(&small(Some(System::Custom(heavier))), &opts("sample"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("another problem named `my_pendulum`"), "{e}");
    let _ = std::fs::remove_dir_all(&root);
}

#[test]
fn the_command_line_refuses_a_custom_plant_naming_it() {
    let root = tmp("cli");
    let custom = small(Some(System::Custom(plant())));
    let opts = RunOptions {
        root: root.clone(),
        until: Some(trainer::pipeline::Stage::Train),
        ..Default::default()
    };
    run_problem(&custom, &opts).unwrap();
    let dir = root.join("my_pendulum");
    let (data, model) = (dir.join("dataset.bin"), dir.join("model_regularized.bin"));
    let named =
        |e: &str| e.contains("custom plant `my_pendulum`") && e.contains("cannot rebuild it");
    // The dataset's stored problem (no --config): train, certify, compare.
    let out = root.join("m.bin");
    let (ok, e) = trainer(&["train", "--data"], &[&data, Path::new("--out"), &out]);
    assert!(!ok && named(&e) && e.contains("dataset.bin"), "{e}");
    assert!(!out.exists());
    let (ok, e) = trainer(
        &["certify", "--model"],
        &[&model, Path::new("--data"), &data],
    );
    assert!(!ok && named(&e), "{e}");
    // The run's problem.toml.
    let (ok, e) = trainer(
        &["run", "--quiet"],
        &[
            &dir.join("problem.toml"),
            Path::new("--out"),
            &root.join("cli_run"),
        ],
    );
    assert!(!ok && named(&e) && e.contains("problem.toml"), "{e}");
    assert!(!root.join("cli_run").exists(), "nothing may run");
    // With another problem's file: the labels are of another problem, never certified.
    let pend = concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/pendulum.toml");
    let (ok, e) = trainer(
        &["certify", "--config", pend, "--model"],
        &[&model, Path::new("--data"), &data],
    );
    assert!(
        !ok && e.contains("labelled for problem `my_pendulum`"),
        "{e}"
    );
    let _ = std::fs::remove_dir_all(&root);
}
