//! The per-cell (stratified) check of the local certificate: every leaf cell C gets
//! 1 + `extra` (where ε_C ≥ `near` × target) fresh MPC solves at uniform states inside it,
//! keyed by the check's seed and the cell itself (so they can be solved ahead, while the
//! refinement retrains: [`super::ahead`]). At each state x with a regular label it records whether ∂κ(x)/∂x lies in C's
//! estimated range ([`crate::certify::local::mpc_slope_estimate`], the one the certificate
//! uses) and whether |κ(x) − sat(κ_NN(x))| ≤ ε_C; at each converged state it also solves
//! again warm-started from C's nearest corner: two converged solves more than
//! `jump_tol` × the input band apart are different local optima — a jump of κ, which the
//! estimate (continuity) cannot bound. The check passes when no state exceeds its ε_C, no
//! jump is found and the share of regular states whose sensitivity misses its range is at
//! most `tolerance`; the offending cells (a miss, an excess or a jump) are listed, for the
//! refinement to split ([`super::reopen`]).

pub use super::solves::Sample;
use super::solves::{cell_state, cell_stream, nearest_corner, Ready};
use super::*;
use crate::certify::local::{mpc_slope_estimate, CellBound, LocalSettings};
use crate::learn::mlp::{Mlp, Workspace};
use crate::problem::CheckSettings;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// A cell the per-cell check found at fault.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OffendingCell {
    /// The leaf's node index in the refinement state.
    pub leaf: usize,
    /// The cell's lower corner.
    pub lo: Vec<f64>,
    /// The cell's upper corner.
    pub hi: Vec<f64>,
    /// Its ε_C.
    pub eps_cell: f64,
    /// States checked in it.
    pub states: usize,
    /// Of which with ∂κ outside the estimated range.
    pub range_misses: usize,
    /// Of which with |e| > ε_C.
    pub over_cell: usize,
    /// Largest distance of a missed sensitivity outside its range (units of ∂κ/∂x).
    pub max_excess: f64,
    /// A jump of κ was found in it (never certified).
    pub jump: bool,
}

/// The result of the per-cell check (`per_cell` in `check.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct CellCheck {
    /// Leaf cells (each visited by at least one state).
    pub cells: usize,
    /// Cells with extra states (ε_C ≥ near × target).
    pub near_cells: usize,
    /// States solved.
    pub states: usize,
    /// Of which labelled (converged or soft).
    pub labelled: usize,
    /// Regular labels in cells with an estimated MPC part: sensitivities compared.
    pub regular: usize,
    /// Of which at least one component of ∂κ/∂x outside the cell's estimated range.
    pub range_misses: usize,
    /// range_misses / regular (0 when none compared).
    pub miss_rate: f64,
    /// The tolerated miss rate (`[refine.check] tolerance`).
    pub tolerance: f64,
    /// States whose error exceeds their cell's ε_C.
    pub over_cell: usize,
    /// States where cold- and warm-started solves converged to different u.
    pub jumps: usize,
    /// Largest |u_cold − u_warm| / input band over the states where both converged.
    pub max_jump: f64,
    /// Whether the check passed (no excess, no jump, miss rate ≤ tolerance).
    pub passed: bool,
    /// Number of offending cells.
    pub offending_cells: usize,
    /// Up to 100 offending cells, most misses first.
    pub offending: Vec<OffendingCell>,
    /// Every offending leaf (node index), for the refinement to split.
    #[serde(skip)]
    pub leaves: Vec<usize>,
    /// The states with a jump.
    pub jump_states: Vec<Vec<f64>>,
}

/// What the per-cell check needs of a refinement.
pub(super) struct Setup<'a> {
    pub st: &'a RefineState,
    pub lat: &'a Lattice,
    pub mlp: &'a Mlp,
    pub band: (&'a [f64], &'a [f64]),
    pub ls: LocalSettings,
    pub centre_check: bool,
    pub settings: &'a CheckSettings,
    pub target: f64,
    pub seed: u64,
    /// S_u of the certificate's norm (empty: unscaled): sampled errors are ‖S_u⁻¹·‖₂.
    pub u_scale: &'a [f64],
    /// Samples solved ahead, during the refinement ([`super::ahead`]).
    pub ahead: Option<&'a Ready>,
}

#[derive(Default, Clone)]
struct PerLeaf {
    states: usize,
    labelled: usize,
    regular: usize,
    misses: usize,
    over: usize,
    excess: f64,
    jumps: Vec<Vec<f64>>,
    max_jump: f64,
}

