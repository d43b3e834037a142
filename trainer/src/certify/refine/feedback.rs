//! The per-cell check's feedback into the refinement: the offending cells of a failed check
//! are split once (along their longest side relative to X), the jump states it found are
//! stored (their cells are never certified), and the checkpoint is reopened so that the next
//! [`super::refine`] call labels the new corners and goes on from there.

use super::*;
use crate::io::write_atomic;
use crate::problem::RefineSettings;
use std::path::Path;

/// Splits the leaves `leaves` of the finished state `state` (those still splittable: at least two lattice
/// steps and `min_width` along the chosen side), adds `jumps` to its jump states and writes
/// the reopened state to `checkpoint`. Returns the number of cells split.
pub fn reopen(
    cfg: &ProblemConfig,
    rs: &RefineSettings,
    state: &RefineState,
    leaves: &[usize],
    jumps: &[Vec<f64>],
    checkpoint: &Path,
) -> Result<usize, RefineError> {
    let mut st = state.clone();
    let counts = rs.initial_counts(cfg.system.nx());
    let lat = Lattice::new(&cfg.domain.lo, &cfg.domain.hi, &counts);
    let mut ctx = Ctx {
        cfg,
        lat: lat.clone(),
        index: region::index(&st),
    };
    let mut pending = Vec::new();
    let mut split = 0;
    for &n in leaves {
        let node = st.nodes[n].clone();
        if node.split.is_some() {
            continue;
        }
        let rel = |k: usize| node.size[k] as f64 / lat.max[k] as f64;
        let axis = (0..node.lo.len())
            .filter(|&k| node.size[k] >= 2 && rel(k) >= rs.min_width)
            .max_by(|&a, &b| rel(a).total_cmp(&rel(b)).then(b.cmp(&a)));
        let Some(axis) = axis else { continue };
        ctx.split(&mut st, n, axis, &mut pending);
        split += 1;
    }
    st.jumps.extend(jumps.iter().cloned());
    st.finished = false;
    let bytes = crate::io::seal(postcard::to_allocvec(&st).unwrap_or_default());
    write_atomic(checkpoint, &bytes)?;
    Ok(split)
}
