//! The check's solves ahead give the check of the solves made in it, bit for bit.

use super::super::check::check_with;
use super::super::tests::{quick_refine, stiff_spring};
use super::super::*;
use super::*;

/// A check with seconds zeroed (the one field that is not a function of the inputs).
fn timeless(mut c: Check) -> Check {
    c.seconds = 0.0;
    c
}

/// A refinement with the solves ahead on a problem with an infeasible part of X: every
/// queued state solved ahead (the gate held open on the final tree), the check that takes
/// them is the check that solves them itself, field for field.
#[test]
fn the_check_with_solves_ahead_is_the_check_without() {
    let cfg = stiff_spring();
    let rs = quick_refine([5, 5], 300, 5, 0.5);
    let (n, seed) = (60, 7);
    let ahead = std::sync::Arc::new(CheckAhead::start(&cfg, &rs, n, seed));
    let opts = RefineOptions {
        ahead: Some(ahead.clone()),
        ..Default::default()
    };
    let r = refine(&cfg, &rs, None, &opts).unwrap();
    let lat = Lattice::new(&cfg.domain.lo, &cfg.domain.hi, &rs.initial_counts(2));
    let gate = ahead.open(&r.state, &lat, &Exclusion::new(&rs, &lat.max));
    ahead.drain();
    drop(gate);
    let ready = ahead.finish();
    let (uniform, cells) = ready.counts();
    assert_eq!(uniform, n);
    assert!(
        cells >= r.state.bounds.len(),
        "{cells} cell states for {} cells",
        r.state.bounds.len()
    );
    assert!(ready.of(&cfg, seed) && !ready.of(&cfg, seed + 1));
    let with = timeless(check_with(&cfg, &rs, &r, (n, seed), Some(&ready)));
    let without = timeless(check(&cfg, &rs, &r, n, seed));
    assert_eq!(with, without);
    assert!(with.per_cell.states > 0 && with.labelled > 0);
    // The check does take them: a result altered ahead shows in the check.
    let mut altered = ready;
    for (_, _, s) in altered.samples.values_mut() {
        if let Some(u) = s.u.as_mut() {
            u[0] += 1e3;
        }
    }
    for l in altered.labels.iter_mut().flatten() {
        l.u[0] += 1e3;
    }
    let taken = timeless(check_with(&cfg, &rs, &r, (n, seed), Some(&altered)));
    assert!(
        taken.max_observed > without.max_observed + 100.0,
        "{taken:?}"
    );
    assert!(taken.per_cell.over_cell > without.per_cell.over_cell);
}

/// A result solved at another state is never taken: the check solves that state itself.
#[test]
fn a_result_at_another_state_is_not_taken() {
    let cfg = stiff_spring();
    let rs = quick_refine([3, 3], 20, 1, 0.5);
    let ahead = CheckAhead::start(&cfg, &rs, 3, 1);
    let (st, lat) = {
        let (_, st, lat) = super::super::tests::grid(&cfg, [3, 3]);
        (st, lat)
    };
    let gate = ahead.open(&st, &lat, &Exclusion::new(&rs, &lat.max));
    ahead.drain();
    drop(gate);
    let ready = ahead.finish();
    let x = uniform_state(&cfg, 1, 0);
    assert!(ready.label(0, &x).is_some());
    let mut y = x.clone();
    y[0] = f64::from_bits(y[0].to_bits() ^ 1);
    assert!(ready.label(0, &y).is_none());
    assert!(ready.label(3, &x).is_none());
    let leaf = (0..st.nodes.len())
        .find(|&n| st.nodes[n].split.is_none())
        .unwrap();
    let node = &st.nodes[leaf];
    let hi: Vec<u64> = node.lo.iter().zip(&node.size).map(|(a, b)| a + b).collect();
    let (lo, hi) = (lat.x(&node.lo), lat.x(&hi));
    let at = cell_state(cell_stream(1), node, (&lo, &hi), 0);
    let corners: Vec<_> = node.corners.iter().map(|&c| &st.points[c]).collect();
    let near = corners[nearest_corner(&corners, &at, (&lo, &hi))].x.clone();
    assert!(ready.sample(node, 0, &at, &near).is_some());
    let mut moved = at.clone();
    moved[1] = f64::from_bits(moved[1].to_bits() ^ 1);
    assert!(ready.sample(node, 0, &moved, &near).is_none());
    let other = corners.iter().map(|c| &c.x).find(|x| **x != near).unwrap();
    assert!(ready.sample(node, 0, &at, other).is_none());
}
