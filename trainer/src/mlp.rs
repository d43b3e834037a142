//! The multilayer perceptron κ_NN = ζ_m ∘ α ∘ … ∘ α ∘ ζ₁ and its exact derivatives.
//!
//! Layers `z_j = W_j a_{j−1} + b_j`, hidden activations `a_j = α(z_j)` (tanh by default;
//! softplus and ReLU optional), linear output. Inputs and outputs are scaled so that the
//! trained parameters see X as [−1, 1]ⁿ and U as [−1, 1]ᵐ:
//! ```text
//! a_0 = D (x − c),   D = diag(1/h),  c, h = centre and half-width of X
//! u   = o + S y,     S = diag(s),    o, s = centre and half-width of the output range
//! ```
//! The input Jacobian is an explicit forward (tangent) computation,
//! `T_0 = D`, `T_j = diag(α′(z_j)) W_j T_{j−1}`, `∂κ_NN/∂x = S W_m T_{m−1}`,
//! and [`Mlp::loss_grad`] differentiates the training loss through both passes in reverse
//! mode (hand-derived; checked against central differences in the tests):
//! ```text
//! loss = λ₁/B Σ‖u_i − κ_i‖² + λ₂/B Σ_{i ∉ degenerate} ‖∂u_i/∂x − ∂κ_i/∂x‖²_F + λ₃ Σ_j ‖W̃_j‖²_F
//! ```
//! with `W̃_j` the weights in physical units (the scalings folded in: `W̃_1 = W_1 D`,
//! `W̃_m = S W_m`), so that λ₃ penalises what the paper penalises on its unscaled network.
//! The weight norm is the Frobenius norm.

use serde::{Deserialize, Serialize};

/// Hidden-layer activation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Activation {
    /// tanh (slope in [0, 1]).
    Tanh,
    /// ln(1 + eᶻ) (slope in [0, 1]).
    Softplus,
    /// max(0, z) (slope in {0, 1}).
    Relu,
}

impl Activation {
    /// (α(z), α′(z), α″(z)).
    #[inline]
    pub fn eval(self, z: f64) -> (f64, f64, f64) {
        match self {
            Activation::Tanh => {
                let t = z.tanh();
                let d = 1.0 - t * t;
                (t, d, -2.0 * t * d)
            }
            Activation::Softplus => {
                let s = 1.0 / (1.0 + (-z).exp());
                let v = if z > 30.0 { z } else { z.exp().ln_1p() };
                (v, s, s * (1.0 - s))
            }
            Activation::Relu => {
                if z > 0.0 {
                    (z, 1.0, 0.0)
                } else {
                    (0.0, 0.0, 0.0)
                }
            }
        }
    }
}

/// One affine layer: `w` row-major (out × inp), bias `b`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Layer {
    /// Input width.
    pub inp: usize,
    /// Output width.
    pub out: usize,
    /// Weights, row-major out × inp.
    pub w: Vec<f64>,
    /// Bias.
    pub b: Vec<f64>,
}

/// The network with its input and output scaling.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Mlp {
    /// Layers, input to output.
    pub layers: Vec<Layer>,
    /// Hidden activation.
    pub activation: Activation,
    /// Input centre c.
    pub in_center: Vec<f64>,
    /// Input half-width h.
    pub in_half: Vec<f64>,
    /// Output centre o.
    pub out_center: Vec<f64>,
    /// Output half-width s.
    pub out_half: Vec<f64>,
}

/// Gradient with the same shapes as the layers.
#[derive(Debug, Clone, PartialEq)]
pub struct Grad {
    /// ∂loss/∂W_j, row-major.
    pub w: Vec<Vec<f64>>,
    /// ∂loss/∂b_j.
    pub b: Vec<Vec<f64>>,
}

/// Loss weights (λ₁, λ₂, λ₃).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LossWeights {
    /// λ₁: value (MSE) term.
    pub value: f64,
    /// λ₂: Jacobian term.
    pub jacobian: f64,
    /// λ₃: weight term.
    pub weights: f64,
}

/// Loss value split into its terms (each already multiplied by its λ).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct LossParts {
    /// λ₁ · MSE.
    pub value: f64,
    /// λ₂ · mean Jacobian mismatch.
    pub jacobian: f64,
    /// λ₃ · Σ‖W̃‖²_F.
    pub weights: f64,
}

impl LossParts {
    /// Sum of the terms.
    pub fn total(&self) -> f64 {
        self.value + self.jacobian + self.weights
    }
}

