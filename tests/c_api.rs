//! The C API (`controller-core/capi`): its header compiles as strict C99 and its static
//! library gives, from C, exactly what the Rust core gives.
//!
//! 1. Host: `libampc_capi.a` built for the host, `ampc_stdin.c` compiled with the host `cc`
//!    (`-std=c99 -Wall -Wextra -Werror -pedantic`) and linked against it; 10⁴ states (inside,
//!    near and outside X, NaN, ±inf, −0, subnormals, random bit patterns) through it: flags
//!    and the bits of u equal `controller_core::demo::evaluate`; the header's certificate equals
//!    the library's (`ampc_linked_certificate`) and the core's.
//! 2. QEMU: the library built for thumbv7em-none-eabihf, the C firmware
//!    (`capi/c/firmware`, arm-none-eabi-gcc, newlib + semihosting) runs the upswing in
//!    QEMU mps2-an386; its 91 rows equal, bit for bit, those of the Rust firmware run in
//!    QEMU; no panic symbol is reachable from `ampc_evaluate` in its ELF.
//! 3. The safety-augmented controller (`ampc_safe.h`): host C closed loops bit-identical to
//!    Rust; the C safe firmware for the pendulum and the quadrotor (library feature
//!    `safe-planar-quadrotor`) on the Cortex-M4F and the Cortex-M0 (thumbv6m-none-eabi, QEMU
//!    microbit), matched against Rust and counted.
//!
//! Needs `cc`, `arm-none-eabi-gcc` with newlib (`gcc-arm-none-eabi`,
//! `libnewlib-arm-none-eabi`), `qemu-system-arm`, binutils-arm-none-eabi and the
//! thumbv7em-none-eabihf and thumbv6m-none-eabi targets (`.ci/run` installs them); fails loudly without them.

use std::collections::{BTreeMap, BTreeSet};
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use controller_core::{
    demo::{CERTIFICATE, NX},
    Flags, FAST_TANH,
};

fn root() -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
}

fn capi() -> PathBuf {
    root().join("controller-core/capi")
}

/// `target/` of this build (target/<profile>/deps/<test> → target).
fn target_dir() -> PathBuf {
    let exe = std::env::current_exe().unwrap();
    exe.ancestors().nth(3).unwrap().to_path_buf()
}

/// Builds `libampc_capi.a` (release, own target dir) for `target` (None: the host) and
/// returns its path.
fn build_staticlib(target: Option<&str>, features: &[&str]) -> PathBuf {
    // A library with another controller compiled in gets its own directory: the tests run
    // in parallel, and one directory holds one `libampc_capi.a` per target.
    let dir = if features.contains(&"safe-planar-quadrotor") {
        target_dir().join("c-api-quadrotor")
    } else {
        target_dir().join("c-api")
    };
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let mut cmd = Command::new(cargo);
    cmd.args(["build", "-p", "ampc-capi", "--release", "--lib"])
        .env("CARGO_TARGET_DIR", &dir)
        .current_dir(root());
    let mut feats: Vec<&str> = features.to_vec();
    if FAST_TANH {
        feats.push("fast-tanh");
    }
    if !feats.is_empty() {
        cmd.args(["--features", &feats.join(",")]);
    }
    if let Some(t) = target {
        cmd.args(["--target", t]);
    }
    let st = cmd.status().expect("run cargo");
    assert!(st.success(), "building ampc-capi for {target:?} failed");
    match target {
        Some(t) => dir.join(t).join("release/libampc_capi.a"),
        None => dir.join("release/libampc_capi.a"),
    }
}

