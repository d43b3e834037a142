//! Adaptive refinement ("sparsification"): the dataset, the network and the local
//! certificate grown together until every cell of X meets a target ε.
//!
//! X is partitioned into boxes (cells) by a k-d tree of bisections on a dyadic lattice:
//! every cell's 2ⁿ corners are labelled points (κ, ∂κ/∂x and the active set), so each
//! solve becomes a corner and splits reuse the existing points. A round:
//! 1. label the new points (in parallel, cold starts: independent of the thread count);
//! 2. train the network (the first round from its seeded weights, later rounds warm-started
//!    for `round_epochs`), with the points of large error repeated (`emphasis`);
//! 3. bound every leaf cell ([`crate::certify::local::cell_bound`]); the certified ε is max_C ε_C;
//! 4. split each cell with ε_C > target (worst first, until the budget of solves is spent)
//!    along the axis with the largest remainder term (the axis whose halving shrinks the
//!    bound most; ties: the longest side relative to X). A cell whose corner error alone
//!    exceeds the target is split too (its new corners become training data there).
//!
//! The state after each round is checkpointed (`refine_state.bin`, atomic), so a killed
//! run resumes at its last completed round.

use crate::certify::local::{cell_bound, CellBound, Corner, Form, LocalSettings};
use crate::certify::netbounds::NetBounder;
use crate::certify::Model;
use crate::data::dataset::{Dataset, DatasetError, Header, Record};
use crate::io::write_atomic;
use crate::learn::mlp::{Mlp, Workspace};
use crate::learn::train::{train_from, TrainOptions, TrainSet};
use crate::mpc::law::{Label, MpcLaw};
use crate::mpc::sqp::SqpStatus;
use crate::problem::{ProblemConfig, RefineSettings, SamplerKind, SamplingSettings, TrainSettings};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

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
        /// The decoder's message.
        reason: String,
    },
    /// The checkpoint belongs to another problem or settings.
    #[error("checkpoint {path} was made for another problem or settings (delete it or use another --out)")]
    Mismatch {
        /// The checkpoint.
        path: PathBuf,
    },
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
}

