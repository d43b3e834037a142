//! The refinement loop: label new corners, (re)train, bound every leaf cell, split the cells
//! above the target — round after round, checkpointed, until the target ε is met or the
//! budget of solves is spent. With [`RefineOptions::fixed`] (`refine --certify-only`) the net
//! is given and never retrained: only the cells are split (their corners solved).

use super::bounds::{bound_leaves, NetBoxes};
use super::labels::{label, Deadline};
use super::progress::{RoundSink, StopReason};
use super::split::split_or_stop;
use super::stale::Stale;
use super::start::{initial_grid, reindex, resume, run_hash};
use super::*;
use crate::certify::critical::QpCertifier;
use crate::certify::local::{CellBound, Form, LocalSettings};
use crate::certify::Model;
use crate::io::write_atomic;
use crate::learn::mlp::{Mlp, Workspace};
use crate::learn::setpoint::Hold;
use crate::learn::train::{train_from, KeepBest, TrainOptions, TrainSet};
use crate::problem::{ProblemConfig, RefineSettings, TrainSettings};
use std::collections::HashMap;
use std::path::Path;
use std::time::Instant;

/// Options of a refinement run.
#[derive(Debug, Clone, Default)]
pub struct RefineOptions {
    /// Called after each round.
    pub on_round: Option<fn(&RoundLog, usize)>,
    /// Labels for the first round (e.g. a dataset of `trainer import`): an initial grid
    /// corner whose state is a labelled record with a finite Jacobian takes that label
    /// instead of an OCP solve. Part of the checkpoint's identity.
    pub initial_labels: Option<crate::data::dataset::Dataset>,
    /// Certify this network as it is (`refine --certify-only`): no training, the rounds
    /// only split cells and solve their corners; the checkpoint is bound to its hash.
    pub fixed: Option<Model>,
    /// Given each round's result and whether it is the best so far ([`RoundSink`]): the
    /// caller writes the best out, so a stopped run leaves its best certificate.
    pub on_result: Option<RoundSink>,
    /// The check's solves, computed ahead on the core a retraining leaves idle
    /// ([`CheckAhead`](super::CheckAhead)); the caller hands it to
    /// [`check_ahead`](super::check_ahead).
    pub ahead: Option<std::sync::Arc<super::CheckAhead>>,
}

/// The result of a refinement run.
#[derive(Debug, Clone)]
pub struct Refined {
    /// The final state.
    pub state: RefineState,
    /// The final trained model.
    pub model: Model,
    /// Whether every cell meets the target.
    pub met: bool,
    /// Why the run stopped ([`StopReason::Running`] for a result handed to [`RoundSink`]).
    pub stopped: StopReason,
}

/// The local certificate's settings of a refinement.
pub(super) fn local_settings(rs: &RefineSettings) -> LocalSettings {
    LocalSettings {
        safety: rs.safety,
        floor: rs.floor,
    }
}

/// The training set: every labelled point, then the `extra` points `reps − 1` more times.
/// With `ex.infeasible` (`refine.exclude_infeasible`) the data is restricted to the
/// certified domain: a hard-infeasible point is kept only as a corner of a leaf that is not
/// excluded (where its soft label bounds the cell).
pub(super) fn train_set(
    st: &RefineState,
    nx: usize,
    nu: usize,
    extra: &[usize],
    reps: usize,
    ex: &Exclusion,
) -> TrainSet {
    let mut s = TrainSet {
        nx,
        nu,
        ..Default::default()
    };
    let keep = kept_points(st, ex);
    let mut push = |p: &Point| {
        s.x.extend(&p.x);
        s.u.extend(&p.u);
        s.du.extend(&p.du);
        s.use_jac.push(p.regular);
    };
    for (i, p) in st.points.iter().enumerate() {
        if p.labelled() && keep[i] {
            push(p);
        }
    }
    for _ in 1..reps {
        for &i in extra.iter().filter(|&&i| keep[i]) {
            push(&st.points[i]);
        }
    }
    s
}

/// The certified ε of a set of leaf bounds: max_C ε_C, and ∞ when no leaf is bounded (every
/// cell excluded: nothing is certified, not ε = 0).
pub(super) fn max_eps(bounds: &[(usize, CellBound)]) -> f64 {
    if bounds.is_empty() {
        return f64::INFINITY;
    }
    bounds.iter().map(|(_, b)| b.eps).fold(0.0, f64::max)
}

