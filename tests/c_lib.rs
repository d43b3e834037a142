//! `trainer export --c-lib DIR` for a net of its own (not the built-in pendulum): a small
//! double-integrator net (2 → 10 → 10 → 1, sampled and trained here in about a second) is
//! exported with `--c-lib`, `--rust` and `--postcard`; the folder is built with no Rust:
//!
//! 1. `make` with the host `cc`; the driver `tests/fixtures/c-lib/driver.c` (strict C99)
//!    runs 2·10³ states (inside, near and outside X, NaN, ±inf, −0, subnormals, random bit
//!    patterns): flags and the bits of u equal the Rust controller's (controller-core
//!    evaluating the exported blob) on every state and `trainer eval`'s on the finite ones;
//!    the header's certificate equals the library's; null pointers give the documented
//!    answers. The CMake build (`cmake`, `cmake --build`) gives the same output.
//! 2. The C tanh (both of them) equals controller-core's on every 4099th f32 bit pattern.
//! 3. `make CC=arm-none-eabi-gcc` for the Cortex-M4; the same driver, linked with
//!    `controller-core/capi/c/firmware`'s start-up and linker script, runs in QEMU
//!    (mps2-an386): bit-identical to the Rust controller.
//! 4. A program compiled with this export's header does not link with another net's
//!    library (nor with this one built with the other tanh): the names differ.
//!
//! Needs `cc`, `make`, `cmake`, `arm-none-eabi-gcc` with newlib and `qemu-system-arm`
//! (tests/run-all installs them); fails loudly without them.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

use ampc_tests::{config, tempdir, trainer};
use controller_core::layer::Dense;
use controller_core::mlp::Hidden;
use controller_core::{Flags, FAST_TANH};

/// The double integrator's default network, `[training] hidden = [10, 10]`.
type Net = Hidden<2, 10, Hidden<10, 10, Dense<10, 1>>>;

const STRICT: [&str; 7] = [
    "-std=c99",
    "-Wall",
    "-Wextra",
    "-Werror",
    "-pedantic",
    "-Wdouble-promotion",
    "-ffp-contract=off",
];

/// What the tests share: the exported folders, the blob of the same export, the states.
struct Exported {
    dir: PathBuf,
    /// `--c-lib` folder of the net.
    lib: PathBuf,
    /// `--c-lib` folder of a second net (another seed).
    other: PathBuf,
    blob: Vec<u8>,
    states: Vec<[f32; 2]>,
    /// `trainer eval` on the finite states: (index, u bits, flags).
    eval: Vec<(usize, u32, u8)>,
}

