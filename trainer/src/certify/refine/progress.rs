//! A refinement's progress as others see it: why a run stopped ([`StopReason`]), the best
//! result so far handed to a sink after every round ([`RoundSink`], so a run
//! that is stopped or killed leaves its best certificate), and why a certified ε is
//! infinite ([`infinite_causes`]: the cells with ε_C = ∞, the corner states at fault and
//! their cause). The report ([`RefineReport`], `refine_report.json`) says what was reached,
//! the binding cell, why the run stopped and how to resume it.

use super::Refined;
use super::{Exclusion, Lattice, RefineState};
use crate::problem::{ProblemConfig, RefineSettings};
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// Why a refinement run ended (or, for an intermediate report, that it is still running).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StopReason {
    /// Still running: the report was written after a round that improved ε. If no process
    /// is running, the run was stopped (killed, Ctrl-C) after that round.
    Running,
    /// Every cell meets the target.
    TargetMet,
    /// The budget of solves (`refine.budget`) is spent.
    Budget,
    /// `refine.max_rounds` rounds were run.
    MaxRounds,
    /// The wall-clock budget `refine.max_seconds` is spent (time-dependent result).
    MaxSeconds,
    /// The wall-clock budget `refine.max_seconds` ran out inside a round, while its new
    /// corners were solved: the result is the last complete round's (every cell bounded),
    /// the checkpoint keeps the solves done (time-dependent result).
    MaxSecondsInRound,
    /// No failing cell can be split (`refine.min_width`, `refine.min_cell`).
    NothingToSplit,
}

impl StopReason {
    /// A phrase for reports.
    pub fn describe(self) -> &'static str {
        match self {
            StopReason::Running => {
                "running (if no process is, it was stopped after this round: resume it)"
            }
            StopReason::TargetMet => "target met",
            StopReason::Budget => "budget of solves spent (refine.budget, --budget)",
            StopReason::MaxRounds => "refine.max_rounds reached",
            StopReason::MaxSeconds => "wall-clock budget refine.max_seconds spent",
            StopReason::MaxSecondsInRound => {
                "wall-clock budget refine.max_seconds spent inside a round: its new solves \
                 were cut off (solved first on resume); the certificate is the last complete \
                 round's"
            }
            StopReason::NothingToSplit => {
                "no failing cell can be split further (refine.min_width, refine.min_cell)"
            }
        }
    }
}

/// The sink of each round's result: called after every round with that round's state and
/// net (the tree as bounded, before the round's splits; `stopped` is
/// [`StopReason::Running`]) and whether its certified ε is finite and below every earlier
/// round's — the best so far, which `write_outputs` turns into a certificate that verifies,
/// so that a stopped or killed run leaves its best certificate. Errors are the sink's to
/// report (the run goes on).
#[derive(Clone)]
pub struct RoundSink(pub Arc<RoundFn>);

/// The function of a [`RoundSink`]: (the round's result, whether it is the best so far).
pub type RoundFn = dyn Fn(&Refined, bool) + Send + Sync;

impl std::fmt::Debug for RoundSink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("RoundSink(..)")
    }
}

/// A cell whose ε_C is infinite and why.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InfiniteCell {
    /// The cell: (lower corner, upper corner).
    pub cell: (Vec<f64>, Vec<f64>),
    /// Its corner states the MPC left unlabelled, with the solve status
    /// (`max_iterations`, `numerical_failure`, `infeasible`, or `unsolved`).
    pub unlabelled: Vec<(Vec<f64>, String)>,
    /// The cause and what refinement does about it.
    pub cause: String,
}

