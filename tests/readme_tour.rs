//! The README's main job and its tour, as a user types them: `trainer run` on the embedded
//! pendulum (all stages, report.md + report.html + figures), a second run that skips
//! everything, then `certify`, `solve`, `eval`, `compare` (2 seeds instead of 10) and
//! `export` on the run directory, and the weights `run` wrote equal the ones compiled into
//! `controller-core` (the README's regeneration command is a copy).

use ampc_tests::{tempdir, trainer};

#[test]
fn main_job_and_tour() {
    let dir = tempdir();
    let d = dir.path();
    let out = d.join("runs");
    let o = trainer(&["run", "--out", out.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    for st in trainer::pipeline::STAGES {
        assert!(err.contains(&format!("{st:>11}] done")), "{st}: {err}");
    }
    let run = out.join("pendulum");
    for f in [
        "report.md",
        "report.html",
        "plots/trajectories.png",
        "seeds.json",
    ] {
        assert!(run.join(f).exists(), "missing {f}");
    }
    let report = std::fs::read_to_string(run.join("report.md")).unwrap();
    assert!(
        report.contains("Over 10 training seeds"),
        "default closed_loop.seeds"
    );
    let o = trainer(&["run", "--out", out.to_str().unwrap()]);
    assert_eq!(
        String::from_utf8_lossy(&o.stderr)
            .matches("] skipped")
            .count(),
        trainer::pipeline::STAGES.len()
    );
    let p = |f: &str| run.join(f).to_str().unwrap().to_string();

    // Reading a certificate: the text form names every term.
    let o = trainer(&[
        "certify",
        "--model",
        &p("model_regularized.bin"),
        "--data",
        &p("dataset.bin"),
    ]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success());
    for k in [
        "eps_D",
        "L_NN",
        "LipSDP-Neuron",
        "sampled lower",
        "L_MPC",
        "covering radius",
        "[estimated: l_mpc",
    ] {
        assert!(text.contains(k), "{k}: {text}");
    }
    let cert: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("certificate.json")).unwrap())
            .unwrap();
    assert!(text.contains(&format!("{:.6}", cert["eps"].as_f64().unwrap())));

    // solve and eval on states of the dataset's grid: `solve` (cold starts) reproduces the
    // dataset's labels (warm-started chains), and the net's error there is at most the
    // certificate's ε_D — the maximum over exactly these points, so a wrong net, scaling or
    // ε_D fails (the bound ε ≈ 31 N·m against |u| ≤ 15 could not).
    let csv = std::fs::read_to_string(run.join("dataset.csv")).unwrap();
    let mut rows = csv.lines();
    let head: Vec<&str> = rows.next().unwrap().split(',').collect();
    let at = |name: &str| head.iter().position(|c| *c == name).unwrap();
    let (ix1, ix2, iu, ist) = (at("x1"), at("x2"), at("u1"), at("status"));
    let grid: Vec<(String, String, f64)> = rows
        .map(|r| r.split(',').collect::<Vec<_>>())
        .filter(|f| f[ist] == "converged")
        .step_by(7)
        .take(40)
        .map(|f| {
            (
                f[ix1].to_string(),
                f[ix2].to_string(),
                f[iu].parse().unwrap(),
            )
        })
        .collect();
    assert_eq!(grid.len(), 40);
    let states = d.join("in.csv");
    let mut text = "x1,x2\n".to_string();
    for (a, b, _) in &grid {
        text += &format!("{a},{b}\n");
    }
    std::fs::write(&states, text).unwrap();
    let (labels, outs) = (d.join("labels.csv"), d.join("outs.csv"));
    let s = |p: &std::path::Path| p.to_str().unwrap().to_string();
    let o = trainer(&["solve", "--states", &s(&states), "--out", &s(&labels)]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = trainer(&[
        "eval",
        "--raw",
        "--model",
        &p("model_regularized.bin"),
        "--states",
        &s(&states),
        "--out",
        &s(&outs),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let col = |f: &std::path::Path, name: &str| -> Vec<f64> {
        let t = std::fs::read_to_string(f).unwrap();
        let mut l = t.lines();
        let i = l
            .next()
            .unwrap()
            .split(',')
            .position(|c| c == name)
            .unwrap();
        l.map(|r| r.split(',').nth(i).unwrap().parse().unwrap())
            .collect()
    };
    let eps_d = cert["eps_d"].as_f64().unwrap();
    let (solved, net) = (col(&labels, "u1"), col(&outs, "u1"));
    for (k, (_, _, u_data)) in grid.iter().enumerate() {
        assert!(
            (solved[k] - u_data).abs() <= 1e-6 * (1.0 + u_data.abs()),
            "state {k}: solve {} vs dataset {u_data}",
            solved[k]
        );
        assert!(
            (u_data - net[k]).abs() <= eps_d * (1.0 + 1e-12),
            "state {k}: |κ − κ_NN| = {} > ε_D = {eps_d}",
            (u_data - net[k]).abs()
        );
    }

    let o = trainer(&["compare", "--data", &p("dataset.bin"), "--seeds", "2"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stdout).contains("median [min, max] over seeds 0..2"));

    let (rs, bin) = (d.join("w.rs"), d.join("w.bin"));
    let o = trainer(&[
        "export",
        "--model",
        &p("model_regularized.bin"),
        "--certificate",
        &p("certificate.json"),
        "--rust",
        &s(&rs),
        "--postcard",
        &s(&bin),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // The stage's export and the command's are the same files, and they are the weights
    // compiled into controller-core.
    let gen = format!("{}/../controller-core/src/demo", env!("CARGO_MANIFEST_DIR"));
    for (mine, stage, committed) in [
        (&rs, "weights.rs", "weights.rs"),
        (&bin, "weights.bin", "weights.bin"),
    ] {
        let a = std::fs::read(mine).unwrap();
        assert_eq!(a, std::fs::read(run.join(stage)).unwrap(), "{stage}");
        assert_eq!(
            a,
            std::fs::read(format!("{gen}/{committed}")).unwrap(),
            "{committed}"
        );
    }
}
