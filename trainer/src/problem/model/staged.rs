//! [`Discrete`]'s derivatives for one stage of an OCP: the entry points of
//! `mpc::ocp`, through which an expression plant's sweep reuses the forward sweep of a stage
//! between `∂F` and `∇²(λᵀF)` at the same point (`expr::Sweep`'s module doc).

use super::Discrete;

impl Discrete {
    /// [`Discrete::linearize`] for stage `stage` of an OCP: an expression plant's sweep keeps
    /// its forward sweep for the stage, and a later call of this or of
    /// [`Discrete::lagrangian_hessian_at`] for the same stage at the same `(x, u)` reuses it
    /// (the same bits as a new sweep; `expr::Sweep`'s module doc).
    pub fn linearize_at(
        &self,
        stage: usize,
        x: &[f64],
        u: &[f64],
        f: &mut [f64],
        jx: &mut [f64],
        ju: &mut [f64],
    ) {
        match self.sweep() {
            Some(sw) => sw.linearize_at(stage, x, u, f, jx, ju),
            None => self.linearize(x, u, f, jx, ju),
        }
    }
    /// [`Discrete::lagrangian_hessian`] for stage `stage` (see [`Discrete::linearize_at`]).
    pub fn lagrangian_hessian_at(
        &self,
        stage: usize,
        x: &[f64],
        u: &[f64],
        lam: &[f64],
        hess: &mut [f64],
    ) {
        match self.sweep() {
            Some(sw) => sw.lagrangian_hessian_at(stage, x, u, lam, hess),
            None => self.lagrangian_hessian(x, u, lam, hess),
        }
    }
}
