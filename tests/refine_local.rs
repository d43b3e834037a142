//! `trainer refine`: adaptive refinement with local certificates, end to end — the target
//! is met, the certificate survives a check at fresh MPC solves, the outputs are usable by
//! `trainer eval` / `trainer export`, and a run killed mid-way resumes to the same model.

use ampc_tests::{kill_at_checkpoint, tempdir, trainer};
use std::path::Path;

/// The paper's pendulum on a small domain around the upright position (saturation kinks
/// included), a 2-16-16-1 net and a loose target, so that the run takes seconds.
fn small_config(dir: &Path) -> String {
    let mut out = Vec::new();
    let mut skip = false;
    for l in trainer::problem::PENDULUM_TOML.lines() {
        if l.starts_with("[domain]") {
            out.push("[domain]\nlo = [-1.0, -0.5]\nhi = [1.0, 0.5]\n".to_string());
            skip = true;
            continue;
        }
        if skip && l.starts_with('[') {
            skip = false;
        }
        if !skip {
            out.push(l.to_string());
        }
    }
    out.push(
        "[refine]\ntarget_eps = 1.0\nbudget = 3000\ninitial = [5, 3]\nmax_rounds = 30\n\n\
         [refine.training]\nhidden = [16, 16]\nepochs = 300\nbatch_size = 64\n\
         learning_rate = 3e-3\nschedule = \"cosine\"\nlambda = [1.0, 0.1, 0.0]\n\
         validation_n = 0\nlog_every = 1000000\nsaturation_aware = true\n"
            .to_string(),
    );
    let p = dir.join("small.toml");
    std::fs::write(&p, out.join("\n")).unwrap();
    p.to_str().unwrap().to_string()
}

/// The problem's `name` in a problem file.
fn cfg_text_name(cfg: &str) -> String {
    trainer::problem::ProblemConfig::load(Path::new(cfg))
        .unwrap()
        .name
}

