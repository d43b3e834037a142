//! The binary starts and documents itself (this test also makes `cargo test` build the
//! `trainer` binary that the workspace's end-to-end scenarios in `tests/` drive).

#[test]
fn help_lists_the_commands() {
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_trainer"))
        .arg("--help")
        .output()
        .unwrap();
    assert!(o.status.success());
    let s = String::from_utf8_lossy(&o.stdout);
    for cmd in ["solve", "sample", "merge"] {
        assert!(s.contains(cmd), "{s}");
    }
}

#[test]
fn robust_eps_is_validated_before_anything_runs() {
    let dir = std::env::temp_dir().join(format!("ampc_cli_robust_{}", std::process::id()));
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_trainer"))
        .args(["run", "--quiet", "--robust-eps=-1", "--out"])
        .arg(&dir)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(e.contains("robust.eps"), "{e}");
    assert!(!dir.exists(), "nothing may run");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_trainer"))
        .args(["run", "--help"])
        .output()
        .unwrap();
    assert!(String::from_utf8_lossy(&o.stdout).contains("--robust-eps"));
}
