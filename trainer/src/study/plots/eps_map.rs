//! `eps_map` (written by `trainer refine`): the local certificate over the first two axes
//! of X — ε_C per cell as a heat map, and which term of ε_C binds in each cell.

use super::{
    axis_names, colour_bar, draw_err, input_unit, register_font, viridis, Figure, PlotError, FONT,
    MISSING_COLOR,
};
use crate::certify::refine::CellView;
use crate::problem::ProblemConfig;
use plotters::prelude::*;

/// The figure's file stem.
const NAME: &str = "eps_map";

/// The local certificate over X: ε_C per cell (left, colour scale up to max(target, max ε_C))
/// and the term that binds in each cell (right).
pub fn eps_map(cfg: &ProblemConfig, cells: &[CellView], target: f64) -> Result<Figure, PlotError> {
    register_font();
    if cells.is_empty() || cfg.system.nx() < 2 {
        return Err(PlotError::Data {
            figure: NAME.into(),
            cause: "no cells, or a one-dimensional state".into(),
        });
    }
    let (xnames, _) = axis_names(&cfg.system);
    let unit = input_unit(&cfg.system);
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
                            MISSING_COLOR
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
        colour_bar(&bar, emax, format!("ε_C {unit}"), NAME)?;
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
