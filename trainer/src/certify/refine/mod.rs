//! Adaptive refinement ("sparsification"): the dataset, the network and the local
//! certificate grown together until every cell of X meets a target ε.
//!
//! X is partitioned into boxes (cells) by a k-d tree of bisections on a dyadic lattice:
//! every cell's 2ⁿ corners are labelled points (κ, ∂κ/∂x and the active set), so each
//! solve becomes a corner and splits reuse the existing points. A round:
//! 1. label the new points (in parallel, cold starts: independent of the thread count);
//! 2. train the network (the first round from its seeded weights, later rounds warm-started
//!    for `round_epochs`), with the points of large error repeated (`emphasis`); a
//!    warm-started retraining returns, of its starting weights and its weights every 10
//!    epochs, those with the smallest excess Σᵢ max(0, eᵢ − retrain_at·target) of the
//!    clamped corner errors ([`crate::learn::train::KeepBest`]): a retraining never
//!    leaves the data fitted worse than it found it;
//! 3. bound every leaf cell ([`crate::certify::local::cell_bound`]); the certified ε is max_C ε_C;
//! 4. split each cell with ε_C > target (worst first, until the budget of solves is spent)
//!    along the axis with the largest remainder term (the axis whose halving shrinks the
//!    bound most; ties: the longest side relative to X). A cell whose corner error alone
//!    exceeds the target is split too (its new corners become training data there).
//!
//! The state after each round is checkpointed (`refine_state.bin`, atomic), so a killed
//! run resumes at its last completed round.
//!
//! Files: this one owns the lattice, the points and cells and the checkpointed state;
//! `rounds` the refinement loop ([`refine`]); `outputs` the local certificate and the
//! files of a run; `bounds` the leaves' ε_C under a net; `check` and `cellcheck` the
//! certificate against fresh MPC solves, `solves` those solves (pure functions of the problem,
//! the seed and the cells) and `ahead` the worker that computes them during the rounds, on the
//! core a retraining leaves idle.

mod ahead;
mod bounds;
mod cellcheck;
mod check;
mod feedback;
mod labels;
mod outputs;
mod progress;
mod region;
mod rounds;
mod solves;
mod split;
mod stale;
mod start;

pub use crate::certify::local_summary::{Excluded, LocalSummary};
pub use ahead::CheckAhead;
pub use cellcheck::{CellCheck, OffendingCell};
pub use check::{check, check_ahead, Check, Offender};
pub use feedback::reopen;
pub use outputs::{
    cell_views, certificate, check_summary, dataset, pretty, sensitivity_spread, write_outputs,
    CellView, LocalCertificate,
};
pub use progress::{
    infinite_causes, print_infinite, write_report, writing_sink, Allowance, InfiniteCell,
    RefineReport, RoundSink, StopReason, REPORT_FILE,
};
pub use rounds::{refine, RefineOptions, Refined};

use crate::certify::local::CellBound;
use crate::certify::Model;
use crate::data::dataset::DatasetError;
use crate::mpc::law::{Label, MpcLaw};
use crate::mpc::sqp::SqpStatus;
use crate::problem::{ProblemConfig, RefineSettings};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::path::PathBuf;

/// Lattice levels below the initial grid spacing (cells can be halved this many times
/// per axis).
pub const LEVELS: u32 = 40;

