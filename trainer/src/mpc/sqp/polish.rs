//! The SQP's active-set Newton polish (step 4 of the parent module's doc): with the active
//! set A guessed from the SQP iterate, Newton's method on the KKT conditions restricted to A,
//! ```text
//! ⎡ ∇²L   ∇cᵀ  G_Aᵀ ⎤ ⎡ Δz  ⎤     ⎡ ∇f          ⎤
//! ⎢ ∇c    0    0    ⎥ ⎢ λ⁺  ⎥ = − ⎢ c           ⎥ ,
//! ⎣ G_A   0    0    ⎦ ⎣ ν_A ⎦     ⎣ G_A z − h_A ⎦
//! ```
//! (exact Hessian, `kkt::ActiveSetKkt`), accepted only if the full KKT residual falls below
//! `tol`; quadratic convergence on the right active set, an early exit on a wrong one.

use super::{residual, Evals, PrimalDual, SqpInfo, SqpSolver};
use crate::mpc::kkt::ActiveSetKkt;
use nalgebra::DVector;

impl SqpSolver {
    /// Newton's method on the KKT conditions with the active set guessed from (z, ν).
    ///
    /// The guess is `A = {r : ν_r > slack_r}`. Near a weakly active row the interior-point
    /// QP returns ν_r ≈ slack_r ≈ √(gap) and the guess is a coin toss, so if it fails the
    /// polish is retried with the ambiguous rows (ν_r and slack_r both ≤ 1e-4, scaled)
    /// added, then removed.
    pub(super) fn polish(
        &mut self,
        xs: &[f64],
        start: &PrimalDual,
        info: &mut SqpInfo,
    ) -> Option<PrimalDual> {
        let ocp = &self.ocp;
        let nu_scale = start.nu.iter().fold(1.0f64, |m, v| m.max(v.abs()));
        let guess: Vec<usize> = (0..ocp.rows.len())
            .filter(|&r| start.nu[r] > ocp.rows[r].slack(&start.z).max(0.0))
            .collect();
        let ambiguous: Vec<usize> = (0..ocp.rows.len())
            .filter(|&r| {
                start.nu[r].abs() <= 1e-4 * nu_scale
                    && ocp.rows[r].slack(&start.z).abs() <= 1e-4 * (1.0 + ocp.rows[r].rhs.abs())
            })
            .collect();
        let found = self.polish_on(xs, start, guess.clone(), info);
        if found.is_none() {
            // The failed Newton iterates moved the linearisation of nonlinear rows.
            self.ocp.relinearize(&start.z);
        }
        if let Some(p) = found {
            return Some(p);
        }
        if ambiguous.is_empty() {
            return None;
        }
        let mut with: Vec<usize> = guess.iter().chain(&ambiguous).copied().collect();
        with.sort_unstable();
        with.dedup();
        if with != guess {
            if let Some(p) = self.polish_on(xs, start, with, info) {
                return Some(p);
            }
            self.ocp.relinearize(&start.z);
        }
        let without: Vec<usize> = guess
            .iter()
            .copied()
            .filter(|r| !ambiguous.contains(r))
            .collect();
        if without != guess {
            let p = self.polish_on(xs, start, without, info);
            if p.is_none() {
                self.ocp.relinearize(&start.z);
            }
            return p;
        }
        None
    }

    /// Newton's method on the KKT conditions with the active set `active`.
    fn polish_on(
        &mut self,
        xs: &[f64],
        start: &PrimalDual,
        mut active: Vec<usize>,
        info: &mut SqpInfo,
    ) -> Option<PrimalDual> {
        let mut p = start.clone();
        let mut ev = Evals::new(&self.ocp);
        let mut last = f64::INFINITY;
        let mut drops = 0;
        let mut it = 0;
        // The factorisation of the last iteration: its ordering and storage are reused while
        // the active set stays (and the ordering kept for the sensitivity's, see
        // `SqpSolver::active_set_kkt`).
        let mut fact: Option<ActiveSetKkt> = None;
        while it < 8 {
            self.ocp.relinearize(&p.z);
            let ocp = &self.ocp;
            ev.first_order(ocp, &p.z, xs);
            let res = residual(ocp, &p.z, &ev, &p.lam, &p.nu);
            if res.max() <= self.settings.tol {
                info.kkt = res;
                info.polished = true;
                self.polish_layout = fact.map(|k| k.layout().clone());
                return Some(p);
            }
            // Newton on the right active set converges quadratically; anything else is a
            // wrong guess: give up early and let SQP continue.
            if it >= 2 && res.max() > 0.25 * last {
                return None;
            }
            last = res.max();
            ocp.hessian_blocks(&p.z, &p.lam, &p.nu, &mut ev.hess);
            let kkt = match fact.as_mut() {
                Some(k) if k.active == active => {
                    k.refactor(ocp, &ev.hess, &ev.jac_x, &ev.jac_u);
                    k
                }
                _ => fact.insert(ActiveSetKkt::new(
                    ocp,
                    &ev.hess,
                    &ev.jac_x,
                    &ev.jac_u,
                    active.clone(),
                )),
            };
            let (nv, ne) = (ocp.n_var, ocp.n_eq);
            let mut rhs = DVector::zeros(nv + ne + active.len());
            for i in 0..nv {
                rhs[i] = -ev.grad[i];
            }
            for i in 0..ne {
                rhs[nv + i] = -ev.c[i];
            }
            for (t, &r) in active.iter().enumerate() {
                rhs[nv + ne + t] = ocp.rows[r].slack(&p.z);
            }
            let Some(sol) = kkt.solve(&rhs) else {
                // Singular: LICQ fails when an active row is implied by others (e.g. a
                // state bound reached exactly by saturated inputs: v₀ + h·Σu = v_max on a
                // lattice point). Drop the active row with the smallest multiplier whose
                // removal makes the system regular (a row outside the dependent set does
                // not; dropping it would only lose the right active set), else the
                // smallest; the Newton point still has to satisfy every dropped row to
                // pass the residual check.
                drops += 1;
                if drops > 8 || active.is_empty() {
                    return None;
                }
                let mut order: Vec<usize> = (0..active.len()).collect();
                order.sort_by(|&a, &b| {
                    start.nu[active[a]]
                        .total_cmp(&start.nu[active[b]])
                        .then(a.cmp(&b))
                });
                let regular = order.iter().copied().find(|&k| {
                    let mut fewer = active.clone();
                    fewer.remove(k);
                    let mut b = rhs.clone();
                    let keep: Vec<usize> = (0..b.len()).filter(|&i| i != nv + ne + k).collect();
                    b = b.select_rows(&keep);
                    ActiveSetKkt::new(ocp, &ev.hess, &ev.jac_x, &ev.jac_u, fewer)
                        .solve(&b)
                        .is_some()
                });
                active.remove(regular.unwrap_or(order[0]));
                continue;
            };
            it += 1;
            info.iterations += 1;
            for i in 0..nv {
                p.z[i] += sol[i];
            }
            for i in 0..ne {
                p.lam[i] = sol[nv + i];
            }
            p.nu.fill(0.0);
            for (t, &r) in active.iter().enumerate() {
                p.nu[r] = sol[nv + ne + t];
            }
        }
        self.ocp.relinearize(&p.z);
        ev.first_order(&self.ocp, &p.z, xs);
        let res = residual(&self.ocp, &p.z, &ev, &p.lam, &p.nu);
        if res.max() <= self.settings.tol {
            info.kkt = res;
            info.polished = true;
            self.polish_layout = fact.map(|k| k.layout().clone());
            Some(p)
        } else {
            None
        }
    }
}