fn ok(o: &std::process::Output) {
    assert!(
        o.status.success(),
        "stdout: {}\nstderr: {}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
}

#[test]
fn refine_meets_its_target_and_passes_the_check() {
    let dir = tempdir();
    let d = dir.path();
    let cfg = small_config(d);
    let out = d.join("r");
    // Target and budget from the command line (they override the file's `[refine]`).
    let cfg_text = std::fs::read_to_string(&cfg).unwrap();
    assert!(cfg_text.contains("target_eps = 1.0\nbudget = 3000\n"));
    let cfg_text = cfg_text.replace(
        "target_eps = 1.0\nbudget = 3000\n",
        "target_eps = 0.2\nbudget = 100\n",
    );
    std::fs::write(&cfg, cfg_text).unwrap();
    let o = trainer(&[
        "refine",
        "--config",
        &cfg,
        "--target-eps",
        "1.0",
        "--budget",
        "3000",
        "--out",
        out.to_str().unwrap(),
        "--check",
        "2000",
        "--statistical",
        "1000",
        "--quiet",
    ]);
    ok(&o);
    let cert: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("certificate.json")).unwrap()).unwrap();
    for key in [
        "eps",
        "eps_d",
        "l_nn",
        "l_nn_method",
        "l_nn_naive",
        "l_nn_lower",
        "l_mpc",
        "l_mpc_is_estimate",
        "covering_radius",
        "f32_allowance",
        "domain_lo",
        "domain_hi",
        "u_lo",
        "u_hi",
        "clamp_lo",
        "clamp_hi",
        "hash",
        "local",
    ] {
        assert!(cert.get(key).is_some(), "certificate.json lacks `{key}`");
    }
    let eps = cert["eps"].as_f64().unwrap();
    assert!(eps <= 1.0, "ε {eps}");
    // The MPC's range in a cell is estimated from its corners: so is ε.
    assert_eq!(cert["guarantee"], "estimated");
    assert_eq!(cert["tiers"]["mpc_range"], "estimated");
    assert_eq!(cert["tiers"]["corner_errors"], "sound");
    assert_eq!(cert["local"]["met"], true);
    let solves = cert["local"]["solves"].as_u64().unwrap();
    assert!(solves <= 3000);
    // The global Theorem 1 needs far more grid points for the same ε.
    assert!(cert["local"]["sparsification"].as_f64().unwrap() > 10.0);
    let check: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("check.json")).unwrap()).unwrap();
    assert_eq!(check["over_eps"], 0);
    assert_eq!(check["over_cell"], 0);
    assert_eq!(check["labelled"], 2000);
    assert_eq!(check["certified"].as_f64().unwrap(), eps);
    // The per-cell check: every cell visited, its verdict passed (the command fails
    // otherwise), the miss rate within the tolerance.
    let pc = &check["per_cell"];
    assert_eq!(pc["cells"], cert["local"]["cells"]);
    assert!(pc["states"].as_u64().unwrap() >= pc["cells"].as_u64().unwrap());
    assert_eq!(pc["passed"], true, "{pc}");
    assert!(pc["miss_rate"].as_f64().unwrap() <= pc["tolerance"].as_f64().unwrap());
    assert_eq!(pc["jumps"], 0);
    // The statistical tier: 1000 other i.i.d. states; ε held at all of them (as at the
    // check's), so the bound is the closed form 1 − β^{1/n}.
    let st = &cert["statistical"];
    assert_eq!(st["samples"], 1000);
    assert_eq!(st["exceedances"], 0, "{st}");
    assert_eq!(st["eps"].as_f64(), Some(eps));
    let p = st["p_exceed_upper"].as_f64().unwrap();
    let closed = 1.0 - 0.01f64.powf(1.0 / 1000.0);
    assert!((p - closed).abs() <= 1e-10 * closed, "{p} vs {closed}");
    assert!(out.join("statistical.bin").exists());
    // The estimated remainders were not exceeded at any state, and the data is not trivial.
    let used = check["max_remainder_use"].as_f64().unwrap();
    assert!(used > 0.0 && used <= 1.0, "remainder use {used}");
    assert!(check["max_observed"].as_f64().unwrap() > 0.05);
    // cells.csv: one row per cell, every ε_C ≤ target.
    let cells = std::fs::read_to_string(out.join("cells.csv")).unwrap();
    let rows: Vec<&str> = cells.lines().skip(1).collect();
    assert_eq!(rows.len() as u64, cert["local"]["cells"].as_u64().unwrap());
    for r in &rows {
        let e: f64 = r.split(',').nth(4).unwrap().parse().unwrap();
        assert!(e <= 1.0, "{r}");
    }
    // The ε_C map: the PNG is the SVG's rendering and decodes at 1.5 × its size.
    let svg = std::fs::read_to_string(out.join("eps_map.svg")).unwrap();
    assert!(svg.contains("ε_C per cell") && svg.matches("<rect").count() >= rows.len());
    let png = std::fs::read(out.join("eps_map.png")).unwrap();
    assert_eq!(
        trainer::study::plots::to_png("eps_map", &svg, 1.5).unwrap(),
        png
    );
    let info = png::Decoder::new(std::io::Cursor::new(png))
        .read_info()
        .expect("PNG header")
        .info()
        .clone();
    assert_eq!((info.width, info.height), (2250, 840));
    // The f32 allowance the certificate's tier map calls sound is the deployed controller's
    // (2-norm, libm tanh), stored in certificate.json and in the model's certificate alike —
    // not a placeholder 0.
    let model = trainer::certify::Model::load(&out.join("model.bin")).unwrap();
    let stored = model
        .certificate
        .as_ref()
        .expect("the model stores its certificate");
    let a = cert["f32_allowance"].as_f64().unwrap();
    assert!(a > 0.0, "f32_allowance {a}");
    assert_eq!(cert["tiers"]["f32_allowance"], "sound");
    assert_eq!(stored.f32_allowance, a);
    let name = cfg_text_name(&cfg);
    assert_eq!(
        trainer::deploy::export::deployed_allowance(&name, &model, stored),
        Some(a)
    );
    // The model is the format `trainer train` writes: eval and export take it.
    let states = d.join("s.csv");
    std::fs::write(&states, "x1,x2\n0.1,0.2\n-0.5,0.3\n").unwrap();
    let model = out.join("model.bin");
    ok(&trainer(&[
        "eval",
        "--model",
        model.to_str().unwrap(),
        "--states",
        states.to_str().unwrap(),
        "--out",
        d.join("e.csv").to_str().unwrap(),
    ]));
    ok(&trainer(&[
        "export",
        "--model",
        model.to_str().unwrap(),
        "--rust",
        d.join("w.rs").to_str().unwrap(),
        "--postcard",
        d.join("w.bin").to_str().unwrap(),
    ]));
    // The dataset file is a regular dataset (sampler "adaptive") with every solve.
    let ds = trainer::data::dataset::Dataset::load(&out.join("dataset.bin")).unwrap();
    assert_eq!(ds.records.len() as u64, solves);
}

