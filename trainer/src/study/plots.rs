//! Figures of a run (the paper's Fig. 1 and Fig. 2, an error map and training curves), as
//! SVG and PNG.
//!
//! This module owns the drawing: it takes data that other stages computed (closed-loop
//! runs, trained models with their training curves, the dataset, MPC labels of a grid) and
//! turns them into SVG text with `plotters`' SVG backend; [`to_png`] rasterises that SVG with
//! `resvg`. Both use the DejaVu Sans font compiled into the binary (no system fonts), so the
//! files are the same on every machine.
//!
//! Figures:
//! - `trajectories`: x_i(t) and u_j(t) of the MPC and both nets from the reference initial
//!   state, with the state and input bounds (Fig. 1);
//! - `errors`: box plots, nominal vs regularized, of ‖κ − κ_NN‖ on the dataset and on the
//!   validation states, of the input divergence ‖κ(x_k) − κ_NN(x_k)‖ along the closed-loop
//!   trajectories, and of the state-bound violations of the violating steps (Fig. 2);
//! - `error_map`: ‖κ − κ_NN‖ of the regularized net on a grid over the first two axes of X
//!   (other coordinates at the centre of X), dataset points overlaid;
//! - `training`: loss terms, ε_D and validation R² per logged epoch;
//! - `eps_map` (`trainer refine`): the local certificate's ε_C per cell over the first two
//!   axes of X, and which term of ε_C binds there.

use crate::certify::refine::CellView;
use crate::certify::Model;
use crate::learn::train::{errors, TrainSet};
use crate::problem::model::System;
use crate::problem::ProblemConfig;
use crate::study::closed_loop::{Run, VIOLATION_TOL};
use plotters::prelude::*;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// One figure of `plots/figures.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FigureEntry {
    /// File stem.
    pub name: String,
    /// Caption (with the figure's own numbers).
    pub caption: String,
    /// SVG path relative to the run directory.
    pub svg: String,
    /// PNG path relative to the run directory.
    pub png: String,
}

/// File stems of the figures the `plots` stage writes (`plots/<stem>.svg` and `.png`).
pub const PLOTS: [&str; 4] = ["trajectories", "errors", "error_map", "training"];

/// A drawing or rasterising failure.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// plotters could not draw a figure.
    #[error("drawing figure `{figure}`: {cause}")]
    Draw {
        /// Figure name.
        figure: String,
        /// The backend's message.
        cause: String,
    },
    /// The SVG could not be parsed or rasterised.
    #[error("rasterising figure `{figure}`: {cause}")]
    Raster {
        /// Figure name.
        figure: String,
        /// What failed.
        cause: String,
    },
    /// The data needed for a figure is missing.
    #[error("figure `{figure}`: {cause}")]
    Data {
        /// Figure name.
        figure: String,
        /// What is missing.
        cause: String,
    },
}

/// One rendered figure.
#[derive(Debug, Clone)]
pub struct Figure {
    /// File stem (`plots/<name>.svg`, `plots/<name>.png`).
    pub name: &'static str,
    /// One-line caption.
    pub caption: String,
    /// The SVG document.
    pub svg: String,
}

/// MPC labels ‖κ − κ_NN‖ on a grid over the first two axes of X.
#[derive(Debug, Clone, PartialEq)]
pub struct ErrorGrid {
    /// Points per axis (axes 0 and 1 of the state).
    pub counts: [usize; 2],
    /// Lower corner of the plotted rectangle.
    pub lo: [f64; 2],
    /// Upper corner of the plotted rectangle.
    pub hi: [f64; 2],
    /// ‖κ(x) − κ_NN(x)‖ per grid point, axis 0 fastest; NaN where the MPC found no label.
    pub err: Vec<f64>,
}

impl ErrorGrid {
    /// Labels a `counts[0] × counts[1]` grid (endpoints included) over the first two axes
    /// of X with the MPC (cold starts, in parallel: the result does not depend on the thread
    /// count) and evaluates `mlp` there. Other state coordinates sit at the centre of X.
    pub fn label(cfg: &ProblemConfig, mlp: &crate::learn::mlp::Mlp, counts: [usize; 2]) -> Self {
        use rayon::prelude::*;
        let (lo, hi) = (&cfg.domain.lo, &cfg.domain.hi);
        let centre: Vec<f64> = lo.iter().zip(hi).map(|(l, h)| 0.5 * (l + h)).collect();
        let coord = |a: usize, i: usize| {
            if counts[a] <= 1 {
                0.5 * (lo[a] + hi[a])
            } else {
                lo[a] + (hi[a] - lo[a]) * i as f64 / (counts[a] - 1) as f64
            }
        };
        if lo.len() < 2 {
            // A one-dimensional state has no map: the figure reports the missing data.
            return ErrorGrid {
                counts,
                lo: [0.0; 2],
                hi: [1.0; 2],
                err: Vec::new(),
            };
        }
        let pts: Vec<Vec<f64>> = (0..counts[0] * counts[1])
            .map(|k| {
                let mut x = centre.clone();
                x[0] = coord(0, k % counts[0]);
                x[1] = coord(1, k / counts[0]);
                x
            })
            .collect();
        let err = pts
            .par_iter()
            .map_init(
                || crate::mpc::law::MpcLaw::new(cfg),
                |law, x| {
                    let (l, _) = law.solve(x, None);
                    if !l.status.is_labelled() {
                        return f64::NAN;
                    }
                    let u = mlp.predict(x);
                    l.u.iter()
                        .zip(&u)
                        .map(|(a, b)| (a - b).powi(2))
                        .sum::<f64>()
                        .sqrt()
                },
            )
            .collect();
        ErrorGrid {
            counts,
            lo: [lo[0], lo[1]],
            hi: [hi[0], hi[1]],
            err,
        }
    }
}