impl Point {
    fn labelled(&self) -> bool {
        self.u.iter().all(|v| v.is_finite()) && self.du.iter().all(|v| v.is_finite())
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

/// Labels the points `idx` of `points` (parallel, cold starts).
fn label(cfg: &ProblemConfig, points: &mut [Point], idx: &[usize]) {
    let xs: Vec<Vec<f64>> = idx.iter().map(|&i| points[i].x.clone()).collect();
    let labels: Vec<Label> = xs
        .par_iter()
        .map_init(|| MpcLaw::new(cfg), |law, x| law.solve(x, None).0)
        .collect();
    for (&i, l) in idx.iter().zip(labels) {
        let p = &mut points[i];
        p.regular = l.status == SqpStatus::Converged && l.degeneracy.is_none();
        p.piece = fnv(&l.active);
        p.u = l.u;
        p.du = l.du_dx;
        p.status = Some(l.status);
        p.cost = l.cost;
        p.degeneracy = l.degeneracy;
        p.max_slack = l.max_slack;
    }
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
}

/// Options of a refinement run.
#[derive(Debug, Clone, Default)]
pub struct RefineOptions {
    /// Called after each round.
    pub on_round: Option<fn(&RoundLog, usize)>,
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
}

/// What a checkpoint must match: the labels (problem), the domain, the initial grid, the
/// network's shape and the safety factor (the certificate's meaning). Target, budget,
/// rounds and training rates may change on resume (e.g. a larger budget continues a run).
fn settings_hash(cfg: &ProblemConfig, rs: &RefineSettings) -> String {
    use sha2::{Digest, Sha256};
    let mut h = Sha256::new();
    h.update(cfg.problem_hash());
    let nx = cfg.system.nx();
    let key = (
        &cfg.domain,
        rs.initial_counts(nx),
        &rs.training.hidden,
        rs.training.activation,
        rs.safety.to_bits(),
    );
    h.update(postcard::to_allocvec(&key).unwrap_or_default());
    crate::io::hex(&h.finalize())
}

fn train_set(st: &RefineState, nx: usize, nu: usize, extra: &[usize], reps: usize) -> TrainSet {
    let mut s = TrainSet {
        nx,
        nu,
        ..Default::default()
    };
    let mut push = |p: &Point| {
        s.x.extend(&p.x);
        s.u.extend(&p.u);
        s.du.extend(&p.du);
        s.use_jac.push(p.regular);
    };
    for p in st.points.iter().filter(|p| p.labelled()) {
        push(p);
    }
    for _ in 1..reps {
        for &i in extra {
            push(&st.points[i]);
        }
    }
    s
}

/// Bounds every leaf; returns (leaf, bound) in leaf order.
fn bound_leaves(
    st: &RefineState,
    lat: &Lattice,
    mlp: &Mlp,
    band: (&[f64], &[f64]),
    ls: &LocalSettings,
) -> Vec<(usize, CellBound)> {
    let nb = NetBounder::new(mlp);
    let nu = mlp.nu();
    // Network at every point once.
    let net_u: Vec<f64> = st
        .points
        .par_chunks(256)
        .flat_map_iter(|ch| {
            let mut ws = Workspace::default();
            let mut out = Vec::with_capacity(ch.len() * nu);
            let mut u = vec![0.0; nu];
            let mut j = vec![0.0; nu * mlp.nx()];
            for p in ch {
                mlp.eval(&p.x, &mut u, &mut j, &mut ws);
                out.extend_from_slice(&u);
            }
            out
        })
        .collect();
    let leaves: Vec<usize> = (0..st.nodes.len())
        .filter(|&i| st.nodes[i].split.is_none())
        .collect();
    leaves
        .par_iter()
        .map(|&n| {
            let node = &st.nodes[n];
            let lo = lat.x(&node.lo);
            let hi_key: Vec<u64> = node.lo.iter().zip(&node.size).map(|(a, b)| a + b).collect();
            let hi = lat.x(&hi_key);
            let pts: Vec<&Point> = node.corners.iter().map(|&c| &st.points[c]).collect();
            if !pts.iter().all(|p| p.labelled()) {
                let b = CellBound {
                    eps: f64::INFINITY,
                    corner: f64::INFINITY,
                    remainder: f64::INFINITY,
                    form: Form::FirstOrder,
                    axis_terms: vec![f64::INFINITY; lo.len()],
                };
                return (n, b);
            }
            let corners: Vec<Corner> = pts
                .iter()
                .map(|p| Corner {
                    u: &p.u,
                    du: &p.du,
                    regular: p.regular,
                    piece: p.piece,
                })
                .collect();
            let nu_c: Vec<f64> = node
                .corners
                .iter()
                .flat_map(|&c| net_u[c * nu..(c + 1) * nu].iter().copied())
                .collect();
            (
                n,
                cell_bound(&lo, &hi, &corners, &nu_c, &nb.bounds(&lo, &hi), band, ls),
            )
        })
        .collect()
}

/// Runs (or resumes from `checkpoint`) the refinement of `cfg` to `rs.target_eps`.
pub fn refine(
    cfg: &ProblemConfig,
    rs: &RefineSettings,
    checkpoint: Option<&Path>,
    opts: &RefineOptions,
) -> Result<Refined, RefineError> {
    let (nx, nu) = (cfg.system.nx(), cfg.system.nu());
    let counts = rs.initial_counts(nx);
    let lat = Lattice::new(&cfg.domain.lo, &cfg.domain.hi, &counts);
    let hash = settings_hash(cfg, rs);
    let band = cfg.ocp.u_bounds(0);
    let ls = LocalSettings { safety: rs.safety };
    let mut ctx = Ctx {
        cfg,
        lat: lat.clone(),
        index: HashMap::new(),
    };
    let resumed = match checkpoint.filter(|p| p.exists()) {
        Some(p) => {
            let bytes = std::fs::read(p).map_err(|e| DatasetError::Io {
                path: p.display().to_string(),
                source: e,
            })?;
            let st: RefineState =
                postcard::from_bytes(&bytes).map_err(|e| RefineError::Corrupt {
                    path: p.to_path_buf(),
                    reason: e.to_string(),
                })?;
            if st.hash != hash {
                return Err(RefineError::Mismatch {
                    path: p.to_path_buf(),
                });
            }
            Some(st)
        }
        None => None,
    };
    let mut pending = Vec::new();
    if let Some(st) = resumed.as_ref().filter(|st| st.finished) {
        // A finished run: return its result unless the settings now allow more (a lower
        // target, a larger budget or more rounds).
        let met = st.bounds.iter().all(|(_, b)| b.eps <= rs.target_eps);
        let more = !met && st.points.len() < rs.budget && st.log.len() < rs.max_rounds;
        if let (false, Some(model)) = (more, st.model.clone()) {
            return Ok(Refined {
                met,
                state: st.clone(),
                model,
            });
        }
    }
    let mut st = match resumed {
        Some(st) => {
            for (i, p) in st.points.iter().enumerate() {
                ctx.index.insert(p.key.clone(), i);
                // Points created by the last checkpointed round's splits, not yet solved.
                if p.status.is_none() {
                    pending.push(i);
                }
            }
            st
        }
        None => {
            let mut st = RefineState {
                hash: hash.clone(),
                points: Vec::new(),
                nodes: Vec::new(),
                roots: Vec::new(),
                model: None,
                best: None,
                log: Vec::new(),
                bounds: Vec::new(),
                finished: false,
            };
            // The initial grid's cells.
            let cells: Vec<usize> = counts.iter().map(|c| c - 1).collect();
            let total: usize = cells.iter().product();
            for mut r in 0..total {
                let mut lo = vec![0u64; nx];
                for k in (0..nx).rev() {
                    lo[k] = ((r % cells[k]) as u64) << LEVELS;
                    r /= cells[k];
                }
                let n = ctx.node(&mut st, lo, vec![1u64 << LEVELS; nx], &mut pending);
                st.roots.push(n);
            }
            st
        }
    };
    loop {
        let t0 = Instant::now();
        let round = st.log.len();
        label(cfg, &mut st.points, &pending);
        pending.clear();
        // Retrain when a failing cell's corner (fit) error is a large part of the target:
        // splitting cannot help there. Otherwise keep the net and only split (retraining
        // would move every cell's bound).
        let fit_bound = st
            .bounds
            .iter()
            .any(|(_, b)| b.eps > rs.target_eps && b.corner > rs.retrain_at * rs.target_eps);
        let retrain = st.model.is_none() || fit_bound;
        if retrain {
            // Emphasis: points with a large error under the current net.
            let mut hard = Vec::new();
            if let Some(m) = &st.model {
                let mut ws = Workspace::default();
                let (mut u, mut j) = (vec![0.0; nu], vec![0.0; nu * nx]);
                for (i, p) in st.points.iter().enumerate().filter(|(_, p)| p.labelled()) {
                    m.mlp.eval(&p.x, &mut u, &mut j, &mut ws);
                    let e = (0..nu)
                        .map(|r| (p.u[r] - u[r].clamp(band.0[r], band.1[r])).powi(2))
                        .sum::<f64>()
                        .sqrt();
                    if e > rs.emphasis_at * rs.target_eps {
                        hard.push(i);
                    }
                }
            }
            let set = train_set(&st, nx, nu, &hard, rs.emphasis);
            let ts = match &st.model {
                Some(_) => TrainSettings {
                    epochs: rs.round_epochs,
                    learning_rate: rs.round_learning_rate,
                    ..rs.training.clone()
                },
                None => rs.training.clone(),
            };
            st.model = Some(train_from(
                st.model.as_ref().map(|m| m.mlp.clone()),
                &ts,
                &TrainOptions {
                    nominal: false,
                    progress: None,
                },
                &set,
                &TrainSet::default(),
                (&cfg.domain.lo, &cfg.domain.hi),
                band,
                &cfg.problem_hash(),
                &hash,
            ));
        }
        let model = st.model.clone().expect("trained above");
        st.bounds = bound_leaves(&st, &lat, &model.mlp, band, &ls);
        let eps = st.bounds.iter().map(|(_, b)| b.eps).fold(0.0, f64::max);
        let eps_d = st.bounds.iter().map(|(_, b)| b.corner).fold(0.0, f64::max);
        let ok = st
            .bounds
            .iter()
            .filter(|(_, b)| b.eps <= rs.target_eps)
            .count();
        let second = st
            .bounds
            .iter()
            .filter(|(_, b)| b.form == Form::SecondOrder)
            .count();
        let solves = st.points.len();
        let log = RoundLog {
            round,
            solves,
            cells: st.bounds.len(),
            cells_ok: ok,
            eps,
            eps_d,
            second_order: second,
            seconds: t0.elapsed().as_secs_f64(),
        };
        st.log.push(log.clone());
        if st.best.as_ref().is_none_or(|(e, _)| eps < *e) {
            st.best = Some((eps, model.clone()));
        }
        if let Some(f) = opts.on_round {
            f(&log, rs.budget);
        }
        let met = ok == st.bounds.len();
        // Split the failing cells, worst first, within the budget.
        let mut bad: Vec<(usize, CellBound)> = st
            .bounds
            .iter()
            .filter(|(_, b)| b.eps > rs.target_eps)
            .cloned()
            .collect();
        bad.sort_by(|a, b| b.1.eps.total_cmp(&a.1.eps).then(a.0.cmp(&b.0)));
        let mut split_any = false;
        if !met && round + 1 < rs.max_rounds {
            for (n, b) in bad {
                let node = st.nodes[n].clone();
                // Axis: the largest remainder term; ties and infinite terms: longest side
                // relative to X.
                let rel = |k: usize| node.size[k] as f64 / lat.max[k] as f64;
                // A corner without an MPC label (failed solve): splitting cannot help; the
                // cell stays uncertified (ε_C = ∞) and is reported.
                if !b.corner.is_finite() {
                    continue;
                }
                let splittable = |k: usize| node.size[k] >= 2 && rel(k) >= rs.min_width;
                let cand: Vec<usize> = (0..nx).filter(|&k| splittable(k)).collect();
                let Some(&first) = cand.first() else {
                    continue;
                };
                // Axis: the largest remainder term; ties and infinite terms: longest side
                // relative to X. Where the fit at the corners dominates: the longest side
                // (more data there).
                let mut axis = first;
                for &k in &cand[1..] {
                    let (tk, ta) = (b.axis_terms[k], b.axis_terms[axis]);
                    if tk > ta || (tk == ta && rel(k) > rel(axis)) {
                        axis = k;
                    }
                }
                if b.remainder < 0.25 * b.corner || !b.axis_terms[axis].is_finite() {
                    axis = cand
                        .iter()
                        .copied()
                        .max_by(|&a, &c| rel(a).total_cmp(&rel(c)).then(c.cmp(&a)))
                        .unwrap_or(first);
                }
                // New points are pushed onto `st.points` as they are created.
                let needed = 1usize << (nx - 1);
                if st.points.len() + needed > rs.budget {
                    break;
                }
                let half = node.size[axis] / 2;
                let mut size = node.size.clone();
                size[axis] = half;
                let a = ctx.node(&mut st, node.lo.clone(), size.clone(), &mut pending);
                let mut lo2 = node.lo.clone();
                lo2[axis] += half;
                let b2 = ctx.node(&mut st, lo2, size, &mut pending);
                st.nodes[n].split = Some((a, b2, axis));
                split_any = true;
            }
        }
        let done = met || !split_any;
        let mut model = model;
        if done && !met {
            // Not met: the best model so far, bounded on the final (finer) tree, may do
            // better than the last one.
            if let Some((_, best)) = st.best.clone() {
                let b = bound_leaves(&st, &lat, &best.mlp, band, &ls);
                let e = b.iter().map(|(_, b)| b.eps).fold(0.0, f64::max);
                if e < eps {
                    st.bounds = b;
                    model = best;
                }
            }
            st.model = Some(model.clone());
        }
        st.finished = done;
        if let Some(p) = checkpoint {
            // The checkpoint holds the tree with the new (unlabelled) points: on resume,
            // they are the ones labelled first.
            let bytes = postcard::to_allocvec(&st).unwrap_or_default();
            write_atomic(p, &bytes)?;
        }
        if done {
            let met = st.bounds.iter().all(|(_, b)| b.eps <= rs.target_eps);
            return Ok(Refined {
                met,
                state: st,
                model,
            });
        }
    }
}

/// The refined points as a dataset file (sampler `adaptive`).
pub fn dataset(cfg: &ProblemConfig, st: &RefineState) -> Dataset {
    let (nx, nu) = (cfg.system.nx(), cfg.system.nu());
    let records = st
        .points
        .iter()
        .enumerate()
        .map(|(i, p)| Record {
            index: i as u64,
            x: p.x.clone(),
            u: p.u.clone(),
            du_dx: p.du.clone(),
            cost: p.cost,
            status: p.status.unwrap_or(SqpStatus::NumericalFailure),
            iterations: 0,
            kkt: f64::NAN,
            degeneracy: p.degeneracy,
            max_slack: p.max_slack,
        })
        .collect::<Vec<_>>();
    Dataset {
        magic: crate::data::dataset::MAGIC,
        version: crate::data::dataset::FORMAT_VERSION,
        header: Header {
            problem: cfg.name.clone(),
            problem_hash: cfg.problem_hash(),
            config_toml: toml::to_string(cfg).unwrap_or_default(),
            nx: nx as u32,
            nu: nu as u32,
            sampling: SamplingSettings {
                sampler: SamplerKind::Adaptive,
                counts: vec![],
                n: records.len(),
                seed: 0,
            },
            total: records.len() as u64,
            shard: None,
            chunk: crate::data::dataset::CHUNK as u32,
        },
        records,
    }
}

/// The local certificate's own figures, next to the design's certificate keys.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LocalSummary {
    /// "local": ε = max_C ε_C over the cells of the k-d tree.
    pub method: String,
    /// Target ε of the refinement.
    pub target_eps: f64,
    /// Whether every cell meets the target.
    pub met: bool,
    /// Leaf cells.
    pub cells: usize,
    /// Cells bounded by the second-order (curvature) form.
    pub cells_second_order: usize,
    /// Cells whose ε_C is dominated by the corner (fit) error rather than the remainder.
    pub cells_fit_bound: usize,
    /// OCP solves (= points = corners).
    pub solves: usize,
    /// Refinement rounds.
    pub rounds: usize,
    /// Safety factor on the estimated MPC parts.
    pub safety: f64,
    /// The largest remainder bound of any cell.
    pub max_remainder: f64,
    /// What binds in the cell with the largest ε_C: `corner` (the fit at its corners is the
    /// larger term), `first_order` or `second_order` (the interpolation remainder).
    pub binding: String,
    /// The cell with the largest ε_C: (lower corner, upper corner).
    pub worst_cell: (Vec<f64>, Vec<f64>),
    /// Uniform grid solves the global Theorem 1 needs for the same ε with this net's
    /// ε_D, L_NN and the L_MPC estimate (`null`: no density suffices, ε ≤ ε_D).
    pub global_grid_solves: Option<f64>,
    /// global_grid_solves / solves.
    pub sparsification: Option<f64>,
    /// What is sound and what is estimated.
    pub note: String,
}

/// The certificate JSON of a refinement run: the design's keys plus [`LocalSummary`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LocalCertificate {
    /// The design's keys (`eps` is the local bound max_C ε_C).
    #[serde(flatten)]
    pub base: crate::certify::certificate::Certificate,
    /// The local figures.
    pub local: LocalSummary,
}

