//! `trainer run` end to end on the shipped problem with a setpoint, path constraints and a
//! terminal region (`configs/stiff_spring_setpoint.toml`, made smaller: fewer states, a
//! shorter training, a shorter closed loop). Checked by computations independent of the run:
//! - the constraints reach the labels: the run's dataset equals `trainer solve` of the full
//!   problem file at the same states (to 1e-7: the run's grid is warm-started, the solves
//!   are cold, both stop at the solver's tolerance), and dropping the path constraints or
//!   the terminal region from the file moves the label (by > 1e-4) at ≥ 1 % of a 17 × 17
//!   grid of X (so the first check can fail);
//! - κ(x_ref) = u_ref, the spring force that holds the setpoint, computed here by hand from
//!   the plant (k·p + 0.5·p³ at p = 0.5), and both nets reproduce κ(x_ref) (the hold);
//! - every closed-loop run's reported `max_violation` equals the violation recomputed here
//!   from its trajectory with the constraints written out in Rust (boxes on x_{k+1}, the
//!   state constraint on x_{k+1}, the mixed one on (x_k, u_k) for k ≥ 1), and the MPC's runs
//!   never violate the state constraints;
//! - the MPC's and the nets' closed loops end at x_ref.

use ampc_tests::{config, tempdir, trainer};
use std::collections::HashMap;
use std::path::Path;

/// Rows of a CSV written by the trainer, as name → value (non-numeric cells skipped).
fn rows(p: &Path) -> Vec<HashMap<String, f64>> {
    let text = std::fs::read_to_string(p).unwrap();
    let mut lines = text.lines();
    let head: Vec<String> = lines
        .next()
        .unwrap()
        .split(',')
        .map(str::to_string)
        .collect();
    lines
        .map(|l| {
            head.iter()
                .zip(l.split(','))
                .filter_map(|(h, v)| v.parse::<f64>().ok().map(|v| (h.clone(), v)))
                .collect()
        })
        .collect()
}

fn json(p: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
}