/// Everything the figures show.
pub struct PlotInputs<'a> {
    /// The problem.
    pub cfg: &'a ProblemConfig,
    /// Labelled training points.
    pub train: &'a TrainSet,
    /// Labelled validation points.
    pub validation: &'a TrainSet,
    /// The nominal net.
    pub nominal: &'a Model,
    /// The sensitivity-regularized net.
    pub regularized: &'a Model,
    /// Closed-loop runs by controller (`mpc`, `nominal`, `regularized`, …).
    pub closed_loop: &'a BTreeMap<String, Vec<Run>>,
    /// Error of the regularized net on a grid.
    pub grid: &'a ErrorGrid,
}

const MPC_COLOR: RGBColor = RGBColor(0, 0, 0);
const NOM_COLOR: RGBColor = RGBColor(213, 94, 0);
const REG_COLOR: RGBColor = RGBColor(0, 114, 178);
const BOUND_COLOR: RGBColor = RGBColor(120, 120, 120);
const FONT: &str = "sans-serif";

fn register_font() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        // The embedded font parses; a failure would show as a drawing error below.
        let _ = plotters::style::register_font(FONT, FontStyle::Normal, dejavu::sans::regular());
        let _ = plotters::style::register_font(FONT, FontStyle::Bold, dejavu::sans::bold());
    });
}

/// Axis names with units: (states, inputs).
pub fn axis_names(sys: &System) -> (Vec<String>, Vec<String>) {
    let v = |a: &[&str]| a.iter().map(|s| s.to_string()).collect::<Vec<_>>();
    match sys {
        System::Pendulum(_) => (v(&["x₁ = θ − π [rad]", "x₂ [rad/s]"]), v(&["u [N·m]"])),
        System::CartPole(_) => (
            v(&["p [m]", "θ [rad]", "ṗ [m/s]", "θ̇ [rad/s]"]),
            v(&["F [N]"]),
        ),
        System::DoubleIntegrator(_) => (v(&["position [m]", "velocity [m/s]"]), v(&["u [N]"])),
    }
}

fn draw_err<E: std::fmt::Debug>(figure: &str) -> impl Fn(E) -> PlotError + '_ {
    move |e| PlotError::Draw {
        figure: figure.to_string(),
        cause: format!("{e:?}"),
    }
}

/// Tick label formatter for an axis spanning `span`: enough decimals for ~10 ticks, and
/// no "-0.0".
fn tick_fmt(span: f64) -> impl Fn(&f64) -> String {
    let d = if span.is_finite() && span > 0.0 {
        (-(span / 10.0).log10().floor()).clamp(0.0, 8.0) as usize
    } else {
        1
    };
    move |v: &f64| {
        let s = format!("{v:.d$}");
        if s.parse::<f64>() == Ok(0.0) {
            format!("{:.d$}", 0.0)
        } else {
            s
        }
    }
}

/// Padded range of finite values.
fn range(vals: impl IntoIterator<Item = f64>) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in vals.into_iter().filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    let pad = if hi > lo { 0.05 * (hi - lo) } else { 0.5 };
    (lo - pad, hi + pad)
}

fn controllers(cl: &BTreeMap<String, Vec<Run>>) -> Vec<(&'static str, RGBColor, &Run)> {
    [
        ("MPC", "mpc", MPC_COLOR),
        ("nominal net", "nominal", NOM_COLOR),
        ("regularized net", "regularized", REG_COLOR),
    ]
    .into_iter()
    .filter_map(|(label, key, c)| cl.get(key).and_then(|v| v.first()).map(|r| (label, c, r)))
    .collect()
}

