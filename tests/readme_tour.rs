//! The README's main job and its tour, as a user types them: `trainer run` on the embedded
//! pendulum (all stages, report.md + report.html + figures), a second run that skips
//! everything, then `certify`, `solve`, `eval`, `compare` (2 seeds instead of 10) and
//! `export` on the run directory, and the weights `run` wrote equal the ones compiled into
//! `controller-core` (the README's regeneration command is a copy).
//!
//! "Your own plant in five minutes": the problem file and the `trainer` commands are read
//! from the README's text (so the README and this test cannot drift), the file must be
//! `configs/arm.toml`, and every command runs as written in a fresh directory; the figures
//! the README quotes from their output are the ones the commands print.

use ampc_tests::{tempdir, trainer, trainer_bin};
use std::path::Path;

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
    // The committed weights are Theorem 1's regularized net; the stage exports the strongest
    // band reached (export_report.json `source`), the same files only when that is Theorem 1
    // of the regularized net.
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("export_report.json")).unwrap())
            .unwrap();
    let same_as_cli = report["source"] == "theorem1" && report["net"] == "regularized";
    for (mine, stage, committed) in [
        (&rs, "weights.rs", "weights.rs"),
        (&bin, "weights.bin", "weights.bin"),
    ] {
        let a = std::fs::read(mine).unwrap();
        if same_as_cli {
            assert_eq!(a, std::fs::read(run.join(stage)).unwrap(), "{stage}");
        }
        assert_eq!(
            a,
            std::fs::read(format!("{gen}/{committed}")).unwrap(),
            "{committed}"
        );
    }
    if !same_as_cli {
        // The stage's weights are the network the report names, with the tier it names.
        let model = report["model"].as_str().unwrap();
        let x = d.join("x.rs");
        let o = trainer(&[
            "export",
            "--model",
            &p(model),
            "--certificate",
            &p(&model
                .replace("model_regularized.bin", "certificate.json")
                .replace("model_nominal.bin", "certificate_nominal.json")
                .replace("model.bin", "certificate.json")),
            "--rust",
            &s(&x),
            "--postcard",
            &s(&d.join("x.bin")),
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let hash = |t: &str| {
            t.lines()
                .skip_while(|l| !l.contains("Model hash"))
                .nth(1)
                .map(str::to_string)
                .unwrap()
        };
        let stage = std::fs::read_to_string(run.join("weights.rs")).unwrap();
        assert_eq!(
            hash(&stage),
            hash(&std::fs::read_to_string(&x).unwrap()),
            "{report}"
        );
        let tier = report["tier"].as_str().unwrap();
        assert!(
            stage.contains(&format!("Guarantee tier of ε: {tier}.")),
            "{report}"
        );
    }
}

/// The README's section whose heading starts with `heading`, up to the next `## `.
fn readme_section(heading: &str) -> String {
    let readme = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../README.md"))
        .expect("README.md");
    let start = readme
        .find(heading)
        .unwrap_or_else(|| panic!("README.md has no section {heading}"));
    let rest = &readme[start + heading.len()..];
    let end = rest.find("\n## ").unwrap_or(rest.len());
    rest[..end].to_string()
}

/// The fenced blocks of `text` whose info string is `lang`, in order.
fn blocks(text: &str, lang: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut cur: Option<String> = None;
    for line in text.lines() {
        let fence = line.trim_start().strip_prefix("```");
        match (cur.take(), fence) {
            // A block of another language is kept as a marked block and dropped at its end.
            (None, Some(info)) if info.trim() == lang => cur = Some(String::new()),
            (None, Some(_)) => cur = Some("\u{0}".into()),
            (Some(b), Some(_)) => {
                if !b.starts_with('\u{0}') {
                    out.push(b);
                }
            }
            (Some(mut b), None) => {
                b.push_str(line);
                b.push('\n');
                cur = Some(b);
            }
            (None, None) => {}
        }
    }
    out
}

/// Runs `trainer` with the arguments of one README line in `dir`.
fn run_in(dir: &Path, line: &str) -> std::process::Output {
    assert!(
        !line.contains(['"', '\'', '$', '|', '>', '<', '&', ';']),
        "README command needs a shell: {line}"
    );
    let args: Vec<&str> = line.split_whitespace().skip(1).collect();
    let o = std::process::Command::new(trainer_bin())
        .args(&args)
        .current_dir(dir)
        .output()
        .expect("run trainer");
    assert!(
        o.status.success(),
        "`{line}` failed:\n{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    o
}

/// The first number after `key` in `text`.
fn number_after(text: &str, key: &str) -> Option<f64> {
    let at = text.find(key)? + key.len();
    let t: String = text[at..]
        .chars()
        .skip_while(|c| !c.is_ascii_digit())
        .take_while(|c| c.is_ascii_digit() || *c == '.')
        .collect();
    t.parse().ok()
}

#[test]
fn own_plant_in_five_minutes_as_the_readme_says() {
    let section = readme_section("## Your own plant in five minutes");
    let toml = blocks(&section, "toml");
    assert_eq!(toml.len(), 1, "one problem file in the section");
    let shipped = std::fs::read_to_string(ampc_tests::config("arm.toml")).unwrap();
    assert_eq!(
        toml[0].trim_end(),
        shipped.trim_end(),
        "the README's problem file is configs/arm.toml"
    );
    // A setpoint away from the origin and a path constraint, as the section promises.
    let cfg = trainer::problem::ProblemConfig::from_toml_str(&toml[0], "README.md").unwrap();
    assert!(cfg
        .ocp
        .x_ref
        .as_ref()
        .is_some_and(|x| x.iter().any(|v| *v != 0.0)));
    assert!(!cfg.ocp.constraints.is_empty());

    let dir = tempdir();
    let d = dir.path();
    std::fs::create_dir_all(d.join("configs")).unwrap();
    std::fs::write(d.join("configs/arm.toml"), &toml[0]).unwrap();
    let commands: Vec<String> = blocks(&section, "sh")
        .iter()
        .flat_map(|b| b.lines().map(str::to_string).collect::<Vec<_>>())
        .filter(|l| l.starts_with("trainer "))
        .collect();
    let names: Vec<&str> = commands
        .iter()
        .map(|c| c.split_whitespace().nth(1).unwrap())
        .collect();
    assert_eq!(names, ["run", "refine", "export"], "{commands:?}");
    let text: Vec<String> = commands
        .iter()
        .map(|c| {
            let o = run_in(d, c);
            format!(
                "{}{}",
                String::from_utf8_lossy(&o.stdout),
                String::from_utf8_lossy(&o.stderr)
            )
        })
        .collect();

    // run: every stage, and the report opens with the verdict the README quotes.
    let report = std::fs::read_to_string(d.join("runs/arm/report.md")).unwrap();
    assert!(report.contains("## Verdict"), "{report}");
    let quoted = |k: &str| number_after(&section, k).unwrap_or_else(|| panic!("README: {k}"));
    // The verdict states the exported net's certificate (`export_report.json`'s `net`).
    let export: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(d.join("runs/arm/export_report.json")).unwrap(),
    )
    .unwrap();
    let cert_file = match export["net"].as_str() {
        Some("nominal") => "runs/arm/certificate_nominal.json",
        _ => "runs/arm/certificate.json",
    };
    let cert: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join(cert_file)).unwrap()).unwrap();
    let eps = cert["eps"].as_f64().unwrap();
    assert!(
        (eps - quoted("**ε = ")).abs() <= 5e-3 * eps.abs().max(1.0),
        "run: ε {eps} vs the README's {}",
        quoted("**ε = ")
    );
    // refine: the certified ε and the solves the README quotes, target met, check passed.
    let refine = &text[1];
    assert!(refine.contains(", met)"), "{refine}");
    assert!(refine.contains("passed"), "{refine}");
    let summary = |t: &str| -> String {
        t.lines()
            .find(|l| l.contains("arm: certified ε "))
            .unwrap_or_else(|| panic!("no refine summary line in {t}"))
            .to_string()
    };
    let (printed, said) = (summary(refine), summary(&section));
    for k in ["certified ε ", ") with "] {
        let (got, want) = (
            number_after(&printed, k).unwrap(),
            number_after(&said, k).unwrap(),
        );
        assert!(
            (got - want).abs() <= 1e-4 * want.abs().max(1.0),
            "refine `{k}`: {got} printed, the README says {want}"
        );
    }
    // export: the four files.
    for f in ["weights.rs", "weights.bin", "ampc.h", "arm.onnx"] {
        assert!(d.join(f).exists(), "export wrote no {f}");
    }
}