fn run_checked(cmd: &mut Command, what: &str) -> String {
    let out = cmd
        .output()
        .unwrap_or_else(|e| panic!("{what}: cannot run {cmd:?}: {e}"));
    assert!(
        out.status.success(),
        "{what} failed ({:?}):\n{}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

const STRICT: [&str; 5] = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic"];

/// 10⁴ states: every branch of `evaluate` and every kind of float.
fn states() -> Vec<[f32; NX]> {
    let mut s = 0x2545_f491_4f6c_dd1du64;
    let mut next = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        s
    };
    let special = [
        f32::NAN,
        f32::INFINITY,
        f32::NEG_INFINITY,
        -0.0,
        0.0,
        f32::MIN_POSITIVE / 4.0,
        f32::MAX,
        f32::MIN,
        1e30,
        -1e-30,
    ];
    let (lo, hi) = (CERTIFICATE.domain_lo, CERTIFICATE.domain_hi);
    (0..10_000)
        .map(|k| {
            let mut x = [0.0f32; NX];
            for (i, xi) in x.iter_mut().enumerate() {
                let r = next();
                let t = (r >> 40) as f64 / (1u64 << 24) as f64;
                let w = hi[i] - lo[i];
                *xi = match k % 10 {
                    0 => f32::from_bits((r >> 32) as u32),
                    1 => special[(r % special.len() as u64) as usize],
                    2 => (lo[i] - 0.5 * w + 2.0 * w * t) as f32,
                    _ => (lo[i] + w * t) as f32,
                };
            }
            x
        })
        .collect()
}

#[test]
fn host_c_program_is_bit_identical_to_the_core_on_ten_thousand_states() {
    let lib = build_staticlib(None, &[]);
    let dir = ampc_tests::tempdir();
    let exe = dir.path().join("ampc_stdin");
    let mut cc = Command::new("cc");
    cc.args(STRICT)
        .arg("-O2")
        .arg("-I")
        .arg(capi().join("include"))
        .arg(capi().join("c/ampc_stdin.c"))
        .arg(&lib)
        .args(["-lm", "-lpthread", "-ldl", "-o"])
        .arg(&exe);
    if FAST_TANH {
        cc.arg("-DAMPC_FAST_TANH");
    }
    run_checked(&mut cc, "cc (strict C99) of ampc_stdin.c + libampc_capi.a");
    // The header on its own, also as C++ would see it, with the same warnings as errors.
    let hdr = capi().join("include/ampc.h");
    run_checked(
        Command::new("cc")
            .args(STRICT)
            .args(["-fsyntax-only", "-x", "c"])
            .arg(&hdr),
        "cc -fsyntax-only ampc.h",
    );

    let xs = states();
    let mut input = String::new();
    for x in &xs {
        let line: Vec<String> = x.iter().map(|v| format!("0x{:08x}", v.to_bits())).collect();
        input += &line.join(" ");
        input.push('\n');
    }
    let mut child = Command::new(&exe)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    // Write from another thread: the child's output would fill its pipe meanwhile.
    let mut stdin = child.stdin.take().unwrap();
    let writer = std::thread::spawn(move || stdin.write_all(input.as_bytes()));
    let out = child.wait_with_output().unwrap();
    writer.join().unwrap().unwrap();
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    let mut lines = text.lines();
    let head = lines.next().unwrap();
    // The expected tier is not read from the constant under test: the committed weights are
    // the default pendulum run's, whose certificate (Theorem 1) rests on a sampled L_MPC, so
    // its tier is `estimated` (`certify::tier::theorem1`); the library, the header and the
    // core must all say so.
    let tier = "estimated";
    assert_eq!(
        CERTIFICATE.guarantee,
        controller_core::Guarantee::Estimated,
        "controller-core's CERTIFICATE does not carry the pendulum certificate's tier"
    );
    let f: Vec<&str> = head.split(' ').collect();
    assert_eq!(
        f.len(),
        5,
        "first line {head:?}: certificate <ok|MISMATCH> eps= tier= hash="
    );
    assert_eq!(
        (f[0], f[1], f[3], f[4]),
        (
            "certificate",
            "ok",
            format!("tier={tier}").as_str(),
            format!("hash={}", CERTIFICATE.hash).as_str()
        ),
        "the header's certificate is not the library's or the core's"
    );
    // %.17g reads back to the same double.
    let eps: f64 = f[2].strip_prefix("eps=").unwrap().parse().unwrap();
    assert_eq!(eps.to_bits(), CERTIFICATE.eps.to_bits());
    let mut seen = BTreeSet::new();
    let mut n = 0;
    for (x, line) in xs.iter().zip(lines) {
        let (flags, bits) = line.split_once(" # ").unwrap();
        let flags: u8 = flags.split(' ').next().unwrap().parse().unwrap();
        let u: Vec<u32> = bits
            .split(' ')
            .map(|b| u32::from_str_radix(b, 16).unwrap())
            .collect();
        let want = controller_core::demo::evaluate(x);
        assert_eq!(
            (flags, u.as_slice()),
            (want.flags.0, want.u.map(f32::to_bits).as_slice()),
            "x = {x:?}: C {line:?}, Rust {want:?}"
        );
        seen.insert(flags);
        n += 1;
    }
    assert_eq!(n, xs.len());
    // The states exercise every outcome: inside, projected, non-finite.
    for f in [Flags::EMPTY, Flags::OUT_OF_DOMAIN, Flags::NON_FINITE] {
        assert!(seen.contains(&f.0), "no state with flags {f:?}: {seen:?}");
    }
    println!(
        "host: {n} states bit-identical; libampc_capi.a {} bytes",
        std::fs::metadata(&lib).unwrap().len()
    );
}

/// One row of a firmware run: k, bits of x1, x2, u, flags.
type Row = (usize, u32, u32, u32, u8);

fn qemu(elf: &Path) -> String {
    ampc_tests::qemu("cortex-m4", "mps2-an386", elf)
}

/// Rows of the C firmware (floats as hex bits) or the Rust firmware (decimal, 9 digits).
fn rows(csv: &str, hex: bool) -> Vec<Row> {
    let mut lines = csv.lines();
    assert_eq!(lines.next(), Some(firmware_example::HEADER));
    let f32_bits = |s: &str| {
        if hex {
            u32::from_str_radix(s, 16).unwrap()
        } else {
            s.parse::<f32>().unwrap().to_bits()
        }
    };
    lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            assert_eq!(f.len(), 5, "row {l:?}");
            (
                f[0].parse().unwrap(),
                f32_bits(f[1]),
                f32_bits(f[2]),
                f32_bits(f[3]),
                f[4].parse().unwrap(),
            )
        })
        .collect()
}

