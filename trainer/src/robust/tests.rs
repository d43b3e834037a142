//! The robust design against closed forms, hand computations, the AD linearisation and
//! sampled error trajectories.

use super::*;
use crate::problem::model::{Discrete, Pendulum, System};
use crate::problem::{ConfigError, MatrixSpec, ProblemConfig};
use crate::rng::uniform;
use crate::robust::jacobians::linearize_at;
use nalgebra::DMatrix;

fn load(name: &str) -> ProblemConfig {
    let path =
        std::path::PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/")).join(name);
    ProblemConfig::load(&path).unwrap()
}

fn pendulum(eps: f64) -> ProblemConfig {
    let mut c = ProblemConfig::default();
    c.robust.eps = eps;
    c
}

fn di(eps: f64) -> ProblemConfig {
    let mut c = load("double_integrator.toml");
    c.robust.eps = eps;
    c
}

/// The double integrator at ε = 0.05 with x₂ ≤ 1.5, the same bound as a constraint, a mixed
/// state–input constraint 0.7x₁ − 0.4x₂ + 0.3u ≤ 2 and an input bound u ≥ −0.8 as one (also
/// used by `mpc`'s check that the margins reach the OCP's rows).
pub(crate) fn di_mixed_constraints() -> ProblemConfig {
    let mut cfg = di(0.05);
    cfg.ocp.x_hi = vec![f64::INFINITY, 1.5];
    cfg.ocp.constraints = vec![
        "velocity <= 1.5".into(),
        "0.7*position - 0.4*velocity + 0.3*force <= 2".into(),
        "force >= -0.8".into(),
    ];
    cfg.validate().unwrap();
    cfg
}

/// σ_max of a 2×2 matrix in closed form.
fn sigma_max_2x2(m: &DMatrix<f64>) -> f64 {
    let f2 = m.iter().map(|v| v * v).sum::<f64>();
    let det = m[(0, 0)] * m[(1, 1)] - m[(0, 1)] * m[(1, 0)];
    ((f2 + (f2 * f2 - 4.0 * det * det).max(0.0).sqrt()) / 2.0).sqrt()
}

/// Equal to 10⁻⁹ relative (proven bounds carry rounding margins of ~10⁻¹²).
fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * (1.0 + b.abs())
}

#[test]
fn double_integrator_lipschitz_tightening_in_closed_form() {
    let mut cfg = di(0.1);
    cfg.robust.method = RobustMethod::Lipschitz;
    let d = design(&cfg).unwrap();
    let t = &d.tube;
    let h: f64 = cfg.ocp.ts; // mass 1: A = [[1, h], [0, 1]], B = [h²/2, h]
    let lx = (h + (h * h + 4.0).sqrt()) / 2.0; // σ_max of the shear [[1, h], [0, 1]]
    let lu = h * (1.0 + h * h / 4.0).sqrt();
    assert_eq!(t.bound, JacobianBound::Exact);
    // Proven bounds (rounding margins): at or above the closed forms, within 10⁻⁹.
    assert!(close(t.rho, lx) && t.rho >= lx, "{} vs {lx}", t.rho);
    assert!(t.w >= 0.1 * lu);
    assert!(close(t.w, 0.1 * lu));
    for k in 0..=cfg.ocp.horizon {
        let r = 0.1 * lu * (lx.powi(k as i32) - 1.0) / (lx - 1.0);
        assert!(close(t.s[k], r), "s_{k}");
    }
    // P = I: σ_i = 1; K = 0: the inputs lose exactly ε.
    for k in 1..=cfg.ocp.horizon {
        let hi = d.stages.x_hi[k - 1][1];
        assert!(close(hi, 1.0 - t.s[k]) && hi <= 1.0 - t.s[k]);
        let lo = d.stages.x_lo[k - 1][0];
        assert!(close(lo, -5.0 + t.s[k]) && lo >= -5.0 + t.s[k]);
    }
    assert!(d
        .stages
        .u_hi
        .iter()
        .all(|u| close(u[0], 0.9) && u[0] <= 0.9));
    assert!(d
        .stages
        .u_lo
        .iter()
        .all(|u| close(u[0], -0.9) && u[0] >= -0.9));
}

