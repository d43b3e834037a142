//! What a refinement run leaves: its dataset, the local certificate (ε = max_C ε_C with the
//! binding term and the worst cell), `certificate.json`, `cells.csv`, and the cells in
//! physical coordinates for the ε_C map.

use super::rounds::train_set;
use super::*;
use crate::certify::certificate::Certificate;
use crate::certify::file::{write_certificate, CertificateFile, CheckSummary};
use crate::certify::local::Form;
use crate::data::dataset::{Dataset, DatasetError, Header, Record};
use crate::io::{write_atomic, RunDir};
use crate::mpc::sqp::SqpStatus;
use crate::problem::{ProblemConfig, RefineSettings, SamplerKind, SamplingSettings};
use serde::Serialize;
use std::path::Path;

/// The refined points as a dataset file (sampler `adaptive`).
pub fn dataset(cfg: &ProblemConfig, st: &RefineState) -> Dataset {
    let (nx, nu) = (cfg.system.nx(), cfg.system.nu());
    let records = st
        .points
        .iter()
        .enumerate()
        .map(|(i, p)| Record {
            index: i as u64,
            x: p.x.clone(),
            u: p.u.clone(),
            du_dx: p.du.clone(),
            cost: p.cost,
            status: p.status.unwrap_or(SqpStatus::NumericalFailure),
            iterations: 0,
            kkt: f64::NAN,
            degeneracy: p.degeneracy,
            max_slack: p.max_slack,
            seq: Vec::new(),
        })
        .collect::<Vec<_>>();
    Dataset {
        magic: crate::data::dataset::MAGIC,
        version: crate::data::dataset::FORMAT_VERSION,
        header: Header {
            problem: cfg.name.clone(),
            problem_hash: cfg.problem_hash(),
            config_toml: toml::to_string(cfg).unwrap_or_default(),
            nx: nx as u32,
            nu: nu as u32,
            sampling: SamplingSettings {
                sampler: SamplerKind::Adaptive,
                counts: vec![],
                n: records.len(),
                seed: 0,
            },
            total: records.len() as u64,
            shard: None,
            chunk: crate::data::dataset::CHUNK as u32,
        },
        records,
        labels: None,
        disagree: Vec::new(),
    }
}

/// The excluded set of a refinement as merged lattice boxes (lower key, size): maximal
/// subtrees whose leaves are all excluded, then pairs of boxes that share a whole face
/// merged until none does. Empty when no leaf is excluded under `ex`.
pub(super) fn excluded_lattice_boxes(
    st: &RefineState,
    ex: &Exclusion,
) -> Vec<(Vec<u64>, Vec<u64>)> {
    // Whole excluded subtrees, from the roots down.
    fn all_excluded(st: &RefineState, ex: &Exclusion, n: usize, memo: &mut [Option<bool>]) -> bool {
        if let Some(v) = memo[n] {
            return v;
        }
        let v = match st.nodes[n].split {
            Some((a, b, _)) => all_excluded(st, ex, a, memo) & all_excluded(st, ex, b, memo),
            None => st.excluded_by(n, ex),
        };
        memo[n] = Some(v);
        v
    }
    let mut memo = vec![None; st.nodes.len()];
    let mut boxes = Vec::new();
    let mut stack: Vec<usize> = st.roots.iter().rev().copied().collect();
    while let Some(n) = stack.pop() {
        if all_excluded(st, ex, n, &mut memo) {
            boxes.push((st.nodes[n].lo.clone(), st.nodes[n].size.clone()));
        } else if let Some((a, b, _)) = st.nodes[n].split {
            stack.push(b);
            stack.push(a);
        }
    }
    // Merge boxes that share a whole face (same extent on every other axis, adjacent on
    // one): each merge keeps the union exact.
    let nx = st.nodes.first().map_or(0, |n| n.lo.len());
    loop {
        let mut merged = false;
        let mut i = 0;
        while i < boxes.len() {
            let mut j = i + 1;
            while j < boxes.len() {
                let (a, b) = (&boxes[i], &boxes[j]);
                let axis = (0..nx).find(|&k| {
                    (0..nx).all(|m| m == k || (a.0[m] == b.0[m] && a.1[m] == b.1[m]))
                        && (a.0[k] + a.1[k] == b.0[k] || b.0[k] + b.1[k] == a.0[k])
                });
                if let Some(k) = axis {
                    let lo = a.0[k].min(b.0[k]);
                    let size = a.1[k] + b.1[k];
                    boxes[i].0[k] = lo;
                    boxes[i].1[k] = size;
                    boxes.swap_remove(j);
                    merged = true;
                } else {
                    j += 1;
                }
            }
            i += 1;
        }
        if !merged {
            return boxes;
        }
    }
}

