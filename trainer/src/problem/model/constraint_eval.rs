//! Values and exact derivatives of the OCP's constraint functions g(x, u) ≤ 0
//! ([`ConstraintSet`]): `g`, the Jacobian `∂g/∂(x, u)` and the weighted Hessian
//! `∇²_{(x,u)} Σᵢ wᵢ gᵢ(x, u)`, by forward-mode AD through the compiled tape — the same
//! per-thread buffers and `NZ = nx + nu` dispatch as the expression plants
//! ([`super::plant`]), so later calls allocate nothing.

use super::expr::ConstraintSet;
use super::nz::by_nz;
use super::plant::Scratch;
use super::MAX_NZ;
use num_dual::{Dual2SVec64, DualNum, DualSVec64};

impl ConstraintSet {
    /// Runs `body(out, regs)` on this thread's buffers with the outputs of the tape at
    /// `(x, u)` seeded by `seed(index, value)` (index over the stacked `(x, u)`).
    fn eval_seeded<D: DualNum<Primitive = f64> + Scratch, R>(
        &self,
        x: &[f64],
        u: &[f64],
        seed: impl Fn(usize, f64) -> D,
        body: impl FnOnce(&[D]) -> R,
    ) -> R {
        let (nx, nu, m) = (self.nx(), self.nu(), self.len());
        D::with_work(|w| {
            w.buf.resize(nx + nu + m, D::from(0.0));
            let (xd, rest) = w.buf.split_at_mut(nx);
            let (ud, out) = rest.split_at_mut(nu);
            for i in 0..nx {
                xd[i] = seed(i, x[i]);
            }
            for j in 0..nu {
                ud[j] = seed(nx + j, u[j]);
            }
            self.eval(xd, ud, out, &mut w.regs);
            body(out)
        })
    }

    /// `g = g(x, u)` (length [`len`](ConstraintSet::len)).
    pub fn values(&self, x: &[f64], u: &[f64], g: &mut [f64]) {
        self.eval_seeded(x, u, |_, v| v, |out: &[f64]| g.copy_from_slice(out))
    }

    /// `g = g(x, u)` and `jac = ∂g/∂(x, u)`, row-major `len × (nx + nu)`.
    pub fn linearize(&self, x: &[f64], u: &[f64], g: &mut [f64], jac: &mut [f64]) {
        by_nz!(self.nx() + self.nu(), self.linearize_n(x, u, g, jac))
    }

    fn linearize_n<const NZ: usize>(&self, x: &[f64], u: &[f64], g: &mut [f64], jac: &mut [f64])
    where
        DualSVec64<NZ>: Scratch,
    {
        self.eval_seeded(
            x,
            u,
            |i, v| DualSVec64::<NZ>::from(v).derivative(i),
            |out| {
                for (i, o) in out.iter().enumerate() {
                    g[i] = o.re;
                    let eps = o
                        .eps
                        .unwrap_generic(nalgebra::Const::<NZ>, nalgebra::Const::<1>);
                    for j in 0..NZ {
                        jac[i * NZ + j] = eps[j];
                    }
                }
            },
        )
    }

    /// `hess = ∇²_{(x,u)} Σᵢ wᵢ gᵢ(x, u)`, row-major `(nx + nu)²`.
    pub fn weighted_hessian(&self, x: &[f64], u: &[f64], w: &[f64], hess: &mut [f64]) {
        by_nz!(self.nx() + self.nu(), self.hessian_n(x, u, w, hess))
    }

