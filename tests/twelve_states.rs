//! `trainer run` end to end on a 12-state, 4-input plant (`configs/mass_chain12.toml`, the
//! largest size of the expression plants: nx + nu = 16) with a tiny budget: every stage
//! runs; the dataset, closed loop and figures have the plant's dimensions; the exported
//! `weights.rs` declares NX = 12, NU = 4 and compiles inside a copy of `controller-core`
//! (own target directory, offline); and `weights.bin` decodes into a 12 → 4
//! `controller_core::Controller` that computes bit for bit what the exporter's f32 model
//! computes.

use ampc_tests::{config, tempdir, trainer};
use controller_core::layer::Dense;
use controller_core::mlp::Hidden;
use std::path::{Path, PathBuf};
use std::process::Command;
use trainer::deploy::export::{self, Tanh};

/// The problem file with a tiny budget: 40 states, 8-8 hidden units, 50 epochs, 10 steps.
fn tiny_problem() -> String {
    let text = std::fs::read_to_string(config("mass_chain12.toml")).unwrap();
    let head = &text[..text.find("[training]").expect("a [training] section")];
    assert!(head.contains("n = 2000"), "the sampling size to shrink");
    head.replace("n = 2000", "n = 40")
        + "[training]\nhidden = [8, 8]\nepochs = 50\nbatch_size = 10\nvalidation_n = 20\nlog_every = 25\n"
        + "\n[closed_loop]\nsteps = 10\nrandom_initial_states = 1\nnoise_runs = 1\nseeds = 1\n"
        + "\n[plots]\nerror_map_grid = [8, 6]\npng_scale = 1.0\n"
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// Copies the directory `from` into `to`, recursively.
fn copy_tree(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap_or_else(|e| panic!("{}: {e}", from.display())) {
        let e = e.unwrap();
        let (s, d) = (e.path(), to.join(e.file_name()));
        if e.file_type().unwrap().is_dir() {
            copy_tree(&s, &d);
        } else {
            std::fs::copy(&s, &d).unwrap_or_else(|err| panic!("{}: {err}", s.display()));
        }
    }
}

/// `cargo check` of a copy of controller-core whose generated weights are `run`'s.
fn check_controller_core_with(run: &Path) {
    let root = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/.."));
    let dir = tempdir();
    let krate = dir.path().join("controller-core");
    let src = krate.join("src");
    // The whole source tree (a module added later is copied too), then the run's weights
    // in place of the demo's.
    copy_tree(&root.join("controller-core/src"), &src);
    for f in ["weights.rs", "weights.bin"] {
        std::fs::copy(run.join(f), src.join("demo").join(f)).unwrap();
    }
    // The workspace manifest's dependencies, without the workspace.
    std::fs::write(
        krate.join("Cargo.toml"),
        "[package]\nname = \"controller-core\"\nversion = \"0.1.0\"\nedition = \"2021\"\n\n\
         [dependencies]\npostcard = { version = \"1.2\", default-features = false }\n\
         serde = { version = \"1\", default-features = false }\n\n[workspace]\n",
    )
    .unwrap();
    std::fs::copy(root.join("Cargo.lock"), krate.join("Cargo.lock")).unwrap();
    let target = std::env::current_exe()
        .unwrap()
        .ancestors()
        .nth(3)
        .unwrap()
        .join("controller-core-nx12");
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let out = Command::new(cargo)
        .args(["check", "--offline", "--lib"])
        .env("CARGO_TARGET_DIR", &target)
        .current_dir(&krate)
        .output()
        .expect("run cargo");
    assert!(
        out.status.success(),
        "controller-core with the 12-state weights does not compile:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn twelve_state_plant_runs_end_to_end_and_exports_to_the_core() {
    let dir = tempdir();
    let d = dir.path();
    let cfg = d.join("chain.toml");
    std::fs::write(&cfg, tiny_problem()).unwrap();
    let out = d.join("runs");
    let o = trainer(&[
        "run",
        cfg.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let run = out.join("mass_chain12");

    // Dataset: 12 states, 4 inputs, 48 sensitivities per row.
    let csv = std::fs::read_to_string(run.join("dataset.csv")).unwrap();
    let head: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    assert!(head.contains(&"x12") && !head.contains(&"x13"), "{head:?}");
    assert!(head.contains(&"u4") && !head.contains(&"u5"), "{head:?}");
    assert!(head.contains(&"du4_dx12"), "{head:?}");
    assert_eq!(csv.lines().count(), 41);

    // Certificate: finite terms.
    let cert = json(&run.join("certificate.json"));
    for k in ["eps", "eps_d", "l_nn"] {
        let v = cert[k]
            .as_f64()
            .unwrap_or_else(|| panic!("certificate lacks {k}"));
        assert!(v.is_finite() && v >= 0.0, "{k} = {v}");
    }

    // Closed loop: 12-dimensional states, 4-dimensional inputs, 10 steps.
    let cl = json(&run.join("closed_loop.json"));
    for k in ["mpc", "nominal", "regularized"] {
        let r = &cl[k][0];
        assert_eq!(r["x0"].as_array().unwrap().len(), 12, "{k}");
        let xs = r["x"].as_array().unwrap();
        assert_eq!(xs.len(), 11, "{k}: x_0..x_10");
        assert!(xs.iter().all(|x| x.as_array().unwrap().len() == 12), "{k}");
        let us = r["u"].as_array().unwrap();
        assert!(us.iter().all(|u| u.as_array().unwrap().len() == 4), "{k}");
    }

    // Figures: a panel per signal and a named slice for the error map.
    let figs = json(&run.join("plots/figures.json"));
    let map = figs
        .as_array()
        .unwrap()
        .iter()
        .find(|f| f["name"] == "error_map")
        .expect("error_map figure");
    let caption = map["caption"].as_str().unwrap();
    assert!(caption.contains("2-D slice over"), "{caption}");
    let svg = std::fs::read_to_string(run.join("plots/error_map.svg")).unwrap();
    assert!(svg.contains("other states at the setpoint"));
    let report = std::fs::read_to_string(run.join("report.md")).unwrap();
    assert!(report.contains("nx = 12, nu = 4"));
    assert!(
        !report.contains("paper R²"),
        "no paper columns for another plant"
    );

    // The export: dimensions in the generated source, and it compiles in the core.
    let rs = std::fs::read_to_string(run.join("weights.rs")).unwrap();
    assert!(rs.contains("pub const NX: usize = 12;"), "{}", &rs[..600]);
    assert!(rs.contains("pub const NU: usize = 4;"));
    assert!(rs.contains("Hidden<12, 8, Hidden<8, 8, Dense<8, 4>>>"));
    check_controller_core_with(&run);

    // The blob decodes into a 12 → 4 controller equal to the exporter's f32 model.
    type Net = Hidden<12, 8, Hidden<8, 8, Dense<8, 4>>>;
    let blob = std::fs::read(run.join("weights.bin")).unwrap();
    let dec = controller_core::blob::decode::<12, 4, Net>(&blob).expect("decode the blob");
    assert!(
        controller_core::blob::decode::<2, 1, controller_core::demo::weights::Net>(&blob).is_err()
    );
    let m = trainer::certify::Model::load(&run.join("model_regularized.bin")).unwrap();
    let c: trainer::certify::certificate::Certificate = serde_json::from_value(cert).unwrap();
    let model = export::ExportModel::from_trained("mass_chain12", &m, &c).unwrap();
    assert_eq!(dec.hash, model.hash);
    let folded = model.folded();
    let (lo, hi) = model.domain_f32();
    let tanh = if controller_core::activation::TANH_KIND == "fast" {
        Tanh::Fast
    } else {
        Tanh::Libm
    };
    let ctl = &dec.controller;
    let mut s = 0x9e37_79b9_7f4a_7c15u64;
    for _ in 0..20_000 {
        let x: [f32; 12] = std::array::from_fn(|_| {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            -1.0 + 2.0 * ((s >> 40) as f32 / (1u64 << 24) as f32)
        });
        let want = export::eval_f32(&folded, &lo, &hi, &x, tanh);
        let got = ctl.evaluate(&x).u;
        for j in 0..4 {
            let w = want[j].clamp(ctl.clamp_lo[j], ctl.clamp_hi[j]);
            assert_eq!(got[j].to_bits(), w.to_bits(), "x = {x:?}, output {j}");
        }
    }
}
