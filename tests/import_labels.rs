//! `trainer import` end to end: ampc's own `dataset.csv` imported back (identical labels),
//! trained and certified with the imported provenance in the certificate; a pandas-style
//! CSV with one label off by 1e-3 refused (file and line named) unless `--trust-labels`,
//! which the certificate then records; a CSV outside X refused; `refine --data` labels its
//! first round's corners from an imported dataset.

use ampc_tests::{config, tempdir, trainer};
use std::path::Path;

fn ok(o: &std::process::Output) {
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

/// A small double-integrator problem file and its sampled dataset (+ CSV) in `d`.
fn setup(d: &Path) -> (String, String) {
    let text = std::fs::read_to_string(config("double_integrator.toml"))
        .unwrap()
        .replace("counts = [21, 11]", "counts = [9, 6]")
        + "\n[training]\nepochs = 100\nbatch_size = 9\nvalidation_n = 20\nlog_every = 50\n";
    let cfg = d.join("di.toml");
    std::fs::write(&cfg, text).unwrap();
    let data = d.join("di.bin");
    ok(&trainer(&[
        "sample",
        "--config",
        cfg.to_str().unwrap(),
        "--out",
        data.to_str().unwrap(),
        "--quiet",
    ]));
    (
        cfg.to_str().unwrap().to_string(),
        data.to_str().unwrap().to_string(),
    )
}

fn certify_json(cfg: &str, model: &str, data: &str) -> serde_json::Value {
    let o = trainer(&[
        "certify", "--config", cfg, "--model", model, "--data", data, "--json",
    ]);
    ok(&o);
    serde_json::from_slice(&o.stdout).unwrap()
}

#[test]
fn imported_ampc_csv_trains_and_certifies_with_its_provenance() {
    let dir = tempdir();
    let d = dir.path();
    let (cfg, data) = setup(d);
    let csv = d.join("di.csv");
    let imported = d.join("imported.bin");
    let o = trainer(&[
        "import",
        "--csv",
        csv.to_str().unwrap(),
        "--config",
        &cfg,
        "--out",
        imported.to_str().unwrap(),
    ]);
    ok(&o);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("54 rows") && err.contains("re-solved 54"),
        "{err}"
    );
    // Identical labels to the dataset the CSV was exported from.
    let a = trainer::data::dataset::Dataset::load(Path::new(&data)).unwrap();
    let b = trainer::data::dataset::Dataset::load(&imported).unwrap();
    assert_eq!(a.records.len(), b.records.len());
    for (r, s) in a.records.iter().zip(&b.records) {
        assert_eq!((&r.x, &r.u, &r.du_dx), (&s.x, &s.u, &s.du_dx));
    }
    let im = imported.to_str().unwrap();
    let model = d.join("m.bin");
    let m = model.to_str().unwrap();
    ok(&trainer(&[
        "train", "--config", &cfg, "--data", im, "--out", m, "--quiet",
    ]));
    let v = certify_json(&cfg, m, im);
    let l = &v["labels"];
    assert_eq!(l["source"], "imported", "{v}");
    assert_eq!(l["file"], csv.to_str().unwrap());
    let sha = trainer::io::sha256_hex(&std::fs::read(&csv).unwrap());
    assert_eq!(l["sha256"], sha.as_str());
    assert_eq!(l["resolved"], 54);
    assert!(l["max_disagreement"].as_f64().unwrap() <= 1e-6, "{l}");
    assert!(v["eps"].as_f64().unwrap().is_finite());
    assert!(
        v["covering_method"]
            .as_str()
            .unwrap()
            .contains("branch and bound"),
        "imported points are scattered points: {v}"
    );
    // ampc's own dataset: no labels record in its certificate.
    let own = d.join("own.bin");
    ok(&trainer(&[
        "train",
        "--config",
        &cfg,
        "--data",
        &data,
        "--out",
        own.to_str().unwrap(),
        "--quiet",
    ]));
    let v = certify_json(&cfg, own.to_str().unwrap(), &data);
    assert!(v.get("labels").is_none(), "{v}");
}

