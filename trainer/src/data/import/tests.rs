//! Import: the CSV round trip of an ampc dataset, pandas' layout, the column and row checks,
//! the seeded sample, and the re-solve check catching a label off by 1e-3.

use super::*;
use crate::data::dataset::{csv_path, generate, GenerateOptions};
use std::path::PathBuf;

fn small_cfg() -> ProblemConfig {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../configs/double_integrator.toml"
    );
    let mut cfg = ProblemConfig::load(Path::new(path)).unwrap();
    cfg.sampling.counts = vec![6, 5];
    cfg
}

fn dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("ampc-import-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The generated dataset of `small_cfg` and its CSV text.
fn generated(name: &str) -> (ProblemConfig, Dataset, String, PathBuf) {
    let cfg = small_cfg();
    let d = dir(name);
    let out = d.join("d.bin");
    let data = generate(&cfg, &out, &GenerateOptions::default()).unwrap();
    let text = std::fs::read_to_string(csv_path(&out)).unwrap();
    (cfg, data, text, d)
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn ampc_csv_imports_back_to_identical_labels_and_the_file_round_trips() {
    let (cfg, data, text, d) = generated("rt");
    let csv = write(&d, "labels.csv", &text);
    let opts = ImportOptions {
        resolve: 10,
        ..Default::default()
    };
    let imp = import(&cfg, &csv, &opts).unwrap();
    assert_eq!(imp.records.len(), data.records.len());
    for (a, b) in imp.records.iter().zip(&data.records) {
        assert_eq!(a.x, b.x);
        assert_eq!(a.u, b.u);
        assert_eq!(a.du_dx, b.du_dx);
        assert_eq!(a.status, b.status);
        assert_eq!(a.degeneracy.is_some(), b.degeneracy.is_some());
    }
    let l = imp.labels.clone().unwrap();
    assert_eq!((l.rows, l.resolved, l.jacobian), (30, 10, true));
    assert_eq!(l.sha256, crate::io::sha256_hex(text.as_bytes()));
    assert!(l.max_disagreement <= RESOLVE_RTOL, "{}", l.max_disagreement);
    assert_eq!(imp.header.sampling.sampler, SamplerKind::Imported);
    // The stored file (version 3) reads back with its provenance.
    let bin = d.join("imported.bin");
    imp.save(&bin).unwrap();
    let back = Dataset::load(&bin).unwrap();
    assert_eq!(back, imp);
    assert_eq!(back.version, IMPORTED_FORMAT_VERSION);
    assert_eq!(back.to_bytes(), std::fs::read(&bin).unwrap());
    // A flipped byte in the labels record is caught by the checksum.
    let mut bytes = std::fs::read(&bin).unwrap();
    let n = bytes.len();
    bytes[n - 40] ^= 1;
    assert!(Dataset::from_bytes(&bytes, "x").is_err());
    // ampc's own datasets stay version 2 without the record.
    assert_eq!(data.version, crate::data::dataset::FORMAT_VERSION);
    assert!(Dataset::from_bytes(&data.to_bytes(), "d")
        .unwrap()
        .labels
        .is_none());
    let _ = std::fs::remove_dir_all(&d);
}

/// pandas' `df.to_csv()`: an unnamed index column, named columns, NaN as empty fields,
/// the problem's state names accepted for x, no Jacobian and no status columns.
#[test]
fn pandas_default_csv_imports() {
    let (cfg, data, _, d) = generated("pandas");
    let mut s = String::from(",position,velocity,u1\n");
    for (i, r) in data.records.iter().enumerate() {
        s += &format!("{},{:?},{:?},{:?}\n", i * 7, r.x[0], r.x[1], r.u[0]);
    }
    let csv = write(&d, "pandas.csv", &s);
    let imp = import(&cfg, &csv, &ImportOptions::default()).unwrap();
    let l = imp.labels.unwrap();
    assert!(!l.jacobian);
    assert_eq!(
        l.resolved, 30,
        "all rows when fewer than the default sample"
    );
    for (a, b) in imp.records.iter().zip(&data.records) {
        assert_eq!((&a.x, &a.u), (&b.x, &b.u));
        assert!(a.du_dx.iter().all(|v| v.is_nan()));
    }
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn a_label_off_by_1e_3_is_detected_unless_trusted() {
    let (cfg, data, _, d) = generated("perturbed");
    let bad_row = 17;
    let mut s = String::from("x1,x2,u1\n");
    for (i, r) in data.records.iter().enumerate() {
        let u = r.u[0] + if i == bad_row { 1e-3 } else { 0.0 };
        s += &format!("{:?},{:?},{:?}\n", r.x[0], r.x[1], u);
    }
    let csv = write(&d, "bad.csv", &s);
    let e = import(&cfg, &csv, &ImportOptions::default()).unwrap_err();
    let msg = e.to_string();
    assert!(
        matches!(e, ImportError::Mismatch { line, .. } if line == bad_row + 2),
        "{msg}"
    );
    assert!(msg.contains("bad.csv:19") && msg.contains("u1"), "{msg}");
    assert!(
        msg.contains(&format!("{:?}", data.records[bad_row].x[0])),
        "{msg}"
    );
    let trusted = import(
        &cfg,
        &csv,
        &ImportOptions {
            trust_labels: true,
            ..Default::default()
        },
    )
    .unwrap();
    let l = trusted.labels.unwrap();
    assert_eq!(
        (l.beyond_tolerance, l.max_line, l.trusted),
        (1, bad_row + 2, true)
    );
    assert!(
        (l.max_disagreement - 1e-3).abs() < 1e-6,
        "{}",
        l.max_disagreement
    );
    // Not re-solving (--resolve 0) cannot see it: the check is the sample.
    let none = ImportOptions {
        resolve: 0,
        ..Default::default()
    };
    assert_eq!(
        import(&cfg, &csv, &none).unwrap().labels.unwrap().resolved,
        0
    );
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn malformed_files_are_errors_naming_file_line_and_column() {
    let cfg = small_cfg();
    let d = dir("bad");
    let err = |name: &str, text: &str| -> String {
        let p = write(&d, name, text);
        import(&cfg, &p, &ImportOptions::default())
            .unwrap_err()
            .to_string()
    };
    let e = err("cols.csv", "x1,x2,u1\n0.1,0.2,0.3\n0.1,0.2\n");
    assert!(
        e.contains("cols.csv:3") && e.contains("2 columns, the header has 3"),
        "{e}"
    );
    let e = err("dom.csv", "x1,x2,u1\n0.1,0.2,0.3\n0.1,99.0,0.3\n");
    assert!(
        e.contains("dom.csv:3") && e.contains("`x2`") && e.contains("outside"),
        "{e}"
    );
    let e = err("nan.csv", "x1,x2,u1\n0.1,NaN,0.3\n");
    assert!(e.contains("nan.csv:2") && e.contains("not finite"), "{e}");
    let e = err("nanu.csv", "x1,x2,u1\n0.1,0.1,\n");
    assert!(e.contains("nanu.csv:2") && e.contains("`u1`"), "{e}");
    let e = err("text.csv", "x1,x2,u1\n0.1,abc,0.3\n");
    assert!(
        e.contains("text.csv:2") && e.contains("`abc` is not a number"),
        "{e}"
    );
    let e = err("miss.csv", "x1,u1\n0.1,0.3\n");
    assert!(
        e.contains("miss.csv:1") && e.contains("missing column x2"),
        "{e}"
    );
    let e = err("unk.csv", "x1,x2,u1,solve_time\n0.1,0.1,0.3,1\n");
    assert!(e.contains("unk.csv:1") && e.contains("`solve_time`"), "{e}");
    let e = err("jac.csv", "x1,x2,u1,du1_dx1\n0.1,0.1,0.3,1\n");
    assert!(
        e.contains("jac.csv:1") && e.contains("give all or none"),
        "{e}"
    );
    let e = err("st.csv", "x1,x2,u1,status\n0.1,0.1,0.3,optimal\n");
    assert!(
        e.contains("st.csv:2") && e.contains("unknown status `optimal`"),
        "{e}"
    );
    let e = err("empty.csv", "");
    assert!(e.contains("empty.csv:1"), "{e}");
    // An unlabelled row may have no label; it is not re-solved.
    let p = write(&d, "unl.csv", "x1,x2,u1,status\n0.1,0.1,NaN,infeasible\n");
    let imp = import(&cfg, &p, &ImportOptions::default()).unwrap();
    assert_eq!(
        (imp.counts().infeasible, imp.labels.unwrap().resolved),
        (1, 0)
    );
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn the_sample_is_seeded_distinct_and_sorted() {
    let rows: Vec<usize> = (0..1000).map(|i| 3 * i).collect();
    let a = resolve_sample(&rows, 50, 7);
    assert_eq!(a, resolve_sample(&rows, 50, 7));
    assert_ne!(a, resolve_sample(&rows, 50, 8));
    assert_eq!(a.len(), 50);
    assert!(a.windows(2).all(|w| w[0] < w[1]) && a.iter().all(|i| i % 3 == 0));
    assert_eq!(resolve_sample(&rows[..5], 50, 7), rows[..5].to_vec());
    assert!(resolve_sample(&rows, 0, 7).is_empty());
}

/// Found by the fuzzer (trainer/tests/fuzz.rs): a column `x0` / `u0` subtracted 1 from 0
/// (an overflow panic in debug builds) before checking the range.
#[test]
fn a_column_numbered_zero_is_an_unknown_column_not_a_panic() {
    let names = (
        vec!["p".to_string(), "v".to_string()],
        vec!["a".to_string()],
    );
    for head in ["x0,x1,u1", "x1,x2,u0"] {
        let text = format!("{head}\n0.0,0.0,0.0\n");
        let e = super::csv::parse(
            &text,
            "z.csv",
            (&names.0, &names.1),
            &[-1.0; 2],
            &[1.0; 2],
            1,
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.starts_with("z.csv:1: column `") && e.contains("unknown column"),
            "{e}"
        );
    }
}

#[test]
fn a_bom_is_skipped_and_a_long_field_is_quoted_short() {
    // Excel's CSV: a UTF-8 byte-order mark before the header.
    let cfg = small_cfg();
    let d = dir("bom");
    let csv = write(&d, "bom.csv", "\u{feff}x1,x2,u1\n0.5,0.25,0.1\n");
    let opts = ImportOptions {
        resolve: 0,
        ..Default::default()
    };
    let imp = import(&cfg, &csv, &opts).unwrap();
    assert_eq!(imp.records[0].x, vec![0.5, 0.25]);
    // A 1 MB field is echoed with 80 characters and its length, not in full.
    let long = "q".repeat(1 << 20);
    let csv = write(&d, "long.csv", &format!("x1,x2,u1\n0.5,{long},0.1\n"));
    let e = import(&cfg, &csv, &opts).unwrap_err().to_string();
    assert!(e.len() < 400, "{} characters: {}", e.len(), &e[..400]);
    assert!(
        e.contains("long.csv:2") && e.contains("(1048576 characters)"),
        "{e}"
    );
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn labels_outside_u_are_refused_naming_the_row_and_value() {
    // `import --resolve 0` re-solves nothing: the input bounds are still checked.
    let cfg = small_cfg();
    let (lo, hi) = cfg.ocp.u_bounds(0);
    let (lo, hi) = (lo[0], hi[0]);
    let d = dir("u");
    let opts = ImportOptions {
        resolve: 0,
        ..Default::default()
    };
    let bad = hi + 0.5;
    let csv = write(
        &d,
        "u.csv",
        &format!("x1,x2,u1\n0.5,0.25,{hi}\n0.5,0.25,{bad}\n"),
    );
    let e = import(&cfg, &csv, &opts).unwrap_err().to_string();
    assert!(
        e.contains("u.csv:3") && e.contains(&format!("label u1 = {bad}")),
        "{e}"
    );
    // Within the stated tolerance (another solver's bound relaxation): accepted.
    let near = lo - 1e-9;
    let csv = write(&d, "near.csv", &format!("x1,x2,u1\n0.5,0.25,{near}\n"));
    assert!(import(&cfg, &csv, &opts).is_ok());
    // Unlabelled rows carry no input to check.
    let csv = write(
        &d,
        "unl.csv",
        &format!("x1,x2,u1,status\n0.5,0.25,{bad},infeasible\n"),
    );
    assert!(import(&cfg, &csv, &opts).is_ok());
    let _ = std::fs::remove_dir_all(&d);
}