/// The Rust firmware, built as tests/firmware_in_qemu.rs builds it (same target dir and
/// arguments: no second build).
fn rust_firmware() -> PathBuf {
    let dir = target_dir().join("firmware-qemu");
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let mut cmd = Command::new(cargo);
    cmd.args(["build", "-p", "firmware-example", "--release", "--bins"])
        .args(["--target", "thumbv7em-none-eabihf"])
        .env("CARGO_TARGET_DIR", &dir)
        // The built-in pendulum, whatever the caller's environment names.
        .env_remove("AMPC_WEIGHTS")
        .current_dir(root());
    if FAST_TANH {
        cmd.args(["--features", "fast-tanh"]);
    }
    assert!(cmd.status().expect("run cargo").success());
    dir.join("thumbv7em-none-eabihf/release/firmware-example")
}

/// The C firmware's ELF: `capi/c/firmware` + the thumbv7em static library.
fn c_firmware() -> PathBuf {
    c_firmware_of("main.c", "c-firmware.elf", &[])
}

/// A C firmware of `capi/c/firmware` (`main`: its main file; `defines`: `-D` options),
/// linked against the thumbv7em library, written to `target/c-api/<elf>`.
fn c_firmware_of(main: &str, elf: &str, defines: &[&str]) -> PathBuf {
    c_firmware_for(Board::M4, &["pendulum-plant"], main, elf, defines)
}

/// The QEMU boards of the C firmware.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Board {
    /// Cortex-M4F, QEMU mps2-an386 (`mps2_an386.ld`), thumbv7em-none-eabihf, hard float.
    M4,
    /// Cortex-M0, QEMU microbit (`microbit.ld`), thumbv6m-none-eabi, soft float.
    M0,
}