/// Fig. 1: states and inputs over time from the reference initial state.
pub fn trajectories(p: &PlotInputs) -> Result<Figure, PlotError> {
    const NAME: &str = "trajectories";
    register_font();
    let cfg = p.cfg;
    let runs = controllers(p.closed_loop);
    let Some((_, _, first)) = runs.first() else {
        return Err(PlotError::Data {
            figure: NAME.into(),
            cause: "closed_loop.json holds no `mpc`/`nominal`/`regularized` run".into(),
        });
    };
    let (nx, nu) = (cfg.system.nx(), cfg.system.nu());
    let (xnames, unames) = axis_names(&cfg.system);
    let ts = cfg.ocp.ts;
    let t_end = first.steps as f64 * ts;
    let panels = nx + nu;
    let (w, h) = (900u32, 60 + 230 * panels as u32);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_err(NAME))?;
        let root = root
            .titled(
                &format!(
                    "Closed loop from x₀ = {} ({} steps, Ts = {} s)",
                    fmt_vec(&first.x0),
                    first.steps,
                    ts
                ),
                (FONT, 22),
            )
            .map_err(draw_err(NAME))?;
        let areas = root.split_evenly((panels, 1));
        for (row, area) in areas.iter().enumerate() {
            let (is_u, idx) = if row < nx {
                (false, row)
            } else {
                (true, row - nx)
            };
            let series = |r: &Run| -> Vec<(f64, f64)> {
                if is_u {
                    r.u.iter()
                        .enumerate()
                        .map(|(k, u)| (k as f64 * ts, u[idx]))
                        .collect()
                } else {
                    r.x.iter()
                        .enumerate()
                        .map(|(k, x)| (k as f64 * ts, x[idx]))
                        .collect()
                }
            };
            let (blo, bhi) = if is_u {
                (cfg.ocp.u_lo[idx], cfg.ocp.u_hi[idx])
            } else {
                (cfg.ocp.x_lo[idx], cfg.ocp.x_hi[idx])
            };
            let (ylo, yhi) = range(
                runs.iter()
                    .flat_map(|(_, _, r)| series(r).into_iter().map(|p| p.1))
                    .chain([blo, bhi]),
            );
            let mut chart = ChartBuilder::on(area)
                .margin(8)
                .x_label_area_size(40)
                .y_label_area_size(75)
                .build_cartesian_2d(0.0..t_end, ylo..yhi)
                .map_err(draw_err(NAME))?;
            let yfmt = tick_fmt(yhi - ylo);
            chart
                .configure_mesh()
                .x_desc("t [s]")
                .y_label_formatter(&yfmt)
                .y_desc(if is_u { &unames[idx] } else { &xnames[idx] })
                .axis_desc_style((FONT, 17))
                .label_style((FONT, 14))
                .light_line_style(TRANSPARENT)
                .draw()
                .map_err(draw_err(NAME))?;
            for b in [blo, bhi].into_iter().filter(|b| b.is_finite()) {
                chart
                    .draw_series(DashedLineSeries::new(
                        vec![(0.0, b), (t_end, b)],
                        8,
                        5,
                        BOUND_COLOR.stroke_width(2),
                    ))
                    .map_err(draw_err(NAME))?;
            }
            for (label, color, r) in &runs {
                let s = chart
                    .draw_series(LineSeries::new(series(r), color.stroke_width(2)))
                    .map_err(draw_err(NAME))?;
                if row == 0 {
                    let c = *color;
                    s.label(*label).legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 22, y)], c.stroke_width(2))
                    });
                }
            }
            if row == 0 {
                chart
                    .draw_series(DashedLineSeries::new(
                        Vec::<(f64, f64)>::new(),
                        8,
                        5,
                        BOUND_COLOR.stroke_width(2),
                    ))
                    .map_err(draw_err(NAME))?
                    .label("bound")
                    .legend(|(x, y)| {
                        PathElement::new(vec![(x, y), (x + 22, y)], BOUND_COLOR.stroke_width(2))
                    });
                chart
                    .configure_series_labels()
                    .position(SeriesLabelPosition::UpperLeft)
                    .label_font((FONT, 15))
                    .background_style(WHITE.mix(0.85))
                    .border_style(BLACK)
                    .draw()
                    .map_err(draw_err(NAME))?;
            }
        }
        root.present().map_err(draw_err(NAME))?;
    }
    Ok(Figure {
        name: NAME,
        caption: format!(
            "Closed-loop trajectories of the MPC and both nets from x₀ = {}; dashed: state and input bounds.",
            fmt_vec(&first.x0)
        ),
        svg,
    })
}

fn fmt_vec(v: &[f64]) -> String {
    let parts: Vec<String> = v.iter().map(|x| format!("{x:.3}")).collect();
    format!("({})", parts.join(", "))
}

/// Quartiles for a box plot: (min, q1, median, q3, max).
pub fn five_numbers(v: &[f64]) -> Option<[f64; 5]> {
    let mut s: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    if s.is_empty() {
        return None;
    }
    s.sort_by(f64::total_cmp);
    let q = |p: f64| {
        let pos = p * (s.len() - 1) as f64;
        let (i, f) = (pos.floor() as usize, pos - pos.floor());
        s[i] + f * (s[(i + 1).min(s.len() - 1)] - s[i])
    };
    Some([s[0], q(0.25), q(0.5), q(0.75), s[s.len() - 1]])
}

/// Per-step violations > tolerance of a run.
fn violations(cfg: &ProblemConfig, r: &Run) -> Vec<f64> {
    r.x.iter()
        .skip(1)
        .map(|x| {
            x.iter()
                .enumerate()
                .map(|(i, v)| (v - cfg.ocp.x_hi[i]).max(cfg.ocp.x_lo[i] - v).max(0.0))
                .fold(0.0f64, f64::max)
        })
        .filter(|v| *v > VIOLATION_TOL)
        .collect()
}

