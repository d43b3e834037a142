//! [`Unlabelled`]: where the MPC left a dataset's states without a label — the feasibility
//! pre-scan of X. From a labelled sampling plan {x_i} it counts the states whose status is
//! not a label (infeasible, or the solver found no solution) by status and gives the
//! smallest box [lo, hi] ⊇ {x_i unlabelled} (lo = min_i x_i, hi = max_i x_i per axis), so
//! that every later stage can work on the labelled states and say where the others are
//! (`infeasible.json` in a run directory).

use super::dataset::Dataset;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The unlabelled states of a dataset (module doc).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Unlabelled {
    /// States of the dataset.
    pub states: usize,
    /// States without a label.
    pub unlabelled: usize,
    /// Unlabelled states per solver status (`infeasible`, `max_iterations`, …).
    pub by_status: BTreeMap<String, usize>,
    /// The smallest box (lower, upper corner) holding every unlabelled state.
    pub bounding_box: Option<(Vec<f64>, Vec<f64>)>,
    /// What the counts mean, in words.
    pub note: String,
}

impl Unlabelled {
    /// The unlabelled states of `ds`.
    pub fn of(ds: &Dataset) -> Self {
        let bad: Vec<_> = ds.records.iter().filter(|r| !r.is_labelled()).collect();
        let mut by_status = BTreeMap::new();
        for r in &bad {
            let name = serde_json::to_value(r.status)
                .ok()
                .and_then(|v| v.as_str().map(str::to_string))
                .unwrap_or_else(|| format!("{:?}", r.status));
            *by_status.entry(name).or_insert(0) += 1;
        }
        Unlabelled {
            states: ds.records.len(),
            unlabelled: bad.len(),
            by_status,
            bounding_box: bounding_box(bad.iter().map(|r| r.x.as_slice())),
            note: "States of the sampling plan where the MPC has no label (its OCP infeasible, \
                   or no solution found): training and certification use the labelled \
                   states only; the box is where the unlabelled ones lie (it may also hold \
                   labelled states)."
                .into(),
        }
    }
}

/// The smallest box (lower, upper corner) holding `states`; None when there are none.
pub fn bounding_box<'a>(
    states: impl IntoIterator<Item = &'a [f64]>,
) -> Option<(Vec<f64>, Vec<f64>)> {
    let mut it = states.into_iter();
    let first = it.next()?;
    let (mut lo, mut hi) = (first.to_vec(), first.to_vec());
    for x in it {
        for (i, v) in x.iter().enumerate() {
            lo[i] = lo[i].min(*v);
            hi[i] = hi[i].max(*v);
        }
    }
    Some((lo, hi))
}
