//! A cell's neighbourhood for the estimated MPC parts of its local certificate: the
//! [`Regional`] floor data (G_ik, the spread of ∂_kκ_i over the cell's corners and the
//! labelled points one cell width outside them; Q_ik, the largest difference quotient of
//! ∂_kκ_i between a corner and its outward neighbour along k) and the solved centre sample
//! that decides whether the second-order form may be used
//! ([`crate::certify::local::centre_consistent`]). Shared by the rounds and the check, so
//! both see the same estimated ranges.

use super::*;
use crate::certify::local::{Corner, Regional};

/// Lattice key → point index.
pub(super) fn index(st: &RefineState) -> HashMap<Vec<u64>, usize> {
    st.points
        .iter()
        .enumerate()
        .map(|(i, p)| (p.key.clone(), i))
        .collect()
}

/// The centre of a node on the lattice (`None` if a side is too short to halve).
pub(super) fn centre_key(node: &Node) -> Option<Vec<u64>> {
    node.lo
        .iter()
        .zip(&node.size)
        .map(|(&l, &s)| (s >= 2).then_some(l + s / 2))
        .collect()
}

/// Whether a node's corners are all regular hard solutions of one active set (a candidate
/// for the second-order form).
pub(super) fn smooth_candidate(st: &RefineState, node: &Node) -> bool {
    let p0 = &st.points[node.corners[0]];
    node.corners.iter().all(|&c| {
        let p = &st.points[c];
        p.labelled() && p.regular && p.piece == p0.piece
    })
}

/// A point as a corner of the local certificate.
pub(super) fn corner(p: &Point) -> Corner<'_> {
    Corner {
        u: &p.u,
        du: &p.du,
        regular: p.regular,
        piece: p.piece,
    }
}

/// The centre sample of a node for [`crate::certify::local::cell_bound`] when the centre
/// check is on: the solved centre point, or — a smooth candidate whose centre is not
/// solved (budget spent, or too small to halve) — an unchecked stand-in that keeps the
/// cell to the first-order form. `None` when the check is off or the cell is no candidate.
pub(super) fn centre<'a>(
    st: &'a RefineState,
    idx: &HashMap<Vec<u64>, usize>,
    node: &Node,
    on: bool,
) -> Option<Corner<'a>> {
    if !on || !smooth_candidate(st, node) {
        return None;
    }
    let unchecked = Corner {
        u: &[],
        du: &[],
        regular: false,
        piece: 0,
    };
    Some(
        centre_key(node)
            .and_then(|k| idx.get(&k))
            .map(|&i| &st.points[i])
            .filter(|p| p.labelled())
            .map_or(unchecked, corner),
    )
}

/// The [`Regional`] data of a node (empty when `floor` is 0: no floor).
pub(super) fn regional(
    st: &RefineState,
    idx: &HashMap<Vec<u64>, usize>,
    lat: &Lattice,
    node: &Node,
    floor: f64,
) -> Regional {
    if floor <= 0.0 {
        return Regional::default();
    }
    let nx = node.lo.len();
    let nu = st.points[node.corners[0]].u.len();
    let mut lo = vec![f64::INFINITY; nu * nx];
    let mut hi = vec![f64::NEG_INFINITY; nu * nx];
    let mut quotient = vec![0.0f64; nu * nx];
    let mut see = |p: &Point| {
        for (j, &g) in p.du.iter().enumerate() {
            lo[j] = lo[j].min(g);
            hi[j] = hi[j].max(g);
        }
    };
    for (c, &ci) in node.corners.iter().enumerate() {
        let v = &st.points[ci];
        if !v.labelled() {
            continue;
        }
        see(v);
        for k in 0..nx {
            let s = node.size[k];
            let key_k = if c & (1 << k) == 0 {
                v.key[k].checked_sub(s)
            } else {
                Some(v.key[k] + s).filter(|&x| x <= lat.max[k])
            };
            let Some(key_k) = key_k else { continue };
            let mut key = v.key.clone();
            key[k] = key_k;
            let Some(n) = idx.get(&key).map(|&i| &st.points[i]) else {
                continue;
            };
            if !n.labelled() {
                continue;
            }
            see(n);
            let wk = s as f64 * lat.step[k];
            for i in 0..nu {
                let j = i * nx + k;
                quotient[j] = quotient[j].max((n.du[j] - v.du[j]).abs() / wk);
            }
        }
    }
    let spread = lo
        .iter()
        .zip(&hi)
        .map(|(a, b)| if b >= a { b - a } else { 0.0 })
        .collect();
    Regional { spread, quotient }
}

/// Whether `x` lies in the closed box [lo, hi].
pub(super) fn contains(lo: &[f64], hi: &[f64], x: &[f64]) -> bool {
    (0..lo.len()).all(|k| lo[k] <= x[k] && x[k] <= hi[k])
}

/// Creates the centre point of every leaf that is a smooth candidate and has none yet,
/// while the budget allows; returns the new points (to label).
pub(super) fn add_centres(ctx: &mut Ctx, st: &mut RefineState, budget: usize) -> Vec<usize> {
    let mut new = Vec::new();
    for n in 0..st.nodes.len() {
        let node = &st.nodes[n];
        if node.split.is_some() || !smooth_candidate(st, node) {
            continue;
        }
        let Some(key) = centre_key(node) else {
            continue;
        };
        if ctx.index.contains_key(&key) {
            continue;
        }
        if st.points.len() >= budget {
            break;
        }
        ctx.point(st, key, &mut new);
    }
    new
}
