//! Lipschitz constants (2-norm, over X) of the network κ_NN and estimates for the MPC law κ.
//!
//! Upper bounds on `L_NN = sup_x ‖∂κ_NN/∂x‖₂` for hidden activations slope-restricted in
//! [0, 1] (tanh, softplus, ReLU), all on the physical-unit weights W̃_j:
//! 1. **naive**: `Π_j ‖W̃_j‖₂`.
//! 2. **LipSDP-Neuron** (Fazlyab et al. 2019): the least ρ such that, for some diagonal
//!    T_j ⪰ 0, the block-tridiagonal matrix M(ρ, T) ⪯ 0, with diagonal blocks
//!    (−ρI, −2T_1, …, −2T_{m−1} + W̃_mᵀW̃_m) and off-diagonal blocks W̃_jᵀT_j; then
//!    L_NN ≤ √ρ. For fixed T the least ρ is the largest eigenvalue of
//!    `N₁ K(T)⁻¹ N₁ᵀ` (Schur complement; K = −(lower-right part of M), which must be ≻ 0,
//!    N₁ = [W̃_1ᵀT_1, 0, …]); this function of T is convex (a partial minimisation of a
//!    convex feasibility problem), so we minimise it over diag T > 0 by gradient steps
//!    (Barzilai–Borwein, backtracking) in log T on the smoothing `μ ln tr exp(A/μ)` of
//!    `λ_max(A)`, A = N₁K⁻¹N₁ᵀ, for decreasing μ (λ_max is not differentiable where
//!    eigenvalues coalesce, typically at the optimum), with the exact eigenvector gradient
//!    `∂ρ/∂t_{j,k} = 2 w_{j,k} ((W̃_j w_{j−1})_k − w_{j,k})`, `w = K⁻¹N₁ᵀv`, `w_0 = v`,
//!    v the top eigenvector — started from the closed-form ECLipsE-Fast-style choice
//!    `T_j = I/‖W̃_j S_{j−1}⁻¹W̃_jᵀ‖`. Whatever T the search ends at, the reported bound is
//!    certified: M(ρ′, T) ⪯ 0 is verified by a Cholesky factorisation of −M at a slightly
//!    inflated ρ′, so the bound is sound regardless of the optimiser's accuracy.
//! 3. **vertex** (small nets): `max ‖W̃_m D_{m−1} ⋯ D_1 W̃_1‖₂` over diagonal D_j with
//!    entries in {0, 1}. The Jacobian is W̃_m D_{m−1}(x)⋯D_1(x)W̃_1 with D_j(x) ∈ [0, 1]ⁿ,
//!    and the norm is convex in each D_j separately, so the maximum over the box is at a
//!    vertex: a sound bound, the tightest of the three, exact over all slope patterns.
//!
//! Sampled estimates (module `sampled`): a lower bound `max ‖∂κ_NN/∂x‖₂` over dense samples
//! of X refined by local ascent; for κ itself only estimates exist (`L_MPC`): the largest
//! ‖∂κ/∂x‖₂ over labelled points and the largest difference quotient between neighbouring
//! points.

use crate::learn::mlp::{Layer, Mlp};
use dense::DenseWork;
use nalgebra::{DMatrix, DVector};

mod dense;
mod norm;
mod sampled;

pub use norm::spectral_norm;
use norm::{max_sq_sum, squared_spectral_norm};
pub use sampled::{mpc_estimates, sampled_lower_bound};

fn mat(l: &Layer) -> DMatrix<f64> {
    DMatrix::from_row_slice(l.out, l.inp, &l.w)
}

/// Product of the layers' spectral norms (physical units).
pub fn naive_bound(mlp: &Mlp) -> f64 {
    mlp.physical_layers()
        .iter()
        .map(|l| spectral_norm(&mat(l)))
        .product()
}

