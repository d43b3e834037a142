//! `refine_rounds` (written by `trainer refine`): the certified ε per refinement round, log
//! scale —
//! ```text
//! ε_k      = max_C ε_C of round k's net on round k's cells
//! ε*_k     = min_{j ≤ k} ε_j      (the smallest certified ε so far: never worse from round to round)
//! ε_D,k    = max corner error of round k's net (after the clamp)
//! ```
//! with the target as a horizontal line and the solves so far in the caption. Each ε_j is a
//! certificate of its own (net j on the cells and labels of round j); the run's outputs hold
//! the last round's where the target is met, otherwise the better of the last net and the
//! best one re-bounded on the final cells (`certify::refine`).

use super::{draw_err, register_font, Figure, PlotError, FONT, REG_COLOR};
use crate::certify::refine::RoundLog;
use plotters::prelude::*;

/// The figure's file stem.
const NAME: &str = "refine_rounds";

/// The best certified ε so far after each round (the running minimum of `eps`).
pub fn best_so_far(log: &[RoundLog]) -> Vec<f64> {
    let mut best = f64::INFINITY;
    log.iter()
        .map(|l| {
            if l.eps < best {
                best = l.eps;
            }
            best
        })
        .collect()
}

/// The ε-per-round curve of a refinement run (module doc).
pub fn refine_rounds(log: &[RoundLog], target: f64) -> Result<Figure, PlotError> {
    register_font();
    let best = best_so_far(log);
    let ok = |v: f64| v.is_finite() && v > 0.0;
    let vals: Vec<f64> = log
        .iter()
        .flat_map(|l| [l.eps, l.eps_d])
        .chain(best.iter().copied())
        .chain([target])
        .filter(|v| ok(*v))
        .collect();
    if log.is_empty() || vals.is_empty() {
        return Err(PlotError::Data {
            figure: NAME.into(),
            cause: "no refinement round with a finite ε".into(),
        });
    }
    let lo = vals.iter().copied().fold(f64::INFINITY, f64::min) * 0.7;
    let hi = vals.iter().copied().fold(0.0f64, f64::max) * 3.0;
    let last = log.last().map_or(0, |l| l.round) as f64;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (1000, 520)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_err(NAME))?;
        let mut chart = ChartBuilder::on(&root)
            .caption("certified ε per refinement round", (FONT, 20))
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(70)
            .build_cartesian_2d(0.0..last.max(1.0), (lo..hi).log_scale())
            .map_err(draw_err(NAME))?;
        chart
            .configure_mesh()
            .x_desc("round")
            .y_desc("ε")
            .x_label_formatter(&|v| format!("{v:.0}"))
            .y_label_formatter(&|v| format!("{v:.2}"))
            .axis_desc_style((FONT, 16))
            .label_style((FONT, 13))
            .light_line_style(TRANSPARENT)
            .draw()
            .map_err(draw_err(NAME))?;
        let series = |f: &dyn Fn(usize, &RoundLog) -> f64| -> Vec<(f64, f64)> {
            log.iter()
                .enumerate()
                .map(|(i, l)| (l.round as f64, f(i, l)))
                .filter(|p| ok(p.1))
                .collect()
        };
        let grey = RGBColor(150, 150, 150);
        let orange = RGBColor(230, 159, 0);
        for (name, pts, style) in [
            (
                "this round's net: max_C ε_C",
                series(&|_, l| l.eps),
                grey.stroke_width(2),
            ),
            (
                "smallest certified ε so far",
                series(&|i, _| best[i]),
                REG_COLOR.stroke_width(3),
            ),
            (
                "max corner error ε_D",
                series(&|_, l| l.eps_d),
                orange.stroke_width(2),
            ),
        ] {
            chart
                .draw_series(LineSeries::new(pts, style))
                .map_err(draw_err(NAME))?
                .label(name)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 22, y)], style));
        }
        let t = BLACK.stroke_width(1);
        chart
            .draw_series(DashedLineSeries::new(
                vec![(0.0, target), (last.max(1.0), target)],
                6,
                4,
                t,
            ))
            .map_err(draw_err(NAME))?
            .label(format!("target {target}"))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 8, y)], t));
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .label_font((FONT, 13))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()
            .map_err(draw_err(NAME))?;
        root.present().map_err(draw_err(NAME))?;
    }
    let l = log.last().expect("non-empty");
    Ok(Figure {
        name: NAME,
        caption: format!(
            "Certified ε per refinement round ({} rounds, {} solves, {} cells): the round's net \
             on the round's cells, the smallest certified ε so far (never worse from one round to \
             the next), the largest corner error; target {target}, smallest ε {:.4}.",
            log.len(),
            l.solves,
            l.cells,
            best.last().copied().unwrap_or(f64::NAN)
        ),
        svg,
    })
}