/// The leaf cells with ε_C = ∞ in `st` (in node order, at most `limit`), each with its
/// unlabelled corners and cause: an unlabelled corner (split down to `refine.min_cell`, then
/// excluded), a jump of κ found by `--check`, or an infinite network/MPC bound.
pub fn infinite_causes(
    cfg: &ProblemConfig,
    rs: &RefineSettings,
    st: &RefineState,
    limit: usize,
) -> Vec<InfiniteCell> {
    let nx = cfg.system.nx();
    let lat = Lattice::new(&cfg.domain.lo, &cfg.domain.hi, &rs.initial_counts(nx));
    let ex = Exclusion::new(rs, &lat.max);
    let mut out = Vec::new();
    for (n, b) in st.bounds.iter().filter(|(_, b)| !b.eps.is_finite()) {
        if out.len() >= limit {
            break;
        }
        let node = &st.nodes[*n];
        let (lo, hi) = lat.cell(node);
        let unlabelled: Vec<(Vec<f64>, String)> = node
            .corners
            .iter()
            .map(|&c| &st.points[c])
            .filter(|p| !p.labelled())
            .map(|p| {
                let s = p.status.map_or("unsolved", |s| s.as_str());
                (p.x.clone(), s.to_string())
            })
            .collect();
        let small = node.size.iter().zip(&ex.min_size).all(|(s, m)| s <= m);
        let cause = if unlabelled.len() == node.corners.len() {
            "the MPC left every corner unlabelled: the cell is excluded from the certified \
             domain at once"
                .to_string()
        } else if !unlabelled.is_empty() {
            format!(
                "the MPC left {} corner(s) unlabelled; the cell is split down to \
                 refine.min_cell = {} of X per axis, then excluded from the certified domain{}",
                unlabelled.len(),
                rs.min_cell,
                if small { " (at that size now)" } else { "" }
            )
        } else if st
            .jumps
            .iter()
            .any(|x| super::region::contains(&lo, &hi, x))
        {
            "a jump of κ (two local optima) found by --check lies in the cell: never certified"
                .into()
        } else if !b.corner.is_finite() {
            "a corner error is not finite (the network's output is not finite there)".into()
        } else {
            "the interpolation remainder is not finite (unbounded sensitivity or curvature \
             estimate; the cell is split)"
                .into()
        };
        out.push(InfiniteCell {
            cell: (lo, hi),
            unlabelled,
            cause,
        });
    }
    out
}

/// `refine_report.json`: what a refinement reached and why it stopped.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RefineReport {
    /// Why the run stopped ([`StopReason`]; `running` for an intermediate report).
    pub stopped: StopReason,
    /// [`StopReason::describe`].
    pub reason: String,
    /// Rounds run.
    pub rounds: usize,
    /// Certified ε of the certificate written beside this report.
    pub eps: f64,
    /// Target ε.
    pub target_eps: f64,
    /// Whether every cell meets the target.
    pub met: bool,
    /// OCP solves.
    pub solves: usize,
    /// The cell with the largest ε_C: (lower corner, upper corner).
    pub binding_cell: (Vec<f64>, Vec<f64>),
    /// Cells with ε_C = ∞ and their causes (the first 10).
    pub infinite: Vec<InfiniteCell>,
    /// How to go on: the command that resumes from `refine_state.bin`.
    pub resume: String,
}

impl RefineReport {
    /// The report of `r` stopped for `stopped`; `resume` is the command that continues it.
    pub fn new(
        cfg: &ProblemConfig,
        rs: &RefineSettings,
        r: &Refined,
        stopped: StopReason,
        resume: String,
    ) -> Self {
        let st = &r.state;
        let nx = cfg.system.nx();
        let lat = Lattice::new(&cfg.domain.lo, &cfg.domain.hi, &rs.initial_counts(nx));
        let worst = st
            .bounds
            .iter()
            .max_by(|a, b| a.1.eps.total_cmp(&b.1.eps).then(b.0.cmp(&a.0)));
        let binding_cell = worst.map_or((vec![], vec![]), |(n, _)| {
            let node = &st.nodes[*n];
            let hi: Vec<u64> = node.lo.iter().zip(&node.size).map(|(a, s)| a + s).collect();
            (lat.x(&node.lo), lat.x(&hi))
        });
        RefineReport {
            stopped,
            reason: stopped.describe().into(),
            rounds: st.log.len(),
            eps: max_eps(&st.bounds),
            target_eps: rs.target_eps,
            met: r.met,
            solves: st.points.len(),
            binding_cell,
            infinite: infinite_causes(cfg, rs, st, 10),
            resume,
        }
    }
}

/// The report's file name in a refinement's output directory.
pub const REPORT_FILE: &str = "refine_report.json";