/// λ_max of the eigenvalues `l`, its smoothing `f_μ = λ_max + μ ln Σ exp((λᵢ − λ_max)/μ)`,
/// the weights exp((λᵢ − λ_max)/μ) and their sum.
fn smoothed_max(l: &[f64], mu: f64) -> (f64, f64, Vec<f64>, f64) {
    let lmax = l.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let wts: Vec<f64> = l.iter().map(|&v| ((v - lmax) / mu).exp()).collect();
    let z: f64 = wts.iter().sum();
    (lmax, lmax + mu * z.ln(), wts, z)
}

/// The LipSDP-Neuron problem data for fixed weights.
struct LipSdp {
    w: Vec<DMatrix<f64>>,
    sizes: Vec<usize>,
    offs: Vec<usize>,
    nh: usize,
    /// W̃_mᵀW̃_m (the last hidden layer's block of K does not depend on T).
    wtw: DMatrix<f64>,
}

impl LipSdp {
    fn new(mlp: &Mlp) -> Self {
        let w: Vec<DMatrix<f64>> = mlp.physical_layers().iter().map(mat).collect();
        let sizes: Vec<usize> = w[..w.len() - 1].iter().map(|m| m.nrows()).collect();
        let mut offs = vec![0];
        for s in &sizes {
            offs.push(offs.last().copied().unwrap_or(0) + s);
        }
        let nh = offs.last().copied().unwrap_or(0);
        let last = &w[w.len() - 1];
        let wtw = last.transpose() * last;
        LipSdp {
            w,
            sizes,
            offs,
            nh,
            wtw,
        }
    }

    /// K(T) = −(hidden part of M).
    fn k(&self, t: &[f64]) -> DMatrix<f64> {
        let m = self.w.len();
        let mut k = DMatrix::zeros(self.nh, self.nh);
        for j in 0..m - 1 {
            let o = self.offs[j];
            for a in 0..self.sizes[j] {
                k[(o + a, o + a)] = 2.0 * t[o + a];
            }
            if j >= 1 {
                // Off-diagonal block (j−1, j): −W̃_{j+1}ᵀ T_{j+1} in 1-based layer terms,
                // i.e. −W[j]ᵀ T_j here (W[j] maps hidden j−1 to hidden j).
                let op = self.offs[j - 1];
                for a in 0..self.sizes[j - 1] {
                    for b in 0..self.sizes[j] {
                        let v = -self.w[j][(b, a)] * t[o + b];
                        k[(op + a, o + b)] = v;
                        k[(o + b, op + a)] = v;
                    }
                }
            }
        }
        let o = self.offs[m - 2];
        for a in 0..self.sizes[m - 2] {
            for b in 0..self.sizes[m - 2] {
                k[(o + a, o + b)] -= self.wtw[(a, b)];
            }
        }
        k
    }

    /// [`LipSdp::k`] into the column-major buffer `k`: the same lower triangle (the upper
    /// one is not read by the kernels and may hold anything).
    ///
    /// K is block tridiagonal, and so is its Cholesky factor (no fill outside the blocks):
    /// the entries outside the blocks are zeroed when the buffer is sized and stay zero
    /// through [`dense::cholesky_in_place`] (only ±0 products are ever added to them), so a
    /// call rewrites the diagonal blocks' lower triangles and the sub-diagonal blocks only.
    /// `shape` records the block sizes the buffer's zeros were laid out for: another
    /// network's blocks (even with as many hidden units) get a freshly zeroed buffer.
    fn k_into(&self, t: &[f64], k: &mut Vec<f64>, shape: &mut Vec<usize>) {
        let (m, n) = (self.w.len(), self.nh);
        if k.len() != n * n || *shape != self.sizes {
            k.clear();
            k.resize(n * n, 0.0);
            shape.clone_from(&self.sizes);
        }
        for j in 0..m - 1 {
            let o = self.offs[j];
            for c in o..o + self.sizes[j] {
                k[c * n + c..c * n + o + self.sizes[j]].fill(0.0);
            }
            for a in 0..self.sizes[j] {
                k[(o + a) * n + o + a] = 2.0 * t[o + a];
            }
            if j >= 1 {
                let op = self.offs[j - 1];
                for a in 0..self.sizes[j - 1] {
                    for b in 0..self.sizes[j] {
                        let v = -self.w[j][(b, a)] * t[o + b];
                        k[(o + b) * n + op + a] = v;
                        k[(op + a) * n + o + b] = v;
                    }
                }
            }
        }
        let o = self.offs[m - 2];
        for b in 0..self.sizes[m - 2] {
            for a in 0..self.sizes[m - 2] {
                k[(o + b) * n + o + a] -= self.wtw[(a, b)];
            }
        }
    }

