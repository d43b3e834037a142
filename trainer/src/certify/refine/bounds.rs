//! Bounding the leaf cells under a net ([`bound_leaves`]): each leaf's ε_C
//! ([`crate::certify::local::cell_bound`], or a QP's exact bound where its critical-region
//! proof succeeds), from its corners, its neighbourhood and the net's enclosures over it
//! ([`NetBoxes`]: kept while the net is the same, so a round without a retraining bounds only
//! its new cells).

use super::*;
use crate::certify::critical::QpCertifier;
use crate::certify::local::{cell_bound, CellBound, Corner, Form, LocalSettings};
use crate::certify::netbounds::{BoxBounds, NetBounder};
use crate::learn::mlp::{Mlp, Workspace};

/// Bounds every leaf; returns (leaf, bound) in leaf order. Where the MPC is a QP (`qp`: the
/// certifier and the target ε), a cell whose critical-region proof succeeds gets the exact
/// bound ([`exact_cell_bound`]) if it meets the target or beats the estimate, the others
/// the estimate ([`cell_bound`]). The excluded leaves ([`RefineState::excluded_by`]: all
/// corners hard-infeasible with `refine.exclude_infeasible`, an unlabelled corner at the
/// smallest size `refine.min_cell`) are left out: they are not part of the certified
/// domain.
#[allow(clippy::too_many_arguments)]
pub(super) fn bound_leaves(
    st: &RefineState,
    lat: &Lattice,
    mlp: &Mlp,
    band: (&[f64], &[f64]),
    ls: &LocalSettings,
    centre_check: bool,
    qp: Option<(&QpCertifier, f64)>,
    ex: &Exclusion,
    u_scale: &[f64],
    boxes: &NetBoxes,
) -> Vec<(usize, CellBound)> {
    let idx = region::index(st);
    let target = qp.map_or(f64::INFINITY, |(_, t)| t);
    let qp = qp.map(|(q, _)| q);
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
        .filter(|&i| st.nodes[i].split.is_none() && !st.excluded_by(i, ex))
        .collect();
    // The net's enclosures over cells it bounded before (the same net: a round without a
    // retraining), or fresh ones, kept for the next call.
    // The net by its bits (`==` on f64 would take −0.0 for 0.0); the map is taken out of
    // the lock for the bounding, so that no lock is held across the parallel work.
    let bits = postcard::to_allocvec(mlp).unwrap_or_default();
    let (net, mut known) = std::mem::take(
        &mut *boxes
            .0
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner),
    );
    if net.as_deref() != Some(bits.as_slice()) || bits.is_empty() {
        known.clear();
    }
    let known_ref = &known;
    let net_box = |node: &Node, (lo, hi): (&[f64], &[f64]), fresh: &mut Fresh| {
        let key = (node.lo.clone(), node.size.clone());
        if let Some(b) = known_ref.get(&key) {
            return b.clone();
        }
        let b = nb.bounds(lo, hi);
        *fresh = Some((key, b.clone()));
        b
    };
    let leaf_bound = |n: usize, fresh: &mut Fresh| -> (usize, CellBound) {
        let node = &st.nodes[n];
        let (lo, hi) = lat.cell(node);
        let pts: Vec<&Point> = node.corners.iter().map(|&c| &st.points[c]).collect();
        let nu_c: Vec<f64> = node
            .corners
            .iter()
            .flat_map(|&c| net_u[c * nu..(c + 1) * nu].iter().copied())
            .collect();
        // Where the MPC is a QP: the exact bound if the cell's proof succeeds (it needs
        // no labels, only candidate active sets from some corners).
        let exact = qp.and_then(|q| {
            let sets: Vec<Option<&[usize]>> = pts.iter().map(|p| p.active.as_deref()).collect();
            let laws = q.prove_from_corners(&lo, &hi, &sets)?;
            // Each law bounded only where it can be the solution (bisected towards
            // the target).
            let b = q.restricted_bound(&lo, &hi, &laws, mlp, &nb, band, target);
            b.exact.then_some(b)
        });
        if !pts.iter().all(|p| p.labelled()) {
            if let Some(b) = exact {
                return (n, b);
            }
            let b = CellBound {
                eps: f64::INFINITY,
                corner: f64::INFINITY,
                remainder: f64::INFINITY,
                form: Form::FirstOrder,
                axis_terms: vec![f64::INFINITY; lo.len()],
                exact: false,
            };
            return (n, b);
        }
        let corners: Vec<Corner> = pts.iter().map(|p| region::corner(p)).collect();
        let centre = region::centre(st, &idx, node, centre_check);
        let reg = region::regional(st, &idx, lat, node, ls.floor);
        let mut estimated = cell_bound(
            &lo,
            &hi,
            &corners,
            centre.as_ref(),
            &reg,
            &nu_c,
            &net_box(node, (&lo, &hi), fresh),
            band,
            ls,
            u_scale,
        );
        // A jump of κ found inside the cell: the continuity the estimate assumes fails.
        if st.jumps.iter().any(|x| region::contains(&lo, &hi, x)) {
            estimated = CellBound {
                eps: f64::INFINITY,
                remainder: f64::INFINITY,
                axis_terms: vec![f64::INFINITY; lo.len()],
                ..estimated
            };
        }
        // The exact bound bounds each candidate law on outer boxes of its region (a
        // superset of where it holds): at a steep region boundary it can still be
        // looser than the estimate. It is kept when it meets the target (`target`) or beats
        // the estimate; otherwise the estimate is (the cell counts as not exact, so
        // the tier says "estimated" and refinement splits it further): the proof never
        // makes a QP's ε miss a target the estimate meets.
        match exact {
            Some(b) if b.eps <= estimated.eps.max(target) => (n, b),
            _ => (n, estimated),
        }
    };
    let bounded: Vec<((usize, CellBound), Fresh)> = leaves
        .par_iter()
        .map(|&n| {
            let mut fresh = None;
            (leaf_bound(n, &mut fresh), fresh)
        })
        .collect();
    let mut out = Vec::with_capacity(bounded.len());
    for (b, fresh) in bounded {
        if let Some((k, v)) = fresh {
            known.insert(k, v);
        }
        out.push(b);
    }
    *boxes
        .0
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner) = (Some(bits), known);
    out
}

/// The key of a cell's net enclosure: its lattice corner and size.
type BoxKey = (Vec<u64>, Vec<u64>);

/// A net enclosure computed by this call of [`bound_leaves`], to keep.
type Fresh = Option<(BoxKey, BoxBounds)>;

/// The net's enclosures over cells ([`NetBounder::bounds`]) under the last net
/// [`bound_leaves`] bounded with: a pure function of the net and the cell, so a round that
/// keeps its net (no retraining) bounds its unchanged cells without computing them again.
/// The net is kept as its serialised bytes (postcard: every weight bit for bit).
#[derive(Default)]
pub(super) struct NetBoxes(std::sync::Mutex<Kept>);

/// The last net's bytes and its enclosures by cell.
type Kept = (Option<Vec<u8>>, HashMap<BoxKey, BoxBounds>);
