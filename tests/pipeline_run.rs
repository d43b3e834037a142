//! `trainer run` end to end on a small double-integrator problem: every stage's artifact
//! and manifest exists, the report (Markdown and HTML), the figures (PNG decodes at the
//! SVG's size × the scale, SVG parses, both have content) and the JSON files hold the
//! contract's keys, a second run skips every stage, and `--force` redoes one.

use ampc_tests::{config, tempdir, trainer};

#[test]
fn run_writes_artifacts_and_skips_unchanged_stages() {
    let dir = tempdir();
    let d = dir.path();
    let text = std::fs::read_to_string(config("double_integrator.toml"))
        .unwrap()
        .replace("counts = [21, 11]", "counts = [9, 5]")
        + "\n[training]\nepochs = 100\nbatch_size = 9\nvalidation_n = 40\nlog_every = 50\n"
        + "\n[closed_loop]\nsteps = 40\nrandom_initial_states = 3\nnoise_runs = 1\nseeds = 2\n"
        + "\n[plots]\nerror_map_grid = [12, 8]\npng_scale = 1.0\n";
    let cfg = d.join("di.toml");
    std::fs::write(&cfg, text).unwrap();
    let out = d.join("runs");
    let args = ["run", cfg.to_str().unwrap(), "--out", out.to_str().unwrap()];
    let o = trainer(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // The seed study ran beside the stages after train and was handed to `seeds`.
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.lines()
            .any(|l| l.contains("[      seeds] done") && l.contains("computed beside")),
        "{err}"
    );
    let run = out.join("double_integrator");
    for f in [
        "problem.toml",
        "dataset.bin",
        "dataset.csv",
        "validation.bin",
        "model_nominal.bin",
        "model_regularized.bin",
        "certificate.json",
        "certificate_nominal.json",
        "closed_loop.json",
        "seeds.json",
        "plots/figures.json",
        "report.md",
        "report.html",
    ] {
        assert!(run.join(f).exists(), "missing {f}");
    }
    for st in trainer::pipeline::STAGES {
        let m: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(run.join(format!("manifest_{st}.json"))).unwrap(),
        )
        .unwrap();
        assert_eq!(m["stage"], st);
        assert!(m["inputs"].as_object().is_some_and(|o| !o.is_empty()));
    }
    let cl: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("closed_loop.json")).unwrap())
            .unwrap();
    for k in ["mpc", "nominal", "regularized"] {
        let runs = cl[k].as_array().expect("a list of runs");
        // The reference state and the 3 random initial states.
        assert_eq!(runs.len(), 4, "{k}");
        let r = &runs[0];
        for f in [
            "x0",
            "steps",
            "violation_steps",
            "max_violation",
            "max_input_divergence",
            "cost",
            "final_offset",
        ] {
            assert!(r.get(f).is_some(), "{k} run lacks {f}");
        }
    }
    assert_eq!(cl["nominal"][0]["steps"], 40);
    let seeds: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("seeds.json")).unwrap()).unwrap();
    assert_eq!(seeds.as_array().map(Vec::len), Some(2));
    assert_eq!(seeds[1][0]["kind"], "nominal");
    assert_eq!(seeds[1][1]["kind"], "regularized");
    // Seed 0 is the run's own nets: the same trajectory as closed_loop.json's.
    assert_eq!(seeds[0][1]["run"]["x"], cl["regularized"][0]["x"]);
    // Figures: the PNG is the SVG rasterised at png_scale = 1, the SVG parses (rendered
    // again here), both have text, lines and more than a blank page.
    let index: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("plots/figures.json")).unwrap())
            .unwrap();
    assert_eq!(
        index.as_array().map(Vec::len),
        Some(trainer::study::plots::PLOTS.len())
    );
    for stem in trainer::study::plots::PLOTS {
        let svg = std::fs::read_to_string(run.join(format!("plots/{stem}.svg"))).unwrap();
        let (w, h) = svg_size(&svg);
        assert!(svg.matches("<text").count() >= 5, "{stem}: too little text");
        assert!(
            svg.matches("<polyline").count() + svg.matches("<rect").count() >= 5,
            "{stem}: nothing drawn"
        );
        let again = trainer::study::plots::to_png(stem, &svg, 1.0).expect("SVG parses");
        let png_bytes = std::fs::read(run.join(format!("plots/{stem}.png"))).unwrap();
        assert_eq!(again, png_bytes, "{stem}: PNG is not the SVG's rendering");
        let dec = png::Decoder::new(std::io::Cursor::new(png_bytes));
        let mut reader = dec.read_info().expect("PNG header");
        let mut buf = vec![0; reader.output_buffer_size()];
        let info = reader.next_frame(&mut buf).expect("PNG data");
        assert_eq!((info.width, info.height), (w, h), "{stem}");
        // Not a blank page: many distinct colours.
        let px = info.color_type.samples();
        let distinct: std::collections::BTreeSet<&[u8]> =
            buf[..info.buffer_size()].chunks(px).collect();
        assert!(distinct.len() > 20, "{stem}: {} colours", distinct.len());
    }
    let report = std::fs::read_to_string(run.join("report.md")).unwrap();
    for s in [
        "Table I",
        "Table II",
        "Certificate",
        "Over 2 training seeds",
        "Stage timings",
        "Reproduce",
        "plots/trajectories.png",
        "plots/error_map.svg",
        "an estimate",
    ] {
        assert!(report.contains(s), "report.md lacks {s}");
    }
    // The first section is the verdict: the certificate's tier, ε judged against the
    // largest distance between two inputs of U, and the band the export clamps to (= U).
    let first = report.split("\n## ").nth(1).expect("a section");
    assert!(first.starts_with("Verdict"), "{first}");
    let read = |f: &str| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(run.join(f)).unwrap()).unwrap()
    };
    let (cert, export) = (read("certificate.json"), read("export_report.json"));
    let tier = cert["guarantee"].as_str().unwrap();
    assert!(first.contains(&format!(", {tier}**")), "{first}");
    let v = |j: &serde_json::Value, k: &str| -> Vec<f64> {
        j[k].as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect()
    };
    let (u_lo, u_hi) = (v(&cert, "u_lo"), v(&cert, "u_hi"));
    let d_u = u_lo
        .iter()
        .zip(&u_hi)
        .map(|(l, h)| (h - l).powi(2))
        .sum::<f64>()
        .sqrt();
    let eps = cert["eps"].as_f64().unwrap();
    match eps / d_u {
        r if r >= 1.0 => assert!(first.contains("bound is vacuous"), "{first}"),
        r if r >= 0.2 => assert!(first.contains("the bound is weak"), "{first}"),
        _ => assert!(!first.contains("the bound is"), "{first}"),
    }
    // (U rounded inward to f32.)
    for (j, (bl, bh)) in v(&export, "clamp_lo")
        .iter()
        .zip(v(&export, "clamp_hi"))
        .enumerate()
    {
        let tol = |u: f64| 1e-7 * u.abs().max(1.0);
        assert!(
            *bl >= u_lo[j] && bl - u_lo[j] <= tol(u_lo[j]),
            "clamp_lo {bl} vs {u_lo:?}"
        );
        assert!(
            bh <= u_hi[j] && u_hi[j] - bh <= tol(u_hi[j]),
            "clamp_hi {bh} vs {u_hi:?}"
        );
    }
    let html = std::fs::read_to_string(run.join("report.html")).unwrap();
    assert!(html.starts_with("<!DOCTYPE html>") && html.trim_end().ends_with("</html>"));
    // Self-contained: every figure inline, every Markdown table an HTML table.
    assert_eq!(
        html.matches("<svg").count(),
        trainer::study::plots::PLOTS.len()
    );
    assert_eq!(
        html.matches("<table>").count(),
        report.matches("\n|---|").count(),
        "tables"
    );
    assert!(html.contains("<th>validation R²</th>") && !html.contains("|---|"));
    for st in trainer::pipeline::STAGES {
        if st != "report" {
            assert!(
                html.contains(&format!("<td>{st}</td>")),
                "no timing of {st}"
            );
        }
    }
    // Unchanged inputs: every stage is skipped.
    let o = trainer(&args);
    assert!(o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(
        err.matches("] skipped").count(),
        trainer::pipeline::STAGES.len(),
        "{err}"
    );
    // --force train retrains; training is deterministic, so the later stages see the same
    // model bytes and stay skipped.
    let mut forced = args.to_vec();
    forced.extend(["--force", "train"]);
    let o = trainer(&forced);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success());
    assert!(err.contains("[      train] done"), "{err}");
    assert_eq!(
        err.matches("] skipped").count(),
        trainer::pipeline::STAGES.len() - 1,
        "{err}"
    );
    // -v lists inputs and outputs; -q prints nothing.
    let mut verbose = args.to_vec();
    verbose.push("-v");
    let o = trainer(&verbose);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        o.status.success() && err.contains("output report.html"),
        "{err}"
    );
    let mut quiet = args.to_vec();
    quiet.push("--quiet");
    let o = trainer(&quiet);
    assert!(o.status.success() && o.stderr.is_empty());
    // A deliverable overwritten after the run is not trusted: its stage is redone, saying
    // which file, and the deliverable is rebuilt (never every stage skipped with exit 0).
    let weights = std::fs::read(run.join("weights.bin")).unwrap();
    std::fs::write(run.join("weights.bin"), "garbage").unwrap();
    let o = trainer(&args);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains("weights.bin differs from what this stage wrote: redone"),
        "{err}"
    );
    assert_eq!(std::fs::read(run.join("weights.bin")).unwrap(), weights);
    // A corrupted dataset is not reused either: labelled again, the same bytes.
    let data = std::fs::read(run.join("dataset.bin")).unwrap();
    let mut bad = data.clone();
    bad[data.len() / 2] ^= 1;
    std::fs::write(run.join("dataset.bin"), bad).unwrap();
    let o = trainer(&args);
    assert!(o.status.success());
    assert_eq!(std::fs::read(run.join("dataset.bin")).unwrap(), data);
    // Another problem under the same name does not silently replace the run.
    let text = std::fs::read_to_string(&cfg).unwrap();
    std::fs::write(&cfg, text.replacen("horizon = ", "horizon = 1", 1)).unwrap();
    let o = trainer(&args);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("holds a run of another problem"), "{err}");
    std::fs::write(&cfg, text).unwrap();
    // A usage error exits 2; a broken problem file exits 1 naming the key.
    assert_eq!(
        trainer(&["run", "--force", "nonsense"]).status.code(),
        Some(2)
    );
    std::fs::write(&cfg, "name = \"x\"\n").unwrap();
    let o = trainer(&args);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("di.toml"));
}

/// Width and height attributes of an SVG document.
fn svg_size(svg: &str) -> (u32, u32) {
    let attr = |name: &str| -> u32 {
        let key = format!("{name}=\"");
        let i = svg.find(&key).expect("size attribute") + key.len();
        svg[i..].split('"').next().unwrap().parse().unwrap()
    };
    (attr("width"), attr("height"))
}
