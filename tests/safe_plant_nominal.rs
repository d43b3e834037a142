//! The nominal terminal ingredients in the generated plant (module of `safe_plant_loop`):
//! - the f32 emulation of `deploy::plant_rs_margin` is bit-for-bit the compiled generated
//!   `step` (so the margin is measured on the code the device runs);
//! - the generated `MARGINS` cover the f32-vs-f64 difference of the compiled code over
//!   N-step trajectories from 10⁵ other seeded states under other input sequences;
//! - the stiff spring's `[ocp]` expression constraints in f32 against the f64 set, and the
//!   OCP's rule of where each is imposed;
//! - a `SafeController` closed loop on the generated quadrotor (MPC candidates, every third
//!   one corrupted and refused).

use super::{config, uniform_seed};
use controller_core::safe::{Plant, SafeController, SafeFlags};
use trainer::deploy::plant_rs::plant_model;
use trainer::deploy::plant_rs_margin::step_f32;
use trainer::mpc::law::MpcLaw;
use trainer::problem::model::Discrete;

#[allow(dead_code)]
mod quad {
    include!("fixtures/safe-plant/planar_quadrotor_safe.rs");
}
#[allow(dead_code)]
mod spring {
    include!("fixtures/safe-plant/stiff_spring_safe.rs");
}

#[test]
fn emulation_is_the_generated_step_bit_for_bit() {
    let cfg = config("planar_quadrotor");
    let model = plant_model(&cfg.system).unwrap();
    let mut s = 0x0e_u64;
    for _ in 0..10_000 {
        let x: [f32; 6] = std::array::from_fn(|_| (4.0 * uniform_seed(&mut s) - 2.0) as f32);
        let u: [f32; 2] = std::array::from_fn(|_| (6.0 * uniform_seed(&mut s) - 3.0) as f32);
        let e = step_f32(&model, cfg.ocp.ts, cfg.ocp.rk4_substeps, &x, &u);
        let g = quad::step(&x, &u);
        for i in 0..6 {
            assert_eq!(e[i].to_bits(), g[i].to_bits(), "x={x:?} u={u:?}");
        }
    }
}

#[test]
fn generated_margins_cover_the_n_step_difference_on_1e5_other_states() {
    let cfg = config("planar_quadrotor");
    let o = &cfg.ocp;
    let f64_model = Discrete::new(cfg.system.clone(), o.ts, o.rk4_substeps);
    let scale = o.x_scale_or_default(&cfg.domain.lo, &cfg.domain.hi);
    let plant = quad::SafePlant;
    let (mut ds, mut df, mut full) = (0.0f64, 0.0f64, 0);
    let mut s = 0x6d61_7267_u64;
    let mut y = [0.0f64; 6];
    for _ in 0..100_000 {
        let mut x32: [f32; 6] = std::array::from_fn(|i| {
            let (lo, hi) = (cfg.domain.lo[i], cfg.domain.hi[i]);
            (lo + (hi - lo) * uniform_seed(&mut s)) as f32
        });
        let mut x64: Vec<f64> = x32.iter().map(|v| f64::from(*v)).collect();
        let mut inside = true;
        for _ in 0..o.horizon {
            // Another input policy than the estimate's: κ_f of the f32 state plus noise of
            // a fifth of the box, projected.
            let kf = plant.terminal_input(&x32);
            let u: [f32; 2] = std::array::from_fn(|j| {
                kf[j] + (0.2 * (o.u_hi[j] - o.u_lo[j]) * (uniform_seed(&mut s) - 0.5)) as f32
            });
            let u = plant.project_input(&u);
            let ud: Vec<f64> = u.iter().map(|v| f64::from(*v)).collect();
            x32 = quad::step(&x32, &u);
            f64_model.step(&x64, &ud, &mut y);
            x64.copy_from_slice(&y);
            inside &= (0..6).all(|i| o.x_lo[i] <= x64[i] && x64[i] <= o.x_hi[i]);
            if !inside {
                break;
            }
            for i in 0..6 {
                if o.x_lo[i].is_finite() || o.x_hi[i].is_finite() {
                    ds = ds.max((f64::from(x32[i]) - x64[i]).abs() / scale[i]);
                }
            }
        }
        if inside {
            full += 1;
            let v64: f64 = (0..6)
                .map(|i| {
                    (x64[i] - f64::from(quad::X_REF[i]))
                        * (0..6)
                            .map(|j| {
                                f64::from(quad::P_F[i][j]) * (x64[j] - f64::from(quad::X_REF[j]))
                            })
                            .sum::<f64>()
                })
                .sum();
            let v32 = f64::from(plant.terminal_violation(&x32)); // (V32 − α)/α ∨ box
            let vt = (v64 - f64::from(quad::ALPHA)) / f64::from(quad::ALPHA);
            if v32 >= -1.0 + 1e-3 && vt > f64::from(quad::state_box_violation(&x32)) {
                df = df.max((v32 - vt).abs());
            }
        }
    }
    eprintln!(
        "quadrotor: {full} of 1e5 trajectories stayed in the box; N-step difference: state \
         {ds:e} (margin {:e}), terminal {df:e} (margin {:e})",
        quad::MARGINS.stage,
        quad::MARGINS.terminal
    );
    assert!(full > 1000 && ds > 0.0, "{full} trajectories, d_s {ds}");
    assert!(
        ds <= f64::from(quad::MARGINS.stage),
        "{ds:e} > {:e}",
        quad::MARGINS.stage
    );
    assert!(
        df <= f64::from(quad::MARGINS.terminal),
        "{df:e} > {:e}",
        quad::MARGINS.terminal
    );
}

