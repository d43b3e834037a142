//! The run report: one structured document ([`Report`]) built from a run directory's
//! artifacts, rendered as Markdown (`report.md`) and as a self-contained HTML page
//! (`report.html`, the figures inlined as SVG).
//!
//! Content: the problem, the dataset's counts (failures, soft labels, degenerate points),
//! Table I and Table II for both nets beside the paper's figures, every term of the
//! certificate and which ones are estimates, the closed-loop distributions (initial states,
//! robustness runs, training seeds as median [min, max]), the figures, the per-stage
//! timings and the command that reproduces the run. Every number is read from the run's
//! files; the only constants are the paper's published figures.

use crate::certify::certificate::Certificate;
use crate::certify::Model;
use crate::data::dataset::Dataset;
use crate::problem::ProblemConfig;
use crate::study::closed_loop::Run;
use crate::study::plots::{FigureEntry, PLOTS};
use crate::study::scenarios::ClosedLoop;
use crate::study::seeds::SeedRun;
use std::fmt::Write as _;
use std::path::Path;

/// A report that cannot be built (names the file at fault).
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct ReportError(pub String);

/// The paper's Table I (R², ε_D, L_NN) for the nominal and the regularized net.
pub const PAPER_TABLE_I: [(&str, [f64; 3]); 2] = [
    ("nominal", [0.985, 3.231, 384.01]),
    ("regularized", [0.992, 1.823, 207.66]),
];
/// The paper's Table II (violating steps %, max violation, max input divergence).
pub const PAPER_TABLE_II: [(&str, [f64; 3]); 2] = [
    ("nominal", [46.534, 1.113, 2.975]),
    ("regularized", [39.604, 1.032, 0.649]),
];

/// Median, minimum and maximum (NaN entries ignored).
pub fn med_min_max(v: &[f64]) -> (f64, f64, f64) {
    let mut s: Vec<f64> = v.iter().copied().filter(|x| !x.is_nan()).collect();
    if s.is_empty() {
        return (f64::NAN, f64::NAN, f64::NAN);
    }
    s.sort_by(f64::total_cmp);
    let n = s.len();
    let med = if n % 2 == 1 {
        s[n / 2]
    } else {
        0.5 * (s[n / 2 - 1] + s[n / 2])
    };
    (med, s[0], s[n - 1])
}

fn mmm(v: &[f64]) -> String {
    let (a, b, c) = med_min_max(v);
    format!("{a:.3} [{b:.3}, {c:.3}]")
}

/// Timing of one stage, for the report.
#[derive(Debug, Clone, PartialEq)]
pub struct Timing {
    /// Stage name.
    pub stage: String,
    /// Wall time in seconds (of the run that produced the artifacts when skipped).
    pub seconds: f64,
    /// Skipped in this run.
    pub skipped: bool,
}

/// A block of the report.
#[derive(Debug, Clone, PartialEq)]
pub enum Block {
    /// A section heading (level 2 or 3).
    Heading(u8, String),
    /// A paragraph; `**bold**` and `` `code` `` are the only inline markup.
    Para(String),
    /// A table.
    Table {
        /// Column headers.
        head: Vec<String>,
        /// Rows of cells (inline markup as in paragraphs).
        rows: Vec<Vec<String>>,
    },
    /// A shell command block.
    Code(String),
    /// A figure `plots/<stem>.svg|png` with its caption.
    Figure {
        /// File stem.
        stem: String,
        /// Caption.
        caption: String,
    },
}

/// The report: a title and blocks.
#[derive(Debug, Clone, PartialEq)]
pub struct Report {
    /// Title.
    pub title: String,
    /// Content in order.
    pub blocks: Vec<Block>,
}

fn load<T: serde::de::DeserializeOwned>(p: &Path) -> Result<T, ReportError> {
    let t = std::fs::read_to_string(p).map_err(|e| ReportError(format!("{}: {e}", p.display())))?;
    serde_json::from_str(&t).map_err(|e| ReportError(format!("{}: {e}", p.display())))
}

