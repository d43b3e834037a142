//! The certified error bound of Theorem 1 and the covering radius of the data.
//!
//! ```text
//! ε = ε_D + (L_MPC + L_NN)·r,    r = sup_{x∈X} min_i ‖x − x_i‖   (covering radius)
//! ```
//! - Grid data: r is exactly half the cell diagonal, `½·√Σ_j Δ_j²`.
//! - Scattered data: a sound upper bound by branch and bound over boxes of X. The distance
//!   to the data d(x) = min_i ‖x − x_i‖ is 1-Lipschitz, so on a box with centre c and
//!   half-diagonal ρ, `sup d ≤ d(c) + ρ`; boxes whose bound cannot beat the best lower
//!   bound (the largest d(c) seen) are dropped, the others are split along their longest
//!   side until upper − lower ≤ tolerance.
//! - The inverse: for a target ε > ε_D the required radius is
//!   `δ = (ε − ε_D)/(L_MPC + L_NN)`; a grid with equal spacing h = 2δ/√n_x per axis
//!   achieves it, with Π_j (⌈(hi_j − lo_j)/h⌉ + 1) OCP solves.

use serde::{Deserialize, Serialize};

/// Exact covering radius of a full grid with per-axis counts over [lo, hi].
pub fn grid_covering_radius(lo: &[f64], hi: &[f64], counts: &[usize]) -> f64 {
    let s: f64 = lo
        .iter()
        .zip(hi)
        .zip(counts)
        .map(|((l, h), &c)| {
            // A single point sits at the midpoint: the farthest point is a full half-width away.
            let d = if c <= 1 {
                h - l
            } else {
                (h - l) / (c - 1) as f64
            };
            d * d
        })
        .sum();
    0.5 * s.sqrt()
}

/// Sound upper bound on the covering radius of scattered `points` (row-major, dimension
/// `lo.len()`) over the box [lo, hi], within `tol` of the lower bound it also finds.
/// Returns (upper, lower).
pub fn scattered_covering_radius(points: &[f64], lo: &[f64], hi: &[f64], tol: f64) -> (f64, f64) {
    let d = lo.len();
    let n = points.len() / d.max(1);
    if n == 0 {
        let diag: f64 = lo
            .iter()
            .zip(hi)
            .map(|(l, h)| (h - l).powi(2))
            .sum::<f64>()
            .sqrt();
        return (diag, diag);
    }
    // The exact nearest-point distance (a k-d tree: the same bits as the brute minimum).
    let tree = super::nearest::KdTree::new(points, d);
    let dist = |c: &[f64]| -> f64 { tree.nearest_sq(c).sqrt() };
    struct Cell {
        lo: Vec<f64>,
        hi: Vec<f64>,
        ub: f64,
    }
    let make = |lo: Vec<f64>, hi: Vec<f64>| -> (Cell, f64) {
        let c: Vec<f64> = lo.iter().zip(&hi).map(|(a, b)| 0.5 * (a + b)).collect();
        let rho = 0.5
            * lo.iter()
                .zip(&hi)
                .map(|(a, b)| (b - a).powi(2))
                .sum::<f64>()
                .sqrt();
        let dc = dist(&c);
        (
            Cell {
                lo,
                hi,
                ub: dc + rho,
            },
            dc,
        )
    };
    let (root, mut lower) = make(lo.to_vec(), hi.to_vec());
    // Corners are candidates for the farthest point too.
    for m in 0..(1usize << d.min(16)) {
        let c: Vec<f64> = (0..d)
            .map(|k| if m >> k & 1 == 1 { hi[k] } else { lo[k] })
            .collect();
        lower = lower.max(dist(&c));
    }
    let mut stack = vec![root];
    let mut upper = lower;
    let mut evals = 0usize;
    while let Some(cell) = stack.pop() {
        if cell.ub <= lower + tol {
            upper = upper.max(cell.ub.min(lower + tol));
            continue;
        }
        evals += 1;
        if evals > 5_000_000 {
            // Budget exhausted: everything left is bounded by its own ub (still sound).
            upper = upper.max(cell.ub);
            for c in stack.drain(..) {
                upper = upper.max(c.ub);
            }
            break;
        }
        let k = (0..d)
            .max_by(|&a, &b| (cell.hi[a] - cell.lo[a]).total_cmp(&(cell.hi[b] - cell.lo[b])))
            .unwrap_or(0);
        let mid = 0.5 * (cell.lo[k] + cell.hi[k]);
        let (mut h1, mut l2) = (cell.hi.clone(), cell.lo.clone());
        h1[k] = mid;
        l2[k] = mid;
        for (l, h) in [(cell.lo.clone(), h1), (l2, cell.hi.clone())] {
            let (c, dc) = make(l, h);
            lower = lower.max(dc);
            stack.push(c);
        }
    }
    (upper.max(lower), lower)
}