impl Board {
    fn rust_target(self) -> &'static str {
        match self {
            Board::M4 => "thumbv7em-none-eabihf",
            Board::M0 => "thumbv6m-none-eabi",
        }
    }
    fn gcc_flags(self) -> &'static [&'static str] {
        match self {
            Board::M4 => &[
                "-mcpu=cortex-m4",
                "-mthumb",
                "-mfloat-abi=hard",
                "-mfpu=fpv4-sp-d16",
            ],
            Board::M0 => &["-mcpu=cortex-m0", "-mthumb", "-mfloat-abi=soft"],
        }
    }
    fn linker_script(self) -> &'static str {
        match self {
            Board::M4 => "mps2_an386.ld",
            Board::M0 => "microbit.ld",
        }
    }
    fn qemu(self) -> [&'static str; 4] {
        match self {
            Board::M4 => ["-cpu", "cortex-m4", "-machine", "mps2-an386"],
            Board::M0 => ["-cpu", "cortex-m0", "-machine", "microbit"],
        }
    }
}

/// A C firmware of `capi/c/firmware` for `board`, linked against the library built with
/// `features`, written to `target/c-api/<elf>`.
fn c_firmware_for(
    board: Board,
    features: &[&str],
    main: &str,
    elf: &str,
    defines: &[&str],
) -> PathBuf {
    let lib = build_staticlib(Some(board.rust_target()), features);
    let fw = capi().join("c/firmware");
    let elf = target_dir().join("c-api").join(elf);
    let mut gcc = Command::new("arm-none-eabi-gcc");
    gcc.args(board.gcc_flags())
        .args(STRICT)
        .args([
            "-O2",
            "-ffunction-sections",
            "-fdata-sections",
            "-nostartfiles",
        ])
        .args([
            "--specs=nano.specs",
            "--specs=rdimon.specs",
            "-Wl,--gc-sections",
        ])
        .arg("-T")
        .arg(fw.join(board.linker_script()))
        .arg("-I")
        .arg(capi().join("include"))
        .args(defines)
        .arg(fw.join("startup.c"))
        .arg(fw.join(main))
        .arg(&lib)
        .arg("-o")
        .arg(&elf);
    if FAST_TANH {
        gcc.arg("-DAMPC_FAST_TANH");
    }
    run_checked(
        &mut gcc,
        "arm-none-eabi-gcc (apt-get install -y gcc-arm-none-eabi libnewlib-arm-none-eabi)",
    );
    elf
}

#[test]
fn c_firmware_in_qemu_is_bit_identical_to_the_rust_firmware() {
    let elf = c_firmware();
    let c = rows(&qemu(&elf), true);
    let rust = rows(&qemu(&rust_firmware()), false);
    assert_eq!(c.len(), firmware_example::STEPS + 1);
    assert_eq!(c.len(), rust.len());
    for (a, b) in c.iter().zip(&rust) {
        assert_eq!(
            a, b,
            "step {}: C firmware {a:x?}, Rust firmware {b:x?}",
            a.0
        );
    }
    // The upswing moves (the comparison is not of two constant sequences).
    assert!(c.iter().map(|r| r.3).collect::<BTreeSet<_>>().len() > 10);

    // No panic path from the C entry point into the library (panic handler: a loop).
    let graph = call_graph(&elf);
    assert!(
        graph.contains_key("ampc_evaluate"),
        "ampc_evaluate not in the ELF"
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
    let size = run_checked(
        Command::new("arm-none-eabi-size").arg(&elf),
        "arm-none-eabi-size",
    );
    // Code reachable from ampc_evaluate (weights are literal pools inside it).
    let nm = run_checked(
        Command::new("arm-none-eabi-nm").arg("-S").arg(&elf),
        "arm-none-eabi-nm",
    );
    let mut controller = 0u64;
    for l in nm.lines() {
        let f: Vec<&str> = l.split_whitespace().collect();
        if f.len() == 4 && seen.contains(f[3]) {
            controller += u64::from_str_radix(f[1], 16).unwrap();
        }
    }
    println!(
        "C firmware (91 rows bit-identical to the Rust firmware):\n{size}\
         controller reachable from ampc_evaluate: {controller} B in {seen:?}"
    );
}

/// function → referenced symbols, from `arm-none-eabi-objdump -d`.
fn call_graph(elf: &Path) -> BTreeMap<String, BTreeSet<String>> {
    let text = run_checked(
        Command::new("arm-none-eabi-objdump")
            .args(["-d", "--no-show-raw-insn"])
            .arg(elf),
        "arm-none-eabi-objdump",
    );
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
            let t = target.split(['+', '>']).next().unwrap_or("");
            if !t.is_empty() && t != cur {
                graph.entry(cur.clone()).or_default().insert(t.to_string());
            }
        }
    }
    graph
}

