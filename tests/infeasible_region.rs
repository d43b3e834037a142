//! A plant with a region of X where the MPC has no solution (`configs/cstr.toml`: a CSTR
//! whose hot, concentrated corner runs away even under full cooling), made small: `trainer
//! run` completes every stage; the closed loop started inside the runaway region stops with
//! status `diverged` (counted on the stage line) and `closed_loop.json` holds no `null`;
//! the dataset has unlabelled states there (so the scenario is the one it claims to be).
//! Before, the diverged runs carried 1e241 and then NaN into `closed_loop.json` as `null`
//! and the `plots` stage failed reading it.

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

/// The shipped CSTR made small, with the reference closed loop started at (0.8, 365), in
/// the runaway corner.
fn small_cstr() -> String {
    let shipped = std::fs::read_to_string(config("cstr.toml")).unwrap();
    let text = shipped
        .replace("counts = [11, 11]", "counts = [6, 6]")
        .replace(
            "hidden = [16, 16]\nepochs = 300",
            "hidden = [8, 8]\nepochs = 100\nbatch_size = 16\nvalidation_n = 30",
        )
        .replace("steps = 60 ", "steps = 30 ")
        .replace("x0 = [0.4, 340.0]", "x0 = [0.8, 365.0]")
        .replace("random_initial_states = 6", "random_initial_states = 2")
        + "\n[solver]\nmax_iter = 40\n\n[plots]\nerror_map_grid = [12, 8]\npng_scale = 1.0\n"
        // Theorem 1 is vacuous here (nx = 2): the refinement runs and is stopped by a small
        // budget with its runaway cells unresolved (ε = ∞ is then no candidate band); the
        // statistical tiers run at test size.
        + "\n[refine]\nbudget = 300\nmax_seconds = 2.0\n\n[certify]\nstatistical = 300\nclosed_loop = 300\n";
    for (a, b) in [
        ("counts = [6, 6]", "grid"),
        ("validation_n = 30", "training"),
        ("steps = 30 ", "closed loop"),
        ("x0 = [0.8, 365.0]", "x0"),
    ] {
        assert!(
            text.contains(a),
            "configs/cstr.toml changed: the {b} edit no longer applies"
        );
    }
    text
}

#[test]
fn every_stage_completes_and_diverged_runs_are_stopped() {
    let dir = tempdir();
    let d = dir.path();
    let cfg = d.join("cstr.toml");
    std::fs::write(&cfg, small_cstr()).unwrap();
    let runs = d.join("runs");
    let out = ok(&trainer(&[
        "run",
        cfg.to_str().unwrap(),
        "--out",
        runs.to_str().unwrap(),
    ]));
    let run = runs.join("cstr");
    for f in [
        "certificate.json",
        "weights.rs",
        "closed_loop.json",
        "report.md",
    ] {
        assert!(run.join(f).exists(), "{f} missing:\n{out}");
    }
    // The scenario: some grid states have no label (the runaway corner).
    let data = std::fs::read_to_string(run.join("dataset.csv")).unwrap();
    let unlabelled = data
        .lines()
        .skip(1)
        .filter(|l| l.split(',').nth(3).is_some_and(|u| u == "NaN"))
        .count();
    assert!(
        unlabelled > 0,
        "no unlabelled state: not an infeasible region\n{data}"
    );
    // The statistical tier: the exported statement is conditional on hard-feasible states
    // (status `converged`); unlabelled and soft-labelled states form the infeasible share.
    let csv = std::fs::read_to_string(run.join("statistical.csv")).unwrap();
    let status = |l: &str| l.split(',').nth(7).unwrap_or_default().to_string();
    let statuses: Vec<String> = csv.lines().skip(1).map(status).collect();
    let n = statuses.len() as u64;
    let conv = statuses.iter().filter(|s| *s == "converged").count() as u64;
    let soft = statuses.iter().filter(|s| *s == "soft").count() as u64;
    let cert: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(run.join("certificate_statistical.json")).unwrap(),
    )
    .unwrap();
    let st = &cert["statistical"];
    assert_eq!(st["samples"].as_u64(), Some(n), "{st}");
    assert_eq!(st["given_feasible"]["samples"].as_u64(), Some(conv), "{st}");
    assert_eq!(
        st["infeasible_share"]["unlabelled"].as_u64(),
        Some(n - conv),
        "{st}"
    );
    if soft > 0 {
        assert_eq!(st["soft_labelled"]["states"].as_u64(), Some(soft), "{st}");
    }
    let outcome: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("statistical.json")).unwrap())
            .unwrap();
    assert_eq!(outcome["infeasible"].as_u64(), Some(n - conv), "{outcome}");
    assert_eq!(outcome["soft"].as_u64(), Some(soft), "{outcome}");
    // The closed loop: no null anywhere, the runs from the runaway corner diverged.
    let text = std::fs::read_to_string(run.join("closed_loop.json")).unwrap();
    assert!(!text.contains("null"), "null in closed_loop.json");
    let cl: serde_json::Value = serde_json::from_str(&text).unwrap();
    let mpc = cl["mpc"].as_array().unwrap();
    let first = &mpc[0];
    assert_eq!(first["x0"], serde_json::json!([0.8, 365.0]));
    assert_eq!(first["status"], "diverged", "{first}");
    let stopped = first["stopped"]["reason"].as_str().unwrap();
    assert!(
        stopped.contains("left X") || stopped.contains("not finite"),
        "{stopped}"
    );
    // Every state recorded lies within the stop box (the stop rule): the hull of X =
    // [0.3, 0.8] × [335, 365] and the state bounds [0, 1] × [300, 380], widened by ten
    // widths of X (0.5 mol/L, 30 K): [−5, 6] × [0, 680]; all finite.
    for r in cl
        .as_object()
        .unwrap()
        .values()
        .flat_map(|v| v.as_array().unwrap())
    {
        for x in r["x"].as_array().unwrap() {
            let (ca, t) = (x[0].as_f64().unwrap(), x[1].as_f64().unwrap());
            assert!(
                (-5.0..=6.0).contains(&ca) && (0.0..=680.0).contains(&t),
                "{x}"
            );
        }
    }
    // The stage line counts the diverged runs per controller.
    let line = out
        .lines()
        .find(|l| l.contains("closed_loop") && l.contains("done"))
        .unwrap_or_else(|| panic!("no closed-loop stage line:\n{out}"));
    assert!(line.contains("runs diverged"), "{line}");
    let mpc_diverged = mpc.iter().filter(|r| r["status"] == "diverged").count();
    let mpc_runs: usize = cl
        .as_object()
        .unwrap()
        .iter()
        .filter(|(k, _)| *k == "mpc" || k.starts_with("mpc_"))
        .map(|(_, v)| v.as_array().unwrap().len())
        .sum();
    let noise_diverged = cl["mpc_noise"].as_array().map_or(0, |v| {
        v.iter().filter(|r| r["status"] == "diverged").count()
    });
    assert!(
        line.contains(&format!(
            "{} of {mpc_runs} runs diverged",
            mpc_diverged + noise_diverged
        )),
        "{line}"
    );
}
