//! The check's MPC solves, as pure functions of the problem, its seed and the cells: the
//! uniform states, each cell's states, a state solved cold and warm-started from its cell's
//! nearest corner ([`mpc_sample`]), and the solves a worker finished ahead ([`Ready`]).
//!
//! ```text
//! uniform state i   x_i = lo + (hi − lo)·u(seed, i, k)                       i = 0 … n−1
//! cell state (C, q) x = lo_C + (hi_C − lo_C)·u(seed ⊕ c, key(C), q·nx + k)   key: C's corner, size
//! ```
//! Used by the check ([`super::check`], [`super::cellcheck`]) and by the worker that solves
//! them during the rounds ([`super::ahead`]); uses none of them.

use super::{Node, Point};
use crate::mpc::law::{Label, MpcLaw};
use crate::mpc::sqp::SqpStatus;
use crate::problem::ProblemConfig;
use std::collections::HashMap;

/// A cell state's key: the cell's lattice corner and size, and the state's number in it.
pub(super) type CellKey = (Vec<u64>, Vec<u64>, usize);

/// One check state as the law reports it: κ(x) if labelled, ∂κ/∂x if a regular hard
/// solution, whether the hard problem converged, and the warm-started solve's κ if that
/// converged too.
#[derive(Debug, Clone, Default)]
pub struct Sample {
    /// κ(x) (`None`: unlabelled).
    pub u: Option<Vec<f64>>,
    /// ∂κ/∂x (row-major nu × nx) of a regular hard solution.
    pub du: Option<Vec<f64>>,
    /// κ from the solve warm-started at the cell's nearest corner (both converged).
    pub warm: Option<Vec<f64>>,
}

/// The stream of the cells' states for the check seed `seed`.
pub(super) fn cell_stream(seed: u64) -> u64 {
    seed ^ 0x00ce_11c4_ec00_0000
}

/// The key of a cell's states: its lattice corner and size, mixed (a cell's states do not
/// depend on where it sits in the tree's order, so they can be solved before the tree is
/// final).
fn cell_key(node: &Node) -> u64 {
    node.lo
        .iter()
        .chain(&node.size)
        .fold(0x5ce1_1ce1_15ce_11ce, |h, &v| crate::rng::splitmix64(h ^ v))
}

/// State `q` of the cell `node` with corners `lo`, `hi`: uniform in it, keyed by the
/// stream `seed` and the cell.
pub(super) fn cell_state(seed: u64, node: &Node, (lo, hi): (&[f64], &[f64]), q: usize) -> Vec<f64> {
    let (nx, key) = (lo.len(), cell_key(node));
    (0..nx)
        .map(|k| lo[k] + (hi[k] - lo[k]) * crate::rng::uniform(seed, key, (q * nx + k) as u64))
        .collect()
}

/// The corner of `corners` nearest to `x`, relative to the cell `lo`, `hi` (ties: the
/// lower index).
pub(super) fn nearest_corner(corners: &[&Point], x: &[f64], (lo, hi): (&[f64], &[f64])) -> usize {
    let d = |c: usize| -> f64 {
        (0..x.len())
            .map(|k| ((corners[c].x[k] - x[k]) / (hi[k] - lo[k]).max(f64::MIN_POSITIVE)).powi(2))
            .sum()
    };
    (0..corners.len())
        .min_by(|&c1, &c2| d(c1).total_cmp(&d(c2)).then(c1.cmp(&c2)))
        .unwrap_or(0)
}

/// Uniform state `i` of the check with `seed`: uniform on X.
pub(super) fn uniform_state(cfg: &ProblemConfig, seed: u64, i: usize) -> Vec<f64> {
    (0..cfg.system.nx())
        .map(|k| {
            cfg.domain.lo[k]
                + (cfg.domain.hi[k] - cfg.domain.lo[k])
                    * crate::rng::uniform(seed, i as u64, k as u64)
        })
        .collect()
}

/// The neighbours' solutions one worker of the per-cell check has solved
/// ([`MpcLaw::neighbour_solution`], keyed by the corner's bits; `None`: not converged): a
/// corner is the nearest corner of several check states (the extra states of a cell, the
/// cells around it), and its cold solve is a pure function of the corner, so it is solved
/// once per worker. Cleared when it holds [`NeighbourCache::CAP`] corners (memory stays
/// bounded; the results never depend on it).
#[derive(Default)]
pub(super) struct NeighbourCache(HashMap<Vec<u64>, Option<(crate::mpc::sqp::PrimalDual, usize)>>);

impl NeighbourCache {
    /// Largest number of corners kept.
    const CAP: usize = 4096;
}

/// A check state solved by the MPC: cold, and (converged) warm-started from `near`'s
/// solution (the same label as [`MpcLaw::solve_from_neighbour`], the neighbour solved once
/// per worker: [`NeighbourCache`]).
pub(super) fn mpc_sample(
    (law, cache): &mut (MpcLaw, NeighbourCache),
    x: &[f64],
    near: &[f64],
) -> Sample {
    let (l, _) = law.solve(x, None);
    let mut s = Sample::default();
    if !l.u.iter().all(|v| v.is_finite()) {
        return s;
    }
    let hard = l.status == SqpStatus::Converged;
    if hard && l.degeneracy.is_none() && l.du_dx.iter().all(|v| v.is_finite()) {
        s.du = Some(l.du_dx.clone());
    }
    if hard {
        let key: Vec<u64> = near.iter().map(|v| v.to_bits()).collect();
        if !cache.0.contains_key(&key) {
            if cache.0.len() >= NeighbourCache::CAP {
                cache.0.clear();
            }
            let n = law.neighbour_solution(near);
            cache.0.insert(key.clone(), n);
        }
        s.warm = cache.0[&key]
            .as_ref()
            .and_then(|n| law.solve_from_solution(x, n))
            .filter(|w| w.status == SqpStatus::Converged)
            .map(|w| w.u);
    }
    s.u = Some(l.u);
    s
}

/// The solves a [`CheckAhead`](super::CheckAhead) finished, for the check.
#[derive(Default)]
pub struct Ready {
    pub(super) problem: String,
    pub(super) seed: u64,
    pub(super) labels: Vec<Option<Label>>,
    pub(super) samples: HashMap<CellKey, (Vec<f64>, Vec<f64>, Sample)>,
}

impl Ready {
    /// Whether these solves are of the problem `cfg` and the check seed `seed`.
    pub(super) fn of(&self, cfg: &ProblemConfig, seed: u64) -> bool {
        self.seed == seed && self.problem == cfg.problem_hash()
    }

    /// Uniform state i's label, if solved at `x` (bit for bit).
    pub(super) fn label(&self, i: usize, x: &[f64]) -> Option<Label> {
        self.labels
            .get(i)?
            .as_ref()
            .filter(|l| same(&l.x, x))
            .cloned()
    }

    /// State q of the cell `node`, if solved at `x` warm-started from `near` (both bit for
    /// bit).
    pub(super) fn sample(&self, node: &Node, q: usize, x: &[f64], near: &[f64]) -> Option<Sample> {
        let key = (node.lo.clone(), node.size.clone(), q);
        let (at, from, s) = self.samples.get(&key)?;
        (same(at, x) && same(from, near)).then(|| s.clone())
    }
}

#[cfg(test)]
impl Ready {
    /// The uniform states and cell states solved.
    pub(super) fn counts(&self) -> (usize, usize) {
        (self.labels.iter().flatten().count(), self.samples.len())
    }
}

/// Whether `a` and `b` are the same numbers, bit for bit.
fn same(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(u, v)| u.to_bits() == v.to_bits())
}