/// Whether every bounded leaf meets `target` — false when none is bounded.
pub(super) fn certified_all(bounds: &[(usize, CellBound)], target: f64) -> bool {
    !bounds.is_empty() && bounds.iter().all(|(_, b)| b.eps <= target)
}

/// The bounding box of the leaves not excluded, when `exclude_infeasible` is on or some
/// leaf is excluded.
fn certified_box(st: &RefineState, lat: &Lattice, ex: &Exclusion) -> Option<(Vec<f64>, Vec<f64>)> {
    if !ex.infeasible && !ex.any(st) {
        return None;
    }
    let mut b: Option<(Vec<u64>, Vec<u64>)> = None;
    for (n, node) in st.nodes.iter().enumerate() {
        if node.split.is_some() || st.excluded_by(n, ex) {
            continue;
        }
        let hi: Vec<u64> = node.lo.iter().zip(&node.size).map(|(a, s)| a + s).collect();
        b = Some(match b {
            None => (node.lo.clone(), hi),
            Some((l, h)) => (
                l.iter().zip(&node.lo).map(|(a, c)| *a.min(c)).collect(),
                h.iter().zip(&hi).map(|(a, c)| *a.max(c)).collect(),
            ),
        });
    }
    b.map(|(l, h)| (lat.x(&l), lat.x(&h)))
}

/// Per point: whether it belongs to the data of the certified domain (every point without
/// `exclude_infeasible`; with it, the hard-feasible points and the corners of leaves not
/// excluded). An unlabelled point is never trained on either way.
pub(super) fn kept_points(st: &RefineState, ex: &Exclusion) -> Vec<bool> {
    if !ex.infeasible {
        return vec![true; st.points.len()];
    }
    let mut keep: Vec<bool> = st.points.iter().map(|p| !p.hard_infeasible()).collect();
    for (n, node) in st.nodes.iter().enumerate() {
        if node.split.is_none() && !st.excluded_by(n, ex) {
            for &c in &node.corners {
                keep[c] = true;
            }
        }
    }
    keep
}

