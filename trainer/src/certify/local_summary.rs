//! What `certificate.json` records of a local certificate (`"local"`): [`LocalSummary`] —
//! ε = max_C ε_C over the leaf cells of the refinement's k-d tree, the term that binds in the
//! worst cell, the solve counts against the uniform grid Theorem 1 would need — and
//! [`Excluded`], the part of X left out of the certified domain (ε holds on X minus its
//! boxes). Written by `refine`, read and re-checked by `file`.

use serde::{Deserialize, Serialize};

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
    /// Regional floor c under the estimated MPC parts (`[refine] floor`).
    pub floor: f64,
    /// States where `--check` found a jump of κ (two local optima); their cells are never
    /// certified (ε_C = ∞).
    pub jumps: usize,
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
    /// Where the MPC is a QP: cells whose MPC part is exact (κ proven affine piecewise on
    /// them, `certify::critical`); absent for other problems.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cells_exact: Option<usize>,
    /// With `refine.exclude_infeasible`: the part of X excluded from the certified domain
    /// (outside the MPC's feasible set as far as the cells' corners show); absent without
    /// the setting or when no cell is excluded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub excluded: Option<Excluded>,
}

/// The cells excluded from the certified domain (`refine.exclude_infeasible`): ε holds on
/// X minus these boxes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Excluded {
    /// Excluded leaf cells (every corner hard-infeasible, or an unlabelled corner at the
    /// smallest cell size `refine.min_cell`).
    pub cells: usize,
    /// Their share of the volume of X.
    pub volume_fraction: f64,
    /// The excluded set as boxes (lower corner, upper corner): the excluded leaves merged
    /// into maximal subtrees and then across shared faces (their union is exactly the
    /// union of the excluded leaves).
    pub boxes: Vec<(Vec<f64>, Vec<f64>)>,
    /// The states at the excluded cells' corners that the MPC left unlabelled (absent when
    /// none, and in files written before it existed).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub unlabelled_states: Vec<Vec<f64>>,
    /// What the exclusion rests on.
    pub note: String,
}
