//! `plots/error_map`: ‖κ − κ_NN‖ of the regularized net on a grid over two axes of X,
//! dataset points overlaid.
//!
//! Owns [`ErrorGrid`], the MPC labels of that grid, the choice of its plane
//! ([`slice_axes`], [`slice_base`]) and the heat map drawn from it. For nx = 2 the grid
//! covers X. For nx > 2 it is a 2-D slice: the two states along which κ changes most over X,
//! `s_i = mean over the labelled points of ‖∂κ/∂x_i‖₂ · (hi_i − lo_i)` (the change of κ
//! across X along axis i, in units of u: comparable between states of different units),
//! with the other states held at the setpoint x = 0 (clamped into X); figure and caption
//! name the slice.

use super::{
    axis_names, colour_bar, draw_err, input_unit, register_font, viridis, Figure, PlotError,
    PlotInputs, FONT, MISSING_COLOR,
};
use crate::learn::train::TrainSet;
use crate::problem::ProblemConfig;
use plotters::prelude::*;

/// The figure's file stem.
const NAME: &str = "error_map";

/// The two state axes of the error map: `[0, 1]` for nx ≤ 2; for nx > 2 the two with the
/// largest `s_i = mean ‖∂κ/∂x_i‖₂ · (hi_i − lo_i)` over the points with a usable Jacobian
/// label (ties and NaN: the lower index), in increasing order.
pub fn slice_axes(cfg: &ProblemConfig, train: &TrainSet) -> [usize; 2] {
    let nx = train.nx;
    if nx <= 2 {
        return [0, 1];
    }
    top_two(&sensitivity_spread(cfg, train))
}

/// The two axes with the largest score `s` (ties and NaN: the lower index), in increasing
/// order; `[0, 1]` for fewer than three axes.
pub fn top_two(s: &[f64]) -> [usize; 2] {
    let nx = s.len();
    if nx <= 2 {
        return [0, 1];
    }
    let mut order: Vec<usize> = (0..nx).collect();
    // Descending score, NaN last, stable on ties (lower index first).
    order.sort_by(|&a, &b| {
        let key = |i: usize| {
            if s[i].is_nan() {
                f64::NEG_INFINITY
            } else {
                s[i]
            }
        };
        key(b).total_cmp(&key(a))
    });
    let (a, b) = (order[0], order[1]);
    [a.min(b), a.max(b)]
}

/// `s_i = mean ‖∂κ/∂x_i‖₂ · (hi_i − lo_i)` per state over the points of `train` with a
/// usable Jacobian label (NaN for every state if there is none).
pub fn sensitivity_spread(cfg: &ProblemConfig, train: &TrainSet) -> Vec<f64> {
    let (nx, nu) = (train.nx, train.nu);
    let mut sum = vec![0.0; nx];
    let mut n = 0usize;
    for (k, &ok) in train.use_jac.iter().enumerate() {
        if !ok {
            continue;
        }
        let jac = &train.du[k * nu * nx..(k + 1) * nu * nx];
        for (i, s) in sum.iter_mut().enumerate() {
            *s += (0..nu).map(|j| jac[j * nx + i].powi(2)).sum::<f64>().sqrt();
        }
        n += 1;
    }
    sum.iter()
        .enumerate()
        .map(|(i, s)| s / n as f64 * (cfg.domain.hi[i] - cfg.domain.lo[i]))
        .collect()
}

/// The state at which the map's other coordinates are held: the setpoint x_ref (the origin unless `ocp.x_ref` is given) of the
/// OCP's cost, clamped into X.
pub fn slice_base(cfg: &ProblemConfig) -> Vec<f64> {
    let (lo, hi) = (&cfg.domain.lo, &cfg.domain.hi);
    let x_ref = cfg.ocp.x_ref_or_origin(lo.len());
    lo.iter()
        .zip(hi)
        .zip(&x_ref)
        .map(|((l, h), r)| r.clamp(*l, *h))
        .collect()
}

/// MPC labels ‖κ − κ_NN‖ on a grid over two axes of X.
#[derive(Debug, Clone, PartialEq)]
pub struct ErrorGrid {
    /// Points per axis (along `axes[0]` and `axes[1]`).
    pub counts: [usize; 2],
    /// The two state axes of the grid (0-based, increasing).
    pub axes: [usize; 2],
    /// The state whose other coordinates the grid's points share (nx > 2).
    pub base: Vec<f64>,
    /// Lower corner of the plotted rectangle.
    pub lo: [f64; 2],
    /// Upper corner of the plotted rectangle.
    pub hi: [f64; 2],
    /// ‖κ(x) − κ_NN(x)‖ per grid point, axis 0 fastest; NaN where the MPC found no label.
    pub err: Vec<f64>,
}

