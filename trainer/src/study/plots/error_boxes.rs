//! Fig. 2, `plots/errors`: box plots, nominal vs regularized, of ‖κ − κ_NN‖ on the dataset
//! and on the validation states, of the input divergence ‖κ(x_k) − κ_NN(x_k)‖ along the
//! closed-loop trajectories, and of the state-bound violations of the violating steps.
//!
//! Owns the figure's four panels (what each shows, `Panel`), the per-step violations of
//! a run (`violations`) and the drawing of one box.

use super::{
    draw_err, five_numbers, input_unit, nets, range, register_font, Figure, Net, PlotError,
    PlotInputs, FONT,
};
use crate::learn::train::errors;
use crate::problem::ProblemConfig;
use crate::study::closed_loop::{step_violation, Run, VIOLATION_TOL};
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;

/// The figure's file stem.
const NAME: &str = "errors";

/// One box-plot panel.
struct Panel {
    /// Caption above the panel.
    title: String,
    /// y-axis label; `[N·m]` stands for the input's unit.
    ylabel: String,
    /// The values of each net (nominal, regularized).
    data: Vec<Vec<f64>>,
}

/// Fig. 2: box plots, nominal vs regularized.
pub fn error_boxes(p: &PlotInputs) -> Result<Figure, PlotError> {
    register_font();
    let nets = nets(p);
    let panels = panels(p, &nets);
    let unit = input_unit(&p.cfg.system);
    let n_runs = runs(p, "nominal").len();
    let (w, h) = (1000u32, 760u32);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_err(NAME))?;
        let root = root
            .titled("Nominal vs sensitivity-regularized net", (FONT, 22))
            .map_err(draw_err(NAME))?;
        let areas = root.split_evenly((2, 2));
        for (area, panel) in areas.iter().zip(&panels) {
            draw_panel(area, panel, &nets, &unit)?;
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

/// The closed-loop runs of controller `k` from the initial states only (nominal plant, no
/// noise): the ones Table II reports.
fn runs(p: &PlotInputs, k: &str) -> Vec<Run> {
    p.closed_loop.get(k).cloned().unwrap_or_default()
}

/// The four panels: approximation error on the dataset and on the validation states, input
/// divergence along the trajectories, state-bound violations of the violating steps.
fn panels(p: &PlotInputs, nets: &[Net]) -> Vec<Panel> {
    vec![
        Panel {
            title: format!("dataset ({} points)", p.train.len()),
            ylabel: "‖κ − κ_NN‖ [N·m]".into(),
            data: nets
                .iter()
                .map(|(_, m, _)| errors(&m.mlp, p.train).0)
                .collect(),
        },
        Panel {
            title: format!("validation ({} random states)", p.validation.len()),
            ylabel: "‖κ − κ_NN‖ [N·m]".into(),
            data: nets
                .iter()
                .map(|(_, m, _)| errors(&m.mlp, p.validation).0)
                .collect(),
        },
        Panel {
            title: "input divergence along trajectories".into(),
            ylabel: "‖κ(x_k) − κ_NN(x_k)‖ [N·m]".into(),
            data: nets
                .iter()
                .map(|(k, _, _)| {
                    runs(p, k)
                        .iter()
                        .flat_map(|r| r.divergence.clone())
                        .collect()
                })
                .collect(),
        },
        Panel {
            title: "state-bound violations (violating steps)".into(),
            ylabel: "violation".into(),
            data: nets
                .iter()
                .map(|(k, _, _)| {
                    runs(p, k)
                        .iter()
                        .flat_map(|r| violations(p.cfg, r))
                        .collect()
                })
                .collect(),
        },
    ]
}

/// Per-step violations > tolerance of a run (as [`step_violation`] counts them).
fn violations(cfg: &ProblemConfig, r: &Run) -> Vec<f64> {
    let cs = cfg.constraint_set().ok().flatten();
    (0..r.u.len())
        .map(|k| step_violation(cfg, cs.as_ref(), k, &r.x[k], &r.u[k], &r.x[k + 1]))
        .filter(|v| *v > VIOLATION_TOL)
        .collect()
}

/// One panel: axes from 0 to the largest value, a box per net at x = 0, 1.
fn draw_panel(
    area: &DrawingArea<SVGBackend<'_>, Shift>,
    panel: &Panel,
    nets: &[Net],
    unit: &str,
) -> Result<(), PlotError> {
    let data = &panel.data;
    let ylabel = panel.ylabel.replace("[N·m]", unit);
    let (_, yhi) = range(data.iter().flatten().copied().chain([0.0]));
    let mut chart = ChartBuilder::on(area)
        .caption(&panel.title, (FONT, 17))
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
    for (i, (vals, (_, _, color))) in data.iter().zip(nets).enumerate() {
        draw_box(&mut chart, i as f64, vals, *color, yhi)?;
    }
    Ok(())
}

/// The box of `vals` at `x`: quartile box, median bar, min/max whiskers and the maximum's
/// value; "none" (at half of `yhi`) when there is no finite value.
fn draw_box(
    chart: &mut ChartContext<'_, SVGBackend<'_>, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    x: f64,
    vals: &[f64],
    c: RGBColor,
    yhi: f64,
) -> Result<(), PlotError> {
    let Some([mn, q1, md, q3, mx]) = five_numbers(vals) else {
        chart
            .draw_series(std::iter::once(Text::new(
                "none",
                (x - 0.1, 0.5 * yhi),
                (FONT, 15),
            )))
            .map_err(draw_err(NAME))?;
        return Ok(());
    };
    let hw = 0.22;
    chart
        .draw_series([
            Rectangle::new([(x - hw, q1), (x + hw, q3)], c.mix(0.25).filled()),
            Rectangle::new([(x - hw, q1), (x + hw, q3)], c.stroke_width(2)),
        ])
        .map_err(draw_err(NAME))?;
    let seg =
        |a: (f64, f64), b: (f64, f64), wdt: u32| PathElement::new(vec![a, b], c.stroke_width(wdt));
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
    Ok(())
}
