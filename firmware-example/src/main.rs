//! Firmware example: a control loop on a Cortex-M4 (arrives with the embedded-side work).
//!
//! On the host this binary does nothing; the bare-metal build is cfg-gated on
//! `target_os = "none"`.

fn main() {
    println!("firmware-example: build for thumbv7em-none-eabihf to run on a Cortex-M4");
}
