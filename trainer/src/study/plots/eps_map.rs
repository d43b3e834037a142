//! `eps_map` (written by `trainer refine`): the local certificate over two axes of X — ε_C
//! per cell as a heat map, and which term of ε_C binds in each cell.
//!
//! For nx = 2 every cell is drawn. For nx > 2 the map is a 2-D slice, chosen as the run's
//! error map chooses it ([`super::error_map::top_two`] of the per-axis spread of κ,
//! `s_i = mean ‖∂κ/∂x_i‖₂ · (hi_i − lo_i)`, other states at the setpoint clamped into X,
//! [`super::error_map::slice_base`]): the cells whose box contains the slice's base point in
//! every other coordinate (half-open, the upper face of X included), drawn over the two
//! axes; title and caption name the slice.

use super::error_map::{slice_base, top_two};
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
/// and the term that binds in each cell (right). `spread`: the per-axis spread of κ
/// (`certify::refine::sensitivity_spread`) that picks the slice for nx > 2 (module doc).
pub fn eps_map(
    cfg: &ProblemConfig,
    cells: &[CellView],
    target: f64,
    spread: &[f64],
) -> Result<Figure, PlotError> {
    register_font();
    let nx = cfg.system.nx();
    if cells.is_empty() || nx < 2 {
        return Err(PlotError::Data {
            figure: NAME.into(),
            cause: "no cells, or a one-dimensional state".into(),
        });
    }
    let (a0, a1) = if nx > 2 && spread.len() == nx {
        let t = top_two(spread);
        (t[0], t[1])
    } else {
        (0, 1)
    };
    let base = slice_base(cfg);
    let in_slice = |c: &CellView| {
        (0..nx).filter(|k| *k != a0 && *k != a1).all(|k| {
            c.lo[k] <= base[k]
                && (base[k] < c.hi[k] || (base[k] == c.hi[k] && c.hi[k] >= cfg.domain.hi[k]))
        })
    };
    let all = cells.len();
    let all_max = cells.iter().map(|c| c.eps).fold(0.0, f64::max);
    let cells: Vec<&CellView> = cells.iter().filter(|c| in_slice(c)).collect();
    let (xnames, _) = axis_names(&cfg.system);
    let unit = input_unit(&cfg.system);
    let emax = cells
        .iter()
        .map(|c| c.eps)
        .filter(|v| v.is_finite())
        .fold(target, f64::max);
    let slice = slice_words(cfg, &xnames, [a0, a1], &base, all);
    let (lo, hi) = (
        [cfg.domain.lo[a0], cfg.domain.lo[a1]],
        [cfg.domain.hi[a0], cfg.domain.hi[a1]],
    );
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
                format!("ε_C per cell ({n} cells, {over} above the target {target}){slice}"),
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
                .x_desc(xnames[a0].as_str())
                .y_desc(xnames[a1].as_str())
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
                            ((c.lo[a0] - ox).max(lo[0]), (c.lo[a1] - oy).max(lo[1])),
                            ((c.hi[a0] + ox).min(hi[0]), (c.hi[a1] + oy).min(hi[1])),
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
    Ok(Figure {
        name: NAME,
        caption: if nx > 2 {
            format!(
                "Local certificate over X{slice}: ε_C of the {} cells the slice cuts (max {:.4}, target {target}; max over all {all} cells {all_max:.4}) and the binding term.",
                cells.len(),
                cells.iter().map(|c| c.eps).fold(0.0, f64::max),
            )
        } else {
            format!(
                "Local certificate over X: ε_C of each of the {all} cells (max {all_max:.4}, target {target}) and the binding term."
            )
        },
        svg,
    })
}

/// The slice in words (empty for nx = 2): " — slice x3 = 0, x4 = 0 (N of M cells)".
fn slice_words(
    cfg: &ProblemConfig,
    names: &[String],
    axes: [usize; 2],
    base: &[f64],
    all: usize,
) -> String {
    let nx = cfg.system.nx();
    if nx <= 2 {
        return String::new();
    }
    let held: Vec<String> = (0..nx)
        .filter(|k| !axes.contains(k))
        .map(|k| format!("{} = {}", names[k], base[k]))
        .collect();
    format!(" — slice {} ({all} cells in X)", held.join(", "))
}