fn run_ok(cmd: &mut Command, what: &str) -> String {
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

fn trainer_ok(args: &[&str]) {
    let o = trainer(args);
    assert!(
        o.status.success(),
        "trainer {args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
}

/// 2·10³ states: every branch of `evaluate` and every kind of float.
fn states(lo: [f32; 2], hi: [f32; 2]) -> Vec<[f32; 2]> {
    let mut s = 0x9e37_79b9_7f4a_7c15u64;
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
    (0..2000)
        .map(|k| {
            let mut x = [0.0f32; 2];
            for (i, xi) in x.iter_mut().enumerate() {
                let r = next();
                let t = (r >> 40) as f32 / (1u64 << 24) as f32;
                let w = hi[i] - lo[i];
                *xi = match k % 10 {
                    0 => f32::from_bits((r >> 32) as u32),
                    1 => special[(r % special.len() as u64) as usize],
                    2 => lo[i] - 0.5 * w + 2.0 * w * t,
                    _ => lo[i] + w * t,
                };
            }
            x
        })
        .collect()
}

fn exported() -> &'static Exported {
    static E: OnceLock<Exported> = OnceLock::new();
    E.get_or_init(|| {
        let dir = tempdir().keep();
        let p = |f: &str| dir.join(f).to_str().unwrap().to_string();
        let text = std::fs::read_to_string(config("double_integrator.toml"))
            .unwrap()
            .replace("counts = [21, 11]", "counts = [11, 6]")
            + "\n[training]\nepochs = 200\nbatch_size = 11\nvalidation_n = 30\nlog_every = 50\n";
        std::fs::write(dir.join("di.toml"), text).unwrap();
        let (cfg, data) = (p("di.toml"), p("di.bin"));
        trainer_ok(&["sample", "--config", &cfg, "--out", &data, "--quiet"]);
        for (model, seed) in [("m.bin", "0"), ("m1.bin", "1")] {
            trainer_ok(&[
                "train",
                "--config",
                &cfg,
                "--data",
                &data,
                "--out",
                &p(model),
                "--seed",
                seed,
                "--quiet",
            ]);
        }
        trainer_ok(&[
            "export",
            "--model",
            &p("m.bin"),
            "--c-lib",
            &p("lib"),
            "--rust",
            &p("w.rs"),
            "--postcard",
            &p("w.bin"),
        ]);
        trainer_ok(&["export", "--model", &p("m1.bin"), "--c-lib", &p("other")]);
        let blob = std::fs::read(dir.join("w.bin")).unwrap();
        let dec = controller_core::blob::decode::<2, 1, Net>(&blob).expect("the blob decodes");
        let xs = states(dec.controller.x_lo, dec.controller.x_hi);
        // `trainer eval` reads finite states only.
        let finite: Vec<usize> = (0..xs.len())
            .filter(|k| xs[*k].iter().all(|v| v.is_finite()))
            .collect();
        let mut csv = String::from("x1,x2\n");
        for k in &finite {
            let x = xs[*k];
            csv += &format!("{:?},{:?}\n", f64::from(x[0]), f64::from(x[1]));
        }
        std::fs::write(dir.join("states.csv"), csv).unwrap();
        trainer_ok(&[
            "eval",
            "--model",
            &p("m.bin"),
            "--states",
            &p("states.csv"),
            "--out",
            &p("eval.csv"),
        ]);
        let eval_csv = std::fs::read_to_string(dir.join("eval.csv")).unwrap();
        let eval: Vec<(usize, u32, u8)> = finite
            .iter()
            .zip(eval_csv.lines().skip(1))
            .map(|(k, line)| {
                let f: Vec<&str> = line.split(',').collect();
                let u: f64 = f[2].parse().unwrap();
                assert_eq!(u as f32 as f64, u, "eval's u is an f32");
                (*k, (u as f32).to_bits(), f[3].parse().unwrap())
            })
            .collect();
        assert_eq!(eval.len(), finite.len());
        // The driver's states, as f32 bit patterns.
        let mut h = format!(
            "#define N_STATES {}u\nstatic const uint32_t STATES[N_STATES][AMPC_NX] = {{\n",
            xs.len()
        );
        for x in &xs {
            h += &format!(
                "    {{0x{:08x}u, 0x{:08x}u}},\n",
                x[0].to_bits(),
                x[1].to_bits()
            );
        }
        h += "};\n";
        std::fs::write(dir.join("states.h"), h).unwrap();
        Exported {
            lib: dir.join("lib"),
            other: dir.join("other"),
            dir,
            blob,
            states: xs,
            eval,
        }
    })
}

fn fixture(f: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fixtures/c-lib")
        .join(f)
}

/// `make` in `lib` into `lib/<build>` with `vars`; returns the static library.
fn make(lib: &Path, build: &str, vars: &[String]) -> PathBuf {
    let mut cmd = Command::new("make");
    cmd.arg("-C")
        .arg(lib)
        .arg(format!("BUILD={build}"))
        .args(vars);
    if FAST_TANH {
        cmd.arg("FAST_TANH=1");
    }
    run_ok(&mut cmd, "make (the --c-lib folder's Makefile)");
    lib.join(build).join("libampc.a")
}

/// The host driver: `driver.c` with `include`'s header, linked with `archive`.
fn host_driver(include: &Path, archive: &Path, exe: &Path) -> Command {
    let e = exported();
    let mut cc = Command::new("cc");
    cc.args(STRICT)
        .arg("-O2")
        .arg("-I")
        .arg(include)
        .arg("-I")
        .arg(&e.dir)
        .arg(fixture("driver.c"))
        .arg(archive)
        .arg("-o")
        .arg(exe);
    if FAST_TANH {
        cc.arg("-DAMPC_FAST_TANH");
    }
    cc
}

/// Checks the driver's output against the Rust controller and `trainer eval`.
fn check_driver_output(out: &str, what: &str) {
    let e = exported();
    let dec = controller_core::blob::decode::<2, 1, Net>(&e.blob).unwrap();
    let c = &dec.controller;
    let mut lines = out.lines();
    let head = lines.next().unwrap();
    assert_eq!(
        head,
        format!("certificate ok {}", dec.hash),
        "{what}: the header's certificate is not the library's"
    );
    let null = lines.next().unwrap();
    assert_eq!(
        null,
        format!("null 130 {:08x} 128", c.fallback[0].to_bits()),
        "{what}: null pointers"
    );
    let rows: Vec<(u8, u32)> = lines
        .map(|l| {
            let (f, u) = l.split_once(' ').unwrap();
            (f.parse().unwrap(), u32::from_str_radix(u, 16).unwrap())
        })
        .collect();
    assert_eq!(rows.len(), e.states.len(), "{what}: one row per state");
    let mut seen = std::collections::BTreeSet::new();
    for (x, (flags, u)) in e.states.iter().zip(&rows) {
        let want = c.evaluate(x);
        assert_eq!(
            (*flags, *u),
            (want.flags.0, want.u[0].to_bits()),
            "{what}: x = {x:?}: C gives flags {flags}, u bits {u:08x}; Rust {want:?}"
        );
        seen.insert(*flags);
    }
    for f in [Flags::EMPTY, Flags::OUT_OF_DOMAIN, Flags::NON_FINITE] {
        assert!(seen.contains(&f.0), "{what}: no state with flags {f:?}");
    }
    if !FAST_TANH {
        for (k, u, flags) in &e.eval {
            assert_eq!(
                (rows[*k].0, rows[*k].1),
                (*flags, *u),
                "{what}: x = {:?}: C vs trainer eval",
                e.states[*k]
            );
        }
    }
    println!(
        "{what}: {} states bit-identical to the Rust controller ({} to trainer eval)",
        rows.len(),
        e.eval.len()
    );
}

#[test]
fn host_make_and_cmake_builds_are_bit_identical_to_the_rust_controller() {
    let e = exported();
    let archive = make(&e.lib, "host", &[]);
    let exe = e.dir.join("driver_host");
    run_ok(
        &mut host_driver(&e.lib, &archive, &exe),
        "cc (strict C99) driver.c + libampc.a",
    );
    let out = run_ok(&mut Command::new(&exe), "the host driver");
    check_driver_output(&out, "host cc (make)");

    // The same folder through its CMakeLists.txt.
    let build = e.dir.join("cmake-build");
    let mut configure = Command::new("cmake");
    configure.arg("-S").arg(&e.lib).arg("-B").arg(&build);
    if FAST_TANH {
        configure.arg("-DAMPC_FAST_TANH=ON");
    }
    run_ok(&mut configure, "cmake -S (apt-get install -y cmake)");
    run_ok(
        Command::new("cmake").arg("--build").arg(&build),
        "cmake --build",
    );
    let exe2 = e.dir.join("driver_cmake");
    run_ok(
        &mut host_driver(&e.lib, &build.join("libampc.a"), &exe2),
        "cc driver.c + CMake's libampc.a",
    );
    let out2 = run_ok(&mut Command::new(&exe2), "the CMake-built driver");
    assert_eq!(out2, out, "CMake and make builds differ");
}

#[test]
fn c_tanh_is_controller_cores_bit_for_bit() {
    let e = exported();
    for fast in [false, true] {
        let exe = e.dir.join(format!("tanh_sweep_{fast}"));
        let mut cc = Command::new("cc");
        cc.args(STRICT)
            .arg("-O2")
            .arg("-I")
            .arg(&e.lib)
            .arg(fixture("tanh_sweep.c"))
            .arg("-o")
            .arg(&exe);
        if fast {
            cc.arg("-DAMPC_FAST_TANH");
        }
        run_ok(&mut cc, "cc tanh_sweep.c (includes ampc.c)");
        let out = run_ok(&mut Command::new(&exe), "tanh sweep");
        let mut n = 0u64;
        for (line, bits) in out.lines().zip((0..=u32::MAX as u64).step_by(4099)) {
            let x = f32::from_bits(bits as u32);
            let want = if fast {
                controller_core::activation::tanh_fast(x)
            } else {
                controller_core::activation::tanh_accurate(x)
            };
            let got = u32::from_str_radix(line, 16).unwrap();
            assert_eq!(
                got,
                want.to_bits(),
                "tanh (fast: {fast}) at x = {x:e} ({bits:08x}): C {:e}, Rust {want:e}",
                f32::from_bits(got)
            );
            n += 1;
        }
        assert_eq!(n, u32::MAX as u64 / 4099 + 1, "one line per input");
    }
}

#[test]
fn cortex_m4_build_in_qemu_is_bit_identical_to_the_rust_controller() {
    let e = exported();
    let flags = "-mcpu=cortex-m4 -mthumb -mfloat-abi=hard -mfpu=fpv4-sp-d16";
    let archive = make(
        &e.lib,
        "m4",
        &[
            "CC=arm-none-eabi-gcc".into(),
            "AR=arm-none-eabi-ar".into(),
            format!("TARGET_FLAGS={flags}"),
        ],
    );
    let fw = Path::new(env!("CARGO_MANIFEST_DIR")).join("../controller-core/capi/c/firmware");
    let elf = e.dir.join("driver_m4.elf");
    let mut gcc = Command::new("arm-none-eabi-gcc");
    gcc.args(flags.split(' '))
        .args(STRICT)
        .args([
            "-O2",
            "-nostartfiles",
            "--specs=nano.specs",
            "--specs=rdimon.specs",
        ])
        .arg("-T")
        .arg(fw.join("mps2_an386.ld"))
        .arg("-I")
        .arg(&e.lib)
        .arg("-I")
        .arg(&e.dir)
        .arg(fw.join("startup.c"))
        .arg(fixture("driver.c"))
        .arg(&archive)
        .arg("-o")
        .arg(&elf);
    if FAST_TANH {
        gcc.arg("-DAMPC_FAST_TANH");
    }
    run_ok(
        &mut gcc,
        "arm-none-eabi-gcc (apt-get install -y gcc-arm-none-eabi libnewlib-arm-none-eabi)",
    );
    let out = ampc_tests::qemu("cortex-m4", "mps2-an386", &elf);
    check_driver_output(&out, "Cortex-M4 in QEMU (arm-none-eabi-gcc, make)");
}

#[test]
fn a_program_does_not_link_with_another_controllers_library() {
    let e = exported();
    let other = make(&e.other, "host", &[]);
    let exe = e.dir.join("driver_mismatch");
    let out = host_driver(&e.lib, &other, &exe).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success(),
        "a program compiled with one net's ampc.h linked with another net's libampc.a"
    );
    let header = std::fs::read_to_string(e.lib.join("ampc.h")).unwrap();
    let id = header
        .split_once("#define AMPC_LINK_ID \"")
        .unwrap()
        .1
        .split('"')
        .next()
        .unwrap();
    assert!(
        err.contains(&format!("ampc_evaluate_{id}")) && err.contains("undefined reference"),
        "the link error names the missing symbol: {err}"
    );
    // This very net's library, built with the other tanh: another certificate, no link.
    let mut cmd = Command::new("make");
    cmd.arg("-C").arg(&e.lib).arg("BUILD=other-tanh");
    if !FAST_TANH {
        cmd.arg("FAST_TANH=1");
    }
    run_ok(&mut cmd, "make (the other tanh)");
    let out = host_driver(&e.lib, &e.lib.join("other-tanh/libampc.a"), &exe)
        .output()
        .unwrap();
    assert!(
        !out.status.success(),
        "linked a library built with the other tanh"
    );
}