/// Fig. 2: box plots, nominal vs regularized.
pub fn error_boxes(p: &PlotInputs) -> Result<Figure, PlotError> {
    const NAME: &str = "errors";
    register_font();
    let nets = [
        ("nominal", p.nominal, NOM_COLOR),
        ("regularized", p.regularized, REG_COLOR),
    ];
    // Initial-state runs only (nominal plant, no noise): the ones Table II reports.
    let runs = |k: &str| p.closed_loop.get(k).cloned().unwrap_or_default();
    let panels: Vec<(String, String, Vec<Vec<f64>>)> = vec![
        (
            format!("dataset ({} points)", p.train.len()),
            "‖κ − κ_NN‖ [N·m]".into(),
            nets.iter()
                .map(|(_, m, _)| errors(&m.mlp, p.train).0)
                .collect(),
        ),
        (
            format!("validation ({} random states)", p.validation.len()),
            "‖κ − κ_NN‖ [N·m]".into(),
            nets.iter()
                .map(|(_, m, _)| errors(&m.mlp, p.validation).0)
                .collect(),
        ),
        (
            "input divergence along trajectories".into(),
            "‖κ(x_k) − κ_NN(x_k)‖ [N·m]".into(),
            nets.iter()
                .map(|(k, _, _)| runs(k).iter().flat_map(|r| r.divergence.clone()).collect())
                .collect(),
        ),
        (
            "state-bound violations (violating steps)".into(),
            "violation".into(),
            nets.iter()
                .map(|(k, _, _)| runs(k).iter().flat_map(|r| violations(p.cfg, r)).collect())
                .collect(),
        ),
    ];
    let (_, unames) = axis_names(&p.cfg.system);
    let unit = unames
        .first()
        .and_then(|s| s.split('[').nth(1))
        .map(|s| format!("[{s}"))
        .unwrap_or_default();
    let n_runs = runs("nominal").len();
    let (w, h) = (1000u32, 760u32);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_err(NAME))?;
        let root = root
            .titled("Nominal vs sensitivity-regularized net", (FONT, 22))
            .map_err(draw_err(NAME))?;
        let areas = root.split_evenly((2, 2));
        for (area, (title, ylabel, data)) in areas.iter().zip(&panels) {
            let ylabel = ylabel.replace("[N·m]", &unit);
            let (_, yhi) = range(data.iter().flatten().copied().chain([0.0]));
            let mut chart = ChartBuilder::on(area)
                .caption(title, (FONT, 17))
                .margin(10)
                .x_label_area_size(35)
                .y_label_area_size(75)
                .build_cartesian_2d(-0.5f64..1.7, 0.0..yhi.max(1e-9))
                .map_err(draw_err(NAME))?;
            let ticks = [
                format!("nominal (n = {})", data[0].len()),
                format!("regularized (n = {})", data[1].len()),
            ];
            chart
                .configure_mesh()
                .disable_x_mesh()
                .x_labels(2)
                .x_label_formatter(&|x| {
                    if (x - 0.0).abs() < 0.25 {
                        ticks[0].clone()
                    } else if (x - 1.0).abs() < 0.25 {
                        ticks[1].clone()
                    } else {
                        String::new()
                    }
                })
                .y_desc(ylabel)
                .axis_desc_style((FONT, 16))
                .label_style((FONT, 14))
                .light_line_style(TRANSPARENT)
                .draw()
                .map_err(draw_err(NAME))?;
            for (i, (vals, (_, _, color))) in data.iter().zip(&nets).enumerate() {
                let x = i as f64;
                let Some([mn, q1, md, q3, mx]) = five_numbers(vals) else {
                    chart
                        .draw_series(std::iter::once(Text::new(
                            "none",
                            (x - 0.1, 0.5 * yhi),
                            (FONT, 15),
                        )))
                        .map_err(draw_err(NAME))?;
                    continue;
                };
                let c = *color;
                let hw = 0.22;
                chart
                    .draw_series([
                        Rectangle::new([(x - hw, q1), (x + hw, q3)], c.mix(0.25).filled()),
                        Rectangle::new([(x - hw, q1), (x + hw, q3)], c.stroke_width(2)),
                    ])
                    .map_err(draw_err(NAME))?;
                let seg = |a: (f64, f64), b: (f64, f64), wdt: u32| {
                    PathElement::new(vec![a, b], c.stroke_width(wdt))
                };
                chart
                    .draw_series([
                        seg((x - hw, md), (x + hw, md), 3),
                        seg((x, q3), (x, mx), 2),
                        seg((x, q1), (x, mn), 2),
                        seg((x - 0.1, mx), (x + 0.1, mx), 2),
                        seg((x - 0.1, mn), (x + 0.1, mn), 2),
                    ])
                    .map_err(draw_err(NAME))?;
                chart
                    .draw_series(std::iter::once(Text::new(
                        format!("max {mx:.3}"),
                        (x + 0.12, mx),
                        (FONT, 13).into_font().color(&BLACK),
                    )))
                    .map_err(draw_err(NAME))?;
            }
        }
        root.present().map_err(draw_err(NAME))?;
    }
    Ok(Figure {
        name: NAME,
        caption: format!(
            "Box plots (box: quartiles, bar: median, whiskers: min and max) of the approximation error on the dataset and the validation states, the input divergence along the closed-loop trajectories from the {n_runs} initial states, and the state-bound violations of their violating steps."
        ),
        svg,
    })
}

/// Viridis colour map, `t` in [0, 1].
pub fn viridis(t: f64) -> RGBColor {
    const STOPS: [(f64, [f64; 3]); 6] = [
        (0.0, [68.0, 1.0, 84.0]),
        (0.2, [65.0, 68.0, 135.0]),
        (0.4, [42.0, 120.0, 142.0]),
        (0.6, [34.0, 168.0, 132.0]),
        (0.8, [122.0, 209.0, 81.0]),
        (1.0, [253.0, 231.0, 37.0]),
    ];
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let k = STOPS
        .windows(2)
        .position(|w| t <= w[1].0)
        .unwrap_or(STOPS.len() - 2);
    let ((t0, a), (t1, b)) = (STOPS[k], STOPS[k + 1]);
    let f = (t - t0) / (t1 - t0);
    let c = |i: usize| (a[i] + f * (b[i] - a[i])).round() as u8;
    RGBColor(c(0), c(1), c(2))
}

