//! The firmware on an emulated Cortex-M4: builds `firmware-example` for
//! thumbv7em-none-eabihf, runs it in QEMU (mps2-an386, semihosting), and compares its
//! 91-row trajectory with (1) the host running the same f32 code — bit for bit — and
//! (2) the f64 network, within the certificate's f32 allowance. Also checks on the ELF
//! that no panic symbol is reachable from `ampc_evaluate` (call graph from objdump).
//!
//! Needs `rustup target add thumbv7em-none-eabihf`, `qemu-system-arm` and
//! `binutils-arm-none-eabi` (`.ci/run` installs them); fails loudly without them.

use std::collections::{BTreeMap, BTreeSet};
use std::path::PathBuf;
use std::process::Command;

use controller_core::{Flags, CERTIFICATE};
use firmware_example::{run, Row, HEADER, STEPS};

/// `target/` of this build (target/<profile>/deps/<test> → target).
fn target_dir() -> PathBuf {
    let exe = std::env::current_exe().unwrap();
    exe.ancestors().nth(3).unwrap().to_path_buf()
}

/// Builds the firmware binaries (own target dir: no lock contention with the outer cargo).
fn build_firmware() -> PathBuf {
    let dir = target_dir().join("firmware-qemu");
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let mut cmd = Command::new(cargo);
    cmd.args(["build", "-p", "firmware-example", "--release", "--bins"])
        .args(["--target", "thumbv7em-none-eabihf"])
        .env("CARGO_TARGET_DIR", &dir)
        .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/.."));
    if controller_core::activation::TANH_KIND == "fast" {
        cmd.args(["--features", "fast-tanh"]);
    }
    let st = cmd.status().expect("run cargo");
    assert!(
        st.success(),
        "building the firmware failed (is the target installed? rustup target add thumbv7em-none-eabihf)"
    );
    dir.join("thumbv7em-none-eabihf/release")
}

fn qemu(elf: &std::path::Path) -> String {
    let out = Command::new("qemu-system-arm")
        .args(["-cpu", "cortex-m4", "-machine", "mps2-an386", "-nographic"])
        .args(["-semihosting-config", "enable=on,target=native", "-kernel"])
        .arg(elf)
        .output()
        .expect("qemu-system-arm not found: apt-get install -y qemu-system-arm");
    assert!(
        out.status.success(),
        "firmware exited with {:?}",
        out.status
    );
    String::from_utf8(out.stdout).unwrap()
}

fn parse(csv: &str) -> Vec<Row> {
    let mut lines = csv.lines();
    assert_eq!(lines.next(), Some(HEADER));
    lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            assert_eq!(f.len(), 5, "row {l:?}");
            Row {
                k: f[0].parse().unwrap(),
                x: [f[1].parse().unwrap(), f[2].parse().unwrap()],
                u: f[3].parse().unwrap(),
                flags: Flags(f[4].parse().unwrap()),
            }
        })
        .collect()
}

#[test]
fn firmware_trajectory_matches_host_and_f64_network() {
    let bins = build_firmware();
    let device = parse(&qemu(&bins.join("firmware-example")));
    assert_eq!(device.len(), STEPS + 1);
    assert!(device.iter().enumerate().all(|(k, r)| r.k == k));

    // (1) The host runs the same f32 code: identical bits.
    let mut host = Vec::new();
    run(|r| host.push(*r));
    for (d, h) in device.iter().zip(&host) {
        assert_eq!(
            (d.x.map(f32::to_bits), d.u.to_bits(), d.flags),
            (h.x.map(f32::to_bits), h.u.to_bits(), h.flags),
            "step {}: device {d:?} host {h:?}",
            d.k
        );
    }

    // (2) Along the device's trajectory, the f64 network (at the projected state, output
    // clamped to the same band) is within the certified f32 allowance.
    let (model, _) = ampc_tests::trained_pendulum();
    assert_eq!(
        model.hash, CERTIFICATE.hash,
        "the test's model is not the compiled-in one"
    );
    let (lo, hi) = model.domain_f32();
    let mut worst = 0.0f64;
    for r in &device {
        let xp: Vec<f64> = (0..2)
            .map(|i| f64::from(r.x[i].clamp(lo[i], hi[i])))
            .collect();
        let u64 = model.eval_f64(&xp)[0].clamp(
            f64::from(CERTIFICATE.clamp_lo[0]),
            f64::from(CERTIFICATE.clamp_hi[0]),
        );
        worst = worst.max((f64::from(r.u) - u64).abs());
    }
    println!(
        "max |u_device − u_f64| = {worst:e} (allowance {:e})",
        CERTIFICATE.f32_allowance
    );
    assert!(worst <= CERTIFICATE.f32_allowance);
}

