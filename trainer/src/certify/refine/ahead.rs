//! The check's MPC solves computed ahead ([`CheckAhead`]), while the refinement retrains.
//!
//! A retraining is serial (Adam on one minibatch at a time), so it leaves a core idle for
//! seconds, and the check ([`super::check`]) runs after the last round. Its solves depend
//! on the problem and the cells, never on the net:
//! ```text
//! uniform state i   x_i = lo + (hi − lo)·u(seed, i, k)             i = 0 … n−1
//! cell state (C, q) x = lo_C + (hi_C − lo_C)·u(seed_C, key(C), q·nx + k)
//!                   solved cold, and warm from C's nearest corner   (cellcheck::Sample)
//! ```
//! So a worker thread solves them while the gate is open — from the start of a retraining
//! to its end ([`CheckAhead::open`]) — and waits while it is shut: the uniform states first
//! (every one is used), then one state of each leaf of the tree as it is then (the leaves
//! that met the target last round first: they are the likeliest to stay leaves), then the
//! extra states of the leaves near the target (never an excluded leaf: the check skips
//! those). A leaf split later wastes its solve, mostly on a core that would have idled: the
//! gate only stops new solves, so the one under way when a retraining ends runs on into the
//! next round, and while the seed study runs beside the rounds the three threads share the
//! two cores. With `refine.max_seconds` the round a budget cuts can therefore move, as it
//! moves with the machine's load.
//!
//! [`CheckAhead::finish`] stops the worker and hands its results over ([`Ready`]); the check
//! takes one only for the same problem, seed and state (bit for bit). Every solve is a pure
//! function of its state (and nearest corner), so the check is the same bits with or
//! without the solves ahead.

use super::solves::{
    cell_state, cell_stream, mpc_sample, nearest_corner, uniform_state, CellKey, NeighbourCache,
    Ready, Sample,
};
use super::{Exclusion, Lattice, Node, RefineState};
use crate::mpc::law::{Label, MpcLaw};
use crate::problem::ProblemConfig;
use std::collections::HashMap;
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};
use std::thread::JoinHandle;

/// A cell state to solve: its key, the state and the cell's nearest corner.
struct CellTask {
    key: CellKey,
    x: Vec<f64>,
    near: Vec<f64>,
}

/// The worker's queue and results (under the mutex).
#[derive(Default)]
struct Queue {
    /// The gate: the worker solves only while it is open.
    open: bool,
    /// Set by [`CheckAhead::finish`] (or a drop): the worker ends after its solve.
    stop: bool,
    /// The uniform states, in order, and the next one to solve.
    uniform: Vec<Vec<f64>>,
    next_uniform: usize,
    /// The cell states of the last [`CheckAhead::open`], the next one last.
    cells: Vec<CellTask>,
    /// Results: uniform state i's label, and each solved cell state with its state and corner.
    labels: Vec<Option<Label>>,
    samples: HashMap<CellKey, (Vec<f64>, Vec<f64>, Sample)>,
}

