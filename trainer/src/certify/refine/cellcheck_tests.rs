//! The per-cell check on synthetic laws: a pocket of another active set strictly inside a
//! cell is caught (and the cell split by the feedback), and a jump of κ (two local optima:
//! the warm-started solve stays on its neighbour's branch) is flagged and never certified.

use super::bounds::bound_leaves;
use super::cellcheck::{per_cell, Sample, Setup};
use super::rounds::local_settings;
use super::*;
use crate::learn::mlp::{Activation, Mlp};
use crate::problem::{CheckSettings, RefineSettings};

/// A synthetic law: x ↦ (κ, ∂κ/∂x, active-set id).
type Law = dyn Fn(&[f64]) -> (f64, [f64; 2], u64) + Sync;

const LO: [f64; 2] = [0.0, 0.0];
const HI: [f64; 2] = [1.6, 1.6];

/// The problem (the pendulum's shape) on X = [0, 1.6]² with a 5 × 5 initial grid (cells of
/// width 0.4), and a small seeded net.
fn setup() -> (ProblemConfig, RefineSettings, Mlp) {
    let mut cfg = ProblemConfig::default();
    cfg.domain.lo = LO.to_vec();
    cfg.domain.hi = HI.to_vec();
    let rs = RefineSettings {
        initial: vec![5, 5],
        centre_check: false,
        check: CheckSettings {
            extra: 19,
            near: 0.0,
            ..Default::default()
        },
        ..Default::default()
    };
    let m = Mlp::new(&[2, 8, 1], Activation::Tanh, 3, &LO, &HI, &[-20.0], &[20.0]);
    (cfg, rs, m)
}

/// The initial grid labelled by `law` (every corner a regular hard solution), bounded.
fn labelled_state(
    cfg: &ProblemConfig,
    rs: &RefineSettings,
    m: &Mlp,
    law: &Law,
) -> (RefineState, Lattice) {
    let counts = rs.initial_counts(2);
    let (_, mut st, lat) = super::tests::grid(cfg, [counts[0], counts[1]]);
    st.finished = true;
    for p in st.points.iter_mut() {
        let (u, g, piece) = law(&p.x);
        p.u = vec![u];
        p.du = g.to_vec();
        p.status = Some(SqpStatus::Converged);
        p.regular = true;
        p.piece = piece;
    }
    bound(&mut st, &lat, rs, m);
    (st, lat)
}

fn bound(st: &mut RefineState, lat: &Lattice, rs: &RefineSettings, m: &Mlp) {
    st.bounds = bound_leaves(
        st,
        lat,
        m,
        (&[-20.0], &[20.0]),
        &local_settings(rs),
        rs.centre_check,
        None,
        &super::Exclusion {
            infeasible: false,
            min_size: vec![0; 2],
        },
        &[],
        &Default::default(),
    );
}

/// The per-cell check of `st` against `cold`, with `warm(x, nearest corner)` the
/// warm-started solve.
fn run(
    st: &RefineState,
    lat: &Lattice,
    rs: &RefineSettings,
    m: &Mlp,
    cold: &Law,
    warm: &(dyn Fn(&[f64], &[f64]) -> f64 + Sync),
) -> super::CellCheck {
    per_cell(
        &Setup {
            st,
            lat,
            mlp: m,
            band: (&[-20.0], &[20.0]),
            ls: local_settings(rs),
            centre_check: rs.centre_check,
            settings: &rs.check,
            target: rs.target_eps,
            seed: 11,
            u_scale: &[],
            ahead: None,
        },
        || (),
        |_, x, near| {
            let (u, g, _) = cold(x);
            Sample {
                u: Some(vec![u]),
                du: Some(g.to_vec()),
                warm: Some(vec![warm(x, near)]),
            }
        },
    )
}

/// Centre, radius and height of the pocket: strictly inside the cell [0.4, 0.8]².
const POCKET: ([f64; 2], f64, f64) = ([0.6, 0.58], 0.15, 5.0);

/// κ₀ = x₁ + 0.3x₂ (active set 0), lifted on the pocket's disk by a cone (active set 1).
fn pocket(x: &[f64], lift: bool) -> (f64, [f64; 2], u64) {
    let ([p0, p1], rho, h) = POCKET;
    let d = ((x[0] - p0).powi(2) + (x[1] - p1).powi(2)).sqrt();
    let (mut u, mut g) = (x[0] + 0.3 * x[1], [1.0, 0.3]);
    if lift && d < rho {
        u += h * (1.0 - d / rho);
        if d > 0.0 {
            g[0] -= h / rho * (x[0] - p0) / d;
            g[1] -= h / rho * (x[1] - p1) / d;
        }
    }
    (u, g, (lift && d < rho) as u64)
}

