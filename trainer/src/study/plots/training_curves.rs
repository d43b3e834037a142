//! `plots/training`: the training curves of both nets per logged epoch — the loss terms on
//! the training set (log scale), ε_D and the validation R².

use super::{
    draw_err, nets, range, register_font, Figure, Net, PlotError, PlotInputs, FONT, REG_COLOR,
};
use crate::learn::train::EpochLog;
use plotters::coord::Shift;
use plotters::prelude::*;

/// The figure's file stem.
const NAME: &str = "training";

/// A loss term: legend name and its value in a log entry.
type Term = (&'static str, fn(&EpochLog) -> f64);

/// Loss terms, in legend order. The nominal net's loss is its value term alone.
const TERMS: [Term; 4] = [
    ("total", |l| l.loss.total()),
    ("λ₁·MSE", |l| l.loss.value),
    ("λ₂·Jacobian", |l| l.loss.jacobian),
    ("λ₃·weights", |l| l.loss.weights),
];

/// A metric panel: title, y label and its value in a log entry.
type Metric = (&'static str, &'static str, fn(&EpochLog) -> f64);

/// The panels below the loss terms.
const METRICS: [Metric; 2] = [
    ("ε_D (max error on the dataset)", "ε_D", |l| l.eps_d),
    ("R² on the validation states", "validation R²", |l| {
        l.r2_validation
    }),
];

/// Training curves: loss terms, ε_D and validation R² per logged epoch.
pub fn training_curves(p: &PlotInputs) -> Result<Figure, PlotError> {
    register_font();
    let nets = nets(p);
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
        draw_loss_terms(&areas[0], &nets, emax)?;
        for (area, metric) in areas[1..].iter().zip(METRICS) {
            draw_metric(area, metric, &nets, emax)?;
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

/// A value a log scale can show.
fn positive(v: f64) -> bool {
    v.is_finite() && v > 0.0
}

/// The loss axis: all positive loss terms of both nets, with head room above the curves for
/// the legend.
fn loss_range(nets: &[Net]) -> (f64, f64) {
    let all: Vec<f64> = nets
        .iter()
        .flat_map(|(_, m, _)| {
            m.history
                .iter()
                .flat_map(|l| TERMS.iter().map(move |t| (t.1)(l)))
        })
        .filter(|v| positive(*v))
        .collect();
    let lmin = all.iter().copied().fold(f64::INFINITY, f64::min);
    let lmax = all.iter().copied().fold(0.0f64, f64::max);
    if lmin.is_finite() && lmax > lmin {
        (lmin * 0.7, lmax * 500.0)
    } else {
        (1e-6, 1.0)
    }
}

/// The top panel: every loss term of the regularized net and the nominal net's total, log
/// scale; the MSE term dashed.
fn draw_loss_terms(
    area: &DrawingArea<SVGBackend<'_>, Shift>,
    nets: &[Net],
    emax: f64,
) -> Result<(), PlotError> {
    let (lmin, lmax) = loss_range(nets);
    let mut chart = ChartBuilder::on(area)
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
    for (name, m, color) in nets {
        for (ti, (tname, f)) in TERMS.iter().enumerate() {
            let nominal = *name == "nominal";
            if nominal && ti > 0 {
                continue;
            }
            let pts: Vec<(f64, f64)> = m
                .history
                .iter()
                .map(|l| (l.epoch as f64, f(l)))
                .filter(|p| positive(p.1))
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
    Ok(())
}

/// A metric panel (ε_D or validation R²), one curve per net. R² is cut at 1 and, since
/// early epochs can have a very negative R², below at the informative range.
fn draw_metric(
    area: &DrawingArea<SVGBackend<'_>, Shift>,
    (title, ylabel, f): Metric,
    nets: &[Net],
    emax: f64,
) -> Result<(), PlotError> {
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
    for (name, m, color) in nets {
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
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 22, y)], c.stroke_width(2)));
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .label_font((FONT, 13))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
        .map_err(draw_err(NAME))?;
    Ok(())
}