    /// N₁ᵀ (nh × n0): rows of hidden layer 1 are T_1 W̃_1.
    fn n1t(&self, t: &[f64]) -> DMatrix<f64> {
        let n0 = self.w[0].ncols();
        let mut n = DMatrix::zeros(self.nh, n0);
        for a in 0..self.sizes[0] {
            for c in 0..n0 {
                n[(a, c)] = t[a] * self.w[0][(a, c)];
            }
        }
        n
    }

    /// ρ(T) = λ_max(A(T)), A = N₁K⁻¹N₁ᵀ, its smoothing `f_μ = μ ln tr exp(A/μ)`
    /// (λ_max ≤ f_μ ≤ λ_max + μ ln n₀) and ∇f_μ; `None` if K(T) is not positive definite.
    /// ∇f_μ = Σᵢ pᵢ ∇λᵢ with softmax weights pᵢ ∝ exp(λᵢ/μ), where for an eigenvector v
    /// `∂λ/∂t_{j,k} = 2 w_{j,k} ((W̃_j w_{j−1})_k − w_{j,k})`, `w = K⁻¹N₁ᵀv`, `w_0 = v`. The
    /// smoothing makes the descent converge where eigenvalues of A coalesce (the typical
    /// situation at the optimum), at which λ_max itself is not differentiable.
    ///
    /// Computed on the buffers of `ws` by the kernels of [`dense`], the operations of the
    /// `nalgebra` version ([`LipSdp::rho_nalgebra`], kept for the tests) in the same order.
    fn rho(&self, t: &[f64], mu: f64, ws: &mut DenseWork) -> Option<(f64, f64, Vec<f64>)> {
        let (lmax, f) = self.rho_value(t, mu, ws)?;
        Some((lmax, f, self.rho_grad(ws)))
    }

    /// The value part of [`LipSdp::rho`]: (λ_max, f_μ), `None` if K(T) is not positive
    /// definite; leaves K⁻¹N₁ᵀ and the eigendecomposition of A in `ws` for
    /// [`LipSdp::rho_grad`] (a line search's rejected trials need no gradient).
    fn rho_value(&self, t: &[f64], mu: f64, ws: &mut DenseWork) -> Option<(f64, f64)> {
        let (n, n0) = (self.nh, self.w[0].ncols());
        ws.eig = None;
        self.k_into(t, &mut ws.k, &mut ws.k_shape);
        if !dense::cholesky_in_place(&mut ws.k, n) {
            return None;
        }
        ws.nt.clear();
        ws.nt.resize(n * n0, 0.0);
        for c in 0..n0 {
            for a in 0..self.sizes[0] {
                ws.nt[c * n + a] = t[a] * self.w[0][(a, c)];
            }
        }
        ws.kin.clone_from(&ws.nt);
        dense::solve_cols(&ws.k, n, &mut ws.kin, n0);
        // A = N₁ K⁻¹ N₁ᵀ (n0 × n0), column after column as `gemv`, then symmetrised.
        let mut a = DMatrix::<f64>::zeros(n0, n0);
        for j1 in 0..n0 {
            let kc = &ws.kin[j1 * n..(j1 + 1) * n];
            for i in 0..n0 {
                let nc = &ws.nt[i * n..(i + 1) * n];
                let mut y = nc[0] * kc[0];
                for c in 1..n {
                    y += nc[c] * kc[c];
                }
                a[(i, j1)] = y;
            }
        }
        let a = 0.5 * (&a + a.transpose());
        let eig = a.symmetric_eigen();
        let (lmax, f, wts, z) = smoothed_max(eig.eigenvalues.as_slice(), mu);
        (ws.eig, ws.wts, ws.z) = (Some(eig), wts, z);
        Some((lmax, f))
    }