#[test]
fn killed_refine_resumes_to_the_same_model() {
    let dir = tempdir();
    let d = dir.path();
    let cfg = small_config(d);
    let reference = d.join("ref");
    ok(&trainer(&[
        "refine",
        "--config",
        &cfg,
        "--out",
        reference.to_str().unwrap(),
        "--quiet",
    ]));
    let out = d.join("run");
    let state = out.join("refine_state.bin");
    let running = kill_at_checkpoint(
        &[
            "refine",
            "--config",
            &cfg,
            "--out",
            out.to_str().unwrap(),
            "--quiet",
        ],
        &state,
    );
    assert!(running, "the run ended before its first checkpoint");
    // The first best round is written at once (it may land just before or after the
    // checkpoint the kill waits for): if its report is there, it says the run was running.
    if out.join("refine_report.json").exists() {
        let report: serde_json::Value =
            serde_json::from_slice(&std::fs::read(out.join("refine_report.json")).unwrap())
                .unwrap();
        assert_eq!(report["stopped"], "running", "{report}");
    }
    // The rounds done before the kill, with their wall times: a resumed run keeps them,
    // a restart would measure them anew.
    let ck: trainer::certify::refine::RefineState =
        postcard::from_bytes(trainer::io::unseal(&std::fs::read(&state).unwrap()).unwrap())
            .unwrap();
    assert!(!ck.log.is_empty() && !ck.finished);
    ok(&trainer(&[
        "refine",
        "--config",
        &cfg,
        "--out",
        out.to_str().unwrap(),
        "--quiet",
    ]));
    let log: Vec<trainer::certify::refine::RoundLog> =
        serde_json::from_slice(&std::fs::read(out.join("refine_log.json")).unwrap()).unwrap();
    assert!(log.len() > ck.log.len(), "the resumed run did more rounds");
    assert_eq!(
        log[..ck.log.len()],
        ck.log[..],
        "the resumed run kept the rounds before the kill"
    );
    for f in ["model.bin", "cells.csv", "dataset.bin"] {
        assert_eq!(
            std::fs::read(out.join(f)).unwrap(),
            std::fs::read(reference.join(f)).unwrap(),
            "{f} differs after resuming"
        );
    }
}

#[test]
fn a_corrupt_checkpoint_is_a_clear_error() {
    let dir = tempdir();
    let out = dir.path().join("r");
    std::fs::create_dir_all(&out).unwrap();
    std::fs::write(out.join("refine_state.bin"), b"not a checkpoint").unwrap();
    let o = trainer(&["refine", "--out", out.to_str().unwrap(), "--quiet"]);
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("refine_state.bin") && err.contains("not a refinement checkpoint"),
        "{err}"
    );
    // Settings that cannot work are refused with the key at fault.
    let o = trainer(&["refine", "--out", out.to_str().unwrap(), "--budget", "10"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("refine.initial"));
}

/// A run stopped by its wall-clock budget (`[refine] max_seconds`, here spent by the first
/// round) ends with its best certificate and a report: the model and certificate are
/// usable by `trainer eval` / `trainer export`, `refine_report.json` says why the run
/// stopped, where the worst cell is and how to resume, and the error names the reason.
#[test]
fn a_refine_stopped_by_its_time_budget_leaves_its_certificate_and_a_report() {
    let dir = tempdir();
    let d = dir.path();
    let cfg = small_config(d);
    let text = std::fs::read_to_string(&cfg).unwrap();
    let timed = d.join("timed.toml");
    std::fs::write(
        &timed,
        text.replace(
            "max_rounds = 30\n",
            "max_rounds = 30\nmax_seconds = 0.001\n",
        ),
    )
    .unwrap();
    let out = d.join("r");
    let o = trainer(&[
        "refine",
        "--config",
        timed.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--quiet",
    ]);
    assert_eq!(
        o.status.code(),
        Some(1),
        "the target is not met in one round"
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("refine.max_seconds") && err.contains("resume"),
        "{err}"
    );
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("refine_report.json")).unwrap()).unwrap();
    assert_eq!(report["stopped"], "max_seconds", "{report}");
    assert_eq!(report["rounds"], 1, "{report}");
    assert!(report["eps"].as_f64().unwrap().is_finite());
    assert!(report["binding_cell"][0].as_array().unwrap().len() == 2);
    let resume = report["resume"].as_str().unwrap();
    assert!(
        resume.contains("--out") && resume.contains("timed.toml"),
        "{resume}"
    );
    // The certificate file and the model agree and readers take them.
    let cert: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("certificate.json")).unwrap()).unwrap();
    assert_eq!(cert["eps"].as_f64(), report["eps"].as_f64());
    let states = d.join("s.csv");
    std::fs::write(&states, "x1,x2\n0.1,0.2\n-0.5,0.3\n").unwrap();
    let model = out.join("model.bin");
    ok(&trainer(&[
        "eval",
        "--model",
        model.to_str().unwrap(),
        "--states",
        states.to_str().unwrap(),
        "--out",
        d.join("e.csv").to_str().unwrap(),
    ]));
    ok(&trainer(&[
        "export",
        "--model",
        model.to_str().unwrap(),
        "--certificate",
        out.join("certificate.json").to_str().unwrap(),
        "--rust",
        d.join("w.rs").to_str().unwrap(),
        "--postcard",
        d.join("w.bin").to_str().unwrap(),
    ]));
}