impl ErrorGrid {
    /// Labels a `counts[0] × counts[1]` grid (endpoints included) over the state axes
    /// `axes` of X with the MPC (cold starts, in parallel: the result does not depend on the
    /// thread count) and evaluates `mlp` there. Other state coordinates are those of
    /// [`slice_base`].
    pub fn label(
        cfg: &ProblemConfig,
        mlp: &crate::learn::mlp::Mlp,
        counts: [usize; 2],
        axes: [usize; 2],
    ) -> Self {
        use rayon::prelude::*;
        let (lo, hi) = (&cfg.domain.lo, &cfg.domain.hi);
        let base = slice_base(cfg);
        // Coordinate i of the grid's axis g (0 or 1), along the state axis axes[g].
        let coord = |g: usize, i: usize| {
            let a = axes[g];
            if counts[g] <= 1 {
                0.5 * (lo[a] + hi[a])
            } else {
                lo[a] + (hi[a] - lo[a]) * i as f64 / (counts[g] - 1) as f64
            }
        };
        if lo.len() < 2 {
            // A one-dimensional state has no map: the figure reports the missing data.
            return ErrorGrid {
                counts,
                axes,
                base,
                lo: [0.0; 2],
                hi: [1.0; 2],
                err: Vec::new(),
            };
        }
        let pts: Vec<Vec<f64>> = (0..counts[0] * counts[1])
            .map(|k| {
                let mut x = base.clone();
                x[axes[0]] = coord(0, k % counts[0]);
                x[axes[1]] = coord(1, k / counts[0]);
                x
            })
            .collect();
        // (The map only shows the error where the MPC labels a point: no retry ladder,
        // whose failing climbs dominated the CSTR's plots stage.)
        let counting = crate::mpc::law::ladder::counting_problem(cfg);
        let err = pts
            .par_iter()
            .map_init(
                || crate::mpc::law::MpcLaw::new(&counting),
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
            axes,
            lo: [lo[axes[0]], lo[axes[1]]],
            hi: [hi[axes[0]], hi[axes[1]]],
            base,
            err,
        }
    }
}

/// Heat map of ‖κ − κ_NN‖ (regularized net) over the grid's two axes of X.
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
    let nx = p.cfg.system.nx();
    let [ax, ay] = g.axes;
    if ax >= nx || ay >= nx || ax == ay || p.train.nx != nx {
        return Err(PlotError::Data {
            figure: NAME.into(),
            cause: format!(
                "grid axes {:?} for {nx} states (training data with {} states)",
                g.axes, p.train.nx
            ),
        });
    }
    // Names without units, for the title and caption of a slice.
    let short = |i: usize| xnames[i].split(" [").next().unwrap_or_default().to_string();
    let title = if nx > 2 {
        format!(
            "‖κ(x) − κ_NN(x)‖ of the regularized net over ({}, {}), other states at the setpoint",
            short(ax),
            short(ay)
        )
    } else {
        "‖κ(x) − κ_NN(x)‖ of the regularized net (MPC labels on a grid)".to_string()
    };
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
            .caption(title.as_str(), (FONT, 19))
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(70)
            .build_cartesian_2d(g.lo[0]..g.hi[0], g.lo[1]..g.hi[1])
            .map_err(draw_err(NAME))?;
        chart
            .configure_mesh()
            .disable_mesh()
            .x_desc(xnames[ax].as_str())
            .y_desc(xnames[ay].as_str())
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
        let tnx = p.train.nx;
        let legend = if nx > 2 {
            format!("dataset points, projected onto the plane ({n})")
        } else {
            format!("dataset points ({n})")
        };
        chart
            .draw_series((0..n).map(|i| {
                let x = &p.train.x[i * tnx..(i + 1) * tnx];
                Circle::new((x[ax], x[ay]), 3, WHITE.stroke_width(1))
            }))
            .map_err(draw_err(NAME))?
            .label(legend)
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
    let slice = if nx > 2 {
        let held: Vec<String> = (0..nx)
            .filter(|i| *i != ax && *i != ay)
            .map(|i| {
                format!(
                    "{} = {}",
                    short(i),
                    g.base.get(i).copied().unwrap_or(f64::NAN)
                )
            })
            .collect();
        format!(
            " (a 2-D slice over {} and {}, the two states along which κ changes most over X — largest mean ‖∂κ/∂x_i‖·(width of X along x_i) over the data; the other states held at the setpoint, clamped into X: {})",
            short(ax),
            short(ay),
            held.join(", ")
        )
    } else {
        String::new()
    };
    Ok(Figure {
        name: NAME,
        caption: format!(
            "‖κ − κ_NN‖ of the regularized net on a {} × {} grid over X{slice}, largest {:.4}; {} grid states without an MPC label (grey); white circles: the training data{}.",
            g.counts[0],
            g.counts[1],
            emax,
            unlabelled,
            if nx > 2 { ", projected onto the plane" } else { "" }
        ),
        svg,
    })
}
