//! Proof that a box of states excluded from the certified domain is infeasible for the
//! tightened OCP (so Corollary 1 needs no ε there): an outer bound of the one-step reach
//!
//! ```text
//! R(B) = { F(x, u) : x ∈ B, u ∈ U_0 } ⊆ Π_i [f_i − r_i, f_i + r_i],
//! f = F(c, c_u),   r_i = Σ_j Ā_ij h_j + Σ_j B̄_ij g_j   (c, h: B's centre and half-widths;
//!                                                        c_u, g: U_0's)
//! ```
//! by the mean-value theorem with Ā_ij ≥ |∂F_i/∂x_j|, B̄_ij ≥ |∂F_i/∂u_j| everywhere (the
//! entrywise maximum over the Jacobian family of `jacobians`; sound when the family is
//! exact — linear plants — or a vertex enumeration — the pendulum —, never for a sampled
//! family). If for some i the interval misses the tightened state bounds of stage 1,
//! [x_lo,1,i, x_hi,1,i], no input of U_0 keeps x_1 feasible: the hard tightened OCP is
//! infeasible at every state of B. The rounding of F(c, c_u) and of the sums is covered by a
//! relative 10⁻¹² of (1 + |f_i| + r_i) (the evaluation is a few dozen operations, each
//! within 2⁻⁵³ of its magnitude). A box this test cannot decide is not proven: the verdict
//! lists it as an assumption.

use super::jacobians::{JacobianBound, JacobianSet};
use crate::problem::model::Discrete;
use crate::problem::{ProblemConfig, StageBounds};

/// Whether the box [lo, hi] is proven infeasible for the tightened OCP with `stages`
/// (module doc).
pub fn infeasible_by_reach(
    cfg: &ProblemConfig,
    stages: &StageBounds,
    js: &JacobianSet,
    lo: &[f64],
    hi: &[f64],
) -> bool {
    if js.bound == JacobianBound::SampledEstimate || js.a.is_empty() {
        return false;
    }
    let (Some(xl), Some(xh), Some(ul), Some(uh)) = (
        stages.x_lo.first(),
        stages.x_hi.first(),
        stages.u_lo.first(),
        stages.u_hi.first(),
    ) else {
        return false;
    };
    let model = Discrete::new(cfg.system.clone(), cfg.ocp.ts, cfg.ocp.rk4_substeps);
    let (nx, nu) = (model.nx(), model.nu());
    if lo.len() != nx || hi.len() != nx || ul.len() != nu || uh.len() != nu {
        return false;
    }
    let c: Vec<f64> = lo.iter().zip(hi).map(|(a, b)| 0.5 * (a + b)).collect();
    let h: Vec<f64> = lo.iter().zip(hi).map(|(a, b)| 0.5 * (b - a)).collect();
    let cu: Vec<f64> = ul.iter().zip(uh).map(|(a, b)| 0.5 * (a + b)).collect();
    let g: Vec<f64> = ul.iter().zip(uh).map(|(a, b)| 0.5 * (b - a)).collect();
    if h.iter().chain(&g).any(|v| !(v.is_finite() && *v >= 0.0)) {
        return false;
    }
    let mut f = vec![0.0; nx];
    model.step(&c, &cu, &mut f);
    (0..nx).any(|i| {
        let amax = |j: usize| js.a.iter().map(|a| a[(i, j)].abs()).fold(0.0, f64::max);
        let bmax = |j: usize| js.b.iter().map(|b| b[(i, j)].abs()).fold(0.0, f64::max);
        let r: f64 = (0..nx).map(|j| amax(j) * h[j]).sum::<f64>()
            + (0..nu).map(|j| bmax(j) * g[j]).sum::<f64>();
        let r = r + 1e-12 * (1.0 + f[i].abs() + r);
        // A NaN anywhere decides nothing.
        r.is_finite() && f[i].is_finite() && (f[i] + r < xl[i] || f[i] - r > xh[i])
    })
}

/// How many of the `boxes` (lower, upper corner) are not proven infeasible
/// ([`infeasible_by_reach`]) for the tightened OCP with `stages`.
pub fn unproven_boxes(
    cfg: &ProblemConfig,
    stages: &StageBounds,
    boxes: &[(Vec<f64>, Vec<f64>)],
) -> usize {
    let js = super::jacobians::jacobian_set(cfg);
    boxes
        .iter()
        .filter(|(lo, hi)| !infeasible_by_reach(cfg, stages, &js, lo, hi))
        .count()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn di() -> ProblemConfig {
        let path = std::path::PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/"))
            .join("double_integrator.toml");
        let mut c = ProblemConfig::load(&path).unwrap();
        c.robust.eps = 0.05;
        c
    }

    /// On the double integrator (exact Jacobians) a box whose every state leaves the
    /// tightened stage-1 bounds under every input is proven; a box around the origin is not.
    /// Checked against sampled one-step successors.
    #[test]
    fn reach_outside_the_tightened_box_is_proven_and_sampling_agrees() {
        let cfg = di();
        let d = super::super::design(&cfg).unwrap();
        let js = super::super::jacobians::jacobian_set(&cfg);
        let model = Discrete::new(cfg.system.clone(), cfg.ocp.ts, cfg.ocp.rk4_substeps);
        let (xh, xl) = (&d.stages.x_hi[0], &d.stages.x_lo[0]);
        // Velocity at its upper bound and beyond: x_1's velocity leaves the tightened box
        // only if the box is far enough out; search outward along the velocity axis.
        let (lo, hi) = (cfg.domain.lo.clone(), cfg.domain.hi.clone());
        assert!(!infeasible_by_reach(
            &cfg,
            &d.stages,
            &js,
            &[-0.1, -0.1],
            &[0.1, 0.1]
        ));
        let mut found = None;
        for k in 0..40 {
            let v = hi[1] + 0.05 * k as f64;
            let b = ([lo[0], v], [hi[0], v + 0.05]);
            if infeasible_by_reach(&cfg, &d.stages, &js, &b.0, &b.1) {
                found = Some(b);
                break;
            }
        }
        let (blo, bhi) = found.expect("some box beyond the velocity bound is proven infeasible");
        let (ul, uh) = (&d.stages.u_lo[0], &d.stages.u_hi[0]);
        let mut next = vec![0.0; 2];
        for n in 0..2000u64 {
            let x: Vec<f64> = (0..2)
                .map(|i| blo[i] + (bhi[i] - blo[i]) * crate::rng::uniform(5, n, i as u64))
                .collect();
            let u = [ul[0] + (uh[0] - ul[0]) * crate::rng::uniform(6, n, 0)];
            model.step(&x, &u, &mut next);
            assert!(
                (0..2).any(|i| next[i] < xl[i] || next[i] > xh[i]),
                "{x:?}, u {u:?} → {next:?} stays feasible"
            );
        }
        assert_eq!(
            unproven_boxes(&cfg, &d.stages, &[(blo.to_vec(), bhi.to_vec())]),
            0
        );
    }
}