/// Refinement failures, naming the file or the point at fault.
#[derive(Debug, thiserror::Error)]
pub enum RefineError {
    /// A file could not be read or written.
    #[error(transparent)]
    File(#[from] DatasetError),
    /// The checkpoint file is not a refinement checkpoint of this version.
    #[error("{path}: not a refinement checkpoint of this trainer version ({reason}); delete it or use another --out")]
    Corrupt {
        /// The checkpoint.
        path: PathBuf,
        /// What is wrong with it.
        reason: String,
    },
    /// The checkpoint's contents do not decode (another trainer version's layout).
    #[error("{path}: not a refinement checkpoint of this trainer version ({source}); delete it or use another --out")]
    Decode {
        /// The checkpoint.
        path: PathBuf,
        /// The decoder's error.
        #[source]
        source: postcard::Error,
    },
    /// The checkpoint belongs to another problem or settings.
    #[error("checkpoint {path} was made for another problem or settings (delete it or use another --out)")]
    Mismatch {
        /// The checkpoint.
        path: PathBuf,
    },
    /// `refine.training.hold_setpoint` is on and the MPC has no label at the setpoint.
    #[error(transparent)]
    Hold(#[from] crate::learn::setpoint::HoldError),
}

impl From<crate::io::FileError> for RefineError {
    fn from(e: crate::io::FileError) -> Self {
        RefineError::File(e.into())
    }
}

/// A labelled lattice point.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Point {
    /// Lattice coordinates.
    pub key: Vec<u64>,
    /// The state.
    pub x: Vec<f64>,
    /// κ(x) (NaN until labelled or if the solve failed).
    pub u: Vec<f64>,
    /// ∂κ/∂x (row-major nu × nx).
    pub du: Vec<f64>,
    /// Solve status.
    pub status: Option<SqpStatus>,
    /// Regular hard solution (converged, not degenerate, no slack).
    pub regular: bool,
    /// Hash of the strongly active set.
    pub piece: u64,
    /// Optimal cost.
    pub cost: f64,
    /// Sensitivity degeneracy, if any.
    pub degeneracy: Option<crate::mpc::sensitivity::Degeneracy>,
    /// Largest slack (soft labels).
    pub max_slack: f64,
    /// The strongly active rows of the solution (`None`: not known, e.g. an imported label
    /// or a point read back from a checkpoint). Candidates for the critical-region proof of
    /// [`crate::certify::critical`]; not stored in checkpoints (refilled on resume).
    #[serde(skip)]
    pub active: Option<Vec<usize>>,
}

impl Point {
    fn labelled(&self) -> bool {
        self.u.iter().all(|v| v.is_finite()) && self.du.iter().all(|v| v.is_finite())
    }
    /// Whether the hard OCP was found infeasible here: a soft label (the exact-penalty
    /// solution needed slack) or no label because of infeasibility. A solver failure is not
    /// infeasibility.
    pub fn hard_infeasible(&self) -> bool {
        matches!(
            self.status,
            Some(SqpStatus::Soft) | Some(SqpStatus::Infeasible)
        )
    }
}

/// Which leaf cells leave the certified domain: with `infeasible`
/// (`refine.exclude_infeasible`) those whose corners are all hard-infeasible
/// ([`RefineState::excluded`]); always those whose corners are all unlabelled, at any size
/// ([`RefineState::all_unlabelled`]), and those with a corner the MPC left unlabelled once
/// they are no larger than `min_size` ([`RefineState::unlabelled_small`], `refine.min_cell`):
/// a cell around a state without a label can never get a finite bound, so a mixed cell
/// (some corners labelled) is split down to that size and then excluded, and ε is certified
/// over the other cells.
#[derive(Debug, Clone, PartialEq)]
pub struct Exclusion {
    /// `refine.exclude_infeasible`.
    pub infeasible: bool,
    /// Per axis: the largest lattice size of an excluded cell with an unlabelled corner
    /// (`refine.min_cell` × the lattice's extent, at least one lattice step).
    pub min_size: Vec<u64>,
}

impl Exclusion {
    /// The exclusion of the settings `rs` on a lattice of extent `lat_max` per axis.
    pub fn new(rs: &RefineSettings, lat_max: &[u64]) -> Self {
        Exclusion {
            infeasible: rs.exclude_infeasible,
            min_size: lat_max
                .iter()
                .map(|&m| ((rs.min_cell * m as f64).floor() as u64).max(1))
                .collect(),
        }
    }

