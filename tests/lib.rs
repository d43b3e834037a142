//! Shared helpers for the end-to-end scenarios in this folder.
//!
//! The scenarios drive the real `trainer` binary. `cargo test --workspace` builds it
//! before any test runs (the `trainer` package has integration tests, so its binary is
//! built), into the same target directory as these test executables.

use std::path::PathBuf;
use std::process::{Command, Output};

/// Path of the `trainer` binary of this build.
pub fn trainer_bin() -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    // target/<profile>/deps/<test> → target/<profile>/trainer
    let dir = exe
        .parent()
        .and_then(|d| d.parent())
        .expect("target directory");
    let bin = dir.join(format!("trainer{}", std::env::consts::EXE_SUFFIX));
    assert!(
        bin.exists(),
        "{} not found: run the tests with `cargo test --workspace` so that the trainer binary is built",
        bin.display()
    );
    bin
}

/// Runs `trainer` with `args`.
pub fn trainer(args: &[&str]) -> Output {
    Command::new(trainer_bin())
        .args(args)
        .output()
        .expect("run trainer")
}

/// Runs `trainer args` and kills it (SIGKILL) as soon as `checkpoint` exists (or after
/// 120 s). Returns whether it was still running when killed, i.e. whether the kill
/// interrupted it after its first checkpoint rather than after its end.
pub fn kill_at_checkpoint(args: &[&str], checkpoint: &std::path::Path) -> bool {
    use std::time::{Duration, Instant};
    let mut child = Command::new(trainer_bin())
        .args(args)
        .spawn()
        .expect("spawn trainer");
    let t = Instant::now();
    while !checkpoint.exists()
        && child.try_wait().expect("poll trainer").is_none()
        && t.elapsed() < Duration::from_secs(120)
    {
        std::thread::sleep(Duration::from_millis(2));
    }
    let running = child.try_wait().expect("poll trainer").is_none();
    child.kill().ok();
    child.wait().expect("reap trainer");
    running
}

/// Path of a problem file shipped in `configs/`.
pub fn config(name: &str) -> String {
    format!("{}/../configs/{name}", env!("CARGO_MANIFEST_DIR"))
}

/// A fresh temporary directory.
pub fn tempdir() -> tempfile::TempDir {
    tempfile::tempdir().expect("temporary directory")
}

/// The paper's pendulum controller as `trainer run` produces it (sample → validate →
/// train → certify → export, default problem and seeds), computed once per test binary.
/// Returns the export model and the directory holding `weights.rs` / `weights.bin`.
pub fn trained_pendulum() -> &'static (trainer::deploy::export::ExportModel, PathBuf) {
    static CELL: std::sync::OnceLock<(trainer::deploy::export::ExportModel, PathBuf)> =
        std::sync::OnceLock::new();
    CELL.get_or_init(|| {
        let root =
            std::env::temp_dir().join(format!("ampc-trained-pendulum-{}", std::process::id()));
        // The committed demo controller is the paper's: Theorem 1's regularized net, without
        // the tiers `trainer run` adds by default (refinement, statistical band).
        let mut cfg = trainer::problem::ProblemConfig::default();
        cfg.refine.enabled = trainer::problem::RefineSwitch::Off;
        cfg.certify.statistical = 0;
        let opts = trainer::pipeline::RunOptions {
            root: root.clone(),
            until: Some(trainer::pipeline::Stage::Export),
            ..Default::default()
        };
        trainer::pipeline::run_problem(&cfg, &opts).expect("pipeline");
        let dir = root.join(&cfg.name);
        let m = trainer::certify::Model::load(&dir.join("model_regularized.bin")).expect("model");
        let (f, _) = trainer::certify::file::read_certificate(
            &dir.join("certificate.json"),
            false,
            &Default::default(),
        )
        .expect("certificate");
        (
            trainer::deploy::export::ExportModel::from_trained(&cfg.name, &m, &f.base)
                .expect("export model")
                .with_certificate_guarantee(&f.guarantee),
            dir,
        )
    })
}

/// Runs the firmware `elf` on QEMU's `machine` with `cpu` (semihosting on) and returns its
/// standard output; panics, naming the file, unless it exits with status 0. Under coreutils'
/// `timeout` (300 s): a firmware that hangs fails the test instead of hanging it.
pub fn qemu(cpu: &str, machine: &str, elf: &std::path::Path) -> String {
    let out = Command::new("timeout")
        .args(["-k", "5", "300", "qemu-system-arm"])
        .args(["-cpu", cpu, "-machine", machine, "-nographic"])
        .args(["-semihosting-config", "enable=on,target=native", "-kernel"])
        .arg(elf)
        .output()
        .expect("coreutils' timeout not found");
    assert!(
        out.status.success(),
        "firmware {} on {machine} exited with {:?} (124: timed out after 300 s; 127: \
         qemu-system-arm not found, apt-get install -y qemu-system-arm): {}",
        elf.display(),
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).expect("firmware output is UTF-8")
}