/// Runs (or resumes from `checkpoint`) the refinement of `cfg` to `rs.target_eps`.
pub fn refine(
    cfg: &ProblemConfig,
    rs: &RefineSettings,
    checkpoint: Option<&Path>,
    opts: &RefineOptions,
) -> Result<Refined, RefineError> {
    let nx = cfg.system.nx();
    let counts = rs.initial_counts(nx);
    let lat = Lattice::new(&cfg.domain.lo, &cfg.domain.hi, &counts);
    let ex = Exclusion::new(rs, &lat.max);
    let hash = run_hash(cfg, rs, opts);
    let band = cfg.ocp.u_bounds(0);
    // Every cell bound is in the certificate's norm ‖S_u⁻¹·‖₂ (`[ocp] u_scale`).
    let u_scale = crate::certify::norm::Norm::of_problem(cfg).u_scale;
    let ls = local_settings(rs);
    // Where the MPC is a QP, cells are proven exact and refinement goes on until all are.
    let qp = QpCertifier::detect(cfg).ok();
    // The centre check is for the estimated (nonlinear) MPC; a QP's cells are proven.
    let centre_check = rs.centre_check && qp.is_none();
    // Every retrained net holds the setpoint (`refine.training.hold_setpoint`).
    let hold = match opts.fixed {
        Some(_) => None,
        None => Hold::if_enabled(cfg, rs.training.hold_setpoint)?,
    };
    let mut ctx = Ctx {
        cfg,
        lat: lat.clone(),
        index: HashMap::new(),
    };
    // The cells' bounds under a net (a QP's cells proven exact where the proof succeeds).
    let boxes = NetBoxes::default();
    let bound = |st: &RefineState, mlp: &crate::learn::mlp::Mlp| {
        let q = qp.as_ref().map(|q| (q, rs.target_eps));
        bound_leaves(
            st,
            &lat,
            mlp,
            band,
            &ls,
            centre_check,
            q,
            &ex,
            &u_scale,
            &boxes,
        )
    };
    let resumed = resume(checkpoint, &hash, &counts, &lat, cfg.system.nu())?;
    let mut pending = Vec::new();
    let finished = resumed.as_ref().filter(|st| st.finished);
    if let Some(r) =
        finished.and_then(|st| finished_result((cfg, rs, opts), st, qp.is_some(), &bound))
    {
        return Ok(r);
    }
    let mut st = match resumed {
        Some(st) => reindex(&mut ctx, st, &mut pending),
        None => {
            let mut st = initial_grid(&mut ctx, &hash, &counts, &mut pending);
            if let Some(d) = &opts.initial_labels {
                pending = take_labels(cfg, &counts, &mut st.points, &pending, d);
            }
            st
        }
    };
    if let Some(m) = &opts.fixed {
        // The given net (with its source hash, which a checkpoint does not store).
        st.model = Some(m.clone());
    }
    let deadline = Deadline::new(rs.max_seconds);
    // The last complete round (its tree as bounded, before its splits) while a wall-clock
    // budget is set: a round cut by it returns this one.
    // And whether the last retraining kept its start (`Stale`; not in the checkpoint).
    let (mut last, mut stale): (Option<RefineState>, _) = (None, Stale::default());
    loop {
        let t0 = Instant::now();
        let round = st.log.len();
        // The first round of a run (or of a resumed run) solves all its points: there is
        // no complete round to fall back on.
        let dl = match last {
            Some(_) => deadline,
            None => Deadline::new(None),
        };
        let complete = label_round(&mut ctx, &mut st, &mut pending, (centre_check, rs), &dl);
        if let (false, Some(prev)) = (complete, last.take()) {
            // Cut inside the round: its new corners are not all solved, so its cells
            // cannot all be bounded. The checkpoint keeps the solves done (the rest are
            // solved first on resume); the result is the last complete round's.
            return cut_round(st, prev, checkpoint, &bound, rs.target_eps);
        }
        if qp.is_some() {
            // Resumed or imported points: their active sets, for the proofs.
            fill_active(cfg, &mut st.points);
        }
        if needs_retrain(&st, rs, opts) && !stale.skips(&st) {
            // The check's solves run beside the (serial) retraining.
            let gate = opts.ahead.as_ref().map(|a| a.open(&st, &lat, &ex));
            let m = retrain_net(cfg, rs, &st, (&lat, &ex), band, &hold, &hash);
            drop(gate);
            st.model = Some(stale.record(st.model.take(), m, &st));
        }
        let model = st.model.clone().expect("trained above");
        st.bounds = bound(&st, &model.mlp);
        let log = round_log(&st, round, rs.target_eps, t0);
        let (eps, ok) = (log.eps, log.cells_ok);
        st.log.push(log.clone());
        let improved = st.best.as_ref().is_none_or(|(e, _)| eps < *e);
        if improved {
            st.best = Some((eps, model.clone()));
        }
        report_round(opts, rs, &st, &model, improved && eps.is_finite());
        if let Some(f) = opts.on_round {
            f(&log, rs.budget);
        }
        // A QP problem's cells are also split until their MPC part is proven exact.
        let unproven = |b: &CellBound| qp.is_some() && !b.exact;
        let met = !st.bounds.is_empty()
            && ok == st.bounds.len()
            && !st.bounds.iter().any(|(_, b)| unproven(b));
        let stopped = match (met, round + 1 >= rs.max_rounds, deadline.spent()) {
            (true, _, _) => Some(StopReason::TargetMet),
            (_, true, _) => Some(StopReason::MaxRounds),
            (_, _, true) => Some(StopReason::MaxSeconds),
            _ => {
                if rs.max_seconds.is_some() {
                    last = Some(st.clone());
                }
                split_or_stop(&mut ctx, &mut st, &mut pending, (&ex, rs), &unproven)
            }
        };
        let done = stopped.is_some();
        let model = match done && !met {
            true => keep_best(&mut st, model, eps, &bound),
            false => model,
        };
        st.finished = done;
        if let Some(p) = checkpoint {
            // The checkpoint holds the tree with the new (unlabelled) points: on resume,
            // they are the ones labelled first.
            write_checkpoint(p, &st)?;
        }
        if done {
            return Ok(Refined {
                met: certified_all(&st.bounds, rs.target_eps),
                state: st,
                model: opts.fixed.clone().unwrap_or(model),
                stopped: stopped.unwrap_or(StopReason::NothingToSplit),
            });
        }
    }
}

/// Solves the round's `pending` points and, with the centre check, the centres of the
/// cells that may use the second-order form (see `certify::local::centre_consistent`),
/// within `dl`; `pending` keeps the points left unsolved. Returns whether every solve ran.
fn label_round(
    ctx: &mut Ctx,
    st: &mut RefineState,
    pending: &mut Vec<usize>,
    (centre_check, rs): (bool, &RefineSettings),
    dl: &Deadline,
) -> bool {
    let complete = label(ctx.cfg, &mut st.points, pending, dl);
    pending.retain(|&i| st.points[i].status.is_none());
    if !(centre_check && complete) {
        return complete;
    }
    let new = region::add_centres(ctx, st, rs.budget);
    label(ctx.cfg, &mut st.points, &new, dl)
}

