//! I/O probes through the CLI: stdout on a full disk, an export that
//! cannot write one of its files, an output path under a regular file, a run name that is
//! not one path component, and a states CSV in Excel's form with the problem's state names.
//! Each ends with a clear error (non-zero status, never the panic status 101), names what
//! is at fault and leaves nothing half-written.

use ampc_tests::{config, tempdir, trainer_bin};
use std::path::Path;
use std::process::{Command, Output, Stdio};

fn run_in(dir: &Path, args: &[&str]) -> Output {
    Command::new(trainer_bin())
        .current_dir(dir)
        .args(args)
        .output()
        .expect("run trainer")
}

/// `args` run in `dir` with stdout on `/dev/full` (every write fails with ENOSPC).
fn run_full(dir: &Path, args: &[&str]) -> Output {
    let full = std::fs::File::create("/dev/full").expect("/dev/full");
    Command::new(trainer_bin())
        .current_dir(dir)
        .args(args)
        .stdout(Stdio::from(full))
        .stderr(Stdio::piped())
        .output()
        .expect("run trainer")
}

fn ok(o: &Output, what: &str) {
    assert!(
        o.status.success(),
        "{what}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A small double integrator: problem, dataset, model and certificate in `dir`.
fn setup(dir: &Path) {
    let di = std::fs::read_to_string(config("double_integrator.toml")).unwrap();
    let small = di.replace("counts = [21, 11]", "counts = [5, 4]");
    assert_ne!(
        small, di,
        "the double integrator's grid changed: update this test"
    );
    std::fs::write(
        dir.join("p.toml"),
        format!("{small}\n[training]\nepochs = 10\nvalidation_n = 10\nlog_every = 50\n"),
    )
    .unwrap();
    ok(
        &run_in(
            dir,
            &["sample", "--config", "p.toml", "--out", "d.bin", "--quiet"],
        ),
        "sample",
    );
    ok(
        &run_in(
            dir,
            &["train", "--data", "d.bin", "--out", "m.bin", "--quiet"],
        ),
        "train",
    );
    let o = run_in(
        dir,
        &["certify", "--model", "m.bin", "--data", "d.bin", "--json"],
    );
    ok(&o, "certify");
    std::fs::write(dir.join("c.json"), &o.stdout).unwrap();
}

#[test]
fn io_probes() {
    let t = tempdir();
    let dir = t.path();
    setup(dir);

    // 1. stdout on a full disk: an error naming stdout, status 1, no panic.
    for args in [
        &["certify", "--model", "m.bin", "--data", "d.bin", "--json"][..],
        &["certify", "--model", "m.bin", "--data", "d.bin"][..],
    ] {
        let o = run_full(dir, args);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {e}");
        assert!(!e.contains("panicked"), "{args:?}: {e}");
        assert!(e.contains("cannot write to stdout"), "{args:?}: {e}");
    }

    // 2. An export whose blob cannot be written (its directory is a regular file): no
    //    Rust file without its blob, no header, no ONNX file — and the error names the path.
    std::fs::write(dir.join("afile"), "a regular file").unwrap();
    let o = run_in(
        dir,
        &[
            "export",
            "--model",
            "m.bin",
            "--certificate",
            "c.json",
            "--rust",
            "w.rs",
            "--postcard",
            "afile/w.bin",
            "--c-header",
            "ampc.h",
            "--onnx",
            "w.onnx",
        ],
    );
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(
        e.contains("afile/w.bin") && e.contains("afile is a file, not a directory"),
        "{e}"
    );
    for f in ["w.rs", "ampc.h", "w.onnx"] {
        assert!(!dir.join(f).exists(), "{f} written by a failed export");
    }

    // 3. `--out afile/x.bin`: the path and the reason, not "File exists (os error 17)".
    let o = run_in(
        dir,
        &[
            "sample",
            "--config",
            "p.toml",
            "--out",
            "afile/x.bin",
            "--quiet",
        ],
    );
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(
        e.contains("afile/x.bin") && e.contains("not a directory") && !e.contains("os error 17"),
        "{e}"
    );

    // 4. A run name that is not one normal path component: refused naming the key.
    let p = std::fs::read_to_string(dir.join("p.toml")).unwrap();
    for bad in ["..", ".", ""] {
        let sub = dir.join(format!("name_{}", bad.len()));
        std::fs::create_dir_all(&sub).unwrap();
        let text = p.replace("name = \"double_integrator\"", &format!("name = \"{bad}\""));
        std::fs::write(sub.join("q.toml"), text).unwrap();
        let o = run_in(
            &sub,
            &["run", "--config", "q.toml", "--out", "runs", "--quiet"],
        );
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{bad:?}: {e}");
        assert!(
            e.contains("name") && e.contains("path component"),
            "{bad:?}: {e}"
        );
        let left: Vec<_> = std::fs::read_dir(&sub).unwrap().collect();
        assert_eq!(left.len(), 1, "{bad:?}: files written beside the problem");
    }

    // 5. `solve` and `eval` read Excel's CSV (a byte-order mark) with the problem's state
    //    names as header, as `import` does.
    let cfg = trainer::problem::ProblemConfig::load(&dir.join("p.toml")).unwrap();
    let names = cfg.system.names().states;
    let csv = format!("\u{feff}{}\n0.5,-0.25\n", names.join(","));
    std::fs::write(dir.join("named.csv"), &csv).unwrap();
    std::fs::write(dir.join("plain.csv"), "x1,x2\n0.5,-0.25\n").unwrap();
    for (cmd, a, b) in [
        (
            ["solve", "--config", "p.toml", "--states"],
            "so_named.csv",
            "so_plain.csv",
        ),
        (
            ["eval", "--model", "m.bin", "--states"],
            "ev_named.csv",
            "ev_plain.csv",
        ),
    ] {
        for (states, out) in [("named.csv", a), ("plain.csv", b)] {
            let mut args = cmd.to_vec();
            args.extend([states, "--out", out]);
            ok(&run_in(dir, &args), &format!("{args:?}"));
        }
        assert_eq!(
            std::fs::read(dir.join(a)).unwrap(),
            std::fs::read(dir.join(b)).unwrap(),
            "{cmd:?}: the named header reads the same states"
        );
    }
}
