//! The report: inline markup and escaping, Markdown and HTML of the same table, number
//! and box formatting, medians.

use super::format::{boxed, num};
use super::sections::strs;
use super::*;

#[test]
fn inline_markup_and_escaping() {
    assert_eq!(
        inline("a **b** `c<d>` & e"),
        "a <strong>b</strong> <code>c&lt;d&gt;</code> &amp; e"
    );
    assert_eq!(inline("**open"), "<strong>open</strong>");
}

#[test]
fn markdown_and_html_hold_the_same_table() {
    let r = Report {
        title: "t".into(),
        blocks: vec![
            Block::Heading(2, "H".into()),
            Block::Table {
                head: strs(&["a", "b|c"]),
                rows: vec![strs(&["1", "**2**"])],
            },
            Block::Code("cargo run".into()),
        ],
    };
    let md = r.to_markdown();
    assert!(
        md.contains("| a | b\\|c |\n|---|---|\n| 1 | **2** |"),
        "{md}"
    );
    let html = r.to_html(Path::new("/nonexistent")).unwrap();
    assert!(html.contains("<th>a</th><th>b|c</th>"), "{html}");
    assert!(
        html.contains("<td>1</td><td><strong>2</strong></td>"),
        "{html}"
    );
    assert!(html.contains("<pre><code>cargo run</code></pre>"));
    assert_eq!(html.matches("<table>").count(), 1);
}

#[test]
fn numbers_and_boxes() {
    assert_eq!(num(-std::f64::consts::TAU), "-6.28319");
    assert_eq!(num(15.0), "15");
    assert_eq!(num(0.1), "0.1");
    assert_eq!(boxed(&[-1.0, 0.0], &[1.0, 2.5]), "[-1, 1] × [0, 2.5]");
}

#[test]
fn median_of_even_and_odd_counts() {
    assert_eq!(med_min_max(&[3.0, 1.0, 2.0]), (2.0, 1.0, 3.0));
    assert_eq!(
        med_min_max(&[4.0, 1.0, 2.0, 3.0, f64::NAN]),
        (2.5, 1.0, 4.0)
    );
    assert!(med_min_max(&[]).0.is_nan());
}

#[test]
fn paper_columns_only_for_the_papers_problem() {
    let load = |name: &str| {
        let path = std::path::PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/"))
            .join(name);
        ProblemConfig::load(&path).unwrap()
    };
    assert!(super::sections::is_paper_problem(&ProblemConfig::default()));
    assert!(super::sections::is_paper_problem(&load("pendulum.toml")));
    assert!(super::sections::is_paper_problem(&load(
        "pendulum_ode.toml"
    )));
    for other in [
        "double_integrator.toml",
        "cartpole.toml",
        "cartpole_public.toml",
        "planar_quadrotor.toml",
    ] {
        assert!(!super::sections::is_paper_problem(&load(other)), "{other}");
    }
    let mut cfg = ProblemConfig::default();
    cfg.ocp.horizon = 10;
    assert!(!super::sections::is_paper_problem(&cfg));
}
