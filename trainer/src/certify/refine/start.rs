//! The refinement's start: the checkpoint's identity (`run_hash`), a verified resume from
//! it (`resume`, `reindex`), or the initial grid's cells as the tree's roots
//! (`initial_grid`), with the corners still to be solved in `pending`.

use super::*;
use crate::problem::{ProblemConfig, RefineSettings};
use std::path::Path;

/// The checkpoint's identity: the settings' hash, with a fixed net's content hash and the
/// initial labels' hash when given (a checkpoint of another run does not match).
pub(super) fn run_hash(cfg: &ProblemConfig, rs: &RefineSettings, opts: &RefineOptions) -> String {
    let mut hash = match &opts.fixed {
        // A fixed net: a checkpoint of another net (or of a training run) does not match.
        Some(m) => crate::io::sha256_hex(
            format!("{}|fixed:{}", settings_hash(cfg, rs), m.content_hash()).as_bytes(),
        ),
        None => settings_hash(cfg, rs),
    };
    if let Some(d) = &opts.initial_labels {
        hash = crate::io::sha256_hex(
            format!("{hash}{}", crate::io::sha256_hex(&d.to_bytes())).as_bytes(),
        );
    }
    hash
}

/// The checkpoint's state, if `checkpoint` exists: verified (seal, hash, tree shape).
pub(super) fn resume(
    checkpoint: Option<&Path>,
    hash: &str,
    counts: &[usize],
    lat: &Lattice,
    nu: usize,
) -> Result<Option<RefineState>, RefineError> {
    let Some(p) = checkpoint.filter(|p| p.exists()) else {
        return Ok(None);
    };
    let bytes = std::fs::read(p).map_err(|e| DatasetError::Io {
        path: p.display().to_string(),
        source: e,
    })?;
    let st = RefineState::from_bytes(&bytes, p)?;
    if st.hash != hash {
        return Err(RefineError::Mismatch {
            path: p.to_path_buf(),
        });
    }
    let roots = counts.iter().map(|c| c - 1).product();
    st.check_consistent(&lat.max, roots, nu, p)?;
    Ok(Some(st))
}

/// A new state whose roots are the initial grid's cells (their corners pushed to `pending`).
pub(super) fn initial_grid(
    ctx: &mut Ctx,
    hash: &str,
    counts: &[usize],
    pending: &mut Vec<usize>,
) -> RefineState {
    let nx = counts.len();
    let mut st = RefineState {
        hash: hash.to_string(),
        points: Vec::new(),
        nodes: Vec::new(),
        roots: Vec::new(),
        model: None,
        best: None,
        log: Vec::new(),
        bounds: Vec::new(),
        finished: false,
        jumps: Vec::new(),
    };
    let cells: Vec<usize> = counts.iter().map(|c| c - 1).collect();
    let total: usize = cells.iter().product();
    for mut r in 0..total {
        let mut lo = vec![0u64; nx];
        for k in (0..nx).rev() {
            lo[k] = ((r % cells[k]) as u64) << LEVELS;
            r /= cells[k];
        }
        let n = ctx.node(&mut st, lo, vec![1u64 << LEVELS; nx], pending);
        st.roots.push(n);
    }
    st
}

/// A resumed state with the index of its points rebuilt; the points created by the last
/// checkpointed round's splits, not yet solved, go to `pending`.
pub(super) fn reindex(ctx: &mut Ctx, st: RefineState, pending: &mut Vec<usize>) -> RefineState {
    for (i, p) in st.points.iter().enumerate() {
        ctx.index.insert(p.key.clone(), i);
        if p.status.is_none() {
            pending.push(i);
        }
    }
    st
}

/// What a checkpoint must match: the labels (problem), the domain, the initial grid, the
/// network's shape, the safety factor, the regional floor and the centre check (the
/// certificate's meaning). Target, budget,
/// rounds and training rates may change on resume (e.g. a larger budget continues a run).
fn settings_hash(cfg: &ProblemConfig, rs: &RefineSettings) -> String {
    use sha2::{Digest, Sha256};
    let mut h = Sha256::new();
    h.update(cfg.problem_hash());
    let nx = cfg.system.nx();
    let key = (
        &cfg.domain,
        rs.initial_counts(nx),
        &rs.training.hidden,
        rs.training.activation,
        rs.safety.to_bits(),
        rs.floor.to_bits(),
        rs.centre_check,
    );
    h.update(postcard::to_allocvec(&key).unwrap_or_default());
    if rs.exclude_infeasible {
        // Appended only when on: checkpoints of runs without exclusion keep their hash.
        h.update(b"exclude_infeasible");
    }
    let norm = crate::certify::norm::Norm::of_problem(cfg);
    if !norm.is_unit() {
        // The cells' bounds are in this norm (`certify::local`); appended only when scaled:
        // checkpoints of unscaled runs keep their hash.
        h.update(b"norm");
        h.update(postcard::to_allocvec(&norm.u_scale).unwrap_or_default());
    }
    crate::io::hex(&h.finalize())
}
