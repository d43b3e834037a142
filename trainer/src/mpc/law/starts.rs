//! Multi-start labels: the hard OCP at x_s solved from each initial guess of
//! `solver.starts`, and the label of the lowest-cost hard optimum kept:
//! ```text
//! κ(x_s) = u₀ of z*_s*,   s* = the first s in starts with J(z*_s) < J(z*_t) − τ·max(1, |J(z*_t)|)
//!                              for no earlier t        (τ = TIE_TOL = 1e-8; z*_s converged hard KKT points)
//! ```
//! The SQP is a local solver: on a non-convex OCP (nonlinear dynamics or nonlinear
//! constraints) different guesses can end in different local optima, and the label should
//! come from the best one found. A convex OCP (affine dynamics, no nonlinear constraint,
//! positive definite weights) has one optimum, so it is solved from one start whatever
//! `starts` lists ([`MpcLaw::starts`]).
//!
//! **Branch.** The list order breaks ties (costs within [`TIE_TOL`]): the default lists
//! `warm` first, so among equal costs the label continues the branch of the nearest labelled
//! neighbour (the previous state of the chunk) — a set-valued law resolved by continuation.
//!
//! **Disagreement.** Two hard optima are distinct when their costs differ by more than
//! [`OPTIMA_TOL`]·max(1, |J|) and their u₀ by more than [`OPTIMA_TOL`]·max(1, |u₀|);
//! [`Label::optima`] counts the distinct optima the starts reached (2 or more: the starts
//! disagree). Only the `warm` start climbs the retry ladder and has the soft fallback; the
//! other starts are one plain hard SQP solve each. If no start reaches a hard optimum the
//! label is that of `warm` ([`MpcLaw::solve_single`], today's solve; run even when not
//! listed). [`MpcLaw::solve`] is this law (without the `neighbour` start, which needs the
//! labelled states of a chunk).

use super::{Label, MpcLaw, Retry};
use crate::mpc::sqp::{Globalisation, PrimalDual, SqpStatus};
use crate::problem::solver::Start;
use nalgebra::DMatrix;

/// Relative cost difference below which two starts tie (the earlier one is kept): one
/// optimum reached from two starts differs in cost by ~1e-9 relative at `solver.tol` = 1e-8
/// (measured on the pendulum), so a smaller tie would switch labels for nothing.
pub const TIE_TOL: f64 = 1e-8;
/// Relative cost and u₀ difference above which two hard optima are distinct.
pub const OPTIMA_TOL: f64 = 1e-6;

/// The solution of the state of `done` nearest to `xs` in the distance scaled by `scale`
/// (per coordinate; the domain's widths), the earliest on ties.
pub fn nearest<'a>(
    done: &'a [(Vec<f64>, PrimalDual)],
    xs: &[f64],
    scale: &[f64],
) -> Option<&'a PrimalDual> {
    let d = |x: &[f64]| -> f64 {
        x.iter()
            .zip(xs)
            .zip(scale)
            .map(|((a, b), s)| {
                let s = if s.is_finite() && *s > 0.0 { *s } else { 1.0 };
                ((a - b) / s).powi(2)
            })
            .sum()
    };
    let mut best: Option<(f64, &PrimalDual)> = None;
    for (x, p) in done {
        let v = d(x);
        if best.is_none_or(|(b, _)| v < b) {
            best = Some((v, p));
        }
    }
    best.map(|(_, p)| p)
}

/// Whether two hard optima (cost, u₀) are distinct ([`OPTIMA_TOL`]).
fn distinct(a: (f64, &[f64]), b: (f64, &[f64])) -> bool {
    let dc = (a.0 - b.0).abs() > OPTIMA_TOL * a.0.abs().max(b.0.abs()).max(1.0);
    let du =
        a.1.iter()
            .zip(b.1)
            .any(|(x, y)| (x - y).abs() > OPTIMA_TOL * x.abs().max(y.abs()).max(1.0));
    dc && du
}

impl MpcLaw {
    /// The starts this law solves from: `solver.starts` (or the problem's default,
    /// [`crate::problem::solver::default_starts`]) for a non-convex OCP, `["warm"]` for a
    /// convex one.
    pub fn starts(&self) -> &[Start] {
        &self.starts
    }