fn excluded_summary(
    cfg: &ProblemConfig,
    rs: &RefineSettings,
    st: &RefineState,
) -> Option<Excluded> {
    let nx = cfg.system.nx();
    let lat = Lattice::new(&cfg.domain.lo, &cfg.domain.hi, &rs.initial_counts(nx));
    let ex = Exclusion::new(rs, &lat.max);
    let leaves = st.excluded_leaves_by(&ex);
    if leaves.is_empty() {
        return None;
    }
    // The unlabelled states at the corners of excluded leaves, once each, in point order.
    let mut unlabelled: Vec<usize> = leaves
        .iter()
        .flat_map(|&n| st.nodes[n].corners.iter().copied())
        .filter(|&c| !st.points[c].labelled())
        .collect();
    unlabelled.sort_unstable();
    unlabelled.dedup();
    let unlabelled_states = unlabelled.iter().map(|&c| st.points[c].x.clone()).collect();
    let volume = |size: &[u64]| -> f64 {
        size.iter()
            .zip(&lat.max)
            .map(|(&s, &m)| s as f64 / m as f64)
            .product()
    };
    let volume_fraction = leaves.iter().map(|&n| volume(&st.nodes[n].size)).sum();
    let boxes = excluded_lattice_boxes(st, &ex)
        .into_iter()
        .map(|(lo, size)| {
            let hi: Vec<u64> = lo.iter().zip(&size).map(|(a, s)| a + s).collect();
            (lat.x(&lo), lat.x(&hi))
        })
        .collect();
    Some(Excluded {
        cells: leaves.len(),
        volume_fraction,
        boxes,
        unlabelled_states,
        note: format!(
            "A leaf cell is excluded when no corner has an MPC label (the solver found no \
             solution at any of them), or when a corner has none and the cell has been split \
             down to refine.min_cell = {} of X per axis{}: no bound can be finite there. Whether a cell is outside the MPC's \
             feasible set is an estimate from its corners, not a proof; the feasible set may \
             reach into an excluded cell between its corners (`refine --check` counts fresh \
             feasible states found there). ε holds on X minus these boxes; the exported \
             controller flags states inside them (EXCLUDED).",
            rs.min_cell,
            if rs.exclude_infeasible {
                ", or (refine.exclude_infeasible) when the hard OCP is infeasible at every \
                 corner (the soft fallback needed slack, or no label)"
            } else {
                ""
            }
        ),
    })
}

/// The certificate of a refinement run: the design's keys plus [`LocalSummary`]; written as
/// a [`CertificateFile`] (its only form on disk).
#[derive(Debug, Clone, PartialEq)]
pub struct LocalCertificate {
    /// The design's keys (`eps` is the local bound max_C ε_C).
    pub base: crate::certify::certificate::Certificate,
    /// The local figures.
    pub local: LocalSummary,
    /// The weakest tier ε rests on, per term its tier, and the assumptions.
    pub guarantee: crate::certify::tier::Guarantee,
    /// The statistical tier (`trainer refine --statistical N`), absent without it.
    pub statistical: Option<crate::certify::statistical::Statistical>,
    /// The check at fresh states (`refine --check`), when it ran.
    pub check: Option<CheckSummary>,
}