/// Builds the certificate of a finished refinement.
pub fn certificate(cfg: &ProblemConfig, rs: &RefineSettings, r: &Refined) -> LocalCertificate {
    use crate::certify::certificate::{requirement, Certificate, LnnMethod};
    use crate::certify::lipschitz;
    let st = &r.state;
    let mlp = &r.model.mlp;
    let (lo, hi) = (&cfg.domain.lo, &cfg.domain.hi);
    let nx = lo.len();
    let eps = st.bounds.iter().map(|(_, b)| b.eps).fold(0.0, f64::max);
    let eps_d = st.bounds.iter().map(|(_, b)| b.corner).fold(0.0, f64::max);
    let naive = lipschitz::naive_bound(mlp);
    let sdp = lipschitz::lipsdp_bound(mlp);
    let (l_nn, method) = if sdp < naive {
        (sdp, LnnMethod::LipSdpNeuron)
    } else {
        (naive, LnnMethod::Naive)
    };
    let lower = lipschitz::sampled_lower_bound(mlp, lo, hi, 20_000, 7);
    let set = train_set(st, nx, cfg.system.nu(), &[], 1);
    let (sl, q) = lipschitz::mpc_estimates(&set.x, &set.u, &set.du, &set.use_jac, nx, set.nu);
    let l_mpc = sl.max(q);
    let lat = Lattice::new(lo, hi, &rs.initial_counts(nx));
    let radius = st
        .bounds
        .iter()
        .map(|(n, _)| {
            let node = &st.nodes[*n];
            (0..nx)
                .map(|k| (0.5 * node.size[k] as f64 * lat.step[k]).powi(2))
                .sum::<f64>()
                .sqrt()
        })
        .fold(0.0, f64::max);
    let req = requirement(eps, eps_d, l_mpc, l_nn, lo, hi);
    let worst = st
        .bounds
        .iter()
        .max_by(|a, b| a.1.eps.total_cmp(&b.1.eps).then(b.0.cmp(&a.0)));
    let (binding, worst_cell) = match worst {
        Some((n, b)) => {
            let node = &st.nodes[*n];
            let hi_key: Vec<u64> = node.lo.iter().zip(&node.size).map(|(a, s)| a + s).collect();
            let what = if b.corner >= b.remainder {
                "corner"
            } else if b.form == Form::SecondOrder {
                "second_order"
            } else {
                "first_order"
            };
            (what.to_string(), (lat.x(&node.lo), lat.x(&hi_key)))
        }
        None => (String::new(), (vec![], vec![])),
    };
    let solves = st.points.len();
    let base = Certificate {
        eps,
        eps_d,
        l_nn,
        l_nn_method: method,
        l_nn_naive: naive,
        l_nn_lipsdp: sdp,
        l_nn_vertex: None,
        l_nn_lower: lower,
        l_mpc,
        l_mpc_is_estimate: true,
        l_mpc_method: format!(
            "estimate: max ‖∂κ/∂x‖₂ over the data ({sl:.4}) and neighbour difference \
             quotients ({q:.4}); the local bound uses per-cell estimates instead (see local.note)"
        ),
        covering_radius: radius,
        covering_method: "upper bound: the largest cell half-diagonal (every state is within \
                          it of a corner of its cell)"
            .into(),
        f32_allowance: 0.0,
        domain_lo: lo.clone(),
        domain_hi: hi.clone(),
        u_lo: cfg.ocp.u_bounds(0).0.to_vec(),
        u_hi: cfg.ocp.u_bounds(0).1.to_vec(),
        // The certificate is about sat(κ_NN), the output clamped to U_d (the data's stage-0
        // input bounds): κ ∈ U_d, so the clamp never increases the error, and U_d lies
        // inside the design's band U_d ⊕ [−ε, ε] ∩ U.
        clamp_lo: cfg.ocp.u_bounds(0).0.to_vec(),
        clamp_hi: cfg.ocp.u_bounds(0).1.to_vec(),
        n_points: set.len(),
        hash: r.model.content_hash(),
    };
    let local = LocalSummary {
        method: "local".into(),
        target_eps: rs.target_eps,
        met: r.met,
        cells: st.bounds.len(),
        cells_second_order: st
            .bounds
            .iter()
            .filter(|(_, b)| b.form == Form::SecondOrder)
            .count(),
        cells_fit_bound: st
            .bounds
            .iter()
            .filter(|(_, b)| b.corner >= b.remainder)
            .count(),
        solves,
        rounds: st.log.len(),
        safety: rs.safety,
        max_remainder: st
            .bounds
            .iter()
            .map(|(_, b)| b.remainder)
            .fold(0.0, f64::max),
        binding,
        worst_cell,
        global_grid_solves: req.solves,
        sparsification: req.solves.map(|g| g / solves.max(1) as f64),
        note: format!(
            "ε = max over cells of max_corners |κ − sat(κ_NN)| + interpolation remainder. \
             Sound: the corner errors (solved points), the network's value/Jacobian/curvature \
             enclosures (interval bound propagation), the interpolation inequalities. \
             Estimated: the range of ∂κ/∂x on each cell (hull of corner sensitivities and edge \
             secants, widened ×{s}) and |∂²κ/∂x²| where all corners share one active set \
             (×{s} the edge difference quotients); κ constant where all corners saturate.",
            s = rs.safety
        ),
    };
    LocalCertificate { base, local }
}

