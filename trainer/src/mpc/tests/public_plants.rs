//! The problem files of plants taken from public sources (tests only), checked against their
//! sources' equations written out here independently, in the sources' own form:
//! `configs/cartpole_public.toml` is Gymnasium's CartPole-v1 `step` (explicit Euler, its
//! constants), `configs/planar_quadrotor.toml` the planar quadrotor of Underactuated
//! Robotics (`m·ẍ = −(u1 + u2) sin θ`, `m·z̈ = (u1 + u2) cos θ − m·g`, `I·θ̈ = L·(u1 − u2)`)
//! under RK4, `configs/mass_chain12.toml` the 12-state, 4-input chain of the tests. Each
//! model's F equals those equations to 1e-12 at random states and inputs, and each OCP
//! solves at random states of X with KKT sensitivities equal to central differences of the
//! converged solver.

use super::{load, point};
use crate::mpc::law::MpcLaw;
use crate::mpc::sqp::SqpStatus;
use crate::problem::model::Discrete;
use crate::problem::ProblemConfig;

fn model(cfg: &ProblemConfig) -> Discrete {
    Discrete::new(cfg.system.clone(), cfg.ocp.ts, cfg.ocp.rk4_substeps)
}

/// Gymnasium's `CartPoleEnv.step` (classic_control/cartpole.py) with the force given
/// directly instead of `±force_mag`; state (x, x_dot, theta, theta_dot).
fn gym_step(s: &[f64], force: f64) -> [f64; 4] {
    let gravity = 9.8;
    let masscart = 1.0;
    let masspole = 0.1;
    let total_mass = masspole + masscart;
    let length = 0.5;
    let polemass_length = masspole * length;
    let tau = 0.02;
    let (x, x_dot, theta, theta_dot) = (s[0], s[1], s[2], s[3]);
    let costheta = theta.cos();
    let sintheta = theta.sin();
    let temp = (force + polemass_length * theta_dot.powi(2) * sintheta) / total_mass;
    let thetaacc = (gravity * sintheta - costheta * temp)
        / (length * (4.0 / 3.0 - masspole * costheta.powi(2) / total_mass));
    let xacc = temp - polemass_length * thetaacc * costheta / total_mass;
    [
        x + tau * x_dot,
        x_dot + tau * xacc,
        theta + tau * theta_dot,
        theta_dot + tau * thetaacc,
    ]
}

/// Underactuated Robotics' `Quadrotor2D` (quadrotor2d.py): q = (x, z, θ), thrusts u1, u2.
fn quadrotor_rhs(s: &[f64], u: [f64; 2]) -> [f64; 6] {
    let (length, mass, inertia, gravity) = (0.25, 0.486, 0.00383, 9.81);
    let q = &s[..3];
    let qdot = &s[3..];
    [
        qdot[0],
        qdot[1],
        qdot[2],
        -q[2].sin() / mass * (u[0] + u[1]),
        q[2].cos() / mass * (u[0] + u[1]) - gravity,
        length / inertia * (u[0] - u[1]),
    ]
}

/// One classical RK4 step of length h with the input held.
fn rk4(f: impl Fn(&[f64]) -> [f64; 6], x: &[f64], h: f64) -> Vec<f64> {
    let add = |a: &[f64], k: &[f64; 6], c: f64| -> Vec<f64> {
        a.iter().zip(k).map(|(a, k)| a + c * k).collect()
    };
    let k1 = f(x);
    let k2 = f(&add(x, &k1, h / 2.0));
    let k3 = f(&add(x, &k2, h / 2.0));
    let k4 = f(&add(x, &k3, h));
    (0..6)
        .map(|i| x[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]))
        .collect()
}

fn assert_close(a: &[f64], b: &[f64], what: &str) {
    for (i, (p, q)) in a.iter().zip(b).enumerate() {
        assert!(
            (p - q).abs() <= 1e-12 * q.abs().max(1.0),
            "{what}, component {i}: {p} vs {q}"
        );
    }
}

#[test]
fn cartpole_public_is_gymnasiums_cartpole_step() {
    let cfg = load("cartpole_public.toml");
    assert_eq!((cfg.system.nx(), cfg.system.nu()), (4, 1));
    // The environment's tau, force_mag and termination thresholds.
    assert_eq!(cfg.ocp.ts, 0.02);
    assert_eq!((cfg.ocp.u_lo[0], cfg.ocp.u_hi[0]), (-10.0, 10.0));
    assert_eq!(cfg.ocp.x_hi[0], 2.4);
    assert_eq!(cfg.ocp.x_hi[2], 12.0 * 2.0 * std::f64::consts::PI / 360.0);
    let f = model(&cfg);
    let mut out = [0.0; 4];
    // Beyond X and U: the whole swing (|θ| ≤ π) and forces past the bound.
    let (lo, hi) = ([-3.0, -5.0, -3.2, -8.0, -15.0], [3.0, 5.0, 3.2, 8.0, 15.0]);
    for i in 0..500 {
        let s = point(11, i, &lo, &hi);
        f.step(&s[..4], &s[4..], &mut out);
        assert_close(&out, &gym_step(&s[..4], s[4]), &format!("step at {s:?}"));
    }
}

