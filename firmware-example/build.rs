//! Puts the memory map where cortex-m-rt's `link.x` finds it: `memory.x` (QEMU mps2-an386,
//! Cortex-M4) for thumbv7em, `memory-microbit.x` (QEMU microbit, Cortex-M0) for thumbv6m;
//! and the controller the firmware runs into `$OUT_DIR/weights.rs`: the `trainer export`
//! file named by `AMPC_WEIGHTS` (absolute, or relative to this package's directory), else
//! controller-core's generated one.
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

    let weights = match env::var_os("AMPC_WEIGHTS") {
        Some(p) if !p.is_empty() => PathBuf::from(p),
        _ => PathBuf::from("../controller-core/src/generated/weights.rs"),
    };
    let text = fs::read_to_string(&weights).unwrap_or_else(|e| {
        panic!(
            "firmware-example: cannot read the controller file {} (AMPC_WEIGHTS, absolute or \
             relative to firmware-example/): {e}",
            weights.display()
        )
    });
    fs::write(out.join("weights.rs"), text).expect("write weights.rs");
    println!("cargo:rerun-if-changed={}", weights.display());
    println!("cargo:rerun-if-env-changed=AMPC_WEIGHTS");
    println!("cargo:rerun-if-changed=memory.x");
    println!("cargo:rerun-if-changed=memory-microbit.x");
    println!("cargo:rerun-if-changed=build.rs");
}
