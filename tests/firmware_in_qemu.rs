//! The firmware on an emulated Cortex-M4 (thumbv7em-none-eabihf, QEMU mps2-an386, hardware
//! f32) and an emulated Cortex-M0 (thumbv6m-none-eabi, QEMU microbit, no FPU: soft-float f32,
//! the ARMv6-M instruction set of the M0+): builds `firmware-example` for the target, runs it
//! in QEMU (semihosting), and compares its 91-row trajectory with (1) the host running the
//! same f32 code — bit for bit — and (2) the f64 network, within the certificate's f32
//! allowance; runs `evaluate-check` (600 probe states: edge cases, inside and around X) and
//! compares every `u` bit pattern and flag set with the host's `evaluate`. Also checks on
//! each ELF that no panic symbol is reachable from `ampc_evaluate`, nor from `ampc_safe_step`
//! (`safe-bench`: the SafeController on the generated quadrotor, which also runs once in QEMU),
//! nor from `ampc_safe_step_net` / `ampc_safe_step_net_pendulum` (the same with the
//! sequence networks of `tests/fixtures/safe-controller`, run three steps in QEMU)
//! (call graph from objdump).
//!
//! Needs `rustup target add thumbv7em-none-eabihf thumbv6m-none-eabi`, `qemu-system-arm`
//! and `binutils-arm-none-eabi` (`.ci/run` installs them); fails loudly without them.

use std::collections::{BTreeMap, BTreeSet};
use std::path::PathBuf;
use std::process::Command;

use controller_core::{demo::CERTIFICATE, Flags};
use firmware_example::{probe_state, run, Row, HEADER, PROBES, STEPS};

/// A QEMU machine and the Rust target built for it.
struct Board {
    target: &'static str,
    cpu: &'static str,
    machine: &'static str,
}

/// Cortex-M4F: QEMU's MPS2 AN386 image.
const M4: Board = Board {
    target: "thumbv7em-none-eabihf",
    cpu: "cortex-m4",
    machine: "mps2-an386",
};

/// Cortex-M0 (ARMv6-M, the M0+'s instruction set, no FPU): QEMU's BBC micro:bit.
const M0: Board = Board {
    target: "thumbv6m-none-eabi",
    cpu: "cortex-m0",
    machine: "microbit",
};

/// `target/` of this build (target/<profile>/deps/<test> → target).
fn target_dir() -> PathBuf {
    let exe = std::env::current_exe().unwrap();
    exe.ancestors().nth(3).unwrap().to_path_buf()
}

/// `cargo <args>` on `firmware-example` with the controller `weights` (a `trainer export
/// --rust` file; `None`: the built-in pendulum, whatever the caller's environment names),
/// the test crate's tanh, and a target dir of its own per controller (no lock contention
/// with the outer cargo); returns the command and that target dir.
fn firmware_cargo(args: &[&str], weights: Option<&str>) -> (Command, PathBuf) {
    let dir = target_dir().join(if weights.is_some() {
        "firmware-qemu-own"
    } else {
        "firmware-qemu"
    });
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let mut cmd = Command::new(cargo);
    cmd.args(args)
        .args(["-p", "firmware-example", "--release"])
        .env("CARGO_TARGET_DIR", &dir)
        .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/.."));
    match weights {
        Some(w) => cmd.env("AMPC_WEIGHTS", w),
        None => cmd.env_remove("AMPC_WEIGHTS"),
    };
    if controller_core::activation::TANH_KIND == "fast" {
        cmd.args(["--features", "fast-tanh"]);
    }
    (cmd, dir)
}

/// Builds the firmware binaries for `board` with `weights` (see [`firmware_cargo`]).
fn build_firmware_with(board: &Board, weights: Option<&str>) -> PathBuf {
    let (mut cmd, dir) = firmware_cargo(&["build", "-q", "--bins"], weights);
    let st = cmd
        .args(["--target", board.target])
        .status()
        .expect("run cargo");
    assert!(
        st.success(),
        "building the firmware ({}) failed (is the target installed? rustup target add {})",
        weights.unwrap_or("the pendulum"),
        board.target
    );
    dir.join(board.target).join("release")
}

/// Builds the pendulum's firmware binaries for `board`.
fn build_firmware(board: &Board) -> PathBuf {
    build_firmware_with(board, None)
}

fn qemu(board: &Board, elf: &std::path::Path) -> String {
    ampc_tests::qemu(board.cpu, board.machine, elf)
}

/// `elf` in QEMU with the semihosting command line `safe-bench <args>` (`args`: QEMU's
/// `arg=` list after the first); its stdout.
fn qemu_args(board: &Board, elf: &std::path::Path, args: &str) -> String {
    let out = Command::new("timeout")
        .args(["-k", "5", "300", "qemu-system-arm"])
        .args(["-cpu", board.cpu, "-machine", board.machine, "-nographic"])
        .arg("-semihosting-config")
        .arg(format!("enable=on,target=native,arg=safe-bench,arg={args}"))
        .arg("-kernel")
        .arg(elf)
        .output()
        .expect("run qemu-system-arm");
    assert!(
        out.status.success(),
        "{} {args}: {:?}",
        elf.display(),
        out.status
    );
    String::from_utf8(out.stdout).expect("firmware output is UTF-8")
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
                u: [f[3].parse().unwrap()],
                flags: Flags(f[4].parse().unwrap()),
            }
        })
        .collect()
}

