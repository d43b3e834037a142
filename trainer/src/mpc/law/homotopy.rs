//! The `barrier` start: a barrier homotopy on the input bounds, the path of an
//! interior-point method (issue 43 §1):
//! ```text
//! z⁰ = the rollout from x_s of u = c (the middle of the input box),  μ_0 = MU0_REL·max(1, |J(z⁰)|)/(N·n_b)
//! z^{i+1} = SQP(OCP_μi(x_s), from z^i),   μ_{i+1} = MU_FACTOR·μ_i,   i = 0..LEVELS−1
//! OCP_μ:  the OCP with the input bounds u_lo ≤ u_k ≤ u_hi replaced by the log barrier B_μ
//! guess = z^LEVELS                                     (n_b: the finite input bounds)
//! ```
//! (`B_μ` of [`crate::mpc::ocp::InputBarrier`].) The true OCP is then solved from the guess
//! like from any other start. In the barrier solves the QP's input rows are moved out of
//! reach (to h + WIDEN·max(1, |h|)): the step is the Newton step of the barrier problem, as
//! in an interior-point method, and the barrier alone keeps the inputs inside their box (the
//! line search rejects a trial point on or beyond a bound, where B_μ = +∞). The SQP's own
//! first QPs put the inputs of a bang-bang-like problem (the swing-up's tiny R) on their
//! bounds at once, and from there it often ends in a worse local optimum than IPOPT's;
//! the barrier path reaches IPOPT's optimum at more states (BENCHMARKS.md, "Multi-start
//! labels"). `None` (the start does not apply) when no input bound is finite or a barrier
//! solve does not converge; the hard solver's OCP is the true one again on return.
//!
//! The constants were chosen on the acados cart-pole swing-up
//! (`tests/reference/cartpole_swingup.toml`, `ipopt_compare.py` seeds 2, 3, 8): a slower
//! decrease (0.3 rather than 0.1) over 8 levels reached IPOPT's optimum where 3 levels of 0.1
//! did not.

use super::MpcLaw;
use crate::mpc::ocp::InputBarrier;
use crate::mpc::sqp::{PrimalDual, SqpStatus};

/// μ_0 relative to the guess's cost per barrier term.
pub const MU0_REL: f64 = 0.1;
/// The ratio of successive barrier weights.
pub const MU_FACTOR: f64 = 0.3;
/// Barrier solves.
pub const LEVELS: usize = 8;
/// How far (relative to max(1, |h|)) the input rows `u ≤ h` are moved during barrier solves.
const WIDEN: f64 = 10.0;

impl MpcLaw {
    /// The guess of the `barrier` start at `xs` (module doc).
    pub(super) fn barrier_guess(&mut self, xs: &[f64]) -> Option<PrimalDual> {
        let (lo, hi) = (self.cfg.ocp.u_lo.clone(), self.cfg.ocp.u_hi.clone());
        let nb = lo.iter().chain(&hi).filter(|v| v.is_finite()).count();
        if nb == 0 {
            return None;
        }
        let centre: Vec<f64> = lo
            .iter()
            .zip(&hi)
            .zip(&self.hard.ocp.u_ref)
            .map(|((&l, &h), &r)| match (l.is_finite(), h.is_finite()) {
                (true, true) => 0.5 * (l + h),
                (true, false) => r.max(l + l.abs().max(1.0)),
                (false, true) => r.min(h - h.abs().max(1.0)),
                (false, false) => r,
            })
            .collect();
        let mut z = vec![0.0; self.hard.ocp.n_var];
        self.rollout(xs, &mut z, |_, _, u| u.copy_from_slice(&centre));
        let n = (self.hard.ocp.horizon * nb) as f64;
        let mu0 = MU0_REL * self.hard.ocp.objective(&z).abs().max(1.0) / n;
        if !mu0.is_finite() {
            return None;
        }
        let p = PrimalDual {
            z,
            lam: vec![0.0; self.hard.ocp.n_eq],
            nu: vec![0.0; self.hard.ocp.rows.len()],
        };
        let saved = self.widen_input_rows(&lo, &hi);
        let out = self.barrier_path(xs, p, mu0, &lo, &hi);
        for (i, h) in saved {
            self.hard.ocp.rows[i].rhs = h;
        }
        self.hard.ocp.barrier = None;
        out
    }