    /// Whether any leaf can be excluded under these settings in `st`.
    pub fn any(&self, st: &RefineState) -> bool {
        !st.excluded_leaves_by(self).is_empty()
    }
}

/// A node of the k-d tree of cells.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Node {
    /// Lower lattice corner.
    pub lo: Vec<u64>,
    /// Lattice size per axis.
    pub size: Vec<u64>,
    /// Corner point indices (corner c: upper on axis k iff bit k of c is set).
    pub corners: Vec<usize>,
    /// Children (lower half, upper half) and the split axis, if split.
    pub split: Option<(usize, usize, usize)>,
}

/// Statistics of one round.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RoundLog {
    /// Round number (0 = initial grid).
    pub round: usize,
    /// OCP solves so far.
    pub solves: usize,
    /// Leaf cells.
    pub cells: usize,
    /// Cells meeting the target.
    pub cells_ok: usize,
    /// Certified ε = max_C ε_C.
    pub eps: f64,
    /// Max corner error (ε_D over the data, after the clamp).
    pub eps_d: f64,
    /// Cells bounded by the second-order form.
    pub second_order: usize,
    /// Wall time of the round (labelling + training + bounding), seconds.
    pub seconds: f64,
}

/// Everything a refinement run carries between rounds (the checkpoint).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RefineState {
    /// SHA-256 of the problem (labels) and of the refine settings.
    pub hash: String,
    /// Points, in creation order.
    pub points: Vec<Point>,
    /// The k-d tree's nodes; the roots are the initial grid's cells.
    pub nodes: Vec<Node>,
    /// Roots of the tree (the initial grid's cells).
    pub roots: Vec<usize>,
    /// Current model, if trained.
    pub model: Option<Model>,
    /// The model with the smallest certified ε so far (on the tree of its round).
    pub best: Option<(f64, Model)>,
    /// Rounds done.
    pub log: Vec<RoundLog>,
    /// Per-leaf bounds of the last round (leaf node index, bound).
    pub bounds: Vec<(usize, CellBound)>,
    /// The run ended (target met, or nothing left to split within budget and rounds).
    pub finished: bool,
    /// States where the check found a jump of κ (cold- and warm-started solves converged to
    /// different local optima): the leaf containing one is never certified (ε_C = ∞).
    pub jumps: Vec<Vec<f64>>,
}

impl RefineState {
    /// Whether node `n` is a leaf excluded from the certified domain when
    /// `refine.exclude_infeasible` is on: every corner hard-infeasible
    /// ([`Point::hard_infeasible`]), so the cell is taken to lie outside the MPC's feasible
    /// set (an estimate from its corners).
    pub fn excluded(&self, n: usize) -> bool {
        let node = &self.nodes[n];
        node.split.is_none()
            && node
                .corners
                .iter()
                .all(|&c| self.points[c].hard_infeasible())
    }

    /// Whether leaf `n` has a corner the MPC left unlabelled and is no larger than
    /// `min_size` (lattice units) on every axis: split as far as [`Exclusion`] allows.
    pub fn unlabelled_small(&self, n: usize, min_size: &[u64]) -> bool {
        let node = &self.nodes[n];
        node.split.is_none()
            && node.size.iter().zip(min_size).all(|(s, m)| s <= m)
            && node.corners.iter().any(|&c| !self.points[c].labelled())
    }

    /// Whether leaf `n` has no labelled corner at all (every corner solved and left
    /// unlabelled by the MPC): no bound can be finite there, nor can splitting it give one
    /// soon — its new corners lie between unlabelled ones — so it is excluded at once, at any
    /// size, instead of being split down to `refine.min_cell` corner by failing corner.
    pub fn all_unlabelled(&self, n: usize) -> bool {
        let node = &self.nodes[n];
        node.split.is_none()
            && node.corners.iter().all(|&c| {
                let p = &self.points[c];
                p.status.is_some() && !p.labelled()
            })
    }

    /// Whether leaf `n` is outside the certified domain under `ex` ([`Exclusion`]).
    pub fn excluded_by(&self, n: usize, ex: &Exclusion) -> bool {
        (ex.infeasible && self.excluded(n))
            || self.all_unlabelled(n)
            || self.unlabelled_small(n, &ex.min_size)
    }

