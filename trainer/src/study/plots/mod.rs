//! Figures of a run (the paper's Fig. 1 and Fig. 2, an error map and training curves), as
//! SVG and PNG.
//!
//! This module owns the drawing: it takes data that other stages computed (closed-loop
//! runs, trained models with their training curves, the dataset, MPC labels of a grid) and
//! turns them into SVG text with `plotters`' SVG backend; [`to_png`] rasterises that SVG with
//! `resvg`. Both use the DejaVu Sans font compiled into the binary (no system fonts), so the
//! files are the same on every machine.
//!
//! Figures, one file each:
//! - `trajectories`: x_i(t) and u_j(t) of the MPC and both nets from the reference initial
//!   state, with the state and input bounds (Fig. 1);
//! - `errors` (`error_boxes.rs`): box plots, nominal vs regularized, of ‖κ − κ_NN‖ on the
//!   dataset and on the validation states, of the input divergence ‖κ(x_k) − κ_NN(x_k)‖ along
//!   the closed-loop trajectories, and of the state-bound violations of the violating steps
//!   (Fig. 2);
//! - `error_map`: ‖κ − κ_NN‖ of the regularized net on a grid over X (nx = 2) or, for
//!   nx > 2, over a 2-D slice: the two states along which κ changes most over X, the others
//!   held at the setpoint (named in the figure and its caption), dataset points overlaid;
//! - `training` (`training_curves.rs`): loss terms, ε_D and validation R² per logged epoch;
//! - `eps_map` (`trainer refine`): the local certificate's ε_C per cell over two
//!   axes of X (a slice for nx > 2), and which term of ε_C binds there.
//!
//! This file holds what the figures share: the figure types ([`Figure`], [`FigureEntry`],
//! [`PlotInputs`], [`PlotError`]), the list [`PLOTS`] and [`all`] of them, [`to_png`], and
//! the drawing helpers (colours, font, tick labels, axis ranges, the viridis map and its
//! colour bar, box-plot quartiles).

mod eps_map;
mod error_boxes;
mod error_map;
mod refine_rounds;
mod training_curves;
mod trajectories;

pub use eps_map::eps_map;
pub use error_boxes::error_boxes;
pub use error_map::{error_map, sensitivity_spread, slice_axes, slice_base, ErrorGrid};
pub use refine_rounds::{best_so_far, refine_rounds};
pub use training_curves::training_curves;
pub use trajectories::trajectories;

use crate::certify::Model;
use crate::learn::train::TrainSet;
use crate::problem::model::System;
use crate::problem::ProblemConfig;
use crate::study::closed_loop::Run;
use plotters::coord::Shift;
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
    #[error("rasterising figure `{figure}`: {source}")]
    Raster {
        /// Figure name.
        figure: String,
        /// What failed: the SVG parser's or the PNG encoder's error, or the size at fault.
        source: Box<dyn std::error::Error + Send + Sync>,
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
    let err = |source: Box<dyn std::error::Error + Send + Sync>| PlotError::Raster {
        figure: figure.to_string(),
        source,
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
    let tree = usvg::Tree::from_str(svg, &opt).map_err(|e| err(e.into()))?;
    let size = tree
        .size()
        .to_int_size()
        .scale_by(scale)
        .ok_or_else(|| err(format!("cannot scale {:?} by {scale}", tree.size()).into()))?;
    let mut pix = tiny_skia::Pixmap::new(size.width(), size.height())
        .ok_or_else(|| err(format!("empty image {size:?}").into()))?;
    pix.fill(tiny_skia::Color::WHITE);
    resvg::render(
        &tree,
        tiny_skia::Transform::from_scale(scale, scale),
        &mut pix.as_mut(),
    );
    pix.encode_png().map_err(|e| err(e.into()))
}

const MPC_COLOR: RGBColor = RGBColor(0, 0, 0);
const NOM_COLOR: RGBColor = RGBColor(213, 94, 0);
const REG_COLOR: RGBColor = RGBColor(0, 114, 178);
const BOUND_COLOR: RGBColor = RGBColor(120, 120, 120);
/// Colour of a cell without a value (no MPC label, or a non-finite ε_C).
const MISSING_COLOR: RGBColor = RGBColor(200, 200, 200);
const FONT: &str = "sans-serif";

/// A net of the figures: name (its key in the closed-loop runs), model, colour.
type Net<'a> = (&'static str, &'a Model, RGBColor);

/// The nominal and the regularized net with their colours, in the figures' order.
fn nets<'a>(p: &PlotInputs<'a>) -> [Net<'a>; 2] {
    [
        ("nominal", p.nominal, NOM_COLOR),
        ("regularized", p.regularized, REG_COLOR),
    ]
}

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
        System::Ode(_) | System::Discrete(_) => {
            // The names of the problem file, with their units where given.
            let m = sys.expr_model().expect("an expression plant");
            let label = |n: &String| match m.unit(n) {
                Some(unit) => format!("{n} [{unit}]"),
                None => n.clone(),
            };
            (
                m.state_names().iter().map(label).collect(),
                m.input_names().iter().map(label).collect(),
            )
        }
        // The names the plant's program gave (`x1`, …, `u1`, … if none).
        System::Custom(p) => (p.state_names(), p.input_names()),
    }
}

/// The unit of the first input, `[…]` as in [`axis_names`] (empty if it has none).
fn input_unit(sys: &System) -> String {
    axis_names(sys)
        .1
        .first()
        .and_then(|s| s.split('[').nth(1))
        .map(|s| format!("[{s}"))
        .unwrap_or_default()
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

/// The viridis colour bar of a heat map: values 0..`vmax` on the `bar` area, labelled
/// `desc`.
fn colour_bar(
    bar: &DrawingArea<SVGBackend<'_>, Shift>,
    vmax: f64,
    desc: String,
    figure: &str,
) -> Result<(), PlotError> {
    let mut cb = ChartBuilder::on(bar)
        .margin_top(45)
        .margin_bottom(57)
        .margin_right(10)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..1.0, 0.0..vmax)
        .map_err(draw_err(figure))?;
    cb.configure_mesh()
        .disable_mesh()
        .disable_x_axis()
        .y_desc(desc)
        .axis_desc_style((FONT, 15))
        .label_style((FONT, 13))
        .draw()
        .map_err(draw_err(figure))?;
    let nb = 100;
    cb.draw_series((0..nb).map(|k| {
        let (a, b) = (k as f64 / nb as f64, (k as f64 + 1.3) / nb as f64);
        Rectangle::new(
            [(0.0, a * vmax), (1.0, b.min(1.0) * vmax)],
            viridis(a).filled(),
        )
    }))
    .map_err(draw_err(figure))?;
    Ok(())
}

#[cfg(test)]
mod tests;
