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

/// The dataset section names where the starts disagreed — the count, the starts, the rule
/// and the first states with the chosen u₀ — and says nothing when they never did.
#[test]
fn the_report_lists_where_the_starts_disagree() {
    use crate::data::dataset::{Header, Record, CHUNK, FORMAT_VERSION, MAGIC};
    use crate::mpc::sqp::SqpStatus;
    use crate::problem::solver::Start;
    let mut data = Dataset {
        magic: MAGIC,
        version: FORMAT_VERSION,
        header: Header {
            problem: "p".into(),
            problem_hash: "h".into(),
            config_toml: String::new(),
            nx: 2,
            nu: 1,
            sampling: crate::problem::SamplingSettings::default(),
            total: 3,
            shard: None,
            chunk: CHUNK as u32,
        },
        records: (0..3u64)
            .map(|i| Record {
                index: i,
                x: vec![0.5, i as f64],
                u: vec![-2.0 + i as f64],
                du_dx: vec![0.0, 0.0],
                cost: 10.0 + i as f64,
                status: SqpStatus::Converged,
                iterations: 3,
                kkt: 1e-9,
                degeneracy: None,
                max_slack: 0.0,
                seq: Vec::new(),
            })
            .collect(),
        labels: None,
        disagree: Vec::new(),
    };
    let starts = [Start::Warm, Start::ULo, Start::UHi];
    assert!(super::sections::starts_disagreement(&starts, &data).is_empty());
    data.disagree = vec![1, 2];
    let r = Report {
        title: "t".into(),
        blocks: super::sections::starts_disagreement(&starts, &data),
    };
    let md = r.to_markdown();
    assert!(md.contains("At 2 of 3 states"), "{md}");
    assert!(md.contains("`warm, u_lo, u_hi`"), "{md}");
    assert!(md.contains("lowest-cost optimum"), "{md}");
    assert!(md.contains("| 1 | (0.5000, 1.0000) | (-1.0000) |"), "{md}");
    assert!(md.contains("| 2 | (0.5000, 2.0000) | (0.0000) |"), "{md}");
    assert!(!md.contains("| 0 |"), "{md}");
}