impl LocalCertificate {
    /// The certificate file of this local certificate.
    pub fn file(&self) -> CertificateFile {
        CertificateFile {
            base: self.base.clone(),
            guarantee: self.guarantee.clone(),
            local: Some(self.local.clone()),
            statistical: self.statistical.clone(),
            statistical_closed_loop: None,
            requirement: None,
            check: self.check.clone(),
        }
    }

    /// Records the check's result: a failed check leaves `local.met` false (the
    /// certificate no longer says the target is met) and the `check` block says so.
    pub fn with_check(mut self, c: &Check) -> Self {
        let s = check_summary(c);
        if !s.passed {
            self.local.met = false;
        }
        self.check = Some(s);
        self
    }
}

/// The summary of a check written into the certificate: exceedances are the states over ε
/// or over their cell's ε_C and the feasible states found in excluded cells; it passes when
/// there are none and the per-cell range check is within its tolerance (what `refine
/// --check` fails on).
pub fn check_summary(c: &Check) -> CheckSummary {
    let exceedances = c.over_eps + c.over_cell + c.feasible_in_excluded;
    CheckSummary {
        states: c.states,
        exceedances,
        passed: exceedances == 0 && c.per_cell.passed,
        report: RunDir::CHECK.into(),
    }
}

/// The largest half-diagonal of a bounded cell: every state is within it of a corner.
fn largest_half_diagonal(st: &RefineState, lat: &Lattice, x_scale: &[f64]) -> f64 {
    st.bounds
        .iter()
        .map(|(n, _)| {
            let node = &st.nodes[*n];
            (0..x_scale.len())
                .map(|k| (0.5 * node.size[k] as f64 * lat.step[k] / x_scale[k]).powi(2))
                .sum::<f64>()
                .sqrt()
        })
        .fold(0.0, f64::max)
}

/// The cell with the largest bound (ties: the lowest node) as (lower, upper corner), and
/// which term binds there: `corner`, `second_order` or `first_order`.
fn binding_cell(st: &RefineState, lat: &Lattice) -> (String, (Vec<f64>, Vec<f64>)) {
    let worst = st
        .bounds
        .iter()
        .max_by(|a, b| a.1.eps.total_cmp(&b.1.eps).then(b.0.cmp(&a.0)));
    match worst {
        Some((n, b)) => {
            let node = &st.nodes[*n];
            let what = if b.corner >= b.remainder {
                "corner"
            } else if b.form == Form::SecondOrder {
                "second_order"
            } else {
                "first_order"
            };
            (what.to_string(), lat.cell(node))
        }
        None => (String::new(), (vec![], vec![])),
    }
}

