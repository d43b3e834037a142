//! The setpoint as an equilibrium of the discrete model: `F(x_ref, u_ref) = x_ref`.
//!
//! The stage cost `(x − x_ref)ᵀQ(x − x_ref) + (u − u_ref)ᵀR(u − u_ref)` drives the loop to
//! x_ref only if u_ref holds it there; with any other u_ref the MPC trades a steady offset
//! for input effort. So a problem file's setpoint is checked once, at the edge:
//!
//! ```text
//! r = F(x_ref, u_ref) − x_ref,   accepted when |r_i| ≤ tol · s_i for every state i,
//! s_i = max(½(hi_i − lo_i), |x_ref_i|)   (the domain X's half-width, or the setpoint's size)
//! ```
//!
//! with `tol = ocp.setpoint_tol` (default [`DEFAULT_SETPOINT_TOL`]) and F the OCP's own
//! discretisation (RK4 with `rk4_substeps`, or the discrete map). When `ocp.u_ref` is
//! omitted it is computed: the input in U that holds x_ref, by projected Gauss–Newton on
//! `min_u ‖S⁻¹(F(x_ref, u) − x_ref)‖²` from the projection of 0 onto U (so a plant that
//! rests at x_ref with u = 0 keeps u_ref = 0 exactly). If no input in U holds x_ref within
//! the tolerance, the error names the largest residual, its state and the best input found.
//! A model that is not finite at the setpoint is not judged here: every solve there fails
//! with `numerical_failure` naming the non-finite quantity, and u_ref stays as written (0).

use super::model::Discrete;
use super::{invalid, ConfigError, ProblemConfig};
use nalgebra::{DMatrix, DVector};

/// Default of `ocp.setpoint_tol`: the largest accepted one-step residual of the setpoint,
/// relative to each state's scale s_i.
pub const DEFAULT_SETPOINT_TOL: f64 = 1e-6;

/// Projected Gauss–Newton iterations for the equilibrium input.
const MAX_ITER: usize = 60;

/// Per-state scale `s_i` of the residual: the domain's half-width, or |x_ref_i| if larger.
fn scales(cfg: &ProblemConfig, x_ref: &[f64]) -> Vec<f64> {
    (0..x_ref.len())
        .map(|i| {
            let hw = 0.5 * (cfg.domain.hi[i] - cfg.domain.lo[i]);
            hw.max(x_ref[i].abs()).max(f64::MIN_POSITIVE)
        })
        .collect()
}

/// `S⁻¹(F(x, u) − x)` and, when asked, `S⁻¹ ∂F/∂u` (row-major nx×nu).
fn residual(model: &Discrete, x: &[f64], u: &[f64], s: &[f64], ju: Option<&mut [f64]>) -> Vec<f64> {
    let (nx, nu) = (model.nx(), model.nu());
    let mut f = vec![0.0; nx];
    match ju {
        Some(ju) => {
            let mut jx = vec![0.0; nx * nx];
            model.linearize(x, u, &mut f, &mut jx, ju);
            for i in 0..nx {
                for j in 0..nu {
                    ju[i * nu + j] /= s[i];
                }
            }
        }
        None => model.step(x, u, &mut f),
    }
    (0..nx).map(|i| (f[i] - x[i]) / s[i]).collect()
}

fn worst(r: &[f64]) -> f64 {
    r.iter().fold(0.0f64, |m, v| {
        if v.is_nan() {
            f64::INFINITY
        } else {
            m.max(v.abs())
        }
    })
}