    /// Moves the input-box rows (`u_k,j ≤ hi_j`, `−u_k,j ≤ −lo_j`: the bounds the barrier
    /// replaces) of the hard OCP out of reach (module doc); returns their indices and previous
    /// right-hand sides. (Other rows are untouched: `[ocp] constraints` and tightened input
    /// bounds stay, and nonlinear rows are relinearised by every solve.)
    fn widen_input_rows(&mut self, lo: &[f64], hi: &[f64]) -> Vec<(usize, f64)> {
        let ocp = &mut self.hard.ocp;
        let (nx, nz, n) = (ocp.nx, ocp.nx + ocp.nu, ocp.horizon);
        let mut saved = Vec::new();
        for (k, r) in ocp.rows.iter_mut().enumerate() {
            let i = r.idx[0];
            let on_input = r.len == 1 && i < n * nz && i % nz >= nx;
            let boxed = on_input && {
                let j = i % nz - nx;
                (r.coef[0] == 1.0 && r.rhs == hi[j]) || (r.coef[0] == -1.0 && r.rhs == -lo[j])
            };
            if boxed {
                saved.push((k, r.rhs));
                r.rhs += WIDEN * r.rhs.abs().max(1.0);
            }
        }
        saved
    }

    /// The barrier solves from `p` at μ_0 = `mu0`, decreasing (module doc).
    fn barrier_path(
        &mut self,
        xs: &[f64],
        mut p: PrimalDual,
        mu0: f64,
        lo: &[f64],
        hi: &[f64],
    ) -> Option<PrimalDual> {
        let mut mu = mu0;
        for _ in 0..LEVELS {
            self.hard.ocp.barrier = Some(InputBarrier {
                mu,
                lo: lo.to_vec(),
                hi: hi.to_vec(),
            });
            let r = self.hard.solve(xs, p);
            if r.status != SqpStatus::Converged {
                return None;
            }
            p = r.point;
            mu *= MU_FACTOR;
        }
        // The multipliers of the widened rows mean nothing for the true OCP.
        p.nu.fill(0.0);
        Some(p)
    }
}

#[cfg(test)]
mod tests {
    use crate::mpc::law::MpcLaw;
    use crate::mpc::sqp::SqpStatus;
    use crate::problem::solver::{default_starts, Start};
    use crate::problem::ProblemConfig;

    /// States of the acados cart-pole swing-up (`ipopt_compare.py --n 60 --seed 8`, states
    /// 20 and 29) where the default starts (warm, u_lo, u_hi) end in a local optimum of
    /// higher cost than IPOPT's (tol 1e-10, the costs below), and adding the `barrier` start
    /// reaches IPOPT's optimum: the label's cost is ≤ IPOPT's (1e-7 relative), the barrier
    /// start alone gives that optimum, the label is a converged hard KKT point, and the
    /// hard solver is the true OCP again afterwards (a fresh law's solve is unchanged).
    #[test]
    fn barrier_start_reaches_ipopts_optimum_where_the_default_starts_do_not() {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../tests/reference/cartpole_swingup.toml"
        );
        let cfg = ProblemConfig::load(std::path::Path::new(path)).unwrap();
        let cases = [
            (
                [
                    0.47915029331272097,
                    -1.1878827364271054,
                    -0.7741733268303763,
                    2.2569094897313793,
                ],
                1794.3849994804718,
            ),
            (
                [
                    0.22042471788796103,
                    1.2418245917824065,
                    0.7465729178773541,
                    -1.9693192359353322,
                ],
                1723.0694466391672,
            ),
        ];
        let mut plain = MpcLaw::with_starts(&cfg, default_starts(false));
        // The start by its name in a problem file.
        let text = std::fs::read_to_string(path).unwrap().replace(
            "[sampling]",
            "[solver]\nstarts = [\"warm\", \"u_lo\", \"u_hi\", \"barrier\"]\n\n[sampling]",
        );
        let listed = ProblemConfig::from_toml_str(&text, "p.toml").unwrap();
        let mut law = MpcLaw::new(&listed);
        let mut with = default_starts(false);
        with.push(Start::Barrier);
        assert_eq!(law.starts(), with.as_slice());
        let mut alone = MpcLaw::with_starts(&cfg, vec![Start::Barrier]);
        for (x, ipopt) in cases {
            let (p, _) = plain.solve(&x, None);
            assert!(p.cost > ipopt * 1.1, "default starts {}", p.cost);
            let (l, sol) = law.solve(&x, None);
            assert_eq!(l.status, SqpStatus::Converged);
            assert!(l.cost <= ipopt * (1.0 + 1e-7), "{} vs {ipopt}", l.cost);
            assert!(l.optima >= 2, "{}", l.optima);
            let sol = sol.expect("a hard label returns its point");
            assert!(law.hard_solver().kkt_residual(&x, &sol).max() <= cfg.solver.tol);
            let (a, _) = alone.solve(&x, None);
            assert!(
                (a.cost - l.cost).abs() <= 1e-7 * l.cost,
                "{} {}",
                a.cost,
                l.cost
            );
            assert!(law.hard_solver().ocp.barrier.is_none());
            let fresh = MpcLaw::with_starts(&cfg, vec![Start::Warm]).solve_single(&x, None);
            assert_eq!(law.solve_single(&x, None), fresh);
        }
    }
}