fn row(cells: impl IntoIterator<Item = String>) -> Vec<String> {
    cells.into_iter().collect()
}

fn strs(v: &[&str]) -> Vec<String> {
    v.iter().map(|s| s.to_string()).collect()
}

/// Builds the report of the run in `dir` from its artifacts.
pub fn build(cfg: &ProblemConfig, dir: &Path, timings: &[Timing]) -> Result<Report, ReportError> {
    let e = |e: crate::data::dataset::DatasetError| ReportError(e.to_string());
    let data = Dataset::load(&dir.join("dataset.bin")).map_err(e)?;
    let nom = Model::load(&dir.join("model_nominal.bin")).map_err(e)?;
    let reg = Model::load(&dir.join("model_regularized.bin")).map_err(e)?;
    let cert: Certificate = load(&dir.join("certificate.json"))?;
    let cert_n: Certificate = load(&dir.join("certificate_nominal.json"))?;
    let cl: ClosedLoop = load(&dir.join("closed_loop.json"))?;
    let seeds: Vec<[SeedRun; 2]> = load(&dir.join("seeds.json"))?;
    let export: serde_json::Value = load(&dir.join("export_report.json"))?;
    let c = data.counts();
    let mut b = Vec::new();
    let js = |v: &dyn erased_json::J| v.json();

    // Problem.
    b.push(Block::Heading(2, "Problem".into()));
    b.push(Block::Para(format!(
        "System `{}` (nx = {}, nu = {}), Ts = {} s, horizon N = {}, RK4 sub-steps {}; Q = {}, R = {}, P = {}. State bounds on x₁..x_N: x ∈ {}; input bounds U = {}. Certified (and sampled) domain X = {}.",
        cfg.system.name(),
        cfg.system.nx(),
        cfg.system.nu(),
        cfg.ocp.ts,
        cfg.ocp.horizon,
        cfg.ocp.rk4_substeps,
        js(&cfg.ocp.q),
        js(&cfg.ocp.r),
        js(&cfg.ocp.p),
        boxed(&cfg.ocp.x_lo, &cfg.ocp.x_hi),
        boxed(&cfg.ocp.u_lo, &cfg.ocp.u_hi),
        boxed(&cfg.domain.lo, &cfg.domain.hi),
    )));

    // Dataset.
    b.push(Block::Heading(2, "Dataset".into()));
    b.push(Block::Table {
        head: strs(&[
            "states",
            "sampler",
            "converged",
            "soft (exact-penalty label)",
            "infeasible",
            "failed",
            "degenerate sensitivity",
        ]),
        rows: vec![row([
            c.total.to_string(),
            format!(
                "{:?} {:?}",
                data.header.sampling.sampler, data.header.sampling.counts
            ),
            c.converged.to_string(),
            c.soft.to_string(),
            c.infeasible.to_string(),
            c.failed.to_string(),
            c.degenerate.to_string(),
        ])],
    });
    b.push(Block::Para(format!(
        "Soft: the hard OCP is infeasible at the state and the label is the exact-penalty optimum; infeasible and failed states have no label and are not trained on; degenerate points keep their value term and drop the Jacobian term. {} labelled training points; R² is measured on {} MPC-labelled random states of X.",
        nom.train_stats.n, nom.validation_stats.n
    )));

    // Table I.
    b.push(Block::Heading(2, "Table I: networks after training".into()));
    let mut rows = Vec::new();
    for ((name, m, ce), (_, paper)) in [("nominal", &nom, &cert_n), ("regularized", &reg, &cert)]
        .into_iter()
        .zip(PAPER_TABLE_I)
    {
        rows.push(row([
            name.to_string(),
            format!("{:.4}", m.validation_stats.r2),
            format!("{:.3}", ce.eps_d),
            format!("{:.2} ({:?})", ce.l_nn, ce.l_nn_method),
            format!("{:.2}", ce.l_nn_lipsdp),
            format!("{:.2}", ce.l_nn_naive),
            format!("{:.2}", ce.l_nn_lower),
            format!("{:.3}", m.train_stats.median),
            format!("{} / {} / {}", paper[0], paper[1], paper[2]),
        ]));
    }
    b.push(Block::Table {
        head: strs(&[
            "net",
            "validation R²",
            "ε_D",
            "L_NN (sound, method)",
            "LipSDP-Neuron",
            "naive",
            "sampled lower",
            "median error",
            "paper R² / ε_D / L_NN",
        ]),
        rows,
    });
    let seed_list =
        |k: usize, f: fn(&SeedRun) -> f64| -> Vec<f64> { seeds.iter().map(|s| f(&s[k])).collect() };
    let seed_range = match (seeds.first(), seeds.last()) {
        (Some(a), Some(z)) => format!("{}..={}", a[0].seed, z[0].seed),
        _ => "none".into(),
    };
    b.push(Block::Para(format!(
        "Training seed {} (initial weights and shuffling, the same for both nets). Over {} seeds ({seed_range}), median [min, max]:",
        cfg.training.seed,
        seeds.len()
    )));
    b.push(Block::Table {
        head: strs(&["net", "validation R²", "ε_D"]),
        rows: ["nominal", "regularized"]
            .iter()
            .enumerate()
            .map(|(k, name)| {
                row([
                    name.to_string(),
                    mmm(&seed_list(k, |s| s.r2_validation)),
                    mmm(&seed_list(k, |s| s.eps_d)),
                ])
            })
            .collect(),
    });

    // Certificate.
    b.push(Block::Heading(2, "Certificate (Theorem 1)".into()));
    let f32a = export["f32_allowance_libm"].as_f64().unwrap_or(f64::NAN);
    let cert_rows = |name: &str, f: &dyn Fn(&Certificate) -> String, how: String| {
        row([name.to_string(), f(&cert), f(&cert_n), how])
    };
    let mut rows = vec![
        cert_rows(
            "ε_D",
            &|c| format!("{:.6}", c.eps_d),
            format!("max ‖κ − κ_NN‖ over {} labelled points (computed)", cert.n_points),
        ),
        cert_rows(
            "L_NN",
            &|c| format!("{:.4}", c.l_nn),
            format!("{:?}: a sound upper bound (naive product of norms {:.2}, sampled lower bound {:.2})", cert.l_nn_method, cert.l_nn_naive, cert.l_nn_lower),
        ),
        cert_rows(
            "L_MPC",
            &|c| format!("{:.4}", c.l_mpc),
            format!(
                "{}{}",
                cert.l_mpc_method,
                if cert.l_mpc_is_estimate { " — **an estimate**, not a proven bound" } else { " — supplied as proven" }
            ),
        ),
        cert_rows(
            "r",
            &|c| format!("{:.6}", c.covering_radius),
            cert.covering_method.clone(),
        ),
        cert_rows(
            "**ε**",
            &|c| format!("**{:.4}**", c.eps),
            format!(
                "ε_D + (L_MPC + L_NN)·r{}",
                if cert.l_mpc_is_estimate { "; L_MPC is an estimate, so ε is too" } else { "" }
            ),
        ),
    ];
    rows.push(row([
        "f32 allowance".to_string(),
        format!("{f32a:.3e}"),
        "—".into(),
        "sound bound on |κ_NN,f32 − κ_NN,f64| over X for the exported controller (libm tanh); added to ε on the device".into(),
    ]));
    rows.push(row([
        "ε on the device".to_string(),
        format!("{:.4}", cert.eps + f32a),
        "—".into(),
        "ε + f32 allowance".into(),
    ]));
    b.push(Block::Table {
        head: strs(&["term", "regularized", "nominal", "how"]),
        rows,
    });
    b.push(Block::Para(format!(
        "Output clamp band U ⊕ [−ε, ε] of the exported (regularized) controller: u ∈ {}.",
        boxed(&cert.clamp_lo, &cert.clamp_hi)
    )));

    // Table II.
    b.push(Block::Heading(2, "Table II: closed loop".into()));
    let first = |k: &str| cl.get(k).and_then(|v| v.first());
    let x0: Vec<String> = first("mpc")
        .map(|r| r.x0.iter().map(|v| num(*v)).collect())
        .unwrap_or_default();
    let steps = first("mpc").map_or(0, |r| r.steps);
    b.push(Block::Para(format!(
        "From x₀ = ({}) ({steps} steps = {} s, nominal plant, no noise), training seed {}:",
        x0.join(", "),
        steps as f64 * cfg.ocp.ts,
        cfg.training.seed
    )));
    let mut rows = Vec::new();
    for k in ["mpc", "nominal", "regularized"] {
        let paper = PAPER_TABLE_II
            .iter()
            .find(|(n, _)| *n == k)
            .map_or("—".to_string(), |(_, p)| {
                format!("{} / {} / {}", p[0], p[1], p[2])
            });
        if let Some(r) = first(k) {
            rows.push(row([
                k.to_string(),
                format!("{:.3}", r.violation_percent),
                format!("{:.4}", r.max_violation),
                format!("{:.4}", r.max_input_divergence),
                format!("{:.1}", r.cost),
                r.settling_step.map_or("never".into(), |v| v.to_string()),
                r.left_band.to_string(),
                paper,
            ]));
        }
    }
    b.push(Block::Table {
        head: strs(&[
            "controller",
            "violating steps %",
            "max violation",
            "max input divergence",
            "cost",
            "settling step",
            "left certified band",
            "paper % / max / divergence",
        ]),
        rows,
    });
    b.push(Block::Para(format!(
        "Over {} training seeds ({seed_range}), same x₀, median [min, max]:",
        seeds.len()
    )));
    b.push(Block::Table {
        head: strs(&[
            "net",
            "violating steps %",
            "max violation",
            "max input divergence",
            "cost",
        ]),
        rows: ["nominal", "regularized"]
            .iter()
            .enumerate()
            .map(|(k, name)| {
                row([
                    name.to_string(),
                    mmm(&seed_list(k, |s| s.run.violation_percent)),
                    mmm(&seed_list(k, |s| s.run.max_violation)),
                    mmm(&seed_list(k, |s| s.run.max_input_divergence)),
                    mmm(&seed_list(k, |s| s.run.cost)),
                ])
            })
            .collect(),
    });
    b.push(Block::Para(format!(
        "Over all initial states (x₀ and {} random states of X) and the robustness runs (`_noise`: measurement noise {} of the domain half-width, {} seeds; `_mass±`: plant mass ±{} %), training seed {}, median [min, max]:",
        cfg.closed_loop.random_initial_states,
        cfg.closed_loop.noise_fraction,
        cfg.closed_loop.noise_runs,
        100.0 * cfg.closed_loop.mass_mismatch,
        cfg.training.seed
    )));
    let mut rows = Vec::new();
    for (k, runs) in &cl {
        let col = |f: fn(&Run) -> f64| mmm(&runs.iter().map(f).collect::<Vec<_>>());
        rows.push(row([
            k.clone(),
            runs.len().to_string(),
            col(|r| r.violation_percent),
            col(|r| r.max_violation),
            col(|r| r.max_input_divergence),
            col(|r| r.cost),
        ]));
    }
    b.push(Block::Table {
        head: strs(&[
            "runs",
            "n",
            "violating steps %",
            "max violation",
            "max input divergence",
            "cost",
        ]),
        rows,
    });

    // Figures.
    b.push(Block::Heading(2, "Figures".into()));
    let figures: Vec<FigureEntry> = load(&dir.join("plots/figures.json"))?;
    for stem in PLOTS {
        let caption = figures
            .iter()
            .find(|f| f.name == stem)
            .map(|f| f.caption.clone())
            .ok_or_else(|| ReportError(format!("plots/figures.json lists no figure `{stem}`")))?;
        b.push(Block::Figure {
            stem: stem.to_string(),
            caption,
        });
    }

    // Timings.
    b.push(Block::Heading(2, "Stage timings".into()));
    let total: f64 = timings
        .iter()
        .filter(|t| !t.skipped)
        .map(|t| t.seconds)
        .sum();
    let mut rows: Vec<Vec<String>> = timings
        .iter()
        .map(|t| {
            row([
                t.stage.clone(),
                format!("{:.3}", t.seconds),
                if t.skipped {
                    "skipped (time of the run that made it)".into()
                } else {
                    "ran".into()
                },
            ])
        })
        .collect();
    rows.push(row([
        "stages run before the report".to_string(),
        format!("{total:.3}"),
        String::new(),
    ]));
    b.push(Block::Table {
        head: strs(&["stage", "seconds", "this run"]),
        rows,
    });
    b.push(Block::Para(format!(
        "Wall-clock times on this machine ({} threads available to rayon).",
        rayon::current_num_threads()
    )));

    // Reproduce.
    b.push(Block::Heading(2, "Reproduce".into()));
    b.push(Block::Code(format!(
        "cargo run --release -p trainer -- run {} --out {}",
        dir.join("problem.toml").display(),
        dir.parent().map_or(".".into(), |p| p.display().to_string())
    )));
    Ok(Report {
        title: format!("ampc run: {}", cfg.name),
        blocks: b,
    })
}