struct Shared {
    queue: Mutex<Queue>,
    gate: Condvar,
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, Queue> {
        // A panic elsewhere leaves the results usable: every entry is written whole.
        self.queue.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

/// The check's solves computed ahead on a worker thread (module doc).
pub struct CheckAhead {
    shared: Arc<Shared>,
    worker: Mutex<Option<JoinHandle<()>>>,
    problem: String,
    seed: u64,
    /// The check's per-cell settings: extra states where ε_C ≥ near × target.
    extra: usize,
    near: f64,
    target: f64,
}

/// A job of the worker.
enum Job {
    Uniform(usize, Vec<f64>),
    Cell(CellTask),
}

impl CheckAhead {
    /// The solves of the check of `n` uniform states with `seed` on the problem `cfg` (its
    /// refinement settings `cfg.refine` or the ones given, `target` and check settings),
    /// with the gate shut: the worker waits for [`open`](Self::open).
    pub fn start(
        cfg: &ProblemConfig,
        rs: &crate::problem::RefineSettings,
        n: usize,
        seed: u64,
    ) -> Self {
        let queue = Queue {
            uniform: (0..n).map(|i| uniform_state(cfg, seed, i)).collect(),
            labels: vec![None; n],
            ..Default::default()
        };
        let shared = Arc::new(Shared {
            queue: Mutex::new(queue),
            gate: Condvar::new(),
        });
        let (s, c) = (shared.clone(), cfg.clone());
        let worker = std::thread::Builder::new()
            .name("check-ahead".into())
            .spawn(move || work(&s, &c))
            .ok();
        CheckAhead {
            shared,
            worker: Mutex::new(worker),
            problem: cfg.problem_hash(),
            seed,
            extra: rs.check.extra,
            near: rs.check.near,
            target: rs.target_eps,
        }
    }

    /// Opens the gate for the leaves of `st` (on the lattice `lat`), replacing the cell
    /// states queued before; the gate shuts when the returned guard is dropped.
    pub(super) fn open(&self, st: &RefineState, lat: &Lattice, ex: &Exclusion) -> Open<'_> {
        if self.shared.lock().stop {
            // Finished: no worker to feed.
            return Open(self);
        }
        let tasks = self.tasks(st, lat, ex);
        let mut q = self.shared.lock();
        q.cells = tasks
            .into_iter()
            .filter(|t| !q.samples.contains_key(&t.key))
            .collect();
        q.open = true;
        drop(q);
        self.shared.gate.notify_all();
        Open(self)
    }

    /// The cell states of the leaves of `st`, the next one last: one state of each leaf
    /// that met the target last round, of each other leaf, then the extra states of the
    /// leaves near the target.
    fn tasks(&self, st: &RefineState, lat: &Lattice, ex: &Exclusion) -> Vec<CellTask> {
        let eps: HashMap<usize, f64> = st.bounds.iter().map(|(n, b)| (*n, b.eps)).collect();
        // The excluded leaves are not checked (nor bounded): their solves would only climb
        // the retry ladder where the MPC has no solution.
        let leaves =
            (0..st.nodes.len()).filter(|&n| st.nodes[n].split.is_none() && !st.excluded_by(n, ex));
        let (mut met, mut other, mut extra) = (Vec::new(), Vec::new(), Vec::new());
        for n in leaves {
            match eps.get(&n) {
                Some(&e) if e <= self.target => {
                    met.push((n, 0));
                    if e >= self.near * self.target {
                        extra.extend((1..=self.extra).map(|q| (n, q)));
                    }
                }
                _ => other.push((n, 0)),
            }
        }
        let seed = cell_stream(self.seed);
        let task = |&(n, q): &(usize, usize)| {
            let node: &Node = &st.nodes[n];
            let (lo, hi) = lat.cell(node);
            let x = cell_state(seed, node, (&lo, &hi), q);
            let corners: Vec<_> = node.corners.iter().map(|&c| &st.points[c]).collect();
            let near = corners[nearest_corner(&corners, &x, (&lo, &hi))].x.clone();
            CellTask {
                key: (node.lo.clone(), node.size.clone(), q),
                x,
                near,
            }
        };
        let order = met.iter().chain(&other).chain(&extra);
        let mut tasks: Vec<CellTask> = order.map(task).collect();
        tasks.reverse();
        tasks
    }

    /// Stops the worker (after the solve in progress) and hands its results over.
    pub fn finish(&self) -> Ready {
        self.halt();
        let mut q = self.shared.lock();
        Ready {
            problem: self.problem.clone(),
            seed: self.seed,
            labels: std::mem::take(&mut q.labels),
            samples: std::mem::take(&mut q.samples),
        }
    }

    fn halt(&self) {
        self.shared.lock().stop = true;
        self.shared.gate.notify_all();
        let handle = self
            .worker
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .take();
        if let Some(h) = handle {
            // A worker that panicked leaves what it finished.
            let _ = h.join();
        }
    }
}

impl std::fmt::Debug for CheckAhead {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CheckAhead")
            .field("problem", &self.problem)
            .field("seed", &self.seed)
            .finish_non_exhaustive()
    }
}

impl Drop for CheckAhead {
    /// A dropped `CheckAhead` stops its worker.
    fn drop(&mut self) {
        self.halt();
    }
}

/// The open gate of a [`CheckAhead`]: shut when dropped.
pub(super) struct Open<'a>(&'a CheckAhead);

impl Drop for Open<'_> {
    fn drop(&mut self) {
        self.0.shared.lock().open = false;
    }
}

/// The worker: solves the queued states while the gate is open, until stopped.
fn work(shared: &Shared, cfg: &ProblemConfig) {
    let mut w: Option<(MpcLaw, NeighbourCache)> = None;
    loop {
        let job = {
            let mut q = shared.lock();
            loop {
                if q.stop {
                    return;
                }
                if q.open {
                    if q.next_uniform < q.uniform.len() {
                        let i = q.next_uniform;
                        q.next_uniform += 1;
                        break Job::Uniform(i, q.uniform[i].clone());
                    }
                    if let Some(t) = q.cells.pop() {
                        break Job::Cell(t);
                    }
                }
                q = shared.gate.wait(q).unwrap_or_else(PoisonError::into_inner);
            }
        };
        let w = w.get_or_insert_with(|| (MpcLaw::new(cfg), NeighbourCache::default()));
        match job {
            Job::Uniform(i, x) => {
                let l = w.0.solve(&x, None).0;
                if let Some(slot) = shared.lock().labels.get_mut(i) {
                    *slot = Some(l);
                }
            }
            Job::Cell(t) => {
                let s = mpc_sample(w, &t.x, &t.near);
                shared.lock().samples.insert(t.key, (t.x, t.near, s));
            }
        }
    }
}

#[cfg(test)]
impl CheckAhead {
    /// Waits until the worker has solved every queued state (with the gate open).
    pub(super) fn drain(&self) {
        let t0 = std::time::Instant::now();
        loop {
            assert!(
                t0.elapsed().as_secs() < 300,
                "the worker did not drain its queue"
            );
            let q = self.shared.lock();
            let queued = q.next_uniform < q.uniform.len() || !q.cells.is_empty();
            let busy = q.labels.iter().take(q.next_uniform).any(Option::is_none);
            drop(q);
            if !queued && !busy {
                return;
            }
            std::thread::sleep(std::time::Duration::from_millis(2));
        }
    }
}

#[cfg(test)]
#[path = "ahead_tests.rs"]
mod tests;