/// The leaf cell containing `x` (clamped into X), descending the k-d tree.
fn leaf_of(st: &RefineState, lat: &Lattice, counts: &[usize], x: &[f64]) -> usize {
    let nx = x.len();
    // Root: the initial grid cell.
    let mut r = 0usize;
    let mut key = vec![0u64; nx];
    for k in 0..nx {
        let t = ((x[k] - lat.lo[k]) / lat.step[k]).clamp(0.0, lat.max[k] as f64);
        key[k] = (t as u64).min(lat.max[k]);
        let cell = ((key[k] >> LEVELS) as usize).min(counts[k] - 2);
        r = r * (counts[k] - 1) + cell;
    }
    let mut n = st.roots[r];
    while let Some((a, b, axis)) = st.nodes[n].split {
        n = if key[axis] >= st.nodes[b].lo[axis] {
            b
        } else {
            a
        };
    }
    n
}

/// A state whose observed error exceeds its cell's ε_C.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Offender {
    /// The state.
    pub x: Vec<f64>,
    /// Its observed error |κ − sat(κ_NN)|.
    pub error: f64,
    /// Its cell's ε_C.
    pub eps_cell: f64,
    /// The cell's lower corner.
    pub cell_lo: Vec<f64>,
    /// The cell's upper corner.
    pub cell_hi: Vec<f64>,
}