/// A finished run's result (`st`), unless the settings now allow more: a lower target, a
/// larger budget or more rounds. Where the MPC is a QP (`qp`) its cells are proved again
/// (which are exact is not stored).
fn finished_result(
    (cfg, rs, opts): (&ProblemConfig, &RefineSettings, &RefineOptions),
    st: &RefineState,
    qp: bool,
    bound: &BoundFn,
) -> Option<Refined> {
    let met = certified_all(&st.bounds, rs.target_eps);
    let more = !met && st.points.len() < rs.budget && st.log.len() < rs.max_rounds;
    let model = opts.fixed.clone().or(st.model.clone()).filter(|_| !more)?;
    let mut state = st.clone();
    if qp {
        fill_active(cfg, &mut state.points);
        state.bounds = bound(&state, &model.mlp);
    }
    let stopped = finished_reason(&state, rs, met);
    Some(Refined {
        met,
        state,
        model,
        stopped,
    })
}

/// Writes the checkpoint `p` of `st` (sealed, atomically).
fn write_checkpoint(p: &Path, st: &RefineState) -> Result<(), RefineError> {
    let bytes = crate::io::seal(postcard::to_allocvec(st).unwrap_or_default());
    write_atomic(p, &bytes)?;
    Ok(())
}

/// A round cut by the wall-clock budget while its new corners were solved: `st` (with the
/// solves done, unfinished) is checkpointed so that a resumed run goes on where it stopped,
/// and the result is `prev`, the last complete round — its tree, its cells' bounds and the
/// better of its net and the best so far ([`keep_best`]) — stopped by
/// [`StopReason::MaxSecondsInRound`]. Its certificate is consistent: every cell bounded.
fn cut_round(
    st: RefineState,
    mut prev: RefineState,
    checkpoint: Option<&Path>,
    bound: &BoundFn,
    target: f64,
) -> Result<Refined, RefineError> {
    if let Some(p) = checkpoint {
        write_checkpoint(p, &st)?;
    }
    let model = prev.model.clone().expect("a complete round has a net");
    let eps = max_eps(&prev.bounds);
    let model = keep_best(&mut prev, model, eps, bound);
    Ok(Refined {
        met: certified_all(&prev.bounds, target),
        state: prev,
        model,
        stopped: StopReason::MaxSecondsInRound,
    })
}

/// The cells' bounds of a state under a net.
type BoundFn<'a> = dyn Fn(&RefineState, &Mlp) -> Vec<(usize, CellBound)> + 'a;

/// A run that ends without meeting the target: the best model so far, bounded on the final
/// (finer) tree, may do better than the last one (of ε `eps`); the better one is kept (its
/// bounds in `st`) and returned.
fn keep_best(st: &mut RefineState, mut model: Model, eps: f64, bound: &BoundFn) -> Model {
    if let Some((_, best)) = st.best.clone() {
        let b = bound(st, &best.mlp);
        if max_eps(&b) < eps {
            st.bounds = b;
            model = best;
        }
    }
    st.model = Some(model.clone());
    model
}

/// Whether the round retrains: never for a fixed net; when there is no net yet or a failing
/// cell's corner (fit) error is a large part of the target (splitting cannot help there).
/// Otherwise the net is kept and cells are only split (retraining would move every bound).
fn needs_retrain(st: &RefineState, rs: &RefineSettings, opts: &RefineOptions) -> bool {
    let fit_bound = st
        .bounds
        .iter()
        .any(|(_, b)| b.eps > rs.target_eps && b.corner > rs.retrain_at * rs.target_eps);
    opts.fixed.is_none() && (st.model.is_none() || fit_bound)
}

/// Hands the round's result to the sink of `opts` (if any); `best`: the best so far.
fn report_round(
    opts: &RefineOptions,
    rs: &RefineSettings,
    st: &RefineState,
    model: &Model,
    best: bool,
) {
    if let Some(sink) = &opts.on_result {
        let r = Refined {
            met: certified_all(&st.bounds, rs.target_eps),
            state: st.clone(),
            model: opts.fixed.clone().unwrap_or_else(|| model.clone()),
            stopped: StopReason::Running,
        };
        (sink.0)(&r, best);
    }
}