    /// Whether the hard OCP is convex: affine dynamics and no nonlinear constraint rows
    /// (the quadratic cost's weights are positive (semi)definite by validation).
    pub fn is_convex(&self) -> bool {
        self.cfg.system.is_affine() && !self.hard.ocp.has_nonlinear_rows()
    }

    /// The label of `xs` from every start (module doc). `warm` is the previous state's hard
    /// solution (the `warm` start, as in [`solve_single`](Self::solve_single)), `near` the nearest labelled
    /// state's (the `neighbour` start; skipped when absent). Returns the label and its hard
    /// solution (to warm-start the next state).
    pub fn solve_starts(
        &mut self,
        xs: &[f64],
        warm: Option<&PrimalDual>,
        near: Option<&PrimalDual>,
    ) -> (Label, Option<PrimalDual>) {
        if self.starts.len() <= 1 && self.starts.first().is_none_or(|s| *s == Start::Warm) {
            return self.solve_single(xs, warm);
        }
        let nx = self.hard.ocp.nx;
        let valid = xs.len() == nx && xs.iter().all(|v| v.is_finite());
        let mut best: Option<(Label, Option<PrimalDual>)> = None;
        let mut fallback: Option<(Label, Option<PrimalDual>)> = None;
        let mut optima: Vec<(f64, Vec<f64>)> = Vec::new();
        for s in self.starts.clone() {
            let (l, p) = if s == Start::Warm {
                self.solve_single(xs, warm)
            } else {
                let Some(guess) = valid.then(|| self.guess(s, xs, near)).flatten() else {
                    continue;
                };
                let r = self.hard.solve(xs, guess);
                if r.status != SqpStatus::Converged {
                    continue;
                }
                self.finish_with_point(&self.hard, xs, r, SqpStatus::Converged)
            };
            if l.status != SqpStatus::Converged {
                if s == Start::Warm {
                    fallback = Some((l, p));
                }
                continue;
            }
            if optima
                .iter()
                .all(|(c, u)| distinct((*c, u), (l.cost, &l.u)))
            {
                optima.push((l.cost, l.u.clone()));
            }
            let better = best
                .as_ref()
                .is_none_or(|(b, _)| l.cost < b.cost - TIE_TOL * b.cost.abs().max(1.0));
            if better {
                best = Some((l, p));
            }
        }
        let (mut l, p) = match (best, fallback) {
            (Some(b), _) => b,
            (None, Some(f)) => f,
            (None, None) => self.solve_single(xs, warm),
        };
        // (`info.iterations` stays that of the solve that produced the label.)
        l.optima = optima.len() as u32;
        (l, p)
    }

    /// Whether [`solve`](Self::solve) at `xs` (cold) labels it by a hard optimum (status
    /// `converged`), decided without solving more than needed: the `warm` start first — if
    /// it converges, so does the multi-start law, whose status is `converged` as soon as one
    /// start reaches a hard optimum (which one wins only decides the label, not the status)
    /// — and the other starts only when it does not. The same answer as
    /// `solve(xs, None).0.status == Converged`, at one solve where the first start converges.
    pub fn is_hard_feasible(&mut self, xs: &[f64]) -> bool {
        let (l, _) = self.solve_single(xs, None);
        if l.status == SqpStatus::Converged {
            return true;
        }
        let valid = xs.len() == self.hard.ocp.nx && xs.iter().all(|v| v.is_finite());
        for s in self.starts.clone() {
            // (As in `solve_starts`: a start without a guess is skipped, `neighbour` has none
            // here.)
            let Some(guess) = (s != Start::Warm && valid)
                .then(|| self.guess(s, xs, None))
                .flatten()
            else {
                continue;
            };
            let r = self.hard.solve(xs, guess);
            if r.status == SqpStatus::Converged
                && self.finish(&self.hard, xs, &r, SqpStatus::Converged).status
                    == SqpStatus::Converged
            {
                return true;
            }
        }
        false
    }

    /// The hard problem at `xs` warm-started from the solution of the hard problem at a
    /// neighbour `near` (solved here first), with the default then the conservative
    /// globalisation: the retry for a state that stayed unlabelled after [`solve`](Self::solve)
    /// once a neighbour has a label. `None` if either solve fails.
    pub fn solve_from_neighbour(&mut self, xs: &[f64], near: &[f64]) -> Option<Label> {
        let n = self.neighbour_solution(near)?;
        self.solve_from_solution(xs, &n)
    }

