//! Fig. 1, `plots/trajectories`: x_i(t) and u_j(t) of the MPC and both nets from the
//! reference initial state, one panel per state and input coordinate (in two columns when
//! there are more than 8), with the state and input bounds and, when the problem states a
//! setpoint (`ocp.x_ref`, `ocp.u_ref`), the setpoint as a dotted line.

use super::{
    axis_names, draw_err, range, register_font, tick_fmt, Figure, PlotError, PlotInputs,
    BOUND_COLOR, FONT, MPC_COLOR, NOM_COLOR, REG_COLOR,
};
use crate::study::closed_loop::Run;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::collections::BTreeMap;

/// The figure's file stem.
const NAME: &str = "trajectories";

/// A controller's first run, with its legend label and colour.
type Controller<'a> = (&'static str, RGBColor, &'a Run);

/// Fig. 1: states and inputs over time from the reference initial state.
pub fn trajectories(p: &PlotInputs) -> Result<Figure, PlotError> {
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
    let unit = cfg.system.time_unit();
    let t_end = first.steps as f64 * ts;
    let panels = nx + nu;
    let o = &cfg.ocp;
    let setpoint = (o.x_ref.is_some() || o.u_ref.is_some())
        .then(|| (o.x_ref_or_origin(nx), o.u_ref_or_zero(nu)));
    // One column of panels; two (in reading order) when there are more than 8.
    let cols = if panels > 8 { 2 } else { 1 };
    let rows = panels.div_ceil(cols);
    let (w, h) = (900 * cols as u32, 60 + 230 * rows as u32);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_err(NAME))?;
        let root = root
            .titled(
                &format!(
                    "Closed loop from x₀ = {} ({} steps, Ts = {} {unit})",
                    fmt_vec(&first.x0),
                    first.steps,
                    ts
                ),
                (FONT, 22),
            )
            .map_err(draw_err(NAME))?;
        let areas = root.split_evenly((rows, cols));
        for (row, area) in areas.iter().enumerate().take(panels) {
            let signal = if row < nx {
                Signal {
                    input: false,
                    idx: row,
                    name: &xnames[row],
                    bounds: [cfg.ocp.x_lo[row], cfg.ocp.x_hi[row]],
                    reference: setpoint.as_ref().map(|s| s.0[row]),
                }
            } else {
                let idx = row - nx;
                Signal {
                    input: true,
                    idx,
                    name: &unames[idx],
                    bounds: [cfg.ocp.u_lo[idx], cfg.ocp.u_hi[idx]],
                    reference: setpoint.as_ref().map(|s| s.1[idx]),
                }
            };
            draw_panel(area, &signal, &runs, (ts, unit), t_end, row == 0)?;
        }
        root.present().map_err(draw_err(NAME))?;
    }
    Ok(Figure {
        name: NAME,
        caption: format!(
            "Closed-loop trajectories of the MPC and both nets from x₀ = {}; dashed: state and input bounds{}.",
            fmt_vec(&first.x0),
            setpoint.as_ref().map_or(String::new(), |(x, u)| format!(
                "; dotted: the setpoint x_ref = {}, u_ref = {}",
                fmt_vec(x),
                fmt_vec(u)
            ))
        ),
        svg,
    })
}

/// The first run of each of the MPC and the two nets that `cl` holds.
fn controllers(cl: &BTreeMap<String, Vec<Run>>) -> Vec<Controller<'_>> {
    [
        ("MPC", "mpc", MPC_COLOR),
        ("nominal net", "nominal", NOM_COLOR),
        ("regularized net", "regularized", REG_COLOR),
    ]
    .into_iter()
    .filter_map(|(label, key, c)| cl.get(key).and_then(|v| v.first()).map(|r| (label, c, r)))
    .collect()
}

/// What one panel shows: state or input coordinate `idx`, its axis name and bounds.
struct Signal<'a> {
    /// An input coordinate (else a state coordinate).
    input: bool,
    /// The coordinate.
    idx: usize,
    /// Axis name with unit.
    name: &'a str,
    /// Lower and upper bound (drawn dashed where finite).
    bounds: [f64; 2],
    /// The setpoint's coordinate (drawn dotted), if the problem states one.
    reference: Option<f64>,
}

impl Signal<'_> {
    /// (t, value) along a run.
    fn series(&self, r: &Run, ts: f64) -> Vec<(f64, f64)> {
        if self.input {
            r.u.iter()
                .enumerate()
                .map(|(k, u)| (k as f64 * ts, u[self.idx]))
                .collect()
        } else {
            r.x.iter()
                .enumerate()
                .map(|(k, x)| (k as f64 * ts, x[self.idx]))
                .collect()
        }
    }
}

/// One panel: the signal of every run over [0, `t_end`] and its bounds; the first panel
/// (`legend`) carries the legend.
fn draw_panel(
    area: &DrawingArea<SVGBackend<'_>, Shift>,
    s: &Signal,
    runs: &[Controller],
    (ts, unit): (f64, &str),
    t_end: f64,
    legend: bool,
) -> Result<(), PlotError> {
    let [blo, bhi] = s.bounds;
    let (ylo, yhi) = range(
        runs.iter()
            .flat_map(|(_, _, r)| s.series(r, ts).into_iter().map(|p| p.1))
            .chain([blo, bhi])
            .chain(s.reference),
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
        .x_desc(format!("t [{unit}]"))
        .y_label_formatter(&yfmt)
        .y_desc(s.name)
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
    if let Some(v) = s.reference {
        chart
            .draw_series(DashedLineSeries::new(
                vec![(0.0, v), (t_end, v)],
                2,
                4,
                BLACK.stroke_width(1),
            ))
            .map_err(draw_err(NAME))?;
    }
    for (label, color, r) in runs {
        let series = chart
            .draw_series(LineSeries::new(s.series(r, ts), color.stroke_width(2)))
            .map_err(draw_err(NAME))?;
        if legend {
            let c = *color;
            series.label(*label).legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 22, y)], c.stroke_width(2))
            });
        }
    }
    if legend {
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
    Ok(())
}

fn fmt_vec(v: &[f64]) -> String {
    let parts: Vec<String> = v.iter().map(|x| format!("{x:.3}")).collect();
    format!("({})", parts.join(", "))
}
