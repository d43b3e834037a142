//! Splitting the cells above the target: which cells ([`split_failing`], worst first within
//! the budget of solves), along which axis ([`split_axis`]: the largest remainder term of
//! the cell's bound in the certificate's norm), and why a round that splits nothing stops
//! ([`split_or_stop`]).

use super::progress::StopReason;
use super::*;

/// Splits the failing cells ([`split_failing`]); `None` if any was split, else why the run
/// stops: the budget (no room for a split's new corners) or nothing left to split.
pub(super) fn split_or_stop(
    ctx: &mut Ctx,
    st: &mut RefineState,
    pending: &mut Vec<usize>,
    (ex, rs): (&Exclusion, &RefineSettings),
    unproven: &dyn Fn(&CellBound) -> bool,
) -> Option<StopReason> {
    if split_failing(ctx, st, pending, (ex, rs), unproven) {
        return None;
    }
    let nx = ctx.lat.max.len();
    Some(if st.points.len() + (1usize << (nx - 1)) > rs.budget {
        StopReason::Budget
    } else {
        StopReason::NothingToSplit
    })
}

/// The axis along which a failing cell is split, `None` when no side may be split (at
/// `refine.min_width`, or a cell with an unlabelled corner at `refine.min_cell`).
fn split_axis(
    node: &Node,
    b: &CellBound,
    lat: &Lattice,
    ex: &Exclusion,
    rs: &RefineSettings,
) -> Option<usize> {
    let nx = node.size.len();
    let rel = |k: usize| node.size[k] as f64 / lat.max[k] as f64;
    // A cell with an unlabelled corner is split down to `refine.min_cell` only: at that
    // size it is excluded (`Exclusion`), not split further.
    let above_min = |k: usize| b.corner.is_finite() || node.size[k] > ex.min_size[k];
    let splittable = |k: usize| node.size[k] >= 2 && rel(k) >= rs.min_width && above_min(k);
    let cand: Vec<usize> = (0..nx).filter(|&k| splittable(k)).collect();
    let &first = cand.first()?;
    // Axis: the largest remainder term; ties and infinite terms: longest side relative to
    // X. Where the fit at the corners dominates: the longest side (more data there).
    let mut axis = first;
    for &k in &cand[1..] {
        let (tk, ta) = (b.axis_terms[k], b.axis_terms[axis]);
        if tk > ta || (tk == ta && rel(k) > rel(axis)) {
            axis = k;
        }
    }
    if b.remainder < 0.25 * b.corner || !b.axis_terms[axis].is_finite() || b.eps <= rs.target_eps {
        axis = cand
            .iter()
            .copied()
            .max_by(|&a, &c| rel(a).total_cmp(&rel(c)).then(c.cmp(&a)))
            .unwrap_or(first);
    }
    Some(axis)
}

/// Splits the failing cells, worst first, within the budget: those above the target first;
/// unproven cells of a QP (`unproven`) only once every cell meets the target (so proving
/// never costs the budget the target needs). Cells with a corner the MPC could not label
/// (ε_C = ∞) are split after the others, with what budget remains, once per round each:
/// the uncertified region around a failed state halves every round instead of staying a
/// whole cell, and the new corners are solved (and retried, warm-started from their
/// labelled neighbours) like any other. Returns whether any cell was split.
fn split_failing(
    ctx: &mut Ctx,
    st: &mut RefineState,
    pending: &mut Vec<usize>,
    (ex, rs): (&Exclusion, &RefineSettings),
    unproven: &dyn Fn(&CellBound) -> bool,
) -> bool {
    let nx = ctx.lat.max.len();
    let above = st.bounds.iter().any(|(_, b)| b.eps > rs.target_eps);
    let mut bad: Vec<(usize, CellBound)> = st
        .bounds
        .iter()
        .filter(|(_, b)| b.eps > rs.target_eps || (!above && unproven(b)))
        .cloned()
        .collect();
    bad.sort_by(|a, b| b.1.eps.total_cmp(&a.1.eps).then(a.0.cmp(&b.0)));
    let (failed, mut bad): (Vec<_>, Vec<_>) =
        bad.into_iter().partition(|(_, b)| !b.corner.is_finite());
    bad.extend(failed);
    let mut split_any = false;
    for (n, b) in bad {
        let Some(axis) = split_axis(&st.nodes[n], &b, &ctx.lat, ex, rs) else {
            continue;
        };
        // New points are pushed onto `st.points` as they are created.
        let needed = 1usize << (nx - 1);
        if st.points.len() + needed > rs.budget {
            break;
        }
        ctx.split(st, n, axis, pending);
        split_any = true;
    }
    split_any
}