mod safe_pendulum {
    controller_core::include_safe_controller!("fixtures/safe-controller/pendulum_ode_safe.rs");
}

mod safe_quadrotor {
    controller_core::include_safe_controller!("fixtures/safe-controller/planar_quadrotor_safe.rs");
}

/// `ampc_safe_step` from C (`capi/c/ampc_safe_stdin.c`, strict C99, `ampc_safe.h`): over
/// 20 closed loops of 40 steps (the f32 plant, every seventh state perturbed, every 23rd a
/// NaN or ±inf component, a reset between runs) flags, the bits of u and `has_safe` equal the
/// Rust controller compiled from the same file; the header's sizes are the library's; null
/// pointers give the documented answers.
#[test]
fn host_c_safe_step_is_bit_identical_to_the_core() {
    use ampc_capi::safe::{AmpcSafe, SAFE_FLAG_NULL_ARGUMENT, SAFE_N, SAFE_NU, SAFE_NX};
    use controller_core::safe::{Plant, SafeFlags};
    let lib = build_staticlib(None, &[]);
    let dir = ampc_tests::tempdir();
    let exe = dir.path().join("ampc_safe_stdin");
    run_checked(
        Command::new("cc")
            .args(STRICT)
            .arg("-O2")
            .arg("-I")
            .arg(capi().join("include"))
            .arg(capi().join("c/ampc_safe_stdin.c"))
            .arg(&lib)
            .args(["-lm", "-lpthread", "-ldl", "-o"])
            .arg(&exe),
        "cc (strict C99) of ampc_safe_stdin.c + libampc_capi.a",
    );
    let mut ctl = safe_pendulum::safe::CONTROLLER;
    let plant = ctl.plant;
    let mut s = 0x5afe_c0de_u64;
    let mut next = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    let (mut input, mut want) = (String::new(), Vec::new());
    let mut k = 0usize;
    for _ in 0..20 {
        input += "reset\n";
        ctl.reset();
        let mut x = [(2.0 * next() - 1.0) as f32, (1.6 * next() - 0.8) as f32];
        for _ in 0..40 {
            k += 1;
            let mut xin = x;
            if k.is_multiple_of(7) {
                xin[0] += (0.2 * next() - 0.1) as f32;
            }
            if k.is_multiple_of(23) {
                xin[k % 2] = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY][k % 3];
            }
            let line: Vec<String> = xin
                .iter()
                .map(|v| format!("0x{:08x}", v.to_bits()))
                .collect();
            input += &line.join(" ");
            input.push('\n');
            let o = ctl.step(&xin);
            let bits: Vec<String> =
                o.u.iter()
                    .map(|v| format!("0x{:08x}", v.to_bits()))
                    .collect();
            want.push(format!(
                "{} {} {}",
                o.flags.0,
                bits.join(" "),
                u8::from(ctl.safe_sequence().is_some())
            ));
            x = if xin.iter().all(|v| v.is_finite()) {
                plant.step(&xin, &o.u)
            } else {
                x
            };
        }
    }
    let mut child = Command::new(&exe)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdin = child.stdin.take().unwrap();
    let writer = std::thread::spawn(move || stdin.write_all(input.as_bytes()));
    let out = child.wait_with_output().unwrap();
    writer.join().unwrap().unwrap();
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    let mut lines = text.lines();
    assert_eq!(
        lines.next().unwrap(),
        format!(
            "sizeof={} n={SAFE_N} nx={SAFE_NX} nu={SAFE_NU}",
            std::mem::size_of::<AmpcSafe>()
        )
    );
    let u_ref = plant.project_input(&[f32::NAN; 1])[0].to_bits();
    let bad = SAFE_FLAG_NULL_ARGUMENT | SafeFlags::NON_FINITE_STATE.0;
    assert_eq!(
        lines.next().unwrap(),
        format!(
            "null {SAFE_FLAG_NULL_ARGUMENT} {bad} 0x{u_ref:08x} {bad} 0x{u_ref:08x} \
             {SAFE_FLAG_NULL_ARGUMENT} has_safe=0"
        )
    );
    let got: Vec<&str> = lines.filter(|l| !l.starts_with("reset")).collect();
    assert_eq!(got.len(), want.len());
    let (mut cand, mut fb) = (0, 0);
    for (i, (g, w)) in got.iter().zip(&want).enumerate() {
        assert_eq!(g, w, "step {i}");
        let f: u8 = w.split(' ').next().unwrap().parse().unwrap();
        cand += usize::from(SafeFlags(f).contains(SafeFlags::CANDIDATE));
        fb += usize::from(SafeFlags(f).contains(SafeFlags::FALLBACK));
    }
    eprintln!(
        "C safe step: {} steps bit-identical (candidate {cand}, fallback {fb})",
        want.len()
    );
    assert!(cand > 0 && fb > 0, "candidate {cand}, fallback {fb}");
}

