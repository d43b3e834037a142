//! A plant implemented in your own crate, through the whole pipeline of the library:
//! problem → dataset (SQP labels with sensitivities) → nets → Theorem 1 certificate →
//! exported weights — without touching the trainer's source.
//!
//! The plant is a damped Duffing oscillator with a negative linear stiffness (a double
//! well), driven by a force: `q̈ + δ·q̇ + α·q + β·q³ = u/m`, α = −1, β = 1, δ = 0.3, m = 1.
//! The origin is the unstable hump between the two wells (q = ±1): the MPC has to hold the
//! mass on top of it with |u| ≤ 2.
//!
//! ```text
//! cargo run --release -p trainer --example custom_plant [-- OUT_DIR]
//! ```
//!
//! The files go to `OUT_DIR/duffing/` (default: `<temp>/ampc_custom_plant/duffing/`). A
//! second run skips every stage whose inputs did not change — and changing `Duffing::rhs`
//! changes the plant's fingerprint, hence the problem hash, hence relabels.

use serde::{Deserialize, Serialize};
use std::path::PathBuf;
// Only the crate root's facade (`trainer`'s lib doc), no module paths.
use trainer::{
    run_problem, Certificate, CustomPlant, Dataset, DualNum, Dynamics, Model, MpcLaw,
    ProblemConfig, RunOptions, Stage, StageReport,
};

/// The plant's parameters: its `serde` record is what problem files and hashes see.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct Duffing {
    /// Linear stiffness (negative: a double well).
    alpha: f64,
    /// Cubic stiffness.
    beta: f64,
    /// Damping.
    delta: f64,
    /// Mass (the closed-loop study's mass mismatch scales a parameter named `m`).
    m: f64,
}

impl Default for Duffing {
    fn default() -> Self {
        Duffing {
            alpha: -1.0,
            beta: 1.0,
            delta: 0.3,
            m: 1.0,
        }
    }
}

/// ẋ = f(x, u), written once for every number type: f64 and num-dual's duals, which give
/// the solver exact first and second derivatives.
impl Dynamics for Duffing {
    const NX: usize = 2;
    const NU: usize = 1;
    fn rhs<D: DualNum<Primitive = f64> + Copy>(&self, x: &[D], u: &[D], dx: &mut [D]) {
        let (q, v) = (x[0], x[1]);
        dx[0] = v;
        dx[1] = u[0] * (1.0 / self.m) - v * self.delta - q * self.alpha - q.powi(3) * self.beta;
    }
}

/// The problem: the plant is named, not written; `[system.parameters]` may override the
/// program's values (the others come from `Duffing::default()`). Small sizes: 21 × 21
/// grid, 300 validation states, 400 epochs.
const PROBLEM: &str = r#"
name = "duffing"

[system]
kind = "custom"
name = "duffing"
version = "1"
[system.parameters]
delta = 0.3

[ocp]
ts = 0.1
horizon = 15
q = [10.0, 1.0]
r = [0.5]
p = [10.0, 1.0]
x_lo = [-2.0, -2.0]
x_hi = [2.0, 2.0]
u_lo = [-2.0]
u_hi = [2.0]

[domain]
lo = [-1.5, -1.5]
hi = [1.5, 1.5]

[sampling]
sampler = "grid"
counts = [21, 21]

[training]
hidden = [12, 12]
epochs = 400
batch_size = 32
learning_rate = 1e-2
validation_n = 300
log_every = 100
"#;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let t = std::time::Instant::now();
    let plant = CustomPlant::new("duffing", "1", Duffing::default())?
        .with_names(&["q", "v"], &["force"])?;
    let cfg = ProblemConfig::from_toml_str_with(PROBLEM, "examples/custom_plant.rs", &[plant])?;
    let root = std::env::args()
        .nth(1)
        .map(PathBuf::from)
        .unwrap_or_else(|| std::env::temp_dir().join("ampc_custom_plant"));
    println!(
        "problem `{}`: custom plant `{}` (nx = {}, nu = {}), problem hash {}",
        cfg.name,
        cfg.system.name(),
        cfg.system.nx(),
        cfg.system.nu(),
        &cfg.problem_hash()[..16]
    );

    // The stages of `trainer run` up to the export, on this problem.
    let opts = RunOptions {
        root: root.clone(),
        until: Some(Stage::Export),
        on_stage: Some(print_stage),
        ..Default::default()
    };
    run_problem(&cfg, &opts)?;
    let dir = root.join(&cfg.name);

    // The figures, read back from the files the stages wrote.
    let data = Dataset::load(&dir.join("dataset.bin"))?;
    let c = data.counts();
    println!(
        "dataset: {} states, {} converged, {} soft, {} infeasible, {} failed, {} degenerate",
        c.total, c.converged, c.soft, c.infeasible, c.failed, c.degenerate
    );
    let cert: Certificate =
        serde_json::from_str(&std::fs::read_to_string(dir.join("certificate.json"))?)?;
    println!(
        "certificate (Theorem 1) of the regularized net: ε = {:.4} = ε_D {:.4} + (L_MPC {:.3} + L_NN {:.3}) · r {:.4}",
        cert.eps, cert.eps_d, cert.l_mpc, cert.l_nn, cert.covering_radius
    );
    if cert.l_mpc_is_estimate {
        println!(
            "  L_MPC is an estimate ({}): ε bounds the error only as far as it holds",
            cert.l_mpc_method
        );
    }
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("export_report.json"))?)?;
    println!(
        "export: weights.rs ({} bytes) + weights.bin ({} bytes); f32 allowance {:.3e}, ε on the device {:.4}",
        std::fs::metadata(dir.join("weights.rs"))?.len(),
        std::fs::metadata(dir.join("weights.bin"))?.len(),
        report["f32_allowance_libm"].as_f64().unwrap_or(f64::NAN),
        report["eps_device_libm"].as_f64().unwrap_or(f64::NAN),
    );

    // The net next to the MPC at a few states of X.
    let model = Model::load(&dir.join("model_regularized.bin"))?;
    let mut law = MpcLaw::new(&cfg);
    for x in [[0.0, 0.0], [0.8, -0.4], [-1.2, 1.0], [1.5, 1.5]] {
        let (label, _) = law.solve(&x, None);
        println!(
            "  x = {x:?}: κ(x) = {:+.4} ({}), κ_NN(x) = {:+.4}",
            label.u[0],
            label.status.as_str(),
            model.mlp.predict(&x)[0]
        );
    }

    // The dataset stores the problem with the plant's record; only a program that has
    // the plant can rebuild it (the `trainer` CLI refuses it, naming the plant).
    let stored = ProblemConfig::from_toml_str_with(
        &data.header.config_toml,
        "dataset.bin",
        cfg.system.custom_plants(),
    )?;
    assert_eq!(stored.problem_hash(), cfg.problem_hash());
    if let Err(e) = ProblemConfig::from_toml_str(&data.header.config_toml, "dataset.bin") {
        let msg = e.to_string();
        let line = msg.lines().last().unwrap_or_default();
        println!("read without the plant: {line}");
    }
    println!(
        "files in {} ({:.1} s)",
        dir.display(),
        t.elapsed().as_secs_f64()
    );
    Ok(())
}

fn print_stage(r: &StageReport) {
    let what = if r.skipped { "skipped" } else { "done" };
    println!("[{:>8}] {what} {:.2} s  {}", r.stage, r.seconds, r.summary);
}