/// Builds the certificate of a finished refinement.
pub fn certificate(cfg: &ProblemConfig, rs: &RefineSettings, r: &Refined) -> LocalCertificate {
    use crate::certify::certificate::{requirement, Certificate, LnnMethod};
    use crate::certify::lipschitz;
    let st = &r.state;
    let (lo, hi) = (&cfg.domain.lo, &cfg.domain.hi);
    let nx = lo.len();
    // Every number in the certificate's norm (`[ocp] x_scale`, `u_scale`; borrowed
    // unchanged when all scales are 1): the cells' ε_C are in it already
    // (`certify::local`); the Theorem-1 figures beside them are those of the scaled net,
    // labels and box ([`crate::certify::norm`]).
    let norm = crate::certify::norm::Norm::of_problem(cfg);
    let scaled = norm.scale_mlp(&r.model.mlp);
    let mlp: &crate::learn::mlp::Mlp = &scaled;
    let (slo, shi) = norm.scale_box(lo, hi);
    let eps = super::rounds::max_eps(&st.bounds);
    let eps_d = st.bounds.iter().map(|(_, b)| b.corner).fold(0.0, f64::max);
    let naive = lipschitz::naive_bound(mlp);
    let (sdp, lower) = rayon::join(
        || lipschitz::lipsdp_bound(mlp),
        || lipschitz::sampled_lower_bound(mlp, &slo, &shi, 20_000, 7),
    );
    let (l_nn, method) = if sdp < naive {
        (sdp, LnnMethod::LipSdpNeuron)
    } else {
        (naive, LnnMethod::Naive)
    };
    let set = train_set(
        st,
        nx,
        cfg.system.nu(),
        &[],
        1,
        &Exclusion::new(rs, &Lattice::new(lo, hi, &rs.initial_counts(nx)).max),
    );
    let set = norm.scale_set(&set);
    let (sl, q) = lipschitz::mpc_estimates(&set.x, &set.u, &set.du, &set.use_jac, nx, set.nu);
    let l_mpc = sl.max(q);
    let lat = Lattice::new(lo, hi, &rs.initial_counts(nx));
    let radius = largest_half_diagonal(st, &lat, &norm.x_scale);
    let req = requirement(eps, eps_d, l_mpc, l_nn, &slo, &shi);
    let (binding, worst_cell) = binding_cell(st, &lat);
    let solves = st.points.len();
    let qp = crate::certify::critical::QpCertifier::detect(cfg).is_ok();
    let n_exact = st.bounds.iter().filter(|(_, b)| b.exact).count();
    let base = Certificate {
        eps,
        eps_d,
        l_nn,
        l_nn_method: method,
        l_nn_naive: naive,
        l_nn_lipsdp: sdp,
        l_nn_vertex: None,
        l_nn_lower: lower,
        l_mpc,
        l_mpc_is_estimate: true,
        l_mpc_method: format!(
            "estimate: max ‖∂κ/∂x‖₂ over the data ({sl:.4}) and neighbour difference \
             quotients ({q:.4}); the local bound uses per-cell estimates instead (see local.note)"
        ),
        covering_radius: radius,
        covering_method: "upper bound: the largest cell half-diagonal (every state is within \
                          it of a corner of its cell)"
            .into(),
        f32_allowance: 0.0,
        domain_lo: lo.clone(),
        domain_hi: hi.clone(),
        u_lo: cfg.ocp.u_bounds(0).0.to_vec(),
        u_hi: cfg.ocp.u_bounds(0).1.to_vec(),
        // The certificate is about sat(κ_NN), the output clamped to U_d (the data's stage-0
        // input bounds): κ ∈ U_d, so the clamp never increases the error, and U_d lies
        // inside the design's band U_d ⊕ [−ε, ε] ∩ U.
        clamp_lo: cfg.ocp.u_bounds(0).0.to_vec(),
        clamp_hi: cfg.ocp.u_bounds(0).1.to_vec(),
        n_points: set.len(),
        hash: r.model.content_hash(),
        problem_hash: cfg.problem_hash(),
        dataset_hash: crate::io::sha256_hex(&dataset(cfg, st).to_bytes()),
        labels: None,
        // The cells' bounds are in the norm of `[ocp] x_scale`, `u_scale`; per input in
        // physical units s_u,j·ε (rounded up).
        epsilon_per_input: norm.per_input(eps),
        scales: Some(norm),
    };
    let local = LocalSummary {
        method: "local".into(),
        target_eps: rs.target_eps,
        met: r.met,
        cells: st.bounds.len(),
        cells_second_order: st
            .bounds
            .iter()
            .filter(|(_, b)| b.form == Form::SecondOrder)
            .count(),
        cells_fit_bound: st
            .bounds
            .iter()
            .filter(|(_, b)| b.corner >= b.remainder)
            .count(),
        solves,
        rounds: st.log.len(),
        safety: rs.safety,
        floor: rs.floor,
        jumps: st.jumps.len(),
        max_remainder: st
            .bounds
            .iter()
            .map(|(_, b)| b.remainder)
            .fold(0.0, f64::max),
        binding,
        worst_cell,
        global_grid_solves: req.solves,
        sparsification: req.solves.map(|g| g / solves.max(1) as f64),
        note: format!(
            "ε = max over cells of max_corners |κ − sat(κ_NN)| + interpolation remainder. \
             Sound: the corner errors (solved points), the network's value/Jacobian/curvature \
             enclosures (interval bound propagation), the interpolation inequalities. \
             Estimated: the range of ∂κ/∂x on each cell (hull of corner sensitivities, edge \
             secants and the solved centre's sensitivity, widened ×{s}, half-width at least \
             {c} × the spread of ∂κ/∂x over the corners and their outward neighbours) and \
             |∂²κ/∂x²| where all corners (and the solved centre{centre}) share one active set \
             (×{s} the edge difference quotients, at least {c} × those towards the \
             neighbours); κ continuous on each cell (a cell where `refine --check` found a \
             jump of κ is never certified). Not sound for a nonlinear MPC: the tier is \
             estimated.",
            s = rs.safety,
            c = rs.floor,
            centre = if rs.centre_check { "" } else { ": off" }
        ) + if qp {
            " The MPC is a convex QP: on a cell whose critical-region proof succeeds (the \
             active sets of its corners, checked for primal and dual feasibility at every \
             vertex with rounding bounds), κ is affine piecewise and the MPC part is exact \
             (cells_exact); the estimate applies to the other cells only."
        } else {
            ""
        },
        cells_exact: qp.then_some(n_exact),
        excluded: excluded_summary(cfg, rs, st),
    };
    LocalCertificate {
        base,
        local,
        guarantee: crate::certify::tier::local_exact(n_exact, st.bounds.len()),
        statistical: None,
        check: None,
    }
}