/// Why a finished run read back from its checkpoint stopped (not stored: inferred from its
/// state and the settings).
fn finished_reason(st: &RefineState, rs: &RefineSettings, met: bool) -> StopReason {
    let nx = st.nodes.first().map_or(1, |n| n.lo.len());
    if met {
        StopReason::TargetMet
    } else if st.log.len() >= rs.max_rounds {
        StopReason::MaxRounds
    } else if st.points.len() + (1usize << (nx - 1)) > rs.budget {
        StopReason::Budget
    } else {
        StopReason::NothingToSplit
    }
}

/// The labelled points whose clamped error under the current net exceeds `level` (the
/// training emphasis); none before a net exists.
fn hard_points(
    st: &RefineState,
    (band, u_scale): ((&[f64], &[f64]), &[f64]),
    (nx, nu): (usize, usize),
    level: f64,
) -> Vec<usize> {
    let mut hard = Vec::new();
    if let Some(m) = &st.model {
        let mut ws = Workspace::default();
        let (mut u, mut j) = (vec![0.0; nu], vec![0.0; nu * nx]);
        for (i, p) in st.points.iter().enumerate().filter(|(_, p)| p.labelled()) {
            m.mlp.eval(&p.x, &mut u, &mut j, &mut ws);
            let e = crate::certify::local::clamped_error(&p.u, &u, band, u_scale);
            if e > level {
                hard.push(i);
            }
        }
    }
    hard
}

/// The round's net, trained on the labelled points (a warm start from the current net for
/// `round_epochs` with its best checkpoint kept, or a new net with `refine.training`), the
/// points with a large error repeated `refine.emphasis` times.
fn retrain_net(
    cfg: &ProblemConfig,
    rs: &RefineSettings,
    st: &RefineState,
    (lat, ex): (&Lattice, &Exclusion),
    band: (&[f64], &[f64]),
    hold: &Option<Hold>,
    hash: &str,
) -> Model {
    let (nx, nu) = (cfg.system.nx(), cfg.system.nu());
    // Emphasis: points with a large error under the current net.
    let u_scale = crate::certify::norm::Norm::of_problem(cfg).u_scale;
    let hard = hard_points(
        st,
        (band, &u_scale),
        (nx, nu),
        rs.emphasis_at * rs.target_eps,
    );
    let set = train_set(st, nx, nu, &hard, rs.emphasis, ex);
    // The points before the repeated ones (those the checkpoints are measured on).
    let keep = kept_points(st, ex);
    let unique = (st.points.iter().zip(&keep))
        .filter(|(p, &k)| k && p.labelled())
        .count();
    // The input scaling of a new net (a warm start keeps its own): X, or with
    // exclusions the bounding box of the certified domain (the net then resolves
    // the part of X it is certified on).
    let scale_box = certified_box(st, lat, ex)
        .unwrap_or_else(|| (cfg.domain.lo.clone(), cfg.domain.hi.clone()));
    let ts = match &st.model {
        Some(_) => TrainSettings {
            epochs: rs.round_epochs,
            learning_rate: rs.round_learning_rate,
            ..rs.training.clone()
        },
        None => rs.training.clone(),
    };
    train_from(
        st.model.as_ref().map(|m| m.mlp.clone()),
        &ts,
        &TrainOptions {
            nominal: false,
            progress: None,
            hold: hold.clone(),
            // A warm start returns its best checkpoint by the clamped errors
            // above the retraining level on the data (the starting net included).
            keep_best: st.model.as_ref().map(|_| KeepBest {
                every: 10,
                lo: band.0.to_vec(),
                hi: band.1.to_vec(),
                points: unique,
                threshold: rs.retrain_at * rs.target_eps,
                u_scale: u_scale.clone(),
            }),
        },
        &set,
        &TrainSet::default(),
        (&scale_box.0, &scale_box.1),
        band,
        &cfg.problem_hash(),
        hash,
    )
}

/// The round's log line from its cell bounds: cells, cells meeting `target`, ε, ε_D, cells
/// using the second-order form, solves and seconds since `t0`.
fn round_log(st: &RefineState, round: usize, target: f64, t0: Instant) -> RoundLog {
    let eps = max_eps(&st.bounds);
    let eps_d = st.bounds.iter().map(|(_, b)| b.corner).fold(0.0, f64::max);
    let ok = st.bounds.iter().filter(|(_, b)| b.eps <= target).count();
    let second = st
        .bounds
        .iter()
        .filter(|(_, b)| b.form == Form::SecondOrder)
        .count();
    RoundLog {
        round,
        solves: st.points.len(),
        cells: st.bounds.len(),
        cells_ok: ok,
        eps,
        eps_d,
        second_order: second,
        seconds: t0.elapsed().as_secs_f64(),
    }
}