#[test]
fn expression_constraints_match_the_f64_set_and_the_ocp_rule() {
    let cfg = config("stiff_spring_setpoint");
    let cs = cfg.constraint_set().unwrap().unwrap();
    assert_eq!(spring::NC, cs.len());
    let (mut g, mut scratch) = (vec![0.0; cs.len()], Vec::new());
    let mut s = 0x5c_u64;
    let (mut hit_path, mut hit_term) = (0, 0);
    for _ in 0..100_000 {
        let x: [f32; 2] = std::array::from_fn(|_| (4.0 * uniform_seed(&mut s) - 2.0) as f32);
        let u: [f32; 1] = [(8.0 * uniform_seed(&mut s) - 4.0) as f32];
        let xd: Vec<f64> = x.iter().map(|v| f64::from(*v)).collect();
        cs.eval(&xd, &[f64::from(u[0])], &mut g, &mut scratch);
        let g32 = spring::constraints(&x, &u);
        for c in 0..cs.len() {
            let d = (f64::from(g32[c]) - g[c]).abs();
            assert!(
                d <= 1e-5 * (1.0 + g[c].abs()),
                "{}: {} vs {}",
                cs.items[c].key,
                g32[c],
                g[c]
            );
        }
        // Every path constraint (all of this plant's mix states and inputs or use states)
        // from k = 1 on; none at k = 0; the terminal one in g_N only.
        let path = (0..cs.len())
            .filter(|c| !cs.items[*c].terminal)
            .map(|c| g32[c])
            .fold(f32::NEG_INFINITY, f32::max);
        let term = (0..cs.len())
            .filter(|c| cs.items[*c].terminal)
            .map(|c| g32[c])
            .fold(f32::NEG_INFINITY, f32::max);
        let p = spring::SafePlant;
        assert!(p.stage_violation(1, &x, &u) >= path);
        assert_eq!(p.stage_violation(0, &x, &u), f32::NEG_INFINITY);
        assert!(p.terminal_violation(&x) >= term);
        hit_path += (path > 0.0) as usize;
        hit_term += (term > 0.0) as usize;
    }
    assert!(hit_path > 0 && hit_term > 0, "{hit_path} {hit_term}");
}

const N: usize = 20;

/// The MPC's input sequence at `x` (f64 SQP, rounded to f32).
fn mpc_sequence(law: &mut MpcLaw, x: &[f32; 6]) -> Option<[[f32; 2]; N]> {
    let xs: Vec<f64> = x.iter().map(|v| *v as f64).collect();
    let (label, sol) = law.solve(&xs, None);
    let z = sol?.z;
    label.status.is_labelled().then_some(())?;
    Some(std::array::from_fn(|k| {
        std::array::from_fn(|j| z[k * 8 + 6 + j] as f32)
    }))
}

#[test]
fn safe_controller_closed_loop_on_the_generated_quadrotor() {
    let cfg = config("planar_quadrotor");
    assert_eq!(cfg.ocp.horizon, N);
    let mut law = MpcLaw::new(&cfg);
    let mut ctl: SafeController<_, (), 6, 2, N> =
        SafeController::new(quad::SafePlant, (), quad::MARGINS);
    let mut x = [0.5f32, -0.4, 0.2, 0.0, 0.3, 0.0];
    let (mut used, mut fallback, mut no_safe) = (0, 0, 0);
    for t in 0..60 {
        let mut cand = mpc_sequence(&mut law, &x).unwrap_or([[f32::NAN; 2]; N]);
        let corrupt = t % 3 == 1;
        if corrupt {
            cand = [[if t % 6 == 1 { f32::NAN } else { 2.0 }, -2.0]; N];
        }
        let out = ctl.step_with(&x, cand);
        if out.flags.contains(SafeFlags::NO_SAFE) {
            no_safe += 1;
            assert!(
                t == 0,
                "step {t}: no safe sequence: {:?} at {x:?}",
                out.flags
            );
        }
        assert!(
            !out.flags.contains(SafeFlags::SAFE_INFEASIBLE),
            "step {t}: {:?}",
            out.flags
        );
        if corrupt {
            assert!(
                out.flags.contains(SafeFlags::FALLBACK),
                "step {t}: {:?}",
                out.flags
            );
        }
        used += out.flags.contains(SafeFlags::CANDIDATE) as usize;
        fallback += out.flags.contains(SafeFlags::FALLBACK) as usize;
        x = quad::step(&x, &out.u);
        assert!(
            quad::state_box_violation(&x) <= 0.0,
            "step {t}: box violated at {x:?}"
        );
    }
    let dist = x.iter().map(|v| v.abs()).fold(0.0f32, f32::max);
    eprintln!(
        "quadrotor safe loop: candidate {used}, fallback {fallback}, no safe {no_safe}, \
         final max|x| {dist:e}"
    );
    assert!(dist < 0.05, "not converged: {x:?}");
}