/// The input in `[lo, hi]` that best holds `x` (projected Gauss–Newton with a backtracking
/// line search on the scaled residual), and its scaled residual.
fn equilibrium_input(
    model: &Discrete,
    x: &[f64],
    s: &[f64],
    lo: &[f64],
    hi: &[f64],
) -> (Vec<f64>, Vec<f64>) {
    let (nx, nu) = (model.nx(), model.nu());
    let project = |u: &mut [f64]| {
        for j in 0..nu {
            u[j] = u[j].clamp(lo[j], hi[j]);
        }
    };
    let mut u = vec![0.0; nu];
    project(&mut u);
    let mut ju = vec![0.0; nx * nu];
    let mut r = residual(model, x, &u, s, Some(&mut ju));
    let norm2 = |r: &[f64]| r.iter().map(|v| v * v).sum::<f64>();
    for _ in 0..MAX_ITER {
        if worst(&r) <= 1e-15 {
            break;
        }
        let b = DMatrix::from_row_slice(nx, nu, &ju);
        let rv = DVector::from_column_slice(&r);
        let mut h = b.transpose() * &b;
        let mu = 1e-12 * h.trace().max(1e-300);
        for j in 0..nu {
            h[(j, j)] += mu;
        }
        let Some(step) = h.cholesky().map(|c| c.solve(&(-(b.transpose() * rv)))) else {
            break;
        };
        let (f0, mut t, mut improved) = (norm2(&r), 1.0, false);
        for _ in 0..30 {
            let mut cand: Vec<f64> = (0..nu).map(|j| u[j] + t * step[j]).collect();
            project(&mut cand);
            let rc = residual(model, x, &cand, s, None);
            if norm2(&rc) < f0 {
                u = cand;
                improved = true;
                break;
            }
            t *= 0.5;
        }
        if !improved {
            break;
        }
        r = residual(model, x, &u, s, Some(&mut ju));
    }
    (u, r)
}

fn tuple(v: &[f64]) -> String {
    let parts: Vec<String> = v.iter().map(|x| format!("{x:?}")).collect();
    format!("[{}]", parts.join(", "))
}