#[test]
fn double_integrator_tube_for_a_chosen_gain_by_hand() {
    let cfg = di(0.1);
    let js = jacobian_set(&cfg);
    let h: f64 = cfg.ocp.ts;
    let k = DMatrix::from_row_slice(1, 2, &[-2.0, -3.0]);
    let t = Tube::new(
        &js,
        &k,
        &DMatrix::identity(2, 2),
        0.1,
        cfg.ocp.horizon,
        RobustMethod::Tube,
    );
    let m = DMatrix::from_row_slice(
        2,
        2,
        &[
            1.0 - 2.0 * h * h / 2.0,
            h - 3.0 * h * h / 2.0,
            -2.0 * h,
            1.0 - 3.0 * h,
        ],
    );
    let rho = sigma_max_2x2(&m); // ≈ 1.013: P = I is not a contraction metric here
    assert!((rho - 1.0).abs() > 1e-3);
    assert!(close(t.rho, rho) && t.rho >= rho, "{} vs {rho}", t.rho);
    let w = 0.1 * h * (1.0 + h * h / 4.0).sqrt();
    assert!(close(t.w, w));
    for kk in 0..=cfg.ocp.horizon {
        let r = w * (1.0 - rho.powi(kk as i32)) / (1.0 - rho);
        assert!(close(t.s[kk], r));
    }
    assert!(close(t.u_margin[0], 13f64.sqrt()));
    let st = t.tighten(&cfg).unwrap();
    let n = cfg.ocp.horizon;
    assert!((st.u_hi[n - 1][0] - (1.0 - 0.1 - 13f64.sqrt() * t.s[n - 1])).abs() < 1e-12);
    assert!((st.u_hi[0][0] - 0.9).abs() < 1e-12);
}