/// A batch of training targets, borrowed from the dataset.
pub struct Batch<'a> {
    /// States, row-major B × nx.
    pub x: &'a [f64],
    /// Targets κ, row-major B × nu.
    pub u: &'a [f64],
    /// Target Jacobians, row-major B × (nu·nx), each row-major nu × nx.
    pub du: &'a [f64],
    /// Whether sample i's Jacobian term is used (false at degenerate points).
    pub use_jac: &'a [bool],
}

/// Reusable per-sample buffers for the passes.
#[derive(Debug, Clone, Default)]
pub struct Workspace {
    a: Vec<Vec<f64>>,
    dz: Vec<Vec<f64>>,
    ddz: Vec<Vec<f64>>,
    t: Vec<Vec<f64>>,
    zt: Vec<Vec<f64>>,
    ga: Vec<f64>,
    gt: Vec<f64>,
    ga2: Vec<f64>,
    gt2: Vec<f64>,
}

impl Mlp {
    /// A network of widths `[nx, h₁, …, nu]` with seeded Glorot-uniform weights and zero
    /// biases; scaling from the input box `[lo, hi]` and output box `[u_lo, u_hi]`.
    pub fn new(
        widths: &[usize],
        activation: Activation,
        seed: u64,
        lo: &[f64],
        hi: &[f64],
        u_lo: &[f64],
        u_hi: &[f64],
    ) -> Self {
        let mut layers = Vec::new();
        for (j, w) in widths.windows(2).enumerate() {
            let (inp, out) = (w[0], w[1]);
            let lim = (6.0 / (inp + out) as f64).sqrt();
            let ws = (0..inp * out)
                .map(|k| lim * (2.0 * crate::sampling::uniform(seed, j as u64, k as u64) - 1.0))
                .collect();
            layers.push(Layer {
                inp,
                out,
                w: ws,
                b: vec![0.0; out],
            });
        }
        let half = |l: &[f64], h: &[f64]| {
            l.iter()
                .zip(h)
                .map(|(a, b)| 0.5 * (b - a))
                .collect::<Vec<_>>()
        };
        let mid = |l: &[f64], h: &[f64]| {
            l.iter()
                .zip(h)
                .map(|(a, b)| 0.5 * (a + b))
                .collect::<Vec<_>>()
        };
        Mlp {
            layers,
            activation,
            in_center: mid(lo, hi),
            in_half: half(lo, hi),
            out_center: mid(u_lo, u_hi),
            out_half: half(u_lo, u_hi),
        }
    }

    /// Input dimension.
    pub fn nx(&self) -> usize {
        self.layers.first().map_or(0, |l| l.inp)
    }
    /// Output dimension.
    pub fn nu(&self) -> usize {
        self.layers.last().map_or(0, |l| l.out)
    }
    /// Layer widths `[nx, h₁, …, nu]`.
    pub fn widths(&self) -> Vec<usize> {
        let mut w = vec![self.nx()];
        w.extend(self.layers.iter().map(|l| l.out));
        w
    }

    /// The weights in physical units: `W̃_1 = W_1 D`, `W̃_m = S W_m` (both for m = 1),
    /// row-major, and the biases of the affine map from x to u (`b̃_1 = b_1 − W_1 D c`,
    /// `b̃_m = o + S b_m`).
    pub fn physical_layers(&self) -> Vec<Layer> {
        let m = self.layers.len();
        let mut out = self.layers.clone();
        for (j, l) in out.iter_mut().enumerate() {
            if j == 0 {
                for r in 0..l.out {
                    let mut shift = 0.0;
                    for c in 0..l.inp {
                        l.w[r * l.inp + c] /= self.in_half[c];
                        shift += l.w[r * l.inp + c] * self.in_center[c];
                    }
                    l.b[r] -= shift;
                }
            }
            if j + 1 == m {
                for r in 0..l.out {
                    for c in 0..l.inp {
                        l.w[r * l.inp + c] *= self.out_half[r];
                    }
                    l.b[r] = self.out_center[r] + self.out_half[r] * l.b[r];
                }
            }
        }
        out
    }

    fn ensure(&self, ws: &mut Workspace) {
        let nx = self.nx();
        let m = self.layers.len();
        if ws.a.len() != m + 1 {
            ws.a = self.widths().iter().map(|&n| vec![0.0; n]).collect();
            ws.dz = self.widths().iter().map(|&n| vec![0.0; n]).collect();
            ws.ddz = self.widths().iter().map(|&n| vec![0.0; n]).collect();
            ws.t = self.widths().iter().map(|&n| vec![0.0; n * nx]).collect();
            ws.zt = self.widths().iter().map(|&n| vec![0.0; n * nx]).collect();
            let maxw = self.widths().into_iter().max().unwrap_or(0);
            ws.ga = vec![0.0; maxw];
            ws.ga2 = vec![0.0; maxw];
            ws.gt = vec![0.0; maxw * nx];
            ws.gt2 = vec![0.0; maxw * nx];
        }
    }