/// The soundness check: observed errors at random states against the certificate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Check {
    /// Uniformly random states of X (seeded) labelled by the MPC.
    pub states: usize,
    /// Of which the MPC labelled (converged or soft).
    pub labelled: usize,
    /// Seed of the states.
    pub seed: u64,
    /// max |κ − sat(κ_NN)| observed.
    pub max_observed: f64,
    /// The certified ε.
    pub certified: f64,
    /// certified / max_observed.
    pub ratio: f64,
    /// States whose error exceeds the certified ε (must be 0).
    pub over_eps: usize,
    /// States whose error exceeds their own cell's ε_C.
    pub over_cell: usize,
    /// Largest observed error / own cell's ε_C.
    pub max_cell_ratio: f64,
    /// Largest share of a cell's allowance above its corner term that was used:
    /// max (|e(x)| − corner term) / (ε_C − corner term) over states whose error exceeds their
    /// cell's corner term (≤ 1 when the estimated remainder holds; how close to 1 says how
    /// tight it is).
    pub max_remainder_use: f64,
    /// Sensitivities ∂κ/∂x_k (per state and axis, regular labels) outside their cell's
    /// estimated range.
    pub slope_misses: usize,
    /// Number of such comparisons.
    pub slope_checks: usize,
    /// Largest distance of a missed sensitivity outside its estimated range (units of
    /// ∂κ/∂x; 0 when none missed).
    pub max_slope_excess: f64,
    /// Up to 20 states whose error exceeds their cell's ε_C.
    pub offenders: Vec<Offender>,
    /// Wall time, seconds.
    pub seconds: f64,
}

