//! `trainer::deploy::safe_emulation` — the runtime-dimension mirror of
//! `controller_core::safe::SafeController` over the f32 emulation of the generated plant —
//! against the real thing: `SafeController` running the committed generated plants
//! (`fixtures/safe-plant/double_integrator_safe.rs`: robust terminal region;
//! `planar_quadrotor_safe.rs`: nominal terminal ingredients), compiled into this test.
//!
//! Both run the same closed loops (the state advanced by the generated `step` with the
//! applied input) from seeded states — near the setpoint and anywhere in X — with candidates
//! of every kind: the terminal controller's f32 rollout (often feasible), the same slightly
//! perturbed, uniform inputs in U, inputs just outside U, NaN entries; some loops start with
//! `init_with`; every seventh step the state is kicked (a disturbance, so that the shifted
//! sequence can fail its check). Both candidate forms run (the feedback form with the same
//! candidates written as offsets from κ_f, and the relaxed decrease σ = 0.5, whose bound β
//! must agree bit for bit too). At every step the applied input, the flags and both costs must be
//! bit-identical, and every kind of outcome (candidate, fallback, no safe sequence,
//! initialised, infeasible fallback) must occur, so that the comparison covers each branch.

use controller_core::safe::{CandidateForm, Margins, Plant, SafeController, SafeFlags};
use std::path::{Path, PathBuf};
use trainer::deploy::safe_emulation::{EmulatedPlant, SafeEmulation};
use trainer::problem::ProblemConfig;

#[allow(dead_code)]
mod di {
    include!("fixtures/safe-plant/double_integrator_safe.rs");
}
#[allow(dead_code)]
mod quad {
    include!("fixtures/safe-plant/planar_quadrotor_safe.rs");
}

fn config(name: &str) -> ProblemConfig {
    let root: PathBuf = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    ProblemConfig::load(&root.join("configs").join(format!("{name}.toml"))).unwrap()
}

/// xorshift64 → uniform [0, 1).
fn next(s: &mut u64) -> f64 {
    *s ^= *s << 13;
    *s ^= *s >> 7;
    *s ^= *s << 17;
    (*s >> 11) as f64 / (1u64 << 53) as f64
}

/// A candidate of kind `kind` at `x` (module doc).
/// With `feedback`, entries 1 … N−1 are then written as offsets from κ_f along the open
/// simulation (the feedback form's coordinates; the realised sequence is then close to it).
fn candidate<P: Plant<NX, NU>, const NX: usize, const NU: usize, const N: usize>(
    p: &P,
    cfg: &ProblemConfig,
    x: &[f32; NX],
    kind: u64,
    s: &mut u64,
    feedback: bool,
) -> [[f32; NU]; N] {
    let (lo, hi) = (&cfg.ocp.u_lo, &cfg.ocp.u_hi);
    let mut xk = *x;
    let mut c = [[0.0f32; NU]; N];
    for (k, row) in c.iter_mut().enumerate() {
        let kf = p.project_input(&p.terminal_input(&xk));
        for j in 0..NU {
            let w = (hi[j] - lo[j]) as f32;
            row[j] = match kind {
                0 => kf[j],
                1 => kf[j] + 0.02 * w * (next(s) as f32 - 0.5),
                2 => (lo[j] + (hi[j] - lo[j]) * next(s)) as f32,
                3 => hi[j] as f32 * 1.0001 + 1e-6,
                _ => {
                    if next(s) < 0.1 {
                        f32::NAN
                    } else {
                        kf[j]
                    }
                }
            };
        }
        let next_x = p.step(&xk, row);
        if feedback && k >= 1 {
            let kf = p.terminal_input(&xk);
            for j in 0..NU {
                row[j] -= kf[j];
            }
        }
        xk = next_x;
    }
    c
}

