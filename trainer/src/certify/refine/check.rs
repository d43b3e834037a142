//! The local certificate against fresh MPC solves at independent random states: the error of
//! the clamped net against its cell's ε_C, and how much of each cell's remainder is used —
//! uniformly over X, and per cell ([`super::cellcheck`]: every cell visited, the verdict).

use super::solves::{mpc_sample, uniform_state, NeighbourCache, Ready};
use super::*;
use crate::certify::local::{CellBound, Corner};
use crate::learn::mlp::Workspace;
use crate::mpc::law::MpcLaw;
use crate::mpc::sqp::SqpStatus;
use crate::problem::{ProblemConfig, RefineSettings};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::time::Instant;

/// The leaf cell containing `x` (clamped into X), descending the k-d tree.
pub(super) fn leaf_of(st: &RefineState, lat: &Lattice, counts: &[usize], x: &[f64]) -> usize {
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
    /// With `refine.exclude_infeasible`: states that fell in an excluded cell (not counted
    /// above: ε does not cover them).
    #[serde(default)]
    pub excluded_states: usize,
    /// Of which the hard OCP was feasible (converged): where the feasible set reaches into an
    /// excluded cell between its corners — the estimate behind the exclusion missed them.
    #[serde(default)]
    pub feasible_in_excluded: usize,
    /// The excluded leaves those feasible states fell in (node indices, for
    /// [`super::reopen`]: splitting them turns their feasible part into cells).
    #[serde(skip)]
    pub feasible_excluded_leaves: Vec<usize>,
    /// The per-cell (stratified) check and its verdict.
    pub per_cell: super::CellCheck,
    /// Wall time, seconds.
    pub seconds: f64,
}

/// Solves the MPC at `n` random states and compares with the certificate of `r`.
pub fn check(cfg: &ProblemConfig, rs: &RefineSettings, r: &Refined, n: usize, seed: u64) -> Check {
    check_with(cfg, rs, r, (n, seed), None)
}

/// [`check`], taking the solves that `ahead` finished during the refinement (the same
/// result, bit for bit: [`super::ahead`]).
pub fn check_ahead(
    cfg: &ProblemConfig,
    rs: &RefineSettings,
    r: &Refined,
    (n, seed): (usize, u64),
    ahead: &super::CheckAhead,
) -> Check {
    let ready = ahead.finish();
    check_with(
        cfg,
        rs,
        r,
        (n, seed),
        Some(&ready).filter(|a| a.of(cfg, seed)),
    )
}