    /// The leaves outside the certified domain under `ex`, in node order.
    pub fn excluded_leaves_by(&self, ex: &Exclusion) -> Vec<usize> {
        (0..self.nodes.len())
            .filter(|&n| self.excluded_by(n, ex))
            .collect()
    }

    /// The leaves excluded from the certified domain (empty when `exclude` is off), in node
    /// order.
    pub fn excluded_leaves(&self, exclude: bool) -> Vec<usize> {
        if !exclude {
            return Vec::new();
        }
        (0..self.nodes.len())
            .filter(|&n| self.excluded(n))
            .collect()
    }

    /// Decodes a checkpoint's bytes (`seal(postcard(state))`, see [`crate::io::seal`]); errors
    /// name `path` and the fault.
    pub fn from_bytes(bytes: &[u8], path: &std::path::Path) -> Result<Self, RefineError> {
        let body = crate::io::unseal(bytes).ok_or_else(|| RefineError::Corrupt {
            path: path.to_path_buf(),
            reason: "checksum mismatch: corrupt, modified or of an older version".into(),
        })?;
        postcard::from_bytes(body).map_err(|e| RefineError::Decode {
            path: path.to_path_buf(),
            source: e,
        })
    }

    /// Checks that a decoded checkpoint is consistent with a lattice of `lat_max` (the
    /// largest key per axis), `roots` initial cells and `nu` inputs: every vector has its
    /// dimension, every index points into its table, the tree's splits are well formed. The
    /// checksum catches damage; this catches a file written by another build or by hand,
    /// which would otherwise index out of bounds later. Errors name `path` and the entry.
    pub(crate) fn check_consistent(
        &self,
        lat_max: &[u64],
        roots: usize,
        nu: usize,
        path: &std::path::Path,
    ) -> Result<(), RefineError> {
        let nx = lat_max.len();
        let bad = |what: String| {
            Err(RefineError::Corrupt {
                path: path.to_path_buf(),
                reason: format!("inconsistent contents: {what}"),
            })
        };
        for (i, p) in self.points.iter().enumerate() {
            if p.key.len() != nx || p.x.len() != nx || p.u.len() != nu || p.du.len() != nu * nx {
                return bad(format!("point {i} has the wrong dimensions"));
            }
            if p.key.iter().zip(lat_max).any(|(k, m)| k > m) {
                return bad(format!("point {i} lies outside the lattice"));
            }
        }
        if self.roots.len() != roots {
            return bad(format!(
                "{} roots, the grid has {roots} cells",
                self.roots.len()
            ));
        }
        let n = self.nodes.len();
        if let Some(r) = self.roots.iter().find(|&&r| r >= n) {
            return bad(format!("root {r} of {n} nodes"));
        }
        for (i, node) in self.nodes.iter().enumerate() {
            if node.lo.len() != nx || node.size.len() != nx || node.corners.len() != 1 << nx {
                return bad(format!("node {i} has the wrong dimensions"));
            }
            if node.corners.iter().any(|&c| c >= self.points.len()) {
                return bad(format!("node {i} names a corner beyond the points"));
            }
            if let Some((a, b, axis)) = node.split {
                if a >= n || b >= n || a <= i || b <= i || axis >= nx {
                    return bad(format!("node {i} has a malformed split"));
                }
            }
        }
        if let Some((leaf, _)) = self.bounds.iter().find(|(l, _)| *l >= n) {
            return bad(format!("a bound of node {leaf} of {n} nodes"));
        }
        let models = self.model.iter().chain(self.best.iter().map(|(_, m)| m));
        if models
            .into_iter()
            .any(|m| (m.mlp.nx(), m.mlp.nu()) != (nx, nu))
        {
            return bad(format!(
                "a network that does not map {nx} states to {nu} inputs"
            ));
        }
        Ok(())
    }
}

/// The geometry of the lattice.
#[derive(Debug, Clone)]
struct Lattice {
    lo: Vec<f64>,
    step: Vec<f64>,
    hi: Vec<f64>,
    max: Vec<u64>,
}