/// Writes `report` as `dir/refine_report.json` (atomically).
pub fn write_report(
    dir: &std::path::Path,
    report: &RefineReport,
) -> Result<(), crate::io::FileError> {
    crate::io::write_atomic(&dir.join(REPORT_FILE), super::pretty(report).as_bytes())
}

/// The f32 allowance of the deployed controller of a net under a certificate (`deploy`
/// computes it; `certify` may not import `deploy`): see [`super::write_outputs`].
pub type Allowance = Arc<
    dyn Fn(&crate::certify::Model, &crate::certify::certificate::Certificate) -> Option<f64>
        + Send
        + Sync,
>;

/// A [`RoundSink`] that writes the best result so far into `dir` as the run's outputs
/// ([`super::write_outputs`]: `certificate.json`, `model.bin`, dataset, cells, log) with a
/// `refine_report.json` saying the run is in progress (`resume`: the command that resumes
/// it). The first best is written at once, so a run stopped during a long later round (an
/// infeasible region's slow solves) still leaves a certificate and a report. Writing costs a
/// certificate (Lipschitz bounds, the f32 allowance), so later writes are paced: from
/// `after` seconds of the run on, once at least 5× the last write's duration has passed
/// since it — at most ~20 % of the run's time; the run's final
/// outputs are written by the caller. A round whose ε is infinite has its first cell at
/// fault and its cause printed on stderr (unless `quiet`). Write errors are printed as
/// warnings (the run goes on).
pub fn writing_sink(
    cfg: &ProblemConfig,
    dir: &std::path::Path,
    resume: &str,
    (after, quiet): (f64, bool),
    allowance: Allowance,
) -> RoundSink {
    let (cfg, dir, resume) = (cfg.clone(), dir.to_path_buf(), resume.to_string());
    let started = std::time::Instant::now();
    // (end of the last write, its duration)
    let last = std::sync::Mutex::new(None::<(std::time::Instant, f64)>);
    RoundSink(Arc::new(move |r: &Refined, best: bool| {
        let rs = &cfg.refine;
        if !quiet && !max_eps(&r.state.bounds).is_finite() {
            print_infinite(&infinite_causes(&cfg, rs, &r.state, 1));
        }
        let Ok(mut last) = last.lock() else { return };
        let due = match *last {
            None => true,
            Some((t, d)) => {
                started.elapsed().as_secs_f64() >= after && t.elapsed().as_secs_f64() >= 5.0 * d
            }
        };
        if !best || !due {
            return;
        }
        let t = std::time::Instant::now();
        let written = super::write_outputs(&cfg, rs, r, &dir, None, &|c| allowance(&r.model, c))
            .map_err(|e| e.to_string())
            .and_then(|_| {
                let report = RefineReport::new(&cfg, rs, r, StopReason::Running, resume.clone());
                write_report(&dir, &report).map_err(|e| e.to_string())
            });
        if let Err(e) = written {
            eprintln!(
                "warning: the best certificate so far was not written to {}: {e}",
                dir.display()
            );
        }
        *last = Some((std::time::Instant::now(), t.elapsed().as_secs_f64()));
    }))
}

/// Prints the cells whose ε_C is infinite (the first three) and why, on stderr.
pub fn print_infinite(cells: &[InfiniteCell]) {
    for c in cells.iter().take(3) {
        let states: Vec<String> = c
            .unlabelled
            .iter()
            .map(|(x, s)| format!("{x:?} ({s})"))
            .collect();
        eprintln!(
            "ε_C = ∞ on cell {:?}–{:?}: {}{}",
            c.cell.0,
            c.cell.1,
            c.cause,
            if states.is_empty() {
                String::new()
            } else {
                format!("; unlabelled: {}", states.join(", "))
            }
        );
    }
}

/// max_C ε_C of `bounds` (∞ when none is bounded), as the rounds compute it.
fn max_eps(bounds: &[(usize, crate::certify::local::CellBound)]) -> f64 {
    if bounds.is_empty() {
        return f64::INFINITY;
    }
    bounds.iter().map(|(_, b)| b.eps).fold(0.0, f64::max)
}
