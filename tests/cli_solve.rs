//! `trainer solve`: labels states from a CSV; the output matches the library and the
//! IPOPT reference; bad input gets a clear error naming the file, line or key, and exit 1;
//! usage errors exit 2.

use ampc_tests::{config, tempdir, trainer};

#[test]
fn solve_labels_states_like_the_reference() {
    let dir = tempdir();
    let input = dir.path().join("in.csv");
    let out = dir.path().join("out.csv");
    std::fs::write(
        &input,
        "x1,x2\n0.548207810803,0.230770222963\n0,0\n-3.14159265359,0\n",
    )
    .unwrap();
    let o = trainer(&[
        "solve",
        "--config",
        &config("pendulum.toml"),
        "--states",
        input.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = std::fs::read_to_string(&out).unwrap();
    let mut lines = text.lines();
    assert_eq!(
        lines.next().unwrap(),
        "x1,x2,u1,du1_dx1,du1_dx2,cost,status,iterations"
    );
    let rows: Vec<Vec<String>> = lines
        .map(|l| l.split(',').map(String::from).collect())
        .collect();
    assert_eq!(rows.len(), 3);
    let num = |r: &Vec<String>, i: usize| r[i].parse::<f64>().unwrap();
    // IPOPT (tol 1e-10): u0 = −12.7254594, ∂u0/∂x0 = (−18.9126959, −6.5222861), cost 75.3903035.
    assert!((num(&rows[0], 2) + 12.7254594219).abs() < 1e-5);
    assert!((num(&rows[0], 3) + 18.9126958835).abs() < 1e-4 * 18.9);
    assert!((num(&rows[0], 4) + 6.52228610471).abs() < 1e-4 * 6.5);
    assert!((num(&rows[0], 5) - 75.3903035349).abs() < 1e-5);
    assert!((num(&rows[1], 3) + 21.155709863).abs() < 1e-4 * 21.2);
    assert_eq!(num(&rows[2], 2), 15.0);
    assert!(rows.iter().all(|r| r[6] == "converged"));
    // The default problem is the embedded pendulum: same answer without --config.
    let out2 = dir.path().join("out2.csv");
    let o = trainer(&[
        "solve",
        "--states",
        input.to_str().unwrap(),
        "--out",
        out2.to_str().unwrap(),
    ]);
    assert!(o.status.success());
    assert_eq!(std::fs::read_to_string(&out2).unwrap(), text);
}

fn solve_err(input: &str, cfg: Option<&str>) -> (i32, String) {
    let dir = tempdir();
    let p = dir.path().join("in.csv");
    std::fs::write(&p, input).unwrap();
    let out = dir.path().join("out.csv");
    let mut args = vec![
        "solve",
        "--states",
        p.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    if let Some(c) = cfg {
        args.extend(["--config", c]);
    }
    let o = trainer(&args);
    assert!(!out.exists(), "no output on error");
    (
        o.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&o.stderr).to_string(),
    )
}

#[test]
fn bad_input_is_a_clear_error() {
    let (c, e) = solve_err("a,b\n1,2\n", None);
    assert_eq!(c, 1);
    assert!(e.contains("in.csv:1") && e.contains("x1,x2"), "{e}");
    let (c, e) = solve_err("x1,x2\n1,2,3\n", None);
    assert_eq!(c, 1);
    assert!(
        e.contains("in.csv:2") && e.contains("expected 2 columns"),
        "{e}"
    );
    let (c, e) = solve_err("x1,x2\n0,0\nNaN,1\n", None);
    assert_eq!(c, 1);
    assert!(e.contains("in.csv:3") && e.contains("x1"), "{e}");
    let (c, e) = solve_err("x1,x2\n0,abc\n", None);
    assert_eq!(c, 1);
    assert!(e.contains("in.csv:2") && e.contains("x2"), "{e}");
    let (c, e) = solve_err("", None);
    assert_eq!(c, 1);
    assert!(e.contains("empty"), "{e}");
    let (c, e) = solve_err("x1,x2\n0,0\n", Some("/nonexistent/p.toml"));
    assert_eq!(c, 1);
    assert!(e.contains("/nonexistent/p.toml"), "{e}");
    // A problem file with an invalid value names the key.
    let dir = tempdir();
    let bad = dir.path().join("bad.toml");
    let text = std::fs::read_to_string(config("pendulum.toml"))
        .unwrap()
        .replace("horizon = 20", "horizon = 0");
    std::fs::write(&bad, text).unwrap();
    let (c, e) = solve_err("x1,x2\n0,0\n", Some(bad.to_str().unwrap()));
    assert_eq!(c, 1);
    assert!(e.contains("ocp.horizon"), "{e}");
    // Missing input file.
    let o = trainer(&[
        "solve",
        "--states",
        "/nonexistent/in.csv",
        "--out",
        "/tmp/x.csv",
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("/nonexistent/in.csv"));
}

#[test]
fn usage_errors_exit_2() {
    assert_eq!(trainer(&["solve"]).status.code(), Some(2));
    assert_eq!(trainer(&["frobnicate"]).status.code(), Some(2));
    assert_eq!(
        trainer(&["sample", "--out", "x.bin", "--shard", "3/3"])
            .status
            .code(),
        Some(2)
    );
}