    /// The first half of [`solve_from_neighbour`](Self::solve_from_neighbour): the hard
    /// problem at `near` from its cold start, with the SQP iterations it took (`None`: not
    /// converged, or `near` not a finite state of length nx). A pure function of `near`
    /// (every SQP solve starts from the given point), so a caller that warm-starts several
    /// states from one neighbour may solve it once and keep it.
    pub fn neighbour_solution(&mut self, near: &[f64]) -> Option<(PrimalDual, usize)> {
        let nx = self.hard.ocp.nx;
        if near.len() != nx || near.iter().any(|v| !v.is_finite()) {
            return None;
        }
        let n = self.hard.solve(near, self.hard.cold_start(near));
        (n.status == SqpStatus::Converged).then_some((n.point, n.info.iterations))
    }

    /// The second half of [`solve_from_neighbour`](Self::solve_from_neighbour): the hard
    /// problem at `xs` warm-started from a neighbour's solution `n` (of
    /// [`neighbour_solution`](Self::neighbour_solution)) with x₀ replaced by `xs`, default
    /// then conservative globalisation.
    pub fn solve_from_solution(&mut self, xs: &[f64], n: &(PrimalDual, usize)) -> Option<Label> {
        let nx = self.hard.ocp.nx;
        if xs.len() != nx || xs.iter().any(|v| !v.is_finite()) {
            return None;
        }
        let mut spent = n.1;
        for g in [Globalisation::Default, Globalisation::Conservative] {
            let mut start = n.0.clone();
            start.z[..nx].copy_from_slice(xs);
            self.hard.set_globalisation(g);
            let r = self.hard.solve(xs, start);
            self.hard.set_globalisation(Globalisation::Default);
            spent += r.info.iterations;
            if r.status == SqpStatus::Converged {
                let mut l = self.finish(&self.hard, xs, &r, SqpStatus::Converged);
                if !l.status.is_labelled() {
                    // The gate refused the numbers (crate::mpc::finite).
                    return None;
                }
                l.info.iterations = spent;
                l.retry = Some(Retry::Neighbour);
                return Some(l);
            }
        }
        None
    }

    /// The initial guess of start `s` at `xs` (`None`: the start does not apply, e.g. no
    /// neighbour yet, or no LQR gain).
    fn guess(&mut self, s: Start, xs: &[f64], near: Option<&PrimalDual>) -> Option<PrimalDual> {
        let ocp = &self.hard.ocp;
        let (nx, nu, n) = (ocp.nx, ocp.nu, ocp.horizon);
        let u_set: Vec<f64> = (0..nu)
            .map(|j| ocp.u_ref[j].clamp(self.cfg.ocp.u_lo[j], self.cfg.ocp.u_hi[j]))
            .collect();
        let mut z = vec![0.0; ocp.n_var];
        match s {
            Start::Warm => return None,
            Start::Barrier => return self.barrier_guess(xs),
            Start::Neighbour => {
                let mut p = near?.clone();
                p.z[..nx].copy_from_slice(xs);
                return Some(p);
            }
            Start::Zero | Start::RepeatX0 => {
                for k in 0..=n {
                    let x = if k == 0 || s == Start::RepeatX0 {
                        xs
                    } else {
                        &ocp.x_ref[..]
                    };
                    z[ocp.ix(k)..ocp.ix(k) + nx].copy_from_slice(x);
                    if k < n {
                        z[ocp.iu(k)..ocp.iu(k) + nu].copy_from_slice(&u_set);
                    }
                }
            }
            Start::ULo | Start::UHi => {
                let u: Vec<f64> = match s {
                    Start::ULo => self.cfg.ocp.u_lo.clone(),
                    _ => self.cfg.ocp.u_hi.clone(),
                };
                if u.iter().any(|v| !v.is_finite()) {
                    return None;
                }
                self.rollout(xs, &mut z, |_, _, out| out.copy_from_slice(&u));
            }
            Start::Lqr => {
                if self.lqr.is_none() {
                    self.lqr = Some(self.lqr_gains());
                }
                let gains = self.lqr.clone().flatten()?;
                let (xr, ur) = (ocp.x_ref.clone(), ocp.u_ref.clone());
                self.rollout(xs, &mut z, |k, x, u| {
                    for (j, uj) in u.iter_mut().enumerate() {
                        *uj = ur[j];
                        for (i, (xi, ri)) in x.iter().zip(&xr).enumerate() {
                            *uj -= gains[k][(j, i)] * (xi - ri);
                        }
                    }
                });
            }
        }
        Some(PrimalDual {
            z,
            lam: vec![0.0; self.hard.ocp.n_eq],
            nu: vec![0.0; self.hard.ocp.rows.len()],
        })
    }