/// Heat map of ‖κ − κ_NN‖ (regularized net) over the first two axes of X.
pub fn error_map(p: &PlotInputs) -> Result<Figure, PlotError> {
    const NAME: &str = "error_map";
    register_font();
    let g = p.grid;
    if g.err.len() != g.counts[0] * g.counts[1] || g.err.is_empty() {
        return Err(PlotError::Data {
            figure: NAME.into(),
            cause: format!(
                "grid has {} values for {} × {} points",
                g.err.len(),
                g.counts[0],
                g.counts[1]
            ),
        });
    }
    let (xnames, _) = axis_names(&p.cfg.system);
    let emax = g
        .err
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .fold(0.0f64, f64::max)
        .max(1e-12);
    let step = |a: usize| {
        if g.counts[a] > 1 {
            (g.hi[a] - g.lo[a]) / (g.counts[a] - 1) as f64
        } else {
            g.hi[a] - g.lo[a]
        }
    };
    let (hx, hy) = (step(0), step(1));
    let (w, h) = (1000u32, 560u32);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_err(NAME))?;
        let (main, bar) = root.split_horizontally(w - 130);
        let mut chart = ChartBuilder::on(&main)
            .caption(
                "‖κ(x) − κ_NN(x)‖ of the regularized net (MPC labels on a grid)",
                (FONT, 19),
            )
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(70)
            .build_cartesian_2d(g.lo[0]..g.hi[0], g.lo[1]..g.hi[1])
            .map_err(draw_err(NAME))?;
        chart
            .configure_mesh()
            .disable_mesh()
            .x_desc(xnames[0].as_str())
            .y_desc(xnames[1].as_str())
            .axis_desc_style((FONT, 17))
            .label_style((FONT, 14))
            .draw()
            .map_err(draw_err(NAME))?;
        let cells = (0..g.err.len()).map(|k| {
            let (i, j) = (k % g.counts[0], k / g.counts[0]);
            let x = g.lo[0] + hx * i as f64;
            let y = g.lo[1] + hy * j as f64;
            // Cells overlap by 12 % (plotters rounds to whole pixels) so that anti-aliasing leaves no seams between them.
            let (x0, x1) = ((x - 0.56 * hx).max(g.lo[0]), (x + 0.56 * hx).min(g.hi[0]));
            let (y0, y1) = ((y - 0.56 * hy).max(g.lo[1]), (y + 0.56 * hy).min(g.hi[1]));
            let e = g.err[k];
            let color = if e.is_finite() {
                viridis(e / emax)
            } else {
                RGBColor(200, 200, 200)
            };
            Rectangle::new([(x0, y0), (x1, y1)], color.filled())
        });
        chart.draw_series(cells).map_err(draw_err(NAME))?;
        let n = p.train.len();
        let nx = p.train.nx;
        chart
            .draw_series((0..n).map(|i| {
                let x = &p.train.x[i * nx..i * nx + 2];
                Circle::new((x[0], x[1]), 3, WHITE.stroke_width(1))
            }))
            .map_err(draw_err(NAME))?
            .label(format!("dataset points ({n})"))
            .legend(|(x, y)| Circle::new((x + 10, y), 3, WHITE.stroke_width(1)));
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .label_font((FONT, 14).into_font().color(&WHITE))
            .background_style(RGBColor(40, 40, 40).mix(0.8))
            .draw()
            .map_err(draw_err(NAME))?;
        // Colour bar.
        let mut cb = ChartBuilder::on(&bar)
            .margin_top(45)
            .margin_bottom(57)
            .margin_right(10)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..1.0, 0.0..emax)
            .map_err(draw_err(NAME))?;
        cb.configure_mesh()
            .disable_mesh()
            .disable_x_axis()
            .y_desc(format!(
                "‖κ − κ_NN‖ {}",
                axis_names(&p.cfg.system)
                    .1
                    .first()
                    .and_then(|s| s.split('[').nth(1))
                    .map(|s| format!("[{s}"))
                    .unwrap_or_default()
            ))
            .axis_desc_style((FONT, 15))
            .label_style((FONT, 13))
            .draw()
            .map_err(draw_err(NAME))?;
        let nb = 100;
        cb.draw_series((0..nb).map(|k| {
            let (a, b) = (k as f64 / nb as f64, (k as f64 + 1.3) / nb as f64);
            Rectangle::new(
                [(0.0, a * emax), (1.0, b.min(1.0) * emax)],
                viridis(a).filled(),
            )
        }))
        .map_err(draw_err(NAME))?;
        root.present().map_err(draw_err(NAME))?;
    }
    let unlabelled = g.err.iter().filter(|v| !v.is_finite()).count();
    let slice = if p.cfg.system.nx() > 2 {
        " (a slice: the other state coordinates at the centre of X)"
    } else {
        ""
    };
    Ok(Figure {
        name: NAME,
        caption: format!(
            "‖κ − κ_NN‖ of the regularized net on a {} × {} grid over X{slice}, largest {:.4}; {} grid states without an MPC label (grey); white circles: the training data.",
            g.counts[0], g.counts[1], emax, unlabelled
        ),
        svg,
    })
}