#[test]
fn a_pocket_inside_a_cell_fails_the_per_cell_check_and_its_cell_is_split() {
    let (cfg, rs, m) = setup();
    let lifted = |x: &[f64]| pocket(x, true);
    let flat = |x: &[f64]| pocket(x, false);
    // The corners cannot see the pocket: the same state (labels, bounds) for both laws.
    let (st, lat) = labelled_state(&cfg, &rs, &m, &lifted);
    let (st0, _) = labelled_state(&cfg, &rs, &m, &flat);
    assert_eq!(st.bounds, st0.bounds);
    let same = |x: &[f64], _: &[f64]| lifted(x).0;
    let c = run(&st, &lat, &rs, &m, &lifted, &same);
    eprintln!(
        "pocket: misses {}/{} (rate {}), offending {:?}",
        c.range_misses, c.regular, c.miss_rate, c.offending
    );
    assert_eq!(c.cells, 16);
    assert_eq!(
        c.states,
        16 * 20,
        "every cell visited, 1 + extra states each"
    );
    assert!(!c.passed);
    assert!(c.miss_rate > rs.check.tolerance);
    let pocket_leaf = check::leaf_of(&st, &lat, &rs.initial_counts(2), &POCKET.0);
    assert_eq!(
        c.leaves,
        vec![pocket_leaf],
        "only the pocket's cell offends"
    );
    // Without the pocket the same check passes.
    let same0 = |x: &[f64], _: &[f64]| flat(x).0;
    let c0 = run(&st0, &lat, &rs, &m, &flat, &same0);
    assert!(c0.passed && c0.leaves.is_empty(), "{c0:?}");
    // The feedback splits the offending cell and reopens the run.
    let dir = std::env::temp_dir().join(format!("ampc-cellcheck-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let ck = dir.join("refine_state.bin");
    assert_eq!(
        reopen(&cfg, &rs, &st, &c.leaves, &c.jump_states, &ck).unwrap(),
        1
    );
    let back = RefineState::from_bytes(&std::fs::read(&ck).unwrap(), &ck).unwrap();
    std::fs::remove_dir_all(&dir).ok();
    assert!(!back.finished);
    assert!(back.nodes[pocket_leaf].split.is_some());
    assert_eq!(back.points.iter().filter(|p| p.status.is_none()).count(), 2);
}

#[test]
fn a_jump_of_kappa_is_flagged_and_its_cell_never_certified() {
    let (cfg, rs, m) = setup();
    // Two local optima: branch +1 for x₁ > 0.7, −1 below (the cold solve's choice); a solve
    // warm-started at a neighbour stays on the neighbour's branch.
    let branch = |x: &[f64]| if x[0] > 0.7 { 1.0 } else { -1.0 };
    let law = move |x: &[f64]| (branch(x) + 0.1 * x[1], [0.0, 0.1], (x[0] > 0.7) as u64);
    let warm = move |x: &[f64], near: &[f64]| branch(near) + 0.1 * x[1];
    let (mut st, lat) = labelled_state(&cfg, &rs, &m, &law);
    let c = run(&st, &lat, &rs, &m, &law, &warm);
    assert!(c.jumps > 0 && !c.passed, "{c:?}");
    assert!(c.max_jump > rs.check.jump_tol);
    // Only cells straddling x₁ = 0.7 jump.
    for o in &c.offending {
        if o.jump {
            assert!(o.lo[0] < 0.7 && 0.7 < o.hi[0], "{o:?}");
        }
    }
    let jumped: Vec<usize> = c
        .offending
        .iter()
        .filter(|o| o.jump)
        .map(|o| o.leaf)
        .collect();
    // A warm start that finds the same optimum: no jump.
    let same = move |x: &[f64], _: &[f64]| law(x).0;
    let c0 = run(&st, &lat, &rs, &m, &law, &same);
    assert_eq!(c0.jumps, 0);
    // Stored, the jump states keep their cells uncertified.
    st.jumps = c.jump_states.clone();
    bound(&mut st, &lat, &rs, &m);
    for (n, b) in &st.bounds {
        assert_eq!(b.eps.is_infinite(), jumped.contains(n), "leaf {n}: {b:?}");
    }
}

/// The regional floor on a refinement state: the cell [0, 0.4]² of the law
/// κ = 3·max(0, x₁ − 0.45) has equal corners (κ = 0, ∂κ = 0), its outward neighbours at
/// x₁ = 0.8 have ∂₁κ = 3: G = (3, 0), Q = (3/0.4, 0); with the floor the cell's bound has an
/// MPC term (a larger remainder than the network's alone), without it none.
#[test]
fn the_floor_reads_the_neighbours_of_a_cell_with_equal_corners() {
    let (cfg, mut rs, m) = setup();
    let law = |x: &[f64]| {
        let on = x[0] > 0.45;
        (
            3.0 * (x[0] - 0.45).max(0.0),
            [if on { 3.0 } else { 0.0 }, 0.0],
            on as u64,
        )
    };
    let (st, lat) = labelled_state(&cfg, &rs, &m, &law);
    let leaf = check::leaf_of(&st, &lat, &rs.initial_counts(2), &[0.2, 0.2]);
    let idx = region::index(&st);
    let reg = region::regional(&st, &idx, &lat, &st.nodes[leaf], 0.5);
    assert_eq!(reg.spread, vec![3.0, 0.0]);
    assert!((reg.quotient[0] - 3.0 / 0.4).abs() < 1e-12 && reg.quotient[1] == 0.0);
    let with = st
        .bounds
        .iter()
        .find(|(n, _)| *n == leaf)
        .unwrap()
        .1
        .clone();
    rs.floor = 0.0;
    let mut st0 = st.clone();
    bound(&mut st0, &lat, &rs, &m);
    let without = st0
        .bounds
        .iter()
        .find(|(n, _)| *n == leaf)
        .unwrap()
        .1
        .clone();
    let zero = |_: &[f64]| (0.0, [0.0, 0.0], 0u64);
    let (mut stz, _) = labelled_state(&cfg, &rs, &m, &zero);
    bound(&mut stz, &lat, &rs, &m);
    let net_only = stz
        .bounds
        .iter()
        .find(|(n, _)| *n == leaf)
        .unwrap()
        .1
        .clone();
    assert_eq!(
        without.remainder, net_only.remainder,
        "no floor: no MPC term"
    );
    assert!(
        with.remainder > net_only.remainder + 0.05,
        "floor: {} vs network alone {}",
        with.remainder,
        net_only.remainder
    );
}