/// Instructions executed by `elf` on `board` (QEMU with the counting plugin
/// `firmware-example/tools/insn_count.c`) and its stdout.
fn counted_run(board: Board, elf: &Path) -> (u64, String) {
    let plugin = target_dir().join("c-api/libinsn_count.so");
    run_checked(
        Command::new("cc")
            .args(["-shared", "-fPIC", "-O2", "-o"])
            .arg(&plugin)
            .arg(root().join("firmware-example/tools/insn_count.c")),
        "cc of the instruction-counting plugin",
    );
    let out = Command::new("timeout")
        .args(["-k", "5", "300", "qemu-system-arm"])
        .args(board.qemu())
        .args([
            "-nographic",
            "-semihosting-config",
            "enable=on,target=native",
            "-plugin",
        ])
        .arg(&plugin)
        .args(["-d", "plugin", "-kernel"])
        .arg(elf)
        .output()
        .expect("run qemu-system-arm");
    assert!(out.status.success(), "{}: {:?}", elf.display(), out.status);
    let text =
        String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr);
    let n = text
        .split("insns:")
        .nth(1)
        .and_then(|t| t.split_whitespace().next())
        .and_then(|t| t.parse().ok())
        .unwrap_or_else(|| panic!("no instruction count in {text:?}"));
    (n, String::from_utf8_lossy(&out.stdout).into_owned())
}

/// The host's expected output of `safe_bench.c` over `calls` steps: `init_with` the
/// terminal rollout from the first state, then steps over the four states.
fn safe_bench_expected<const NX: usize, const NU: usize>(
    mut ctl: controller_core::safe::SafeController<
        impl controller_core::safe::Plant<NX, NU>,
        impl controller_core::safe::SequenceSource<NX, NU, 20>,
        NX,
        NU,
        20,
    >,
    states: &[[f32; NX]; 4],
    calls: u32,
) -> String {
    let p = &ctl.plant;
    let mut x = states[0];
    let seq: [[f32; NU]; 20] = std::array::from_fn(|_| {
        let u = p.project_input(&p.terminal_input(&x));
        x = p.step(&x, &u);
        u
    });
    let init = u32::from(ctl.init_with(&states[0], &seq).is_ok());
    let (mut fl, mut acc) = (0u32, 0u32);
    for i in 0..calls as usize {
        let o = ctl.step(&states[i % 4]);
        fl = fl.wrapping_add(u32::from(o.flags.0));
        acc = o.u.iter().fold(acc, |a, u| a.wrapping_add(u.to_bits()));
    }
    format!("calls={calls} init={init} flags_sum={fl} u_sum_bits={acc}")
}

