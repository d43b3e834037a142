//! Labelling the refinement's new points within the wall-clock budget: a [`Deadline`] is
//! `refine.max_seconds` counted from the run's start, and [`label`] checks it before every
//! solve, so a round whose solves are slow (the failing solves of an infeasible region,
//! ≈ 0.2 s each) stops within one solve per thread of the budget instead of at the end of
//! the round. A point left unsolved keeps no status: it is labelled first when the run is
//! resumed from its checkpoint (`start::reindex`).

use super::{set_label, Point};
use crate::mpc::law::{Label, MpcLaw};
use crate::mpc::sqp::SqpStatus;
use crate::problem::ProblemConfig;
use rayon::prelude::*;
use std::time::Instant;

/// The wall-clock budget of a run (`refine.max_seconds`), from its start.
#[derive(Debug, Clone, Copy)]
pub(super) struct Deadline {
    started: Instant,
    max_seconds: Option<f64>,
}

impl Deadline {
    /// A budget of `max_seconds` (none: never spent) starting now.
    pub(super) fn new(max_seconds: Option<f64>) -> Self {
        Deadline {
            started: Instant::now(),
            max_seconds,
        }
    }

    /// Whether the budget is spent.
    pub(super) fn spent(&self) -> bool {
        self.max_seconds
            .is_some_and(|s| self.started.elapsed().as_secs_f64() >= s)
    }
}

/// Labels the points `idx` of `points` (parallel, cold starts; the failed ones retried from
/// their nearest labelled regular point), no solve started once `deadline` is spent.
/// Returns whether every solve ran (false: the round was cut; the unsolved points have no
/// status, the failed ones not retried keep their failure). Which points are solved does
/// not depend on the order of the solves, so a run that is not cut labels bit for bit as
/// without a deadline.
pub(super) fn label(
    cfg: &ProblemConfig,
    points: &mut [Point],
    idx: &[usize],
    deadline: &Deadline,
) -> bool {
    let xs: Vec<Vec<f64>> = idx.iter().map(|&i| points[i].x.clone()).collect();
    let labels: Vec<Option<Label>> = xs
        .par_iter()
        .map_init(
            || MpcLaw::new(cfg),
            |law, x| (!deadline.spent()).then(|| law.solve(x, None).0),
        )
        .collect();
    let mut complete = true;
    for (&i, l) in idx.iter().zip(labels) {
        match l {
            Some(l) => set_label(&mut points[i], l),
            None => complete = false,
        }
    }
    // States still without a label: retried warm-started from the nearest labelled regular
    // point (distance relative to the lattice's extent; ties: the lower index), which a
    // failed corner gains as its cells are split around it.
    let failed: Vec<usize> = idx
        .iter()
        .copied()
        .filter(|&i| {
            matches!(
                points[i].status,
                Some(SqpStatus::MaxIterations | SqpStatus::NumericalFailure)
            )
        })
        .collect();
    if failed.is_empty() {
        return complete;
    }
    let (lo, hi) = (&cfg.domain.lo, &cfg.domain.hi);
    let near: Vec<(usize, Option<usize>)> = failed
        .iter()
        .map(|&i| {
            let d = |p: &Point| -> f64 {
                (0..lo.len())
                    .map(|k| ((p.x[k] - points[i].x[k]) / (hi[k] - lo[k])).powi(2))
                    .sum()
            };
            let best = (0..points.len())
                .filter(|&j| points[j].regular)
                .min_by(|&a, &b| d(&points[a]).total_cmp(&d(&points[b])).then(a.cmp(&b)));
            (i, best)
        })
        .collect();
    let retried: Vec<(usize, Option<Option<Label>>)> = near
        .par_iter()
        .map_init(
            || MpcLaw::new(cfg),
            |law, &(i, j)| {
                let l = (!deadline.spent())
                    .then(|| j.and_then(|j| law.solve_from_neighbour(&points[i].x, &points[j].x)));
                (i, l)
            },
        )
        .collect();
    for (i, l) in retried {
        match l {
            Some(Some(l)) => set_label(&mut points[i], l),
            Some(None) => {}
            None => complete = false,
        }
    }
    complete
}
