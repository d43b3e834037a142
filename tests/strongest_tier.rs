//! `trainer run` reaches the strongest non-vacuous guarantee by default (issue 40 §3, §4): on
//! a small pendulum whose Theorem-1 ε is vacuous (coarse grid) and with `[refine] enabled =
//! "off"`, the `refine` stage says it was skipped and why, the `statistical` stage tests the
//! deployed controller, and the export ships the statistical band — the strongest
//! non-vacuous candidate — naming its source and tier in `export_report.json`; the report's
//! verdict names the guarantee reached, why not a stronger one, the next command, and the
//! closed loop's statistical statement ("violates a constraint or does not converge").

use ampc_tests::{config, tempdir, trainer};

fn ok(o: &std::process::Output) -> String {
    assert!(
        o.status.success(),
        "{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).into_owned() + &String::from_utf8_lossy(&o.stderr)
}

fn small_pendulum() -> String {
    let shipped = std::fs::read_to_string(config("pendulum.toml")).unwrap();
    assert!(
        shipped.contains("counts = [35, 10]"),
        "configs/pendulum.toml changed"
    );
    shipped.replace("counts = [35, 10]", "counts = [9, 5]")
        + "\n[training]\nhidden = [16, 16]\nepochs = 150\nvalidation_n = 100\n\
           \n[closed_loop]\nsteps = 40\nrandom_initial_states = 1\nnoise_runs = 1\nseeds = 1\n\
           \n[plots]\nerror_map_grid = [12, 8]\npng_scale = 1.0\n\
           \n[refine]\nenabled = \"off\"\n\
           \n[certify]\nstatistical = 400\nclosed_loop = 40\np_target = 0.05\n"
}

fn json(p: &std::path::Path) -> serde_json::Value {
    let t = std::fs::read_to_string(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    serde_json::from_str(&t).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

#[test]
fn the_run_exports_the_strongest_non_vacuous_band_and_says_which() {
    let dir = tempdir();
    let d = dir.path();
    let cfg = d.join("pendulum.toml");
    std::fs::write(&cfg, small_pendulum()).unwrap();
    let runs = d.join("runs");
    let out = ok(&trainer(&[
        "run",
        cfg.to_str().unwrap(),
        "--out",
        runs.to_str().unwrap(),
    ]));
    let run = runs.join("pendulum");
    // The stages ran, each with its line.
    assert!(
        out.contains("[     refine] done") && out.contains("skipped: [refine] enabled = \"off\""),
        "{out}"
    );
    assert!(out.contains("[statistical] done"), "{out}");
    assert!(out.contains("400 states of the"), "{out}");
    assert!(
        out.contains("closed-loop statistical: P(run violates or does not converge)"),
        "{out}"
    );
    // Theorem 1 is vacuous for the exported net: ε ≥ d_U = 30 (|u| ≤ 15).
    let t1 = json(&run.join("certificate.json"));
    let t1n = json(&run.join("certificate_nominal.json"));
    let eps1 = t1["eps"]
        .as_f64()
        .unwrap()
        .min(t1n["eps"].as_f64().unwrap());
    assert!(
        eps1 >= 30.0,
        "the scenario needs a vacuous Theorem 1, got ε = {eps1}"
    );
    // The statistical level is finite and non-vacuous, so it is the strongest band.
    let st = json(&run.join("statistical.json"));
    let eps_p = st["eps_p"].as_f64().expect("a finite statistical level");
    assert!(eps_p < 30.0, "{st}");
    let ex = json(&run.join("export_report.json"));
    assert_eq!(ex["source"], "statistical", "{ex}");
    assert_eq!(ex["tier"], "statistical", "{ex}");
    assert_eq!(ex["eps_f64"].as_f64().unwrap(), eps_p, "{ex}");
    let reached = ex["verdict"]["reached"].as_str().unwrap();
    assert!(
        reached.starts_with("statistical: P(‖κ − κ̂‖ > ε ="),
        "{reached}"
    );
    let why = ex["verdict"]["why_not_stronger"].to_string();
    assert!(
        why.contains("vacuous") && why.contains("local refinement skipped"),
        "{why}"
    );
    assert!(
        ex["verdict"]["next"]
            .as_str()
            .unwrap()
            .contains("trainer refine"),
        "{ex}"
    );
    // The exported band is the clamp: U widened by ε_p + the f32 allowance, cut to the
    // actuator's range (the pendulum's actuator range is U = [-15, 15] itself).
    let a = ex["f32_allowance_libm"].as_f64().unwrap();
    let hi = ex["clamp_hi"][0].as_f64().unwrap();
    assert!(eps_p + a > 0.0, "{ex}");
    assert!((hi - (15.0 + eps_p + a).min(15.0)).abs() < 1e-6, "{ex}");
    // The closed loop, statistically: failing = violating or not converging.
    let cl = json(&run.join("closed_loop_statistical.json"));
    assert_eq!(cl["failing"]["trajectories"], 40, "{cl}");
    assert!(
        cl["failing"]["violating"].as_u64().unwrap() >= cl["all"]["violating"].as_u64().unwrap(),
        "{cl}"
    );
    // Where the runs went: the failing ones that left X among them, the box of the states
    // the controller was evaluated at (every start lies in X, so the box meets X).
    let left = cl["left_domain"].as_u64().expect("left_domain");
    let failing_left = cl["failing_left_domain"]
        .as_u64()
        .expect("failing_left_domain");
    assert!(
        failing_left <= left.min(cl["failing"]["violating"].as_u64().unwrap()),
        "{cl}"
    );
    let (lo, hi) = (&cl["reach"][0], &cl["reach"][1]);
    for j in 0..2 {
        let (l, h) = (lo[j].as_f64().unwrap(), hi[j].as_f64().unwrap());
        assert!(l <= h, "{cl}");
    }
    assert!(
        lo[1].as_f64().unwrap() <= 1.0 && hi[1].as_f64().unwrap() >= -1.0,
        "{cl}"
    );
    // The report's verdict names the guarantee and the closed-loop statement.
    let md = std::fs::read_to_string(run.join("report.md")).unwrap();
    assert!(md.contains("**Guarantee reached — statistical"), "{md}");
    assert!(
        md.contains("Not stronger:") && md.contains("Next: `trainer refine"),
        "{md}"
    );
    assert!(md.contains("Closed loop, statistically"), "{md}");
    // A rerun skips every stage (the new ones keep manifests too).
    let again = ok(&trainer(&[
        "run",
        cfg.to_str().unwrap(),
        "--out",
        runs.to_str().unwrap(),
    ]));
    assert!(!again.contains("] done"), "{again}");
}
