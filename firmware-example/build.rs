//! Puts the memory map where cortex-m-rt's `link.x` finds it: `memory.x` (QEMU mps2-an386,
//! Cortex-M4) for thumbv7em, `memory-microbit.x` (QEMU microbit, Cortex-M0) for thumbv6m;
//! and the controller the firmware runs into `$OUT_DIR/weights.rs`: the `trainer export`
//! file named by `AMPC_WEIGHTS` (absolute, or relative to this package's directory), else
//! controller-core's generated one (then the cfg `ampc_pendulum` is set: the library's closed
//! loop simulates that controller's plant).
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

    // The built-in pendulum unless AMPC_WEIGHTS names another export; `ampc_pendulum` tells
    // the library that its f32 pendulum plant is the controller's plant (the closed loop).
    println!("cargo::rustc-check-cfg=cfg(ampc_pendulum)");
    let weights = match env::var_os("AMPC_WEIGHTS") {
        Some(p) if !p.is_empty() => PathBuf::from(p),
        _ => {
            println!("cargo:rustc-cfg=ampc_pendulum");
            PathBuf::from("../controller-core/src/demo/weights.rs")
        }
    };
    // Cargo runs build scripts in the package's directory: name the file as it was looked up.
    let shown = env::current_dir()
        .map(|d| d.join(&weights))
        .unwrap_or_else(|_| weights.clone());
    let text = fs::read_to_string(&weights).unwrap_or_else(|e| {
        panic!(
            "firmware-example: cannot read the controller file {} (AMPC_WEIGHTS, absolute or \
             relative to firmware-example/): {e}",
            shown.display()
        )
    });
    for item in [
        "pub const NX: usize",
        "pub const NU: usize",
        "pub type Net",
        "CERTIFICATE_LIBM",
    ] {
        assert!(
            text.contains(item),
            "firmware-example: {} (AMPC_WEIGHTS) is not a `trainer export --rust` file: no `{item}`",
            shown.display()
        );
    }
    fs::write(out.join("weights.rs"), text).expect("write weights.rs");
    println!("cargo:rerun-if-changed={}", weights.display());
    println!("cargo:rerun-if-env-changed=AMPC_WEIGHTS");
    println!("cargo:rerun-if-changed=memory.x");
    println!("cargo:rerun-if-changed=memory-microbit.x");
    println!("cargo:rerun-if-changed=build.rs");
}