impl Lattice {
    fn new(lo: &[f64], hi: &[f64], counts: &[usize]) -> Self {
        let max: Vec<u64> = counts.iter().map(|&c| (c as u64 - 1) << LEVELS).collect();
        Lattice {
            lo: lo.to_vec(),
            hi: hi.to_vec(),
            step: lo
                .iter()
                .zip(hi)
                .zip(&max)
                .map(|((l, h), &m)| (h - l) / m as f64)
                .collect(),
            max,
        }
    }
    /// The box [lo, hi] of the cell `node`.
    fn cell(&self, node: &Node) -> (Vec<f64>, Vec<f64>) {
        let hi: Vec<u64> = node.lo.iter().zip(&node.size).map(|(a, s)| a + s).collect();
        (self.x(&node.lo), self.x(&hi))
    }

    fn x(&self, key: &[u64]) -> Vec<f64> {
        key.iter()
            .enumerate()
            .map(|(k, &i)| {
                if i == self.max[k] {
                    self.hi[k]
                } else {
                    self.lo[k] + i as f64 * self.step[k]
                }
            })
            .collect()
    }
}

fn fnv(v: &[usize]) -> u64 {
    let mut h = 0xcbf29ce484222325u64;
    for &x in v {
        for b in (x as u64).to_le_bytes() {
            h ^= b as u64;
            h = h.wrapping_mul(0x100000001b3);
        }
    }
    h
}

/// Stores a label in its point.
fn set_label(p: &mut Point, l: Label) {
    p.regular = l.status == SqpStatus::Converged && l.degeneracy.is_none();
    p.piece = fnv(&l.active);
    // Hard solutions only (a soft label's rows are those of another problem).
    p.active = (l.status == SqpStatus::Converged).then(|| l.active.clone());
    p.u = l.u;
    p.du = l.du_dx;
    p.status = Some(l.status);
    p.cost = l.cost;
    p.degeneracy = l.degeneracy;
    p.max_slack = l.max_slack;
}

/// Gives every labelled point whose active set is unknown (an imported label, a point read
/// back from a checkpoint) the active set of a fresh cold solve at its state (in parallel):
/// only the critical-region proof of a QP problem uses it. Returns the number of solves.
fn fill_active(cfg: &ProblemConfig, points: &mut [Point]) -> usize {
    let idx: Vec<usize> = (0..points.len())
        .filter(|&i| points[i].active.is_none() && points[i].labelled())
        .collect();
    let xs: Vec<Vec<f64>> = idx.iter().map(|&i| points[i].x.clone()).collect();
    let sets: Vec<Option<Vec<usize>>> = xs
        .par_iter()
        .map_init(
            || MpcLaw::new(cfg),
            |law, x| {
                let l = law.solve(x, None).0;
                (l.status == SqpStatus::Converged).then_some(l.active)
            },
        )
        .collect();
    for (&i, a) in idx.iter().zip(sets) {
        points[i].active = a;
    }
    idx.len()
}

/// The labelled records of `data` with a finite Jacobian that sit on the initial grid
/// (`counts` points per axis over X; within 1e-9 of a grid spacing per axis), by lattice key.
fn keyed_labels<'d>(
    cfg: &ProblemConfig,
    counts: &[usize],
    data: &'d crate::data::dataset::Dataset,
) -> HashMap<Vec<u64>, &'d crate::data::dataset::Record> {
    let (lo, hi) = (&cfg.domain.lo, &cfg.domain.hi);
    let mut by_key = HashMap::new();
    let usable = |r: &&crate::data::dataset::Record| {
        r.is_labelled()
            && r.x.len() == lo.len()
            && r.u.iter().chain(&r.du_dx).all(|v| v.is_finite())
    };
    for r in data.records.iter().filter(usable) {
        let key: Option<Vec<u64>> = (0..lo.len())
            .map(|k| {
                let n = counts[k].saturating_sub(1).max(1) as f64;
                let t = (r.x[k] - lo[k]) / (hi[k] - lo[k]) * n;
                let i = t.round();
                ((t - i).abs() <= 1e-9 && (0.0..=n).contains(&i)).then_some((i as u64) << LEVELS)
            })
            .collect();
        if let Some(k) = key {
            by_key.entry(k).or_insert(r);
        }
    }
    by_key
}

