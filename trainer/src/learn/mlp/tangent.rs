//! The tangent pass of [`Mlp`]: the input Jacobian by forward-mode differentiation,
//! computed block-wise alongside the forward pass.
//! ```text
//! T_0 = D,   T_j = diag(α′(z_j)) W_j T_{j−1},   ∂κ_NN/∂x = S W_m T_{m−1}
//! ```
//! The pre-activation tangents `W_j T_{j−1}` of the hidden layers are kept (`ws.zt`) for
//! the reverse pass of the Jacobian loss term; for the output layer `T_m = W_m T_{m−1} = Y`.

use super::kernels::dot_block;
use super::{Mlp, Workspace};

impl Mlp {
    /// `T_0 = D` over a block of `nb` samples.
    pub(super) fn tangent_input(&self, nb: usize, ws: &mut Workspace) {
        let nx = self.nx();
        let t0 = &mut ws.t[0][..nx * nx * nb];
        for (ck, tc) in t0.chunks_exact_mut(nb).enumerate() {
            let (c, k) = (ck / nx, ck % nx);
            tc.fill(if c == k { 1.0 / self.in_half[c] } else { 0.0 });
        }
    }

    /// One layer of the tangent pass over a block, after the layer's forward step (which
    /// leaves α′(z) in `ws.dz[j + 1]`): `Z = W T` from `ws.t[j]`, summed over the inputs in
    /// order, then, for a hidden layer, `ws.t[j + 1] = diag(α′(z)) Z`.
    pub(super) fn tangent_layer(&self, j: usize, nb: usize, ws: &mut Workspace) {
        let nx = self.nx();
        let l = &self.layers[j];
        let hidden = j + 1 < self.layers.len();
        let (inp, out) = (l.inp, l.out);
        // Z = W T_{j−1} (into zt for hidden layers, straight into T_m for the output).
        let (tlo, thi) = ws.t.split_at_mut(j + 1);
        let tp = &tlo[j][..inp * nx * nb];
        let dst = if hidden {
            &mut ws.zt[j + 1][..out * nx * nb]
        } else {
            &mut thi[0][..out * nx * nb]
        };
        for (row, zr) in l.w.chunks_exact(inp).zip(dst.chunks_exact_mut(nx * nb)) {
            for (k, s) in zr.chunks_exact_mut(nb).enumerate() {
                dot_block(row, &tp[k * nb..], nx * nb, 0.0, s);
            }
        }
        if hidden {
            let dz = &ws.dz[j + 1][..out * nb];
            let zt = &ws.zt[j + 1][..out * nx * nb];
            let tn = &mut ws.t[j + 1][..out * nx * nb];
            for ((tr, zr), dr) in tn
                .chunks_exact_mut(nx * nb)
                .zip(zt.chunks_exact(nx * nb))
                .zip(dz.chunks_exact(nb))
            {
                for (tk, zk) in tr.chunks_exact_mut(nb).zip(zr.chunks_exact(nb)) {
                    for ((t, &z), &d) in tk.iter_mut().zip(zk).zip(dr) {
                        *t = d * z;
                    }
                }
            }
        }
    }
}