    /// Fills `z` with the rollout from `xs` of the input `law(k, x_k, u_k)`, clamped to the
    /// input bounds (states clamped to the state bounds, a non-finite step keeps x_k).
    pub(super) fn rollout(
        &self,
        xs: &[f64],
        z: &mut [f64],
        law: impl Fn(usize, &[f64], &mut [f64]),
    ) {
        let ocp = &self.hard.ocp;
        let (nx, nu) = (ocp.nx, ocp.nu);
        let (mut x, mut xn, mut u) = (xs.to_vec(), vec![0.0; nx], vec![0.0; nu]);
        z[..nx].copy_from_slice(xs);
        for k in 0..ocp.horizon {
            law(k, &x, &mut u);
            let iu = ocp.iu(k);
            for j in 0..nu {
                let v = if u[j].is_finite() { u[j] } else { 0.0 };
                z[iu + j] = v.clamp(self.cfg.ocp.u_lo[j], self.cfg.ocp.u_hi[j]);
            }
            ocp.model.step(&x, &z[iu..iu + nu], &mut xn);
            let ix = ocp.ix(k + 1);
            for i in 0..nx {
                let v = if xn[i].is_finite() { xn[i] } else { x[i] };
                x[i] = v.clamp(self.cfg.ocp.x_lo[i], self.cfg.ocp.x_hi[i]);
                z[ix + i] = x[i];
            }
        }
    }

    /// The finite-horizon LQR gains K_0..K_{N−1} of the linearisation (A, B) at the setpoint:
    /// P_N = P, K_k = (R + BᵀP_{k+1}B)⁻¹BᵀP_{k+1}A, P_k = Q + AᵀP_{k+1}(A − BK_k).
    /// `None` if the linearisation is not finite or R + BᵀPB is singular.
    fn lqr_gains(&self) -> Option<Vec<DMatrix<f64>>> {
        let ocp = &self.hard.ocp;
        let (nx, nu) = (ocp.nx, ocp.nu);
        let (mut f, mut jx, mut ju) = (vec![0.0; nx], vec![0.0; nx * nx], vec![0.0; nx * nu]);
        ocp.model
            .linearize(&ocp.x_ref, &ocp.u_ref, &mut f, &mut jx, &mut ju);
        if jx.iter().chain(&ju).any(|v| !v.is_finite()) {
            return None;
        }
        let a = DMatrix::from_row_slice(nx, nx, &jx);
        let b = DMatrix::from_row_slice(nx, nu, &ju);
        let (q, r) = (self.cfg.q(), self.cfg.r());
        let mut p = self.cfg.p();
        let mut gains = vec![DMatrix::zeros(nu, nx); ocp.horizon];
        for k in (0..ocp.horizon).rev() {
            let bp = b.transpose() * &p;
            let k_gain = (&r + &bp * &b).try_inverse()? * (&bp * &a);
            p = &q + a.transpose() * &p * (&a - &b * &k_gain);
            p = (&p + p.transpose()) * 0.5;
            if k_gain.iter().any(|v| !v.is_finite()) {
                return None;
            }
            gains[k] = k_gain;
        }
        Some(gains)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::problem::ProblemConfig;

    fn swingup() -> ProblemConfig {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../tests/reference/cartpole_swingup.toml"
        );
        ProblemConfig::load(std::path::Path::new(path)).unwrap_or_else(|e| panic!("{e}"))
    }