/// How many of the initial grid's corners `data` labels (see [`RefineOptions::initial_labels`]),
/// and how many corners there are.
pub fn initial_corners_labelled(
    cfg: &ProblemConfig,
    rs: &crate::problem::RefineSettings,
    data: &crate::data::dataset::Dataset,
) -> (usize, usize) {
    let counts = rs.initial_counts(cfg.system.nx());
    (
        keyed_labels(cfg, &counts, data).len(),
        counts.iter().product(),
    )
}

/// Gives the corners `idx` the labels of `data`'s records at their states
/// ([`keyed_labels`]); returns the corners left to solve. The active set of such a label is
/// not known, so the corner is not `regular` (its cells use the first-order form).
fn take_labels(
    cfg: &ProblemConfig,
    counts: &[usize],
    points: &mut [Point],
    idx: &[usize],
    data: &crate::data::dataset::Dataset,
) -> Vec<usize> {
    let by_key = keyed_labels(cfg, counts, data);
    let mut left = Vec::new();
    for &i in idx {
        match by_key.get(&points[i].key) {
            Some(r) => {
                let p = &mut points[i];
                p.u = r.u.clone();
                p.du = r.du_dx.clone();
                p.status = Some(r.status);
                p.cost = r.cost;
                p.degeneracy = r.degeneracy;
                p.max_slack = r.max_slack;
                p.regular = false;
                p.piece = 0;
            }
            None => left.push(i),
        }
    }
    left
}

struct Ctx<'a> {
    cfg: &'a ProblemConfig,
    lat: Lattice,
    index: HashMap<Vec<u64>, usize>,
}

impl Ctx<'_> {
    fn point(&mut self, st: &mut RefineState, key: Vec<u64>, new: &mut Vec<usize>) -> usize {
        if let Some(&i) = self.index.get(&key) {
            return i;
        }
        let (nx, nu) = (self.cfg.system.nx(), self.cfg.system.nu());
        let i = st.points.len();
        st.points.push(Point {
            x: self.lat.x(&key),
            key: key.clone(),
            u: vec![f64::NAN; nu],
            du: vec![f64::NAN; nu * nx],
            status: None,
            regular: false,
            piece: 0,
            cost: f64::NAN,
            degeneracy: None,
            max_slack: f64::NAN,
            active: None,
        });
        self.index.insert(key, i);
        new.push(i);
        i
    }

    fn node(
        &mut self,
        st: &mut RefineState,
        lo: Vec<u64>,
        size: Vec<u64>,
        new: &mut Vec<usize>,
    ) -> usize {
        let nx = lo.len();
        let corners = (0..1usize << nx)
            .map(|c| {
                let key: Vec<u64> = (0..nx)
                    .map(|k| lo[k] + if c & (1 << k) != 0 { size[k] } else { 0 })
                    .collect();
                self.point(st, key, new)
            })
            .collect();
        st.nodes.push(Node {
            lo,
            size,
            corners,
            split: None,
        });
        st.nodes.len() - 1
    }

    /// Bisects leaf `n` along `axis`: its two halves become new nodes (their new corner
    /// points pushed onto `new`) and `n` records the split.
    fn split(&mut self, st: &mut RefineState, n: usize, axis: usize, new: &mut Vec<usize>) {
        let node = st.nodes[n].clone();
        let half = node.size[axis] / 2;
        let mut size = node.size.clone();
        size[axis] = half;
        let a = self.node(st, node.lo.clone(), size.clone(), new);
        let mut lo2 = node.lo;
        lo2[axis] += half;
        let b = self.node(st, lo2, size, new);
        st.nodes[n].split = Some((a, b, axis));
    }
}

#[cfg(test)]
mod cellcheck_tests;
#[cfg(test)]
mod tests;
