//! Convexity of the SQP's QP subproblem on the null space of the linearised dynamics.
//!
//! With `dx_0 = 0` and `dx_{k+1} = A_k dx_k + B_k du_k` the QP's objective `½dᵀHd + gᵀd`
//! is a quadratic in the inputs `du = (du_0, …, du_{N−1})` alone, with Hessian `Zᵀ H Z`
//! (the reduced Hessian; Z maps du to d). The QP has a unique solution whatever its bounds
//! when `ZᵀHZ` is positive definite, which the backward Riccati recursion decides in
//! O(N·(nx + nu)³) without forming Z:
//! ```text
//! P_N = H_N^xx
//! R̃_k = H_k^uu + B_kᵀ P_{k+1} B_k,   S̃_k = H_k^ux + B_kᵀ P_{k+1} A_k
//! P_k = H_k^xx + A_kᵀ P_{k+1} A_k − S̃_kᵀ R̃_k⁻¹ S̃_k
//! ```
//! `ZᵀHZ ≻ 0` iff every `R̃_k ≻ 0` (the recursion is a block LDLᵀ factorisation of `ZᵀHZ`,
//! eliminating `du_{N−1}` first; the `R̃_k` are its pivots). [`ReducedHessian`] owns the
//! workspace; it is tested against the eigenvalues of the dense `ZᵀHZ`.

use crate::mpc::ocp::Ocp;
use crate::mpc::qp::by_nx;

/// Workspace of the Riccati test (sized once per OCP structure).
#[derive(Debug, Clone, Default)]
pub struct ReducedHessian {
    p: Vec<f64>,
    pa: Vec<f64>,
    pb: Vec<f64>,
    rt: Vec<f64>,
    st: Vec<f64>,
    q: Vec<f64>,
}

/// Relative size below which a Cholesky pivot of `R̃_k` counts as not positive.
const PIVOT_TOL: f64 = 1e-10;

impl ReducedHessian {
    /// Workspace for `ocp`'s dimensions.
    pub fn new(ocp: &Ocp) -> Self {
        let (nx, nu) = (ocp.nx, ocp.nu);
        ReducedHessian {
            p: vec![0.0; nx * nx],
            pa: vec![0.0; nx * nx],
            pb: vec![0.0; nx * nu],
            rt: vec![0.0; nu * nu],
            st: vec![0.0; nu * nx],
            q: vec![0.0; nx * nx],
        }
    }

    /// Whether `ZᵀHZ` is positive definite for the stage blocks `hess`
    /// ([`Ocp::hessian_blocks`] layout) and the dynamics Jacobians `jac_x`, `jac_u`: every
    /// Cholesky pivot of every `R̃_k` exceeds `1e-10·max(1, max_i |H_k^uu[i, i]|)`.
    pub fn is_positive_definite(
        &mut self,
        ocp: &Ocp,
        hess: &[f64],
        jac_x: &[f64],
        jac_u: &[f64],
    ) -> bool {
        by_nx!(ocp.nx, self.test_nx(ocp, hess, jac_x, jac_u))
    }