    /// The gradient ∇f_μ of [`LipSdp::rho`] at the T of the last [`LipSdp::rho_value`],
    /// from what it left in `ws` (zeros if that call returned `None`).
    fn rho_grad(&self, ws: &mut DenseWork) -> Vec<f64> {
        let (n, z) = (self.nh, ws.z);
        let mut g = vec![0.0; self.nh];
        let Some(eig) = ws.eig.take() else {
            return g;
        };
        ws.w.resize(n, 0.0);
        ws.wp
            .resize(self.sizes.iter().copied().max().unwrap_or(0), 0.0);
        for (i, &wt) in ws.wts.iter().enumerate() {
            let p = wt / z;
            if p < 1e-300 {
                continue;
            }
            let v = eig.eigenvectors.column(i);
            dense::gemv_cols(&ws.kin, n, v.as_slice(), &mut ws.w);
            let w = &ws.w;
            for j in 0..self.w.len() - 1 {
                let o = self.offs[j];
                let prev = if j == 0 {
                    v.as_slice()
                } else {
                    &w[self.offs[j - 1]..self.offs[j - 1] + self.sizes[j - 1]]
                };
                let wp = &mut ws.wp[..self.sizes[j]];
                dense::gemv_cols(self.w[j].as_slice(), self.sizes[j], prev, wp);
                for k in 0..self.sizes[j] {
                    g[o + k] += p * 2.0 * w[o + k] * (wp[k] - w[o + k]);
                }
            }
        }
        ws.eig = Some(eig);
        g
    }

    /// [`LipSdp::rho`] with `nalgebra`'s allocating routines (the reference of its tests).
    #[cfg(test)]
    fn rho_nalgebra(&self, t: &[f64], mu: f64) -> Option<(f64, f64, Vec<f64>)> {
        let chol = nalgebra::Cholesky::new(self.k(t))?;
        let nt = self.n1t(t);
        let kin = chol.solve(&nt);
        let a = nt.transpose() * &kin;
        let a = 0.5 * (&a + a.transpose());
        let eig = a.symmetric_eigen();
        let (lmax, f, wts, z) = smoothed_max(eig.eigenvalues.as_slice(), mu);
        let mut g = vec![0.0; self.nh];
        for (i, &wt) in wts.iter().enumerate() {
            let p = wt / z;
            if p < 1e-300 {
                continue;
            }
            let v: DVector<f64> = eig.eigenvectors.column(i).into_owned();
            let w = &kin * &v;
            for j in 0..self.w.len() - 1 {
                let o = self.offs[j];
                let prev: DVector<f64> = if j == 0 {
                    v.clone()
                } else {
                    w.rows(self.offs[j - 1], self.sizes[j - 1]).into_owned()
                };
                let wp = &self.w[j] * prev;
                for k in 0..self.sizes[j] {
                    g[o + k] += p * 2.0 * w[o + k] * (wp[k] - w[o + k]);
                }
            }
        }
        Some((lmax, f, g))
    }

    /// Whether M(ρ, T) ⪯ 0, checked by a Cholesky factorisation of −M + 0·I.
    fn certify(&self, rho: f64, t: &[f64]) -> bool {
        let n0 = self.w[0].ncols();
        let dim = n0 + self.nh;
        let mut neg = DMatrix::zeros(dim, dim);
        for i in 0..n0 {
            neg[(i, i)] = rho;
        }
        let k = self.k(t);
        neg.view_mut((n0, n0), (self.nh, self.nh)).copy_from(&k);
        let nt = self.n1t(t);
        for a in 0..self.nh {
            for c in 0..n0 {
                neg[(n0 + a, c)] = -nt[(a, c)];
                neg[(c, n0 + a)] = -nt[(a, c)];
            }
        }
        nalgebra::Cholesky::new(neg).is_some()
    }
}