fn ok(o: &std::process::Output) {
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

/// `trainer solve --config cfg` at `states`; returns its rows.
fn solve(dir: &Path, tag: &str, cfg: &Path, states: &Path) -> Vec<HashMap<String, f64>> {
    let out = dir.join(format!("solved_{tag}.csv"));
    ok(&trainer(&[
        "solve",
        "--config",
        cfg.to_str().unwrap(),
        "--states",
        states.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]));
    rows(&out)
}

/// The problem's constraints written out directly (k ≥ 1 for the mixed one, as placed by
/// the OCP): the largest violation of step k → k+1.
fn violation(k: usize, x: [f64; 2], u: f64, next: [f64; 2]) -> f64 {
    let (p, v) = (next[0], next[1]);
    let mut worst = (p - 2.0).max(-2.0 - p).max(0.0);
    worst = worst.max(p + 0.5 * v - 1.0);
    if k >= 1 {
        worst = worst.max(x[1] * x[1] + u * u / 4.0 - 2.0);
    }
    worst.max(0.0)
}

#[test]
fn run_with_setpoint_path_constraints_and_terminal_region() {
    let dir = tempdir();
    let d = dir.path();
    let shipped = std::fs::read_to_string(config("stiff_spring_setpoint.toml")).unwrap();
    let text = shipped
        .replace("counts = [31, 31]", "counts = [9, 9]")
        .replace(
            "hidden = [16, 16]",
            "hidden = [8, 8]\nepochs = 150\nbatch_size = 16\nvalidation_n = 40\nlog_every = 50",
        )
        .replace(
            "steps = 80",
            "steps = 80\nrandom_initial_states = 4\nnoise_runs = 1\nseeds = 1",
        )
        + "\n[plots]\nerror_map_grid = [12, 8]\npng_scale = 1.0\n";
    assert_ne!(text, shipped);
    let cfg = d.join("spring.toml");
    std::fs::write(&cfg, &text).unwrap();
    let runs = d.join("runs");
    ok(&trainer(&[
        "run",
        cfg.to_str().unwrap(),
        "--out",
        runs.to_str().unwrap(),
        "--quiet",
    ]));
    let run = runs.join("stiff_spring_setpoint");
    for f in ["certificate.json", "weights.rs", "weights.bin", "report.md"] {
        assert!(run.join(f).exists(), "{f} missing");
    }
    let eps = json(&run.join("certificate.json"))["eps"].as_f64().unwrap();
    assert!(eps.is_finite() && eps > 0.0, "ε = {eps}");

    // 1. The labels carry the constraints.
    let data = rows(&run.join("dataset.csv"));
    assert_eq!(data.len(), 81);
    let states = d.join("states.csv");
    let mut csv = String::from("x1,x2\n");
    for r in &data {
        csv += &format!("{:?},{:?}\n", r["x1"], r["x2"]);
    }
    std::fs::write(&states, csv).unwrap();
    let full = solve(d, "full", &cfg, &states);
    for (a, b) in data.iter().zip(&full) {
        assert!(
            (a["u1"] - b["u1"]).abs() <= 1e-7,
            "dataset u at ({}, {}) = {} vs solve {}",
            a["x1"],
            a["x2"],
            a["u1"],
            b["u1"]
        );
    }
    // On a finer grid of X (17 × 17), the constraints must matter at some states.
    let grid = d.join("grid.csv");
    let mut csv = String::from("x1,x2\n");
    for i in 0..17 {
        for j in 0..17 {
            let (a, b) = (-1.0 + f64::from(i) / 8.0, -1.0 + f64::from(j) / 8.0);
            csv += &format!("{a:?},{b:?}\n");
        }
    }
    std::fs::write(&grid, csv).unwrap();
    let fine = solve(d, "fine", &cfg, &grid);
    let moved = |tag: &str, from: &str, to: &str| {
        assert!(text.contains(from));
        let p = d.join(format!("{tag}.toml"));
        std::fs::write(&p, text.replace(from, to)).unwrap();
        let other = solve(d, tag, &p, &grid);
        fine.iter()
            .zip(&other)
            .filter(|(a, b)| (a["u1"] - b["u1"]).abs() > 1e-4)
            .count()
    };
    let path = moved(
        "no_path",
        "constraints = [\"pos + 0.5*vel <= 1.0\", \"vel^2 + force^2/4 <= 2.0\"]",
        "",
    );
    let terminal = moved(
        "no_terminal",
        "terminal_constraints = [\"(pos - 0.5)^2 + 0.5*vel^2 <= 0.02\"]",
        "",
    );
    assert!(
        path >= 3,
        "path constraints change only {path} of 81 labels"
    );
    assert!(
        terminal >= 3,
        "terminal region changes only {terminal} of 289 labels"
    );

    // 2. The setpoint: κ(x_ref) = u_ref = k·p + 0.5·p³ (k = 2, p = 0.5), held by the nets.
    let u_ref = 2.0 * 0.5 + 0.5 * 0.5f64.powi(3);
    let xref = d.join("xref.csv");
    std::fs::write(&xref, "x1,x2\n0.5,0\n").unwrap();
    let kappa = solve(d, "xref", &cfg, &xref)[0]["u1"];
    assert!(
        (kappa - u_ref).abs() <= 1e-8,
        "κ(x_ref) = {kappa} vs {u_ref}"
    );
    for name in ["nominal", "regularized"] {
        let out = d.join(format!("eval_{name}.csv"));
        ok(&trainer(&[
            "eval",
            "--raw",
            "--model",
            run.join(format!("model_{name}.bin")).to_str().unwrap(),
            "--states",
            xref.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]));
        let u = rows(&out)[0]["u1"];
        assert!(
            (u - kappa).abs() <= 1e-9,
            "{name}: κ_NN(x_ref) = {u} vs κ(x_ref) = {kappa}"
        );
    }

    // 3. Closed loop: the reported violations against the constraints written out here.
    let cl = json(&run.join("closed_loop.json"));
    let mut checked = 0;
    for (ctrl, list) in cl.as_object().unwrap() {
        for r in list.as_array().unwrap() {
            let x: Vec<[f64; 2]> = serde_json::from_value(r["x"].clone()).unwrap();
            let u: Vec<[f64; 1]> = serde_json::from_value(r["u"].clone()).unwrap();
            assert_eq!(x.len(), u.len() + 1, "{ctrl}");
            let worst = (0..u.len())
                .map(|k| violation(k, x[k], u[k][0], x[k + 1]))
                .fold(0.0f64, f64::max);
            let reported = r["max_violation"].as_f64().unwrap();
            assert!(
                (worst - reported).abs() <= 1e-12 * (1.0 + worst),
                "{ctrl} from {:?}: reported max violation {reported}, recomputed {worst}",
                r["x0"]
            );
            if ctrl == "mpc" {
                // The MPC keeps its state constraints on every step it takes.
                let state_worst = (0..u.len())
                    .map(|k| {
                        let (p, v) = (x[k + 1][0], x[k + 1][1]);
                        (p + 0.5 * v - 1.0).max(p.abs() - 2.0)
                    })
                    .fold(f64::NEG_INFINITY, f64::max);
                assert!(state_worst <= 1e-7, "mpc from {:?}: {state_worst}", r["x0"]);
            }
            checked += 1;
        }
    }
    assert!(checked >= 10, "{checked} closed-loop runs");
    for name in ["mpc", "nominal", "regularized"] {
        let first = &cl[name][0];
        let off: Vec<f64> = serde_json::from_value(first["final_offset"].clone()).unwrap();
        let last: [f64; 2] =
            serde_json::from_value(first["x"].as_array().unwrap().last().unwrap().clone()).unwrap();
        assert!(
            ((last[0] - 0.5).abs() - off[0]).abs() <= 1e-15
                && (last[1].abs() - off[1]).abs() <= 1e-15,
            "{name}: final_offset {off:?} is not |x_N − x_ref| of {last:?}"
        );
        eprintln!("{name}: final offset {off:?}");
        assert!(
            off.iter().all(|o| *o <= 1e-3),
            "{name} ends {off:?} away from x_ref"
        );
    }
}