/// Runs the per-cell check with `solve(workspace, x, nearest corner)` as the MPC law
/// (`init` makes a workspace per thread).
pub(super) fn per_cell<W>(
    s: &Setup,
    init: impl Fn() -> W + Sync + Send,
    solve: impl Fn(&mut W, &[f64], &[f64]) -> Sample + Sync + Send,
) -> CellCheck {
    let st = s.st;
    let idx = region::index(st);
    let nu = s.mlp.nu();
    let bounds: Vec<&(usize, CellBound)> = st.bounds.iter().collect();
    // Stream of the states: the cell (its lattice corner and size) and the state's number.
    let seed = cell_stream(s.seed);
    let per: Vec<PerLeaf> = bounds
        .par_iter()
        .map_init(
            || (init(), Workspace::default()),
            |(w, ws), (leaf, b)| {
                let node = &st.nodes[*leaf];
                let nx = node.lo.len();
                let (lo, hi) = s.lat.cell(node);
                let near = b.eps >= s.settings.near * s.target;
                let m = 1 + if near { s.settings.extra } else { 0 };
                let corners: Vec<_> = node.corners.iter().map(|&c| &st.points[c]).collect();
                let est = !b.exact && corners.iter().all(|p| p.labelled());
                let cs: Vec<_> = corners.iter().map(|p| region::corner(p)).collect();
                let centre = region::centre(st, &idx, node, s.centre_check);
                let reg = region::regional(st, &idx, s.lat, node, s.ls.floor);
                let mut a = PerLeaf::default();
                for q in 0..m {
                    let x = cell_state(seed, node, (&lo, &hi), q);
                    let nearest = nearest_corner(&corners, &x, (&lo, &hi));
                    // Solved ahead (the same state, bit for bit), or here.
                    let smp = s
                        .ahead
                        .and_then(|a| a.sample(node, q, &x, &corners[nearest].x))
                        .unwrap_or_else(|| solve(w, &x, &corners[nearest].x));
                    a.states += 1;
                    let Some(u) = smp.u else { continue };
                    a.labelled += 1;
                    let (mut un, mut jn) = (vec![0.0; nu], vec![0.0; nu * nx]);
                    s.mlp.eval(&x, &mut un, &mut jn, ws);
                    let e = crate::certify::local::clamped_error(&u, &un, s.band, s.u_scale);
                    let e = if e.is_finite() { e } else { f64::INFINITY };
                    a.over += (e > b.eps) as usize;
                    if let Some(wu) = &smp.warm {
                        let jump = (0..nu)
                            .map(|r| (wu[r] - u[r]).abs() / (s.band.1[r] - s.band.0[r]))
                            .fold(0.0, f64::max);
                        a.max_jump = a.max_jump.max(jump);
                        if jump > s.settings.jump_tol {
                            a.jumps.push(x.clone());
                        }
                    }
                    let Some(du) = smp.du.filter(|_| est) else {
                        continue;
                    };
                    a.regular += 1;
                    let mut out = 0.0f64;
                    let mut missed = false;
                    for r in 0..nu {
                        for k in 0..nx {
                            let wk = hi[k] - lo[k];
                            let (kr, _) =
                                mpc_slope_estimate(&cs, centre.as_ref(), &reg, wk, nx, r, k, &s.ls);
                            let g = du[r * nx + k];
                            if !kr.contains(g) {
                                missed = true;
                                out = out.max((kr.lo - g).max(g - kr.hi));
                            }
                        }
                    }
                    if missed {
                        a.misses += 1;
                        a.excess = a.excess.max(out);
                    }
                }
                a
            },
        )
        .collect();
    let mut c = CellCheck {
        cells: bounds.len(),
        tolerance: s.settings.tolerance,
        ..Default::default()
    };
    let mut offending = Vec::new();
    for ((leaf, b), a) in bounds.iter().map(|x| (x.0, &x.1)).zip(&per) {
        c.near_cells += (a.states > 1) as usize;
        c.states += a.states;
        c.labelled += a.labelled;
        c.regular += a.regular;
        c.range_misses += a.misses;
        c.over_cell += a.over;
        c.jumps += a.jumps.len();
        c.max_jump = c.max_jump.max(a.max_jump);
        c.jump_states.extend(a.jumps.iter().cloned());
        if a.misses > 0 || a.over > 0 || !a.jumps.is_empty() {
            let node = &st.nodes[leaf];
            let (lo, hi) = s.lat.cell(node);
            offending.push(OffendingCell {
                leaf,
                lo,
                hi,
                eps_cell: b.eps,
                states: a.states,
                range_misses: a.misses,
                over_cell: a.over,
                max_excess: a.excess,
                jump: !a.jumps.is_empty(),
            });
        }
    }
    c.miss_rate = if c.regular > 0 {
        c.range_misses as f64 / c.regular as f64
    } else {
        0.0
    };
    c.passed = c.over_cell == 0 && c.jumps == 0 && c.miss_rate <= c.tolerance;
    c.offending_cells = offending.len();
    c.leaves = offending.iter().map(|o| o.leaf).collect();
    offending.sort_by(|a, b| {
        (b.range_misses + b.over_cell)
            .cmp(&(a.range_misses + a.over_cell))
            .then(b.max_excess.total_cmp(&a.max_excess))
            .then(a.leaf.cmp(&b.leaf))
    });
    offending.truncate(100);
    c.offending = offending;
    c
}