#[test]
fn a_perturbed_pandas_label_is_refused_unless_trusted() {
    let dir = tempdir();
    let d = dir.path();
    let (cfg, data) = setup(d);
    let ds = trainer::data::dataset::Dataset::load(Path::new(&data)).unwrap();
    // pandas' df.to_csv(): unnamed index column, named columns, no Jacobian.
    let mut s = String::from(",x1,x2,u1\n");
    for (i, r) in ds.records.iter().enumerate() {
        // Moved toward the interior of U = [−1, 1], so the label is admissible and only its
        // disagreement with ampc's re-solve is at fault.
        let u = r.u[0]
            + if i == 20 {
                -1e-3 * r.u[0].signum()
            } else {
                0.0
            };
        s += &format!("{i},{:?},{:?},{:?}\n", r.x[0], r.x[1], u);
    }
    let csv = d.join("pandas.csv");
    std::fs::write(&csv, s).unwrap();
    let c = csv.to_str().unwrap();
    let o = trainer(&["import", "--csv", c, "--config", &cfg]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("pandas.csv:22") && err.contains("--trust-labels"),
        "{err}"
    );
    assert!(
        !d.join("pandas.imported.bin").exists(),
        "nothing written on refusal"
    );
    ok(&trainer(&[
        "import",
        "--csv",
        c,
        "--config",
        &cfg,
        "--trust-labels",
        "--quiet",
    ]));
    let im = d.join("pandas.imported.bin");
    let model = d.join("m.bin");
    let o = trainer(&[
        "train",
        "--config",
        &cfg,
        "--data",
        im.to_str().unwrap(),
        "--out",
        model.to_str().unwrap(),
    ]);
    ok(&o);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("λ₂ = 0"),
        "the dropped Jacobian term is stated: {err}"
    );
    let v = certify_json(&cfg, model.to_str().unwrap(), im.to_str().unwrap());
    let l = &v["labels"];
    assert_eq!(l["beyond_tolerance"], 1, "{l}");
    assert_eq!(l["trusted"], true);
    assert_eq!(l["jacobian"], false);
    assert!(
        (l["max_disagreement"].as_f64().unwrap() - 1e-3).abs() < 1e-6,
        "{l}"
    );
    // A state outside X: an error naming the file, line and column.
    std::fs::write(&csv, ",x1,x2,u1\n0,0.0,0.0,0.0\n1,1e6,0.0,0.0\n").unwrap();
    let o = trainer(&[
        "import",
        "--csv",
        c,
        "--config",
        &cfg,
        "--out",
        "/dev/null/x",
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("pandas.csv:3") && err.contains("`x1`"),
        "{err}"
    );
}

#[test]
fn refine_takes_its_first_round_labels_from_an_imported_dataset() {
    let dir = tempdir();
    let d = dir.path();
    // The sampling grid is refine's initial grid (9 × 9 for two states).
    let text = std::fs::read_to_string(config("double_integrator.toml"))
        .unwrap()
        .replace("counts = [21, 11]", "counts = [9, 9]");
    let cfg = d.join("di.toml");
    std::fs::write(&cfg, text).unwrap();
    let cfg = cfg.to_str().unwrap();
    let data = d.join("di.bin");
    ok(&trainer(&[
        "sample",
        "--config",
        cfg,
        "--out",
        data.to_str().unwrap(),
        "--quiet",
    ]));
    let csv = d.join("di.csv");
    ok(&trainer(&[
        "import",
        "--csv",
        csv.to_str().unwrap(),
        "--config",
        cfg,
        "--quiet",
    ]));
    let o = trainer(&[
        "refine",
        "--config",
        cfg,
        "--data",
        d.join("di.imported.bin").to_str().unwrap(),
        "--out",
        d.join("r").to_str().unwrap(),
        "--budget",
        "120",
        "--target-eps",
        "100",
    ]);
    ok(&o);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("first round: 81 of the 81 initial grid corners"),
        "{err}"
    );
    // Without Jacobian columns the local certificate cannot use the labels: refused.
    let ds = trainer::data::dataset::Dataset::load(&data).unwrap();
    let mut s = String::from("x1,x2,u1\n");
    for r in &ds.records {
        s += &format!("{:?},{:?},{:?}\n", r.x[0], r.x[1], r.u[0]);
    }
    let nojac = d.join("nojac.csv");
    std::fs::write(&nojac, s).unwrap();
    ok(&trainer(&[
        "import",
        "--csv",
        nojac.to_str().unwrap(),
        "--config",
        cfg,
        "--quiet",
    ]));
    let o = trainer(&[
        "refine",
        "--config",
        cfg,
        "--data",
        d.join("nojac.imported.bin").to_str().unwrap(),
        "--out",
        d.join("r2").to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("without Jacobian columns"));
}