/// LipSDP-Neuron bound √ρ (see the module doc), certified by a Cholesky factorisation;
/// falls back to the naive bound if no certificate is found. Without hidden layers: ‖W̃‖₂.
pub fn lipsdp_bound(mlp: &Mlp) -> f64 {
    if mlp.layers.len() == 1 {
        return spectral_norm(&mat(&mlp.physical_layers()[0]));
    }
    match lipsdp_multipliers(mlp) {
        Some((rho, _)) => rho.sqrt(),
        None => naive_bound(mlp),
    }
}

/// The certified LipSDP-Neuron solution behind [`lipsdp_bound`]: ρ and the diagonal
/// multipliers T (hidden units in layer order) with M(ρ, T) ⪯ 0 verified by a Cholesky
/// factorisation of −M(ρ, T); `None` without hidden layers or if no certificate was found.
pub fn lipsdp_multipliers(mlp: &Mlp) -> Option<(f64, Vec<f64>)> {
    let sdp = LipSdp::new(mlp);
    if sdp.w.len() == 1 {
        return None;
    }
    // Closed-form start: S_0 = I, t_j = 1/‖W̃_j S_{j−1}⁻¹ W̃_jᵀ‖, S_j = 2t_jI − t_j²W̃_jS⁻¹W̃_jᵀ.
    let mut t = vec![0.0; sdp.nh];
    let mut s_inv = DMatrix::<f64>::identity(sdp.w[0].ncols(), sdp.w[0].ncols());
    for j in 0..sdp.w.len() - 1 {
        let a = &sdp.w[j] * &s_inv * sdp.w[j].transpose();
        let nrm = spectral_norm(&a).max(1e-300);
        let tj = 1.0 / nrm;
        for k in 0..sdp.sizes[j] {
            t[sdp.offs[j] + k] = tj;
        }
        let s = DMatrix::identity(a.nrows(), a.nrows()) * (2.0 * tj) - a * (tj * tj);
        s_inv = s
            .try_inverse()
            .unwrap_or_else(|| DMatrix::identity(sdp.sizes[j], sdp.sizes[j]));
    }
    // Scale T up until K(T) ≻ 0 (the last block subtracts W̃_mᵀW̃_m); ρ scales accordingly.
    let mut ws = DenseWork::default();
    let mut scale = 1.0;
    let mut cur = None;
    for _ in 0..200 {
        let ts: Vec<f64> = t.iter().map(|v| v * scale).collect();
        if let Some(r) = sdp.rho(&ts, 1.0, &mut ws) {
            t = ts;
            cur = Some(r.0);
            break;
        }
        scale *= 2.0;
    }
    let rho0 = cur?;
    // Minimise f_μ over θ = ln t by gradient steps with backtracking (BB step sizes), for
    // μ = 10⁻²ρ₀, 10⁻³ρ₀, …, 10⁻¹¹ρ₀ (each stage warm-started), keeping the T of the least
    // λ_max seen.
    let mut theta: Vec<f64> = t.iter().map(|v| v.ln()).collect();
    let (mut rho, mut best_theta) = (rho0, theta.clone());
    let mut step = 0.1;
    let mut mu = 1e-2 * rho0.max(1e-300);
    for _stage in 0..10 {
        let t: Vec<f64> = theta.iter().map(|v| v.exp()).collect();
        let Some((_, mut f, g)) = sdp.rho(&t, mu, &mut ws) else {
            break;
        };
        let mut gt: Vec<f64> = g.iter().zip(&t).map(|(g, t)| g * t).collect();
        for _ in 0..300 {
            let gn: f64 = gt.iter().map(|v| v * v).sum::<f64>().sqrt();
            if gn <= 1e-12 * f.abs().max(1e-300) {
                break;
            }
            let mut accepted = false;
            for _ in 0..40 {
                let th2: Vec<f64> = theta.iter().zip(&gt).map(|(th, g)| th - step * g).collect();
                let t2: Vec<f64> = th2.iter().map(|v| v.exp()).collect();
                if let Some((l2, f2)) = sdp.rho_value(&t2, mu, &mut ws) {
                    if f2 <= f - 1e-4 * step * gn * gn {
                        let g2 = sdp.rho_grad(&mut ws);
                        let gt2: Vec<f64> = g2.iter().zip(&t2).map(|(g, t)| g * t).collect();
                        // Barzilai–Borwein step for the next iteration.
                        let s: Vec<f64> = th2.iter().zip(&theta).map(|(a, b)| a - b).collect();
                        let y: Vec<f64> = gt2.iter().zip(&gt).map(|(a, b)| a - b).collect();
                        let sy: f64 = s.iter().zip(&y).map(|(a, b)| a * b).sum();
                        let ss: f64 = s.iter().map(|a| a * a).sum();
                        step = if sy > 0.0 {
                            (ss / sy).clamp(1e-8, 1e3)
                        } else {
                            step * 2.0
                        };
                        let rel = (f - f2) / f.abs().max(1e-300);
                        theta = th2;
                        f = f2;
                        gt = gt2;
                        if l2 < rho {
                            rho = l2;
                            best_theta.clone_from(&theta);
                        }
                        accepted = rel >= 1e-13;
                        break;
                    }
                }
                step *= 0.5;
            }
            if !accepted {
                break;
            }
        }
        mu *= 0.1;
    }
    let theta = best_theta;
    let t: Vec<f64> = theta.iter().map(|v| v.exp()).collect();
    // Certify: inflate ρ until −M(ρ′, T) has a Cholesky factorisation.
    let mut rho_c = rho * (1.0 + 1e-9) + 1e-12;
    for _ in 0..60 {
        if sdp.certify(rho_c, &t) {
            return Some((rho_c, t));
        }
        rho_c *= 1.0 + 1e-6;
        rho_c += 1e-9;
    }
    None
}