pub(super) fn check_with(
    cfg: &ProblemConfig,
    rs: &RefineSettings,
    r: &Refined,
    (n, seed): (usize, u64),
    ahead: Option<&Ready>,
) -> Check {
    let t0 = Instant::now();
    let (nx, nu) = (cfg.system.nx(), cfg.system.nu());
    let counts = rs.initial_counts(nx);
    let lat = Lattice::new(&cfg.domain.lo, &cfg.domain.hi, &counts);
    let ex = Exclusion::new(rs, &lat.max);
    let st = &r.state;
    let mlp = &r.model.mlp;
    let band = cfg.ocp.u_bounds(0);
    // Errors in the certificate's norm ‖S_u⁻¹·‖₂, as the cells' bounds.
    let u_scale = crate::certify::norm::Norm::of_problem(cfg).u_scale;
    let bound_of: HashMap<usize, &CellBound> = st.bounds.iter().map(|(n, b)| (*n, b)).collect();
    let certified = super::rounds::max_eps(&st.bounds);
    let ls = super::rounds::local_settings(rs);
    let centre_check =
        rs.centre_check && crate::certify::critical::QpCertifier::detect(cfg).is_err();
    let idx = super::region::index(st);
    let acc = (0..n)
        .into_par_iter()
        .fold_chunks(
            1024,
            || (None::<MpcLaw>, Workspace::default(), Acc::default()),
            |(law, mut ws, mut a), i| {
                let law = law.unwrap_or_else(|| MpcLaw::new(cfg));
                let mut law = law;
                let x = uniform_state(cfg, seed, i);
                let l = ahead
                    .and_then(|a| a.label(i, &x))
                    .unwrap_or_else(|| law.solve(&x, None).0);
                let leaf = leaf_of(st, &lat, &counts, &x);
                if st.excluded_by(leaf, &ex) {
                    a.excluded += 1;
                    if l.status == SqpStatus::Converged {
                        a.feasible_excluded += 1;
                        a.feasible_leaves.push(leaf);
                    }
                } else if l.u.iter().all(|v| v.is_finite()) {
                    a.labelled += 1;
                    let (mut u, mut j) = (vec![0.0; nu], vec![0.0; nu * nx]);
                    mlp.eval(&x, &mut u, &mut j, &mut ws);
                    let e = crate::certify::local::clamped_error(&l.u, &u, band, &u_scale);
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
                        let cell = (&lat, &idx, &ls, centre_check);
                        slope_check(st, cell, leaf, &l.du_dx, (nx, nu), &mut a);
                    }
                }
                (Some(law), ws, a)
            },
        )
        .map(|(_, _, a)| a)
        .reduce(Acc::default, Acc::merge);
    let per_cell = super::cellcheck::per_cell(
        &super::cellcheck::Setup {
            st,
            lat: &lat,
            mlp,
            band,
            ls,
            centre_check,
            settings: &rs.check,
            target: rs.target_eps,
            seed,
            u_scale: &u_scale,
            ahead,
        },
        || (MpcLaw::new(cfg), NeighbourCache::default()),
        mpc_sample,
    );
    Check {
        per_cell,
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
        excluded_states: acc.excluded,
        feasible_in_excluded: acc.feasible_excluded,
        feasible_excluded_leaves: {
            let mut v = acc.feasible_leaves;
            v.sort_unstable();
            v.dedup();
            v
        },
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

/// The check's running totals over its states (merged across threads in state order).
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
    excluded: usize,
    feasible_excluded: usize,
    feasible_leaves: Vec<usize>,
}

impl Acc {
    /// `x` then `y`: sums, maxima, the first 20 offenders, the leaves in order.
    fn merge(mut x: Acc, y: Acc) -> Acc {
        Acc {
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
            excluded: x.excluded + y.excluded,
            feasible_excluded: x.feasible_excluded + y.feasible_excluded,
            feasible_leaves: {
                let mut v = x.feasible_leaves;
                v.extend(y.feasible_leaves);
                v
            },
        }
    }
}

/// Checks the solved ∂κ/∂x (`du_dx`, row-major nu×nx) at a state of cell `leaf` against the
/// cell's estimated slope range of every entry; counts checks, misses and the largest excess.
fn slope_check(
    st: &RefineState,
    (lat, idx, ls, centre_check): (
        &Lattice,
        &HashMap<Vec<u64>, usize>,
        &crate::certify::local::LocalSettings,
        bool,
    ),
    leaf: usize,
    du_dx: &[f64],
    (nx, nu): (usize, usize),
    a: &mut Acc,
) {
    let node = &st.nodes[leaf];
    let corners: Vec<Corner> = node
        .corners
        .iter()
        .map(|&c| super::region::corner(&st.points[c]))
        .collect();
    let centre = super::region::centre(st, idx, node, centre_check);
    let reg = super::region::regional(st, idx, lat, node, ls.floor);
    for r in 0..nu {
        for k in 0..nx {
            let wk = node.size[k] as f64 * lat.step[k];
            let (kr, _) = crate::certify::local::mpc_slope_estimate(
                &corners,
                centre.as_ref(),
                &reg,
                wk,
                nx,
                r,
                k,
                ls,
            );
            a.checks += 1;
            let g = du_dx[r * nx + k];
            if !kr.contains(g) {
                a.misses += 1;
                let out = (kr.lo - g).max(g - kr.hi);
                a.excess = a.excess.max(out);
            }
        }
    }
}