    fn hessian_n<const NZ: usize>(&self, x: &[f64], u: &[f64], w: &[f64], hess: &mut [f64])
    where
        Dual2SVec64<NZ>: Scratch,
    {
        self.eval_seeded(
            x,
            u,
            |i, v| Dual2SVec64::<NZ>::from(v).derivative(i),
            |out| {
                let mut acc = Dual2SVec64::<NZ>::from(0.0);
                for (o, &wi) in out.iter().zip(w) {
                    if wi != 0.0 {
                        acc += *o * wi;
                    }
                }
                let h = acc
                    .v2
                    .unwrap_generic(nalgebra::Const::<NZ>, nalgebra::Const::<NZ>);
                for r in 0..NZ {
                    for c in 0..NZ {
                        hess[r * NZ + c] = h[(r, c)];
                    }
                }
            },
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::problem::model::expr::SystemSpec;

    fn spec() -> SystemSpec {
        toml::from_str(
            r#"
            states = ["pos", "vel"]
            inputs = ["force"]
            parameters = { k = 2.0 }
            definitions = ["e = 0.5*k*pos^2 + 0.5*vel^2"]
            rhs = ["vel", "force - k*pos"]
            "#,
        )
        .unwrap()
    }

    fn set() -> ConstraintSet {
        let path = [
            "pos + 0.5*vel <= 1.2".to_string(),
            "vel^2 + force^2/4 <= 9".into(),
            "sin(pos)*force >= -e".into(),
            "-2 <= force".into(),
        ];
        let term = ["pos^2 + 0.5*vel^2 <= 0.25".to_string()];
        ConstraintSet::compile(&spec(), &path, &term).unwrap()
    }

    /// Direct f64 formulas of the five constraints as g ≤ 0.
    fn direct(x: &[f64], u: &[f64]) -> [f64; 5] {
        let (p, v, f) = (x[0], x[1], u[0]);
        let e = 0.5 * 2.0 * p * p + 0.5 * v * v;
        [
            p + 0.5 * v - 1.2,
            v * v + f * f / 4.0 - 9.0,
            -e - p.sin() * f,
            -2.0 - f,
            p * p + 0.5 * v * v - 0.25,
        ]
    }

    #[test]
    fn classification() {
        let s = set();
        let aff: Vec<bool> = s.items.iter().map(|c| c.affine).collect();
        assert_eq!(aff, [true, false, false, true, false]);
        let vars: Vec<Vec<usize>> = s.items.iter().map(|c| c.vars.clone()).collect();
        assert_eq!(
            vars,
            [vec![0, 1], vec![1, 2], vec![0, 1, 2], vec![2], vec![0, 1]]
        );
        assert!(s.items[4].terminal && !s.items[3].terminal);
        assert!(!s.items[3].uses_states(2) && s.items[3].uses_inputs(2));
    }

    #[test]
    fn values_jacobian_and_hessian_match_direct_and_finite_differences() {
        let s = set();
        let (m, nz) = (s.len(), 3);
        let draw = |t: u64, j: u64, a: f64, b: f64| a + (b - a) * crate::rng::uniform(7, t, j);
        for t in 0..50 {
            let z: Vec<f64> = (0..nz).map(|j| draw(t, j as u64, -2.0, 2.0)).collect();
            let (x, u) = z.split_at(2);
            let mut g = vec![0.0; m];
            s.values(x, u, &mut g);
            let d = direct(x, u);
            for i in 0..m {
                assert!((g[i] - d[i]).abs() <= 1e-14 * (1.0 + d[i].abs()), "{i}");
            }
            let mut g2 = vec![0.0; m];
            let mut jac = vec![0.0; m * nz];
            s.linearize(x, u, &mut g2, &mut jac);
            assert_eq!(g, g2);
            let h = 1e-6;
            for j in 0..nz {
                let (mut zp, mut zm) = (z.clone(), z.clone());
                zp[j] += h;
                zm[j] -= h;
                let (dp, dm) = (direct(&zp[..2], &zp[2..]), direct(&zm[..2], &zm[2..]));
                for i in 0..m {
                    let fd = (dp[i] - dm[i]) / (2.0 * h);
                    assert!(
                        (jac[i * nz + j] - fd).abs() <= 1e-7 * (1.0 + fd.abs()),
                        "{i},{j}"
                    );
                }
            }
            let w: Vec<f64> = (0..m).map(|i| draw(t, 10 + i as u64, 0.0, 3.0)).collect();
            let mut hess = vec![0.0; nz * nz];
            s.weighted_hessian(x, u, &w, &mut hess);
            // Finite differences of the weighted gradient.
            let grad = |zz: &[f64]| -> Vec<f64> {
                let (mut gg, mut jj) = (vec![0.0; m], vec![0.0; m * nz]);
                s.linearize(&zz[..2], &zz[2..], &mut gg, &mut jj);
                (0..nz)
                    .map(|j| (0..m).map(|i| w[i] * jj[i * nz + j]).sum())
                    .collect()
            };
            for j in 0..nz {
                let (mut zp, mut zm) = (z.clone(), z.clone());
                zp[j] += h;
                zm[j] -= h;
                let (gp, gm) = (grad(&zp), grad(&zm));
                for r in 0..nz {
                    let fd = (gp[r] - gm[r]) / (2.0 * h);
                    assert!(
                        (hess[r * nz + j] - fd).abs() <= 1e-6 * (1.0 + fd.abs()),
                        "{r},{j}"
                    );
                }
            }
        }
    }

    #[test]
    fn errors_name_the_key_and_column() {
        let sp = spec();
        let err = |path: &[&str], term: &[&str]| {
            let p: Vec<String> = path.iter().map(|s| s.to_string()).collect();
            let t: Vec<String> = term.iter().map(|s| s.to_string()).collect();
            ConstraintSet::compile(&sp, &p, &t).unwrap_err().to_string()
        };
        let e = err(&["pos + vel"], &[]);
        assert!(
            e.starts_with("ocp.constraints[0], column 1 of `pos + vel`: expected"),
            "{e}"
        );
        let e = err(&["pos <= 1", "pos + velo <= 1"], &[]);
        assert!(
            e.contains("ocp.constraints[1], column 7 of `pos + velo <= 1`: unknown name `velo`"),
            "{e}"
        );
        let e = err(&[], &["pos <= 1 <= 2"]);
        assert!(e.contains("ocp.terminal_constraints[0], column 10"), "{e}");
        let e = err(&["pos < 1"], &[]);
        assert!(e.contains("column 5") && e.contains("`<=`"), "{e}");
        let e = err(&["vel <= 1 + force^"], &[]);
        assert!(e.starts_with("ocp.constraints[0], column 18"), "{e}");
        let e = err(&[], &["pos + force <= 1"]);
        assert!(e.contains("may not use the input `force`"), "{e}");
        let e = err(&["k <= 3"], &[]);
        assert!(e.contains("no state or input"), "{e}");
    }
}