/// A number with at most 6 significant digits.
fn num(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let digits = (5 - v.abs().log10().floor() as i32).clamp(0, 12) as usize;
    let s = format!("{v:.digits$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// A box `[lo₁, hi₁] × [lo₂, hi₂] × …`.
fn boxed(lo: &[f64], hi: &[f64]) -> String {
    let parts: Vec<String> = lo
        .iter()
        .zip(hi)
        .map(|(l, h)| format!("[{}, {}]", num(*l), num(*h)))
        .collect();
    parts.join(" × ")
}

fn md_cell(s: &str) -> String {
    s.replace('|', "\\|")
}

impl Report {
    /// Markdown; figures link `plots/<stem>.png` (and the SVG).
    pub fn to_markdown(&self) -> String {
        let mut s = format!("# {}\n\n", self.title);
        for b in &self.blocks {
            match b {
                Block::Heading(l, t) => {
                    let _ = writeln!(s, "{} {t}\n", "#".repeat(usize::from(*l)));
                }
                Block::Para(t) => {
                    let _ = writeln!(s, "{t}\n");
                }
                Block::Table { head, rows } => {
                    let h: Vec<String> = head.iter().map(|c| md_cell(c)).collect();
                    let _ = writeln!(s, "| {} |", h.join(" | "));
                    let _ = writeln!(s, "|{}", "---|".repeat(head.len()));
                    for r in rows {
                        let r: Vec<String> = r.iter().map(|c| md_cell(c)).collect();
                        let _ = writeln!(s, "| {} |", r.join(" | "));
                    }
                    s.push('\n');
                }
                Block::Code(c) => {
                    let _ = writeln!(s, "```sh\n{c}\n```\n");
                }
                Block::Figure { stem, caption } => {
                    let _ = writeln!(
                        s,
                        "![{stem}](plots/{stem}.png)\n\n{caption} ([SVG](plots/{stem}.svg))\n"
                    );
                }
            }
        }
        s
    }

    /// A self-contained HTML page: the same content, tables as HTML tables, the figures'
    /// SVG (read from `dir/plots/`) inline.
    pub fn to_html(&self, dir: &Path) -> Result<String, ReportError> {
        let mut s = String::new();
        let _ = write!(
            s,
            "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>{}</title>\n<style>\nbody{{font-family:'DejaVu Sans',sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;line-height:1.45;color:#222}}\ntable{{border-collapse:collapse;margin:0.8em 0;font-size:0.92em}}\nth,td{{border:1px solid #bbb;padding:0.25em 0.6em;text-align:left}}\nth{{background:#eee}}\ncode,pre{{background:#f4f4f4;font-family:'DejaVu Sans Mono',monospace}}\npre{{padding:0.6em;overflow-x:auto}}\nfigure{{margin:1.5em 0}}\nfigure svg{{max-width:100%;height:auto}}\nfigcaption{{font-size:0.92em;color:#444}}\n</style>\n</head>\n<body>\n<h1>{}</h1>\n",
            esc(&self.title),
            esc(&self.title)
        );
        for b in &self.blocks {
            match b {
                Block::Heading(l, t) => {
                    let _ = writeln!(s, "<h{l}>{}</h{l}>", inline(t));
                }
                Block::Para(t) => {
                    let _ = writeln!(s, "<p>{}</p>", inline(t));
                }
                Block::Table { head, rows } => {
                    s += "<table>\n<thead><tr>";
                    for h in head {
                        let _ = write!(s, "<th>{}</th>", inline(h));
                    }
                    s += "</tr></thead>\n<tbody>\n";
                    for r in rows {
                        s += "<tr>";
                        for c in r {
                            let _ = write!(s, "<td>{}</td>", inline(c));
                        }
                        s += "</tr>\n";
                    }
                    s += "</tbody>\n</table>\n";
                }
                Block::Code(c) => {
                    let _ = writeln!(s, "<pre><code>{}</code></pre>", esc(c));
                }
                Block::Figure { stem, caption } => {
                    let p = dir.join("plots").join(format!("{stem}.svg"));
                    let svg = std::fs::read_to_string(&p)
                        .map_err(|e| ReportError(format!("{}: {e}", p.display())))?;
                    let svg = svg
                        .find("<svg")
                        .map_or(svg.as_str(), |i| &svg[i..])
                        .to_string();
                    let _ = writeln!(
                        s,
                        "<figure id=\"{stem}\">\n{svg}\n<figcaption>{} (<a href=\"plots/{stem}.png\">PNG</a>, <a href=\"plots/{stem}.svg\">SVG</a>)</figcaption>\n</figure>",
                        inline(caption)
                    );
                }
            }
        }
        s += "</body>\n</html>\n";
        Ok(s)
    }
}

/// HTML escape.
pub fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// Escapes and converts `**bold**` and `` `code` `` to HTML.
pub fn inline(s: &str) -> String {
    let mut out = String::new();
    let (mut bold, mut code) = (false, false);
    let mut rest = s;
    while !rest.is_empty() {
        if !code && rest.starts_with("**") {
            out += if bold { "</strong>" } else { "<strong>" };
            bold = !bold;
            rest = &rest[2..];
        } else if rest.starts_with('`') {
            out += if code { "</code>" } else { "<code>" };
            code = !code;
            rest = &rest[1..];
        } else {
            let ch = rest.chars().next().unwrap_or(' ');
            out += &esc(&ch.to_string());
            rest = &rest[ch.len_utf8()..];
        }
    }
    if code {
        out += "</code>";
    }
    if bold {
        out += "</strong>";
    }
    out
}

mod erased_json {
    /// Compact JSON of a value, for the report's problem summary.
    pub trait J {
        fn json(&self) -> String;
    }
    impl<T: serde::Serialize> J for T {
        fn json(&self) -> String {
            serde_json::to_string(self).unwrap_or_default()
        }
    }
}

#[cfg(test)]
mod tests {
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
}