#[test]
fn planar_quadrotor_is_the_books_model_under_rk4() {
    let cfg = load("planar_quadrotor.toml");
    assert_eq!((cfg.system.nx(), cfg.system.nu()), (6, 2));
    let f = model(&cfg);
    let h = cfg.ocp.ts / cfg.ocp.rk4_substeps as f64;
    let hover = 0.486 * 9.81 / 2.0;
    let mut out = [0.0; 6];
    let lo = [-2.0, -2.0, -1.5, -3.0, -3.0, -5.0, -2.5, -2.5];
    let hi = [2.0, 2.0, 1.5, 3.0, 3.0, 5.0, 2.5, 2.5];
    for i in 0..500 {
        let s = point(12, i, &lo, &hi);
        let (x, du) = (&s[..6], &s[6..]);
        f.step(x, du, &mut out);
        let mut want = x.to_vec();
        for _ in 0..cfg.ocp.rk4_substeps {
            want = rk4(
                |y| quadrotor_rhs(y, [hover + du[0], hover + du[1]]),
                &want,
                h,
            );
        }
        assert_close(&out, &want, &format!("step at {s:?}"));
    }
    // Hover is an equilibrium: the inputs are deviations from m·g/2.
    f.step(&[0.0; 6], &[0.0; 2], &mut out);
    assert!(out.iter().all(|v| v.abs() <= 1e-14), "{out:?}");
}

#[test]
fn mass_chain12_file_is_the_test_chain() {
    let cfg = load("mass_chain12.toml");
    assert_eq!((cfg.system.nx(), cfg.system.nu()), (12, 4));
    let (a, b) = (
        model(&cfg),
        Discrete::new(
            crate::problem::model::test_plants::chain12(),
            cfg.ocp.ts,
            cfg.ocp.rk4_substeps,
        ),
    );
    let (mut fa, mut fb) = ([0.0; 12], [0.0; 12]);
    for i in 0..100 {
        let s = point(13, i, &[-1.0; 16], &[1.0; 16]);
        a.step(&s[..12], &s[12..], &mut fa);
        b.step(&s[..12], &s[12..], &mut fb);
        assert_eq!(fa, fb, "at {s:?}");
    }
}

/// Solves at `n` random states of X: all converge, and where the active set does not change
/// within ±h (no kink) the KKT sensitivities equal central differences of the solver to 1e-5
/// of the largest entry. Returns the number of states checked that way.
fn solves_with_fd_sensitivities(cfg: &ProblemConfig, n: u64) -> usize {
    let (nx, nu) = (cfg.system.nx(), cfg.system.nu());
    let mut law = MpcLaw::new(cfg);
    let h = 1e-6;
    let mut checked = 0;
    for i in 0..n {
        let x = point(14, i, &cfg.domain.lo, &cfg.domain.hi);
        let (l, _) = law.solve(&x, None);
        assert_eq!(l.status, SqpStatus::Converged, "{} at {x:?}", cfg.name);
        if l.degeneracy.is_some() {
            continue;
        }
        let mut fd = vec![0.0; nu * nx];
        let mut kink = false;
        for j in 0..nx {
            let (mut xp, mut xm) = (x.clone(), x.clone());
            xp[j] += h;
            xm[j] -= h;
            let ((lp, _), (lm, _)) = (law.solve(&xp, None), law.solve(&xm, None));
            assert!(lp.status == SqpStatus::Converged && lm.status == SqpStatus::Converged);
            for r in 0..nu {
                let (fwd, bwd) = ((lp.u[r] - l.u[r]) / h, (l.u[r] - lm.u[r]) / h);
                kink |= (fwd - bwd).abs() > 1e-3 * (1.0 + fwd.abs());
                fd[r * nx + j] = (lp.u[r] - lm.u[r]) / (2.0 * h);
            }
        }
        if kink {
            continue;
        }
        let scale = fd
            .iter()
            .chain(&l.du_dx)
            .fold(1.0f64, |m, v| m.max(v.abs()));
        for (k, (a, b)) in fd.iter().zip(&l.du_dx).enumerate() {
            assert!(
                (a - b).abs() <= 1e-5 * scale,
                "{} at {x:?}: du{}/dx{}: fd {a} vs kkt {b}",
                cfg.name,
                k / nx,
                k % nx
            );
        }
        checked += 1;
    }
    checked
}

#[test]
fn cartpole_public_solves_with_finite_difference_sensitivities() {
    let checked = solves_with_fd_sensitivities(&load("cartpole_public.toml"), 6);
    assert!(checked >= 2, "only {checked} states checked");
}

#[test]
fn planar_quadrotor_solves_with_finite_difference_sensitivities() {
    let checked = solves_with_fd_sensitivities(&load("planar_quadrotor.toml"), 5);
    assert!(checked >= 2, "only {checked} states checked");
}