/// How L_NN was bounded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LnnMethod {
    /// Product of spectral norms.
    Naive,
    /// LipSDP-Neuron.
    LipSdpNeuron,
    /// Exact maximum over slope vertices.
    SlopeVertices,
}

/// The certificate record (keys as in the design's "Contracts").
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Certificate {
    /// Certified bound ε on ‖κ − κ_NN‖ over X.
    pub eps: f64,
    /// max error over the data.
    pub eps_d: f64,
    /// Tightest sound upper bound on L_NN used.
    pub l_nn: f64,
    /// Its method.
    pub l_nn_method: LnnMethod,
    /// Product-of-norms bound.
    pub l_nn_naive: f64,
    /// LipSDP-Neuron bound.
    pub l_nn_lipsdp: f64,
    /// Slope-vertex bound, if computed.
    pub l_nn_vertex: Option<f64>,
    /// Sampled lower bound.
    pub l_nn_lower: f64,
    /// L_MPC used.
    pub l_mpc: f64,
    /// Whether L_MPC is an estimate (true unless the user supplied a proven value).
    pub l_mpc_is_estimate: bool,
    /// How L_MPC was obtained.
    pub l_mpc_method: String,
    /// Covering radius r of the data.
    pub covering_radius: f64,
    /// How r was computed.
    pub covering_method: String,
    /// |κ_NN,f32 − κ_NN,f64| allowance (0 until an export adds it).
    pub f32_allowance: f64,
    /// Domain X, lower corner.
    pub domain_lo: Vec<f64>,
    /// Domain X, upper corner.
    pub domain_hi: Vec<f64>,
    /// Input bounds U_d used for the data.
    pub u_lo: Vec<f64>,
    /// Input bounds U_d used for the data.
    pub u_hi: Vec<f64>,
    /// Output clamp band U_d ⊕ [−ε, ε].
    pub clamp_lo: Vec<f64>,
    /// Output clamp band U_d ⊕ [−ε, ε].
    pub clamp_hi: Vec<f64>,
    /// Number of labelled points used.
    pub n_points: usize,
    /// Content hash (SHA-256 of the model file the certificate is about).
    pub hash: String,
    /// [`ProblemConfig::problem_hash`](crate::problem::ProblemConfig::problem_hash) of the
    /// problem whose MPC the bound is about (empty in certificates of older versions).
    #[serde(default)]
    pub problem_hash: String,
    /// SHA-256 of the dataset (its file bytes) the bound was computed on (empty in
    /// certificates of older versions).
    #[serde(default)]
    pub dataset_hash: String,
    /// `"labels"`: where the data's labels come from when they were imported from another
    /// solver (file, SHA-256, the re-solve check); absent for ampc's own labels. Kept in the
    /// JSON certificate only: the postcard model file does not store it (its format, and
    /// every existing model, stay as they were).
    #[serde(default, skip_serializing_if = "Option::is_none", with = "json_only")]
    pub labels: Option<crate::data::dataset::ImportedLabels>,
    /// `"norm"`: the scales S_x, S_u of the norm ε, ε_D, L_MPC, L_NN and the covering radius
    /// are stated in ([`Norm`](crate::certify::norm::Norm): ε bounds ‖S_u⁻¹(κ − κ_NN)‖₂,
    /// states measured as ‖S_x⁻¹Δx‖₂). Absent in certificates of older versions, which
    /// were computed unscaled (S = I): [`Certificate::norm`] reads them so. JSON only
    /// (the postcard model file does not store it: its format stays as it was).
    #[serde(
        default,
        rename = "norm",
        skip_serializing_if = "Option::is_none",
        with = "json_only"
    )]
    pub scales: Option<crate::certify::norm::Norm>,
    /// `"epsilon_per_input"`: ε per input in physical units, |κ_j − κ_NN,j| ≤ entry j
    /// (s_u,j·ε rounded up). Absent in older certificates (then ε itself, unscaled). JSON
    /// only.
    #[serde(default, skip_serializing_if = "Vec::is_empty", with = "json_only")]
    pub epsilon_per_input: Vec<f64>,
}

impl Certificate {
    /// The norm the certificate is stated in: its `"norm"`, else (an older certificate)
    /// the unscaled one it was computed in.
    pub fn norm(&self) -> crate::certify::norm::Norm {
        self.scales.clone().unwrap_or_else(|| {
            crate::certify::norm::Norm::unscaled(self.domain_lo.len(), self.u_lo.len())
        })
    }