/// Solves the MPC at `n` random states and compares with the certificate of `r`.
pub fn check(cfg: &ProblemConfig, rs: &RefineSettings, r: &Refined, n: usize, seed: u64) -> Check {
    let t0 = Instant::now();
    let (nx, nu) = (cfg.system.nx(), cfg.system.nu());
    let counts = rs.initial_counts(nx);
    let lat = Lattice::new(&cfg.domain.lo, &cfg.domain.hi, &counts);
    let st = &r.state;
    let mlp = &r.model.mlp;
    let band = cfg.ocp.u_bounds(0);
    let bound_of: HashMap<usize, &CellBound> = st.bounds.iter().map(|(n, b)| (*n, b)).collect();
    let certified = st.bounds.iter().map(|(_, b)| b.eps).fold(0.0, f64::max);
    #[derive(Default, Clone)]
    struct Acc {
        labelled: usize,
        max: f64,
        over_eps: usize,
        over_cell: usize,
        cell_ratio: f64,
        rem_use: f64,
        misses: usize,
        checks: usize,
        excess: f64,
        offenders: Vec<(Vec<f64>, f64, f64, usize)>,
    }
    let acc = (0..n)
        .into_par_iter()
        .fold_chunks(
            1024,
            || (None::<MpcLaw>, Workspace::default(), Acc::default()),
            |(law, mut ws, mut a), i| {
                let law = law.unwrap_or_else(|| MpcLaw::new(cfg));
                let mut law = law;
                let x: Vec<f64> = (0..nx)
                    .map(|k| {
                        cfg.domain.lo[k]
                            + (cfg.domain.hi[k] - cfg.domain.lo[k])
                                * crate::rng::uniform(seed, i as u64, k as u64)
                    })
                    .collect();
                let (l, _) = law.solve(&x, None);
                if l.u.iter().all(|v| v.is_finite()) {
                    a.labelled += 1;
                    let (mut u, mut j) = (vec![0.0; nu], vec![0.0; nu * nx]);
                    mlp.eval(&x, &mut u, &mut j, &mut ws);
                    let e = (0..nu)
                        .map(|r| (l.u[r] - u[r].clamp(band.0[r], band.1[r])).powi(2))
                        .sum::<f64>()
                        .sqrt();
                    let leaf = leaf_of(st, &lat, &counts, &x);
                    let b = bound_of.get(&leaf);
                    let ec = b.map_or(f64::INFINITY, |b| b.eps);
                    if let Some(b) = b.filter(|b| e > b.corner && b.eps > b.corner) {
                        a.rem_use = a.rem_use.max((e - b.corner) / (b.eps - b.corner));
                    }
                    // A non-finite error (diverged net) counts as above every bound.
                    let e = if e.is_finite() { e } else { f64::INFINITY };
                    a.max = a.max.max(e);
                    a.over_eps += (e > certified) as usize;
                    if e > ec {
                        a.over_cell += 1;
                        if a.offenders.len() < 20 {
                            a.offenders.push((x.clone(), e, ec, leaf));
                        }
                    }
                    a.cell_ratio = a.cell_ratio.max(e / ec);
                    if l.status == SqpStatus::Converged && l.degeneracy.is_none() {
                        let node = &st.nodes[leaf];
                        let corners: Vec<Corner> = node
                            .corners
                            .iter()
                            .map(|&c| {
                                let p = &st.points[c];
                                Corner {
                                    u: &p.u,
                                    du: &p.du,
                                    regular: p.regular,
                                    piece: p.piece,
                                }
                            })
                            .collect();
                        for r in 0..nu {
                            for k in 0..nx {
                                let wk = node.size[k] as f64 * lat.step[k];
                                let (kr, _) = crate::certify::local::mpc_slope_estimate(
                                    &corners, wk, nx, r, k, rs.safety,
                                );
                                a.checks += 1;
                                let g = l.du_dx[r * nx + k];
                                if !kr.contains(g) {
                                    a.misses += 1;
                                    let out = (kr.lo - g).max(g - kr.hi);
                                    a.excess = a.excess.max(out);
                                }
                            }
                        }
                    }
                }
                (Some(law), ws, a)
            },
        )
        .map(|(_, _, a)| a)
        .reduce(Acc::default, |mut x, y| Acc {
            offenders: {
                x.offenders.extend(y.offenders);
                x.offenders.truncate(20);
                x.offenders
            },
            labelled: x.labelled + y.labelled,
            max: x.max.max(y.max),
            over_eps: x.over_eps + y.over_eps,
            over_cell: x.over_cell + y.over_cell,
            cell_ratio: x.cell_ratio.max(y.cell_ratio),
            rem_use: x.rem_use.max(y.rem_use),
            misses: x.misses + y.misses,
            checks: x.checks + y.checks,
            excess: x.excess.max(y.excess),
        });
    Check {
        states: n,
        labelled: acc.labelled,
        seed,
        max_observed: acc.max,
        certified,
        ratio: certified / acc.max,
        over_eps: acc.over_eps,
        over_cell: acc.over_cell,
        max_cell_ratio: acc.cell_ratio,
        max_remainder_use: acc.rem_use,
        slope_misses: acc.misses,
        slope_checks: acc.checks,
        max_slope_excess: acc.excess,
        offenders: acc
            .offenders
            .iter()
            .map(|(x, e, ec, leaf)| {
                let node = &st.nodes[*leaf];
                let hi: Vec<u64> = node.lo.iter().zip(&node.size).map(|(a, s)| a + s).collect();
                Offender {
                    x: x.clone(),
                    error: *e,
                    eps_cell: *ec,
                    cell_lo: lat.x(&node.lo),
                    cell_hi: lat.x(&hi),
                }
            })
            .collect(),
        seconds: t0.elapsed().as_secs_f64(),
    }
}

