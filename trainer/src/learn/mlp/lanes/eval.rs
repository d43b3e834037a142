//! The network's outputs and Jacobians over a batch of states on the f32 lane engine
//! ([`Lanes::eval_batch`]): the forward and tangent passes of [`Lanes`] (`y = κ_NN(x)`,
//! `Y = ∂κ_NN/∂x` through the jets), without a loss.

use super::{chunk_groups, Lanes, L};
use crate::learn::mlp::Mlp;

impl Lanes {
    /// κ_NN at the states `x` (row-major n × nx) into `u` (n × nu) and, if given, the
    /// Jacobians into `jac` (n × nu·nx), computed in f32 (the outputs of
    /// [`Mlp::eval_batch`] up to f32 rounding).
    pub fn eval_batch(&mut self, mlp: &Mlp, x: &[f64], u: &mut [f64], jac: Option<&mut [f64]>) {
        self.load(mlp);
        #[cfg(target_arch = "x86_64")]
        if super::cpu_has_avx2() {
            // SAFETY: the CPU has AVX and AVX2 (`cpu_has_avx2`), see `loss_grad`.
            return unsafe { self.eval_batch_avx2(mlp, x, u, jac) };
        }
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx") {
            // SAFETY: the CPU has AVX (checked just above), see `loss_grad`.
            return unsafe { self.eval_batch_avx(mlp, x, u, jac) };
        }
        self.eval_batch_impl(mlp, x, u, jac)
    }

    /// [`Lanes::eval_batch_impl`] compiled with AVX (the same bits, see `loss_grad_avx`).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    pub(super) fn eval_batch_avx(
        &mut self,
        mlp: &Mlp,
        x: &[f64],
        u: &mut [f64],
        jac: Option<&mut [f64]>,
    ) {
        self.eval_batch_impl(mlp, x, u, jac)
    }

    /// [`Lanes::eval_batch_impl`] compiled with AVX2 (the same bits, see `loss_grad_avx2`).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx,avx2")]
    fn eval_batch_avx2(&mut self, mlp: &Mlp, x: &[f64], u: &mut [f64], jac: Option<&mut [f64]>) {
        self.eval_batch_impl(mlp, x, u, jac)
    }

    #[inline(always)]
    pub(super) fn eval_batch_impl(
        &mut self,
        mlp: &Mlp,
        x: &[f64],
        u: &mut [f64],
        mut jac: Option<&mut [f64]>,
    ) {
        let (nx, nu, m) = (mlp.nx(), mlp.nu(), mlp.layers.len());
        let n = x.len() / nx.max(1);
        let q = if jac.is_some() { 1 + nx } else { 1 };
        let maxw = self.widths.iter().copied().max().unwrap_or(0);
        let span = chunk_groups(maxw, q) * L;
        for i0 in (0..n).step_by(span) {
            let nb = span.min(n - i0);
            self.pass(mlp, x, None, i0, nb, q, nb.div_ceil(L));
            let y = &self.h[m];
            for s in 0..nb {
                let (o, i) = ((s / L) * nu * q, s % L);
                for r in 0..nu {
                    let sc = mlp.out_half[r];
                    u[(i0 + s) * nu + r] = mlp.out_center[r] + sc * f64::from(y[o + r * q][i]);
                    if let Some(jac) = jac.as_deref_mut() {
                        for k in 0..nx {
                            jac[(i0 + s) * nu * nx + r * nx + k] =
                                sc * f64::from(y[o + r * q + 1 + k][i]);
                        }
                    }
                }
            }
        }
    }
}