    /// A bound on ‖κ − κ_NN‖₂ in physical units: min(‖(ε_j)_j‖₂, max_j s_u,j·ε) (ε
    /// itself for the unscaled norm), from |κ_j − κ_NN,j| ≤ ε_j and ‖S_u v‖₂ ≤ max s·‖v‖₂.
    pub fn eps_physical(&self) -> f64 {
        let norm = self.norm();
        let smax = norm.u_scale.iter().copied().fold(0.0, f64::max);
        let by_max = crate::certify::norm::mul_up(smax, self.eps);
        let per = self.eps_per_input();
        let s: f64 = per.iter().map(|e| e * e).sum();
        let by_inputs = if per.len() == 1 {
            per[0]
        } else {
            s.sqrt() * (1.0 + 4.0 * f64::EPSILON)
        };
        by_max.min(by_inputs)
    }

    /// ε per input in physical units: `epsilon_per_input`, else s_u,j·ε.
    pub fn eps_per_input(&self) -> Vec<f64> {
        if self.epsilon_per_input.len() == self.u_lo.len() {
            self.epsilon_per_input.clone()
        } else {
            self.norm().per_input(self.eps)
        }
    }
}

/// Serde adapter of the JSON-only fields ([`Certificate::labels`], `norm`,
/// `epsilon_per_input`): the value in human-readable formats (JSON), nothing at all in binary
/// ones (postcard writes and reads zero bytes for a unit; the default is read back).
mod json_only {
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    pub fn serialize<T: Serialize, S: Serializer>(v: &T, s: S) -> Result<S::Ok, S::Error> {
        if s.is_human_readable() {
            v.serialize(s)
        } else {
            s.serialize_unit()
        }
    }

    pub fn deserialize<'de, T: Deserialize<'de> + Default, D: Deserializer<'de>>(
        d: D,
    ) -> Result<T, D::Error> {
        if d.is_human_readable() {
            T::deserialize(d)
        } else {
            <()>::deserialize(d).map(|_| T::default())
        }
    }
}

/// Inputs that do not belong together: certifying them would bound the wrong thing.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MismatchError {
    /// The dataset's labels cannot carry a certificate (none, numerical failures, or a
    /// non-finite label).
    #[error(transparent)]
    Labels(#[from] crate::data::dataset::LabelsError),
    /// The network is beyond the documented size limits for certification.
    #[error(transparent)]
    NetTooLarge(#[from] crate::problem::limits::NetTooLarge),
    /// The model and the data have different state or input dimensions.
    #[error("the model maps {model_nx} states to {model_nu} inputs but the dataset has {data_nx} states and {data_nu} inputs")]
    Dimensions {
        /// The model's n_x.
        model_nx: usize,
        /// The model's n_u.
        model_nu: usize,
        /// The dataset's n_x.
        data_nx: usize,
        /// The dataset's n_u.
        data_nu: usize,
    },
    /// The model was trained on labels of another problem.
    #[error("the model was trained on labels of problem hash {model}, the dataset holds labels of problem hash {data}")]
    ModelProblem {
        /// The model's problem hash.
        model: String,
        /// The dataset's.
        data: String,
    },
    /// The dataset was labelled for another problem than the one certified for.
    #[error("the dataset was labelled for problem `{data_name}` (hash {data}), not for `{cfg_name}` (hash {cfg}): certify it with its own problem (omit --config) or relabel")]
    DataProblem {
        /// The dataset's problem name.
        data_name: String,
        /// Its problem hash.
        data: String,
        /// The problem certified for.
        cfg_name: String,
        /// Its hash.
        cfg: String,
    },
    /// The dataset covers another domain X or sampling plan than the problem certified for.
    #[error("the dataset's {what} differs from the problem's ({data} vs {cfg}): the covering radius would be computed for the wrong points")]
    Coverage {
        /// `domain X` or `sampling plan`.
        what: String,
        /// The dataset's value.
        data: String,
        /// The problem's value.
        cfg: String,
    },
}

/// Checks that a model, a dataset and a problem belong together before they are certified:
/// equal dimensions, the model trained on labels of the dataset's problem, the dataset
/// labelled for this problem (same problem hash) over this domain X with this sampling plan.
pub fn check_inputs(
    model: &crate::certify::Model,
    data: &crate::data::dataset::Dataset,
    cfg: &crate::problem::ProblemConfig,
) -> Result<(), MismatchError> {
    // No certificate from labels that do not exist or are not finite (data::dataset::gate;
    // a solver breakdown where the plant itself is finite counts as unlabelled), nor for a
    // net beyond the documented size limits (problem::limits).
    data.check_labels_for(cfg)?;
    crate::problem::limits::check_net(&model.mlp.widths())?;
    let (mx, mu) = (model.mlp.widths()[0], model.mlp.nu());
    let (dx, du) = (data.header.nx as usize, data.header.nu as usize);
    if (mx, mu) != (dx, du) || (dx, du) != (cfg.system.nx(), cfg.system.nu()) {
        return Err(MismatchError::Dimensions {
            model_nx: mx,
            model_nu: mu,
            data_nx: dx,
            data_nu: du,
        });
    }
    if !model.problem_hash.is_empty() && model.problem_hash != data.header.problem_hash {
        return Err(MismatchError::ModelProblem {
            model: model.problem_hash.clone(),
            data: data.header.problem_hash.clone(),
        });
    }
    if data.header.problem_hash != cfg.problem_hash() {
        return Err(MismatchError::DataProblem {
            data_name: data.header.problem.clone(),
            data: data.header.problem_hash.clone(),
            cfg_name: cfg.name.clone(),
            cfg: cfg.problem_hash(),
        });
    }
    if let Ok(own) = crate::problem::ProblemConfig::from_toml_str_with(
        &data.header.config_toml,
        "dataset header",
        cfg.system.custom_plants(),
    ) {
        if own.domain != cfg.domain {
            return Err(MismatchError::Coverage {
                what: "domain X".into(),
                data: format!("{:?} … {:?}", own.domain.lo, own.domain.hi),
                cfg: format!("{:?} … {:?}", cfg.domain.lo, cfg.domain.hi),
            });
        }
    }
    Ok(())
}

/// What a target ε requires.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Requirement {
    /// Target ε.
    pub target_eps: f64,
    /// Required covering radius δ (None if ε ≤ ε_D: no data density suffices).
    pub delta: Option<f64>,
    /// Grid spacing per axis achieving δ.
    pub spacing: Option<f64>,
    /// Number of OCP solves of that grid.
    pub solves: Option<f64>,
}