/// Writes the outputs of a refinement into `dir`: `model.bin`, `dataset.bin` (+ `.csv`),
/// `certificate.json`, `cells.csv` (every leaf: box, ε_C, corner term, remainder, form),
/// `refine_log.json`. Returns the certificate.
pub fn write_outputs(
    cfg: &ProblemConfig,
    rs: &RefineSettings,
    r: &Refined,
    dir: &Path,
) -> Result<LocalCertificate, DatasetError> {
    let cert = certificate(cfg, rs, r);
    let mut model = r.model.clone();
    model.certificate = Some(cert.base.clone());
    model.save(&dir.join("model.bin"))?;
    let ds = dataset(cfg, &r.state);
    ds.save(&dir.join("dataset.bin"))?;
    write_atomic(&dir.join("dataset.csv"), ds.to_csv().as_bytes())?;
    write_atomic(&dir.join("certificate.json"), pretty(&cert).as_bytes())?;
    write_atomic(
        &dir.join("refine_log.json"),
        pretty(&r.state.log).as_bytes(),
    )?;
    let nx = cfg.system.nx();
    let lat = Lattice::new(&cfg.domain.lo, &cfg.domain.hi, &rs.initial_counts(nx));
    let mut csv = String::new();
    for k in 0..nx {
        csv.push_str(&format!("lo{},", k + 1));
    }
    for k in 0..nx {
        csv.push_str(&format!("hi{},", k + 1));
    }
    csv.push_str("eps_c,corner,remainder,form\n");
    for (n, b) in &r.state.bounds {
        let node = &r.state.nodes[*n];
        let hi: Vec<u64> = node.lo.iter().zip(&node.size).map(|(a, s)| a + s).collect();
        for v in lat.x(&node.lo).iter().chain(&lat.x(&hi)) {
            csv.push_str(&format!("{v},"));
        }
        csv.push_str(&format!(
            "{},{},{},{}\n",
            b.eps,
            b.corner,
            b.remainder,
            match b.form {
                Form::FirstOrder => "first_order",
                Form::SecondOrder => "second_order",
            }
        ));
    }
    write_atomic(&dir.join("cells.csv"), csv.as_bytes())?;
    Ok(cert)
}