    /// States of the acados cart-pole swing-up (`tests/reference/cartpole_swingup.toml`;
    /// `ipopt_compare.py --n 60 --seed 7`, states 6 and 29) where the single (cold) start
    /// ends in a local optimum of much higher cost than IPOPT's (tol 1e-10, started from
    /// u = 0 and x₀ repeated; the costs below), and the default starts reach IPOPT's
    /// optimum: the label's cost is ≤ IPOPT's (1e-7 relative), the starts disagree, and the
    /// label is a converged hard KKT point with a finite sensitivity.
    #[test]
    fn starts_reach_ipopts_optimum_where_one_start_does_not() {
        let cfg = swingup();
        let cases = [
            (
                [
                    -0.9286394424528077,
                    0.09354921677031136,
                    -0.1351758986988436,
                    3.337342185542818,
                ],
                1774.41348658631,
            ),
            (
                [
                    0.6210536606344903,
                    -2.2822787743870934,
                    -0.3243853963472594,
                    2.522050223960365,
                ],
                1020.3917968530036,
            ),
        ];
        let mut law = MpcLaw::new(&cfg);
        assert!(!law.is_convex());
        // The default starts, decided by the pilot: the swing-up's extra starts matter.
        assert_eq!(law.starts(), super::super::pilot::extra_starts().as_slice());
        let pilot = super::super::pilot::pilot(&cfg);
        assert!(pilot.disagreed + pilot.rescued > 0, "{pilot:?}");
        for (x, ipopt) in cases {
            let (single, _) = law.solve_single(&x, None);
            let (l, sol) = law.solve(&x, None);
            eprintln!(
                "{x:?}: single {} starts {} IPOPT {ipopt}",
                single.cost, l.cost
            );
            assert_eq!(single.status, SqpStatus::Converged);
            assert!(single.cost > 1.5 * ipopt, "single start {}", single.cost);
            assert_eq!(l.status, SqpStatus::Converged);
            assert!(
                l.cost <= ipopt * (1.0 + 1e-7),
                "{} vs IPOPT {ipopt}",
                l.cost
            );
            assert!(l.optima >= 2, "{}", l.optima);
            let sol = sol.expect("a hard label returns its point");
            let res = law.hard_solver().kkt_residual(&x, &sol);
            assert!(res.max() <= cfg.solver.tol, "{res:?}");
            assert!(l.du_dx.iter().all(|v| v.is_finite()));
        }
    }

    /// Two swing-up states (`ipopt_compare.py --n 60 --seed 5`) whose optimum has input
    /// bounds active where the dynamics' null space is indefinite: with the blockwise
    /// Gauss–Newton rule every start but one crawled to the iteration limit and the label
    /// cost 1.12× and 3.1× IPOPT's (2715.29 against 2415.25, 2944.03 against 949.70). With
    /// the bound curvature (`sqp` module doc, step 2) the plain hard SQP from the `zero`
    /// guess (it too stopped at the limit before) converges to IPOPT's optimum at both, and
    /// the label is no worse than IPOPT's (1e-7 relative).
    #[test]
    fn bound_curvature_reaches_ipopts_optimum_where_gauss_newton_stalled() {
        let cfg = swingup();
        let cases = [
            (
                [
                    0.6124306620540871,
                    -1.1532655475835905,
                    -1.4038456658657767,
                    1.5880959225464863,
                ],
                2415.2496754681647,
            ),
            (
                [
                    0.9833534339803927,
                    1.4053993567868428,
                    1.2353752361386796,
                    -2.777079814834617,
                ],
                949.6974374149386,
            ),
        ];
        let mut law = MpcLaw::new(&cfg);
        for (x, ipopt) in cases {
            let guess = law.guess(Start::Zero, &x, None).expect("a guess");
            let r = law.hard.solve(&x, guess);
            assert_eq!(r.status, SqpStatus::Converged, "{x:?}: {:?}", r.info);
            let cost = law.hard.ocp.objective(&r.point.z);
            assert!(
                (cost - ipopt).abs() <= 1e-7 * ipopt,
                "{cost} vs IPOPT {ipopt}"
            );
            let (l, _) = law.solve(&x, None);
            assert_eq!(l.status, SqpStatus::Converged);
            assert!(
                l.cost <= ipopt * (1.0 + 1e-7),
                "{} vs IPOPT {ipopt}",
                l.cost
            );
        }
    }