/// The trajectory on `board` against the host (bit for bit) and the f64 network (within
/// the allowance).
fn trajectory_matches_host_and_f64_network(board: &Board) {
    let bins = build_firmware(board);
    let device = parse(&qemu(board, &bins.join("firmware-example")));
    assert_eq!(device.len(), STEPS + 1);
    assert!(device.iter().enumerate().all(|(k, r)| r.k == k));

    // (1) The host runs the same f32 code: identical bits.
    let mut host = Vec::new();
    assert!(run(|r| host.push(*r)));
    for (d, h) in device.iter().zip(&host) {
        assert_eq!(
            (d.x.map(f32::to_bits), d.u.map(f32::to_bits), d.flags),
            (h.x.map(f32::to_bits), h.u.map(f32::to_bits), h.flags),
            "{}, step {}: device {d:?} host {h:?}",
            board.machine,
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
        worst = worst.max((f64::from(r.u[0]) - u64).abs());
    }
    println!(
        "{}: max |u_device − u_f64| = {worst:e} (allowance {:e})",
        board.machine, CERTIFICATE.f32_allowance
    );
    assert!(worst > 0.0, "no rounding seen at all: comparison blind?");
    assert!(worst <= CERTIFICATE.f32_allowance);
}

#[test]
fn firmware_trajectory_matches_host_and_f64_network() {
    trajectory_matches_host_and_f64_network(&M4);
}

#[test]
fn cortex_m0_trajectory_matches_host_and_f64_network() {
    trajectory_matches_host_and_f64_network(&M0);
}

/// `evaluate-check` on `board`: every probe state's `u` bits and flags equal the host's.
fn probe_states_match_host(board: &Board) {
    let bins = build_firmware(board);
    let out = qemu(board, &bins.join("evaluate-check"));
    let rows: Vec<Vec<u32>> = out
        .lines()
        .map(|l| l.split(',').map(|f| f.parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len(), PROBES as usize, "{}", board.machine);
    let mut flagged = 0;
    for (i, row) in rows.iter().enumerate() {
        let x = probe_state(i as u32);
        let h = controller_core::demo::evaluate(&x);
        assert_eq!(
            row.as_slice(),
            [
                i as u32,
                x[0].to_bits(),
                x[1].to_bits(),
                h.u[0].to_bits(),
                u32::from(h.flags.0)
            ],
            "{}: state {i} {x:?}: device u = {:e}, host u = {:e}",
            board.machine,
            f32::from_bits(row[3]),
            h.u[0]
        );
        flagged += usize::from(h.flags != Flags::EMPTY);
    }
    // The probe set reaches the projection and the non-finite path, and plain states.
    for f in [Flags::OUT_OF_DOMAIN, Flags::NON_FINITE] {
        assert!(
            (0..PROBES).any(|i| controller_core::demo::evaluate(&probe_state(i))
                .flags
                .contains(f))
        );
    }
    assert!(flagged > 0 && flagged < PROBES as usize / 2, "{flagged}");

    // The device's u (= the host's, bit for bit) is within the certified f32 allowance of
    // the f64 network at the projected state, clamped to the band, on every finite probe.
    let (model, _) = ampc_tests::trained_pendulum();
    assert_eq!(model.hash, CERTIFICATE.hash);
    let (lo, hi) = model.domain_f32();
    let mut worst = 0.0f64;
    for (i, row) in rows.iter().enumerate() {
        let x = probe_state(i as u32);
        if !x.iter().all(|v| v.is_finite()) {
            continue;
        }
        let xp: Vec<f64> = (0..2)
            .map(|k| f64::from(x[k].clamp(lo[k], hi[k])))
            .collect();
        let u64 = model.eval_f64(&xp)[0].clamp(
            f64::from(CERTIFICATE.clamp_lo[0]),
            f64::from(CERTIFICATE.clamp_hi[0]),
        );
        worst = worst.max((f64::from(f32::from_bits(row[3])) - u64).abs());
    }
    println!(
        "{}: probes: max |u_device − u_f64| = {worst:e} (allowance {:e})",
        board.machine, CERTIFICATE.f32_allowance
    );
    assert!(worst > 0.0 && worst <= CERTIFICATE.f32_allowance);
}

#[test]
fn probe_states_match_host_on_cortex_m4() {
    probe_states_match_host(&M4);
}

#[test]
fn probe_states_match_host_on_cortex_m0() {
    probe_states_match_host(&M0);
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
    for board in [M4, M0] {
        no_panic_reachable_from(&board, "evaluate-bench", "ampc_evaluate");
        // The safety-augmented step on the generated quadrotor (`safe-bench`, built by the
        // same `--bins` build): no panic path, and it runs on the device with its safe
        // sequence adopted (`init=1`).
        no_panic_reachable_from(&board, "safe-bench", "ampc_safe_step");
        no_panic_reachable_from(&board, "safe-bench", "ampc_safe_step_pendulum");
        // With the sequence network (`trainer export --safe-rs` files): the whole step.
        no_panic_reachable_from(&board, "safe-bench", "ampc_safe_step_net");
        no_panic_reachable_from(&board, "safe-bench", "ampc_safe_step_net_pendulum");
        let bins = build_firmware(&board);
        let out = qemu(&board, &bins.join("safe-bench"));
        assert!(
            out.starts_with("calls=1 ") && out.contains(" init=1 "),
            "{}: {out}",
            board.machine
        );
        for (args, prefix) in [
            ("net,arg=3", "net calls=3 "),
            ("pendulum,arg=net,arg=3", "pendulum net calls=3 "),
        ] {
            let out = qemu_args(&board, &bins.join("safe-bench"), args);
            assert!(
                out.starts_with(prefix) && out.contains(" init=1 "),
                "{} {args}: {out}",
                board.machine
            );
        }
    }
}

fn no_panic_reachable_from(board: &Board, bin: &str, entry: &str) {
    let bins = build_firmware(board);
    let elf = bins.join(bin);
    let (graph, sizes) = call_graph(&elf);
    assert!(graph.contains_key(entry), "{entry} not in {bin}");
    // Sanity: the checker sees panics where they are (the firmware's own panic handler).
    assert!(
        graph.keys().any(|k| k.contains("panic")),
        "no panic symbol at all: checker blind?"
    );
    let mut seen = BTreeSet::new();
    let mut stack = vec![entry.to_string()];
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
        "{bin}: panic paths reachable from {entry}: {bad:?}"
    );
    let code: u64 = seen.iter().filter_map(|f| sizes.get(f)).sum();
    // The optimiser turns the weights into literal-pool constants of `ampc_evaluate`, so the
    // static itself usually disappears: its size (if any) is added separately.
    let data = sizes.get("AMPC_CONTROLLER").copied().unwrap_or(0);
    println!(
        "{} {entry}: controller flash: {code} B in {} functions {:?} (code + literal pools) + AMPC_CONTROLLER static {data} B = {} B",
        board.machine,
        seen.len(),
        seen,
        code + data
    );
    assert!(code > 0);
}

/// The 3-6-2 controller of `tests/fixtures/own-weights`, compiled into this test.
mod own {
    controller_core::include_controller!("fixtures/own-weights/src/weights.rs");
}

/// A controller of other dimensions on the device: `firmware-example` built with
/// `AMPC_WEIGHTS` = the 3-6-2 net of `tests/fixtures/own-weights` (nx = 3, nu = 2, an
/// excluded box). The host build's `evaluate-check` lines equal this test's own evaluation of
/// the fixture at the printed states; on the M4 and the M0 they are the same bit for bit, the
/// closed loop says why it is skipped, and `evaluate-bench` runs.
#[test]
fn another_controller_size_runs_on_both_boards() {
    let weights = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/fixtures/own-weights/src/weights.rs"
    );
    let (mut host, _) = firmware_cargo(&["run", "-q", "--bin", "evaluate-check"], Some(weights));
    let host = host.output().expect("run cargo");
    assert!(
        host.status.success(),
        "{}",
        String::from_utf8_lossy(&host.stderr)
    );
    let host = String::from_utf8(host.stdout).unwrap();
    // Every line against the fixture's controller compiled into this test (not the
    // firmware crate's code): i, the state's 3 bit patterns, two u bit patterns, flags.
    let rows: Vec<Vec<u32>> = host
        .lines()
        .map(|l| l.split(',').map(|f| f.parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len(), PROBES as usize);
    let mut plain = 0;
    let mut us = std::collections::BTreeSet::new();
    for (i, row) in rows.iter().enumerate() {
        assert_eq!(row.len(), 1 + 3 + 2 + 1, "line {i}: {row:?}");
        assert_eq!(row[0], i as u32);
        let x = [row[1], row[2], row[3]].map(f32::from_bits);
        let o = own::evaluate(&x);
        assert_eq!(
            &row[4..],
            [o.u[0].to_bits(), o.u[1].to_bits(), u32::from(o.flags.0)],
            "line {i}, x = {x:?}"
        );
        plain += usize::from(o.flags == Flags::EMPTY);
        us.insert((o.u[0].to_bits(), o.u[1].to_bits()));
    }
    // Plain states, varied outputs, and some states off X (out of domain) among the probes.
    assert!(plain > PROBES as usize / 4, "{plain} unflagged");
    assert!(
        us.len() > PROBES as usize / 4,
        "{} distinct outputs",
        us.len()
    );
    assert!(rows.iter().any(|r| r[6] != 0));
    for board in [&M4, &M0] {
        let bins = build_firmware_with(board, Some(weights));
        assert_eq!(
            qemu(board, &bins.join("evaluate-check")),
            host,
            "{}: device and host differ",
            board.machine
        );
        let cl = qemu(board, &bins.join("firmware-example"));
        assert!(cl.contains("# closed loop skipped"), "{cl}");
        assert!(qemu(board, &bins.join("evaluate-bench")).starts_with("calls=1 "));
    }
}
