//! Your weights without forking: a separate crate (`tests/fixtures/own-weights`, its own
//! workspace, depending on `controller-core` by path as it would from crates.io or git)
//! compiles a second, differently shaped controller (3 → 6 (tanh) → 2) with
//! `controller_core::include_controller!`, from the file `trainer export` writes.
//!
//! Checks: the fixture's `src/weights.rs` is exactly what the exporter writes for the second
//! net (regenerate with `AMPC_BLESS=1`); the crate builds in release with fat LTO and
//! controller-core's `no-panic` feature (the link fails if its `evaluate` could panic); its
//! certificate is the exporter's (ε bits, tier, hash, dimensions); and on 2·10³ states its
//! `evaluate` equals the exporter's f32 model of the device (projection onto X, forward pass,
//! clamp; fallback for non-finite states) bit for bit, flags included.

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use controller_core::{Flags, FAST_TANH};
use trainer::deploy::export::{self, DenseF64, ExportModel, Guarantee, Scaling, Tanh};

/// The second net: deterministic weights (xorshift), nx = 3, nu = 2, one hidden layer of 6,
/// non-symmetric domain and bands. Untrained, so a placeholder (ε from the learning side 0,
/// tier `estimated`).
fn second_net() -> ExportModel {
    let mut s: u64 = 0xC0FF_EE12_3456_789B;
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
    let layers = vec![layer(3, 6), layer(6, 2)];
    ExportModel {
        name: "second".into(),
        layers,
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
        fallback: None,
        eps: 0.0,
        eps_d: 0.0,
        l_nn: 0.0,
        l_nn_method: "placeholder (untrained network, no certificate)".into(),
        l_mpc: 0.0,
        l_mpc_is_estimate: true,
        covering_radius: 0.0,
        hash: "placeholder-3-6-2-seed-c0ffee".into(),
        placeholder: true,
        guarantee: Guarantee::Estimated,
        statistical: None,
        // One box the certificate excludes: states in it are flagged (EXCLUDED).
        excluded: vec![(vec![0.5, -0.5, 1.0], vec![2.0, 0.0, 3.0])],
        rests_on: Vec::new(),
        u_scale: Vec::new(),
    }
}

fn root() -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
}

/// Copies the fixture crate to `to` with an absolute path to controller-core and the
/// workspace's lock file (an offline build with the workspace's dependency versions).
fn copy_fixture(to: &Path) {
    let src = root().join("tests/fixtures/own-weights");
    std::fs::create_dir_all(to.join("src")).unwrap();
    for f in ["lib.rs", "main.rs", "weights.rs"] {
        std::fs::copy(src.join("src").join(f), to.join("src").join(f)).unwrap();
    }
    let core = root().join("controller-core").canonicalize().unwrap();
    let manifest = std::fs::read_to_string(src.join("Cargo.toml"))
        .unwrap()
        .replace("\"../../../controller-core\"", &format!("{:?}", core));
    assert!(
        manifest.contains(&format!("{:?}", core)),
        "path dependency not found"
    );
    std::fs::write(to.join("Cargo.toml"), manifest).unwrap();
    std::fs::copy(root().join("Cargo.lock"), to.join("Cargo.lock")).unwrap();
}