/// Training curves: loss terms, ε_D and validation R² per logged epoch.
pub fn training_curves(p: &PlotInputs) -> Result<Figure, PlotError> {
    const NAME: &str = "training";
    register_font();
    let nets = [
        ("nominal", p.nominal, NOM_COLOR),
        ("regularized", p.regularized, REG_COLOR),
    ];
    if nets.iter().any(|(_, m, _)| m.history.is_empty()) {
        return Err(PlotError::Data {
            figure: NAME.into(),
            cause: "a model has no training history".into(),
        });
    }
    let emax = nets
        .iter()
        .flat_map(|(_, m, _)| m.history.iter().map(|l| l.epoch))
        .max()
        .unwrap_or(1) as f64;
    let (w, h) = (1000u32, 900u32);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_err(NAME))?;
        let root = root
            .titled(
                "Training curves (full training set, logged epochs)",
                (FONT, 22),
            )
            .map_err(draw_err(NAME))?;
        let areas = root.split_evenly((3, 1));
        // Loss terms, log scale. The nominal net's loss is its value term alone.
        type Term = (&'static str, fn(&crate::learn::train::EpochLog) -> f64);
        let terms: [Term; 4] = [
            ("total", |l| l.loss.total()),
            ("λ₁·MSE", |l| l.loss.value),
            ("λ₂·Jacobian", |l| l.loss.jacobian),
            ("λ₃·weights", |l| l.loss.weights),
        ];
        let pos = |v: f64| v.is_finite() && v > 0.0;
        let all: Vec<f64> = nets
            .iter()
            .flat_map(|(_, m, _)| {
                m.history
                    .iter()
                    .flat_map(|l| terms.iter().map(move |t| (t.1)(l)))
            })
            .filter(|v| pos(*v))
            .collect();
        let lmin = all.iter().copied().fold(f64::INFINITY, f64::min);
        let lmax = all.iter().copied().fold(0.0f64, f64::max);
        // Head room above the curves for the legend.
        let (lmin, lmax) = if lmin.is_finite() && lmax > lmin {
            (lmin * 0.7, lmax * 500.0)
        } else {
            (1e-6, 1.0)
        };
        let mut chart = ChartBuilder::on(&areas[0])
            .caption("loss terms on the training set", (FONT, 16))
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(75)
            .build_cartesian_2d(0.0..emax, (lmin..lmax).log_scale())
            .map_err(draw_err(NAME))?;
        chart
            .configure_mesh()
            .x_desc("epoch")
            .y_desc("loss term")
            .x_label_formatter(&|v| format!("{v:.0}"))
            .y_label_formatter(&|v| format!("{v:.0e}"))
            .axis_desc_style((FONT, 16))
            .label_style((FONT, 13))
            .light_line_style(TRANSPARENT)
            .draw()
            .map_err(draw_err(NAME))?;
        let term_colors = [
            REG_COLOR,
            REG_COLOR,
            RGBColor(204, 121, 167),
            RGBColor(0, 158, 115),
        ];
        for (name, m, color) in &nets {
            for (ti, (tname, f)) in terms.iter().enumerate() {
                let nominal = *name == "nominal";
                if nominal && ti > 0 {
                    continue;
                }
                let pts: Vec<(f64, f64)> = m
                    .history
                    .iter()
                    .map(|l| (l.epoch as f64, f(l)))
                    .filter(|p| pos(p.1))
                    .collect();
                if pts.is_empty() {
                    continue;
                }
                let c = if nominal { *color } else { term_colors[ti] };
                let style = c.stroke_width(if ti == 0 { 3 } else { 2 });
                let label = if nominal {
                    format!("{name}: total = λ₁·MSE")
                } else {
                    format!("{name}: {tname}")
                };
                let anno = if ti == 1 {
                    chart
                        .draw_series(DashedLineSeries::new(pts, 6, 4, style))
                        .map_err(draw_err(NAME))?
                } else {
                    chart
                        .draw_series(LineSeries::new(pts, style))
                        .map_err(draw_err(NAME))?
                };
                let dashed = ti == 1;
                anno.label(label).legend(move |(x, y)| {
                    if dashed {
                        PathElement::new(vec![(x, y), (x + 8, y)], style)
                    } else {
                        PathElement::new(vec![(x, y), (x + 22, y)], style)
                    }
                });
            }
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .label_font((FONT, 13))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()
            .map_err(draw_err(NAME))?;
        // ε_D and R².
        type Metric = (
            &'static str,
            &'static str,
            fn(&crate::learn::train::EpochLog) -> f64,
        );
        let metrics: [Metric; 2] = [
            ("ε_D (max error on the dataset)", "ε_D", |l| l.eps_d),
            ("R² on the validation states", "validation R²", |l| {
                l.r2_validation
            }),
        ];
        for (area, (title, ylabel, f)) in areas[1..].iter().zip(metrics) {
            let vals: Vec<f64> = nets
                .iter()
                .flat_map(|(_, m, _)| m.history.iter().map(f))
                .collect();
            let (mut ylo, mut yhi) = range(vals.iter().copied());
            if ylabel == "validation R²" {
                yhi = yhi.min(1.0);
                // Early epochs can have a very negative R²: show the informative range.
                let last_min = nets
                    .iter()
                    .filter_map(|(_, m, _)| m.history.last().map(f))
                    .fold(f64::INFINITY, f64::min);
                ylo = ylo.max(last_min - 0.5 * (1.0 - last_min).max(0.02));
            }
            let mut chart = ChartBuilder::on(area)
                .caption(title, (FONT, 16))
                .margin(10)
                .x_label_area_size(40)
                .y_label_area_size(75)
                .build_cartesian_2d(0.0..emax, ylo..yhi)
                .map_err(draw_err(NAME))?;
            chart
                .configure_mesh()
                .x_desc("epoch")
                .x_label_formatter(&|v| format!("{v:.0}"))
                .y_desc(ylabel)
                .axis_desc_style((FONT, 16))
                .label_style((FONT, 13))
                .light_line_style(TRANSPARENT)
                .draw()
                .map_err(draw_err(NAME))?;
            for (name, m, color) in &nets {
                let c = *color;
                chart
                    .draw_series(LineSeries::new(
                        m.history
                            .iter()
                            .map(|l| (l.epoch as f64, f(l)))
                            .filter(|p| p.1.is_finite() && p.1 >= ylo),
                        c.stroke_width(2),
                    ))
                    .map_err(draw_err(NAME))?
                    .label(*name)
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 22, y)], c.stroke_width(2))
                    });
            }
            chart
                .configure_series_labels()
                .position(SeriesLabelPosition::UpperRight)
                .label_font((FONT, 13))
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .draw()
                .map_err(draw_err(NAME))?;
        }
        root.present().map_err(draw_err(NAME))?;
    }
    Ok(Figure {
        name: NAME,
        caption: format!(
            "Training curves over {} epochs (logged every {}): loss terms on the whole training set (log scale), ε_D and validation R².",
            emax, p.regularized.settings.log_every
        ),
        svg,
    })
}