/// Runs both controllers over `loops` closed loops of `steps` steps; returns how often each
/// flag occurred.
fn compare<P, const NX: usize, const NU: usize, const N: usize>(
    name: &str,
    plant: P,
    margins: Margins,
    loops: usize,
    steps: usize,
    (form, decrease): (CandidateForm, Option<f32>),
) -> [usize; 5]
where
    P: Plant<NX, NU> + Copy,
{
    let cfg = config(name);
    let (emu, _) = EmulatedPlant::new(&cfg).unwrap();
    assert_eq!(emu.margins, (margins.stage, margins.terminal), "{name}");
    let mut seen = [0usize; 5];
    let mut s = 0x5afe_e301_u64;
    for l in 0..loops {
        let near = l % 2 == 0;
        let mut x: [f32; NX] = std::array::from_fn(|i| {
            let (lo, hi) = (cfg.domain.lo[i], cfg.domain.hi[i]);
            let u = next(&mut s);
            let v = if near {
                0.1 * (lo + (hi - lo) * u)
            } else {
                lo + (hi - lo) * u
            };
            v as f32
        });
        let mut real = SafeController::<P, (), NX, NU, N>::new(plant, (), margins).with_form(form);
        if let Some(sigma) = decrease {
            real = real.with_decrease(sigma);
        }
        let mut mine = SafeEmulation::new(&emu, N)
            .with_form(form)
            .with_decrease(decrease);
        let feedback = form == CandidateForm::Feedback;
        if l % 3 == 0 {
            // init_with takes inputs in both forms.
            let c: [[f32; NU]; N] = candidate(&plant, &cfg, &x, 0, &mut s, false);
            let rows: Vec<Vec<f32>> = c.iter().map(|r| r.to_vec()).collect();
            let a = real.init_with(&x, &c).ok();
            let b = mine.init_with(x.as_ref(), &rows);
            assert_eq!(
                a.map(f32::to_bits),
                b.map(f32::to_bits),
                "{name} init at {x:?}"
            );
        }
        for k in 0..steps {
            let kind = (next(&mut s) * 5.0) as u64 % 5;
            let c: [[f32; NU]; N] = candidate(&plant, &cfg, &x, kind, &mut s, feedback);
            let rows: Vec<Vec<f32>> = c.iter().map(|r| r.to_vec()).collect();
            let a = real.step_with(&x, c);
            let b = mine.step_with(&x, rows);
            let what = format!("{name} loop {l} step {k} kind {kind} x {x:?}");
            assert_eq!(a.flags, b.flags, "{what}");
            assert_eq!(
                a.candidate_cost.to_bits(),
                b.candidate_cost.to_bits(),
                "{what}"
            );
            assert_eq!(a.safe_cost.to_bits(), b.safe_cost.to_bits(), "{what}");
            assert_eq!(real.bound().to_bits(), mine.bound().to_bits(), "{what}");
            let ua: Vec<u32> = a.u.iter().map(|v| v.to_bits()).collect();
            let ub: Vec<u32> = b.u.iter().map(|v| v.to_bits()).collect();
            assert_eq!(ua, ub, "{what}");
            for (i, f) in [
                SafeFlags::CANDIDATE,
                SafeFlags::FALLBACK,
                SafeFlags::NO_SAFE,
                SafeFlags::INITIALISED,
                SafeFlags::SAFE_INFEASIBLE,
            ]
            .iter()
            .enumerate()
            {
                seen[i] += usize::from(a.flags.contains(*f));
            }
            x = plant.step(&x, &a.u);
            if k % 7 == 6 {
                // A disturbance now and then: the shifted sequence may then fail its check.
                for (i, v) in x.iter_mut().enumerate() {
                    let w = cfg.domain.hi[i] - cfg.domain.lo[i];
                    *v += (0.2 * w * (next(&mut s) - 0.5)) as f32;
                }
            }
        }
    }
    eprintln!(
        "{name} ({form:?}): candidate, fallback, no safe, initialised, safe infeasible: {seen:?}"
    );
    for (i, n) in seen.iter().enumerate() {
        assert!(*n > 0, "{name}: outcome {i} never occurred: {seen:?}");
    }
    seen
}

#[test]
fn double_integrator_emulation_is_the_safe_controller_bit_for_bit() {
    compare::<di::SafePlant, 2, 1, 20>(
        "double_integrator_ode",
        di::SafePlant,
        di::MARGINS,
        200,
        40,
        (CandidateForm::Open, None),
    );
}

#[test]
fn quadrotor_emulation_is_the_safe_controller_bit_for_bit() {
    compare::<quad::SafePlant, 6, 2, 20>(
        "planar_quadrotor",
        quad::SafePlant,
        quad::MARGINS,
        200,
        40,
        (CandidateForm::Open, None),
    );
}

#[test]
fn feedback_form_and_relaxed_decrease_emulation_is_the_safe_controller_bit_for_bit() {
    compare::<di::SafePlant, 2, 1, 20>(
        "double_integrator_ode",
        di::SafePlant,
        di::MARGINS,
        120,
        40,
        (CandidateForm::Feedback, Some(0.5)),
    );
    compare::<quad::SafePlant, 6, 2, 20>(
        "planar_quadrotor",
        quad::SafePlant,
        quad::MARGINS,
        120,
        40,
        (CandidateForm::Feedback, Some(0.5)),
    );
}