/// One cell of a local certificate in physical coordinates (what `study::plots::eps_map`
/// draws).
#[derive(Debug, Clone, PartialEq)]
pub struct CellView {
    /// Lower corner (first two state axes are drawn).
    pub lo: Vec<f64>,
    /// Upper corner.
    pub hi: Vec<f64>,
    /// ε_C.
    pub eps: f64,
    /// 0: the corner (fit) term binds; 1: first-order remainder; 2: second-order remainder.
    pub binding: u8,
}

/// The leaf cells with their bounds, for the ε_C map.
pub fn cell_views(cfg: &ProblemConfig, rs: &RefineSettings, st: &RefineState) -> Vec<CellView> {
    let lat = Lattice::new(
        &cfg.domain.lo,
        &cfg.domain.hi,
        &rs.initial_counts(cfg.system.nx()),
    );
    st.bounds
        .iter()
        .map(|(n, b)| {
            let node = &st.nodes[*n];
            let hi: Vec<u64> = node.lo.iter().zip(&node.size).map(|(a, s)| a + s).collect();
            CellView {
                lo: lat.x(&node.lo),
                hi: lat.x(&hi),
                eps: b.eps,
                binding: if b.corner >= b.remainder {
                    0
                } else if b.form == Form::SecondOrder {
                    2
                } else {
                    1
                },
            }
        })
        .collect()
}

/// Pretty JSON of a serialisable value.
pub fn pretty<T: Serialize>(v: &T) -> String {
    serde_json::to_string_pretty(v).unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn leaf_lookup_finds_the_cell_containing_the_state() {
        let cfg = ProblemConfig::default();
        let counts = [4usize, 3];
        let lat = Lattice::new(&cfg.domain.lo, &cfg.domain.hi, &counts);
        let mut ctx = Ctx {
            cfg: &cfg,
            lat: lat.clone(),
            index: HashMap::new(),
        };
        let mut st = RefineState {
            hash: String::new(),
            points: vec![],
            nodes: vec![],
            roots: vec![],
            model: None,
            best: None,
            log: vec![],
            bounds: vec![],
            finished: false,
        };
        let mut new = Vec::new();
        for r in 0..6u64 {
            let lo = vec![(r / 2) << LEVELS, (r % 2) << LEVELS];
            let n = ctx.node(&mut st, lo, vec![1 << LEVELS; 2], &mut new);
            st.roots.push(n);
        }
        // Random splits.
        for s in 0..300u64 {
            let leaves: Vec<usize> = (0..st.nodes.len())
                .filter(|&i| st.nodes[i].split.is_none())
                .collect();
            let n = leaves[(crate::rng::uniform(5, s, 0) * leaves.len() as f64) as usize];
            let axis = (crate::rng::uniform(5, s, 1) * 2.0) as usize;
            let node = st.nodes[n].clone();
            let half = node.size[axis] / 2;
            let mut size = node.size.clone();
            size[axis] = half;
            let a = ctx.node(&mut st, node.lo.clone(), size.clone(), &mut new);
            let mut lo2 = node.lo.clone();
            lo2[axis] += half;
            let b = ctx.node(&mut st, lo2, size, &mut new);
            st.nodes[n].split = Some((a, b, axis));
        }
        for s in 0..5000u64 {
            let x: Vec<f64> = (0..2)
                .map(|k| {
                    cfg.domain.lo[k]
                        + (cfg.domain.hi[k] - cfg.domain.lo[k])
                            * crate::rng::uniform(6, s, k as u64)
                })
                .collect();
            let leaf = leaf_of(&st, &lat, &counts, &x);
            let node = &st.nodes[leaf];
            assert!(node.split.is_none());
            let hi: Vec<u64> = node.lo.iter().zip(&node.size).map(|(a, b)| a + b).collect();
            let (l, h) = (lat.x(&node.lo), lat.x(&hi));
            for k in 0..2 {
                assert!(
                    l[k] - 1e-12 <= x[k] && x[k] <= h[k] + 1e-12,
                    "{x:?} not in {l:?}..{h:?}"
                );
            }
            // Corners are the lattice points of the box.
            assert_eq!(st.points[node.corners[3]].x, h);
        }
        // The domain's upper corner belongs to a cell too.
        let leaf = leaf_of(&st, &lat, &counts, &cfg.domain.hi);
        assert!(st.nodes[leaf].split.is_none());
    }
}