/// All figures, in report order.
pub fn all(p: &PlotInputs) -> Result<Vec<Figure>, PlotError> {
    Ok(vec![
        trajectories(p)?,
        error_boxes(p)?,
        error_map(p)?,
        training_curves(p)?,
    ])
}

/// Rasterises an SVG document to PNG at `scale` × its size, with the embedded font.
pub fn to_png(figure: &str, svg: &str, scale: f32) -> Result<Vec<u8>, PlotError> {
    use resvg::{tiny_skia, usvg};
    let err = |cause: String| PlotError::Raster {
        figure: figure.to_string(),
        cause,
    };
    let mut db = usvg::fontdb::Database::new();
    db.load_font_data(dejavu::sans::regular().to_vec());
    db.load_font_data(dejavu::sans::bold().to_vec());
    db.set_sans_serif_family("DejaVu Sans");
    let opt = usvg::Options {
        font_family: "DejaVu Sans".into(),
        fontdb: std::sync::Arc::new(db),
        ..Default::default()
    };
    let tree = usvg::Tree::from_str(svg, &opt).map_err(|e| err(e.to_string()))?;
    let size = tree
        .size()
        .to_int_size()
        .scale_by(scale)
        .ok_or_else(|| err(format!("cannot scale {:?} by {scale}", tree.size())))?;
    let mut pix = tiny_skia::Pixmap::new(size.width(), size.height())
        .ok_or_else(|| err(format!("empty image {size:?}")))?;
    pix.fill(tiny_skia::Color::WHITE);
    resvg::render(
        &tree,
        tiny_skia::Transform::from_scale(scale, scale),
        &mut pix.as_mut(),
    );
    pix.encode_png().map_err(|e| err(e.to_string()))
}