    /// Forward and tangent pass for one state; leaves activations, slopes and tangents in
    /// `ws` and returns nothing (read `u`/`jac` with [`Mlp::eval`]).
    fn pass(&self, x: &[f64], ws: &mut Workspace) {
        let nx = self.nx();
        let m = self.layers.len();
        for i in 0..nx {
            ws.a[0][i] = (x[i] - self.in_center[i]) / self.in_half[i];
            for k in 0..nx {
                ws.t[0][i * nx + k] = if i == k { 1.0 / self.in_half[i] } else { 0.0 };
            }
        }
        for (j, l) in self.layers.iter().enumerate() {
            let (prev, rest) = ws.a.split_at_mut(j + 1);
            let (tprev, trest) = ws.t.split_at_mut(j + 1);
            let (ap, an) = (&prev[j], &mut rest[0]);
            let (tp, tn) = (&tprev[j], &mut trest[0]);
            let zt = &mut ws.zt[j + 1];
            for r in 0..l.out {
                let row = &l.w[r * l.inp..(r + 1) * l.inp];
                let mut z = l.b[r];
                for c in 0..l.inp {
                    z += row[c] * ap[c];
                }
                for k in 0..nx {
                    let mut s = 0.0;
                    for c in 0..l.inp {
                        s += row[c] * tp[c * nx + k];
                    }
                    zt[r * nx + k] = s;
                }
                if j + 1 < m {
                    let (v, d, dd) = self.activation.eval(z);
                    an[r] = v;
                    ws.dz[j + 1][r] = d;
                    ws.ddz[j + 1][r] = dd;
                    for k in 0..nx {
                        tn[r * nx + k] = d * zt[r * nx + k];
                    }
                } else {
                    an[r] = z;
                    for k in 0..nx {
                        tn[r * nx + k] = zt[r * nx + k];
                    }
                }
            }
        }
    }

    /// κ_NN(x) into `u` and ∂κ_NN/∂x (row-major nu × nx) into `jac`.
    pub fn eval(&self, x: &[f64], u: &mut [f64], jac: &mut [f64], ws: &mut Workspace) {
        self.ensure(ws);
        self.pass(x, ws);
        let (nx, m) = (self.nx(), self.layers.len());
        for r in 0..self.nu() {
            u[r] = self.out_center[r] + self.out_half[r] * ws.a[m][r];
            for k in 0..nx {
                jac[r * nx + k] = self.out_half[r] * ws.t[m][r * nx + k];
            }
        }
    }

    /// κ_NN(x) only (allocating convenience).
    pub fn predict(&self, x: &[f64]) -> Vec<f64> {
        let mut ws = Workspace::default();
        let mut u = vec![0.0; self.nu()];
        let mut j = vec![0.0; self.nu() * self.nx()];
        self.eval(x, &mut u, &mut j, &mut ws);
        u
    }

    /// The weight term Σ_j ‖W̃_j‖²_F (physical units).
    pub fn weight_norm2(&self) -> f64 {
        self.physical_layers()
            .iter()
            .map(|l| l.w.iter().map(|v| v * v).sum::<f64>())
            .sum()
    }

