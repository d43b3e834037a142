//! The Jacobian family {(A(ξ), B(ξ))} of the discrete dynamics F over the arguments ξ the
//! mean-value theorem can visit, and how its supremum is bounded (exact, vertices, sampled).

use crate::problem::model::{Discrete, Pendulum, System};
use crate::problem::ProblemConfig;
use crate::rng::uniform;
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

/// How the supremum over the Jacobians was obtained.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum JacobianBound {
    /// Constant Jacobians (linear system): exact.
    Exact,
    /// Vertex enumeration of a multi-affine Jacobian family: sound on all of R^nx × R^nu.
    Vertices,
    /// Maximum over random samples of X × U: an estimate.
    SampledEstimate,
}

/// A finite family of Jacobian pairs (A, B) of F whose norms bound the sup over ξ.
#[derive(Debug, Clone)]
pub struct JacobianSet {
    /// ∂F/∂x, nx × nx.
    pub a: Vec<DMatrix<f64>>,
    /// ∂F/∂u, nx × nu.
    pub b: Vec<DMatrix<f64>>,
    /// Soundness of the family.
    pub bound: JacobianBound,
}

/// The RK4 Jacobian of the pendulum with the stage cosines `c` (4 per sub-step,
/// `c = cos(x₁)` at each RK4 stage point) given freely: multi-affine in `c`.
pub fn pendulum_rk4_jacobian(
    p: &Pendulum,
    ts: f64,
    substeps: usize,
    c: &[f64],
) -> (DMatrix<f64>, DMatrix<f64>) {
    let a_g = p.g / p.l;
    let bu = 1.0 / (p.m * p.l * p.l);
    let h = ts / substeps as f64;
    let mut a_tot = DMatrix::<f64>::identity(2, 2);
    let mut b_tot = DMatrix::<f64>::zeros(2, 1);
    for s in 0..substeps {
        // Tangents as 2×3 matrices (columns x₁, x₂, u).
        let x0 = DMatrix::from_row_slice(2, 3, &[1.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
        let eu = DMatrix::from_row_slice(2, 3, &[0.0, 0.0, 0.0, 0.0, 0.0, bu]);
        let jac = |ci: f64| DMatrix::from_row_slice(2, 2, &[0.0, 1.0, a_g * ci, 0.0]);
        let cs = &c[4 * s..4 * s + 4];
        let k1 = jac(cs[0]) * &x0 + &eu;
        let k2 = jac(cs[1]) * (&x0 + &k1 * (h / 2.0)) + &eu;
        let k3 = jac(cs[2]) * (&x0 + &k2 * (h / 2.0)) + &eu;
        let k4 = jac(cs[3]) * (&x0 + &k3 * h) + &eu;
        let d = &x0 + (k1 + k2 * 2.0 + k3 * 2.0 + k4) * (h / 6.0);
        let a_s = d.columns(0, 2).into_owned();
        let b_s = d.columns(2, 1).into_owned();
        b_tot = &a_s * b_tot + b_s;
        a_tot = a_s * a_tot;
    }
    (a_tot, b_tot)
}

pub(crate) fn linearize_at(model: &Discrete, x: &[f64], u: &[f64]) -> (DMatrix<f64>, DMatrix<f64>) {
    let (nx, nu) = (model.nx(), model.nu());
    let (mut f, mut jx, mut ju) = (vec![0.0; nx], vec![0.0; nx * nx], vec![0.0; nx * nu]);
    model.linearize(x, u, &mut f, &mut jx, &mut ju);
    (
        DMatrix::from_row_slice(nx, nx, &jx),
        DMatrix::from_row_slice(nx, nu, &ju),
    )
}

/// The Jacobian family of the problem's discrete dynamics (see the module doc).
pub fn jacobian_set(cfg: &ProblemConfig) -> JacobianSet {
    let model = Discrete::new(cfg.system.clone(), cfg.ocp.ts, cfg.ocp.rk4_substeps);
    let (nx, nu) = (model.nx(), model.nu());
    match &cfg.system {
        System::DoubleIntegrator(_) => {
            let (a, b) = linearize_at(&model, &vec![0.0; nx], &vec![0.0; nu]);
            JacobianSet {
                a: vec![a],
                b: vec![b],
                bound: JacobianBound::Exact,
            }
        }
        System::Pendulum(p) if model.substeps <= 2 => {
            let nc = 4 * model.substeps;
            let (mut av, mut bv) = (Vec::new(), Vec::new());
            for mask in 0..(1usize << nc) {
                let c: Vec<f64> = (0..nc)
                    .map(|i| if mask >> i & 1 == 1 { 1.0 } else { -1.0 })
                    .collect();
                let (a, b) = pendulum_rk4_jacobian(p, model.ts, model.substeps, &c);
                av.push(a);
                bv.push(b);
            }
            JacobianSet {
                a: av,
                b: bv,
                bound: JacobianBound::Vertices,
            }
        }
        // The cart-pole, the pendulum with more sub-steps, and every plant written as
        // expressions (`ode`/`discrete`, even a linear one: its linearity is not detected):
        // sampled Jacobians at random points of X × U, flagged as an estimate.
        _ => {
            let s = &cfg.robust;
            let (mut av, mut bv) = (Vec::new(), Vec::new());
            let (ulo, uhi) = (&cfg.ocp.u_lo, &cfg.ocp.u_hi);
            for n in 0..s.samples as u64 {
                let x: Vec<f64> = (0..nx)
                    .map(|i| {
                        let (l, h) = (cfg.domain.lo[i], cfg.domain.hi[i]);
                        l + (h - l) * uniform(s.seed, n, i as u64)
                    })
                    .collect();
                let u: Vec<f64> = (0..nu)
                    .map(|j| {
                        let (l, h) = (ulo[j].max(-1e3), uhi[j].min(1e3));
                        l + (h - l) * uniform(s.seed, n, (nx + j) as u64)
                    })
                    .collect();
                let (a, b) = linearize_at(&model, &x, &u);
                av.push(a);
                bv.push(b);
            }
            JacobianSet {
                a: av,
                b: bv,
                bound: JacobianBound::SampledEstimate,
            }
        }
    }
}