/// The inverse of Theorem 1 for a target ε (see the module doc).
pub fn requirement(
    target: f64,
    eps_d: f64,
    l_mpc: f64,
    l_nn: f64,
    lo: &[f64],
    hi: &[f64],
) -> Requirement {
    if target <= eps_d || l_mpc + l_nn <= 0.0 {
        return Requirement {
            target_eps: target,
            delta: None,
            spacing: None,
            solves: None,
        };
    }
    let delta = (target - eps_d) / (l_mpc + l_nn);
    let h = 2.0 * delta / (lo.len() as f64).sqrt();
    let solves = lo
        .iter()
        .zip(hi)
        .map(|(l, u)| ((u - l) / h).ceil() + 1.0)
        .product();
    Requirement {
        target_eps: target,
        delta: Some(delta),
        spacing: Some(h),
        solves: Some(solves),
    }
}

/// Inputs of a certificate beyond the model and the data.
#[derive(Debug, Clone, Default)]
pub struct CertifyOptions {
    /// A proven L_MPC supplied by the user (replaces the estimate).
    pub l_mpc: Option<f64>,
    /// Largest number of hidden units for the exact slope-vertex bound (default 22).
    pub vertex_max_hidden: Option<usize>,
    /// Extra states labelled by the MPC (e.g. the validation set) for the L_MPC estimate.
    pub extra: Option<crate::learn::train::TrainSet>,
}