    /// Loss of a batch and its exact gradient with respect to the (scaled) parameters.
    pub fn loss_grad(
        &self,
        batch: &Batch,
        lam: LossWeights,
        grad: &mut Grad,
        ws: &mut Workspace,
    ) -> LossParts {
        self.ensure(ws);
        let (nx, nu, m) = (self.nx(), self.nu(), self.layers.len());
        let bsz = batch.use_jac.len();
        for (gw, gb) in grad.w.iter_mut().zip(grad.b.iter_mut()) {
            gw.fill(0.0);
            gb.fill(0.0);
        }
        let inv_b = 1.0 / bsz.max(1) as f64;
        let mut parts = LossParts::default();
        for i in 0..bsz {
            let x = &batch.x[i * nx..(i + 1) * nx];
            self.pass(x, ws);
            // Output gradients (w.r.t. the network's raw output y and its tangent Y).
            let use_jac = batch.use_jac[i] && lam.jacobian != 0.0;
            for r in 0..nu {
                let s = self.out_half[r];
                let e = self.out_center[r] + s * ws.a[m][r] - batch.u[i * nu + r];
                parts.value += lam.value * inv_b * e * e;
                ws.ga[r] = 2.0 * lam.value * inv_b * e * s;
                for k in 0..nx {
                    let g = if use_jac {
                        let e = s * ws.t[m][r * nx + k] - batch.du[i * nu * nx + r * nx + k];
                        parts.jacobian += lam.jacobian * inv_b * e * e;
                        2.0 * lam.jacobian * inv_b * e * s
                    } else {
                        0.0
                    };
                    ws.gt[r * nx + k] = g;
                }
            }
            // Backward through the layers. ga/gt hold ∂loss/∂z_j and ∂loss/∂Z_j for the
            // current layer j (for the output layer z = y, Z = Y).
            for j in (0..m).rev() {
                let l = &self.layers[j];
                if j + 1 < m {
                    // ga, gt hold ∂/∂a_{j+1}, ∂/∂T_{j+1}: convert to ∂/∂z, ∂/∂Z.
                    let (d, dd, zt) = (&ws.dz[j + 1], &ws.ddz[j + 1], &ws.zt[j + 1]);
                    for r in 0..l.out {
                        let mut acc = 0.0;
                        for k in 0..nx {
                            acc += ws.gt[r * nx + k] * zt[r * nx + k];
                            ws.gt[r * nx + k] *= d[r];
                        }
                        ws.ga[r] = d[r] * ws.ga[r] + dd[r] * acc;
                    }
                }
                let (ap, tp) = (&ws.a[j], &ws.t[j]);
                let gw = &mut grad.w[j];
                for r in 0..l.out {
                    grad.b[j][r] += ws.ga[r];
                    for c in 0..l.inp {
                        let mut g = ws.ga[r] * ap[c];
                        for k in 0..nx {
                            g += ws.gt[r * nx + k] * tp[c * nx + k];
                        }
                        gw[r * l.inp + c] += g;
                    }
                }
                if j > 0 {
                    for c in 0..l.inp {
                        let mut g = 0.0;
                        for r in 0..l.out {
                            g += l.w[r * l.inp + c] * ws.ga[r];
                        }
                        ws.ga2[c] = g;
                        for k in 0..nx {
                            let mut g = 0.0;
                            for r in 0..l.out {
                                g += l.w[r * l.inp + c] * ws.gt[r * nx + k];
                            }
                            ws.gt2[c * nx + k] = g;
                        }
                    }
                    std::mem::swap(&mut ws.ga, &mut ws.ga2);
                    std::mem::swap(&mut ws.gt, &mut ws.gt2);
                }
            }
        }
        // Weight term on the physical weights: ‖W̃‖² with W̃_1 = W_1 D, W̃_m = S W_m.
        if lam.weights != 0.0 {
            for (j, l) in self.layers.iter().enumerate() {
                for r in 0..l.out {
                    let rs = if j + 1 == m { self.out_half[r] } else { 1.0 };
                    for c in 0..l.inp {
                        let cs = if j == 0 { 1.0 / self.in_half[c] } else { 1.0 };
                        let f = rs * rs * cs * cs;
                        let w = l.w[r * l.inp + c];
                        parts.weights += lam.weights * f * w * w;
                        grad.w[j][r * l.inp + c] += 2.0 * lam.weights * f * w;
                    }
                }
            }
        }
        parts
    }