    /// A convex OCP (the double integrator: affine plant, box constraints) is solved from one
    /// start whatever `solver.starts` lists, bit for bit today's label; a non-convex one
    /// honours the list, and `["warm"]` alone is today's solve.
    #[test]
    fn convex_problems_use_one_start_and_warm_alone_is_todays_solve() {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../configs/double_integrator.toml"
        );
        let mut cfg = ProblemConfig::load(std::path::Path::new(path)).unwrap();
        cfg.solver.starts = Some(vec![Start::Warm, Start::Zero, Start::Lqr]);
        let mut law = MpcLaw::new(&cfg);
        assert!(law.is_convex());
        assert_eq!(law.starts(), &[Start::Warm]);
        let x = [0.7, -0.3];
        assert_eq!(law.solve(&x, None), law.solve_single(&x, None));
        let mut cfg = swingup();
        cfg.solver.starts = Some(vec![Start::Warm]);
        let mut law = MpcLaw::new(&cfg);
        let x = [0.1, 2.0, 0.0, 0.0];
        let (a, pa) = law.solve(&x, None);
        let (b, pb) = law.solve_single(&x, None);
        assert_eq!((a, pa), (b, pb));
    }

    /// `is_hard_feasible` is `solve(x, None).0.status == Converged`, state by state: the
    /// pendulum's grid over X (its hard-infeasible corners included) and random swing-up
    /// states (three starts).
    #[test]
    fn hard_feasibility_is_the_multi_start_status() {
        let pendulum = ProblemConfig::default();
        let mut cases: Vec<(ProblemConfig, Vec<f64>)> = Vec::new();
        for i in 0..=12 {
            for j in 0..=6 {
                let (lo, hi) = (&pendulum.domain.lo, &pendulum.domain.hi);
                let x = vec![
                    lo[0] + (hi[0] - lo[0]) * i as f64 / 12.0,
                    lo[1] + (hi[1] - lo[1]) * j as f64 / 6.0,
                ];
                cases.push((pendulum.clone(), x));
            }
        }
        let swing = swingup();
        for i in 0..12u64 {
            let (lo, hi) = (&swing.domain.lo, &swing.domain.hi);
            let x = (0..4)
                .map(|k| lo[k] + (hi[k] - lo[k]) * crate::rng::uniform(5, i, k as u64))
                .collect();
            cases.push((swing.clone(), x));
        }
        let (mut feasible, mut infeasible) = (0, 0);
        for (cfg, x) in &cases {
            let expected = MpcLaw::new(cfg).solve(x, None).0.status == SqpStatus::Converged;
            assert_eq!(MpcLaw::new(cfg).is_hard_feasible(x), expected, "{x:?}");
            if expected {
                feasible += 1;
            } else {
                infeasible += 1;
            }
        }
        assert!(feasible > 0 && infeasible > 0, "{feasible} / {infeasible}");
    }

    /// A neighbour's solution solved once and reused (the per-cell check's cache) gives
    /// each state the label `solve_from_neighbour` gives it on a fresh law — also after
    /// other solves on the same law in between (every SQP solve starts from its given point).
    #[test]
    fn neighbour_solution_reused_is_the_one_call_label() {
        let cfg = ProblemConfig::default();
        let near = [0.5, 0.2];
        let mut law = MpcLaw::new(&cfg);
        let n = law.neighbour_solution(&near).expect("the corner converges");
        let mut labelled = 0;
        for x in [[0.55, 0.25], [0.45, 0.1], [3.0, -0.9], [0.6, 0.3]] {
            let want = MpcLaw::new(&cfg).solve_from_neighbour(&x, &near);
            let _ = law.solve(&[-2.0, 0.7], None);
            let got = law.solve_from_solution(&x, &n);
            assert_eq!(got, want, "{x:?}");
            labelled += got.is_some() as usize;
        }
        assert!(labelled >= 3, "{labelled}");
        assert_eq!(law.neighbour_solution(&[f64::NAN, 0.0]), None);
        assert_eq!(law.neighbour_solution(&[0.0]), None);
    }

    /// `solver.starts` is validated: empty or repeated lists are errors naming the key.
    #[test]
    fn bad_start_lists_are_refused() {
        let text = std::fs::read_to_string(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../tests/reference/cartpole_swingup.toml"
        ))
        .unwrap();
        for (list, why) in [("[]", "at least one"), ("[\"zero\", \"zero\"]", "twice")] {
            let t = text.replace(
                "[sampling]",
                &format!("[solver]\nstarts = {list}\n\n[sampling]"),
            );
            let e = ProblemConfig::from_toml_str(&t, "p.toml")
                .unwrap_err()
                .to_string();
            assert!(e.contains("solver.starts") && e.contains(why), "{e}");
        }
        let t = text.replace("[sampling]", "[solver]\nstarts = [\"best\"]\n\n[sampling]");
        assert!(ProblemConfig::from_toml_str(&t, "p.toml").is_err());
    }
}