/// Computes the certificate of `model` on `data` (Theorem 1) with every term.
pub fn certify(
    model: &crate::certify::Model,
    data: &crate::data::dataset::Dataset,
    cfg: &crate::problem::ProblemConfig,
    opts: &CertifyOptions,
) -> Result<Certificate, MismatchError> {
    use crate::certify::lipschitz;
    check_inputs(model, data, cfg)?;
    // Every term in the problem's norm (crate::certify::norm): the scaled net on the scaled
    // points over the scaled box; the unit norm borrows the originals unchanged.
    let norm = crate::certify::norm::Norm::of_problem(cfg);
    let phys = crate::learn::train::TrainSet::from_dataset(data);
    let set = norm.scale_set(&phys);
    let mlp = norm.scale_mlp(&model.mlp);
    let (_, stats) = crate::learn::train::errors(&mlp, &set);
    let (lo, hi) = norm.scale_box(&cfg.domain.lo, &cfg.domain.hi);
    let (lo, hi) = (&lo, &hi);
    let naive = lipschitz::naive_bound(&mlp);
    let (nx, nu) = (set.nx, set.nu);
    // L_MPC: the proven value given, or the estimates from the data and the extra states.
    let l_mpc_term = || match opts.l_mpc {
        Some(v) => (v, false, "user-supplied proven value".to_string()),
        None => {
            let (s, q) = lipschitz::mpc_estimates(&set.x, &set.u, &set.du, &set.use_jac, nx, nu);
            let (s2, q2) = opts.extra.as_ref().map_or((0.0f64, 0.0f64), |e| {
                let e = norm.scale_set(e);
                lipschitz::mpc_estimates(&e.x, &e.u, &e.du, &e.use_jac, nx, nu)
            });
            let method = if opts.extra.is_some() {
                format!(
                    "estimate: max of max‖∂κ/∂x‖₂ over the data ({s:.4}) and the extra states ({s2:.4}), \
                     max neighbour difference quotient ({q:.4}, {q2:.4})"
                )
            } else {
                format!(
                    "estimate: max of max‖∂κ/∂x‖₂ over the data ({s:.4}) and the largest \
                     neighbour difference quotient ({q:.4})"
                )
            };
            (s.max(q).max(s2).max(q2), true, method)
        }
    };
    // The four are independent and deterministic: LipSDP (the longest) beside the other
    // three.
    let (sdp, ((vertex, lower), (l_mpc, l_mpc_is_estimate, l_mpc_method))) = rayon::join(
        || lipschitz::lipsdp_bound(&mlp),
        || {
            rayon::join(
                || {
                    (
                        lipschitz::vertex_bound(&mlp, opts.vertex_max_hidden.unwrap_or(22)),
                        lipschitz::sampled_lower_bound(&mlp, lo, hi, 20_000, 7),
                    )
                },
                l_mpc_term,
            )
        },
    );
    let (mut l_nn, mut method) = (naive, LnnMethod::Naive);
    if sdp < l_nn {
        (l_nn, method) = (sdp, LnnMethod::LipSdpNeuron);
    }
    if let Some(v) = vertex.filter(|v| *v < l_nn) {
        (l_nn, method) = (v, LnnMethod::SlopeVertices);
    }
    let all_labelled = set.len() == data.records.len();
    let (covering_radius, covering_method) = if data.header.sampling.sampler
        == crate::problem::SamplerKind::Grid
        && all_labelled
        && data.header.shard.is_none()
    {
        (
            grid_covering_radius(lo, hi, &data.header.sampling.counts),
            "exact: half the grid cell diagonal".to_string(),
        )
    } else {
        let (ub, lb) = scattered_covering_radius(
            &set.x,
            lo,
            hi,
            1e-4 * lo.iter().zip(hi).map(|(a, b)| b - a).fold(0.0, f64::max),
        );
        (ub, format!("sound upper bound by branch and bound over X (lower {lb:.6}); labelled points only"))
    };
    let eps = stats.max + (l_mpc + l_nn) * covering_radius;
    // Per input in physical units: the clamp band U_d ⊕ [−ε_j, ε_j].
    let per_input = norm.per_input(eps);
    let (u_lo, u_hi) = cfg.ocp.u_bounds(0);
    Ok(Certificate {
        eps,
        eps_d: stats.max,
        l_nn,
        l_nn_method: method,
        l_nn_naive: naive,
        l_nn_lipsdp: sdp,
        l_nn_vertex: vertex,
        l_nn_lower: lower,
        l_mpc,
        l_mpc_is_estimate,
        l_mpc_method,
        covering_radius,
        covering_method,
        f32_allowance: 0.0,
        domain_lo: cfg.domain.lo.clone(),
        domain_hi: cfg.domain.hi.clone(),
        // U_d, the input bounds of the data: the stage-0 bounds (tightened by the design ε
        // in a robust design; the problem's U otherwise).
        u_lo: u_lo.to_vec(),
        u_hi: u_hi.to_vec(),
        clamp_lo: u_lo.iter().zip(&per_input).map(|(u, e)| u - e).collect(),
        clamp_hi: u_hi.iter().zip(&per_input).map(|(u, e)| u + e).collect(),
        n_points: set.len(),
        hash: model.content_hash(),
        problem_hash: cfg.problem_hash(),
        dataset_hash: crate::io::sha256_hex(&data.to_bytes()),
        labels: data.labels.clone(),
        scales: Some(norm),
        epsilon_per_input: per_input,
    })
}

#[cfg(test)]
pub(crate) mod tests;
