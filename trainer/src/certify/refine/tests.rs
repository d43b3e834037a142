//! The refinement's lattice lookup and state handling.

use super::check::leaf_of;
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
                    + (cfg.domain.hi[k] - cfg.domain.lo[k]) * crate::rng::uniform(6, s, k as u64)
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