impl ProblemConfig {
    /// Checks that (x_ref, u_ref) is an equilibrium of the model within `ocp.setpoint_tol`,
    /// and computes u_ref when it is omitted (stored as the derived setpoint input, read by
    /// [`OcpSettings::u_ref_or_zero`](super::OcpSettings::u_ref_or_zero)). Errors name the
    /// key, the largest residual and its state, and the input that holds x_ref if one does.
    pub fn settle_setpoint(&mut self) -> Result<(), ConfigError> {
        let nx = self.system.nx();
        let x_ref = self.ocp.x_ref_or_origin(nx);
        let model = Discrete::new(self.system.clone(), self.ocp.ts, self.ocp.rk4_substeps);
        let s = scales(self, &x_ref);
        let tol = self.ocp.setpoint_tol;
        let name = |i: usize| -> String {
            self.system
                .expr_model()
                .and_then(|m| m.state_names().get(i).cloned())
                .map_or(format!("state {i}"), |n| format!("state {i} ({n})"))
        };
        let largest = |r: &[f64]| -> (usize, f64) {
            r.iter().enumerate().fold((0, 0.0), |(bi, bv), (i, v)| {
                let a = if v.is_nan() { f64::INFINITY } else { v.abs() };
                if a > bv {
                    (i, a)
                } else {
                    (bi, bv)
                }
            })
        };
        let where_x = if self.ocp.x_ref.is_some() {
            "x_ref"
        } else {
            "x_ref = the origin (no ocp.x_ref)"
        };
        let (u_best, r_best) =
            equilibrium_input(&model, &x_ref, &s, &self.ocp.u_lo, &self.ocp.u_hi);
        let probe = self.ocp.u_ref.as_deref().unwrap_or(&u_best);
        if residual(&model, &x_ref, probe, &s, None)
            .iter()
            .any(|v| !v.is_finite())
        {
            // A model that is not finite at its setpoint cannot be checked here; every
            // solve there fails and names the non-finite quantity (status
            // `numerical_failure`), which is where such a model is reported.
            self.ocp.derived_u_ref = None;
            return Ok(());
        }
        match &self.ocp.u_ref {
            Some(u_ref) => {
                let r = residual(&model, &x_ref, u_ref, &s, None);
                let (i, w) = largest(&r);
                if w > tol {
                    let hint = if worst(&r_best) <= tol {
                        format!(
                            "; the input that holds x_ref is u = {} (set ocp.u_ref to it, or omit ocp.u_ref to have it computed)",
                            tuple(&u_best)
                        )
                    } else {
                        format!(
                            "; no input in [ocp.u_lo, ocp.u_hi] holds x_ref (best u = {}, residual {:.3e}): choose an x_ref that is an equilibrium",
                            tuple(&u_best),
                            worst(&r_best)
                        )
                    };
                    return Err(invalid(
                        "ocp.u_ref",
                        format!(
                            "({where_x}, u_ref) = ({}, {}) is not an equilibrium of the model: one step moves {} by {:.3e} (residual {:.3e} of its scale {:.3e}, tolerance ocp.setpoint_tol = {tol:e}){hint}",
                            tuple(&x_ref),
                            tuple(u_ref),
                            name(i),
                            w * s[i],
                            w,
                            s[i]
                        ),
                    ));
                }
                self.ocp.derived_u_ref = None;
            }
            None => {
                let (i, w) = largest(&r_best);
                if w > tol {
                    return Err(invalid(
                        if self.ocp.x_ref.is_some() {
                            "ocp.x_ref"
                        } else {
                            "ocp.u_ref"
                        },
                        format!(
                            "{where_x} = {} is not an equilibrium of the model for any input in [ocp.u_lo, ocp.u_hi]: the best input u = {} moves {} by {:.3e} in one step (residual {:.3e} of its scale {:.3e}, tolerance ocp.setpoint_tol = {tol:e}); give an equilibrium as ocp.x_ref (and ocp.u_ref)",
                            tuple(&x_ref),
                            tuple(&u_best),
                            name(i),
                            w * s[i],
                            w,
                            s[i]
                        ),
                    ));
                }
                self.ocp.derived_u_ref = Some(u_best);
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spring(refs: &str, tol: &str) -> Result<ProblemConfig, ConfigError> {
        spring_within(refs, tol, 3.0)
    }

    fn spring_within(refs: &str, tol: &str, u_hi: f64) -> Result<ProblemConfig, ConfigError> {
        let text = format!(
            r#"
name = "spring"
[system]
kind = "ode"
states = ["pos", "vel"]
inputs = ["force"]
parameters = {{ k = 2.0, c = 0.3, d = 0.5 }}
rhs = ["vel", "force - k*pos - d*pos^3 - c*vel"]
[ocp]
ts = 0.1
horizon = 10
q = [1.0, 1.0]
r = [0.1]
p = [1.0, 1.0]
{refs}
{tol}
x_lo = [-2.0, -1.5]
x_hi = [2.0, 1.5]
u_lo = [-3.0]
u_hi = [{u_hi:?}]
[domain]
lo = [-1.0, -1.0]
hi = [1.0, 1.0]
"#
        );
        ProblemConfig::from_toml_str(&text, "spring")
    }

    #[test]
    fn the_origin_with_zero_input_stays_exactly_zero() {
        let cfg = spring("", "").unwrap();
        assert_eq!(cfg.ocp.u_ref_or_zero(1), vec![0.0]);
    }

    #[test]
    fn an_omitted_u_ref_is_the_input_that_holds_x_ref() {
        // Equilibrium force at pos = 0.5: k·p + d·p³ = 1 + 0.0625.
        let cfg = spring("x_ref = [0.5, 0.0]", "").unwrap();
        let u = cfg.ocp.u_ref_or_zero(1)[0];
        assert!((u - 1.0625).abs() <= 1e-12, "u_ref = {u}");
        // Not serialised: the problem's hash is that of the file as written.
        assert!(!cfg.to_toml_string().unwrap().contains("u_ref"));
    }

    #[test]
    fn a_wrong_u_ref_is_an_error_naming_the_residual_and_the_right_input() {
        let e = spring("x_ref = [0.5, 0.0]\nu_ref = [1.0]", "")
            .unwrap_err()
            .to_string();
        assert!(e.contains("ocp.u_ref"), "{e}");
        assert!(e.contains("not an equilibrium"), "{e}");
        assert!(e.contains("state 1 (vel)"), "{e}");
        assert!(
            e.contains("u = [1.0625") || e.contains("u = [1.06249999"),
            "{e}"
        );
        // The right one, and a loose tolerance, are accepted.
        spring("x_ref = [0.5, 0.0]\nu_ref = [1.0625]", "").unwrap();
        spring("x_ref = [0.5, 0.0]\nu_ref = [1.0]", "setpoint_tol = 0.1").unwrap();
    }

    #[test]
    fn a_state_no_input_can_hold_is_an_error() {
        // A moving setpoint (vel ≠ 0) is no equilibrium for any force.
        let e = spring("x_ref = [0.5, 0.25]", "").unwrap_err().to_string();
        assert!(e.contains("ocp.x_ref"), "{e}");
        assert!(e.contains("for any input"), "{e}");
        // Holding pos = 1 needs a force k + d = 2.5 > u_hi = 2.
        let e = spring_within("x_ref = [1.0, 0.0]\nu_ref = [2.0]", "", 2.0)
            .unwrap_err()
            .to_string();
        assert!(e.contains("no input in"), "{e}");
    }
}