#[test]
fn a_separate_crate_compiles_its_own_exported_controller() {
    let model = second_net();
    let dir = ampc_tests::tempdir();
    let (rs, bin) = (
        dir.path().join("weights.rs"),
        dir.path().join("weights.bin"),
    );
    let report = export::export_files(&model, &rs, &bin).unwrap();
    let fresh = std::fs::read_to_string(&rs).unwrap();
    let committed_path = root().join("tests/fixtures/own-weights/src/weights.rs");
    if std::env::var_os("AMPC_BLESS").is_some() {
        std::fs::write(&committed_path, &fresh).unwrap();
    }
    let committed = std::fs::read_to_string(&committed_path).unwrap_or_default();
    assert!(
        fresh == committed,
        "{} is not what trainer export writes for the second net: rerun with AMPC_BLESS=1",
        committed_path.display()
    );
    assert!(fresh.contains("pub type Net = Hidden<3, 6, Dense<6, 2>>;"));

    // Build the crate: release, fat LTO, controller-core's no-panic proof.
    let krate = dir.path().join("own-weights");
    copy_fixture(&krate);
    let target = std::env::current_exe()
        .unwrap()
        .ancestors()
        .nth(3)
        .unwrap()
        .join("own-weights");
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let features = if FAST_TANH {
        "no-panic,fast-tanh"
    } else {
        "no-panic"
    };
    let out = Command::new(cargo)
        .args(["build", "--offline", "--release", "--features", features])
        .env("CARGO_TARGET_DIR", &target)
        .env("CARGO_PROFILE_RELEASE_LTO", "fat")
        .current_dir(&krate)
        .output()
        .expect("run cargo");
    assert!(
        out.status.success(),
        "the crate with its own controller does not build (no-panic, fat LTO):\n{}",
        String::from_utf8_lossy(&out.stderr)
    );

    // States: inside, around and outside X, and non-finite ones.
    let mut s = 0x9E37_79B9_7F4A_7C15u64;
    let mut rnd = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 40) as f32 / (1u64 << 24) as f32
    };
    let xs: Vec<[f32; 3]> = (0..2000)
        .map(|k| {
            let mut x = [0.0f32; 3];
            for (i, xi) in x.iter_mut().enumerate() {
                let (lo, hi) = (model.domain_lo[i] as f32, model.domain_hi[i] as f32);
                let w = hi - lo;
                *xi = lo - 0.3 * w + 1.6 * w * rnd();
            }
            if k % 97 == 0 {
                x[k % 3] = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY][k % 3];
            }
            x
        })
        .collect();
    let input: String = xs
        .iter()
        .map(|x| {
            let w: Vec<String> = x.iter().map(|v| format!("{:08x}", v.to_bits())).collect();
            w.join(" ") + "\n"
        })
        .collect();
    let exe = target.join("release/own-weights");
    let mut child = Command::new(&exe)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("{}: {e}", exe.display()));
    // Write from another thread: the child's output would fill its pipe meanwhile.
    let mut stdin = child.stdin.take().unwrap();
    let writer = std::thread::spawn(move || stdin.write_all(input.as_bytes()));
    let out = child.wait_with_output().unwrap();
    writer.join().unwrap().unwrap();
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    let mut lines = text.lines();

    // The certificate compiled into the crate is the exporter's for this build's tanh.
    let (k, tanh) = if FAST_TANH {
        (1, Tanh::Fast)
    } else {
        (0, Tanh::Libm)
    };
    let eps = model.eps + report.f32_allowance[k];
    assert_eq!(
        lines.next().unwrap(),
        format!("3 2 {:016x} Estimated {}", eps.to_bits(), model.hash)
    );

    // evaluate = the exporter's f32 model of the device, bit for bit.
    let folded = model.folded();
    let (lo, hi) = model.domain_f32();
    let (clo, chi) = model.clamp_band(eps);
    let fallback = model.fallback_f32(&clo, &chi);
    let boxes = model.excluded_f32();
    let mut n = 0;
    let mut clamped = 0;
    let mut excluded = 0;
    for (x, line) in xs.iter().zip(lines) {
        let (mut want_u, mut flags) = (fallback.clone(), Flags::NON_FINITE);
        if x.iter().all(|v| v.is_finite()) {
            flags = Flags::EMPTY;
            if (0..3).any(|i| x[i] < lo[i] || x[i] > hi[i]) {
                flags = flags.union(Flags::OUT_OF_DOMAIN);
            }
            let xp: Vec<f32> = (0..3).map(|i| x[i].clamp(lo[i], hi[i])).collect();
            if boxes
                .iter()
                .any(|(l, h)| (0..3).all(|i| l[i] <= xp[i] && xp[i] <= h[i]))
            {
                flags = flags.union(Flags::EXCLUDED);
            }
            let y = export::eval_f32(&folded, &lo, &hi, x, tanh);
            for j in 0..2 {
                want_u[j] = y[j].clamp(clo[j], chi[j]);
                if want_u[j] != y[j] {
                    flags = flags.union(Flags::CLAMPED);
                }
            }
        }
        let want = format!(
            "{} {:08x} {:08x}",
            flags.0,
            want_u[0].to_bits(),
            want_u[1].to_bits()
        );
        assert_eq!(line, want, "x = {x:?}");
        clamped += usize::from(flags.contains(Flags::CLAMPED));
        excluded += usize::from(flags.contains(Flags::EXCLUDED));
        n += 1;
    }
    assert_eq!(n, xs.len());
    assert!(
        excluded > 0,
        "no state in the excluded box: the flag is not exercised"
    );
    println!(
        "{n} states bit-identical to the exporter's f32 model ({clamped} clamped, {excluded} \
         in the excluded box)"
    );
}