/// Exact maximum of ‖W̃_m D_{m−1}⋯D_1 W̃_1‖₂ over slope vertices D_j ∈ {0,1}ⁿ; `None` if
/// the number of hidden units exceeds `max_hidden` (2^units vertices).
///
/// Enumeration: with h the widest hidden layer, `J = A D_h B` where
/// `A = W̃_m D_{m−1}⋯W̃_{h+1}` and `B = W̃_h D_{h−1}⋯W̃_1` depend only on the other layers'
/// slopes, so `J(S) = Σ_{a∈S} A_{:,a} B_{a,:}` over the active units S of layer h. For each
/// pattern of the other layers, the partial sums over the low and the high half of layer
/// h's units are tabulated (each entry one addition from another), and every vertex costs
/// one nu × n0 addition and a norm. Each J is a sum of at most n_h outer products, so it
/// carries only the rounding of an ordinary matrix product (a different association than
/// the plain product W̃_m D ⋯ W̃_1).
pub fn vertex_bound(mlp: &Mlp, max_hidden: usize) -> Option<f64> {
    let w: Vec<DMatrix<f64>> = mlp.physical_layers().iter().map(mat).collect();
    let m = w.len();
    let hidden: usize = w[..m - 1].iter().map(|m| m.nrows()).sum();
    if hidden > max_hidden {
        return None;
    }
    if m == 1 {
        return Some(spectral_norm(&w[0]));
    }
    let n0 = w[0].ncols();
    let nu = w[m - 1].nrows();
    // Inner layer: the widest hidden layer (index into w: W[h] maps into hidden layer h).
    let h = (0..m - 1)
        .max_by_key(|&j| (w[j].nrows(), std::cmp::Reverse(j)))
        .unwrap_or(0);
    let nh = w[h].nrows();
    let others: Vec<usize> = (0..m - 1).filter(|&j| j != h).collect();
    let outer_bits: usize = others.iter().map(|&j| w[j].nrows()).sum();
    let (lo_bits, hi_bits) = (nh / 2, nh - nh / 2);
    let dim = nu * n0;
    let mut lo_tab = vec![0.0; dim << lo_bits];
    let mut hi_tab = vec![0.0; dim << hi_bits];
    let mut rank1 = vec![0.0; dim * nh];
    let mut j_buf = vec![0.0; dim];
    let mut lo_soa = vec![0.0; dim << lo_bits];
    let mut best = 0.0f64;
    for outer in 0u64..1u64 << outer_bits {
        // Slopes of the other layers from the outer mask.
        let slope = |j: usize| -> DVector<f64> {
            let mut bit = 0;
            for &o in &others {
                if o == j {
                    break;
                }
                bit += w[o].nrows();
            }
            DVector::from_fn(w[j].nrows(), |r, _| {
                if outer >> (bit + r) & 1 == 1 {
                    1.0
                } else {
                    0.0
                }
            })
        };
        // B = W̃_h D_{h−1} ⋯ D_1 W̃_1 (nh × n0), A = W̃_m D_{m−1} ⋯ D_{h+1} W̃_{h+1} (nu × nh).
        let mut b = w[0].clone();
        for j in 1..=h {
            let d = slope(j - 1);
            let mut db = b;
            for (r, mut row) in db.row_iter_mut().enumerate() {
                row *= d[r];
            }
            b = &w[j] * db;
        }
        let mut a = w[m - 1].clone();
        for j in (h + 1..m - 1).rev() {
            let d = slope(j);
            for (c, mut col) in a.column_iter_mut().enumerate() {
                col *= d[c];
            }
            a = &a * &w[j];
        }
        // Rank-one terms A_{:,u} B_{u,:}, row-major nu × n0.
        for u in 0..nh {
            for r in 0..nu {
                for c in 0..n0 {
                    rank1[u * dim + r * n0 + c] = a[(r, u)] * b[(u, c)];
                }
            }
        }
        for (tab, bits, first) in [
            (&mut lo_tab, lo_bits, 0usize),
            (&mut hi_tab, hi_bits, lo_bits),
        ] {
            for s in 1usize..1 << bits {
                let low = s.trailing_zeros() as usize;
                let prev = s & (s - 1);
                let (done, rest) = tab.split_at_mut(s * dim);
                let src = &done[prev * dim..(prev + 1) * dim];
                let term = &rank1[(first + low) * dim..(first + low + 1) * dim];
                for ((d, &p), &t) in rest[..dim].iter_mut().zip(src).zip(term) {
                    *d = p + t;
                }
            }
        }
        if nu == 1 || n0 == 1 {
            // ‖J‖₂² = Σ_e (l_e + h_e)² (a vector): the low table entry by entry
            // (structure of arrays), eight of its patterns per step in independent lanes.
            for (e, col) in lo_soa.chunks_exact_mut(1 << lo_bits).enumerate() {
                for (d, lv) in col.iter_mut().zip(lo_tab.chunks_exact(dim)) {
                    *d = lv[e];
                }
            }
            for hv in hi_tab.chunks_exact(dim) {
                best = best.max(max_sq_sum(&lo_soa, 1 << lo_bits, hv));
            }
        } else {
            for hv in hi_tab.chunks_exact(dim) {
                for lv in lo_tab.chunks_exact(dim) {
                    for ((j, &l), &h) in j_buf.iter_mut().zip(lv).zip(hv) {
                        *j = l + h;
                    }
                    best = best.max(squared_spectral_norm(&j_buf, nu, n0));
                }
            }
        }
    }
    Some(best.sqrt())
}

#[cfg(test)]
mod tests;