/// Writes the outputs of a refinement into `dir`: `model.bin`, `dataset.bin` (+ `.csv`),
/// `certificate.json`, `cells.csv` (every leaf: box, ε_C, corner term, remainder, form),
/// `refine_log.json`. With `check` (`refine --check`, run before) its result is written into
/// the certificate ([`LocalCertificate::with_check`]). `allowance` gives the deployed
/// controller's f32 allowance for the certificate (`deploy` computes it; `certify` may not
/// import `deploy`): it is stored as `f32_allowance`, so the file, the model's stored
/// certificate and `export` agree; `None` (a net the device cannot run, which `export`
/// refuses) stores 0. Returns the certificate. A net imported from another format (ONNX,
/// `source_hash` set) is not written as `model.bin`: the certificate binds the source file,
/// which stays the model to export.
pub fn write_outputs(
    cfg: &ProblemConfig,
    rs: &RefineSettings,
    r: &Refined,
    dir: &Path,
    check: Option<&Check>,
    allowance: &dyn Fn(&Certificate) -> Option<f64>,
) -> Result<LocalCertificate, DatasetError> {
    let mut cert = certificate(cfg, rs, r);
    if let Some(c) = check {
        cert = cert.with_check(c);
    }
    cert.base.f32_allowance = allowance(&cert.base).unwrap_or(0.0);
    if r.model.source_hash.is_none() {
        let mut model = r.model.clone();
        // The model file's certificate has no room for excluded boxes: with them, the
        // model stores none, and exporting needs `--certificate certificate.json` (which
        // carries them) — the stored one would claim ε on all of X.
        model.certificate = cert.local.excluded.is_none().then(|| cert.base.clone());
        model.problem_toml = cfg.to_toml_string().ok();
        model.save(&dir.join("model.bin"))?;
    }
    let ds = dataset(cfg, &r.state);
    ds.save(&dir.join(RunDir::DATASET))?;
    write_atomic(&dir.join(RunDir::DATASET_CSV), ds.to_csv().as_bytes())?;
    let path = dir.join(crate::certify::file::FILE_NAME);
    write_certificate(&path, &cert.file()).map_err(|e| DatasetError::Format {
        path: path.display().to_string(),
        reason: e.to_string(),
    })?;
    write_atomic(
        &dir.join("refine_log.json"),
        pretty(&r.state.log).as_bytes(),
    )?;
    let nx = cfg.system.nx();
    let lat = Lattice::new(&cfg.domain.lo, &cfg.domain.hi, &rs.initial_counts(nx));
    let mut csv = String::new();
    for k in 0..nx {
        csv.push_str(&format!("lo{},", k + 1));
    }
    for k in 0..nx {
        csv.push_str(&format!("hi{},", k + 1));
    }
    csv.push_str("eps_c,corner,remainder,form\n");
    for (n, b) in &r.state.bounds {
        let node = &r.state.nodes[*n];
        let hi: Vec<u64> = node.lo.iter().zip(&node.size).map(|(a, s)| a + s).collect();
        for v in lat.x(&node.lo).iter().chain(&lat.x(&hi)) {
            csv.push_str(&format!("{v},"));
        }
        csv.push_str(&format!(
            "{},{},{},{}\n",
            b.eps,
            b.corner,
            b.remainder,
            match b.form {
                Form::FirstOrder => "first_order",
                Form::SecondOrder => "second_order",
            }
        ));
    }
    write_atomic(&dir.join(RunDir::CELLS), csv.as_bytes())?;
    Ok(cert)
}