    /// A zero gradient of matching shapes.
    pub fn zero_grad(&self) -> Grad {
        Grad {
            w: self.layers.iter().map(|l| vec![0.0; l.w.len()]).collect(),
            b: self.layers.iter().map(|l| vec![0.0; l.b.len()]).collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn net(seed: u64, act: Activation, widths: &[usize]) -> Mlp {
        let nx = widths[0];
        let nu = *widths.last().unwrap();
        let lo: Vec<f64> = (0..nx).map(|i| -1.0 - i as f64).collect();
        let hi: Vec<f64> = (0..nx).map(|i| 2.0 + 0.5 * i as f64).collect();
        let mut m = Mlp::new(widths, act, seed, &lo, &hi, &vec![-3.0; nu], &vec![5.0; nu]);
        for (j, l) in m.layers.iter_mut().enumerate() {
            for (k, b) in l.b.iter_mut().enumerate() {
                *b = 0.3 * (2.0 * crate::sampling::uniform(seed + 99, j as u64, k as u64) - 1.0);
            }
        }
        m
    }

    fn data(
        seed: u64,
        nx: usize,
        nu: usize,
        b: usize,
    ) -> (Vec<f64>, Vec<f64>, Vec<f64>, Vec<bool>) {
        let r = |a: u64, k: usize| 4.0 * crate::sampling::uniform(seed, a, k as u64) - 2.0;
        let x = (0..b * nx).map(|k| r(1, k)).collect();
        let u = (0..b * nu).map(|k| r(2, k)).collect();
        let du = (0..b * nu * nx).map(|k| 3.0 * r(3, k)).collect();
        let use_jac = (0..b).map(|i| i % 3 != 1).collect();
        (x, u, du, use_jac)
    }

    /// Central differences of the loss against the hand-derived gradient, term by term.
    fn check_grad(act: Activation, widths: &[usize], seed: u64) {
        let m = net(seed, act, widths);
        let (nx, nu) = (m.nx(), m.nu());
        let (x, u, du, uj) = data(seed, nx, nu, 7);
        let batch = Batch {
            x: &x,
            u: &u,
            du: &du,
            use_jac: &uj,
        };
        for lam in [
            LossWeights {
                value: 1.0,
                jacobian: 0.0,
                weights: 0.0,
            },
            LossWeights {
                value: 0.0,
                jacobian: 1.0,
                weights: 0.0,
            },
            LossWeights {
                value: 0.0,
                jacobian: 0.0,
                weights: 1.0,
            },
            LossWeights {
                value: 1.0,
                jacobian: 3.0,
                weights: 0.05,
            },
        ] {
            let mut ws = Workspace::default();
            let mut g = m.zero_grad();
            m.loss_grad(&batch, lam, &mut g, &mut ws);
            let h = 1e-6;
            for j in 0..m.layers.len() {
                for k in 0..m.layers[j].w.len() + m.layers[j].b.len() {
                    let nw = m.layers[j].w.len();
                    let f = |d: f64| {
                        let mut p = m.clone();
                        if k < nw {
                            p.layers[j].w[k] += d;
                        } else {
                            p.layers[j].b[k - nw] += d;
                        }
                        let mut g2 = p.zero_grad();
                        p.loss_grad(&batch, lam, &mut g2, &mut Workspace::default())
                            .total()
                    };
                    let fd = (f(h) - f(-h)) / (2.0 * h);
                    let an = if k < nw { g.w[j][k] } else { g.b[j][k - nw] };
                    assert!(
                        (fd - an).abs() <= 1e-6 * (1.0 + an.abs()),
                        "{act:?} {widths:?} {lam:?} layer {j} param {k}: fd {fd} analytic {an}"
                    );
                }
            }
        }
    }

    #[test]
    fn gradients_match_finite_differences() {
        check_grad(Activation::Tanh, &[2, 10, 10, 1], 1);
        check_grad(Activation::Tanh, &[3, 4, 2], 2);
        check_grad(Activation::Tanh, &[2, 1], 3);
        check_grad(Activation::Softplus, &[2, 5, 4, 2], 4);
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(32))]
        #[test]
        fn jacobian_matches_finite_differences(seed in 0u64..1000, x in proptest::collection::vec(-3.0f64..3.0, 3)) {
            for act in [Activation::Tanh, Activation::Softplus] {
                let m = net(seed, act, &[3, 6, 5, 2]);
                let mut ws = Workspace::default();
                let (mut u, mut j) = (vec![0.0; 2], vec![0.0; 6]);
                m.eval(&x, &mut u, &mut j, &mut ws);
                for k in 0..3 {
                    let (mut xp, mut xm) = (x.clone(), x.clone());
                    xp[k] += 1e-6;
                    xm[k] -= 1e-6;
                    let (up, um) = (m.predict(&xp), m.predict(&xm));
                    for r in 0..2 {
                        let fd = (up[r] - um[r]) / 2e-6;
                        prop_assert!((fd - j[r * 3 + k]).abs() <= 1e-6 * (1.0 + fd.abs()));
                    }
                }
            }
        }
    }

    #[test]
    fn physical_layers_compute_the_same_function() {
        let m = net(5, Activation::Tanh, &[2, 7, 3]);
        let phys = m.physical_layers();
        let x = [0.7, -1.3];
        let mut a = x.to_vec();
        for (j, l) in phys.iter().enumerate() {
            let mut z = l.b.clone();
            for r in 0..l.out {
                for c in 0..l.inp {
                    z[r] += l.w[r * l.inp + c] * a[c];
                }
            }
            a = if j + 1 < phys.len() {
                z.iter().map(|v| v.tanh()).collect()
            } else {
                z
            };
        }
        let u = m.predict(&x);
        for r in 0..3 {
            assert!((u[r] - a[r]).abs() < 1e-12);
        }
    }
}
