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
        "[L_MPC is an estimate]",
    ] {
        assert!(text.contains(k), "{k}: {text}");
    }
    let cert: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("certificate.json")).unwrap())
            .unwrap();
    assert!(text.contains(&format!("{:.6}", cert["eps"].as_f64().unwrap())));

    // solve and eval on the same states.
    let states = d.join("in.csv");
    std::fs::write(&states, "x1,x2\n-3.141592653589793,0\n0.5,-0.2\n").unwrap();
    let (labels, outs) = (d.join("labels.csv"), d.join("outs.csv"));
    let s = |p: &std::path::Path| p.to_str().unwrap().to_string();
    let o = trainer(&["solve", "--states", &s(&states), "--out", &s(&labels)]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = trainer(&[
        "eval",
        "--model",
        &p("model_regularized.bin"),
        "--states",
        &s(&states),
        "--out",
        &s(&outs),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // |κ − κ_NN| at these states is within the certified ε.
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
    for (a, b) in col(&labels, "u1").iter().zip(col(&outs, "u1")) {
        assert!((a - b).abs() <= cert["eps"].as_f64().unwrap());
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
    let gen = format!(
        "{}/../controller-core/src/generated",
        env!("CARGO_MANIFEST_DIR")
    );
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