/// A 3 → 6 (tanh) → 2 net with deterministic weights and a box the certificate excludes
/// (through the library, `render_c_lib`): the EXCLUDED flag and two inputs, against the
/// exporter's f32 model of the device (`trainer eval`'s, bit-identical to controller-core:
/// tests/own_weights.rs).
#[test]
fn excluded_boxes_and_two_inputs_match_the_device_model() {
    use trainer::deploy::export::{self, device::Device, DenseF64, ExportModel, Scaling, Tanh};
    let mut s: u64 = 0x5151_7e57_c0de_0042;
    let mut next = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    let mut layer = |n_in: usize, n_out: usize| DenseF64 {
        w: (0..n_out)
            .map(|_| (0..n_in).map(|_| 1.2 * next()).collect())
            .collect(),
        b: (0..n_out).map(|_| 0.2 * next()).collect(),
    };
    let mut model = ExportModel {
        name: "three_two".into(),
        layers: vec![layer(3, 6), layer(6, 2)],
        input: Scaling {
            mean: vec![0.5, 0.0, 1.5],
            scale: vec![1.5, 0.5, 1.5],
        },
        output: Scaling {
            mean: vec![0.0, 2.5],
            scale: vec![2.0, 2.5],
        },
        domain_lo: vec![-1.0, -0.5, 0.0],
        domain_hi: vec![2.0, 0.5, 3.0],
        u_lo: vec![-2.0, 0.0],
        u_hi: vec![2.0, 5.0],
        actuator_lo: vec![-2.5, 0.0],
        actuator_hi: vec![2.5, 6.0],
        excluded: vec![(vec![0.5, -0.5, 1.0], vec![2.0, 0.0, 3.0])],
        rests_on: Vec::new(),
        ..export::placeholder_pendulum()
    };
    model.hash = "placeholder-3-6-2-c-lib".into();
    let dir = tempdir();
    let lib = dir.path().join("lib");
    std::fs::create_dir_all(&lib).unwrap();
    let report = export::certify_f32(&model).unwrap();
    export::write_files(&export::render_c_lib(&model, &report, &lib).unwrap()).unwrap();
    let tanh = if FAST_TANH { Tanh::Fast } else { Tanh::Libm };
    let dev = Device::new(&model, tanh).unwrap();
    let mut r: u64 = 0x0123_4567_89ab_cdef;
    let xs: Vec<[f32; 3]> = (0..2000)
        .map(|k| {
            std::array::from_fn(|i| {
                r ^= r << 13;
                r ^= r >> 7;
                r ^= r << 17;
                let t = (r >> 40) as f64 / (1u64 << 24) as f64;
                let (lo, hi) = (model.domain_lo[i], model.domain_hi[i]);
                match k % 7 {
                    0 => f32::from_bits((r >> 32) as u32),
                    1 => (lo - 0.3 * (hi - lo) + 1.6 * (hi - lo) * t) as f32,
                    _ => (lo + (hi - lo) * t) as f32,
                }
            })
        })
        .collect();
    let mut h = format!(
        "#define N_STATES {}u\nstatic const uint32_t STATES[N_STATES][AMPC_NX] = {{\n",
        xs.len()
    );
    for x in &xs {
        let b: Vec<String> = x
            .iter()
            .map(|v| format!("0x{:08x}u", v.to_bits()))
            .collect();
        h += &format!("    {{{}}},\n", b.join(", "));
    }
    h += "};\n";
    std::fs::write(dir.path().join("states.h"), h).unwrap();
    let archive = make(&lib, "host", &[]);
    let exe = dir.path().join("driver");
    let mut cc = Command::new("cc");
    cc.args(STRICT)
        .arg("-O2")
        .arg("-I")
        .arg(&lib)
        .arg("-I")
        .arg(dir.path())
        .arg(fixture("driver.c"))
        .arg(&archive)
        .arg("-o")
        .arg(&exe);
    if FAST_TANH {
        cc.arg("-DAMPC_FAST_TANH");
    }
    run_ok(&mut cc, "cc driver.c + libampc.a (3 -> 2 net)");
    let out = run_ok(&mut Command::new(&exe), "the driver (3 -> 2 net)");
    let mut lines = out.lines();
    assert_eq!(
        lines.next().unwrap(),
        format!("certificate ok {}", model.hash)
    );
    let fb: Vec<String> = dev
        .fallback
        .iter()
        .map(|v| format!("{:08x}", v.to_bits()))
        .collect();
    assert_eq!(
        lines.next().unwrap(),
        format!("null 130 {} 128", fb.join(" "))
    );
    let mut excluded = 0;
    let mut n = 0;
    for (x, line) in xs.iter().zip(lines) {
        let f: Vec<&str> = line.split(' ').collect();
        let (u, flags) = dev.evaluate(x);
        let want: Vec<String> = std::iter::once(flags.to_string())
            .chain(u.iter().map(|v| format!("{:08x}", v.to_bits())))
            .collect();
        assert_eq!(f, want, "x = {x:?}");
        excluded += usize::from(flags & Flags::EXCLUDED.0 != 0);
        n += 1;
    }
    assert_eq!(n, xs.len());
    assert!(excluded > 100, "{excluded} states in the excluded box");
    println!("3 -> 2 net: {n} states bit-identical to the device model, {excluded} excluded");
}
