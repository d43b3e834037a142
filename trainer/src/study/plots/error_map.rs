//! `plots/error_map`: ‖κ − κ_NN‖ of the regularized net on a grid over the first two axes
//! of X (other coordinates at the setpoint x_ref if given, else the centre of X), dataset
//! points overlaid.
//!
//! Owns [`ErrorGrid`], the MPC labels of that grid, and the heat map drawn from it.

use super::{
    axis_names, colour_bar, draw_err, input_unit, register_font, viridis, Figure, PlotError,
    PlotInputs, FONT, MISSING_COLOR,
};
use crate::problem::ProblemConfig;
use plotters::prelude::*;

/// The figure's file stem.
const NAME: &str = "error_map";

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
    /// count) and evaluates `mlp` there. Other state coordinates sit at the setpoint
    /// `ocp.x_ref` if the problem states one, else at the centre of X.
    pub fn label(cfg: &ProblemConfig, mlp: &crate::learn::mlp::Mlp, counts: [usize; 2]) -> Self {
        use rayon::prelude::*;
        let (lo, hi) = (&cfg.domain.lo, &cfg.domain.hi);
        let centre: Vec<f64> = match &cfg.ocp.x_ref {
            Some(r) => r.clone(),
            None => lo.iter().zip(hi).map(|(l, h)| 0.5 * (l + h)).collect(),
        };
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

/// Heat map of ‖κ − κ_NN‖ (regularized net) over the first two axes of X.
pub fn error_map(p: &PlotInputs) -> Result<Figure, PlotError> {
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
                MISSING_COLOR
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
        let unit = input_unit(&p.cfg.system);
        colour_bar(&bar, emax, format!("‖κ − κ_NN‖ {unit}"), NAME)?;
        root.present().map_err(draw_err(NAME))?;
    }
    let unlabelled = g.err.iter().filter(|v| !v.is_finite()).count();
    let slice = match (p.cfg.system.nx() > 2, &p.cfg.ocp.x_ref) {
        (false, _) => "",
        (true, Some(_)) => " (a slice: the other state coordinates at the setpoint x_ref)",
        (true, None) => " (a slice: the other state coordinates at the centre of X)",
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