/// One cell of a local certificate in physical coordinates (what `study::plots::eps_map`
/// draws).
#[derive(Debug, Clone, PartialEq)]
pub struct CellView {
    /// Lower corner (first two state axes are drawn).
    pub lo: Vec<f64>,
    /// Upper corner.
    pub hi: Vec<f64>,
    /// ε_C.
    pub eps: f64,
    /// 0: the corner (fit) term binds; 1: first-order remainder; 2: second-order remainder.
    pub binding: u8,
}

/// The leaf cells with their bounds, for the ε_C map.
pub fn cell_views(cfg: &ProblemConfig, rs: &RefineSettings, st: &RefineState) -> Vec<CellView> {
    let lat = Lattice::new(
        &cfg.domain.lo,
        &cfg.domain.hi,
        &rs.initial_counts(cfg.system.nx()),
    );
    st.bounds
        .iter()
        .map(|(n, b)| {
            let node = &st.nodes[*n];
            let hi: Vec<u64> = node.lo.iter().zip(&node.size).map(|(a, s)| a + s).collect();
            CellView {
                lo: lat.x(&node.lo),
                hi: lat.x(&hi),
                eps: b.eps,
                binding: if b.corner >= b.remainder {
                    0
                } else if b.form == Form::SecondOrder {
                    2
                } else {
                    1
                },
            }
        })
        .collect()
}

/// Per state axis i, `s_i = mean ‖∂κ/∂x_i‖₂ · (hi_i − lo_i)` over the labelled points of
/// the refinement (the change of κ across X along axis i; NaN without a labelled point): the
/// ε_C map of nx > 2 slices along the two largest, as the run's error map does.
pub fn sensitivity_spread(cfg: &ProblemConfig, st: &RefineState) -> Vec<f64> {
    let (nx, nu) = (cfg.system.nx(), cfg.system.nu());
    let mut sum = vec![0.0; nx];
    let mut n = 0usize;
    for p in st
        .points
        .iter()
        .filter(|p| p.labelled() && p.du.len() == nu * nx)
    {
        for (i, s) in sum.iter_mut().enumerate() {
            *s += (0..nu)
                .map(|j| p.du[j * nx + i].powi(2))
                .sum::<f64>()
                .sqrt();
        }
        n += 1;
    }
    sum.iter()
        .enumerate()
        .map(|(i, s)| s / n as f64 * (cfg.domain.hi[i] - cfg.domain.lo[i]))
        .collect()
}

/// Pretty JSON of a serialisable value.
pub fn pretty<T: Serialize>(v: &T) -> String {
    serde_json::to_string_pretty(v).unwrap_or_default()
}