    /// [`ReducedHessian::is_positive_definite`] with the state dimension the constant `NX`
    /// (0: the OCP's; `qp::by_nx!`), the same operations.
    fn test_nx<const NX: usize>(
        &mut self,
        ocp: &Ocp,
        hess: &[f64],
        jac_x: &[f64],
        jac_u: &[f64],
    ) -> bool {
        let nx = if NX == 0 { ocp.nx } else { NX };
        let (nu, n) = (ocp.nu, ocp.horizon);
        let nz = nx + nu;
        let ReducedHessian {
            p,
            pa,
            pb,
            rt,
            st,
            q,
        } = self;
        let hn = &hess[n * nz * nz..(n + 1) * nz * nz];
        for i in 0..nx {
            p[i * nx..(i + 1) * nx].copy_from_slice(&hn[i * nz..i * nz + nx]);
        }
        for k in (0..n).rev() {
            let a = &jac_x[k * nx * nx..(k + 1) * nx * nx];
            let b = &jac_u[k * nx * nu..(k + 1) * nx * nu];
            let h = &hess[k * nz * nz..(k + 1) * nz * nz];
            // pa = P A, pb = P B.
            for i in 0..nx {
                for j in 0..nx {
                    pa[i * nx + j] = (0..nx).map(|l| p[i * nx + l] * a[l * nx + j]).sum();
                }
                for j in 0..nu {
                    pb[i * nu + j] = (0..nx).map(|l| p[i * nx + l] * b[l * nu + j]).sum();
                }
            }
            // R̃ = H^uu + Bᵀ P B, S̃ = H^ux + Bᵀ P A.
            for i in 0..nu {
                for j in 0..nu {
                    rt[i * nu + j] = h[(nx + i) * nz + nx + j]
                        + (0..nx).map(|l| b[l * nu + i] * pb[l * nu + j]).sum::<f64>();
                }
                for j in 0..nx {
                    st[i * nx + j] = h[(nx + i) * nz + j]
                        + (0..nx).map(|l| b[l * nu + i] * pa[l * nx + j]).sum::<f64>();
                }
            }
            // Cholesky R̃ = L Lᵀ in place (lower triangle).
            let scale = (0..nu).fold(1.0f64, |m, i| m.max(h[(nx + i) * nz + nx + i].abs()));
            for j in 0..nu {
                let mut d = rt[j * nu + j];
                for l in 0..j {
                    d -= rt[j * nu + l] * rt[j * nu + l];
                }
                if d.is_nan() || d <= PIVOT_TOL * scale {
                    return false;
                }
                let d = d.sqrt();
                rt[j * nu + j] = d;
                for i in j + 1..nu {
                    let mut v = rt[i * nu + j];
                    for l in 0..j {
                        v -= rt[i * nu + l] * rt[j * nu + l];
                    }
                    rt[i * nu + j] = v / d;
                }
            }
            if k == 0 {
                break;
            }
            // S̃ ← L⁻¹ S̃, so that S̃ᵀ R̃⁻¹ S̃ = (L⁻¹S̃)ᵀ(L⁻¹S̃).
            for c in 0..nx {
                for i in 0..nu {
                    let mut v = st[i * nx + c];
                    for l in 0..i {
                        v -= rt[i * nu + l] * st[l * nx + c];
                    }
                    st[i * nx + c] = v / rt[i * nu + i];
                }
            }
            // P ← H^xx + Aᵀ P A − S̃ᵀ R̃⁻¹ S̃, symmetrised.
            for i in 0..nx {
                for j in 0..nx {
                    q[i * nx + j] = h[i * nz + j]
                        + (0..nx).map(|l| a[l * nx + i] * pa[l * nx + j]).sum::<f64>()
                        - (0..nu)
                            .map(|l| st[l * nx + i] * st[l * nx + j])
                            .sum::<f64>();
                }
            }
            for i in 0..nx {
                for j in 0..nx {
                    p[i * nx + j] = 0.5 * (q[i * nx + j] + q[j * nx + i]);
                }
            }
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::problem::ProblemConfig;
    use crate::rng::uniform;
    use nalgebra::DMatrix;

    /// The dense `ZᵀHZ` (Z maps du to d with dx_0 = 0 and the linearised dynamics).
    fn dense_reduced(ocp: &Ocp, hess: &[f64], jx: &[f64], ju: &[f64]) -> DMatrix<f64> {
        let (nx, nu, n) = (ocp.nx, ocp.nu, ocp.horizon);
        let nz = nx + nu;
        let m = n * nu;
        let mut z = DMatrix::<f64>::zeros(ocp.n_var, m);
        for c in 0..m {
            let mut dx = vec![0.0; nx];
            for k in 0..n {
                let du: Vec<f64> = (0..nu).map(|j| f64::from(k * nu + j == c)).collect();
                for j in 0..nu {
                    z[(ocp.iu(k) + j, c)] = du[j];
                }
                let next: Vec<f64> = (0..nx)
                    .map(|r| {
                        (0..nx)
                            .map(|j| jx[k * nx * nx + r * nx + j] * dx[j])
                            .sum::<f64>()
                            + (0..nu)
                                .map(|j| ju[k * nx * nu + r * nu + j] * du[j])
                                .sum::<f64>()
                    })
                    .collect();
                for r in 0..nx {
                    z[(ocp.ix(k + 1) + r, c)] = next[r];
                }
                dx = next;
            }
        }
        let mut h = DMatrix::<f64>::zeros(ocp.n_var, ocp.n_var);
        for s in 0..=n {
            let size = if s < n { nz } else { nx };
            for i in 0..size {
                for j in 0..size {
                    h[(s * nz + i, s * nz + j)] = hess[s * nz * nz + i * nz + j];
                }
            }
        }
        z.transpose() * h * z
    }

    /// The Riccati verdict equals the sign of the smallest eigenvalue of the dense reduced
    /// Hessian, on exact Lagrangian Hessians at random points and multipliers of the
    /// cart-pole (indefinite blocks) and the pendulum, scaled from small to large
    /// multipliers so that both verdicts occur.
    #[test]
    fn riccati_test_agrees_with_dense_reduced_hessian_eigenvalues() {
        let mut seen = [0usize; 2];
        for name in ["cartpole.toml", "pendulum.toml"] {
            let path =
                std::path::PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/"))
                    .join(name);
            let mut cfg = ProblemConfig::load(&path).unwrap();
            cfg.ocp.horizon = 6;
            let ocp = Ocp::new(&cfg, false);
            let (nx, nu, n) = (ocp.nx, ocp.nu, ocp.horizon);
            let nz = nx + nu;
            let mut test = ReducedHessian::new(&ocp);
            for i in 0..40u64 {
                let z: Vec<f64> = (0..ocp.n_var)
                    .map(|j| 2.0 * uniform(5, i, j as u64) - 1.0)
                    .collect();
                let scale = 10f64.powf(-1.0 + 4.0 * uniform(6, i, 0));
                let lam: Vec<f64> = (0..ocp.n_eq)
                    .map(|j| scale * (2.0 * uniform(7, i, j as u64) - 1.0))
                    .collect();
                let (mut c, mut jx, mut ju) = (
                    vec![0.0; ocp.n_eq],
                    vec![0.0; n * nx * nx],
                    vec![0.0; n * nx * nu],
                );
                ocp.constraints(&z, &z[..nx], &mut c, &mut jx, &mut ju);
                let mut hess = vec![0.0; (n + 1) * nz * nz];
                ocp.hessian_blocks(&z, &lam, &[], &mut hess);
                let min = dense_reduced(&ocp, &hess, &jx, &ju)
                    .symmetric_eigen()
                    .eigenvalues
                    .min();
                let pd = test.is_positive_definite(&ocp, &hess, &jx, &ju);
                // Skip the numerically ambiguous band around a zero eigenvalue.
                if min.abs() < 1e-6 {
                    continue;
                }
                assert_eq!(pd, min > 0.0, "{name} case {i}: smallest eigenvalue {min}");
                seen[pd as usize] += 1;
            }
        }
        assert!(
            seen[0] > 0 && seen[1] > 0,
            "both verdicts must occur: {seen:?}"
        );
    }
}