/// The local certificate over X: ε_C per cell (left, colour scale up to max(target, max ε_C))
/// and the term that binds in each cell (right).
pub fn eps_map(cfg: &ProblemConfig, cells: &[CellView], target: f64) -> Result<Figure, PlotError> {
    const NAME: &str = "eps_map";
    register_font();
    if cells.is_empty() || cfg.system.nx() < 2 {
        return Err(PlotError::Data {
            figure: NAME.into(),
            cause: "no cells, or a one-dimensional state".into(),
        });
    }
    let (xnames, unames) = axis_names(&cfg.system);
    let unit = unames
        .first()
        .and_then(|s| s.split('[').nth(1))
        .map(|s| format!("[{s}"))
        .unwrap_or_default();
    let emax = cells
        .iter()
        .map(|c| c.eps)
        .filter(|v| v.is_finite())
        .fold(target, f64::max);
    let (lo, hi) = (&cfg.domain.lo, &cfg.domain.hi);
    let (w, h) = (1500u32, 560u32);
    let mut svg = String::new();
    let bind_colors = [
        ("fit at the corners", RGBColor(230, 159, 0)),
        ("first-order remainder", RGBColor(0, 114, 178)),
        ("second-order remainder", RGBColor(0, 158, 115)),
    ];
    {
        let root = SVGBackend::with_string(&mut svg, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_err(NAME))?;
        let (left, right) = root.split_horizontally(800);
        let (main, bar) = left.split_horizontally(800 - 110);
        let n = cells.len();
        let over = cells
            .iter()
            .filter(|c| c.eps > target || c.eps.is_nan())
            .count();
        for (panel, title) in [
            (
                &main,
                format!("ε_C per cell ({n} cells, {over} above the target {target})"),
            ),
            (&right, "which term of ε_C binds".to_string()),
        ] {
            let mut chart = ChartBuilder::on(panel)
                .caption(title, (FONT, 18))
                .margin(12)
                .x_label_area_size(45)
                .y_label_area_size(65)
                .build_cartesian_2d(lo[0]..hi[0], lo[1]..hi[1])
                .map_err(draw_err(NAME))?;
            chart
                .configure_mesh()
                .disable_mesh()
                .x_desc(xnames[0].as_str())
                .y_desc(xnames[1].as_str())
                .axis_desc_style((FONT, 17))
                .label_style((FONT, 14))
                .draw()
                .map_err(draw_err(NAME))?;
            let heat = std::ptr::eq(panel, &main);
            chart
                .draw_series(cells.iter().map(|c| {
                    let color = if heat {
                        if c.eps.is_finite() {
                            viridis(c.eps / emax)
                        } else {
                            RGBColor(200, 200, 200)
                        }
                    } else {
                        bind_colors[c.binding.min(2) as usize].1
                    };
                    // A slight overlap: anti-aliasing would leave seams between cells.
                    let (ox, oy) = (1e-3 * (hi[0] - lo[0]), 1e-3 * (hi[1] - lo[1]));
                    Rectangle::new(
                        [
                            ((c.lo[0] - ox).max(lo[0]), (c.lo[1] - oy).max(lo[1])),
                            ((c.hi[0] + ox).min(hi[0]), (c.hi[1] + oy).min(hi[1])),
                        ],
                        color.filled(),
                    )
                }))
                .map_err(draw_err(NAME))?;
            if !heat {
                for (label, color) in bind_colors {
                    chart
                        .draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())
                        .map_err(draw_err(NAME))?
                        .label(label)
                        .legend(move |(x, y)| {
                            Rectangle::new([(x, y - 6), (x + 14, y + 6)], color.filled())
                        });
                }
                chart
                    .configure_series_labels()
                    .position(SeriesLabelPosition::UpperRight)
                    .label_font((FONT, 14))
                    .background_style(WHITE.mix(0.85))
                    .border_style(BLACK)
                    .draw()
                    .map_err(draw_err(NAME))?;
            }
        }
        let mut cb = ChartBuilder::on(&bar)
            .margin_top(45)
            .margin_bottom(57)
            .margin_right(10)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..1.0, 0.0..emax)
            .map_err(draw_err(NAME))?;
        cb.configure_mesh()
            .disable_mesh()
            .disable_x_axis()
            .y_desc(format!("ε_C {unit}"))
            .axis_desc_style((FONT, 15))
            .label_style((FONT, 13))
            .draw()
            .map_err(draw_err(NAME))?;
        let nb = 100;
        cb.draw_series((0..nb).map(|k| {
            let (a, b) = (k as f64 / nb as f64, (k as f64 + 1.3) / nb as f64);
            Rectangle::new(
                [(0.0, a * emax), (1.0, b.min(1.0) * emax)],
                viridis(a).filled(),
            )
        }))
        .map_err(draw_err(NAME))?;
        root.present().map_err(draw_err(NAME))?;
    }
    let slice = if cfg.system.nx() > 2 {
        " (projected on the first two state axes)"
    } else {
        ""
    };
    Ok(Figure {
        name: NAME,
        caption: format!(
            "Local certificate over X{slice}: ε_C of each of the {} cells (max {:.4}, target {target}) and the binding term.",
            cells.len(),
            cells.iter().map(|c| c.eps).fold(0.0, f64::max),
        ),
        svg,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn five_numbers_interpolate_quartiles() {
        assert_eq!(
            five_numbers(&[4.0, 0.0, 2.0, 1.0, 3.0, f64::NAN]),
            Some([0.0, 1.0, 2.0, 3.0, 4.0])
        );
        assert_eq!(five_numbers(&[1.0, 2.0]), Some([1.0, 1.25, 1.5, 1.75, 2.0]));
        assert_eq!(five_numbers(&[f64::NAN]), None);
    }

    #[test]
    fn tick_labels_have_no_negative_zero() {
        let f = tick_fmt(2.0);
        assert_eq!(f(&-0.00001), "0.0");
        assert_eq!(f(&-0.25), "-0.2");
        assert_eq!(tick_fmt(30.0)(&-4.0), "-4");
        assert_eq!(tick_fmt(0.05)(&0.0123), "0.012");
    }

    #[test]
    fn viridis_ends_and_clamps() {
        assert_eq!(viridis(0.0), RGBColor(68, 1, 84));
        assert_eq!(viridis(1.0), RGBColor(253, 231, 37));
        assert_eq!(viridis(2.0), viridis(1.0));
        assert_eq!(viridis(f64::NAN), viridis(0.0));
    }

    /// Text is rasterised with the embedded font: an SVG holding only text renders dark
    /// pixels, and the PNG has the SVG's size × the scale.
    #[test]
    fn text_renders_with_the_embedded_font() {
        let svg = r#"<svg width="120" height="40" viewBox="0 0 120 40" xmlns="http://www.w3.org/2000/svg"><text x="5" y="28" font-family="sans-serif" font-size="24">κ x₁ 1.5</text></svg>"#;
        let png = to_png("t", svg, 2.0).unwrap();
        let pix = resvg::tiny_skia::Pixmap::decode_png(&png).unwrap();
        assert_eq!((pix.width(), pix.height()), (240, 80));
        let dark = pix.pixels().iter().filter(|p| p.red() < 100).count();
        assert!(dark > 200, "{dark} dark pixels: no text drawn");
        assert!(to_png("t", "<svg", 1.0).is_err());
    }
}