/// Call graph of an ELF from `arm-none-eabi-objdump -d`: function → called/branched-to
/// functions, plus each function's size from `arm-none-eabi-nm -S`.
fn call_graph(
    elf: &std::path::Path,
) -> (BTreeMap<String, BTreeSet<String>>, BTreeMap<String, u64>) {
    let out = Command::new("arm-none-eabi-objdump")
        .args(["-d", "--no-show-raw-insn"])
        .arg(elf)
        .output()
        .expect("arm-none-eabi-objdump not found: apt-get install -y binutils-arm-none-eabi");
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    let mut graph: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    let mut cur = String::new();
    for line in text.lines() {
        if let Some(name) = line
            .strip_suffix(">:")
            .and_then(|l| l.split_once(" <"))
            .map(|x| x.1)
        {
            cur = name.to_string();
            graph.entry(cur.clone()).or_default();
        } else if let Some((_, target)) = line.split_once('<') {
            // Any reference to another symbol: bl, b.w, b, cbz/cbnz, and ldr of an address.
            let t = target.split(['+', '>']).next().unwrap_or("");
            if !t.is_empty() && t != cur {
                graph.entry(cur.clone()).or_default().insert(t.to_string());
            }
        }
    }
    let nm = Command::new("arm-none-eabi-nm")
        .args(["-S", "--size-sort"])
        .arg(elf)
        .output()
        .unwrap();
    let sizes = String::from_utf8(nm.stdout)
        .unwrap()
        .lines()
        .filter_map(|l| {
            let f: Vec<&str> = l.split_whitespace().collect();
            Some((
                f.get(3)?.to_string(),
                u64::from_str_radix(f.get(1)?, 16).ok()?,
            ))
        })
        .collect();
    (graph, sizes)
}

#[test]
fn no_panic_reachable_from_evaluate_in_the_elf() {
    let bins = build_firmware();
    let elf = bins.join("evaluate-bench");
    let (graph, sizes) = call_graph(&elf);
    assert!(
        graph.contains_key("ampc_evaluate"),
        "ampc_evaluate not in the ELF"
    );
    // Sanity: the checker sees panics where they are (the firmware's own panic handler).
    assert!(
        graph.keys().any(|k| k.contains("panic")),
        "no panic symbol at all: checker blind?"
    );
    let mut seen = BTreeSet::new();
    let mut stack = vec!["ampc_evaluate".to_string()];
    while let Some(f) = stack.pop() {
        if seen.insert(f.clone()) {
            stack.extend(graph.get(&f).into_iter().flatten().cloned());
        }
    }
    let bad: Vec<&String> = seen
        .iter()
        .filter(|f| f.to_lowercase().contains("panic"))
        .collect();
    assert!(
        bad.is_empty(),
        "panic paths reachable from ampc_evaluate: {bad:?}"
    );
    let code: u64 = seen.iter().filter_map(|f| sizes.get(f)).sum();
    // The optimiser turns the weights into literal-pool constants of `ampc_evaluate`, so the
    // static itself usually disappears: its size (if any) is added separately.
    let data = sizes.get("AMPC_CONTROLLER").copied().unwrap_or(0);
    println!(
        "controller flash: {code} B in {} functions {:?} (code + literal pools) + AMPC_CONTROLLER static {data} B = {} B",
        seen.len(),
        seen,
        code + data
    );
    assert!(code > 0);
}