#[test]
fn pendulum_vertex_jacobian_matches_the_ad_linearisation() {
    let p = Pendulum::default();
    for substeps in [1usize, 2] {
        let model = Discrete::new(System::Pendulum(p.clone()), 0.05, substeps);
        for n in 0..20u64 {
            let x = [
                -6.0 + 12.0 * uniform(3, n, 0),
                -3.0 + 6.0 * uniform(3, n, 1),
            ];
            let u = [-15.0 + 30.0 * uniform(3, n, 2)];
            // The stage cosines of the actual RK4 step.
            let h = 0.05 / substeps as f64;
            let f = |x: [f64; 2]| [x[1], u[0] - 9.81 * (x[0] + std::f64::consts::PI).sin()];
            let mut c = Vec::new();
            let mut xs = x;
            for _ in 0..substeps {
                let k1 = f(xs);
                let p2 = [xs[0] + h / 2.0 * k1[0], xs[1] + h / 2.0 * k1[1]];
                let k2 = f(p2);
                let p3 = [xs[0] + h / 2.0 * k2[0], xs[1] + h / 2.0 * k2[1]];
                let k3 = f(p3);
                let p4 = [xs[0] + h * k3[0], xs[1] + h * k3[1]];
                let k4 = f(p4);
                c.extend([xs[0].cos(), p2[0].cos(), p3[0].cos(), p4[0].cos()]);
                for i in 0..2 {
                    xs[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
                }
            }
            let (a, b) = pendulum_rk4_jacobian(&p, 0.05, substeps, &c);
            let (a2, b2) = linearize_at(&model, &x, &u);
            assert!((&a - &a2).amax() < 1e-12, "{a} vs {a2}");
            assert!((&b - &b2).amax() < 1e-12, "{b} vs {b2}");
        }
    }
}

/// Simulates the error dynamics x⁺ = F(x, v + K(x − z) + e), z⁺ = F(z, v) along random
/// nominal trajectories with bang-bang, alternating, random and greedy worst-case
/// |e| ≤ ε, and checks ‖x_k − z_k‖_P ≤ s_k and |x_k,i − z_k,i| ≤ σ_i s_k. Returns the
/// largest ratio ‖Δ_k‖_P / s_k seen.
fn check_tube_soundness(cfg: &ProblemConfig, trajectories: u64) -> f64 {
    let d = design(cfg).unwrap();
    let t = &d.tube;
    let model = Discrete::new(cfg.system.clone(), cfg.ocp.ts, cfg.ocp.rk4_substeps);
    let nx = cfg.system.nx();
    let p = DMatrix::from_fn(nx, nx, |i, j| t.p[i][j]);
    let k = DMatrix::from_fn(1, nx, |_, j| t.k[0][j]);
    let pnorm = |d: &[f64]| {
        let v = nalgebra::DVector::from_column_slice(d);
        (v.transpose() * &p * &v)[(0, 0)].sqrt()
    };
    let eps = cfg.robust.eps;
    let step = |x: &[f64], z: &[f64], v: f64, e: f64| {
        let dz: Vec<f64> = (0..nx).map(|i| x[i] - z[i]).collect();
        let kd = (0..nx).map(|i| k[(0, i)] * dz[i]).sum::<f64>();
        let mut out = vec![0.0; nx];
        model.step(x, &[v + kd + e], &mut out);
        out
    };
    let mut worst_ratio = 0.0f64;
    for n in 0..trajectories {
        for mode in 0..4 {
            let mut z: Vec<f64> = (0..nx)
                .map(|i| {
                    let (l, h) = (cfg.domain.lo[i], cfg.domain.hi[i]);
                    l + (h - l) * uniform(11, n, i as u64)
                })
                .collect();
            let mut x = z.clone();
            for kk in 0..cfg.ocp.horizon {
                let (ul, uh) = (cfg.ocp.u_lo[0], cfg.ocp.u_hi[0]);
                let v = ul + (uh - ul) * uniform(12, n, kk as u64);
                let e = match mode {
                    0 => eps,
                    1 => {
                        if kk % 2 == 0 {
                            eps
                        } else {
                            -eps
                        }
                    }
                    2 => eps * (2.0 * uniform(13, n, kk as u64) - 1.0),
                    _ => {
                        let mut zn = vec![0.0; nx];
                        model.step(&z, &[v], &mut zn);
                        let grow = |e: f64| {
                            let xn = step(&x, &z, v, e);
                            pnorm(&(0..nx).map(|i| xn[i] - zn[i]).collect::<Vec<_>>())
                        };
                        if grow(eps) >= grow(-eps) {
                            eps
                        } else {
                            -eps
                        }
                    }
                };
                let xn = step(&x, &z, v, e);
                let mut zn = vec![0.0; nx];
                model.step(&z, &[v], &mut zn);
                x = xn;
                z = zn;
                let dlt: Vec<f64> = (0..nx).map(|i| x[i] - z[i]).collect();
                let s = t.s[kk + 1];
                let pn = pnorm(&dlt);
                assert!(
                    pn <= s * (1.0 + 1e-9) + 1e-14,
                    "‖Δ_{}‖_P = {pn} > s = {s} (mode {mode})",
                    kk + 1
                );
                for i in 0..nx {
                    assert!(dlt[i].abs() <= t.x_margin[i] * s * (1.0 + 1e-9) + 1e-14);
                }
                worst_ratio = worst_ratio.max(pn / s);
            }
        }
    }
    worst_ratio
}

#[test]
fn tube_is_sound_for_the_error_dynamics() {
    let r = check_tube_soundness(&di(0.1), 50);
    eprintln!("double integrator: largest ‖Δ‖_P / s_k = {r:.4}");
    // Bang-bang at the bound of a linear system nearly attains the bound.
    assert!(r > 0.5, "{r}");
    let r = check_tube_soundness(&pendulum(0.5), 200);
    eprintln!("pendulum: largest ‖Δ‖_P / s_k = {r:.4}");
    assert!(r > 0.05, "{r}");
}

#[test]
fn settings_defaults_serialise_as_before_and_validate_with_keys() {
    let c = ProblemConfig::default();
    let text = toml::to_string(&c).unwrap();
    assert!(
        !text.contains("robust") && !text.contains("stages"),
        "{text}"
    );
    let mut r = c.clone();
    r.ocp.stages = Some(design(&pendulum(0.5)).unwrap().stages);
    assert_ne!(r.problem_hash(), c.problem_hash());
    let back = ProblemConfig::from_toml_str(&toml::to_string(&r).unwrap(), "r").unwrap();
    assert_eq!(back.ocp.stages, r.ocp.stages);
    let key = |edit: &dyn Fn(&mut ProblemConfig)| {
        let mut c = ProblemConfig::default();
        edit(&mut c);
        match c.validate() {
            Err(ConfigError::Invalid { key, .. }) => key,
            other => panic!("{other:?}"),
        }
    };
    assert_eq!(key(&|c| c.robust.eps = -1.0), "robust.eps");
    assert_eq!(
        key(&|c| c.robust.lqr_r_scales = vec![1.0, 0.0]),
        "robust.lqr_r_scales[1]"
    );
    assert_eq!(
        key(&|c| c.robust.lqr_q = Some(MatrixSpec::Diagonal(vec![1.0]))),
        "robust.lqr_q"
    );
    let st = r.ocp.stages.clone();
    assert_eq!(
        key(&|c| {
            c.ocp.stages = st.clone();
            c.ocp.stages.as_mut().unwrap().x_lo.pop();
        }),
        "ocp.stages.x_lo"
    );
    let parsed = ProblemConfig::from_toml_str(
        &format!(
            "{}\n[robust]\neps = 0.7\nmethod = \"lipschitz\"\n",
            crate::problem::PENDULUM_TOML
        ),
        "f",
    )
    .unwrap();
    assert_eq!(parsed.robust.eps, 0.7);
    assert_eq!(parsed.robust.method, RobustMethod::Lipschitz);
}

/// Evidence for a design ε of 0.5 where everything is proven (sound ε, proven recursive
/// feasibility, a passed check, no excluded cell).
fn proven(eps: f64, allowance: f64) -> super::Evidence {
    super::Evidence {
        design_eps: 0.5,
        certified_eps: eps,
        f32_allowance: allowance,
        recursive_feasibility: super::Feasibility::Proven,
        eps_sound: true,
        eps_rests_on: vec![],
        check: super::Check::Passed,
        excluded_unproven: 0,
        feasible_in_excluded: 0,
        feasible_outside_domain: 0,
    }
}

#[test]
fn verdict_compares_certified_plus_allowance_with_design_eps() {
    use super::Feasibility::*;
    use super::VerdictStatus::*;
    let v = |e: super::Evidence| verdict(&e);
    assert_eq!(v(proven(0.4, 0.0)).status, Certified);
    assert!(v(proven(0.5, 0.0)).certified);
    // The f32 allowance counts: 0.5 + 1e-6 > 0.5.
    let r = v(proven(0.5, 1e-6));
    assert!(
        !r.certified && r.status == NotCertified && r.message.contains("NOT certified"),
        "{}",
        r.message
    );
    let r = v(proven(31.0, 0.0));
    assert!(!r.certified && r.message.contains("NOT certified") && r.message.contains("31"));
    assert_eq!(v(proven(f64::NAN, 0.0)).status, NotCertified);
    assert_eq!(v(proven(0.4, f64::NAN)).status, NotCertified);
    // Corollary 1 is claimed only when everything is proven.
    let r = v(proven(0.4, 1e-6));
    assert!(r.message.contains("Corollary 1 applies") && r.rests_on.is_empty());
    for rf in [Sampled, Unknown] {
        let r = v(super::Evidence {
            recursive_feasibility: rf,
            ..proven(0.4, 1e-6)
        });
        assert_eq!(
            r.status, Conditional,
            "the ε inequality holds, feasibility is {rf:?}"
        );
        assert!(!r.certified);
        assert!(!r.message.contains("Corollary 1 applies"), "{}", r.message);
        assert!(r.rests_on[0].contains(rf.name()), "{:?}", r.rests_on);
    }
}

/// An estimated ε (a sampled L_MPC) is never `certified`, however small: `conditional`, with
/// the assumption in `rests_on`; the same for a check not run and excluded cells whose
/// infeasibility is estimated; a failed check or a feasible state in an excluded cell is
/// `not_certified`.
#[test]
fn verdict_is_conditional_on_what_is_not_proven() {
    use super::VerdictStatus::*;
    let estimated = super::Evidence {
        eps_sound: false,
        eps_rests_on: vec!["l_mpc: sampled from the data's sensitivities (an estimate)".into()],
        ..proven(0.1, 1e-6)
    };
    let r = verdict(&estimated);
    assert_eq!((r.status, r.certified), (Conditional, false));
    assert_eq!(r.rests_on.len(), 1);
    assert!(r.rests_on[0].starts_with("l_mpc"), "{:?}", r.rests_on);
    assert!(!r.message.contains("Corollary 1 applies"), "{}", r.message);
    assert!(r.message.contains("l_mpc"), "{}", r.message);
    let r = verdict(&super::Evidence {
        check: super::Check::NotRun,
        ..proven(0.1, 0.0)
    });
    assert_eq!(r.status, Conditional);
    assert!(r.rests_on[0].contains("check"), "{:?}", r.rests_on);
    let r = verdict(&super::Evidence {
        excluded_unproven: 3,
        ..proven(0.1, 0.0)
    });
    assert_eq!(r.status, Conditional);
    assert!(
        r.rests_on[0].contains("3 excluded boxes"),
        "{:?}",
        r.rests_on
    );
    let r = verdict(&super::Evidence {
        check: super::Check::Failed,
        ..estimated.clone()
    });
    assert_eq!(r.status, NotCertified);
    assert!(r.message.contains("check failed"), "{}", r.message);
    let r = verdict(&super::Evidence {
        feasible_in_excluded: 2,
        ..proven(0.1, 0.0)
    });
    assert_eq!(r.status, NotCertified);
    let r = verdict(&super::Evidence {
        feasible_outside_domain: 1,
        ..proven(0.1, 0.0)
    });
    assert_eq!(r.status, NotCertified);
    assert!(r.message.contains("outside X"), "{}", r.message);
    // A missed design is not_certified whatever else holds.
    assert_eq!(verdict(&proven(0.6, 0.0)).status, NotCertified);
    assert_eq!(VerdictStatus::Conditional.name(), "conditional");
}

/// A nonlinear constraint is refused, naming its key; affine ones are tightened.
#[test]
fn nonlinear_constraints_are_refused_affine_ones_tightened() {
    for (path, terminal, key) in [
        (
            vec!["position * velocity <= 3".to_string()],
            vec![],
            "ocp.constraints[0]",
        ),
        (
            vec!["position + velocity <= 3".to_string()],
            vec!["position^2 <= 1".to_string()],
            "ocp.terminal_constraints[0]",
        ),
    ] {
        let mut cfg = di(0.01);
        cfg.ocp.constraints = path;
        cfg.ocp.terminal_constraints = terminal;
        cfg.validate().unwrap();
        let e = design::design(&cfg).unwrap_err().to_string();
        assert!(
            e.contains(&format!("`{key}`")) && e.contains("nonlinear"),
            "{e}"
        );
        cfg.ocp.terminal_constraints.clear();
        cfg.ocp.constraints = vec!["position + velocity <= 3".into()];
        let d = design::design(&cfg).unwrap();
        assert_eq!(d.stages.margins.len(), 1);
        assert_eq!(d.stages.margins[0].len(), cfg.ocp.horizon + 1);
    }
}

/// The margin of an affine constraint: a constraint that is a box gets the box's
/// tightening; a mixed one is never exceeded by sampled tube deviations and input errors
/// (KΔ + e), and is approached by them (the support function is attained).
#[test]
fn affine_constraint_margins_are_the_support_function_of_the_tube() {
    let cfg = di_mixed_constraints();
    let d = design::design(&cfg).unwrap();
    let t = &d.tube;
    let n = cfg.ocp.horizon;
    // The box x₂ ≤ 1.5 and the constraint "velocity <= 1.5": the same tightening.
    for k in 1..=n {
        let box_hi = d.stages.x_hi[k - 1][1];
        assert!(
            (1.5 - d.stages.margins[0][k] - box_hi).abs() < 1e-12,
            "stage {k}"
        );
    }
    // "force >= -0.8": the input box's ε + τ s_k.
    for k in 0..n {
        let want = t.eps + t.u_margin[0] * t.s[k];
        assert!((d.stages.margins[2][k] - want).abs() < 1e-12, "stage {k}");
    }
    // The mixed one against samples of (aₓ + Kᵀa_u)ᵀΔ + a_uᵀe.
    let (ax, au) = ([0.7, -0.4], 0.3);
    let p = DMatrix::from_fn(2, 2, |i, j| t.p[i][j]);
    let l = p.clone().cholesky().unwrap().l(); // P = L Lᵀ: Δ = L⁻ᵀ w, ‖w‖ ≤ s
    let linv_t = l.transpose().try_inverse().unwrap();
    for k in [1usize, n / 2, n] {
        let m = d.stages.margins[1][k];
        let mut best = f64::NEG_INFINITY;
        for i in 0..20_000u64 {
            // Half the samples on the boundary ‖Δ‖_P = s_k with e = ±ε (where the maximum
            // lies), half inside with e uniform.
            let r: Vec<f64> = (0..3).map(|c| uniform(1234 + k as u64, i, c)).collect();
            let ang = std::f64::consts::TAU * r[0];
            let (rad, e) = if i % 2 == 0 {
                (1.0, if r[2] < 0.5 { -t.eps } else { t.eps })
            } else {
                (r[1].sqrt(), t.eps * (2.0 * r[2] - 1.0))
            };
            let w = nalgebra::DVector::from_vec(vec![ang.cos(), ang.sin()]) * (t.s[k] * rad);
            let delta = &linv_t * w;
            assert!((delta.transpose() * &p * &delta)[(0, 0)].sqrt() <= t.s[k] * (1.0 + 1e-12));
            let du = (0..2).map(|j| t.k[0][j] * delta[j]).sum::<f64>() + e;
            let v = ax[0] * delta[0] + ax[1] * delta[1] + au * du;
            assert!(v <= m * (1.0 + 1e-12), "stage {k}: {v} > margin {m}");
            best = best.max(v);
        }
        assert!(
            best >= 0.995 * m,
            "stage {k}: the margin {m} is loose (max {best})"
        );
    }
    // (That the OCP's rows carry the margins is checked in `mpc`, which builds them:
    // `mpc::constraint_checks::robust_margins_reach_the_ocp_rows`.)
    // The terminal region satisfies every constraint with its stage-N margin under the
    // local feedback, on its boundary.
    let tr = d
        .terminal
        .as_ref()
        .expect("a terminal region of the double integrator");
    {
        let c = tr.radius;
        for i in 0..2000u64 {
            let ang = std::f64::consts::TAU * i as f64 / 2000.0;
            let w = nalgebra::DVector::from_vec(vec![ang.cos(), ang.sin()]) * c;
            let dx = &linv_t * w;
            let x = [tr.x_ref[0] + dx[0], tr.x_ref[1] + dx[1]];
            let u = tr.u_ref[0] + t.k[0][0] * dx[0] + t.k[0][1] * dx[1];
            let g = 0.7 * x[0] - 0.4 * x[1] + 0.3 * u;
            let room = [
                2.0 - d.stages.margins[1][n] - g,
                1.5 - d.stages.margins[0][n] - x[1],
                u - (-0.8 + d.stages.margins[2][n]),
            ];
            assert!(room.iter().all(|r| *r >= -1e-9), "{room:?}");
        }
    }
}

/// With a setpoint, the ancillary LQR gain is that of the linearisation at (x_ref, u_ref),
/// not at the origin (where the pendulum's linearisation differs).
#[test]
fn tube_gain_is_the_lqr_of_the_linearisation_at_the_setpoint() {
    let mut cfg = pendulum(0.05);
    let (th, p) = (0.3f64, Pendulum::default());
    // The torque that holds θ = 0.3: ω̇ = 0 there.
    let u_eq = p.m * p.l * p.g * (th + std::f64::consts::PI).sin();
    cfg.ocp.x_ref = Some(vec![th, 0.0]);
    cfg.ocp.u_ref = Some(vec![u_eq]);
    cfg.validate().unwrap();
    let d = design::design(&cfg).unwrap();
    let scale = d.tube.lqr_r_scale.expect("tube method");
    let model = Discrete::new(cfg.system.clone(), cfg.ocp.ts, cfg.ocp.rk4_substeps);
    let gain = |x: &[f64], u: &[f64]| {
        let (a, b) = linearize_at(&model, x, u);
        tube::dare(&a, &b, &cfg.q(), &(cfg.r() * scale)).unwrap().1
    };
    let at_ref = gain(&[th, 0.0], &[u_eq]);
    let at_origin = gain(&[0.0, 0.0], &[0.0]);
    let k = DMatrix::from_row_slice(1, 2, &[d.tube.k[0][0], d.tube.k[0][1]]);
    assert!((&k - &at_ref).amax() <= 1e-12, "{k} vs {at_ref}");
    assert!(
        (&k - &at_origin).amax() > 1e-3,
        "the setpoint's gain {k} should differ from the origin's {at_origin}"
    );
}
