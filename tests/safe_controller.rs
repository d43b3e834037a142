//! The safety-augmented controller as a firmware crate gets it (issue 41 §5): `trainer export
//! --safe-rs` of a sequence-net model, compiled with `controller_core::include_safe_controller!`
//! — the pendulum (`pendulum_ode`, 2 → 16 → 20) and the planar quadrotor (6 → 16 → 40), both
//! trained with `[training] outputs = "sequence"` from `fixtures/safe-controller/*.toml`:
//!
//! ```sh
//! trainer sample --config tests/fixtures/safe-controller/P.toml --out /tmp/P.bin
//! trainer train  --config tests/fixtures/safe-controller/P.toml --data /tmp/P.bin \
//!                --out tests/fixtures/safe-controller/P.model
//! trainer export --model tests/fixtures/safe-controller/P.model \
//!                --safe-rs tests/fixtures/safe-controller/P_safe.rs
//! ```
//! Checks: the committed `P_safe.rs` is what the exporter writes today for the committed
//! model (regenerate with `AMPC_BLESS=1`, through the CLI); the compiled sequence net equals
//! the model's f64 net within f32 rounding on 10³ states of X; and the compiled `CONTROLLER`
//! closes the loop around the trainer's **f64** model (not the f32 plant it checks with) from
//! seeded states of X: once a safe sequence exists, the state box holds at every step, the
//! safe candidate never fails its check (`SAFE_INFEASIBLE`: the f32 margins cover the f64/f32
//! difference on these runs) and the fallback share is printed.

use controller_core::mlp::Network;
use controller_core::safe::SafeFlags;
use std::path::{Path, PathBuf};
use std::process::Command;
use trainer::problem::model::Discrete;
use trainer::problem::ProblemConfig;

mod pend {
    controller_core::include_safe_controller!("fixtures/safe-controller/pendulum_ode_safe.rs");
}
mod quad {
    controller_core::include_safe_controller!("fixtures/safe-controller/planar_quadrotor_safe.rs");
}

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn fixture(file: &str) -> PathBuf {
    root().join("tests/fixtures/safe-controller").join(file)
}

fn config(name: &str) -> ProblemConfig {
    ProblemConfig::load(&fixture(&format!("{name}.toml"))).unwrap()
}

fn model(name: &str) -> trainer::certify::Model {
    trainer::certify::Model::load(&fixture(&format!("{name}.model"))).unwrap()
}

fn uniform(s: &mut u64) -> f64 {
    *s ^= *s << 13;
    *s ^= *s >> 7;
    *s ^= *s << 17;
    (*s >> 11) as f64 / (1u64 << 53) as f64
}

#[test]
fn committed_files_are_what_the_exporter_writes() {
    let dir = tempfile::tempdir().unwrap();
    for name in ["pendulum_ode", "planar_quadrotor"] {
        let out = dir.path().join(format!("{name}_safe.rs"));
        let st = Command::new(ampc_tests::trainer_bin())
            .args(["export", "--model"])
            .arg(fixture(&format!("{name}.model")))
            .arg("--safe-rs")
            .arg(&out)
            .output()
            .unwrap();
        assert!(
            st.status.success(),
            "{}",
            String::from_utf8_lossy(&st.stderr)
        );
        let text = std::fs::read_to_string(&out).unwrap();
        let path = fixture(&format!("{name}_safe.rs"));
        if std::env::var_os("AMPC_BLESS").is_some() {
            std::fs::write(&path, &text).unwrap();
        }
        assert!(
            std::fs::read_to_string(&path).unwrap() == text,
            "{} is not what `trainer export --safe-rs` writes: rerun with AMPC_BLESS=1",
            path.display()
        );
        // The library call gives the same file from the fixture's problem file.
        let seq = model(name).sequence.unwrap();
        let (lib, _) = trainer::deploy::safe_rs::render_safe_rs(
            &config(name),
            &seq,
            model(name).settings.sequence_form,
        )
        .unwrap();
        assert!(lib == text, "{name}: CLI and library differ");
    }
}

#[test]
fn a_model_without_a_sequence_net_is_refused_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let mut m = model("pendulum_ode");
    m.sequence = None;
    let plain = dir.path().join("plain.model");
    m.save(&plain).unwrap();
    let out = dir.path().join("x.rs");
    let st = Command::new(ampc_tests::trainer_bin())
        .args(["export", "--model"])
        .arg(&plain)
        .arg("--safe-rs")
        .arg(&out)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&st.stderr);
    assert!(!st.status.success());
    assert!(
        err.contains("plain.model") && err.contains("no sequence net"),
        "{err}"
    );
    assert!(!out.exists());
}

