//! Puts the memory map where cortex-m-rt's `link.x` finds it: `memory.x` (QEMU mps2-an386,
//! Cortex-M4) for thumbv7em, `memory-microbit.x` (QEMU microbit, Cortex-M0) for thumbv6m.
use std::{env, fs, path::PathBuf};

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let target = env::var("TARGET").unwrap_or_default();
    let map: &[u8] = if target.starts_with("thumbv6m") {
        include_bytes!("memory-microbit.x")
    } else {
        include_bytes!("memory.x")
    };
    fs::write(out.join("memory.x"), map).expect("write memory.x");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=memory.x");
    println!("cargo:rerun-if-changed=memory-microbit.x");
    println!("cargo:rerun-if-changed=build.rs");
}