/// The C safe firmware (`capi/c/firmware/safe_bench.c`: `ampc_safe_init_with` the terminal
/// rollout, then `ampc_safe_step` with the sequence network) in QEMU, for the pendulum's and
/// the quadrotor's safe controllers, on the Cortex-M4F and the Cortex-M0: its sums of flags
/// and of the bits of u equal the Rust controller's on the host, the safe sequence is
/// adopted, no panic is reachable from `ampc_safe_step`, and the instructions per step are
/// printed ((count(1 + K) − count(1))/K, K = 1000 on the M4, 100 on the M0; BENCHMARKS.md).
#[test]
fn c_safe_firmware_in_qemu_matches_rust_and_is_counted() {
    const PEND: [[f32; 2]; 4] = [[0.1, -0.1], [0.05, 0.1], [-0.1, 0.05], [0.02, -0.02]];
    const QUAD: [[f32; 6]; 4] = [
        [0.05, -0.05, 0.02, 0.0, 0.05, 0.0],
        [0.04, -0.04, 0.015, 0.01, 0.04, 0.0],
        [-0.05, 0.05, -0.02, 0.0, -0.05, 0.01],
        [0.02, 0.01, 0.0, -0.01, 0.0, 0.0],
    ];
    for board in [Board::M4, Board::M0] {
        let k: u32 = if board == Board::M4 { 1000 } else { 100 };
        for quad in [false, true] {
            let (feats, defs): (&[&str], &[&str]) = if quad {
                (
                    &["safe-planar-quadrotor"],
                    &["-DAMPC_SAFE_PLANAR_QUADROTOR"],
                )
            } else if board == Board::M4 {
                (&["pendulum-plant"], &[])
            } else {
                (&[], &[])
            };
            let name = format!("c-safe-{board:?}-{}", if quad { "quad" } else { "pend" });
            let elf_of = |calls: u32| {
                let d = format!("-DSAFE_CALLS={calls}");
                let mut all: Vec<&str> = defs.to_vec();
                all.push(&d);
                c_firmware_for(
                    board,
                    feats,
                    "safe_bench.c",
                    &format!("{name}-{calls}.elf"),
                    &all,
                )
            };
            let (one, many) = (elf_of(1), elf_of(1 + k));
            let (c1, _) = counted_run(board, &one);
            let (c2, out) = counted_run(board, &many);
            let want = if quad {
                safe_bench_expected(safe_quadrotor::safe::CONTROLLER, &QUAD, 1 + k)
            } else {
                safe_bench_expected(safe_pendulum::safe::CONTROLLER, &PEND, 1 + k)
            };
            assert!(want.contains(" init=1 "), "{name}: host init_with failed");
            assert_eq!(out.trim(), want, "{name}");
            let graph = call_graph(&many);
            assert!(
                graph.contains_key("ampc_safe_step"),
                "{name}: ampc_safe_step not in the ELF"
            );
            let mut seen = BTreeSet::new();
            let mut todo = vec!["ampc_safe_step".to_string()];
            while let Some(f) = todo.pop() {
                if seen.insert(f.clone()) {
                    assert!(
                        !f.contains("panic"),
                        "{name}: {f} reachable from ampc_safe_step"
                    );
                    todo.extend(graph.get(&f).into_iter().flatten().cloned());
                }
            }
            eprintln!(
                "C safe firmware ({board:?}, {}): {} instructions per ampc_safe_step \
                 (counts {c1}, {c2}); {} functions reachable",
                if quad { "quadrotor" } else { "pendulum" },
                (c2 - c1) / u64::from(k),
                seen.len()
            );
        }
    }
}