/// Largest |compiled − f64| / (1 + |f64|) of the sequence net over 10³ states of X.
fn net_difference<const NX: usize, const M: usize>(
    name: &str,
    net: &impl Network<NX, Output = [f32; M]>,
) -> f64 {
    let cfg = config(name);
    let seq = model(name).sequence.unwrap();
    assert_eq!(seq.nu(), M);
    let mut s = 0x5eed_u64;
    let mut worst = 0.0f64;
    for _ in 0..1000 {
        let x: [f32; NX] = std::array::from_fn(|i| {
            let (lo, hi) = (cfg.domain.lo[i], cfg.domain.hi[i]);
            (lo + (hi - lo) * uniform(&mut s)) as f32
        });
        let xd: Vec<f64> = x.iter().map(|v| f64::from(*v)).collect();
        let p = seq.predict(&xd);
        let y = net.forward(&x);
        for (a, b) in y.iter().zip(&p) {
            worst = worst.max((f64::from(*a) - b).abs() / (1.0 + b.abs()));
        }
    }
    worst
}

#[test]
fn compiled_sequence_nets_are_the_models() {
    let d = net_difference::<2, 20>("pendulum_ode", &pend::safe::sequence::NET);
    let q = net_difference::<6, 40>("planar_quadrotor", &quad::safe::sequence::NET);
    eprintln!(
        "sequence nets, largest relative difference f32 vs f64: pendulum {d:e}, quadrotor {q:e}"
    );
    assert!(d < 1e-4 && q < 1e-4, "{d:e} {q:e}");
    assert_eq!((pend::safe::N, pend::safe::NX, pend::safe::NU), (20, 2, 1));
    assert_eq!((quad::safe::N, quad::safe::NX, quad::safe::NU), (20, 6, 2));
    assert!(quad::safe::GUARANTEE.starts_with("deterministic for the nominal model"));
}

/// Counts of a closed loop: steps with the candidate, with the fallback, without a safe
/// sequence, and runs that never got one.
#[derive(Debug, Default)]
struct Tally {
    candidate: usize,
    fallback: usize,
    no_safe: usize,
    never: usize,
    steps: usize,
}

/// Closed loops of the compiled controller `step` around the f64 model of `name` from
/// `runs` seeded states of X (scaled by `shrink` about its centre), `len` steps each.
fn closed_loops<const NX: usize, const NU: usize>(
    name: &str,
    runs: usize,
    len: usize,
    shrink: f64,
    mut step: impl FnMut(bool, &[f32; NX]) -> controller_core::SafeOutput<NU>,
    box_violation: impl Fn(&[f32; NX]) -> f32,
) -> Tally {
    let cfg = config(name);
    let f = Discrete::new(cfg.system.clone(), cfg.ocp.ts, cfg.ocp.rk4_substeps);
    let mut s = 0x00c1_05ed_u64;
    let mut t = Tally::default();
    for run in 0..runs {
        let mut x: Vec<f64> = (0..NX)
            .map(|i| {
                let (lo, hi) = (cfg.domain.lo[i], cfg.domain.hi[i]);
                let c = 0.5 * (lo + hi);
                c + shrink * (hi - lo) * (uniform(&mut s) - 0.5)
            })
            .collect();
        let mut safe = false;
        for k in 0..len {
            let xf: [f32; NX] = std::array::from_fn(|i| x[i] as f32);
            let out = step(k == 0, &xf);
            let fl = out.flags;
            t.steps += 1;
            t.candidate += fl.contains(SafeFlags::CANDIDATE) as usize;
            t.fallback += fl.contains(SafeFlags::FALLBACK) as usize;
            t.no_safe += fl.contains(SafeFlags::NO_SAFE) as usize;
            if safe {
                assert!(
                    !fl.contains(SafeFlags::SAFE_INFEASIBLE) && !fl.contains(SafeFlags::NO_SAFE),
                    "{name} run {run} step {k}: {fl:?} at {xf:?}"
                );
            }
            safe |= fl.contains(SafeFlags::CANDIDATE) || fl.contains(SafeFlags::FALLBACK);
            let u: Vec<f64> = out.u.iter().map(|v| f64::from(*v)).collect();
            let mut next = vec![0.0; NX];
            f.step(&x, &u, &mut next);
            x = next;
            if safe {
                let xf: [f32; NX] = std::array::from_fn(|i| x[i] as f32);
                assert!(
                    box_violation(&xf) <= 0.0,
                    "{name} run {run} step {k}: state box violated at {x:?}"
                );
            }
        }
        t.never += (!safe) as usize;
    }
    t
}

#[test]
fn compiled_controllers_close_the_loop_on_the_f64_model() {
    let mut ctl = pend::safe::CONTROLLER;
    let p = closed_loops::<2, 1>(
        "pendulum_ode",
        40,
        80,
        0.5,
        |first, x| {
            if first {
                ctl.reset();
            }
            ctl.step(x)
        },
        pend::safe::plant::state_box_violation,
    );
    let mut ctl = quad::safe::CONTROLLER;
    let q = closed_loops::<6, 2>(
        "planar_quadrotor",
        40,
        80,
        0.5,
        |first, x| {
            if first {
                ctl.reset();
            }
            ctl.step(x)
        },
        quad::safe::plant::state_box_violation,
    );
    eprintln!("safe closed loops on the f64 model: pendulum {p:?}, quadrotor {q:?}");
    for (name, t) in [("pendulum", &p), ("quadrotor", &q)] {
        assert!(
            t.candidate > 0,
            "{name}: the candidate was never used: {t:?}"
        );
        assert_eq!(t.candidate + t.fallback + t.no_safe, t.steps, "{name}");
    }
}
