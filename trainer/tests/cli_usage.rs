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
